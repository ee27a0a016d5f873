"""The learned pose stage (paper section IV-C): DenseFusion-like network and iterative refiner.

Stage commands (see :mod:`.cli`)::

    sixdpose train-pose    --data DIR --out RUN [--profile smoke|cpu|paper] [--masks gt|PRED_DIR] [--val DIR] [--resume]
    sixdpose train-refiner --pose RUN --data DIR --out RUN2 [--profile ...] [--resume]
    sixdpose predict-pose  --data DIR --pose RUN [--refiner RUN2] [--iterations 2] [--masks gt|PRED_DIR]
                           [--icp] [--colour-verify] --out results.csv

Modules: :mod:`.config` (PoseConfig, RefinerConfig, profiles), :mod:`.model` (PSPNet, PoseNet,
Refiner), :mod:`.geometry` (quaternion / 6D, composition), :mod:`.loss` (ADD / chamfer), :mod:`.data`
(instance inputs), :mod:`.dense` (the project's dense head: object-coordinate targets under symmetries,
loss, RANSAC + weighted Kabsch; ``train-pose --set head=dense``), :mod:`.train`, :mod:`.checkpoint`,
:mod:`.infer` (Estimator).
"""

import importlib

_LAZY = {
    "PROFILES": "config",
    "REFINER_PROFILES": "config",
    "PoseConfig": "config",
    "RefinerConfig": "config",
    "PoseNet": "model",
    "Refiner": "model",
    "PSPNet": "model",
    "pose_loss": "loss",
    "PoseError": "data",
    "CheckpointError": "checkpoint",
    "Estimator": "infer",
    "predict_dataset": "infer",
    "train_pose": "train",
    "train_refiner": "train",
    "ensure_trained": "train",
    "run_ablation": "ablation",
}


def __getattr__(name):  # lazy, so that building the CLI parser does not import torch
    if name in _LAZY:
        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = sorted(_LAZY)
