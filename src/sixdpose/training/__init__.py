"""One training engine for every network: :func:`~.engine.train` runs a :class:`~.engine.TrainTask`
(see :mod:`.engine`); :class:`~.schedule.TrainSchedule` is the schedule every training config derives
from; :mod:`.rundir` keeps the run directory (status, data fingerprint, resume hygiene, metrics).

Names are imported lazily, so that the configs (which derive from :class:`~.schedule.TrainSchedule`)
and the CLI parser do not import torch.
"""

from ..lazy import by_module, lazy_getattr

_LAZY = by_module(
    engine=("StepContext", "TrainTask", "ensure_trained", "shard", "train"),
    rundir=("TrainingError", "data_fingerprint", "read_metrics", "read_status"),
    schedule=("RESUMABLE", "TrainSchedule", "learning_rate"),
)


__getattr__ = lazy_getattr(__name__, _LAZY)  # lazy, so that building the CLI parser does not import torch


__all__ = sorted(_LAZY)
