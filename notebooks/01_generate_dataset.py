# %% [markdown]
# # 01 · Generate the synthetic dataset (paper section III)
#
# Drake drops 5-20 target and 5-10 noise YCB objects on a table (some beyond its edge), simulates the physics until
# everything rests, and renders 20 RGB-D views along a random camera arc. The output follows the paper's layout
# (section III-C); see `sixdpose.datasets.synthetic`.
#
# `make` generates the dataset (`sixdpose generate --profile PROFILE --out DATA`, one rule per generator
# profile of the graph; an interrupted run resumes, completed scenes are kept); this notebook shows it. A
# missing dataset stops it with the make target that writes it.

# %% tags=["parameters"]
# Parameters: plain values only (papermill overrides them). None means "from the environment / the profile",
# resolved in the next cell: PROFILE from $SIXDPOSE_PROFILE (the CI / headless switch, default "smoke").
# a generator profile: smoke (CI), demo (laptop CPU), train / test / test_single (the cpu graph),
# paper (GPU machine, 25,000 images)
PROFILE = None
DATA = None  # None: $SIXDPOSE_DATA, else ../data/<PROFILE>
FIGURES = "../figures"
WORKERS = 2  # unused (the generator's workers are make's WORKERS)

# %%
import os

PROFILE = PROFILE or os.environ.get("SIXDPOSE_PROFILE", "smoke")
DATA = DATA or os.environ.get("SIXDPOSE_DATA") or f"../data/{PROFILE}"
# the `make reproduce` profile whose graph generates the generator profile PROFILE
GRAPH_PROFILE = {"train": "cpu", "test": "cpu", "test_single": "cpu", "val": "cpu"}.get(PROFILE, PROFILE)
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from sixdpose.datasets import open_dataset
from sixdpose.datasets.viz import plot_views
from sixdpose.graph import require_dataset

Path(FIGURES).mkdir(parents=True, exist_ok=True)

# %% [markdown]
# The dataset's manifest (written last by `sixdpose generate`: the config, the images, the objects).

# %%
require_dataset(DATA, GRAPH_PROFILE)
manifest = json.loads(Path(DATA, "manifest.json").read_text())
{k: v for k, v in manifest.items() if k != "config"}

# %% [markdown]
# One scene's views with the target instance masks (noise objects carry no annotation).

# %%
ds = open_dataset(DATA)
scene = ds.keys()[0][0]
keys = [k for k in ds.keys() if k[0] == scene][:6]  # noqa: SIM118 (a dataset reader's keys(), not a dict)
fig = plot_views([ds.load(k) for k in keys], ncols=3, title=f"scene {scene}")
fig.savefig(f"{FIGURES}/scene_views.png", dpi=100)
plt.show()

# %% [markdown]
# What CI compares (`make nbval`, `notebooks/reference/<profile>/`): the dataset's counts, which a generation
# with the same profile and seed reproduces exactly.

# %%
# NBVAL_CHECK_OUTPUT
print(f"{manifest.get('num_images')} images (seed {manifest.get('seed')}), {len(ds.keys())} read back")
