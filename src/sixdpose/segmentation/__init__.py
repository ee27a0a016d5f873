"""Instance segmentation with Mask R-CNN (paper sections II-B and IV-A).

Stage commands (see :mod:`.cli`)::

    sixdpose train-seg --data DIR --out RUN_DIR [--profile smoke|paper] [--resume]
    sixdpose segment   --data DIR --seg RUN_DIR --out PRED_DIR [--subset all|train|test]
    sixdpose eval-seg  --data DIR --masks PRED_DIR [--figures figures/]

Modules: :mod:`.config` (typed config, profiles ``smoke``/``paper``), :mod:`.model` (torchvision Mask
R-CNN, ResNet- or MobileNetV3-FPN), :mod:`.data` (class map, split, scan of bad annotations, augmentation),
:mod:`.train` (training loop, checkpoints, resume, DDP, AMP), :mod:`.infer` (inference),
:mod:`.evaluate` (COCO mask/box AP).

Output: ``segment`` writes the predicted-masks artifact, :mod:`sixdpose.artifacts.predictions` (its
format, writer and reader), read by the pose stages with ``--masks PRED_DIR``.
"""

from ..lazy import by_module, lazy_getattr

_LAZY = by_module(
    config=("PROFILES", "SegConfig", "profile_config"),
    infer=("Segmenter", "coco_image_id", "segment"),
)


__getattr__ = lazy_getattr(__name__, _LAZY)  # lazy, so that building the CLI parser does not import torch


__all__ = [
    "PROFILES",
    "SegConfig",
    "Segmenter",
    "coco_image_id",
    "profile_config",
    "segment",
]
