"""The files of the ``make reproduce`` graph (mk/reproduce.mk) that the notebooks read.

The notebooks never generate a dataset, train a network or write a result of record: make does, one
command per file (``sixdpose generate``, ``train-seg``, ``train-pose``, ``train-refiner``, ``segment``,
``pose-ablation``, ``evaluate``), and a notebook shows what those commands wrote. When a file is missing
the notebook stops with one line that names the make target building it, e.g.::

    the pose network runs/smoke/pose/model.pt is missing: `make runs/smoke/pose/model.pt PROFILE=smoke` makes it
"""

from __future__ import annotations

import os
from pathlib import Path

from .errors import SixdposeError

#: The makefile of the graph; the repository root is the first ancestor of the working directory holding it.
GRAPH_FILE = Path("mk") / "reproduce.mk"


class MissingInputError(SixdposeError, FileNotFoundError):
    """A file the make graph writes (dataset, trained run, predictions, result) is not there yet."""


def repo_root(start: str | os.PathLike | None = None) -> Path | None:
    """The first directory from ``start`` (default: the working directory) upwards that holds
    :data:`GRAPH_FILE`, or None."""
    d = Path(start or Path.cwd()).resolve()
    for p in (d, *d.parents):
        if (p / GRAPH_FILE).is_file():
            return p
    return None


def make_target(path: str | os.PathLike) -> str:
    """``path`` as a make target: relative to :func:`repo_root` when it lies inside the repository
    (``../runs/cpu/pose/model.pt`` from ``notebooks/`` is ``runs/cpu/pose/model.pt``), else unchanged."""
    root = repo_root()
    p = Path(path).resolve()
    if root is not None and p.is_relative_to(root):
        return p.relative_to(root).as_posix()
    return str(path)


def require(path: str | os.PathLike, what: str, profile: str | None = None) -> Path:
    """Return ``path`` if it exists; otherwise raise :class:`MissingInputError` naming the make target.

    Args:
        path: a file of the graph (a ``manifest.json``, ``model.pt``, ``meta.json`` or result ``.json``).
        what: what the file is, for the message (``"the pose network"``).
        profile: the ``PROFILE`` of the make command in the message (None: not given).
    """
    path = Path(path)
    if path.exists():
        return path
    cmd = f"make {make_target(path)}" + (f" PROFILE={profile}" if profile else "")
    raise MissingInputError(f"{what} {path} is missing: `{cmd}` makes it (or `make reproduce"
                            f"{f' PROFILE={profile}' if profile else ''}`, the whole graph)")


def require_dataset(path: str | os.PathLike, profile: str | None = None) -> Path:
    """Return the dataset directory ``path`` once ``sixdpose generate`` has completed it
    (``path/manifest.json``, written last); see :func:`require`."""
    require(Path(path) / "manifest.json", "the dataset", profile)
    return Path(path)


def require_run(run_dir: str | os.PathLike, profile: str | None = None, what: str = "the trained network") -> Path:
    """Return the run directory ``run_dir`` once training has finished (``run_dir/model.pt``, written
    last by train-seg / train-pose / train-refiner); see :func:`require`."""
    require(Path(run_dir) / "model.pt", what, profile)
    return Path(run_dir)


def training_data(profile: str, data: str | None = None, test_data: str | None = None) -> tuple[str, str]:
    """The training and held-out dataset directories of a training notebook (05, 06), relative to
    ``notebooks/``, where the notebook's parameters leave them None.

    Args:
        profile: the graph profile (smoke, demo, cpu, paper).
        data: the training data; None: ``$SIXDPOSE_DATA``, else ``../data/<generator profile>`` (the
            cpu profile trains on ``../data/train``).
        test_data: the held-out data; None: the training data for smoke and demo (a pipeline check),
            else ``../data/test``.
    Returns:
        ``(data, test_data)``.
    """
    gen_profile = {"cpu": "train"}.get(profile, profile)
    data = data or os.environ.get("SIXDPOSE_DATA") or f"../data/{gen_profile}"
    return data, test_data or (data if profile in ("smoke", "demo") else "../data/test")
