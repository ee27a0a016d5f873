# %% [markdown]
# # 09 · Synthetic to real: the learned network trained on generated YCB-Video data
#
# The paper closes (section VI) on what users ask first: training on their own objects and running on
# real frames. Here the generator's `ycbv` profile (the 19 textured YCB-Video BOP models as targets, so
# the ground truth is in YCB-Video's model frames and obj_ids; the YCB-Video camera; the `kinect`
# depth-sensor model) provides the only training data of the learned pose network, which then runs on
# real Kinect frames (`../shared/data/ycbv_sample`, or any BOP YCB-Video split given as `BOP_DATA`),
# next to the hybrid methods on the same frames. With `IDEAL_RUN`, the same network trained on the
# ideal-depth twin of the data stands beside it (what the sensor model buys).
#
# Command line: `sixdpose generate --profile ycbv`, `sixdpose train-pose --profile cpu`,
# `sixdpose predict-pose --data BOP_ROOT --split train_real`, `sixdpose evaluate --symmetric-ids ...`.
# `make` generates the data and trains the networks (mk/reproduce.mk, the synthetic-to-real branch); the
# notebook trains nothing: a missing dataset or run stops it with the make target that writes it.

# %% tags=["parameters"]
# Parameters: plain values only (papermill overrides them). None means "from the environment / the profile",
# resolved in the next cell: PROFILE from $SIXDPOSE_PROFILE (the CI / headless switch, default "smoke").
PROFILE = None  # smoke (CI), demo (laptop CPU), cpu (this machine, about an hour), paper (GPU)
TRAIN_DATA = None  # generated ycbv data; None: ../data/ycbv (cpu, paper), else a tiny ../data/ycbv_<PROFILE>
POSE_RUN = None  # None: ../runs/<PROFILE>/pose_ycbv
REFINER_RUN = None  # None: ../runs/<PROFILE>/refiner_ycbv (trained on POSE_RUN's network)
POSE_PROFILE = None  # the networks' profile, for the titles; None: smoke for smoke/demo, else PROFILE
IDEAL_RUN = None  # the same network trained on the ideal-depth twin (../data/ycbv_ideal), scored beside it if trained
BOP_DATA = None  # real frames; None: $SIXDPOSE_BOP, else ../../shared/data/ycbv_sample
BOP_SPLIT = "train_real"
SYMMETRIC_IDS = [1, 13, 14, 16, 18, 19, 20, 21]  # BOP YCB-Video symmetric objects (the sample has no annotations)
MAX_IMAGES = None  # real frames scored; None: smoke 4, demo 8, else all
FIGURES = "../figures"
WORKERS = 2

# %%
import os

PROFILE = PROFILE or os.environ.get("SIXDPOSE_PROFILE", "smoke")
SMALL = PROFILE in ("smoke", "demo")
TRAIN_DATA = TRAIN_DATA or ("../data/ycbv" if not SMALL else f"../data/ycbv_{PROFILE}")
POSE_RUN = POSE_RUN or f"../runs/{PROFILE}/pose_ycbv"
REFINER_RUN = REFINER_RUN or f"../runs/{PROFILE}/refiner_ycbv"
POSE_PROFILE = POSE_PROFILE or ("smoke" if SMALL else PROFILE)
IDEAL_RUN = IDEAL_RUN or (None if SMALL else f"../runs/{PROFILE}/pose_ycbv_ideal")
BOP_DATA = BOP_DATA or os.environ.get("SIXDPOSE_BOP") or "../../shared/data/ycbv_sample"
MAX_IMAGES = MAX_IMAGES or {"smoke": 4, "demo": 8}.get(PROFILE)
from pathlib import Path

import matplotlib.pyplot as plt

from sixdpose.artifacts.tables import write_table
from sixdpose.datasets import open_dataset
from sixdpose.evaluation.visualize import plot_cases
from sixdpose.graph import require_dataset, require_run
from sixdpose.pose.plots import plot_training
from sixdpose.reporting.compare import compare_methods, hybrid_methods, learned_method, per_object_table

figures = Path(FIGURES)
figures.mkdir(parents=True, exist_ok=True)

# %% [markdown]
# ## Training data and network
#
# `smoke`/`demo`: a tiny `ycbv` dataset (2 scenes x 3 views) and the smoke network, a pipeline check
# whose accuracy means nothing. `cpu`: the full `ycbv` profile (60 scenes x 20 views, `kinect` depth), the
# `cpu` pose network and its refiner for 6 epochs each (the `make reproduce PROFILE=cpu` graph trains them,
# the ideal-depth twins and the networks with colour jitter; mk/profiles.mk, `YCBV_POSE_cpu`).

# %%
require_dataset(TRAIN_DATA, PROFILE)
require_run(POSE_RUN, PROFILE, "the pose network trained on ycbv data")
require_run(REFINER_RUN, PROFILE, "its refiner")
plot_training(
    POSE_RUN,
    out=figures / f"pose_ycbv_training_{PROFILE}.png",
    title=f"pose network on generated ycbv data ({POSE_PROFILE})",
)
plt.show()

# %% [markdown]
# ## Real frames: learned and hybrid methods
#
# Ground-truth masks, target instances of every visibility, ADD(-S) at 10 % of the diameter with the BOP
# symmetric ids; `ADD-S (all)` treats every object as symmetric (how well the surface was fitted), `ar`
# is the BOP average recall, `adds_auc` the YCB-Video ADD-S AUC. `+ ICP` and `+ colour verification`
# add the hybrid stage's ICP or colour search after the network.

# %%
real = open_dataset(BOP_DATA, split=BOP_SPLIT, symmetric_ids=SYMMETRIC_IDS)
every_symmetric = open_dataset(BOP_DATA, split=BOP_SPLIT, symmetric_ids=list(real.object_ids))
methods = {"learned (ycbv, kinect depth)": learned_method(POSE_RUN),
           "learned + 2 refinement it.": learned_method(POSE_RUN, refiner=REFINER_RUN, iterations=2),
           "learned + ICP": learned_method(POSE_RUN, icp=True),
           "learned + colour verification": learned_method(POSE_RUN, colour_verify=True)}
if IDEAL_RUN and Path(IDEAL_RUN, "model.pt").is_file():
    # the same network trained on ideal depth, with the same stages after it (the sensor model's pairs)
    methods["learned, ideal-depth training data"] = learned_method(IDEAL_RUN)
    methods["learned + ICP, ideal-depth training data"] = learned_method(IDEAL_RUN, icp=True)
    methods["learned + colour verification, ideal-depth training data"] = learned_method(IDEAL_RUN, colour_verify=True)
methods.update(hybrid_methods(workers=WORKERS, methods=("ransac", "super4pcs"), icp=(True,)))
table, runs = compare_methods(real, methods, {"gt": ("gt", list(range(len(real)))[:MAX_IMAGES])}, min_px=0, bop=True,
                              also=[("ADD-S (all)", every_symmetric)])
write_table(
    table,
    ["method", "add_s", "ADD-S (all)", "ar", "adds_auc", "fps"],
    figures / f"synthetic_to_real_{PROFILE}.csv",
    figures / f"synthetic_to_real_{PROFILE}.tex",
    headers=["Method", "ADD(-S)", "ADD-S", "AR", "ADD-S AUC", "FPS"],
)
table[["method", "add_s", "ADD-S (all)", "ar", "adds_auc", "n_gt", "fps"]]

# %% [markdown]
# Per object (ADD(-S) %):

# %%
per_object = per_object_table(runs)
write_table(per_object, list(per_object.columns), figures / f"synthetic_to_real_per_object_{PROFILE}.csv")
per_object  # noqa: B018 (the cell's displayed value)

# %%
fig = plot_cases(
    real,
    runs[("gt", "learned (ycbv, kinect depth)")].result,
    n_good=3,
    n_bad=3,
    ncols=3,
    title="learned network trained on generated ycbv data, real Kinect frames: GT (green) vs estimate (red)",
)
fig.savefig(figures / f"synthetic_to_real_poses_{PROFILE}.png", dpi=120)
plt.show()
