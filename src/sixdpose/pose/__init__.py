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

from ..lazy import by_module, lazy_getattr

_LAZY = by_module(
    config=("PROFILES", "REFINER_PROFILES", "PoseConfig", "RefinerConfig"),
    model=("PoseNet", "Refiner", "PSPNet"),
    loss=("pose_loss",),
    data=("PoseError",),
    checkpoint=("CheckpointError",),
    infer=("Estimator", "predict_dataset"),
    train=("train_pose", "train_refiner", "ensure_trained"),
    ablation=("run_ablation",),
)


__getattr__ = lazy_getattr(__name__, _LAZY)  # lazy, so that building the CLI parser does not import torch


__all__ = sorted(_LAZY)
