"""One training engine for every network: :func:`~.engine.train` runs a :class:`~.engine.TrainTask`
(see :mod:`.engine`); :class:`~.schedule.TrainSchedule` is the schedule every training config derives
from; :mod:`.rundir` keeps the run directory (status, data fingerprint, resume hygiene, metrics).

Names are imported lazily, so that the configs (which derive from :class:`~.schedule.TrainSchedule`)
and the CLI parser do not import torch.
"""

import importlib

_LAZY = {
    "StepContext": "engine",
    "TrainTask": "engine",
    "ensure_trained": "engine",
    "shard": "engine",
    "train": "engine",
    "TrainingError": "rundir",
    "data_fingerprint": "rundir",
    "read_metrics": "rundir",
    "read_status": "rundir",
    "RESUMABLE": "schedule",
    "TrainSchedule": "schedule",
    "learning_rate": "schedule",
}


def __getattr__(name):
    if name in _LAZY:
        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = sorted(_LAZY)
