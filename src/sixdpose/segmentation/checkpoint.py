"""Checkpoint files of a segmentation run: atomic writes, validated reads.

``RUN_DIR/last.pt`` (rewritten after every epoch) holds everything needed to resume: model,
optimizer, AMP grad-scaler, global step and the RNG states of every process. ``RUN_DIR/model.pt``
(written when training finishes) holds the weights and what inference needs. Both are plain
dictionaries readable with ``torch.load(..., weights_only=True)``::

    format: "sixdpose-seg"     version: CHECKPOINT_VERSION
    config: SegConfig.to_dict()   classes: [[obj_id, name], ...]   init: "imagenet" | "random"
    epoch: completed epochs        global_step, elapsed (training seconds)     model: state_dict
    (last.pt only) optimizer, scaler, rng: [per-rank state], world_size
    (runs of older versions also have a ``scheduler`` entry, ignored: the learning rate is a function
    of epoch and step, :func:`sixdpose.training.learning_rate`)
"""

from __future__ import annotations

from pathlib import Path

from ..errors import SixdposeError
from ..runs import FINAL, LAST, load_checkpoint, resolve_checkpoint  # noqa: F401  (FINAL, LAST re-exported)

FORMAT = "sixdpose-seg"
CHECKPOINT_VERSION = 1


class CheckpointError(SixdposeError):
    """A checkpoint is missing, corrupt, or not compatible with this code or dataset."""


def header(cfg, classes: list, init: str) -> dict:
    """The fields every segmentation checkpoint starts with: format, version, ``config``
    (:class:`~sixdpose.segmentation.config.SegConfig`), ``classes`` ``[[obj_id, name], ...]`` and ``init``
    (``imagenet`` | ``random``). The training task and the benchmarks' untrained checkpoints both use it."""
    return {"format": FORMAT, "version": CHECKPOINT_VERSION, "config": cfg.to_dict(),
            "classes": [list(c) for c in classes], "init": init}


def weights(cfg, classes: list, init: str, state_dict: dict, epoch: int = 0, global_step: int = 0,
            elapsed: float = 0.0) -> dict:
    """A complete ``model.pt`` checkpoint (:func:`header` plus weights and counters) for a network that was
    not trained by :func:`~sixdpose.segmentation.train.train` (an untrained one timed by the benchmarks)."""
    return {**header(cfg, classes, init), "epoch": int(epoch), "global_step": int(global_step),
            "elapsed": float(elapsed), "model": state_dict}


def load(path: str | Path) -> dict:
    """Read and validate a segmentation checkpoint (file or run directory) onto the CPU.

    Raises:
        CheckpointError: missing, unreadable/corrupt, not a sixdpose segmentation checkpoint, or of
            another format version.
    """
    return load_checkpoint(path, FORMAT, CHECKPOINT_VERSION, ("config", "classes", "model", "epoch"), "segmentation",
                           CheckpointError)


def resolve(path: str | Path) -> Path:
    """The checkpoint file of ``path`` (a file, or ``model.pt`` else ``last.pt`` of a run directory)."""
    return resolve_checkpoint(path, CheckpointError)
