# sixdpose: make targets are the dependency graph of the project.
#   make setup      system packages (as root) + .venv from uv.lock
#   make test       everything CI runs: unit/integration tests + every notebook on the smoke profile
#   make test-fast  the edit loop: tests without Drake generation or slow training (under 2 minutes)
#   make demo       the whole chain at a small scale on a laptop CPU (data/demo, figures/)
#   make reproduce  the paper-scale run (GPU machine): 25,000 images, all notebooks
#   make benchmark  the benchmark scripts (print their figures, write them to results/)
#   make results-readme  rewrite the README's generated tables from results/ (results-check: only compare)

SHELL := /bin/bash
PYTHON_SYS ?= python3
UV := $(PYTHON_SYS) -m uv
VENV := .venv
PY := $(VENV)/bin/python
APT_PKGS := libegl1 libgl1-mesa-dri libgbm1 libglib2.0-0 libusb-1.0-0
SIXDPOSE_YCB ?= $(abspath ../shared/data/ycb)
export SIXDPOSE_YCB
WORKERS ?= 2
PAPERMILL := $(PY) -m papermill --cwd notebooks --log-output --no-progress-bar

.PHONY: setup apt venv test test-fast notebooks-sync demo reproduce benchmark results-readme results-check clean-data

setup: apt venv

apt:
	@if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	  missing=$$(for p in $(APT_PKGS); do dpkg -s $$p >/dev/null 2>&1 || echo $$p; done); \
	  if [ -n "$$missing" ]; then echo "installing: $$missing"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq $$missing >/dev/null; fi; \
	else echo "not root: make sure these Debian packages are installed: $(APT_PKGS)"; fi

venv: $(VENV)/.synced

$(VENV)/.synced: pyproject.toml uv.lock
	@$(UV) --version >/dev/null 2>&1 || $(PYTHON_SYS) -m pip install -q uv
	$(UV) sync --frozen --python 3.11 --extra test
	@touch $@

test: setup
	$(PY) -m pytest -p no:dash -q tests
	SIXDPOSE_PROFILE=smoke $(PY) -m pytest -p no:dash -q --nbval-lax notebooks

test-fast: setup
	$(PY) -m pytest -p no:dash -q -m "not slow and not drake" tests

# notebooks/NN_*.py (jupytext percent format) are the sources; the .ipynb twins are written from them
notebooks-sync: setup
	@for f in notebooks/[0-9]*.py; do $(VENV)/bin/jupytext --quiet --to ipynb --update "$$f"; done

demo: setup
	mkdir -p notebooks/executed figures
	$(PAPERMILL) notebooks/01_generate_dataset.ipynb notebooks/executed/01_generate_dataset.ipynb -p PROFILE demo -p WORKERS $(WORKERS)
	@for nb in notebooks/[0-9]*.ipynb; do case $$nb in *01_generate_dataset*) continue;; esac; \
	  $(PAPERMILL) $$nb notebooks/executed/$$(basename $$nb) -p PROFILE demo || exit 1; done

reproduce: setup
	mkdir -p notebooks/executed figures
	@for nb in notebooks/[0-9]*.ipynb; do \
	  $(PAPERMILL) $$nb notebooks/executed/$$(basename $$nb) -p PROFILE paper -p WORKERS $(WORKERS) || exit 1; done

BENCHMARKS := generation segmentation registration colour_robustness

benchmark: setup
	@for b in $(BENCHMARKS); do echo "== benchmarks/$$b.py"; $(PY) benchmarks/$$b.py || exit 1; done

# README blocks between <!-- results:NAME --> markers are generated from results/*.json (sixdpose.artifacts.readme)
results-readme: setup
	$(PY) -m sixdpose.artifacts.readme --readme README.md --results results

results-check: setup
	$(PY) -m sixdpose.artifacts.readme --readme README.md --results results --check
