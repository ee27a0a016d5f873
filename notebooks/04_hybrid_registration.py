# %% [markdown]
# # 04 · Hybrid registration (paper section IV-B, Tables II and III)
#
# Every hybrid method (RANSAC, FGR, Super4PCS; with and without ICP) on the test split, with ground-truth
# masks and with the masks notebook 03 predicted on its held-out images (`PRED_DIR`). The loop lives in
# `sixdpose.reporting.compare.compare_methods`; the methods in `sixdpose.registration`.

# %% tags=["parameters"]
# Parameters: plain values only (papermill overrides them). None means "from the environment / the profile",
# resolved in the next cell: PROFILE from $SIXDPOSE_PROFILE (the CI / headless switch, default "smoke").
PROFILE = None  # smoke (CI), demo (laptop CPU), paper (GPU machine, 25,000 images)
DATA = None  # None: $SIXDPOSE_DATA, else ../data/<PROFILE>
FIGURES = "../figures"
# predicted masks shown in notebook 03; "auto": ../runs/<PROFILE>/seg/pred_test if it exists; None: GT only
PRED_DIR = "auto"
SPLIT = "test"
PRESET = "default"
MAX_IMAGES = None  # images registered per method; None: smoke 3 (< 2 min), demo 6, paper all
WORKERS = 2

# %%
import os

PROFILE = PROFILE or os.environ.get("SIXDPOSE_PROFILE", "smoke")
DATA = DATA or os.environ.get("SIXDPOSE_DATA") or f"../data/{PROFILE}"
if PRED_DIR == "auto":
    PRED_DIR = f"../runs/{PROFILE}/seg/pred_test"
MAX_IMAGES = MAX_IMAGES or {"smoke": 3, "demo": 6}.get(PROFILE)
# the `make reproduce` profile whose graph generates the generator profile PROFILE
GRAPH_PROFILE = {"train": "cpu", "test": "cpu", "test_single": "cpu", "val": "cpu"}.get(PROFILE, PROFILE)
from pathlib import Path

import matplotlib.pyplot as plt

from sixdpose.artifacts.predictions import list_predictions
from sixdpose.artifacts.tables import write_table
from sixdpose.datasets import open_dataset
from sixdpose.evaluation.visualize import plot_cases
from sixdpose.graph import require_dataset
from sixdpose.registration import get_preset
from sixdpose.reporting.compare import compare_methods, hybrid_methods

require_dataset(DATA, GRAPH_PROFILE)
ds = open_dataset(DATA, split=SPLIT)
figures = Path(FIGURES)
figures.mkdir(parents=True, exist_ok=True)
keys = ds.keys()

# %% [markdown]
# Mask sources: GT masks on the first `MAX_IMAGES` images; predicted masks on the images notebook 03 held
# out and segmented (every such image is evaluated, detections or not).

# %%
mask_sources = {"gt": ("gt", list(range(len(ds)))[:MAX_IMAGES])}
if PRED_DIR and Path(PRED_DIR).is_dir():
    predicted = set(list_predictions(PRED_DIR))
    pred_idx = [i for i, k in enumerate(keys) if k in predicted][:MAX_IMAGES]
    if pred_idx:
        mask_sources["pred"] = (PRED_DIR, pred_idx)
{k: (v[0], len(v[1])) for k, v in mask_sources.items()}

# %% [markdown]
# The six methods of the paper's tables, then the best of them (Super4PCS + ICP) with the hypothesis
# verification stage (`register --verify`, new, not in the paper: several hypotheses per instance, each
# rendered and scored against the frame's depth, mask and texture; `sixdpose.registration.hypotheses`).

# %%
methods = hybrid_methods(get_preset(PRESET), workers=WORKERS)
methods.update(hybrid_methods(get_preset(PRESET), workers=WORKERS, methods=("super4pcs",), icp=(True,), verify=(True,)))
table, runs = compare_methods(ds, methods, mask_sources)
table  # noqa: B018 (the cell's displayed value)

# %%
write_table(table, ["masks", "method", "fps", "instances_per_s"], figures / "table2_hybrid_fps.csv",
            figures / "table2_hybrid_fps.tex", headers=["Masks", "Method", "FPS", "Instances/s"])
write_table(table, ["masks", "method", "add_s", "n_gt"], figures / "table3_hybrid_adds.csv",
            figures / "table3_hybrid_adds.tex", headers=["Masks", "Method", "ADD(-S) (\\%)", "GT instances"])
print((figures / "table3_hybrid_adds.tex").read_text())

# %% [markdown]
# Estimated poses over the image for the best GT-mask method: good cases (first row) and failures.

# %%
best = max((k for k in runs if k[0] == "gt"), key=lambda k: runs[k].result.accuracy)
fig = plot_cases(ds, runs[best].result, n_good=3, n_bad=3, ncols=3, title=f"{best[1]}: GT (green) vs estimate (red)")
fig.savefig(figures / "hybrid_poses.png", dpi=150)
plt.show()
