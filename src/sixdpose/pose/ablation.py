"""Ablations of the main pose network (issue: each option measured against the paper's architecture).

Every variant is a set of :class:`~sixdpose.pose.config.PoseConfig` overrides on one base profile,
trained with the same data, seed and time budget, then scored by ADD(-S) (10 % of the diameter,
ground-truth masks, instances with >= ``min_px`` visible pixels) on a held-out split (``val``: never
``test``). Equal *time* rather than equal steps is the budget, because the question a CPU user asks is
which option gives the best network in the time they have; the steps and instances each variant
reached are reported beside its accuracy. Runs are resumable: a variant whose ``model.pt`` exists is
scored, not retrained.

Seeds (``seeds``): every variant is trained once per seed (initialisation, shuffling and sampling); its row
holds the mean ``val_add`` over the seeds, their sample standard deviation ``val_add_std`` (0 with one
seed), ``seeds`` and the per-seed figures ``val_add_per_seed``. The paper's claims are decided on the
mean against that spread (:mod:`sixdpose.reporting.claims`).

The refiner (``refiner_variants``, :data:`REFINER_VARIANTS`): the paper trains it on the main network's
poses perturbed by noise and says (section IV-C5) this "makes the refinement model significantly more
effective, however, this is not yet provably demonstrated by ablation studies". Each refiner variant is
trained, per seed, on that seed's network of the first pose variant, with the same budget (``epochs``
or ``time_budget``), and scored after 2 refinement iterations; its row has ``network`` = ``refiner``.
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

#: The refiner variants: :class:`~sixdpose.pose.config.RefinerConfig` overrides (the paper's noise, and none).
REFINER_VARIANTS: dict[str, dict] = {
    "refiner trained with noise (paper)": {},
    "refiner trained without noise": {"noise_rot_deg": 0.0, "noise_trans": 0.0},
}

COLUMNS = ("variant", "network", "translation", "rotation", "norm", "epochs", "steps", "train_seconds", "val_add",
           "val_add_std", "seeds", "val_add_per_seed", "n_val")


def _slug(name: str) -> str:
    return "".join(c if c.isalnum() else "_" for c in name.lower()).strip("_")[:40]


def _summary(name: str, network: str, cfg: dict, runs: list[dict]) -> dict:
    """One row of the table from the per-seed ``runs`` (``epochs, steps, train_seconds, val_add, n_val``)."""
    import statistics

    acc = [r["val_add"] for r in runs]
    return {
        "variant": name,
        "network": network,
        "translation": cfg["translation"],
        "rotation": cfg["rotation"],
        "norm": cfg["norm"],
        "epochs": runs[0]["epochs"],
        "steps": runs[0]["steps"],
        "train_seconds": round(statistics.fmean(r["train_seconds"] for r in runs), 1),
        "val_add": round(statistics.fmean(acc), 2),
        "val_add_std": round(statistics.stdev(acc), 2) if len(acc) > 1 else 0.0,
        "seeds": len(runs),
        "val_add_per_seed": "/".join(f"{a:.2f}" for a in acc),
        "n_val": runs[0]["n_val"],
    }


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
    seeds=(0,),
    refiner_variants: dict | None = None,
    **overrides,
):
    """Train each variant (per seed) for the same budget and score it on ``val``.

    Args:
        train: training dataset (reader or path). val: held-out dataset (reader or path; tune on
            ``val``, never on ``test``). out_dir: one run directory per variant and seed is created below
            it (``out_dir/<k>_<slug>``, ``k`` the variant's index in :data:`VARIANTS`, else its position in
            ``variants``), so ablations picking different variants into one ``out_dir`` share the runs
            they have in common.
        profile: base PoseConfig profile. time_budget: seconds per variant (None: the profile's).
        variants: ``{name: overrides}`` (default :data:`VARIANTS`). min_px: visible-pixel threshold of the
            scored instances. val_images: first N images of ``val`` (0: all). progress: progress bars.
        seeds: the training seeds of every variant (>= 1; seed 0's runs keep the run names of a one-seed
            ablation, the others get ``_s<seed>``). refiner_variants: ``{name: RefinerConfig
            overrides}`` trained on each seed's network of the first variant (None or empty: none; see the
            module docstring).
        **overrides: further overrides shared by every variant (e.g. ``epochs``; the budget keys ``epochs``
            and ``time_budget`` also apply to the refiners).
    Returns:
        ``pandas.DataFrame`` with the columns of :data:`COLUMNS`, one row per variant.
    Raises:
        ValueError: no seed.
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
    seeds = [int(x) for x in seeds]
    if not seeds:
        raise ValueError("seeds: give at least one training seed")
    keys = val_r.keys()[:val_images] if val_images else None

    def score(run, refiner=None) -> dict:
        ckpt = load(refiner or run, kind="refiner" if refiner else None)
        metrics = [r for r in read_metrics(refiner or run) if r["val_add"] is None]
        est, _ = predict_dataset(val_r, run, refiner=refiner, iterations=2 if refiner else 0, limit=val_images)
        res = evaluate(val_r, est, min_px=min_px, images=keys)
        return {"epochs": ckpt["epoch"], "steps": metrics[-1]["step"] if metrics else 0,
                "train_seconds": metrics[-1]["seconds"] if metrics else 0.0, "val_add": res.accuracy,
                "n_val": res.n_gt, "config": ckpt["config"]}

    rows, base_runs = [], []
    for pos, (name, ov) in enumerate((variants or VARIANTS).items()):
        k = pos
        if VARIANTS.get(name) == ov:  # a variant of the table keeps its run names whichever others are picked
            k = list(VARIANTS).index(name)
        runs = []
        for seed in seeds:
            run = out_dir / (f"{k}_{_slug(name)}" + (f"_s{seed}" if seed else ""))
            ensure_trained("pose", train_r, run, profile=profile, progress=progress, **shared, **ov, seed=seed)
            runs.append(score(run))
            if pos == 0:  # the refiners train on the first picked variant's networks
                base_runs.append(run)
        if pos == 0:
            base_cfg = runs[0]["config"]
        rows.append(_summary(name, "pose", runs[0]["config"], runs))
    budget = {key: shared[key] for key in ("epochs", "time_budget") if key in shared}
    for k, (name, ov) in enumerate((refiner_variants or {}).items()):
        runs = []
        for seed, base in zip(seeds, base_runs, strict=True):
            run = out_dir / (f"r{k}_{_slug(name)}" + (f"_s{seed}" if seed else ""))
            ensure_trained("refiner", train_r, run, profile=profile, pose_run=base, progress=progress, **budget,
                           **ov, seed=seed)
            runs.append(score(base, refiner=run))
        rows.append(_summary(name, "refiner", base_cfg, runs))
    return pd.DataFrame(rows, columns=list(COLUMNS))
