"""Ablations of the main pose network (issue: each option measured against the paper's architecture).

Every variant is a set of :class:`~sixdpose.pose.config.PoseConfig` overrides on one base profile,
trained with the same data, seed and time budget, then scored by ADD(-S) (10 % of the diameter,
ground-truth masks, instances with >= ``min_px`` visible pixels) on a held-out split (``val``: never
``test``). Equal *time* rather than equal steps is the budget, because the question a CPU user asks is
which option gives the best network in the time they have; the steps and instances each variant
reached are reported beside its accuracy. Runs are resumable: a variant whose ``model.pt`` exists is
scored, not retrained.
"""

from __future__ import annotations

from pathlib import Path

from ..constants import MIN_VISIBLE_PX

#: The variants of the issue, as overrides of a base profile. ``paper``: the paper's choices (absolute
#: translation, quaternion, no normalisation) on the base profile's crop/width; each other row changes
#: one thing. The last three change one thing on the centroid-offset base: at a CPU budget every
#: absolute-translation variant can stay at 0 %, which would hide the effect of the other options.
#: ``full image`` is absent on purpose: on a CPU it is the cost the crop removes (its
#: throughput is in ``benchmarks/pose.py``), and at the paper's scale it is the ``paper`` profile itself.
VARIANTS: dict[str, dict] = {
    "paper (absolute t, quaternion, no norm)": {"translation": "absolute", "rotation": "quaternion", "norm": "none"},
    "+ centroid offset": {"translation": "centroid_offset", "rotation": "quaternion", "norm": "none"},
    "+ 6D rotation": {"translation": "absolute", "rotation": "6d", "norm": "none"},
    "+ group norm": {"translation": "absolute", "rotation": "quaternion", "norm": "group"},
    "+ batch norm": {"translation": "absolute", "rotation": "quaternion", "norm": "batch"},
    "centroid offset + 6D rotation": {"translation": "centroid_offset", "rotation": "6d", "norm": "none"},
    "centroid offset + group norm": {"translation": "centroid_offset", "rotation": "quaternion", "norm": "group"},
    "centroid offset + batch norm": {"translation": "centroid_offset", "rotation": "quaternion", "norm": "batch"},
}

COLUMNS = ("variant", "translation", "rotation", "norm", "epochs", "steps", "train_seconds", "val_add", "n_val")


def run_ablation(
    train,
    val,
    out_dir,
    *,
    profile: str = "cpu",
    time_budget: float | None = None,
    variants: dict | None = None,
    min_px: int = MIN_VISIBLE_PX,
    val_images: int = 0,
    progress: bool = False,
    **overrides,
):
    """Train each variant for the same budget and score it on ``val``.

    Args:
        train: training dataset (reader or path). val: held-out dataset (reader or path; tune on
            ``val``, never on ``test``). out_dir: one run directory per variant is created below it
            (``out_dir/<k>_<slug>``).
        profile: base PoseConfig profile. time_budget: seconds per variant (None: the profile's).
        variants: ``{name: overrides}`` (default :data:`VARIANTS`). min_px: visible-pixel threshold of the
            scored instances. val_images: first N images of ``val`` (0: all). progress: progress bars.
        **overrides: further PoseConfig overrides shared by every variant (e.g. ``epochs``).
    Returns:
        ``pandas.DataFrame`` with the columns of :data:`COLUMNS`, one row per variant.
    """
    import pandas as pd

    from ..datasets.readers import as_reader
    from ..evaluation.evaluate import evaluate
    from .checkpoint import load
    from .infer import predict_dataset
    from .train import ensure_trained, read_metrics

    train_r, val_r = as_reader(train, split="train"), as_reader(val, split="test")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    shared = dict(overrides)
    if time_budget is not None:
        shared["time_budget"] = float(time_budget)
    rows = []
    for k, (name, ov) in enumerate((variants or VARIANTS).items()):
        slug = "".join(c if c.isalnum() else "_" for c in name.lower()).strip("_")[:40]
        run = out_dir / f"{k}_{slug}"
        ensure_trained("pose", train_r, run, profile=profile, progress=progress, **shared, **ov)
        ckpt = load(run)
        cfg = ckpt["config"]
        metrics = [r for r in read_metrics(run) if r["val_add"] is None]
        est, _ = predict_dataset(val_r, run, iterations=0, limit=val_images)
        res = evaluate(val_r, est, min_px=min_px, images=val_r.keys()[:val_images] if val_images else None)
        rows.append(
            {
                "variant": name,
                "translation": cfg["translation"],
                "rotation": cfg["rotation"],
                "norm": cfg["norm"],
                "epochs": ckpt["epoch"],
                "steps": metrics[-1]["step"] if metrics else 0,
                "train_seconds": round(metrics[-1]["seconds"], 1) if metrics else 0.0,
                "val_add": round(res.accuracy, 2),
                "n_val": res.n_gt,
            }
        )
    return pd.DataFrame(rows, columns=list(COLUMNS))
