"""One training engine for every network: :func:`~.engine.train` runs a :class:`~.engine.TrainTask`
(see :mod:`.engine`); :class:`~.schedule.TrainSchedule` is the schedule every training config derives
from; :mod:`.rundir` keeps the run directory (status, data fingerprint, resume hygiene, metrics)."""

from .engine import StepContext, TrainTask, ensure_trained, shard, train
from .rundir import TrainingError, data_fingerprint, read_metrics, read_status
from .schedule import RESUMABLE, TrainSchedule, learning_rate

__all__ = ["RESUMABLE", "StepContext", "TrainSchedule", "TrainTask", "TrainingError", "data_fingerprint",
           "ensure_trained", "learning_rate", "read_metrics", "read_status", "shard", "train"]
