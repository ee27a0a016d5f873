# `make reproduce`: the paper's tables, figures and write-up as a dependency graph of files.
#
#   data/<gen>/manifest.json                 sixdpose generate   (training data, test, single-instance test, val)
#   runs/P/seg/model.pt                      sixdpose train-seg
#   runs/P/masks/<split>/meta.json           sixdpose segment    (predicted masks of a held-out split)
#   runs/P/pose/model.pt, refiner/model.pt   sixdpose train-pose, train-refiner
#   runs/P/poses/<split>_<masks>_<method>.csv  sixdpose register (hybrid) / predict-pose (learned)
#   results/P/<split>_<masks>_<method>.json  sixdpose evaluate --result-name (+ .csv; commit, date, hardware)
#   runs/P/seg/pred_test/meta.json           sixdpose segment    (notebook 03's held-out training images)
#   runs/P/seg_fast/model.pt, masks_fast/test/meta.json  train-seg, segment (cpu: the dense head's real-time
#                                            segmenter, SEG_FAST_P; results/P/test_fast_<method>.json its rows)
#   results/P/e2e_dense.json                 benchmarks/pose.py (cpu, paper: the dense head end to end, timed)
#   data/<test>_kinect, results/P/test_kinect_gt_<method>.json  the test split with kinect depth (notebook 08)
#   results/P/pose_ablation_P.json           sixdpose pose-ablation (notebook 05)
#   notebooks/executed/P/NN_*.ipynb          papermill, on top of those files (figures/P/...)
#   paper/generated/P/*.tex                  notebook 07: Tables I-III, per-object tables, macros
#   paper/build/P/paper.pdf (+ paper/paper.pdf)  latexmk
#
# P is $(PROFILE) (mk/profiles.mk). <split>: test (multi-instance) or single (no repeated object, the
# paper's Table III subset); <masks>: gt or pred (Mask R-CNN of runs/P/seg); <method>: $(METHODS).
# Each target is a file written atomically by the command that makes it, so an interrupted run resumes
# where it stopped (training resumes from last.pt) and `make -n reproduce` prints the plan. Every dataset,
# trained network and result of record is a target here: the notebooks only read them (sixdpose.graph
# names the target of a missing one).
# LMO=/path/to/lmo (a full BOP LM-O with depth) adds the LM-O rows of Table I.
# `make tables` and `make paper` (without RECOMPUTE=yes) are not this graph: they build the write-up from the
# result files that are here (the committed results/cpu on a fresh clone) and run no stage; see "what the
# write-up reads" below.

SIXDPOSE := $(VENV)/bin/sixdpose
VENV_OK := $(VENV)/.synced $(APT_STAMP)
LMO ?=
LMO_SPLIT ?= test
LMO_TRAIN_SPLIT ?= train_pbr

ALL_HYBRID  := ransac ransac_icp fgr fgr_icp super4pcs super4pcs_icp
# the paper's Table III hybrid rows rerun with its own settings (registration preset `paper`, section IV-B)
PAPER_HYBRID := ransac_icp_paper fgr_icp_paper super4pcs_paper
ALL_LEARNED := learned_it0 learned_it2 learned_it2_icp learned_it2_colour dense dense_icp dense_icp_verify
FEW_METHODS := ransac_icp super4pcs learned_it0 learned_it2
HYBRID  := $(if $(filter few,$(P_METHODS)),$(filter $(FEW_METHODS),$(ALL_HYBRID)),$(ALL_HYBRID))
LEARNED := $(if $(filter few,$(P_METHODS)),$(filter $(FEW_METHODS),$(ALL_LEARNED)),$(ALL_LEARNED))
METHODS := $(HYBRID) $(if $(filter yes,$(P_PAPER_ROWS)),$(PAPER_HYBRID)) $(LEARNED)
SPLITS  := test single
MASKS   := gt pred

_limit = $(if $(filter-out 0,$(P_LIMIT)),--limit $(P_LIMIT))

# ---- datasets ----------------------------------------------------------------------------------
# one rule per generator profile the graph uses (a dataset is complete when manifest.json is written;
# generate resumes an interrupted dataset and leaves a complete one untouched)
DATASETS := $(sort $(P_TRAIN_GEN) $(P_TEST_GEN) $(P_SINGLE_GEN) $(P_VAL_GEN))
$(foreach g,$(DATASETS),$(eval data/$(g)/manifest.json: | $(VENV_OK) ; \
	$(SIXDPOSE) generate --profile $(g) --out data/$(g) --workers $(WORKERS) --no-progress))

# ---- ImageNet weights (profiles with an IMAGENET backbone: paper) --------------------------------
# train-seg never downloads: it starts from ImageNet weights only when torchvision's file is in the torch hub
# cache, torch.hub.get_dir()/checkpoints/<the file name of the weights' URL> (get_dir: $TORCH_HOME/hub, by default
# $XDG_CACHE_HOME/torch/hub or ~/.cache/torch/hub). fetch-weights puts it there (resumable, checksum-checked);
# tests/test_make.py checks that this is the path torch and the segmentation stage use
TORCH_HUB := $(or $(TORCH_HOME),$(or $(XDG_CACHE_HOME),$(HOME)/.cache)/torch)/hub
IMAGENET_FILE_resnet50 := resnet50-0676ba61.pth
IMAGENET_WEIGHTS := $(if $(P_IMAGENET),$(TORCH_HUB)/checkpoints/$(IMAGENET_FILE_$(P_IMAGENET)))
ifneq ($(P_IMAGENET),)
$(IMAGENET_WEIGHTS): | $(VENV_OK)
	$(SIXDPOSE) fetch-weights --backbone $(P_IMAGENET) --no-progress
endif

# ---- segmentation ------------------------------------------------------------------------------
# train-seg writes model.pt last; an interrupted run (its config.json is written first, last.pt after each
# epoch) is resumed, also one stopped before its first epoch ended (no last.pt yet)
$(RUNS)/seg/model.pt: $(TRAIN_DIR)/manifest.json | $(VENV_OK) $(IMAGENET_WEIGHTS)
	$(SIXDPOSE) train-seg --data $(TRAIN_DIR) --out $(@D) --no-progress \
	  $(if $(wildcard $(@D)/config.json),--resume,--profile $(P_SEG))

$(RUNS)/masks/%/meta.json: $(RUNS)/seg/model.pt | $(VENV_OK)
	$(SIXDPOSE) segment --data $(DATA_$*) --seg $(RUNS)/seg --out $(@D) --no-progress

$(RUNS)/masks/test/meta.json: $(DATA_test)/manifest.json
$(RUNS)/masks/single/meta.json: $(DATA_single)/manifest.json

# notebook 03's predictions: the run's own held-out training images (notebook 04 registers on them)
$(RUNS)/seg/pred_test/meta.json: $(RUNS)/seg/model.pt $(TRAIN_DIR)/manifest.json | $(VENV_OK)
	$(SIXDPOSE) segment --data $(TRAIN_DIR) --seg $(RUNS)/seg --subset test --out $(@D) --no-progress

# the dense head's real-time segmenter (SEG_FAST_$(PROFILE), profiles that have one): trained on the same data,
# its masks of the multi-instance test split scored with the dense head (rows test_fast_dense*, beside Tables I-III,
# not in them), and the end-to-end frame rate of that pipeline (benchmarks/pose.py, results/P/e2e_dense.json)
ifneq ($(SEG_FAST_$(PROFILE)),)
$(RUNS)/seg_fast/model.pt: $(TRAIN_DIR)/manifest.json | $(VENV_OK)
	$(SIXDPOSE) train-seg --data $(TRAIN_DIR) --out $(@D) --no-progress \
	  $(if $(wildcard $(@D)/config.json),--resume,$(SEG_FAST_$(PROFILE)))

$(RUNS)/masks_fast/test/meta.json: $(RUNS)/seg_fast/model.pt $(DATA_test)/manifest.json | $(VENV_OK)
	$(SIXDPOSE) segment --data $(DATA_test) --seg $(RUNS)/seg_fast --out $(@D) --no-progress
FAST_SEG := seg_fast
FAST_STAGES := $(RUNS)/seg_fast/model.pt $(RUNS)/masks_fast/test/meta.json
endif

# ---- learned pose ------------------------------------------------------------------------------
_val = $(if $(VAL_DIR),--val $(VAL_DIR))
$(RUNS)/pose/model.pt: $(TRAIN_DIR)/manifest.json $(if $(VAL_DIR),$(VAL_DIR)/manifest.json) | $(VENV_OK)
	$(SIXDPOSE) train-pose --data $(TRAIN_DIR) --out $(@D) $(_val) --no-progress \
	  $(if $(wildcard $(@D)/config.json),--resume,--profile $(P_POSE))

$(RUNS)/refiner/model.pt: $(RUNS)/pose/model.pt $(TRAIN_DIR)/manifest.json $(if $(VAL_DIR),$(VAL_DIR)/manifest.json) | $(VENV_OK)
	$(SIXDPOSE) train-refiner --pose $(RUNS)/pose --data $(TRAIN_DIR) --out $(@D) $(_val) --no-progress \
	  $(if $(wildcard $(@D)/config.json),--resume,--profile $(P_POSE))

# the dense head (the project's own method, rows `dense` and `dense_icp`) on the same training data, with the
# recipe of DENSE_$(PROFILE) (that of the synthetic-to-real dense head); no per-epoch validation
$(RUNS)/pose_dense/model.pt: $(TRAIN_DIR)/manifest.json | $(VENV_OK)
	$(SIXDPOSE) train-pose --data $(TRAIN_DIR) --out $(@D) --no-progress \
	  $(if $(wildcard $(@D)/config.json),--resume,$(DENSE_$(PROFILE)))

# the ablation of notebook 05 (each option of the paper's architecture changed alone, the budget of
# ABLATION_$(PROFILE)), scored on the validation split (smoke, demo: the test split's images)
ABLATION_VAL := $(or $(VAL_DIR),$(DATA_test))
ABLATION_RESULT := $(RES)/pose_ablation_$(PROFILE).json
$(ABLATION_RESULT): $(TRAIN_DIR)/manifest.json $(ABLATION_VAL)/manifest.json | $(VENV_OK)
	$(SIXDPOSE) pose-ablation --data $(TRAIN_DIR) --val $(ABLATION_VAL) --out $(RUNS)/pose_ablation --profile $(P_POSE) \
	  $(ABLATION_$(PROFILE)) --no-progress --result-name pose_ablation_$(PROFILE) --results-dir $(RES)
# ... and over seeds (ABLATION_SEEDS), after it: its seed-0 runs are the ones above
ABLATION_SEEDS_RESULT := $(RES)/pose_ablation_seeds_$(PROFILE).json
$(ABLATION_SEEDS_RESULT): $(TRAIN_DIR)/manifest.json $(ABLATION_VAL)/manifest.json | $(VENV_OK) $(ABLATION_RESULT)
	$(SIXDPOSE) pose-ablation --data $(TRAIN_DIR) --val $(ABLATION_VAL) --out $(RUNS)/pose_ablation --profile $(P_POSE) \
	  $(ABLATION_$(PROFILE)) $(ABLATION_SEEDS) --no-progress --result-name pose_ablation_seeds_$(PROFILE) --results-dir $(RES)

# ---- pose estimates: one results CSV per split x masks x method --------------------------------
# the paper's methods without the hypothesis verification that `register` runs by default (--no-verify)
CMD_ransac         := register --method ransac --no-verify
CMD_ransac_icp     := register --method ransac --icp --no-verify
CMD_fgr            := register --method fgr --no-verify
CMD_fgr_icp        := register --method fgr --icp --no-verify
CMD_super4pcs      := register --method super4pcs --no-verify
CMD_super4pcs_icp  := register --method super4pcs --icp --no-verify
CMD_ransac_icp_paper := register --method ransac --icp --no-verify --preset paper
CMD_fgr_icp_paper    := register --method fgr --icp --no-verify --preset paper
CMD_super4pcs_paper  := register --method super4pcs --no-verify --preset paper
CMD_learned_it0    := predict-pose --pose $(RUNS)/pose --iterations 0
CMD_learned_it2    := predict-pose --pose $(RUNS)/pose --refiner $(RUNS)/refiner --iterations 2
CMD_learned_it2_icp    := $(CMD_learned_it2) --icp
CMD_learned_it2_colour := $(CMD_learned_it2) --colour-verify
NEEDS_learned_it0  := $(RUNS)/pose/model.pt
$(foreach m,learned_it2 learned_it2_icp learned_it2_colour,$(eval NEEDS_$(m) := $(RUNS)/pose/model.pt $(RUNS)/refiner/model.pt))
CMD_dense          := predict-pose --pose $(RUNS)/pose_dense
CMD_dense_icp      := $(CMD_dense) --icp
CMD_dense_icp_verify := $(CMD_dense) --icp --verify
$(foreach m,dense dense_icp dense_icp_verify,$(eval NEEDS_$(m) := $(RUNS)/pose_dense/model.pt))
# mask arguments: GT masks count instances with >= 400 visible px (as evaluate does); predicted masks
# keep detections scoring >= 0.5. Predicted masks come from a segmenter's directory of masks per split:
# `pred` the profile's Mask R-CNN (runs/P/masks), `fast` the real-time segmenter (runs/P/masks_fast)
MASKDIR_pred := $(RUNS)/masks
MASKDIR_fast := $(RUNS)/masks_fast
ARGS_register_gt     := --masks gt --min-px 400 --workers $(WORKERS)
ARGS_register_pred   = --masks $(MASKDIR_$(2))/$(1) --score-thresh 0.5 --workers $(WORKERS)
ARGS_predict-pose_gt := --masks gt
ARGS_predict-pose_pred = --masks $(MASKDIR_$(2))/$(1) --score-thresh 0.5

# $(call pose_rule,split,masks,method): masks gt, pred or fast
define pose_rule
$(POSES)/$(1)_$(2)_$(3).csv: $(DATA_$(1))/manifest.json $(NEEDS_$(3)) $(if $(filter-out gt,$(2)),$(MASKDIR_$(2))/$(1)/meta.json) | $(VENV_OK)
	$(SIXDPOSE) $(CMD_$(3)) --data $(DATA_$(1)) $(if $(filter-out gt,$(2)),$(call ARGS_$(firstword $(CMD_$(3)))_pred,$(1),$(2)),$(ARGS_$(firstword $(CMD_$(3)))_gt)) $(_limit) --no-progress --out $$@

$(RES)/$(1)_$(2)_$(3).json: $(POSES)/$(1)_$(2)_$(3).csv $(DATA_$(1))/manifest.json | $(VENV_OK)
	$(SIXDPOSE) evaluate --data $(DATA_$(1)) --results $$< --no-bop --no-progress --all-images $(_limit) --label $(1)_$(2)_$(3) \
	  --result-name $(1)_$(2)_$(3) --results-dir $(RES)
endef
$(foreach s,$(SPLITS),$(foreach k,$(MASKS),$(foreach m,$(METHODS),$(eval $(call pose_rule,$(s),$(k),$(m))))))

# the dense head on the real-time segmenter's masks (profiles with SEG_FAST_$(PROFILE)): test_fast_<method>
ifneq ($(SEG_FAST_$(PROFILE)),)
FAST_METHODS := dense dense_icp
$(foreach m,$(FAST_METHODS),$(eval $(call pose_rule,test,fast,$(m))))
FAST_RESULTS := $(foreach m,$(FAST_METHODS),$(RES)/test_fast_$(m).json)
endif
# the dense head end to end (segmentation, then the pose stage, on the test split's first 40 frames, 3 passes;
# the real-time segmenter where the profile has one, else its Mask R-CNN): benchmarks/pose.py's figures as a
# result (the pose stage alone on GT masks and the training throughput beside them); cpu and paper (smoke and demo
# time nothing). A timing: run it alone
ifneq ($(filter cpu paper,$(PROFILE)),)
E2E_SEG := $(or $(FAST_SEG),seg)
E2E_DEVICE := $(if $(filter paper,$(PROFILE)),cuda,cpu)
E2E_RESULT := $(RES)/e2e_dense.json
$(E2E_RESULT): $(RUNS)/pose_dense/model.pt $(RUNS)/$(E2E_SEG)/model.pt $(DATA_test)/manifest.json | $(VENV_OK)
	$(PY) benchmarks/pose.py --pose $(RUNS)/pose_dense --seg $(RUNS)/$(E2E_SEG) --data $(DATA_test) --device $(E2E_DEVICE) \
	  --frames 40 --repeats 3 --steps 5 --result-name e2e_dense --results-dir $(RES)
endif

# ---- sensor noise (notebook 08): the multi-instance test split again with the `kinect` depth model -----
# (the same scenes and images; masks and poses exact), scored by the hybrid methods with ICP beside their
# ideal-depth rows test_gt_<method>
DATA_test_kinect := data/$(P_TEST_GEN)_kinect
$(DATA_test_kinect)/manifest.json: | $(VENV_OK)
	$(SIXDPOSE) generate --profile $(P_TEST_GEN) --set sensor=kinect --out $(@D) --workers $(WORKERS) --no-progress
KINECT_METHODS := $(filter ransac_icp super4pcs_icp,$(HYBRID))
$(foreach m,$(KINECT_METHODS),$(eval $(call pose_rule,test_kinect,gt,$(m))))
KINECT_RESULTS := $(foreach m,$(KINECT_METHODS),$(RES)/test_kinect_gt_$(m).json)

# the stages in the order of the plan (`make -n reproduce` lists them so)
STAGES = $(IMAGENET_WEIGHTS) $(foreach g,$(DATASETS),data/$(g)/manifest.json) $(DATA_test_kinect)/manifest.json \
	$(RUNS)/seg/model.pt $(RUNS)/pose/model.pt $(RUNS)/refiner/model.pt $(RUNS)/pose_dense/model.pt $(RUNS)/masks/test/meta.json $(RUNS)/masks/single/meta.json \
	$(RUNS)/seg/pred_test/meta.json $(FAST_STAGES) $(YCBV_STAGES)
# results of record: every split x masks x method, the kinect rows and the ablation
RESULTS := $(foreach s,$(SPLITS),$(foreach k,$(MASKS),$(foreach m,$(METHODS),$(RES)/$(s)_$(k)_$(m).json))) \
	$(KINECT_RESULTS) $(ABLATION_RESULT) $(ABLATION_SEEDS_RESULT) $(FAST_RESULTS) $(E2E_RESULT)

# ---- synthetic to real (notebook 09): networks trained only on generated YCB-Video data -----------
# YCBV_REAL (a BOP YCB-Video root, split YCBV_SPLIT) holds the real frames they are scored on, with the
# hybrid methods beside them; the sample's models carry no symmetry annotations, hence YCBV_SYMMETRIC
# (BOP's symmetric YCB-Video objects). To score other real frames, point YCBV_REAL/YCBV_SPLIT at them
# and give them a name of their own (YCBV_NAME), which prefixes their results CSVs and result files.
YCBV_REAL ?= ../shared/data/ycbv_sample
YCBV_SPLIT ?= train_real
YCBV_SYMMETRIC ?= 1,13,14,16,18,19,20,21
YCBV_NAME ?= ycbv
ifeq ($(P_YCBV),yes)
YCBV_DATASETS := ycbv ycbv_ideal
$(foreach g,$(YCBV_DATASETS),$(eval data/$(g)/manifest.json: | $(VENV_OK) ; \
	$(SIXDPOSE) generate --profile $(g) --out data/$(g) --workers $(WORKERS) --no-progress))
DATASETS += $(YCBV_DATASETS)
# run -> its training data and extra train-pose arguments: YCBV_POSE_$(PROFILE), or YCBV_POSE_LONG_$(PROFILE)
# for the pair trained twice as long (_e12, no refiners), plus colour jitter for the _jitter pair
YCBV_RUNS := pose_ycbv pose_ycbv_ideal pose_ycbv_jitter pose_ycbv_ideal_jitter pose_ycbv_e12 pose_ycbv_ideal_e12
# a graph target is a distinct network: where the "twice as long" arguments are the base ones (PROFILE=paper:
# the paper profile's own schedule both times) the _e12 pair would train the base networks again, so that pair
# and its rows are left out (YCBV_TRAINED, YCBV_SCORED: the runs and methods of this profile)
_E12_SAME := $(if $(filter-out $(strip $(YCBV_POSE_$(PROFILE))),$(strip $(YCBV_POSE_LONG_$(PROFILE))))$(filter-out \
	$(strip $(YCBV_POSE_LONG_$(PROFILE))),$(strip $(YCBV_POSE_$(PROFILE)))),,yes)
YCBV_TRAINED := $(if $(_E12_SAME),$(filter-out %_e12,$(YCBV_RUNS)),$(YCBV_RUNS))
$(foreach r,$(YCBV_RUNS),$(eval DATA_$(r) := data/$(if $(findstring ideal,$(r)),ycbv_ideal,ycbv)))
JITTER := --set colour_jitter=0.3
_ycbv_args = $(if $(findstring _e12,$(1)),$(YCBV_POSE_LONG_$(PROFILE)),$(YCBV_POSE_$(PROFILE))) $(if $(findstring jitter,$(1)),$(JITTER))
$(foreach r,$(YCBV_TRAINED),$(eval $(RUNS)/$(r)/model.pt: $(DATA_$(r))/manifest.json | $(VENV_OK) ; \
	$(SIXDPOSE) train-pose --data $(DATA_$(r)) --out $$(@D) --no-progress \
	  $$(if $$(wildcard $$(@D)/last.pt),--resume,$(call _ycbv_args,$(r)))))
# the refiners of the two networks without jitter (the paper's learned method is the network + 2 iterations)
$(foreach r,pose_ycbv pose_ycbv_ideal,$(eval $(RUNS)/$(subst pose,refiner,$(r))/model.pt: $(RUNS)/$(r)/model.pt \
	$(DATA_$(r))/manifest.json | $(VENV_OK) ; \
	$(SIXDPOSE) train-refiner --pose $(RUNS)/$(r) --data $(DATA_$(r)) --out $$(@D) --no-progress \
	  $$(if $$(wildcard $$(@D)/last.pt),--resume,$(YCBV_POSE_$(PROFILE)))))
# the dense head (the project's own method): trained once, on kinect depth, with the sim-to-real augmentation
$(RUNS)/pose_ycbv_dense/model.pt: data/ycbv/manifest.json | $(VENV_OK)
	$(SIXDPOSE) train-pose --data data/ycbv --out $(@D) --no-progress \
	  $(if $(wildcard $(@D)/config.json),--resume,$(YCBV_DENSE_$(PROFILE)))
# method -> command and the runs it needs
YCBV_CMD_learned              := predict-pose --pose $(RUNS)/pose_ycbv
YCBV_CMD_learned_it2          := predict-pose --pose $(RUNS)/pose_ycbv --refiner $(RUNS)/refiner_ycbv --iterations 2
YCBV_CMD_learned_icp          := predict-pose --pose $(RUNS)/pose_ycbv --icp
YCBV_CMD_learned_colour       := predict-pose --pose $(RUNS)/pose_ycbv --colour-verify
YCBV_CMD_learned_ideal        := predict-pose --pose $(RUNS)/pose_ycbv_ideal
YCBV_CMD_learned_ideal_it2    := predict-pose --pose $(RUNS)/pose_ycbv_ideal --refiner $(RUNS)/refiner_ycbv_ideal --iterations 2
YCBV_CMD_learned_ideal_icp    := predict-pose --pose $(RUNS)/pose_ycbv_ideal --icp
YCBV_CMD_learned_ideal_colour := predict-pose --pose $(RUNS)/pose_ycbv_ideal --colour-verify
YCBV_CMD_learned_e12          := predict-pose --pose $(RUNS)/pose_ycbv_e12
YCBV_CMD_learned_ideal_e12    := predict-pose --pose $(RUNS)/pose_ycbv_ideal_e12
YCBV_CMD_learned_jitter       := predict-pose --pose $(RUNS)/pose_ycbv_jitter
YCBV_CMD_learned_ideal_jitter := predict-pose --pose $(RUNS)/pose_ycbv_ideal_jitter
YCBV_CMD_ransac_icp           := register --method ransac --icp --no-verify --workers $(WORKERS) --min-px 0
YCBV_CMD_fgr_icp              := register --method fgr --icp --no-verify --workers $(WORKERS) --min-px 0
YCBV_CMD_super4pcs_icp        := register --method super4pcs --icp --no-verify --workers $(WORKERS) --min-px 0
YCBV_CMD_super4pcs_icp_verify := register --method super4pcs --icp --verify --workers $(WORKERS) --min-px 0
YCBV_CMD_dense                := predict-pose --pose $(RUNS)/pose_ycbv_dense
YCBV_CMD_dense_icp            := predict-pose --pose $(RUNS)/pose_ycbv_dense --icp
YCBV_CMD_dense_verify         := predict-pose --pose $(RUNS)/pose_ycbv_dense --verify
YCBV_CMD_dense_icp_verify     := predict-pose --pose $(RUNS)/pose_ycbv_dense --icp --verify
YCBV_METHODS := learned learned_it2 learned_icp learned_colour learned_ideal learned_ideal_it2 learned_ideal_icp \
	learned_ideal_colour learned_e12 learned_ideal_e12 learned_jitter learned_ideal_jitter dense dense_icp dense_verify \
	dense_icp_verify ransac_icp fgr_icp super4pcs_icp super4pcs_icp_verify
YCBV_SCORED := $(if $(_E12_SAME),$(filter-out %_e12,$(YCBV_METHODS)),$(YCBV_METHODS))
# the model.pt of every run a command names (--pose, --refiner)
_ycbv_needs = $(foreach w,$(filter $(RUNS)/%,$(YCBV_CMD_$(1))),$(w)/model.pt)
define ycbv_rule
$(POSES)/$(YCBV_NAME)_gt_$(1).csv: $(call _ycbv_needs,$(1)) | $(VENV_OK)
	$(SIXDPOSE) $(YCBV_CMD_$(1)) --data $(YCBV_REAL) --split $(YCBV_SPLIT) --masks gt --no-progress --out $$@

$(RES)/$(YCBV_NAME)_gt_$(1).json: $(POSES)/$(YCBV_NAME)_gt_$(1).csv | $(VENV_OK)
	$(SIXDPOSE) evaluate --data $(YCBV_REAL) --split $(YCBV_SPLIT) --symmetric-ids $(YCBV_SYMMETRIC) --min-px 0 \
	  --results $$< --no-progress --all-images --label $(YCBV_NAME)_gt_$(1) --result-name $(YCBV_NAME)_gt_$(1) --results-dir $(RES)
endef
$(foreach m,$(YCBV_SCORED),$(eval $(call ycbv_rule,$(m))))
YCBV_STAGES := $(foreach r,$(YCBV_TRAINED) refiner_ycbv refiner_ycbv_ideal pose_ycbv_dense,$(RUNS)/$(r)/model.pt)
YCBV_RESULTS := $(foreach m,$(YCBV_SCORED),$(RES)/$(YCBV_NAME)_gt_$(m).json)
NB09_ARGS := -p TRAIN_DATA ../data/ycbv -p POSE_RUN ../$(RUNS)/pose_ycbv -p REFINER_RUN ../$(RUNS)/refiner_ycbv \
	-p IDEAL_RUN ../$(RUNS)/pose_ycbv_ideal -p POSE_PROFILE $(P_POSE)
NB09_NEEDS := $(RUNS)/pose_ycbv/model.pt $(RUNS)/refiner_ycbv/model.pt $(RUNS)/pose_ycbv_ideal/model.pt
else
# without the branch (smoke, demo): notebook 09's pipeline check, the smoke network and its refiner trained on a
# tiny ycbv dataset (2 scenes x 3 views)
YCBV_SMALL := data/ycbv_$(PROFILE)
$(YCBV_SMALL)/manifest.json: | $(VENV_OK)
	$(SIXDPOSE) generate --profile ycbv --scenes 2 --views 3 --out $(@D) --workers $(WORKERS) --no-progress
$(RUNS)/pose_ycbv/model.pt: $(YCBV_SMALL)/manifest.json | $(VENV_OK)
	$(SIXDPOSE) train-pose --data $(YCBV_SMALL) --out $(@D) --no-progress $(if $(wildcard $(@D)/config.json),--resume,--profile $(P_POSE))
$(RUNS)/refiner_ycbv/model.pt: $(RUNS)/pose_ycbv/model.pt $(YCBV_SMALL)/manifest.json | $(VENV_OK)
	$(SIXDPOSE) train-refiner --pose $(RUNS)/pose_ycbv --data $(YCBV_SMALL) --out $(@D) --no-progress \
	  $(if $(wildcard $(@D)/config.json),--resume,--profile $(P_POSE))
YCBV_STAGES := $(YCBV_SMALL)/manifest.json $(RUNS)/pose_ycbv/model.pt $(RUNS)/refiner_ycbv/model.pt
NB09_ARGS := -p TRAIN_DATA ../$(YCBV_SMALL) -p POSE_RUN ../$(RUNS)/pose_ycbv -p REFINER_RUN ../$(RUNS)/refiner_ycbv \
	-p POSE_PROFILE $(P_POSE)
NB09_NEEDS := $(RUNS)/pose_ycbv/model.pt $(RUNS)/refiner_ycbv/model.pt
endif

# ---- LM-O (Table I): only with LMO=/path/to/lmo (a full BOP LM-O with depth and masks) ----------
ifneq ($(strip $(LMO)),)
DATA_lmo := $(LMO)
$(RUNS)/lmo_seg/model.pt: | $(VENV_OK) $(IMAGENET_WEIGHTS)
	$(SIXDPOSE) train-seg --data $(LMO) --train-split $(LMO_TRAIN_SPLIT) --test-split $(LMO_SPLIT) --out $(@D) \
	  --no-progress $(if $(wildcard $(@D)/config.json),--resume,--profile $(P_SEG))
$(RUNS)/masks/lmo/meta.json: $(RUNS)/lmo_seg/model.pt
	$(SIXDPOSE) segment --data $(LMO) --split $(LMO_SPLIT) --seg $(RUNS)/lmo_seg --out $(@D) --no-progress

define lmo_rule
$(POSES)/lmo_$(1)_$(2).csv: $(if $(filter pred,$(1)),$(RUNS)/masks/lmo/meta.json) | $(VENV_OK)
	$(SIXDPOSE) $(CMD_$(2)) --data $(LMO) --split $(LMO_SPLIT) $(if $(filter pred,$(1)),$(call ARGS_register_pred,lmo),$(ARGS_register_gt)) $(_limit) --no-progress --out $$@

$(RES)/lmo_$(1)_$(2).json: $(POSES)/lmo_$(1)_$(2).csv | $(VENV_OK)
	$(SIXDPOSE) evaluate --data $(LMO) --split $(LMO_SPLIT) --results $$< --no-progress --all-images $(_limit) --label lmo_$(1)_$(2) \
	  --result-name lmo_$(1)_$(2) --results-dir $(RES)
endef
$(foreach k,$(MASKS),$(foreach m,$(HYBRID),$(eval $(call lmo_rule,$(k),$(m)))))
RESULTS += $(foreach k,$(MASKS),$(foreach m,$(HYBRID),$(RES)/lmo_$(k)_$(m).json))
endif

# ---- what the write-up reads: the graph's results, or the result files as they are -------------
# `make reproduce` (and demo, smoke) recomputes: notebook 07 and the PDF wait for every result target of the
# graph and for notebook 02 (Fig. 2, Fig. 3, the dataset statistics). Any other goal (`make tables`, `make
# paper`, `make fig2`) reads the files that are here (the committed results/cpu on a fresh clone) and runs no
# stage: they are named by their absolute paths (on_disk), which no rule of the graph makes, so make only
# compares their times. RECOMPUTE=yes makes those goals recompute as reproduce does.
RECOMPUTE ?= $(if $(filter reproduce demo smoke,$(MAKECMDGOALS)),yes)
override RECOMPUTE := $(filter yes,$(RECOMPUTE))
on_disk = $(abspath $(wildcard $(1)))
ifeq ($(RECOMPUTE),yes)
WRITEUP_RESULTS = $(RESULTS) $(YCBV_RESULTS)
WRITEUP_NB02 = $(EXEC)/02_dataset_overview.ipynb
WRITEUP_FIGS :=
else
WRITEUP_RESULTS = $(call on_disk,$(RES)/*.json)
WRITEUP_NB02 = $(call on_disk,$(FIG)/dataset_statistics.csv)
WRITEUP_FIGS = $(call on_disk,$(addprefix $(FIG)/,fig2_lmo_vs_ours.png fig3_random_images.png fig7.png))
endif

# ---- notebooks, executed on top of those files -----------------------------------------------
# papermill writes the executed copy beside its target and moves it into place when every cell ran,
# so a failed notebook leaves no target behind
define papermill
	@mkdir -p $(EXEC) $(FIG)
	$(PAPERMILL) $(1) $(EXEC)/.$(notdir $(1)).tmp.ipynb $(2) && mv $(EXEC)/.$(notdir $(1)).tmp.ipynb $(EXEC)/$(notdir $(1))
endef
NB_FIG := -p FIGURES ../$(FIG)

$(EXEC)/01_generate_dataset.ipynb: notebooks/01_generate_dataset.ipynb $(TRAIN_DIR)/manifest.json | $(VENV_OK)
	$(call papermill,$<,-p PROFILE $(P_TRAIN_GEN) -p DATA ../$(TRAIN_DIR) $(NB_FIG) -p WORKERS $(WORKERS))

# notebook 02 also draws Fig. 2 (figures/P/fig2_lmo_vs_ours.png): LM-O frames of LMO_FRAMES (a BOP LM-O root,
# its test split; LMO when given, else the sample in ../shared/data/lmo) beside the training data's
LMO_FRAMES ?= $(or $(LMO),../shared/data/lmo)
$(EXEC)/02_dataset_overview.ipynb: notebooks/02_dataset_overview.ipynb $(TRAIN_DIR)/manifest.json | $(VENV_OK)
	$(call papermill,$<,-p PROFILE $(P_TRAIN_GEN) -p DATA ../$(TRAIN_DIR) -p LMO $(abspath $(LMO_FRAMES)) $(NB_FIG))

# Fig. 2 alone (`make fig2 PROFILE=demo`): the same figure without the rest of notebook 02, from the training
# data that is here (RECOMPUTE=yes generates it first where it is not)
FIG2 := $(FIG)/fig2_lmo_vs_ours.png
$(FIG2): $(if $(RECOMPUTE),$(TRAIN_DIR)/manifest.json,$(call on_disk,$(TRAIN_DIR)/manifest.json)) | $(VENV_OK)
	@test -f $(TRAIN_DIR)/manifest.json || { echo "make fig2: $(TRAIN_DIR) is not here;" \
	  "make fig2 PROFILE=$(PROFILE) RECOMPUTE=yes generates it first" >&2; exit 2; }
	$(PY) -m sixdpose.reporting.fig2 --lmo $(LMO_FRAMES) --ours $(TRAIN_DIR) --out $@

$(EXEC)/03_train_segmentation.ipynb: notebooks/03_train_segmentation.ipynb $(RUNS)/seg/model.pt $(RUNS)/seg/pred_test/meta.json \
	| $(VENV_OK)
	$(call papermill,$<,-p PROFILE $(PROFILE) -p DATA ../$(TRAIN_DIR) -p RUN_DIR ../$(RUNS)/seg $(NB_FIG))

# notebook 04 compares the hybrid methods itself on a few training-data images (the masks segment predicted
# on the seg run's held-out images); Tables II and III come from the graph's results (notebook 07)
$(EXEC)/04_hybrid_registration.ipynb: notebooks/04_hybrid_registration.ipynb $(TRAIN_DIR)/manifest.json \
	$(RUNS)/seg/pred_test/meta.json | $(VENV_OK)
	$(call papermill,$<,-p PROFILE $(P_TRAIN_GEN) -p DATA ../$(TRAIN_DIR) -p PRED_DIR ../$(RUNS)/seg/pred_test \
	  -p MAX_IMAGES $(P_NB04) -p WORKERS $(WORKERS) $(NB_FIG))

$(EXEC)/05_train_pose_network.ipynb: notebooks/05_train_pose_network.ipynb $(RUNS)/pose/model.pt $(RUNS)/pose_dense/model.pt \
	$(DATA_test)/manifest.json $(ABLATION_RESULT) $(ABLATION_SEEDS_RESULT) | $(VENV_OK)
	$(call papermill,$<,-p PROFILE $(PROFILE) -p DATA ../$(TRAIN_DIR) -p TEST_DATA ../$(DATA_test) -p RUN_DIR ../$(RUNS)/pose \
	  -p DENSE_RUN ../$(RUNS)/pose_dense \
	  -p POSE_PROFILE $(P_POSE) -p RESULTS ../$(RES) $(NB_FIG))

$(EXEC)/06_train_refiner.ipynb: notebooks/06_train_refiner.ipynb $(RUNS)/refiner/model.pt $(RUNS)/pose_dense/model.pt \
	$(DATA_test)/manifest.json | $(VENV_OK)
	$(call papermill,$<,-p PROFILE $(PROFILE) -p DATA ../$(TRAIN_DIR) -p TEST_DATA ../$(DATA_test) -p POSE_RUN ../$(RUNS)/pose \
	  -p RUN_DIR ../$(RUNS)/refiner -p DENSE_RUN ../$(RUNS)/pose_dense -p REFINER_PROFILE $(P_POSE) $(NB_FIG))

# notebook 08: the hybrid methods on the real frames of YCBV_REAL, and the sensor-noise rows (results/P/
# test_gt_<m> beside test_kinect_gt_<m>)
$(EXEC)/08_real_data.ipynb: notebooks/08_real_data.ipynb $(KINECT_RESULTS) $(KINECT_METHODS:%=$(RES)/test_gt_%.json) | $(VENV_OK)
	$(call papermill,$<,-p PROFILE $(PROFILE) -p WORKERS $(WORKERS) -p RESULTS ../$(RES) -p SENSOR_METHODS "$(KINECT_METHODS)" \
	  $(NB_FIG))

# notebook 07 reads results/P/ only (and, for Fig. 7, the results CSV and dataset a result names; the dataset
# statistics of notebook 02). Besides TEX_OUT and FIG_OUT it writes the charts of the tables
# (sixdpose.reporting.charts: table3.png, table2_fps.png, per_object_<split>_<masks>.png, real_frames.png,
# real_threshold.png, ablation.png, where there are results) and fig7.png where its inputs are here.
TEX_OUT := $(addprefix $(GEN)/,macros.tex table1.tex table2.tex table2_e2e.tex table3.tex claims.tex table_dataset.tex table_real.tex table_ablation.tex table_ablation_seeds.tex \
	$(foreach s,$(SPLITS),$(foreach k,$(MASKS),per_object_$(s)_$(k).tex)))
FIG_OUT := $(addprefix $(FIG)/,accuracy_threshold.png table1.csv table2.csv table2_e2e.csv table3.csv claims.csv)
# precious: a failed run of notebook 07 (which writes each file atomically) leaves the tables as they were
# (.DELETE_ON_ERROR would delete them, the committed ones of cpu too)
.PRECIOUS: $(TEX_OUT) $(FIG_OUT)
$(EXEC)/07_evaluation.ipynb $(TEX_OUT) $(FIG_OUT) &: notebooks/07_evaluation.ipynb $(WRITEUP_RESULTS) $(WRITEUP_NB02) \
	| $(VENV_OK)
	$(if $(RECOMPUTE)$(WRITEUP_RESULTS),,@echo "make tables: $(RES) holds no result file; make reproduce PROFILE=$(PROFILE)" \
	  "(or make tables PROFILE=$(PROFILE) RECOMPUTE=yes) computes them" >&2; exit 2)
	$(call papermill,$<,-p PROFILE $(PROFILE) -p RESULTS ../$(RES) -p TEX ../$(GEN) -p TRAIN_DATA ../$(TRAIN_DIR) $(NB_FIG))

# notebook 09: the synthetic-to-real networks of the YCBV branch (or, without it, the smoke network and refiner of data/ycbv_$(PROFILE))
$(EXEC)/09_synthetic_to_real.ipynb: notebooks/09_synthetic_to_real.ipynb $(NB09_NEEDS) | $(VENV_OK)
	$(call papermill,$<,-p PROFILE $(PROFILE) -p WORKERS $(WORKERS) -p BOP_DATA $(abspath $(YCBV_REAL)) \
	  -p BOP_SPLIT $(YCBV_SPLIT) $(NB09_ARGS) $(NB_FIG))

NOTEBOOKS := $(addprefix $(EXEC)/,01_generate_dataset.ipynb 02_dataset_overview.ipynb 03_train_segmentation.ipynb \
	04_hybrid_registration.ipynb 05_train_pose_network.ipynb 06_train_refiner.ipynb 07_evaluation.ipynb 08_real_data.ipynb \
	09_synthetic_to_real.ipynb)

# ---- the write-up ----------------------------------------------------------------------------
# paper/build/P/paper.pdf per profile; paper/paper.pdf is a copy of the last one built
PAPER_SRC := $(wildcard paper/*.tex paper/*.bib)
LATEXMK := latexmk
# LaTeX is there, or WITH_LATEX=1 installs it before any target runs (order-only $(APT_STAMP))
HAVE_LATEX := $(if $(WITH_LATEX),yes,$(shell command -v $(LATEXMK) >/dev/null 2>&1 && command -v pdflatex >/dev/null 2>&1 && echo yes))
# a figure of the write-up that is not in figures/P/ (drawn from a dataset that is not here) is a placeholder
# in the PDF saying what makes it (sixdpose.reporting.writeup, in paper/build/P/missing/)
# The PDF's dates (CreationDate, ModDate, /ID) are fixed (SOURCE_DATE_EPOCH; the write-up's own date is the
# results' dates, \val{dates}), so the same inputs give the same bytes: PROFILE=cpu also writes the committed
# copy paper/sixdpose-cpu.pdf, which `make paper PROFILE=cpu` on a fresh clone rewrites unchanged.
PDF_EPOCH := 1764547200
PDF_COPY := $(if $(filter cpu,$(PROFILE)),paper/sixdpose-cpu.pdf)
$(PDF_DIR)/paper.pdf paper/paper.pdf $(PDF_COPY) &: $(PAPER_SRC) $(EXEC)/07_evaluation.ipynb $(TEX_OUT) $(FIG_OUT) \
	$(WRITEUP_NB02) $(WRITEUP_FIGS) | $(VENV_OK)
	@mkdir -p $(PDF_DIR)
	$(PY) -m sixdpose.reporting.writeup --profile $(PROFILE) --figures $(FIG) --out $(PDF_DIR)/missing
	cd paper && SOURCE_DATE_EPOCH=$(PDF_EPOCH) TEXINPUTS=generated/$(PROFILE)//:../$(FIG)//:build/$(PROFILE)/missing//: \
	  $(LATEXMK) -pdf -interaction=nonstopmode -halt-on-error \
	  -quiet -outdir=build/$(PROFILE) paper.tex >build/$(PROFILE)/latexmk.log 2>&1 \
	  || { tail -40 build/$(PROFILE)/latexmk.log; exit 1; }
	@touch $(PDF_DIR)/paper.pdf  # latexmk leaves the PDF alone when its inputs' contents did not change
	cp $(PDF_DIR)/paper.pdf paper/.paper.pdf.tmp && mv paper/.paper.pdf.tmp paper/paper.pdf
	$(if $(PDF_COPY),cmp -s $(PDF_DIR)/paper.pdf $(PDF_COPY) || { cp $(PDF_DIR)/paper.pdf paper/.copy.pdf.tmp && mv paper/.copy.pdf.tmp $(PDF_COPY); })

PDF := $(if $(HAVE_LATEX),$(PDF_DIR)/paper.pdf)
