"""ADD(-S) accuracy and timing of a BOP results CSV against a dataset (``sixdpose evaluate``).

Protocol (paper section V-A; matching as in the BOP toolkit):

* GT instances counted: every annotated instance whose visible mask has at least ``min_px`` pixels
  (400 by default; instances with unknown pixel count are counted).
* Per image and object, only the ``n`` best-scoring estimates are considered, ``n`` = number of counted
  GT instances of that object in the image; estimates with score <= 0 are "no estimate".
* Greedy matching in decreasing score: an estimate is matched to the still unmatched GT instance of
  its object with the smallest ADD(-S) error, if that error is below ``threshold`` x diameter; a
  matched GT instance counts as correct. ADD-S for symmetric objects, ADD otherwise (eq. 4).
* Accuracy against the threshold (0-20 % of the diameter, :attr:`EvalResult.curve`): the same matching
  redone at each threshold.
* Timing: frames per second = images in the results / sum of their per-image times (each image's
  time once); instances per second = estimates / the same total. Times exclude disk reads. A time that
  is negative or not finite is refused (:class:`EvaluationError`).
* Rows checked before scoring (:func:`check_estimates`): a row whose ``R`` is not a rotation
  (``max |R^T R - I| > ROTATION_TOL`` or ``det R <= 0``), with a non-finite value, or with an
  ``obj_id`` the dataset does not have is *rejected*: never credited, counted in ``n_rejected`` and
  named in one warning line. A row that repeats an earlier row's pose (same image, object, R and t,
  whatever its score) is counted once, the first one kept (``n_duplicates``, one warning line).
"""

from __future__ import annotations

import json
import logging
import math
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..artifacts.poses import PoseEstimate
from ..artifacts.tables import write_table
from ..constants import ADD_THRESHOLD, MIN_VISIBLE_PX
from ..datasets.base import DatasetReader
from ..datasets.readers import as_reader
from ..errors import SixdposeError
from ..fileio import atomic_write_text
from . import bop as bop_scores
from . import metrics

log = logging.getLogger(__name__)

#: Largest ``max |R^T R - I|`` of a results row's R that counts as a rotation.
ROTATION_TOL = 1e-3

class EvaluationError(SixdposeError):
    """Results and dataset do not fit together (unknown images or objects)."""


@dataclass
class MatchRecord:
    """The outcome for one counted GT instance.

    Attributes:
        scene_id, im_id, obj_id: the instance's image and object. gt_index: its index in
        ``Sample.instances``. error: ADD(-S) (metres) of its matched estimate, else of the nearest
        estimate of its object in the image, else nan. correct: matched within the threshold.
        estimate: the matched (or nearest) :class:`~sixdpose.artifacts.poses.PoseEstimate`, or None.
    """

    scene_id: int
    im_id: int
    obj_id: int
    gt_index: int
    error: float
    correct: bool
    estimate: PoseEstimate | None = None


@dataclass
class EvalResult:
    """Outcome of :func:`evaluate`.

    Attributes:
        per_object: obj_id -> dict(name, n_gt, n_correct, accuracy (%)).
        accuracy: % over all counted GT instances. mean_object_accuracy: mean of per-object %.
        n_gt, n_correct: counts. fps, instances_per_s, n_images, n_estimates, total_time: timing.
        records: one :class:`MatchRecord` per counted GT instance.
        bop: the BOP 2019 scores (:mod:`.bop`): ``ar``, ``ar_vsd``, ``ar_mssd``, ``ar_mspd`` and the
            YCB-Video ``adds_auc`` (percent), plus ``unannotated_symmetric_ids``; per object in
            ``per_object[obj_id]["bop"]``. Empty when not computed.
        curve: accuracy against the threshold: ``{"threshold_pct": [...], "accuracy": [...]}``, the
            threshold in % of the object's diameter (:data:`CURVE_THRESHOLDS_PCT`, 0-20 %), the accuracy
            in % of the counted GT instances, each point with the matching redone at that threshold.
        n_rejected: results rows not scored (not a rotation, non-finite, unknown obj_id), listed in
            ``rejected`` as ``(scene_id, im_id, obj_id, reason)``. n_duplicates: exact repeats counted once.
    """

    per_object: dict
    accuracy: float
    mean_object_accuracy: float
    n_gt: int
    n_correct: int
    fps: float
    instances_per_s: float
    n_images: int
    n_estimates: int
    total_time: float
    records: list = field(default_factory=list)
    bop: dict = field(default_factory=dict)
    curve: dict = field(default_factory=dict)
    n_rejected: int = 0
    n_duplicates: int = 0
    rejected: list = field(default_factory=list)

    def summary(self) -> dict:
        """The scalar fields (and the BOP scores) as a dict (JSON-serialisable)."""
        return {k: v for k, v in self.__dict__.items() if k not in ("per_object", "records", "rejected")}


#: Thresholds of :attr:`EvalResult.curve`, % of the object's diameter: 0, 0.5, ..., 20.
CURVE_THRESHOLDS_PCT = tuple(0.5 * i for i in range(41))


def greedy_match(err: np.ndarray, limit: float) -> list[int | None]:
    """Greedy matching of one image and object (BOP toolkit style): estimates (rows, in decreasing
    score) each take the still unmatched GT instance (column) with the smallest error below ``limit``.

    Args:
        err: (n_estimates, n_gt) ADD(-S) errors (any unit). limit: the largest error that counts (same unit, exclusive).
    Returns:
        for each GT instance, the row index of its estimate, or None.
    """
    match: list[int | None] = [None] * err.shape[1]
    for i in range(err.shape[0]):
        cand = [(err[i, j], j) for j in range(err.shape[1]) if match[j] is None and err[i, j] < limit]
        if cand:
            match[min(cand)[1]] = i
    return match


def rotation_problem(R) -> str:
    """Why ``R`` is not a rotation matrix (``""`` if it is, within :data:`ROTATION_TOL`)."""
    R = np.asarray(R, dtype=np.float64)
    if R.shape != (3, 3):
        return f"R has shape {R.shape}, not (3, 3)"
    if not np.isfinite(R).all():
        return "R is not finite"
    dev = float(np.abs(R.T @ R - np.eye(3)).max())
    if dev > ROTATION_TOL:
        return f"R is not orthonormal (max |R^T R - I| = {dev:.3g} > {ROTATION_TOL:g})"
    if np.linalg.det(R) <= 0:
        return "R is a reflection (det R = -1), not a rotation"
    return ""


def check_estimates(estimates, object_ids) -> tuple[list[PoseEstimate], list[tuple], int]:
    """Split results rows into those that can be scored and those that cannot (see the module docstring).

    Args:
        estimates: :class:`~sixdpose.artifacts.poses.PoseEstimate` rows. object_ids: the dataset's obj_ids.
    Returns:
        ``(kept, rejected, n_duplicates)``: the rows to score (repeated poses dropped), ``(scene_id,
        im_id, obj_id, reason)`` of each rejected row, and the number of repeats dropped.
    Raises:
        EvaluationError: a row's time is negative or not finite.
    """
    known = set(int(o) for o in object_ids)
    kept, rejected, seen, n_dup = [], [], set(), 0
    for e in estimates:
        if not (math.isfinite(float(e.time)) and e.time >= 0):
            raise EvaluationError(f"results: scene {e.scene_id} image {e.im_id} obj {e.obj_id}: time {e.time!r} s; "
                                  "times must be finite and >= 0")
        R = np.asarray(e.R, dtype=np.float64)
        t = np.asarray(e.t, dtype=np.float64)
        reason = ""
        if int(e.obj_id) not in known:
            reason = f"obj_id {e.obj_id} is not an object of the dataset"
        elif not math.isfinite(float(e.score)) or t.shape != (3,) or not np.isfinite(t).all():
            reason = "non-finite score or t"
        else:
            reason = rotation_problem(R)
        if reason:
            rejected.append((int(e.scene_id), int(e.im_id), int(e.obj_id), reason))
            continue
        key = (int(e.scene_id), int(e.im_id), int(e.obj_id), R.tobytes(), t.tobytes())
        if key in seen:
            n_dup += 1
            continue
        seen.add(key)
        kept.append(e)
    if rejected:
        s, i, o, why = rejected[0]
        log.warning("%d results row(s) rejected and not credited (first: scene %d image %d obj %d: %s)",
                    len(rejected), s, i, o, why)
    if n_dup:
        log.warning("%d results row(s) repeat the pose of an earlier row; each pose is counted once", n_dup)
    return kept, rejected, n_dup


def evaluate(dataset: DatasetReader | str | Path, estimates: list[PoseEstimate], min_px: int = MIN_VISIBLE_PX,
             threshold: float = ADD_THRESHOLD, progress: bool = False, images=None, bop: bool = False) -> EvalResult:
    """Score ``estimates`` against ``dataset`` (see the module docstring for the protocol).

    Linear in the number of images: each evaluated image's annotations are read once, without its
    image files.

    Args:
        dataset: a :class:`~sixdpose.datasets.base.DatasetReader` or a dataset path.
        estimates: :class:`~sixdpose.artifacts.poses.PoseEstimate` rows (from a results CSV or straight
            from a stage). min_px: GT visibility threshold (pixels).
        threshold: fraction of the diameter (0.1).
        images: the ``(scene_id, im_id)`` keys evaluated; an image without estimates counts its GT
            instances as failures. ``None``: the images that appear in the results (every image if
            there are none), which suits GT-mask runs on a subset; with predicted masks an image where
            nothing was detected has no rows, so pass the registered images (or ``dataset.keys()``).
        bop: also compute the BOP 2019 scores and the ADD-S AUC (:mod:`.bop`; VSD reads the test
            depth and renders the model mesh by ray casting, so it costs a few ms per instance).
    Returns:
        :class:`EvalResult`.
    """
    from tqdm import tqdm

    dataset = as_reader(dataset)
    names = dataset.object_ids
    estimates = list(estimates)
    # images with rows, rejected ones included: a rejected row leaves its GT instances counted, not skipped
    row_time: dict[tuple[int, int], float] = {}
    for e in estimates:
        k = (int(e.scene_id), int(e.im_id))
        row_time[k] = max(row_time.get(k, 0.0), float(e.time))
    estimates, rejected, n_dup = check_estimates(estimates, names)
    by_img: dict[tuple[int, int], list[PoseEstimate]] = defaultdict(list)
    for e in estimates:
        by_img[(e.scene_id, e.im_id)].append(e)
    keys = dataset.keys()
    known = set(keys)
    unknown = [k for k in row_time if k not in known]
    if unknown:
        raise EvaluationError(
            f"results refer to image(s) not in {dataset.location}, e.g. scene {unknown[0][0]} image {unknown[0][1]}"
        )
    n_gt_obj: dict[int, int] = defaultdict(int)
    n_ok_obj: dict[int, int] = defaultdict(int)
    records = []
    # only images with results are evaluated when the results cover a subset (e.g. --limit runs)
    if images is not None:
        want = {(int(a), int(b)) for a, b in images}
        missing = sorted(want - known)
        if missing:
            raise EvaluationError(f"images not in {dataset.location}, e.g. scene {missing[0][0]} image {missing[0][1]}")
        eval_keys = [k for k in keys if k in want]
    else:
        eval_keys = [k for k in keys if k in row_time] if row_time else keys
    bop_err: dict[int, list] = defaultdict(list)
    syms: dict[int, list] = {}
    rel_err: list[np.ndarray] = []  # per image and object: (estimates, GT) errors / diameter
    for key in tqdm(eval_keys, desc="evaluate", unit="img", disable=not progress):
        sample = dataset.load(key, masks=False, rgb=False, depth=bop and dataset.has_depth)
        gts = [g for g in sample.instances if g.px_visib < 0 or g.px_visib >= min_px]
        ests = by_img.get(key, [])
        for oid in sorted({g.obj_id for g in gts}):
            g_o = [g for g in gts if g.obj_id == oid]
            e_o = sorted((e for e in ests if e.obj_id == oid and e.score > 0), key=lambda e: -e.score)[: len(g_o)]
            model = dataset.model(oid)
            err = np.array(
                [[metrics.add_or_adds(e.R, e.t, g.R, g.t, model.points, model.symmetric) for g in g_o] for e in e_o]
            ).reshape(len(e_o), len(g_o))
            rel_err.append(err / model.diameter)
            match_est = greedy_match(err, threshold * model.diameter)
            for j, g in enumerate(g_o):
                ok = match_est[j] is not None
                i = match_est[j] if ok else (int(np.argmin(err[:, j])) if len(e_o) else None)
                best = float(err[i, j]) if i is not None else math.nan
                records.append(MatchRecord(key[0], key[1], oid, sample.instances.index(g), float(best), ok,
                                           None if i is None else e_o[i]))
                if bop:
                    if oid not in syms:
                        syms[oid] = bop_scores.model_symmetries(model, dataset.location)
                    with_vsd = sample.depth is not None and model.mesh is not None
                    bop_err[oid].append(
                        bop_scores.instance_errors(sample, g, model, records[-1].estimate, syms[oid], with_vsd)
                    )
                n_gt_obj[oid] += 1
                n_ok_obj[oid] += int(ok)
    per_object = {
        oid: {
            "name": names.get(oid, str(oid)),
            "n_gt": n_gt_obj[oid],
            "n_correct": n_ok_obj[oid],
            "accuracy": 100.0 * n_ok_obj[oid] / n_gt_obj[oid],
        }
        for oid in sorted(n_gt_obj)
    }
    bop_all: dict = {}
    if bop:
        width = sample.depth.shape[1] if eval_keys and sample.depth is not None else 640  # MSPD's image-width scaling
        diam = {oid: dataset.model(oid).diameter for oid in bop_err}
        for oid, errs in bop_err.items():
            per_object[oid]["bop"] = bop_scores.summarize(errs, [diam[oid]] * len(errs), width)
        every = [e for errs in bop_err.values() for e in errs]
        bop_all = bop_scores.summarize(every, [diam[o] for o, errs in bop_err.items() for _ in errs], width)
        bop_all["unannotated_symmetric_ids"] = sorted(o for o in bop_err if dataset.model(o).symmetric
                                                      and dataset.model(o).symmetries is None)
    n_gt = sum(n_gt_obj.values())
    n_ok = sum(n_ok_obj.values())
    curve = {"threshold_pct": list(CURVE_THRESHOLDS_PCT),
             "accuracy": [100.0 * sum(sum(m is not None for m in greedy_match(e, pct / 100.0)) for e in rel_err) / n_gt
                          if n_gt else float("nan") for pct in CURVE_THRESHOLDS_PCT]}
    img_time = row_time  # each image once (its rows repeat the image's time)
    total = float(sum(img_time.values()))
    n_est = sum(len(v) for v in by_img.values())
    return EvalResult(
        per_object=per_object,
        accuracy=100.0 * n_ok / n_gt if n_gt else float("nan"),
        mean_object_accuracy=float(np.mean([v["accuracy"] for v in per_object.values()]))
        if per_object
        else float("nan"),
        n_gt=n_gt,
        n_correct=n_ok,
        fps=len(img_time) / total if total > 0 else float("nan"),
        instances_per_s=n_est / total if total > 0 else float("nan"),
        n_images=len(img_time),
        n_estimates=n_est,
        total_time=total,
        records=records,
        bop=bop_all,
        curve=curve,
        n_rejected=len(rejected),
        n_duplicates=n_dup,
        rejected=rejected,
    )


def _json_ready(v):
    """``v`` with NaN/inf floats replaced by None (JSON has no NaN), recursively."""
    if isinstance(v, dict):
        return {k: _json_ready(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_json_ready(x) for x in v]
    if isinstance(v, (float, np.floating)):
        return float(v) if math.isfinite(v) else None
    if isinstance(v, np.integer):
        return int(v)
    return v


def _nanmean(values) -> float:
    """Mean of the finite values (nan if there are none)."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    return float(v.mean()) if len(v) else math.nan


#: Units of the per-object table and of :meth:`EvalResult.summary` (for result artifacts).
UNITS = {"add_s_accuracy": "%", "accuracy": "%", "mean_object_accuracy": "%", "fps": "frames/s",
         "instances_per_s": "instances/s", "total_time": "s", "n_gt": "GT instances", "n_correct": "GT instances",
         "ar": "%", "ar_vsd": "%", "ar_mssd": "%", "ar_mspd": "%", "adds_auc": "%"}


def table_rows(res: EvalResult) -> list[dict]:
    """The per-object table: one row per object (``obj_id``, ``name``, ``n_gt``, ``n_correct``,
    ``add_s_accuracy`` in %, and the BOP scores in % when computed), then ``obj_id="all"`` (mean over
    GT instances) and ``obj_id="objects"`` (mean over objects; counts empty)."""
    bop_cols = ["ar", "ar_vsd", "ar_mssd", "ar_mspd", "adds_auc"] if res.bop else []
    rows = [
        {
            "obj_id": oid,
            "name": v["name"],
            "n_gt": v["n_gt"],
            "n_correct": v["n_correct"],
            "add_s_accuracy": v["accuracy"],
            **{c: v["bop"][c] for c in bop_cols},
        }
        for oid, v in res.per_object.items()
    ]
    rows.append({"obj_id": "all", "name": "mean over instances", "n_gt": res.n_gt, "n_correct": res.n_correct,
                 "add_s_accuracy": res.accuracy, **{c: res.bop[c] for c in bop_cols}})
    rows.append({"obj_id": "objects", "name": "mean over objects", "n_gt": "", "n_correct": "",
                 "add_s_accuracy": res.mean_object_accuracy,
                 **{c: _nanmean([v["bop"][c] for v in res.per_object.values()]) for c in bop_cols}})
    return rows


def write_tables(res: EvalResult, out_dir: str | Path, label: str = "method") -> dict[str, Path]:
    """Write ``add_s_per_object.csv`` (with the BOP scores when computed), ``add_s.tex``, ``timing.csv``
    and ``summary.json`` to ``out_dir``.

    Returns:
        name -> path of each written file.
    """
    out = Path(out_dir)
    bop_cols = ["ar", "ar_vsd", "ar_mssd", "ar_mspd", "adds_auc"] if res.bop else []
    rows = table_rows(res)
    paths = {"per_object": out / "add_s_per_object.csv", "latex": out / "add_s.tex"}
    write_table(
        rows,
        ["obj_id", "name", "n_gt", "n_correct", "add_s_accuracy"] + bop_cols,
        paths["per_object"],
        paths["latex"],
        headers=["Id", "Object", "GT instances", "Correct", "ADD(-S) (\\%)"]
        + ["AR", "AR$_{VSD}$", "AR$_{MSSD}$", "AR$_{MSPD}$", "ADD-S AUC"][: len(bop_cols)],
        comment=f"{label}: FPS {res.fps:.3f}, instances/s {res.instances_per_s:.3f}",
    )
    paths["timing"] = out / "timing.csv"
    write_table(
        [
            {
                "method": label,
                "n_images": res.n_images,
                "n_estimates": res.n_estimates,
                "total_time_s": res.total_time,
                "fps": res.fps,
                "instances_per_s": res.instances_per_s,
            }
        ],
        ["method", "n_images", "n_estimates", "total_time_s", "fps", "instances_per_s"],
        paths["timing"],
    )
    summary = json.dumps(_json_ready(dict(res.summary(), label=label)), indent=1, allow_nan=False)
    paths["summary"] = atomic_write_text(out / "summary.json", summary + "\n")  # NaN (undefined) -> null
    return paths
