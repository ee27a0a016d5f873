"""Training-run plumbing shared by the networks' stages (segmentation, learned pose): devices and
process groups, atomic checkpoints with every RNG state and the per-epoch ``metrics.csv``.
Each stage keeps its own checkpoint format and errors; this module holds the mechanics once.
"""

from __future__ import annotations

import contextlib
import csv
import logging
import os
import random
from datetime import timedelta
from pathlib import Path

import numpy as np
import torch

from .errors import SixdposeError
from .fileio import atomic_path

#: Checkpoint file names of a run directory: resumable state after each epoch, and the final model.
LAST = "last.pt"
FINAL = "model.pt"

log = logging.getLogger("sixdpose.runs")


class RunError(SixdposeError):
    """A run cannot use the requested device or read its checkpoint."""


def dist_info() -> tuple[int, int, int]:
    """``(world size, rank, local rank)`` from torchrun's environment (1, 0, 0 without torchrun)."""
    return (
        int(os.environ.get("WORLD_SIZE", "1")),
        int(os.environ.get("RANK", "0")),
        int(os.environ.get("LOCAL_RANK", "0")),
    )


def pick_device(name: str | None = None, local_rank: int = 0) -> torch.device:
    """``name`` if given (``cpu``, ``cuda``, ``cuda:1``), else the local GPU when present, else CPU.

    Raises:
        RunError: CUDA requested but not available.
    """
    if name and name != "auto":
        dev = torch.device(name)
        if dev.type == "cuda" and not torch.cuda.is_available():
            raise RunError(f"device {name!r} requested but CUDA is not available")
        if dev.type == "cuda" and dev.index is None:
            dev = torch.device("cuda", local_rank)
        return dev
    return torch.device("cuda", local_rank) if torch.cuda.is_available() else torch.device("cpu")


@contextlib.contextmanager
def process_group(device: str | None, timeout_hours: float = 1.0):
    """Pick this process's device and, under torchrun, join the process group (NCCL on GPUs, gloo on
    CPUs) for the duration of the block. Yields ``(device, world size, rank)``."""
    import torch.distributed as dist

    world, rank, local_rank = dist_info()
    dev = pick_device(device, local_rank)
    if dev.type == "cuda":
        torch.cuda.set_device(dev)
    joined = world > 1 and not dist.is_initialized()
    if joined:
        dist.init_process_group("nccl" if dev.type == "cuda" else "gloo", timeout=timedelta(hours=timeout_hours))
    try:
        yield dev, world, rank
    finally:
        if joined and dist.is_initialized():
            dist.destroy_process_group()


def save_checkpoint(obj: dict, path: str | Path) -> None:
    """``torch.save`` to a temporary file beside ``path``, fsync, then rename (never half-written)."""
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        torch.save(obj, f)
        f.flush()
        os.fsync(f.fileno())


def resolve_checkpoint(path: str | Path, error=RunError) -> Path:
    """The checkpoint file of ``path``: the file itself, or :data:`FINAL` (else :data:`LAST`) of a run
    directory. Raises ``error`` (a :class:`~sixdpose.errors.SixdposeError` subclass) naming the path."""
    path = Path(path)
    if path.is_dir():
        for name in (FINAL, LAST):
            if (path / name).is_file():
                return path / name
        raise error(f"{path}: no {FINAL} or {LAST} in this run directory (training not run or not finished an epoch)")
    if not path.exists():
        raise error(f"{path}: checkpoint not found")
    return path


def load_checkpoint(
    path: str | Path, fmt: str, version: int, required: tuple[str, ...], what: str, error=RunError
) -> dict:
    """Read a checkpoint (file or run directory) onto the CPU and check its format tag, version and keys.

    Args:
        fmt: the expected ``format`` entry. version: the expected ``version``. required: keys it must
        have. what: words for messages (``"segmentation"``). error: exception class to raise.
    A run directory without :data:`FINAL` (an unfinished run) is used through its :data:`LAST` with one
    warning line naming its last completed epoch.

    Raises:
        ``error``: missing, corrupt, another format or version, or incomplete (the message names the file).
    """
    run_dir = Path(path) if Path(path).is_dir() else None
    path = resolve_checkpoint(path, error)
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # noqa: BLE001 - truncated zip, pickle garbage, ...
        msg = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise error(f"{path}: corrupt or unreadable checkpoint ({msg[:200]})") from None
    if not isinstance(ckpt, dict) or ckpt.get("format") != fmt:
        raise error(f"{path}: not a sixdpose {what} checkpoint")
    if ckpt.get("version") != version:
        raise error(f"{path}: checkpoint format version {ckpt.get('version')} is not supported (expected {version})")
    for key in required:
        if key not in ckpt:
            raise error(f"{path}: incomplete checkpoint (no {key!r})")
    if run_dir is not None and path.name == LAST and dist_info()[1] == 0:  # said once, by rank 0
        planned = ckpt.get("config", {}).get("epochs") if isinstance(ckpt.get("config"), dict) else None
        log.warning("%s: unfinished run (no %s; last completed epoch %s%s): using its %s", run_dir, FINAL,
                    ckpt.get("epoch"), f" of {planned}" if planned else "", LAST)
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


def append_metrics(path: str | Path, rows: list[dict], fields) -> None:
    """Append rows to a run's ``metrics.csv`` (header ``fields`` written with the first rows)."""
    path = Path(path)
    new = not path.exists()
    with open(path, "a", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(fields))
        if new:
            w.writeheader()
        w.writerows(rows)


def truncate_metrics(path: str | Path, from_epoch: int, fields) -> None:
    """Drop the rows of epochs ``>= from_epoch`` (they are redone after a resume); atomic."""
    path = Path(path)
    if not path.exists():
        return
    with open(path, newline="") as f:
        rows = [r for r in csv.DictReader(f) if int(r["epoch"]) < from_epoch]
    with atomic_path(path) as tmp, open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(fields))
        w.writeheader()
        w.writerows(rows)
