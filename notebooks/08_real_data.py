# %% [markdown]
# # 08 · Real data: YCB-Video frames and simulated depth sensors
#
# The hybrid methods on real Kinect frames (`../shared/data/ycbv_sample`, BOP format, or any BOP dataset
# given as `BOP_DATA`), with the textured BOP models so the colour step runs: per method ADD(-S) with the
# BOP symmetric ids, ADD-S for every object, the BOP 2019 average recall and the YCB-Video ADD-S AUC; a
# figure of estimated poses over the real images; and what sensor noise costs on synthetic data (the same
# split generated with the ideal depth and with the `kinect` sensor model): the results make wrote
# (`results/<profile>/test_gt_<method>.json` beside `test_kinect_gt_<method>.json`).

# %% tags=["parameters"]
# Parameters: plain values only (papermill overrides them). None means "from the environment / the profile",
# resolved in the next cell: PROFILE from $SIXDPOSE_PROFILE (the CI / headless switch, default "smoke").
PROFILE = None  # smoke (CI), demo (laptop CPU), paper (GPU machine)
BOP_DATA = None  # None: $SIXDPOSE_BOP, else ../../shared/data/ycbv_sample
BOP_SPLIT = "train_real"
SYMMETRIC_IDS = [1, 13, 14, 16, 18, 19, 20, 21]  # BOP YCB-Video symmetric objects (the sample has no annotations)
FIGURES = "../figures"
MAX_IMAGES = None  # real frames per method; None: smoke 4, demo 5, paper all
RESULTS = None  # result artifacts of the graph; None: ../results/<PROFILE>
SENSOR_METHODS = "ransac_icp super4pcs_icp"  # methods of the sensor-noise rows (make passes its profile's)
WORKERS = 2

# %%
import os

PROFILE = PROFILE or os.environ.get("SIXDPOSE_PROFILE", "smoke")
BOP_DATA = BOP_DATA or os.environ.get("SIXDPOSE_BOP") or "../../shared/data/ycbv_sample"
MAX_IMAGES = MAX_IMAGES or {"smoke": 4, "demo": 5}.get(PROFILE)
RESULTS = RESULTS or f"../results/{PROFILE}"
from pathlib import Path

import matplotlib.pyplot as plt

from sixdpose.artifacts.results import read_result
from sixdpose.artifacts.tables import write_table
from sixdpose.datasets import open_dataset
from sixdpose.evaluation.visualize import plot_cases
from sixdpose.graph import require
from sixdpose.reporting.compare import compare_methods, hybrid_methods

figures = Path(FIGURES)
figures.mkdir(parents=True, exist_ok=True)

# %% [markdown]
# ## Real frames
#
# Ground-truth masks; target instances of every visibility. `add_s` is ADD(-S) with the BOP symmetric
# ids, `ADD-S (all)` treats every object as symmetric (how well the surface was fitted), `ar` is the BOP
# average recall (objects flagged symmetric without an annotation are scored with the identity only in
# MSSD/MSPD), `adds_auc` the YCB-Video ADD-S AUC.

# %%
real = open_dataset(BOP_DATA, split=BOP_SPLIT, symmetric_ids=SYMMETRIC_IDS)
every_symmetric = open_dataset(BOP_DATA, split=BOP_SPLIT, symmetric_ids=list(real.object_ids))
methods = hybrid_methods(workers=WORKERS, icp=(True,))
# the best of them with the hypothesis verification stage (`register --verify`: render, compare depth, mask and
# texture, keep the best; the colour step's successor)
methods.update(hybrid_methods(workers=WORKERS, methods=("super4pcs",), icp=(True,), verify=(True,)))
table, runs = compare_methods(real, methods, {"gt": ("gt", list(range(len(real)))[:MAX_IMAGES])}, min_px=0, bop=True,
                              also=[("ADD-S (all)", every_symmetric)])
write_table(table, ["method", "add_s", "ADD-S (all)", "ar", "adds_auc", "instances_per_s"], figures / "real_ycbv.csv",
            figures / "real_ycbv.tex", headers=["Method", "ADD(-S)", "ADD-S", "AR", "ADD-S AUC", "Instances/s"])
table[["method", "add_s", "ADD-S (all)", "ar", "ar_vsd", "ar_mssd", "ar_mspd", "adds_auc", "instances_per_s"]]

# %% [markdown]
# Per object, the best method:

# %%
best = max(runs, key=lambda k: runs[k].result.accuracy)
res = runs[best].result
per_object = [{"obj_id": o, "name": v["name"], "n_gt": v["n_gt"], "add_s": v["accuracy"], "ar": v["bop"]["ar"],
               "adds_auc": v["bop"]["adds_auc"]} for o, v in res.per_object.items()]
write_table(per_object, ["obj_id", "name", "n_gt", "add_s", "ar", "adds_auc"], figures / "real_ycbv_per_object.csv")
best[1], per_object

# %%
fig = plot_cases(
    real, res, n_good=3, n_bad=3, ncols=3, title=f"{best[1]} on real Kinect frames: GT (green) vs estimate (red)"
)
fig.savefig(figures / "real_ycbv_poses.png", dpi=120)
plt.show()

# %% [markdown]
# ## What sensor noise costs (synthetic data)
#
# The same generator profile twice: ideal depth (the paper's) and the `kinect` structured-light model
# (Gaussian pixel shift, disparity quantised to 1/8 px, holes at depth discontinuities, Nguyen et al.
# 2012 axial noise). Masks and poses are exact in both. The graph's test split and its `kinect` twin
# (`data/<test>_kinect`, `sixdpose generate --set sensor=kinect`), every image, GT masks, instances with
# >= 400 visible px: `sixdpose register` + `sixdpose evaluate` write the results read here.

# %%
rows = []
for method in SENSOR_METHODS.split():
    for label, name in (("ideal", f"test_gt_{method}"), ("kinect", f"test_kinect_gt_{method}")):
        path = require(Path(RESULTS, f"{name}.json"), f"the result {name}", PROFILE)
        f = read_result(path).figures
        rows.append({"sensor": label, "method": method, "add_s": f["accuracy"], "n_gt": f["n_gt"],
                     "instances_per_s": f["instances_per_s"]})
write_table(rows, ["sensor", "method", "add_s", "n_gt", "instances_per_s"], figures / "sensor_noise.csv",
            figures / "sensor_noise.tex", headers=["Depth", "Method", "ADD(-S)", "GT instances", "Instances/s"])
rows  # noqa: B018 (the cell's displayed value)
