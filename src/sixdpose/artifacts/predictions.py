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
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import SixdposeError
from ..fileio import atomic_path, atomic_write_json

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
        raise ValueError(f"expected masks (N,H,W), labels (N,), scores (N,); got {masks.shape}, {labels.shape}, {scores.shape}")
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
        PredictionError: the file is unreadable, or its arrays are missing or inconsistent.
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


def read_predictions_meta(pred_dir: str | Path) -> dict:
    """Read ``pred_dir/meta.json`` (``{}`` if absent). Raises :class:`PredictionError` if corrupt."""
    p = Path(pred_dir) / "meta.json"
    if not p.is_file():
        return {}
    try:
        return json.loads(p.read_text())
    except ValueError as e:
        raise PredictionError(f"{p}: corrupt JSON ({e})") from None
