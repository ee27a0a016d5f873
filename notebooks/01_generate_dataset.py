# %% [markdown]
# # 01 · Generate the synthetic dataset (paper section III)
#
# Drake drops 5-20 target and 5-10 noise YCB objects on a table (some beyond its edge), simulates the physics until everything rests, and renders 20 RGB-D views along a random camera arc. The output follows the paper's layout (section III-C); see `sixdpose.datasets.synthetic`.

# %% tags=["parameters"]
# Parameters: plain values only (papermill overrides them). None means "from the environment / the profile",
# resolved in the next cell: PROFILE from $SIXDPOSE_PROFILE (the CI / headless switch, default "smoke").
PROFILE = None  # a generator profile: smoke (CI), demo (laptop CPU), train / test / test_single (the cpu graph), paper (GPU machine, 25,000 images)
DATA = None  # None: $SIXDPOSE_DATA, else ../data/<PROFILE>
FIGURES = "../figures"
SCENES = None  # None: the profile's number of scenes
VIEWS = None
SEED = None  # None: the profile's seed
WORKERS = 2

# %%
import os

PROFILE = PROFILE or os.environ.get("SIXDPOSE_PROFILE", "smoke")
DATA = DATA or os.environ.get("SIXDPOSE_DATA") or f"../data/{PROFILE}"
from pathlib import Path

import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt

from sixdpose.datasets import open_dataset
from sixdpose.datasets.viz import plot_views
from sixdpose.generation import generate, profile

Path(FIGURES).mkdir(parents=True, exist_ok=True)

# %% [markdown]
# Generate (or finish an interrupted run: completed scenes are kept).

# %%
cfg = profile(PROFILE, scenes=SCENES, views=VIEWS, seed=SEED)
summary = generate(DATA, cfg, workers=WORKERS)
print({k: v for k, v in summary.items() if k != "manifest"})
assert not summary["scenes_failed"], summary["scenes_failed"]

# %% [markdown]
# One scene's views with the target instance masks (noise objects carry no annotation).

# %%
ds = open_dataset(DATA)
scene = ds.keys()[0][0]
keys = [k for k in ds.keys() if k[0] == scene][:6]
fig = plot_views([ds.load(k) for k in keys], ncols=3, title=f"scene {scene}")
fig.savefig(f"{FIGURES}/scene_views.png", dpi=100)
plt.show()
