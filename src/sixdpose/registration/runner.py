"""Run a hybrid method over a dataset split and write BOP-format results (``sixdpose register``).

Results CSV (BOP 2019 format): ``scene_id,im_id,obj_id,score,R,t,time`` with ``R`` the 9 row-major
entries of the rotation of ``X_CO`` separated by spaces, ``t`` in millimetres, ``time`` the seconds
spent on the whole image (every instance, every step but disk reads), repeated on each row of the image
as the BOP format prescribes. An instance whose input is unusable gets a row with score 0 (identity
pose) and its reason is logged.
"""

from __future__ import annotations

import logging
import os
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from .presets import RegistrationConfig

log = logging.getLogger(__name__)

RESULT_FIELDS = ("scene_id", "im_id", "obj_id", "score", "R", "t", "time")


@dataclass
class ResultRow:
    """One estimate. R: (3, 3). t: (3,) metres. time: seconds of the whole image. reason: why the
    estimate is empty (score 0), or ''."""

    scene_id: int
    im_id: int
    obj_id: int
    score: float
    R: np.ndarray
    t: np.ndarray
    time: float
    reason: str = ""
    inst_time: float = 0.0


def load_predicted_masks(pred_dir: str | Path, scene_id: int, im_id: int) -> list[tuple[int, float, np.ndarray]]:
    """Read the segmentation stage's predictions for one image.

    Format: ``PRED_DIR/<scene_id>_<im_id>.npz`` (plain integers; 6-digit zero-padded names are also
    accepted) with ``masks`` (N, H, W) bool, ``labels`` (N,) int obj_id, ``scores`` (N,) float.

    Returns:
        list of ``(obj_id, score, mask (H, W) bool)``; empty if the image has no file (no detections).
    Raises:
        DatasetError: the file is unreadable or its arrays are missing / inconsistent.
    """
    from ..datasets.base import DatasetError

    pred_dir = Path(pred_dir)
    path = pred_dir / f"{int(scene_id)}_{int(im_id)}.npz"
    if not path.is_file():
        alt = pred_dir / f"{int(scene_id):06d}_{int(im_id):06d}.npz"
        if not alt.is_file():
            return []
        path = alt
    try:
        with np.load(path) as z:
            masks, labels, scores = z["masks"], z["labels"], z["scores"]
    except KeyError as e:
        raise DatasetError(f"{path}: missing array {e}") from None
    except Exception as e:
        raise DatasetError(f"{path}: unreadable predictions ({e})") from None
    if masks.ndim != 3 or labels.shape != (len(masks),) or scores.shape != (len(masks),):
        raise DatasetError(
            f"{path}: expected masks (N,H,W), labels (N,), scores (N,); got {masks.shape}, {labels.shape}, {scores.shape}"
        )
    return [(int(labels[i]), float(scores[i]), masks[i].astype(bool)) for i in range(len(masks))]


# ------------------------------------------------------------------------------------------
# per-image work (runs in the worker processes)
# ------------------------------------------------------------------------------------------
_W: dict = {}


def _init_worker(data: str, split: str, method: str, icp: bool, cfg: dict, masks: str, min_px: int, min_score: float = 0.5) -> None:
    from ..datasets.base import open_dataset
    from .geometry import ReferenceCache

    ds = open_dataset(data, split=split)
    _W.update(ds=ds, cache=ReferenceCache(ds), method=method, icp=icp, cfg=RegistrationConfig(**cfg), masks=masks, min_px=min_px, min_score=min_score)
    if _W["cfg"].colour_verify:
        from .verify import warmup

        warmup()  # compile (or load from the on-disk cache) the Numba kernel now: a start-up cost, like imports


def process_image(index: int) -> tuple[list[ResultRow], tuple | None]:
    """Register every instance of image ``index`` of the worker's dataset (see :func:`run_registration`).

    Returns:
        ``(rows, failure)``: the image's rows, and ``None`` or ``(scene_id, im_id, reason)`` when the
        image itself could not be used (unreadable image files or predictions); the run goes on.
    """
    from ..datasets.base import DatasetError
    from .geometry import backproject
    from .methods import estimate_pose

    ds, cache, cfg = _W["ds"], _W["cache"], _W["cfg"]
    method, icp, masks, min_px = _W["method"], _W["icp"], _W["masks"], _W["min_px"]
    pred = masks != "gt"
    try:
        sample = ds[index]  # disk reads: not timed
        if pred:
            dets = [d for d in load_predicted_masks(masks, sample.scene_id, sample.im_id) if d[1] >= _W.get("min_score", 0.0)]
        else:
            dets = [(i.obj_id, 1.0, i.mask) for i in sample.instances if i.px_visib < 0 or i.px_visib >= min_px]
    except DatasetError as e:
        key = ds.keys()[index]
        log.warning("scene %d image %d skipped: %s", key[0], key[1], e)
        return [], (int(key[0]), int(key[1]), str(e))
    known = set(ds.object_ids)
    # models are read from disk outside the timed section; an unreadable model fails its instances only
    bad_model: dict[int, str] = {}
    for oid in {d[0] for d in dets if d[0] in known}:
        try:
            ds.model(oid)
        except DatasetError as e:
            bad_model[oid] = f"model unreadable ({e})"
    rows: list[ResultRow] = []
    for oid, det_score, mask in dets:
        t0 = time.perf_counter()
        reason = ""
        if sample.depth is None:
            reason = "no depth image"
        elif oid not in known:
            reason = f"no model for obj_id {oid}"
        elif oid in bad_model:
            reason = bad_model[oid]
        elif mask is None:
            reason = "no mask"
        elif mask.shape != sample.depth.shape:
            reason = f"mask shape {mask.shape} != depth shape {sample.depth.shape}"
        if not reason:
            if np.isnan(sample.depth[mask]).any():
                log.debug("scene %d image %d obj %d: NaN depth values ignored", sample.scene_id, sample.im_id, oid)
            use_rgb = cfg.colour_verify and sample.rgb is not None and sample.rgb.shape[:2] == mask.shape
            pts, col, _ = backproject(sample.depth, sample.K, mask, sample.rgb if use_rgb else None)
            if len(pts) < 3:
                reason = f"mask has {len(pts)} valid depth points (< 3)"
        if reason:
            log.warning("scene %d image %d obj %d: %s; score 0", sample.scene_id, sample.im_id, oid, reason)
            rows.append(ResultRow(sample.scene_id, sample.im_id, oid, 0.0, np.eye(3), np.zeros(3), 0.0, reason, time.perf_counter() - t0))
            continue
        try:
            est = estimate_pose(pts, oid, method, cache, cfg, icp=icp, colors=col)
        except Exception as e:  # a numerical failure or unreadable model in one instance must not stop the run
            log.warning("scene %d image %d obj %d: registration failed (%s); score 0", sample.scene_id, sample.im_id, oid, e)
            rows.append(ResultRow(sample.scene_id, sample.im_id, oid, 0.0, np.eye(3), np.zeros(3), 0.0, f"error: {e}", time.perf_counter() - t0))
            continue
        bp_time = time.perf_counter() - t0 - est.time  # backprojection etc. (est.time measured inside)
        score = est.score * det_score if pred else est.score
        rows.append(
            ResultRow(sample.scene_id, sample.im_id, oid, float(score), est.T[:3, :3].copy(), est.T[:3, 3].copy(), 0.0, "", est.time + max(bp_time, 0.0))
        )
    total = sum(r.inst_time for r in rows)
    for r in rows:
        r.time = total
    return rows, None


# ------------------------------------------------------------------------------------------
# driver
# ------------------------------------------------------------------------------------------
def check_inputs(ds, masks: str) -> None:
    """Fail early with one clear line if the split cannot be registered (no depth, no masks)."""
    from ..cli import UserError

    if len(ds) == 0:
        raise UserError("the dataset split has no images")
    if getattr(ds, "has_depth", True) is False:
        raise UserError(f"{getattr(ds, 'split_dir', ds.root)}: this split has no depth images (depth/ missing); the hybrid methods need depth")
    from ..datasets.base import DatasetError

    s = None
    for i in range(min(len(ds), 5)):  # one unreadable image must not stop the run (it is skipped later)
        try:
            s = ds[i]
            break
        except DatasetError as e:
            err = e
    if s is None:
        raise UserError(f"the first images cannot be read: {err}")
    if s.depth is None:
        raise UserError(f"{getattr(ds, 'root', '?')}: this split has no depth images; the hybrid methods need depth")
    if masks == "gt":
        if getattr(ds, "has_masks", True) is False or any(i.mask is None for i in s.instances):
            raise UserError(f"{getattr(ds, 'root', '?')}: this split has no ground-truth masks (mask_visib/); pass --masks PRED_DIR")
    elif not Path(masks).is_dir():
        raise UserError(f"{masks}: predicted-mask directory not found")


def run_registration(
    data: str | Path,
    method: str,
    icp: bool = False,
    masks: str = "gt",
    split: str = "test",
    cfg: RegistrationConfig | None = None,
    workers: int = 2,
    limit: int | None = None,
    min_px: int = 0,
    min_score: float = 0.5,
    progress: bool = True,
    indices=None,
    failures: list | None = None,
) -> list[ResultRow]:
    """Register every instance of every image of ``data`` (a synthetic or BOP dataset).

    Args:
        data: dataset directory. method: ``ransac`` | ``fgr`` | ``super4pcs``. icp: refine with ICP.
        masks: ``"gt"`` or a directory of predicted masks (:func:`load_predicted_masks`).
        split: BOP split (ignored for the synthetic layout).
        cfg: configuration (default: the ``default`` preset).
        workers: processes (a pool over images; 1 = in this process). Each worker uses one thread.
        limit: only the first ``limit`` images. min_px: with GT masks, skip instances with fewer
            visible pixels (0: register all). min_score: with predicted masks, skip detections scoring
            below this. progress: tqdm bar. indices: explicit image indices.
        failures: if a list, receives ``(scene_id, im_id, reason)`` for every image that could not be
            read (corrupt RGB/depth/mask files or predictions); such images are logged and skipped.
    Returns:
        one :class:`ResultRow` per instance (per prediction with predicted masks), in image order.
    """
    from tqdm import tqdm

    from ..datasets.base import open_dataset
    from .methods import METHODS
    from .presets import PRESETS

    if method not in METHODS:
        from ..cli import UserError

        raise UserError(f"unknown method {method!r} (choose from {', '.join(METHODS)})")
    cfg = cfg or PRESETS["default"]
    ds = open_dataset(data, split=split)
    check_inputs(ds, masks)
    idx = list(range(len(ds))) if indices is None else list(indices)
    if limit is not None:
        idx = idx[:limit]
    cfgd = {k: v for k, v in asdict(cfg).items()}
    args = (str(data), split, method, icp, cfgd, str(masks), int(min_px), float(min_score))
    rows: list[ResultRow] = []
    bad_images: list[tuple] = []
    bar = tqdm(total=len(idx), desc=f"register {method}{'+icp' if icp else ''}", unit="img", disable=not progress)
    if workers <= 1 or len(idx) <= 1:
        _init_worker(*args)
        _W["ds"] = ds
        for i in idx:
            r, fail = process_image(i)
            rows.extend(r)
            if fail:
                bad_images.append(fail)
            bar.update()
    else:
        import multiprocessing as mp

        # one thread per worker (Open3D/OpenMP, BLAS); spawned children inherit the environment
        saved = {k: os.environ.get(k) for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}
        for k in saved:
            os.environ[k] = "1"
        try:
            with mp.get_context("spawn").Pool(workers, initializer=_init_worker, initargs=args) as pool:
                for r, fail in pool.imap(process_image, idx, chunksize=1):
                    rows.extend(r)
                    if fail:
                        bad_images.append(fail)
                    bar.update()
        finally:
            for k, v in saved.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v
    bar.close()
    n_fail = sum(1 for r in rows if r.reason)
    if n_fail:
        log.warning("%d of %d instances had unusable input or failed (score 0)", n_fail, len(rows))
    if bad_images:
        log.warning("%d of %d images could not be read and were skipped", len(bad_images), len(idx))
    if failures is not None:
        failures.extend(bad_images)
    return rows


def write_results(rows: list[ResultRow], path: str | Path) -> Path:
    """Write rows as a BOP results CSV (R row-major, t in mm, time in s)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    lines = [",".join(RESULT_FIELDS)]
    for r in rows:
        R = " ".join(f"{v:.9g}" for v in np.asarray(r.R).reshape(-1))
        t = " ".join(f"{v:.6f}" for v in np.asarray(r.t).reshape(-1) * 1000.0)
        lines.append(f"{r.scene_id},{r.im_id},{r.obj_id},{r.score:.6f},{R},{t},{r.time:.6f}")
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text("\n".join(lines) + "\n")
    tmp.replace(path)
    return path
