# %% [markdown]
# # 06 · Iterative refinement (paper section IV-C.5)
#
# Shows the refiner `make` trained on the main network of notebook 05 (`sixdpose train-refiner`; its poses
# perturbed during training: rotation N(0, 15 deg) about a random axis, translation N(0, 2 cm) per axis),
# then measures ADD(-S) against the number of refinement iterations (0-4; the paper uses 2) and shows
# refined poses over the images. Command line: `sixdpose predict-pose --refiner RUN --iterations K`. The
# notebook trains nothing: a missing run stops it with the make target that trains it.

# %% tags=["parameters"]
# Parameters: plain values only (papermill overrides them). None means "from the environment / the profile",
# resolved in the next cell: PROFILE from $SIXDPOSE_PROFILE (the CI / headless switch, default "smoke").
PROFILE = None  # smoke (CI), demo (laptop CPU), cpu (2 h on a 2-core CPU: train / test splits), paper (GPU)
DATA = None  # training data; None: $SIXDPOSE_DATA, else ../data/<PROFILE> (cpu: ../data/train)
TEST_DATA = None  # held-out data; None: the training data's images (smoke, demo: a pipeline check), else ../data/test
POSE_RUN = None  # None: ../runs/<PROFILE>/pose (notebook 05)
RUN_DIR = None  # None: ../runs/<PROFILE>/refiner
DENSE_RUN = None  # None: ../runs/<PROFILE>/pose_dense (the dense head of notebook 05)
# the refiner's profile, for the titles; None: the refiner profile of the same name (smoke for demo)
REFINER_PROFILE = None
TEST_IMAGES = None  # images predicted; None: smoke 4, demo 4, else all
MAX_ITERATIONS = 4
FIGURES = "../figures"

# %%
import os

from sixdpose.graph import training_data

PROFILE = PROFILE or os.environ.get("SIXDPOSE_PROFILE", "smoke")
SMALL = PROFILE in ("smoke", "demo")
DATA, TEST_DATA = training_data(PROFILE, DATA, TEST_DATA)
POSE_RUN = POSE_RUN or f"../runs/{PROFILE}/pose"
RUN_DIR = RUN_DIR or f"../runs/{PROFILE}/refiner"
DENSE_RUN = DENSE_RUN or f"../runs/{PROFILE}/pose_dense"
REFINER_PROFILE = REFINER_PROFILE or ("smoke" if SMALL else PROFILE)
TEST_IMAGES = TEST_IMAGES or {"smoke": 4, "demo": 4}.get(PROFILE, 0)
from pathlib import Path

import matplotlib.pyplot as plt
import pandas as pd

from sixdpose.artifacts.tables import write_table
from sixdpose.datasets import open_dataset
from sixdpose.evaluation.evaluate import evaluate
from sixdpose.evaluation.visualize import plot_cases
from sixdpose.graph import require_dataset, require_run
from sixdpose.pose.infer import predict_dataset
from sixdpose.pose.plots import plot_iterations, plot_training

require_dataset(TEST_DATA, PROFILE)  # seed 300: never trained or tuned on
require_run(POSE_RUN, PROFILE, "the pose network (notebook 05)")
require_run(RUN_DIR, PROFILE, "the refiner")
require_run(DENSE_RUN, PROFILE, "the dense head (notebook 05)")
figures = Path(FIGURES)
figures.mkdir(parents=True, exist_ok=True)

# %%
plot_training(RUN_DIR, out=figures / f"refiner_training_{PROFILE}.png", title=f"refiner ({REFINER_PROFILE} profile)")
plt.show()

# %% [markdown]
# ## Accuracy against refinement iterations

# %%
test = open_dataset(TEST_DATA)
results = {
    k: evaluate(test, predict_dataset(test, POSE_RUN, refiner=RUN_DIR, iterations=k, limit=TEST_IMAGES)[0], min_px=400)
    for k in range(MAX_ITERATIONS + 1)
}
table = pd.DataFrame([{"iterations": k, "add_s": r.accuracy, "n_gt": r.n_gt, "fps": r.fps} for k, r in results.items()])
write_table(
    table,
    ["iterations", "add_s", "n_gt", "fps"],
    figures / f"refiner_iterations_{PROFILE}.csv",
    figures / f"refiner_iterations_{PROFILE}.tex",
    headers=["Iterations", "ADD(-S) (\\%)", "GT instances", "FPS"],
)
plot_iterations(table, out=figures / f"refiner_iterations_{PROFILE}.png")
plt.show()
table  # noqa: B018 (the cell's displayed value)

# %% [markdown]
# ## Fig. 7 with two refinement iterations

# %%
fig = plot_cases(
    test, results[min(2, MAX_ITERATIONS)], n_good=3, n_bad=3, ncols=3, title="learned pose + 2 refinement iterations"
)
fig.savefig(figures / f"fig7_refined_{PROFILE}.png", dpi=120)
plt.show()

# %% [markdown]
# ## The dense head refined by ICP, beside the learned refiner
#
# The dense head (notebook 05) has no learned refiner: its pose comes from a robust fit of per-point
# correspondences, and point-to-plane ICP on the masked cloud (`predict-pose --icp`) refines it. The rows
# below put the dense head alone and with ICP beside the paper's network with 0 and 2 refinement
# iterations, on the same held-out images (the graph's `dense` and `dense_icp` rows of Tables I-III).

# %%
dense = {icp: evaluate(test, predict_dataset(test, DENSE_RUN, icp=icp, limit=TEST_IMAGES)[0], min_px=400)
         for icp in (False, True)}
compare = pd.DataFrame([
    {"method": "paper network, 0 iterations", "add_s": results[0].accuracy, "fps": results[0].fps},
    {"method": f"paper network + refiner, {min(2, MAX_ITERATIONS)} iterations",
     "add_s": results[min(2, MAX_ITERATIONS)].accuracy, "fps": results[min(2, MAX_ITERATIONS)].fps},
    {"method": "dense head", "add_s": dense[False].accuracy, "fps": dense[False].fps},
    {"method": "dense head + ICP", "add_s": dense[True].accuracy, "fps": dense[True].fps},
])
write_table(compare, ["method", "add_s", "fps"], figures / f"dense_refinement_{PROFILE}.csv",
            headers=["Method", "ADD(-S) (\\%)", "FPS"])
compare  # noqa: B018 (the cell's displayed value)
