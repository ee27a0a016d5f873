# %% [markdown]
# # 03 · Instance segmentation with Mask R-CNN (paper §II-B, §IV-A)
#
# Trains torchvision's Mask R-CNN (ResNet-FPN backbone) on the dataset's target objects, or loads an
# existing run, then shows the loss curve, predicted masks next to the ground truth on held-out images,
# and the COCO mask/box AP table. All logic lives in `sixdpose.segmentation`; the same steps on the
# command line are `sixdpose train-seg`, `sixdpose segment`, `sixdpose eval-seg`.
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
RUN_DIR = None  # None: ../runs/seg_<PROFILE>
SEG_PROFILE = None  # Mask R-CNN profile; None: the profile of the same name (smoke for demo)

# %%
import os

PROFILE = PROFILE or os.environ.get("SIXDPOSE_PROFILE", "smoke")
GEN_PROFILE = {"cpu": "train"}.get(PROFILE, PROFILE)  # generator profile of the data
DATA = DATA or os.environ.get("SIXDPOSE_DATA") or f"../data/{GEN_PROFILE}"
RUN_DIR = RUN_DIR or f"../runs/seg_{PROFILE}"
SEG_PROFILE = SEG_PROFILE or ("smoke" if PROFILE in ("smoke", "demo") else PROFILE)
import matplotlib.pyplot as plt

from sixdpose.generation import ensure_dataset
from sixdpose.segmentation.evaluate import evaluate
from sixdpose.segmentation.infer import segment
from sixdpose.segmentation.plots import ap_table_text, plot_loss, plot_predictions
from sixdpose.segmentation.train import ensure_trained

ensure_dataset(DATA, profile=GEN_PROFILE)

# %% [markdown]
# ## Training (or loading an existing run)
#
# `RUN_DIR` holds the config, the split, the dataset manifest, per-epoch checkpoints and `metrics.csv`;
# an interrupted run is resumed, a finished one is loaded.

# %%
summary = ensure_trained(DATA, RUN_DIR, profile=SEG_PROFILE, progress=False)
summary

# %%
plot_loss(RUN_DIR, out=f"{FIGURES}/seg_loss_{PROFILE}.png")
plt.show()

# %% [markdown]
# ## Predictions on the held-out images
#
# Left: ground-truth visible masks; right: predicted masks with score ≥ 0.5 (colour = object).

# %%
PRED = f"{RUN_DIR}/pred_test"
result = segment(DATA, RUN_DIR, PRED, subset="test", progress=False)
print(result)
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
