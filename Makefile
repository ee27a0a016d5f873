# sixdpose: make targets are the dependency graph of the project.
#   make setup      system packages (as root) + .venv from uv.lock; WITH_LATEX=1 adds LaTeX (for `make paper`)
#   make test       everything CI runs: unit/integration tests, then the smoke graph (every notebook on the smoke profile)
#   make lint       ruff check (clean) and the mypy error count (tools/mypy_baseline.txt, may not grow)
#   make test-fast  the edit loop: tests without Drake generation or slow training (under 2 minutes)
#   make demo       the whole graph at laptop scale (= make reproduce PROFILE=demo): every table, figure, the PDF
#   make reproduce  the graph of mk/reproduce.mk for PROFILE (paper by default: GPU machine, 25,000 images);
#                   files keyed by their inputs, so an interrupted run resumes; `make -n reproduce` prints the plan
#   make ycbv       PROFILE=cpu|paper: only the synthetic-to-real branch (networks trained on generated
#                   YCB-Video data, scored on YCBV_REAL's real frames)
#   make tables     the write-up's tables, macros and charts of PROFILE from the result files that are here
#                   (paper/generated/PROFILE, figures/PROFILE); runs no stage (RECOMPUTE=yes: the graph first)
#   make paper      the same, then the write-up PDF when LaTeX is installed (paper/build/PROFILE/paper.pdf, copied
#                   to paper/paper.pdf); `make paper PROFILE=cpu` builds it from the committed results/cpu
#   make fig2       Fig. 2 of PROFILE alone (figures/PROFILE/fig2_lmo_vs_ours.png: LM-O frames beside the training
#                   data's), from the training data that is here (RECOMPUTE=yes generates it)
#   make nbval      the executed notebooks with a reference (notebooks/reference/PROFILE/) run again under
#                   pytest --nbval-lax: their `# NBVAL_CHECK_OUTPUT` cells must print what the reference holds
#   make nbval-reference  record PROFILE's references from notebooks/executed/PROFILE/
#   make benchmark  the benchmark scripts (print their figures, write them to results/)
#   make results-readme  rewrite the generated tables of README.md and docs/*.md from results/ (results-check:
#                   only compare)
#   make lab        JupyterLab on notebooks/ (the NN_*.py sources open as notebooks); LAB_ARGS="--port 8890 ..."

SHELL := /bin/bash
PYTHON_SYS ?= python3
UV := $(PYTHON_SYS) -m uv
VENV := .venv
PY := $(VENV)/bin/python
APT_PKGS := libegl1 libgl1-mesa-dri libgbm1 libglib2.0-0 libusb-1.0-0
LATEX_PKGS := latexmk texlive-latex-recommended texlive-latex-extra texlive-fonts-recommended lmodern poppler-utils
WITH_LATEX ?=
APT_STAMP := $(VENV)/.apt$(if $(WITH_LATEX),-latex)
SIXDPOSE_YCB ?= $(abspath ../shared/data/ycb)
export SIXDPOSE_YCB
WORKERS ?= 2
PAPERMILL := $(PY) -m papermill --cwd notebooks --log-output --no-progress-bar

# the profile of the graph: `make demo` is PROFILE=demo, `make smoke` PROFILE=smoke, anything else paper
_GOAL_PROFILE := $(filter demo smoke,$(MAKECMDGOALS))
ifneq ($(_GOAL_PROFILE),)
ifeq ($(origin PROFILE),command line)
$(if $(filter-out $(_GOAL_PROFILE),$(PROFILE)),$(error make $(_GOAL_PROFILE) is PROFILE=$(_GOAL_PROFILE); run make reproduce PROFILE=$(PROFILE) instead))
endif
override PROFILE := $(firstword $(_GOAL_PROFILE))
endif
PROFILE ?= paper
include mk/profiles.mk
include mk/reproduce.mk

.PHONY: setup apt venv lint test test-pytest test-smoke test-fast notebooks-sync demo smoke reproduce evaluations ycbv paper tables fig2 benchmark \
	results-readme results-check nbval nbval-reference lab
.DELETE_ON_ERROR:

setup: apt venv

# LaTeX packages without their recommendations (documentation, fonts the write-up does not use)
apt:
	@if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	  missing=$$(for p in $(APT_PKGS); do dpkg -s $$p >/dev/null 2>&1 || echo $$p; done); \
	  latex=$$(for p in $(if $(WITH_LATEX),$(LATEX_PKGS)); do dpkg -s $$p >/dev/null 2>&1 || echo $$p; done); \
	  if [ -n "$$missing$$latex" ]; then echo "installing:" $$missing $$latex; apt-get update -qq || exit 1; fi; \
	  if [ -n "$$missing" ]; then DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing >/dev/null || exit 1; fi; \
	  if [ -n "$$latex" ]; then DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends $$latex >/dev/null || exit 1; fi; \
	else echo "not root: make sure these Debian packages are installed: $(APT_PKGS) $(if $(WITH_LATEX),$(LATEX_PKGS))"; fi

# the graph's file targets wait for the set-up (order-only prerequisites: it never makes them out of date);
# WITH_LATEX=1 has its own stamp, so `make demo WITH_LATEX=1` installs LaTeX once even after a plain set-up
$(APT_STAMP): | $(VENV)/.synced
	@$(MAKE) --no-print-directory apt
	@touch $@

venv: $(VENV)/.synced

$(VENV)/.synced: pyproject.toml uv.lock
	@$(UV) --version >/dev/null 2>&1 || $(PYTHON_SYS) -m pip install -q uv
	$(UV) sync --frozen --python 3.11 --extra test --compile-bytecode
	@touch $@

# CI: the tests beside the smoke graph (every notebook executed by papermill on the smoke profile, on
# top of the smoke graph's datasets, runs and results), then the cpu write-up's tables from the committed
# results (notebook 07, no stage), then nbval on the executed notebooks that have a reference
test: setup lint
	$(MAKE) --no-print-directory -j2 -Oline test-pytest test-smoke
	$(MAKE) --no-print-directory tables PROFILE=cpu
	$(MAKE) --no-print-directory nbval

# make test's two long parts, side by side (-j2): each keeps about one core busy (a CI run used 40 min of CPU
# in 41 min of wall time on 2 cores, run one after the other); once the tests end, the smoke graph takes both
# slots of the jobserver and runs two of its stages at a time
test-pytest: setup
	$(PY) -m pytest -p no:dash -q tests

test-smoke: setup
	$(MAKE) --no-print-directory smoke

# ruff (rules in pyproject.toml) must be clean; mypy's error count may not grow past tools/mypy_baseline.txt
lint: setup
	$(VENV)/bin/ruff check .
	$(PY) tools/mypy_gate.py

test-fast: setup
	$(PY) -m pytest -p no:dash -q -m "not slow and not drake" tests

# notebooks/NN_*.py (jupytext percent format) are the sources; the .ipynb twins are written from them
notebooks-sync: setup
	@for f in notebooks/[0-9]*.py; do $(VENV)/bin/jupytext --quiet --to ipynb --update "$$f"; done

# the reader's workbench: JupyterLab with the repository as its root, opened on notebooks/; jupytext's contents
# manager opens the NN_*.py sources as notebooks (saving one writes the .py; `make notebooks-sync` updates the
# .ipynb twins). As root (a container) --allow-root. LAB_ARGS: more jupyter-lab options (--port 8890, --no-browser,
# --IdentityProvider.token=...)
LAB_ARGS ?=
lab: setup
	$(VENV)/bin/jupyter lab --ServerApp.root_dir=. --LabApp.default_url=/lab/tree/notebooks \
	  --ServerApp.contents_manager_class=jupytext.AsyncTextFileContentsManager \
	  $$([ "$$(id -u)" = 0 ] && echo --allow-root) $(LAB_ARGS)

# the graph (mk/reproduce.mk): every result, table, figure and executed notebook of PROFILE, and the PDF
# when LaTeX is installed
reproduce: $(STAGES) $(RESULTS) $(YCBV_RESULTS) $(NOTEBOOKS) $(PDF) | $(VENV_OK)
ifeq ($(HAVE_LATEX),)
ifneq ($(filter demo smoke reproduce paper,$(MAKECMDGOALS)),)
$(info paper PDF skipped: latexmk/pdflatex not found (install them with `make setup WITH_LATEX=1`))
endif
endif
demo smoke: reproduce

# the graph up to the result files (results/PROFILE/*.json), without notebooks and write-up
evaluations: $(STAGES) $(RESULTS) $(YCBV_RESULTS)

# the synthetic-to-real branch alone (PROFILE=cpu or paper): the ycbv datasets, their networks and their
# results on the real frames of YCBV_REAL (results/PROFILE/$(YCBV_NAME)_gt_*.json)
ycbv: $(YCBV_RESULTS)
ifneq ($(filter ycbv,$(MAKECMDGOALS)),)
ifneq ($(P_YCBV),yes)
$(error make ycbv needs PROFILE=cpu or PROFILE=paper (PROFILE=$(PROFILE) has no synthetic-to-real branch))
endif
endif

# the tables, macros and figures of notebook 07 (Tables I-III, per object, accuracy vs threshold, the charts;
# Fig. 7 where its dataset is here): from the result files that are here unless RECOMPUTE=yes (mk/reproduce.mk)
# (the executed notebook is a target too: on a fresh clone, where it is not, notebook 07 runs once)
tables: $(EXEC)/07_evaluation.ipynb $(TEX_OUT) $(FIG_OUT)

fig2: $(FIG2)

paper: tables $(if $(HAVE_LATEX),$(PDF_DIR)/paper.pdf)

# nbval (sixdpose.reporting.nbcheck): runs after the notebooks were executed (make test: the smoke graph and
# `make tables PROFILE=cpu`); the notebooks it runs are written to build/nbval/
nbval: setup
	$(PY) -m sixdpose.reporting.nbcheck check --reference notebooks/reference --executed notebooks/executed --out build/nbval

nbval-reference: setup
	$(PY) -m sixdpose.reporting.nbcheck record --executed $(EXEC) --out notebooks/reference/$(PROFILE)

BENCHMARKS := generation segmentation registration colour_robustness

benchmark: setup
	@for b in $(BENCHMARKS); do echo "== benchmarks/$$b.py"; $(PY) benchmarks/$$b.py || exit 1; done

# blocks between <!-- results:NAME --> markers in README.md and docs/*.md are generated from results/*.json
# (sixdpose.reporting.readme)
results-readme: setup
	$(PY) -m sixdpose.reporting.readme --readme README.md $(wildcard docs/*.md) --results results

results-check: setup
	$(PY) -m sixdpose.reporting.readme --readme README.md $(wildcard docs/*.md) --results results --check
