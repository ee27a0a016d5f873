"""Run a hybrid method over a dataset split and write BOP-format results (``sixdpose register``).

The rows are :class:`~sixdpose.artifacts.poses.PoseEstimate` and go to a BOP results CSV
(:func:`~sixdpose.artifacts.poses.write_results`). ``time`` is the seconds spent on the whole image
(every instance, every step but disk reads). An instance whose input is unusable gets a row with score
0 (identity pose) and its reason is logged; so does one whose computation raised or warned (a numpy
``RuntimeWarning`` from a zero ``cam_K``, say: the warning becomes the row's reason, not stderr noise).

Repeatable: every random choice of an instance (Open3D's RANSAC and FGR, Super4PCS, the colour search)
is seeded from :func:`instance_seed` (the run's seed and the instance's scene, image, object and
detection index), and Open3D runs on one thread (its parallel RANSAC is not repeatable otherwise), so
the same seed and arguments give the same estimates whatever the number of workers, their order or the
machine's load; only the times differ.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import os
import time
import warnings
from pathlib import Path

import numpy as np

from ..artifacts.journal import ImageJournal
from ..artifacts.poses import PoseEstimate
from ..artifacts.predictions import check_predictions_dataset, read_predictions
from ..constants import MIN_DETECTION_SCORE
from ..datasets.base import DatasetError, DatasetReader, check_depth_scale
from ..datasets.readers import as_reader
from ..errors import SixdposeError
from .presets import RegistrationConfig

log = logging.getLogger(__name__)


class RegistrationError(SixdposeError):
    """The hybrid stage cannot run on this input (no depth, no masks, unknown method ...)."""


# ------------------------------------------------------------------------------------------
# per-image work (runs in the worker processes)
# ------------------------------------------------------------------------------------------
_W: dict = {}
_REISSUED: dict = {}  # warnings registry of the non-numeric warnings passed on (each shown once per place)


def instance_seed(seed: int, scene_id: int, im_id: int, obj_id: int, k: int) -> int:
    """The random seed of one instance: a hash of the run's ``seed`` and the instance's ids.

    Args:
        seed: the run's seed (``RegistrationConfig.seed``, ``register --seed``), >= 0.
        scene_id, im_id, obj_id: the instance's scene, image and object ids (>= 0).
        k: its index among the image's detections (GT instances or predictions), >= 0.
    Returns:
        an int in ``[0, 2**31)`` (Open3D's seed is a C ``int``), independent of the worker that
        registers the instance and of the order of the images.
    """
    state = np.random.SeedSequence([int(seed), int(scene_id), int(im_id), int(obj_id), int(k)]).generate_state(1)
    return int(state[0]) & 0x7FFFFFFF


def _open3d_threads(n: int) -> bool:
    """Limit Open3D to ``n`` threads (0: its automatic default); False if this Open3D cannot (< 0.20,
    whose OpenMP threads follow ``OMP_NUM_THREADS`` at start-up instead)."""
    import open3d as o3d

    setter = getattr(o3d.utility, "set_max_threads", None)
    if setter is None:
        return False
    setter(n)
    return True


@contextlib.contextmanager
def _one_thread():
    """Open3D on one thread in this process while the block runs (the in-process ``workers=1`` run)."""
    if not _open3d_threads(1):
        log.warning("this Open3D has no set_max_threads: RANSAC/FGR may differ from run to run with --workers 1")
        yield
        return
    try:
        yield
    finally:
        _open3d_threads(0)


def _init_pool_worker(*args) -> None:
    """Initializer of the pool workers (after ``workers.init_worker``, which ``process_pool`` runs first:
    die with the parent, leave Ctrl-C to it): one Open3D thread."""
    _open3d_threads(1)
    _init_worker(*args)


def _init_worker(ds: DatasetReader, method: str, icp: bool, cfg: RegistrationConfig, masks: str, min_px: int,
                 min_score: float) -> None:
    from .geometry import ReferenceCache

    _W.update(
        ds=ds,
        cache=ReferenceCache(ds),
        method=method,
        icp=icp,
        cfg=cfg,
        masks=masks,
        min_px=min_px,
        min_score=min_score,
    )
    if _W["cfg"].colour_verify:
        from .verify import warmup

        warmup()  # compile (or load from the on-disk cache) the Numba kernel now: a start-up cost, like imports
    if _W["cfg"].verify:
        from .hypotheses import warmup as warmup_verify

        warmup_verify()


def process_image(index: int) -> tuple[list[PoseEstimate], tuple | None, float]:
    """Register every instance of image ``index`` of the worker's dataset (see :func:`run_registration`).

    Returns:
        ``(rows, failure, onboarding_s)``: the image's rows, ``None`` or ``(scene_id, im_id, reason)`` when
        the image itself could not be used (unreadable image files or predictions; the run goes on), and the
        seconds of object onboarding (first-use model-side data,
        :class:`~sixdpose.registration.geometry.ReferenceCache`) this image triggered. The rows' ``time``
        (the image's) leaves disk reads and that onboarding out.
    """
    from ..artifacts.predictions import PredictionError
    from .geometry import backproject
    from .methods import estimate_pose

    ds, cache, cfg = _W["ds"], _W["cache"], _W["cfg"]
    method, icp, masks, min_px = _W["method"], _W["icp"], _W["masks"], _W["min_px"]
    pred = masks != "gt"
    try:
        sample = ds[index]  # disk reads: not timed
        if pred:
            dets = [(d.obj_id, d.score, d.mask) for d in read_predictions(masks, sample.scene_id, sample.im_id)
                    if d.score >= _W["min_score"]]
        else:
            dets = [(i.obj_id, 1.0, i.mask) for i in sample.instances if i.px_visib < 0 or i.px_visib >= min_px]
    except (DatasetError, PredictionError) as e:
        key = ds.keys()[index]
        log.warning("scene %d image %d skipped: %s", key[0], key[1], e)
        return [], (int(key[0]), int(key[1]), str(e)), 0.0
    known = set(ds.object_ids)
    # models are read from disk outside the timed section; an unreadable model fails its instances only
    bad_model: dict[int, str] = {}
    for oid in {d[0] for d in dets if d[0] in known}:
        try:
            ds.model(oid)
        except DatasetError as e:
            bad_model[oid] = f"model unreadable ({e})"
    rows: list[PoseEstimate] = []
    inst_time: list[float] = []
    onboarded = cache.onboarding_s
    for k, (oid, det_score, mask) in enumerate(dets):
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
        elif not _valid_K(sample.K):
            reason = "invalid cam_K (fx and fy must be finite and non-zero)"
        est = None
        if not reason:
            if np.isnan(sample.depth[mask]).any():
                log.debug("scene %d image %d obj %d: NaN depth values ignored", sample.scene_id, sample.im_id, oid)
            cfg_k = dataclasses.replace(cfg, seed=instance_seed(cfg.seed, sample.scene_id, sample.im_id, oid, k))
            error = None
            with warnings.catch_warnings(record=True) as caught, np.errstate(all="warn", under="ignore"):
                warnings.simplefilter("always")
                try:
                    rgb_ok = sample.rgb is not None and sample.rgb.shape[:2] == mask.shape
                    use_rgb = cfg.colour_verify and rgb_ok
                    pts, col, _ = backproject(sample.depth, sample.K, mask, sample.rgb if use_rgb else None)
                    frame = None
                    if cfg.verify:
                        from .hypotheses import Frame

                        frame = Frame(sample.depth, sample.K, mask, sample.rgb if rgb_ok else None)
                    if len(pts) < 3:
                        reason = f"mask has {len(pts)} valid depth points (< 3)"
                    else:
                        est = estimate_pose(pts, oid, method, cache, cfg_k, icp=icp, colors=col, frame=frame)
                except Exception as e:  # a numerical failure or unreadable model in one instance must not stop the run
                    error = e
            # a numeric warning (numpy's RuntimeWarning: division by zero, invalid value, ...) fails the
            # instance and is its reason (it is also the likely cause of an error that followed); other
            # warnings are passed on as they were
            numeric = [w for w in caught if issubclass(w.category, RuntimeWarning)]
            for w in caught:
                if w not in numeric:
                    warnings.warn_explicit(w.message, w.category, w.filename, w.lineno, registry=_REISSUED)
            if numeric and not reason:
                reason, est = f"numerical warning: {numeric[0].message}", None
            elif error is not None:
                log.warning("scene %d image %d obj %d: registration failed (%s); score 0", sample.scene_id,
                            sample.im_id, oid, error)
                rows.append(PoseEstimate.failed(sample.scene_id, sample.im_id, oid, f"error: {error}"))
                inst_time.append(time.perf_counter() - t0)
                continue
            if est is not None and not np.isfinite(est.X_CO).all():
                reason, est = "non-finite pose", None
        if reason:
            log.warning("scene %d image %d obj %d: %s; score 0", sample.scene_id, sample.im_id, oid, reason)
            rows.append(PoseEstimate.failed(sample.scene_id, sample.im_id, oid, reason))
            inst_time.append(time.perf_counter() - t0)
            continue
        assert est is not None
        bp_time = time.perf_counter() - t0 - est.time  # backprojection etc. (est.time measured inside)
        score = est.score * det_score if pred else est.score
        rows.append(
            PoseEstimate(
                sample.scene_id, sample.im_id, oid, float(score), est.X_CO[:3, :3].copy(), est.X_CO[:3, 3].copy()
            )
        )
        inst_time.append(est.time + max(bp_time, 0.0))
    onboarded = cache.onboarding_s - onboarded
    total = max(sum(inst_time) - onboarded, 0.0)
    for r in rows:
        r.time = total
    return rows, None, onboarded


# ------------------------------------------------------------------------------------------
# driver
# ------------------------------------------------------------------------------------------
def _valid_K(K) -> bool:
    """True if the intrinsics ``K`` (3, 3) have finite, non-zero focal lengths and a finite centre."""
    K = np.asarray(K, dtype=np.float64)
    return K.shape == (3, 3) and bool(np.isfinite(K).all()) and K[0, 0] != 0 and K[1, 1] != 0


def check_inputs(ds: DatasetReader, masks: str) -> None:
    """Fail early with one clear line if the split cannot be registered (no depth, no masks).

    Raises:
        RegistrationError: no images, no depth, no GT masks (with ``masks="gt"``), or a missing
            prediction directory. PredictionError: predicted masks made on another dataset. DatasetError: the
            depth looks wrongly scaled (:func:`~sixdpose.datasets.base.check_depth_scale`).
    """
    if len(ds) == 0:
        raise RegistrationError(f"{ds.location}: the dataset split has no images")
    if not ds.has_depth:
        raise RegistrationError(
            f"{ds.location}: this split has no depth images (depth/ missing); the hybrid methods need depth"
        )
    if masks == "gt":
        if not ds.has_masks:
            raise RegistrationError(
                f"{ds.location}: this split has no ground-truth masks (mask_visib/); pass --masks PRED_DIR"
            )
    elif not Path(masks).is_dir():
        raise RegistrationError(f"{masks}: predicted-mask directory not found")
    else:
        check_predictions_dataset(masks, ds)  # masks of another dataset are refused
    if ds.has_masks:
        check_depth_scale(ds)  # a wrong depth unit would give silently wrong poses


def run_registration(
    data: str | Path | DatasetReader,
    method: str,
    icp: bool = False,
    masks: str = "gt",
    split: str = "test",
    cfg: RegistrationConfig | None = None,
    workers: int = 2,
    limit: int | None = None,
    min_px: int = 0,
    min_score: float = MIN_DETECTION_SCORE,
    progress: bool = True,
    indices=None,
    failures: list | None = None,
    timing: dict | None = None,
    journal: ImageJournal | None = None,
) -> list[PoseEstimate]:
    """Register every instance of every image of ``data`` (a synthetic or BOP dataset).

    Args:
        data: a :class:`~sixdpose.datasets.base.DatasetReader` or a dataset directory.
        method: ``ransac`` | ``fgr`` | ``super4pcs``. icp: refine with ICP.
        masks: ``"gt"`` or a directory of predicted masks (:mod:`sixdpose.artifacts.predictions`).
        split: BOP split (when ``data`` is a path; ignored for the synthetic layout).
        cfg: configuration (default: the ``default`` preset).
        workers: processes (a pool over images; 1 = in this process). Each worker uses one thread and
            receives a copy of the reader; workers die with this process and ignore Ctrl-C (this
            process's ``KeyboardInterrupt`` terminates them). The rows do not depend on ``workers``.
        limit: only the first ``limit`` images. min_px: with GT masks, skip instances with fewer
            visible pixels (0: register all). min_score: with predicted masks, skip detections scoring
            below this. progress: tqdm bar. indices: explicit image indices.
        failures: if a list, receives ``(scene_id, im_id, reason)`` for every image that could not be
            read (corrupt RGB/depth/mask files or predictions); such images are logged and skipped.
        timing: if a dict, receives ``onboarding_s``: the seconds all processes spent onboarding objects
            (building their model-side data on first use), which the rows' per-image ``time`` leaves out.
        journal: an :class:`~sixdpose.artifacts.journal.ImageJournal` (not yet opened): the images it
            already holds are taken from it, not registered again, and every image finished here is added
            to it as it finishes, so a stopped run resumes (``register`` keeps it beside ``--out``). It is
            left open for the caller to remove once the results are written (or closed on an error).
    Returns:
        one :class:`~sixdpose.artifacts.poses.PoseEstimate` per instance (per prediction with
        predicted masks), in image order.
    Raises:
        RegistrationError: unknown method or unusable split (see :func:`check_inputs`).
    """
    from tqdm import tqdm

    from .methods import METHODS
    from .presets import PRESETS

    if method not in METHODS:
        raise RegistrationError(f"unknown method {method!r} (choose from {', '.join(METHODS)})")
    cfg = cfg or PRESETS["default"]
    ds = as_reader(data, split=split)
    check_inputs(ds, masks)
    idx = list(range(len(ds))) if indices is None else list(indices)
    if limit is not None:
        idx = idx[:limit]
    args = (ds, method, icp, cfg, str(masks), int(min_px), float(min_score))
    done: dict[int, tuple] = {}
    if journal is not None:
        journal.open(keep=idx)  # entries of other images are not kept
        done = dict(journal.done)
    pending = [i for i in idx if i not in done]
    bar = tqdm(total=len(idx), initial=len(done), desc=f"register {method}{'+icp' if icp else ''}", unit="img",
               disable=not progress)

    def finished(i: int, out: tuple) -> None:
        done[i] = out
        if journal is not None:
            journal.add(i, *out)
        bar.update()

    try:
        _register_pending(args, pending, workers, finished)
    finally:
        bar.close()
        if journal is not None:
            journal.close()
    rows: list[PoseEstimate] = []
    bad_images: list[tuple] = []
    onboarding = 0.0
    for i in idx:
        r, fail, onb = done[i]
        rows.extend(r)
        onboarding += onb
        if fail:
            bad_images.append(tuple(fail))
    n_fail = sum(1 for r in rows if r.reason)
    if n_fail:
        log.warning("%d of %d instances had unusable input or failed (score 0)", n_fail, len(rows))
    if bad_images:
        log.warning("%d of %d images could not be read and were skipped", len(bad_images), len(idx))
    if failures is not None:
        failures.extend(bad_images)
    if timing is not None:
        timing["onboarding_s"] = onboarding
    return rows


def _register_pending(args: tuple, pending: list[int], workers: int, finished) -> None:
    """Register images ``pending`` (indices) in this process (``workers <= 1``) or a pool, calling
    ``finished(i, (rows, failure, onboarding_s))`` for each in order as it completes."""
    if not pending:
        return
    if workers <= 1 or len(pending) <= 1:
        _init_worker(*args)
        with _one_thread():
            for i in pending:
                finished(i, process_image(i))
        return
    from ..workers import process_pool

    # one thread per worker (Open3D: set_max_threads in the initializer; OpenMP, BLAS: the
    # environment, which spawned children inherit)
    saved = {k: os.environ.get(k) for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}
    for k in saved:
        os.environ[k] = "1"
    try:
        # leaving the block by an exception (also KeyboardInterrupt) terminates the workers
        with process_pool(workers, _init_pool_worker, args) as pool:
            for i, out in zip(pending, pool.imap(process_image, pending, chunksize=1), strict=True):
                finished(i, out)
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
