"""Figures of the segmentation stage (used by ``notebooks/03_train_segmentation.ipynb``)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..constants import MIN_DETECTION_SCORE
from .train import LOSS_KEYS, read_metrics


def plot_loss(run_dir: str | Path, ax=None, out: str | Path | None = None):
    """Plot the training loss of a run (per logged step, total and each term, plus epoch means).

    Args:
        run_dir: a run directory with ``metrics.csv``.
        ax: matplotlib axes to draw on (default: a new figure).
        out: also save the figure here (PNG/PDF by extension).
    Returns:
        The matplotlib figure.
    """
    import matplotlib.pyplot as plt

    rows = read_metrics(run_dir)
    if ax is None:
        fig, ax = plt.subplots(figsize=(7, 4))
    else:
        fig = ax.figure
    steps = [r["step"] for r in rows]
    ax.plot(steps, [r["loss"] for r in rows], color="k", lw=1.5, label="total")
    for k in LOSS_KEYS:
        ax.plot(steps, [r[k] for r in rows], lw=0.8, alpha=0.8, label=k.replace("loss_", ""))
    epochs = sorted({r["epoch"] for r in rows})
    means = [(max(r["step"] for r in rows if r["epoch"] == e), np.mean([r["loss"] for r in rows if r["epoch"] == e]))
             for e in epochs]
    ax.plot([m[0] for m in means], [m[1] for m in means], "o-", color="tab:red", ms=3, lw=1, label="epoch mean")
    ax.set_yscale("log")
    ax.set_xlabel("step")
    ax.set_ylabel("loss")
    ax.set_title(f"Mask R-CNN training loss ({Path(run_dir).name})")
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    if out is not None:
        Path(out).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(out, dpi=120)
    return fig


def _overlay(rgb: np.ndarray, masks, labels, colors: dict) -> np.ndarray:
    img = rgb.astype(np.float32) / 255.0
    for m, lab in zip(masks, labels, strict=True):
        c = np.asarray(colors[int(lab)], np.float32)
        img[m] = 0.45 * img[m] + 0.55 * c
        # outline
        edge = m & ~(np.roll(m, 1, 0) & np.roll(m, -1, 0) & np.roll(m, 1, 1) & np.roll(m, -1, 1))
        img[edge] = c
    return img


def plot_predictions(data, pred_dir: str | Path, n: int = 3, score_thresh: float = MIN_DETECTION_SCORE, seed: int = 0,
                     out: str | Path | None = None):
    """Ground-truth masks next to predicted masks for ``n`` random segmented images.

    Args:
        data: dataset directory that was segmented.
        pred_dir: output of ``sixdpose segment`` (its ``meta.json`` lists the images).
        n: number of images (rows).
        score_thresh: predictions below are not drawn.
        seed: selects the images.
        out: also save the figure here.
    Returns:
        The matplotlib figure (one row per image: ground truth, prediction; colour = object).
    """
    import matplotlib.pyplot as plt

    from ..artifacts.predictions import read_predictions
    from .evaluate import open_segmented

    pred_dir = Path(pred_dir)
    ds, meta, index = open_segmented(data, pred_dir)
    keys = [tuple(k[:2]) for k in meta["images"]]
    if not keys:
        raise ValueError(f"{pred_dir}: no segmented image")
    rng = np.random.default_rng(seed)
    pick = [keys[i] for i in sorted(rng.choice(len(keys), size=min(n, len(keys)), replace=False))]
    ids = [c[0] for c in meta["classes"]]
    names = {c[0]: c[1] for c in meta["classes"]}
    cmap = plt.get_cmap("tab20")
    colors = {i: cmap(k % 20)[:3] for k, i in enumerate(ids)}
    fig, axes = plt.subplots(len(pick), 2, figsize=(9, 3.4 * len(pick)), squeeze=False)
    for row, key in zip(axes, pick, strict=True):
        s = ds[index[key]]
        gt_masks = [i.mask for i in s.instances if i.mask is not None and i.obj_id in colors]
        gt_labels = [i.obj_id for i in s.instances if i.mask is not None and i.obj_id in colors]
        dets = [d for d in read_predictions(pred_dir, *key) if d.score >= score_thresh]
        row[0].imshow(_overlay(s.rgb, gt_masks, gt_labels, colors))
        row[0].set_title(f"ground truth: scene {key[0]} image {key[1]} ({len(gt_masks)})", fontsize=8)
        row[1].imshow(_overlay(s.rgb, [d.mask for d in dets], [d.obj_id for d in dets], colors))
        shown = sorted({names.get(d.obj_id, str(d.obj_id)) for d in dets})
        row[1].set_title(f"predicted, score >= {score_thresh} ({len(dets)})", fontsize=8)
        row[1].set_xlabel(", ".join(shown)[:90], fontsize=7)
        for a in row:
            a.set_xticks([])
            a.set_yticks([])
    fig.tight_layout()
    if out is not None:
        Path(out).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(out, dpi=110)
    return fig


def ap_table_text(metrics: dict) -> str:
    """The AP table of :func:`~.evaluate.coco_evaluate` as aligned plain text (percent)."""
    cols = [f"{t}_{m}" for t in ("mask", "box") for m in ("AP", "AP50", "AP75")]
    head = f"{'object':<28}{'n_gt':>6}" + "".join(f"{c:>11}" for c in cols)
    lines = [head, "-" * len(head)]
    rows = list(metrics["per_class"])
    overall = {"name": "all", "n_gt": metrics["n_gt"]}
    overall.update({f"{t}_{m}": metrics["overall"][t][m] for t in ("mask", "box") for m in ("AP", "AP50", "AP75")})
    for r in rows + [overall]:
        vals = "".join(f"{'--' if math.isnan(r[c]) else f'{100 * r[c]:.1f}':>11}" for c in cols)
        lines.append(f"{str(r['name'])[:27]:<28}{r['n_gt']:>6}{vals}")
    return "\n".join(lines)
