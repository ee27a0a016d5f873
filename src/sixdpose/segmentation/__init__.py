"""Instance segmentation with Mask R-CNN (paper sections II-B and IV-A).

Stage commands (see :mod:`.cli`)::

    sixdpose train-seg --data DIR --out RUN_DIR [--profile smoke|paper] [--resume]
    sixdpose segment   --data DIR --ckpt RUN_DIR --out PRED_DIR [--subset all|train|test]
    sixdpose eval-seg  --data DIR --pred PRED_DIR [--figures figures/]

Modules: :mod:`.config` (typed config, profiles ``smoke``/``paper``), :mod:`.model` (torchvision Mask
R-CNN, ResNet-FPN), :mod:`.data` (class map, split, scan of bad annotations, augmentation),
:mod:`.train` (training loop, checkpoints, resume, DDP, AMP), :mod:`.infer` (inference),
:mod:`.evaluate` (COCO mask/box AP).

Prediction format (agreed with the registration stage, ``--masks PRED_DIR``)
-----------------------------------------------------------------------------
For every segmented image, ``PRED_DIR/<scene_id>_<im_id>.npz`` (plain decimal integers, e.g.
``0_12.npz``; see :func:`pred_path`), written with ``numpy.savez_compressed``, holding:

``masks``  (N, H, W) bool
    visible mask of each detection at the full input image resolution (mask probability > 0.5).
``labels`` (N,) int32
    dataset object id (``obj_id`` of :class:`~sixdpose.datasets.Instance`), not a network class index.
``scores`` (N,) float32
    detection confidence in [0, 1]; detections are sorted by decreasing score and include every
    detection above the run's ``score_thresh`` (0.05, so AP sees the whole precision-recall curve):
    consumers should apply their own threshold (0.5 is a sensible default).

N may be 0 (arrays of shape (0, H, W), (0,), (0,)). Read with :func:`load_prediction`.
``PRED_DIR/coco_results.json`` holds the same detections as COCO results (RLE masks, ``category_id`` =
obj id, ``image_id`` = :func:`coco_image_id`), and ``PRED_DIR/meta.json`` the checkpoint, classes and
list of images.
"""

import importlib

_LAZY = {
    "PROFILES": "config",
    "SegConfig": "config",
    "profile_config": "config",
    "Segmenter": "infer",
    "coco_image_id": "infer",
    "load_prediction": "infer",
    "pred_path": "infer",
    "segment": "infer",
}


def __getattr__(name):  # lazy, so that building the CLI parser does not import torch
    if name in _LAZY:
        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "PROFILES",
    "SegConfig",
    "Segmenter",
    "coco_image_id",
    "load_prediction",
    "pred_path",
    "profile_config",
    "segment",
]
