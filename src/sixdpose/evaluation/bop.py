"""The BOP 2019 scores of an evaluation (Hodaň et al. 2020): MSSD, MSPD and VSD errors of each GT
instance's estimate, their average recalls AR_MSSD, AR_MSPD, AR_VSD and AR, and the YCB-Video ADD-S
AUC (Xiang et al. 2018), computed beside ADD(-S) by :func:`~sixdpose.evaluation.evaluate.evaluate`.

Protocol notes (where this differs from the bop_toolkit, it is said here):

* Each counted GT instance is scored with the estimate the ADD(-S) matching gave it (or the nearest
  estimate of its object in the image); an instance without any estimate has error +inf in every metric.
  The bop_toolkit matches estimates to GT per metric and threshold; with one estimate per instance, as
  our stages produce, the two agree except when two estimates compete for one instance.
* Symmetries come from the dataset's annotations (``ObjectModel.symmetries``, BOP ``models_info``).
  An object flagged symmetric without annotations (``--symmetric-ids`` on a dataset that has none, or
  the synthetic layout, whose ``models_info.yml`` has only a flag) is scored with the identity alone
  in MSSD / MSPD; its ids are listed in ``unannotated_symmetric_ids``.
* VSD needs the model's mesh and the test depth; without either it is skipped (``ar_vsd`` is nan and AR
  is the mean of the other two).
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import SixdposeError
from . import metrics


def model_symmetries(model, location) -> list:
    """The symmetry transformations ``[(R, t metres)]`` of an :class:`~sixdpose.datasets.base.ObjectModel`
    (identity only if it has no annotation); a malformed annotation is an error naming ``location``."""
    if model.symmetries is None:
        return [(np.eye(3), np.zeros(3))]
    try:
        return metrics.symmetry_transformations(model.symmetries)
    except ValueError as e:
        raise SixdposeError(f"{location}: models_info of object {model.obj_id}: {e}") from None


def instance_errors(sample, gt, model, estimate, syms, with_vsd: bool) -> dict:
    """BOP errors of one GT instance: ``mssd`` (m), ``mspd`` (px), ``vsd`` (list over the taus, or
    None), ``adds`` (m; for the AUC). An absent estimate gives +inf everywhere."""
    inf = math.inf
    if estimate is None:
        return {"mssd": inf, "mspd": inf, "vsd": [1.0] * len(metrics.BOP19_VSD_TAUS) if with_vsd else None, "adds": inf}
    R, t = estimate.R, estimate.t
    out = {
        "mssd": metrics.mssd(R, t, gt.R, gt.t, model.points, syms),
        "mspd": metrics.mspd(R, t, gt.R, gt.t, sample.K, model.points, syms),
        "adds": metrics.adds(R, t, gt.R, gt.t, model.points),
        "vsd": None,
    }
    if with_vsd:
        out["vsd"] = metrics.vsd(R, t, gt.R, gt.t, sample.depth, sample.K, metrics.BOP19_VSD_DELTA,
                                 metrics.BOP19_VSD_TAUS, True, model.diameter, model.mesh[0], model.mesh[1])
    return out


def summarize(errors: list[dict], diameters: list[float], image_width: int) -> dict:
    """AR_VSD, AR_MSSD, AR_MSPD, AR (percent) and the ADD-S AUC (percent, up to 10 cm) of a list of
    :func:`instance_errors` outputs with their objects' diameters (metres)."""
    if not errors:
        return {k: math.nan for k in ("ar", "ar_vsd", "ar_mssd", "ar_mspd", "adds_auc")}
    mssd = np.array([e["mssd"] for e in errors])
    mspd = np.array([e["mspd"] for e in errors])
    ar_mssd = 100.0 * metrics.ar_mssd(mssd, np.asarray(diameters))
    ar_mspd = 100.0 * metrics.ar_mspd(mspd, image_width=image_width)
    have_vsd = all(e["vsd"] is not None for e in errors)
    ar_vsd = 100.0 * metrics.ar_vsd(np.array([e["vsd"] for e in errors])) if have_vsd else math.nan
    parts = [ar_mssd, ar_mspd] + ([ar_vsd] if have_vsd else [])
    return {"ar": float(np.mean(parts)), "ar_vsd": ar_vsd, "ar_mssd": ar_mssd, "ar_mspd": ar_mspd,
            "adds_auc": metrics.adds_auc([e["adds"] for e in errors])}
