"""Predicted instance masks: the segmentation stage's output, read by the pose stages.

Layout of a prediction directory ``P`` (written by ``sixdpose segment``)::

    P/<scene_id>_<im_id>.npz   per segmented image (plain decimal integers, e.g. ``0_12.npz``)
    P/meta.json                checkpoint, classes, score threshold, data, list of images
    P/coco_results.json        the same detections as COCO results (for pycocotools)

Each ``.npz`` (``numpy.savez_compressed``) holds

``masks``  (N, H, W) bool
    visible mask of each detection at the input image resolution.
``labels`` (N,) int32
    dataset object id (``obj_id``), not a network class index.
``scores`` (N,) float32
    detection confidence in [0, 1], sorted decreasing; every detection above the segmenter's
    ``score_thresh`` is kept, so consumers apply their own threshold (0.5 is sensible).
``boxes``  (N, 4) float32, optional
    ``x0, y0, x1, y1`` in pixels.

N may be 0. An image without a file had no detections (or was not segmented).
"""

from __future__ import annotations

import json
import logging
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import schemas
from ..errors import SixdposeError
from ..fileio import atomic_path, atomic_write_json

log = logging.getLogger(__name__)

_NAME = re.compile(r"^(\d+)_(\d+)\.npz$")


class PredictionError(SixdposeError):
    """A prediction file is unreadable or inconsistent (the message names the file)."""


@dataclass
class Detection:
    """One predicted instance: ``obj_id``, ``score`` in [0, 1], ``mask`` (H, W) bool, ``box`` (4,) or None."""

    obj_id: int
    score: float
    mask: np.ndarray
    box: np.ndarray | None = None


def prediction_path(pred_dir: str | Path, scene_id: int, im_id: int) -> Path:
    """Path of the prediction file of one image: ``pred_dir/<scene_id>_<im_id>.npz``."""
    return Path(pred_dir) / f"{int(scene_id)}_{int(im_id)}.npz"


def write_predictions(pred_dir: str | Path, scene_id: int, im_id: int, masks: np.ndarray, labels: np.ndarray,
                      scores: np.ndarray, boxes: np.ndarray | None = None) -> Path:
    """Write the detections of one image atomically (see the module docstring for the arrays)."""
    masks = np.asarray(masks, dtype=bool)
    labels = np.asarray(labels, dtype=np.int32).reshape(-1)
    scores = np.asarray(scores, dtype=np.float32).reshape(-1)
    n = len(labels)
    if masks.ndim != 3 or len(masks) != n or len(scores) != n:
        raise ValueError(f"expected masks (N,H,W), labels (N,), scores (N,); "
                         f"got {masks.shape}, {labels.shape}, {scores.shape}")
    arrays = {"masks": masks, "labels": labels, "scores": scores}
    if boxes is not None:
        arrays["boxes"] = np.asarray(boxes, dtype=np.float32).reshape(n, 4)
    path = prediction_path(pred_dir, scene_id, im_id)
    with atomic_path(path) as tmp:
        np.savez_compressed(tmp, **arrays)
    return path


def read_predictions(pred_dir: str | Path, scene_id: int, im_id: int) -> list[Detection]:
    """Read the detections of one image, sorted by decreasing score.

    Returns:
        a list of :class:`Detection`; empty if the image has no file (no detections).
    Raises:
        PredictionError: the file is unreadable, or its arrays are missing, inconsistent, or out of
            range (scores outside [0, 1], labels that are not integers).
    """
    path = prediction_path(pred_dir, scene_id, im_id)
    if not path.is_file():
        return []
    try:
        with np.load(path) as z:
            masks, labels, scores = z["masks"], z["labels"], z["scores"]
            boxes = z["boxes"] if "boxes" in z.files else None
    except KeyError as e:
        raise PredictionError(f"{path}: missing array {e}") from None
    except Exception as e:  # noqa: BLE001 - zip/pickle/OS errors of a corrupt file
        raise PredictionError(f"{path}: unreadable predictions ({e})") from None
    n = len(labels)
    if masks.ndim != 3 or labels.shape != (n,) or scores.shape != (n,) or len(masks) != n:
        raise PredictionError(f"{path}: expected masks (N,H,W), labels (N,), scores (N,); got "
                              f"{masks.shape}, {labels.shape}, {scores.shape}")
    if not np.isfinite(scores).all():
        raise PredictionError(f"{path}: non-finite scores")
    if n and not (scores.min() >= 0 and scores.max() <= 1):
        raise PredictionError(f"{path}: scores: expected confidences in [0, 1], got {scores.min():g} to "
                              f"{scores.max():g}")
    if not (np.issubdtype(labels.dtype, np.integer) or n == 0):
        raise PredictionError(f"{path}: labels: expected integer obj_ids, got dtype {labels.dtype}")
    order = np.argsort(-scores, kind="stable")
    return [Detection(int(labels[i]), float(scores[i]), masks[i].astype(bool, copy=False),
                      None if boxes is None else boxes[i]) for i in order]


def list_predictions(pred_dir: str | Path) -> list[tuple[int, int]]:
    """``(scene_id, im_id)`` of every prediction file in ``pred_dir``, sorted."""
    out = []
    for p in Path(pred_dir).glob("*.npz"):
        m = _NAME.match(p.name)
        if m:
            out.append((int(m.group(1)), int(m.group(2))))
    return sorted(out)


def write_predictions_meta(pred_dir: str | Path, meta: dict) -> Path:
    """Write ``pred_dir/meta.json`` (checkpoint, classes, score threshold, images ...)."""
    return atomic_write_json(Path(pred_dir) / "meta.json", meta)


def read_predictions_meta(pred_dir: str | Path, required: tuple[str, ...] = ()) -> dict:
    """Read ``pred_dir/meta.json`` (``{}`` if absent), checked against
    :class:`sixdpose.schemas.PredictionMeta`.

    Args:
        pred_dir: the prediction directory. required: fields that must be present (e.g. ``("classes",
            "images")``); with any, a missing ``meta.json`` is an error too.
    Raises:
        PredictionError: corrupt or truncated JSON, a field of the wrong type or range, or a required
            field missing (one line naming the file and the field).
    """
    p = Path(pred_dir) / "meta.json"
    if not p.is_file():
        if required:
            raise PredictionError(f"{p}: not a prediction directory of `sixdpose segment` (no meta.json)")
        return {}
    try:
        meta = json.loads(p.read_text())
    except (ValueError, OSError) as e:
        raise PredictionError(f"{p}: corrupt JSON ({e})") from None
    if not isinstance(meta, dict):
        raise PredictionError(f"{p}: expected a JSON object, got {type(meta).__name__}")
    checked = schemas.check(schemas.PredictionMeta, meta, p, PredictionError)
    for k in required:
        if getattr(checked, k, None) is None:
            raise PredictionError(f"{p}: missing field {k!r}")
    return meta


def read_coco_results(pred_dir: str | Path) -> list[dict] | None:
    """Read ``pred_dir/coco_results.json`` (None if absent), checked against
    :data:`sixdpose.schemas.COCO_RESULTS` (image_id, category_id, RLE segmentation, bbox, score in [0, 1]).

    Raises:
        PredictionError: corrupt or truncated JSON, or an entry that does not fit (names the entry and field).
    """
    p = Path(pred_dir) / "coco_results.json"
    if not p.is_file():
        return None
    try:
        data = json.loads(p.read_text())
    except (ValueError, OSError) as e:
        raise PredictionError(f"{p}: corrupt JSON ({e})") from None
    schemas.check(schemas.COCO_RESULTS, data, p, PredictionError, item="entry")
    return data


def check_predictions_dataset(pred_dir: str | Path, reader, meta: dict | None = None) -> None:
    """Refuse predicted masks made on another dataset (or split) than ``reader``'s.

    ``sixdpose segment`` records the fingerprint of the dataset split it segmented
    (:func:`sixdpose.datasets.readers.dataset_fingerprint`) in ``meta.json``; a consumer (register,
    predict-pose, train-pose, eval-seg) calls this before using the masks. A directory without
    ``meta.json``, or with one written before fingerprints were recorded, is accepted with a warning;
    a reader that has no fingerprint (not a BOP or synthetic reader) is not checked.

    ``meta``: the directory's ``meta.json`` when the caller has read it already (else it is read here).

    Raises:
        PredictionError: the fingerprints differ (the message names both datasets), or ``meta.json`` is
            corrupt.
    """
    from ..datasets.readers import dataset_fingerprint

    fp = dataset_fingerprint(reader)
    if fp is None:
        return
    if meta is None:
        meta = read_predictions_meta(pred_dir)
    made_on = meta.get("data", "an unknown dataset")
    if not meta:
        log.warning("%s: no meta.json; cannot check that these masks were predicted on %s", pred_dir, reader.location)
        return
    if meta.get("dataset_fingerprint") is None:
        log.warning("%s/meta.json has no dataset fingerprint (written by an older sixdpose); cannot check that these "
                    "masks were predicted on %s (meta.json says %s)", pred_dir, reader.location, made_on)
        return
    if meta["dataset_fingerprint"] != fp:
        split = f" (split {meta['split']})" if meta.get("split") else ""
        raise PredictionError(f"{pred_dir}: masks predicted on another dataset: {made_on}{split}, not "
                              f"{reader.location} (dataset fingerprints differ); run `sixdpose segment` on this "
                              "dataset")
