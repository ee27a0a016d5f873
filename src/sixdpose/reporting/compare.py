"""Run several pose methods over the same images and tabulate them (the experiment loop of the paper's
Tables II and III; notebooks call this, they hold no loop of their own).

A *method* is a name and a function ``run(reader, masks, indices) -> list[PoseEstimate]``;
:func:`hybrid_methods` builds the six hybrid ones (RANSAC / FGR / Super4PCS, each with and without ICP),
:func:`learned_method` one of a trained learned-pose run.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from ..artifacts.poses import PoseEstimate
from ..constants import ADD_THRESHOLD, MIN_DETECTION_SCORE, MIN_VISIBLE_PX
from ..datasets.base import DatasetReader
from ..datasets.readers import as_reader
from ..evaluation.evaluate import EvalResult, evaluate
from ..registry import HYBRID_ALGORITHMS


@dataclass
class Run:
    """One method on one mask source: its rows and their evaluation."""

    method: str
    masks: str
    estimates: list[PoseEstimate]
    result: EvalResult


def hybrid_methods(
    cfg=None, workers: int = 2, methods=tuple(HYBRID_ALGORITHMS), icp=(False, True), verify=(False,)
) -> dict[str, Callable]:
    """The hybrid methods as ``{display name: run(reader, masks, indices)}``.

    Args:
        cfg: a :class:`~sixdpose.registration.presets.RegistrationConfig` (default preset if None).
        workers: registration processes. methods, icp, verify: which combinations (``verify``: the
            hypothesis verification stage, ``register --verify``; its rows are named "+ verification").
    """
    from ..registration.presets import get_preset
    from ..registration.runner import run_registration

    base = cfg if cfg is not None else get_preset("default")
    out = {}
    for m in methods:
        for use_icp in icp:
            for use_verify in verify:
                c = base.replace(verify=True) if use_verify else base

                def run(reader, masks, indices, m=m, use_icp=use_icp, c=c):
                    return run_registration(reader, m, icp=use_icp, masks=masks, cfg=c, workers=workers,
                                            indices=indices, min_px=MIN_VISIBLE_PX if masks == "gt" else 0,
                                            progress=False)

                name = HYBRID_ALGORITHMS[m] + (" + ICP" if use_icp else "") + (" + verification" if use_verify else "")
                out[f"Hybrid ({name})"] = run
    return out


def learned_method(pose, refiner=None, iterations: int = 0, icp: bool = False, colour_verify: bool = False,
                   score_thresh: float = MIN_DETECTION_SCORE) -> Callable:
    """A trained learned-pose run as a method ``run(reader, masks, indices)`` for :func:`compare_methods`.

    Args:
        pose: run directory of ``train-pose``. refiner: run directory of ``train-refiner`` or None.
        iterations, icp, colour_verify, score_thresh: as :class:`sixdpose.pose.Estimator`.
    """
    from ..pose.infer import predict_dataset

    def run(reader, masks, indices):
        return predict_dataset(reader, pose, refiner=refiner, masks=masks, iterations=iterations, icp=icp,
                               colour_verify=colour_verify, score_thresh=score_thresh, indices=indices)[0]

    return run


def compare_methods(
    data: DatasetReader | str,
    methods: dict[str, Callable],
    mask_sources: dict[str, tuple[str, list[int]]],
    min_px: int = MIN_VISIBLE_PX,
    threshold: float = ADD_THRESHOLD,
    bop: bool = False,
    also=(),
):
    """Run every method on every mask source and evaluate each run on the same images.

    Args:
        data: a :class:`~sixdpose.datasets.base.DatasetReader` or a dataset path.
        methods: ``{display name: run(reader, masks, indices) -> list[PoseEstimate]}``
            (e.g. :func:`hybrid_methods`).
        mask_sources: ``{label: (masks, image indices)}`` with ``masks`` ``"gt"`` or a prediction
            directory; every listed image is evaluated, so an image where nothing was detected counts
            its instances as failures.
        min_px, threshold: the evaluation protocol (:func:`~sixdpose.evaluation.evaluate.evaluate`).
        bop: also the BOP scores (columns ``ar, ar_vsd, ar_mssd, ar_mspd, adds_auc``).
        also: ``[(column label, reader)]``: the same estimates scored once more against another reader
            of the same images, e.g. one that treats every object as symmetric (an ``ADD-S`` column).
    Returns:
        ``(table, runs)``: a tidy ``pandas.DataFrame`` with one row per (masks, method) and columns
        ``masks, method, add_s, n_gt, n_correct, fps, instances_per_s`` (and the optional ones); and
        ``{(masks, method): Run}``.
    """
    import pandas as pd

    reader = as_reader(data)
    keys = reader.keys()
    rows, runs = [], {}
    for label, (masks, indices) in mask_sources.items():
        images = [keys[i] for i in indices]
        for name, run in methods.items():
            est = run(reader, masks, indices)
            res = evaluate(reader, est, min_px=min_px, threshold=threshold, images=images, bop=bop)
            runs[(label, name)] = Run(name, label, est, res)
            row = {"masks": label, "method": name, "add_s": res.accuracy, "n_gt": res.n_gt, "n_correct": res.n_correct,
                   "fps": res.fps, "instances_per_s": res.instances_per_s}
            row.update({k: v for k, v in res.bop.items() if k != "unannotated_symmetric_ids"})
            for col, other in also:
                row[col] = evaluate(other, est, min_px=min_px, threshold=threshold, images=images).accuracy
            rows.append(row)
    return pd.DataFrame(rows), runs


def per_object_table(runs: dict, masks: str = "gt"):
    """ADD(-S) per object of every method of one mask source, side by side.

    Args:
        runs: the ``{(masks, method): Run}`` of :func:`compare_methods`. masks: the mask source label.
    Returns:
        ``pandas.DataFrame`` with columns ``obj_id, name, n_gt`` and one ADD(-S) % column per method (in
        the order of ``runs``), one row per object with GT instances, sorted by obj_id.
    """
    import pandas as pd

    table: dict[int, dict] = {}
    for (label, method), run in runs.items():
        if label != masks:
            continue
        for oid, v in run.result.per_object.items():
            row = table.setdefault(int(oid), {"obj_id": int(oid), "name": v["name"], "n_gt": v["n_gt"]})
            row[method] = v["accuracy"]
    return pd.DataFrame([table[k] for k in sorted(table)])
