"""Checkpoint files of a segmentation run: atomic writes, validated reads.

``RUN_DIR/last.pt`` (rewritten after every epoch) holds everything needed to resume: model,
optimizer, LR scheduler, AMP grad-scaler and the RNG states of every process. ``RUN_DIR/model.pt``
(written when training finishes) holds the weights and what inference needs. Both are plain
dictionaries readable with ``torch.load(..., weights_only=True)``::

    format: "sixdpose-seg"     version: CHECKPOINT_VERSION
    config: SegConfig.to_dict()   classes: [[obj_id, name], ...]   init: "imagenet" | "random"
    epoch: completed epochs        model: state_dict
    (last.pt only) optimizer, scheduler, scaler, rng: [per-rank state], world_size
"""

from __future__ import annotations

from ..errors import SixdposeError
from ..fileio import atomic_path

import os
import random
from pathlib import Path

import numpy as np
import torch

FORMAT = "sixdpose-seg"
CHECKPOINT_VERSION = 1
LAST = "last.pt"
FINAL = "model.pt"


class CheckpointError(SixdposeError):
    """A checkpoint is missing, corrupt, or not compatible with this code or dataset."""


def save_atomic(obj: dict, path: str | Path) -> None:
    """``torch.save`` to a temporary file in the same directory, flush to disk, then rename."""
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        torch.save(obj, f)
        f.flush()
        os.fsync(f.fileno())


def resolve(path: str | Path) -> Path:
    """The checkpoint file of ``path``: the file itself, or ``model.pt`` (else ``last.pt``) of a run dir."""
    path = Path(path)
    if path.is_dir():
        for name in (FINAL, LAST):
            if (path / name).is_file():
                return path / name
        raise CheckpointError(f"{path}: no {FINAL} or {LAST} in this run directory (training not run or not finished an epoch)")
    if not path.exists():
        raise CheckpointError(f"{path}: checkpoint not found")
    return path


def load(path: str | Path) -> dict:
    """Read and validate a checkpoint (file or run directory) onto the CPU.

    Raises:
        CheckpointError: missing, unreadable/corrupt, not a sixdpose segmentation checkpoint, or of
            another format version.
    """
    path = resolve(path)
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # truncated zip, pickle garbage, ...
        msg = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise CheckpointError(f"{path}: corrupt or unreadable checkpoint ({msg[:200]})") from None
    if not isinstance(ckpt, dict) or ckpt.get("format") != FORMAT:
        raise CheckpointError(f"{path}: not a sixdpose segmentation checkpoint")
    if ckpt.get("version") != CHECKPOINT_VERSION:
        raise CheckpointError(
            f"{path}: checkpoint format version {ckpt.get('version')} is not supported (expected {CHECKPOINT_VERSION})"
        )
    for key in ("config", "classes", "model", "epoch"):
        if key not in ckpt:
            raise CheckpointError(f"{path}: incomplete checkpoint (no {key!r})")
    return ckpt


def rng_state() -> dict:
    """The RNG states of this process (torch CPU and CUDA, numpy, python)."""
    st = {
        "torch": torch.get_rng_state(),
        "numpy": [x.tolist() if isinstance(x, np.ndarray) else x for x in np.random.get_state()],
        "python": random.getstate(),
    }
    if torch.cuda.is_available():
        st["cuda"] = torch.cuda.get_rng_state_all()
    return st


def set_rng_state(st: dict) -> None:
    """Restore states captured by :func:`rng_state`."""
    torch.set_rng_state(st["torch"])
    npst = list(st["numpy"])
    npst[1] = np.asarray(npst[1], dtype=np.uint32)
    np.random.set_state(tuple(npst))
    py = st["python"]
    random.setstate((py[0], tuple(py[1]), py[2]))
    if "cuda" in st and torch.cuda.is_available() and len(st["cuda"]) == torch.cuda.device_count():
        torch.cuda.set_rng_state_all(st["cuda"])
