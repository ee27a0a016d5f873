# %% [markdown]
# # 08 · Real data: YCB-Video frames and simulated depth sensors
#
# The hybrid methods on real Kinect frames (`../shared/data/ycbv_sample`, BOP format, or any BOP dataset
# given as `BOP_DATA`), with the textured BOP models so the colour step runs: per method ADD(-S) with the
# BOP symmetric ids, ADD-S for every object, the BOP 2019 average recall and the YCB-Video ADD-S AUC; a
# figure of estimated poses over the real images; and what sensor noise costs on synthetic data (the same
# split generated with the ideal depth and with the `kinect` sensor model).

# %% tags=["parameters"]
# Parameters: plain values only (papermill overrides them). None means "from the environment / the profile",
# resolved in the next cell: PROFILE from $SIXDPOSE_PROFILE (the CI / headless switch, default "smoke").
PROFILE = None  # smoke (CI), demo (laptop CPU), paper (GPU machine)
BOP_DATA = None  # None: $SIXDPOSE_BOP, else ../../shared/data/ycbv_sample
BOP_SPLIT = "train_real"
SYMMETRIC_IDS = [1, 13, 14, 16, 18, 19, 20, 21]  # BOP YCB-Video symmetric objects (the sample has no annotations)
FIGURES = "../figures"
MAX_IMAGES = None  # real frames per method; None: smoke 4, demo 5, paper all
SYN_PROFILE = None  # generator profile of the ideal-vs-kinect comparison; None: smoke, demo as PROFILE, else test
SYN_IMAGES = None  # synthetic images per method (from the first scenes); None: smoke 2, demo 4, paper all
WORKERS = 2

# %%
import os

PROFILE = PROFILE or os.environ.get("SIXDPOSE_PROFILE", "smoke")
BOP_DATA = BOP_DATA or os.environ.get("SIXDPOSE_BOP") or "../../shared/data/ycbv_sample"
MAX_IMAGES = MAX_IMAGES or {"smoke": 4, "demo": 5}.get(PROFILE)
SYN_PROFILE = SYN_PROFILE or (PROFILE if PROFILE in ("smoke", "demo") else "test")
SYN_IMAGES = SYN_IMAGES or {"smoke": 2, "demo": 4}.get(PROFILE)
from pathlib import Path

import matplotlib.pyplot as plt

from sixdpose.artifacts.tables import write_table
from sixdpose.datasets import open_dataset
from sixdpose.evaluation.visualize import plot_cases
from sixdpose.generation import ensure_dataset
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
fig = plot_cases(real, res, n_good=3, n_bad=3, ncols=3, title=f"{best[1]} on real Kinect frames: GT (green) vs estimate (red)")
fig.savefig(figures / "real_ycbv_poses.png", dpi=120)
plt.show()

# %% [markdown]
# ## What sensor noise costs (synthetic data)
#
# The same generator profile twice: ideal depth (the paper's) and the `kinect` structured-light model
# (Gaussian pixel shift, disparity quantised to 1/8 px, holes at depth discontinuities, Nguyen et al.
# 2012 axial noise). Masks and poses are exact in both.

# %%
ideal = ensure_dataset(f"../data/{SYN_PROFILE}", profile=SYN_PROFILE, workers=WORKERS)
# the kinect twin needs only the scenes that hold the compared images (scenes are drawn from (seed, scene))
views = open_dataset(ideal).manifest["config"]["views"]
scenes = -(-SYN_IMAGES // views) if SYN_IMAGES else None
kinect = ensure_dataset(f"../data/{SYN_PROFILE}_kinect" + (f"_{scenes}scenes" if scenes else ""), profile=SYN_PROFILE,
                        workers=WORKERS, sensor="kinect", scenes=scenes)
rows = []
for label, path in (("ideal", ideal), ("kinect", kinect)):
    t, _ = compare_methods(path, hybrid_methods(workers=WORKERS, methods=("ransac", "super4pcs"), icp=(True,)),
                           {"gt": ("gt", list(range(len(open_dataset(path))))[:SYN_IMAGES])})
    rows += [dict(r, sensor=label) for r in t.to_dict("records")]
write_table(rows, ["sensor", "method", "add_s", "n_gt", "instances_per_s"], figures / "sensor_noise.csv",
            figures / "sensor_noise.tex", headers=["Depth", "Method", "ADD(-S)", "GT instances", "Instances/s"])
rows
