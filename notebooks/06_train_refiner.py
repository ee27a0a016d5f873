# %% [markdown]
# # 06 · Iterative refinement (paper section IV-C.5)
#
# Trains the refiner on the main network of notebook 05 (its poses perturbed during training: rotation
# N(0, 15 deg) about a random axis, translation N(0, 2 cm) per axis), then measures ADD(-S) against the
# number of refinement iterations (0-4; the paper uses 2) and shows refined poses over the images. Command
# line: `sixdpose train-refiner`, `sixdpose predict-pose --refiner RUN --iterations K`.

# %% tags=["parameters"]
# Parameters: plain values only (papermill overrides them). None means "from the environment / the profile",
# resolved in the next cell: PROFILE from $SIXDPOSE_PROFILE (the CI / headless switch, default "smoke").
PROFILE = None  # smoke (CI), demo (laptop CPU), paper (GPU machine)
DATA = None  # training data; None: $SIXDPOSE_DATA, else ../data/<PROFILE>
TEST_DATA = None  # held-out data; None: the training data's images (smoke, demo: a pipeline check)
POSE_RUN = None  # None: ../runs/pose_<PROFILE> (notebook 05)
RUN_DIR = None  # None: ../runs/refiner_<PROFILE>
REFINER_PROFILE = None  # None: "paper" at paper scale, else "smoke"
TEST_IMAGES = None  # images predicted; None: smoke 4, demo 4, paper all
MAX_ITERATIONS = 4
FIGURES = "../figures"

# %%
import os

PROFILE = PROFILE or os.environ.get("SIXDPOSE_PROFILE", "smoke")
DATA = DATA or os.environ.get("SIXDPOSE_DATA") or f"../data/{PROFILE}"
TEST_DATA = TEST_DATA or DATA
POSE_RUN = POSE_RUN or f"../runs/pose_{PROFILE}"
RUN_DIR = RUN_DIR or f"../runs/refiner_{PROFILE}"
REFINER_PROFILE = REFINER_PROFILE or ("paper" if PROFILE == "paper" else "smoke")
TEST_IMAGES = TEST_IMAGES or {"smoke": 4, "demo": 4}.get(PROFILE, 0)
from pathlib import Path

import matplotlib.pyplot as plt
import pandas as pd

from sixdpose.artifacts.tables import write_table
from sixdpose.datasets import open_dataset
from sixdpose.evaluation.evaluate import evaluate
from sixdpose.evaluation.visualize import plot_cases
from sixdpose.generation import ensure_dataset
from sixdpose.pose.infer import predict_dataset
from sixdpose.pose.plots import plot_iterations, plot_training
from sixdpose.pose.train import ensure_trained

ensure_dataset(DATA, profile=PROFILE)
pose_profile = "paper" if PROFILE == "paper" else "smoke"
ensure_trained("pose", DATA, POSE_RUN, profile=pose_profile)  # notebook 05's run (trained here if missing)
figures = Path(FIGURES)
figures.mkdir(parents=True, exist_ok=True)

# %%
summary = ensure_trained("refiner", DATA, RUN_DIR, profile=REFINER_PROFILE, pose_run=POSE_RUN)
plot_training(RUN_DIR, out=figures / f"refiner_training_{PROFILE}.png", title=f"refiner ({REFINER_PROFILE} profile)")
plt.show()

# %% [markdown]
# ## Accuracy against refinement iterations

# %%
test = open_dataset(TEST_DATA)
results = {k: evaluate(test, predict_dataset(test, POSE_RUN, refiner=RUN_DIR, iterations=k, limit=TEST_IMAGES)[0], min_px=400)
           for k in range(MAX_ITERATIONS + 1)}
table = pd.DataFrame([{"iterations": k, "add_s": r.accuracy, "n_gt": r.n_gt, "fps": r.fps} for k, r in results.items()])
write_table(table, ["iterations", "add_s", "n_gt", "fps"], figures / f"refiner_iterations_{PROFILE}.csv",
            figures / f"refiner_iterations_{PROFILE}.tex", headers=["Iterations", "ADD(-S) (\\%)", "GT instances", "FPS"])
plot_iterations(table, out=figures / f"refiner_iterations_{PROFILE}.png")
plt.show()
table

# %% [markdown]
# ## Fig. 7 with two refinement iterations

# %%
fig = plot_cases(test, results[min(2, MAX_ITERATIONS)], n_good=3, n_bad=3, ncols=3, title="learned pose + 2 refinement iterations")
fig.savefig(figures / f"fig7_refined_{PROFILE}.png", dpi=120)
plt.show()
