# %% [markdown]
# # 03 · Instance segmentation with Mask R-CNN (paper §II-B, §IV-A)
#
# Shows the run of torchvision's Mask R-CNN (ResNet-FPN backbone) that `make` trained on the dataset's
# target objects (`sixdpose train-seg`) and the masks it predicted on its held-out images (`sixdpose segment
# --subset test`, `RUN_DIR/pred_test`): the loss curve, predicted masks next to the ground truth, and the
# COCO mask/box AP table (`sixdpose eval-seg`). The notebook trains and predicts nothing: a missing run or
# prediction directory stops it with the make target that writes it (`make reproduce PROFILE=...` makes all).
#
# * `PROFILE = "smoke"` (default): small images and backbone, a few minutes on a CPU (CI).
# * `PROFILE = "cpu"`: the smoke network at 320 px for 2 epochs on `sixdpose generate --profile train`
#   (about 30 min on a 2-core CPU); its masks feed the predicted-mask rows of notebooks 05 and 07.
# * `PROFILE = "paper"`: section IV-A (ResNet-50-FPN, ImageNet init when cached, Adam 1e-3, /10 every 30
#   epochs, 100 epochs, random 90/10 split) — a GPU job; multi-GPU with
#   `torchrun --nproc_per_node N -m sixdpose.cli train-seg --profile paper ...`.

# %% tags=["parameters"]
# Parameters: plain values only (papermill overrides them). None means "from the environment / the profile",
# resolved in the next cell: PROFILE from $SIXDPOSE_PROFILE (the CI / headless switch, default "smoke").
PROFILE = None  # smoke (CI), demo (laptop CPU), cpu (2-core CPU, the train split), paper (GPU machine, 25,000 images)
DATA = None  # None: $SIXDPOSE_DATA, else ../data/<PROFILE> (cpu: ../data/train)
FIGURES = "../figures"
RUN_DIR = None  # None: ../runs/<PROFILE>/seg (the graph's run)

# %%
import os

PROFILE = PROFILE or os.environ.get("SIXDPOSE_PROFILE", "smoke")
GEN_PROFILE = {"cpu": "train"}.get(PROFILE, PROFILE)  # generator profile of the data
DATA = DATA or os.environ.get("SIXDPOSE_DATA") or f"../data/{GEN_PROFILE}"
RUN_DIR = RUN_DIR or f"../runs/{PROFILE}/seg"
import json

import matplotlib.pyplot as plt

from sixdpose.graph import require, require_dataset, require_run
from sixdpose.segmentation.config import SegConfig
from sixdpose.segmentation.evaluate import evaluate
from sixdpose.segmentation.plots import ap_table_text, plot_loss, plot_predictions

require_dataset(DATA, PROFILE)
require_run(RUN_DIR, PROFILE, "the Mask R-CNN run")
PRED = f"{RUN_DIR}/pred_test"
require(f"{PRED}/meta.json", "the predicted masks of the run's held-out images", PROFILE)

# %% [markdown]
# ## Training
#
# `RUN_DIR` holds the config, the split, the dataset manifest, per-epoch checkpoints and `metrics.csv`
# (`sixdpose train-seg`; an interrupted run is resumed by the same make target).

# %%
SegConfig.load(f"{RUN_DIR}/config.json")

# %%
plot_loss(RUN_DIR, out=f"{FIGURES}/seg_loss_{PROFILE}.png")
plt.show()

# %% [markdown]
# ## Predictions on the held-out images
#
# Left: ground-truth visible masks; right: predicted masks with score ≥ 0.5 (colour = object).

# %%
with open(f"{PRED}/meta.json") as fh:
    meta = json.load(fh)
print(f"{len(meta['images'])} held-out image(s) segmented ({PRED})")
plot_predictions(DATA, PRED, n=3, out=f"{FIGURES}/seg_examples_{PROFILE}.png")
plt.show()

# %% [markdown]
# ## COCO AP on the held-out images
#
# Mask and box AP (IoU 0.50:0.95), AP50 and AP75, per object and overall (pycocotools); written to
# `FIGURES/seg_ap_<profile>.csv` and `.tex`. In the smoke profile the numbers only show that the
# pipeline runs: the model is trained for a couple of minutes on a handful of images.

# %%
metrics = evaluate(DATA, PRED, FIGURES, tag=f"_{PROFILE}")
print(ap_table_text(metrics))
print("written:", *metrics["files"])
