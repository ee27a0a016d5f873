"""Pose results: one :class:`PoseEstimate` type and the BOP 2019 results CSV that stores it.

Written by the hybrid stage (``sixdpose register``) and the learned stage (``sixdpose predict-pose``),
read by ``sixdpose evaluate``. Format (BOP challenge, https://bop.felk.cvut.cz/challenges/)::

    scene_id,im_id,obj_id,score,R,t,time

``R``: the 9 row-major entries of the rotation of ``X_CO`` separated by spaces; ``t``: translation of
``X_CO`` in **millimetres**; ``time``: seconds spent on the whole image (every instance, every step but
disk reads), repeated on each row of the image. In memory translations are metres. An instance whose
input was unusable has score 0 (identity pose); its ``reason`` is kept in memory and logged, not
written (the BOP format has no column for it).
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import SixdposeError
from ..fileio import atomic_write_text, claim_output_file
from ..geometry import X_from

#: First line of every results CSV.
RESULTS_HEADER = "scene_id,im_id,obj_id,score,R,t,time"


class ResultsError(SixdposeError):
    """A results CSV is missing or malformed (the message names the file and line)."""


@dataclass
class PoseEstimate:
    """One estimated object pose.

    Attributes:
        scene_id, im_id: the image key. obj_id: the object.
        score: confidence (> 0); 0 means "no estimate" (see ``reason``).
        R: (3, 3) rotation of ``X_CO``. t: (3,) translation of ``X_CO``, metres.
        time: seconds spent on the whole image (shared by its rows; disk reads excluded).
        reason: why the estimate is empty (score 0), or ``""``.
    """

    scene_id: int
    im_id: int
    obj_id: int
    score: float
    R: np.ndarray
    t: np.ndarray
    time: float = 0.0
    reason: str = ""

    @property
    def X_CO(self) -> np.ndarray:
        """The pose as a (4, 4) homogeneous matrix (metres)."""
        return X_from(self.R, self.t)

    @classmethod
    def failed(cls, scene_id: int, im_id: int, obj_id: int, reason: str) -> "PoseEstimate":
        """A score-0 row (identity pose) recording why no estimate could be made."""
        return cls(int(scene_id), int(im_id), int(obj_id), 0.0, np.eye(3), np.zeros(3), 0.0, reason)


def write_results(estimates, path: str | Path) -> Path:
    """Write estimates as a BOP results CSV (atomically; R row-major, t in mm, time in s).

    Args:
        estimates: iterable of :class:`PoseEstimate` (or objects with the same attributes).
        path: the CSV to write; an existing file is replaced only if it is a results CSV.
    Raises:
        OutputError: ``path`` exists and is not a results CSV, or cannot be written.
    """
    path = Path(path)
    claim_output_file(path, RESULTS_HEADER)
    lines = [RESULTS_HEADER]
    for r in estimates:
        R = " ".join(f"{v:.9g}" for v in np.asarray(r.R, dtype=np.float64).reshape(-1))
        t = " ".join(f"{v:.6f}" for v in np.asarray(r.t, dtype=np.float64).reshape(-1) * 1000.0)
        lines.append(f"{int(r.scene_id)},{int(r.im_id)},{int(r.obj_id)},{float(r.score):.6f},{R},{t},{float(r.time):.6f}")
    return atomic_write_text(path, "\n".join(lines) + "\n")


def read_results(path: str | Path) -> list[PoseEstimate]:
    """Read a BOP results CSV (t in mm) into :class:`PoseEstimate` rows (t in metres).

    Raises:
        ResultsError: missing file, missing column, or a malformed row (the message names the line).
    """
    path = Path(path)
    if not path.is_file():
        raise ResultsError(f"{path}: results file not found")
    out = []
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        missing = set(RESULTS_HEADER.split(",")) - set(reader.fieldnames or [])
        if missing:
            raise ResultsError(f"{path}: missing column(s) {', '.join(sorted(missing))}")
        for line, row in enumerate(reader, start=2):
            try:
                R = np.array([float(v) for v in row["R"].split()], dtype=np.float64).reshape(3, 3)
                t = np.array([float(v) for v in row["t"].split()], dtype=np.float64).reshape(3) / 1000.0
                est = PoseEstimate(int(row["scene_id"]), int(row["im_id"]), int(row["obj_id"]), float(row["score"]), R, t,
                                   float(row["time"]))
            except (ValueError, TypeError, AttributeError) as e:
                raise ResultsError(f"{path}: line {line}: malformed row ({e})") from None
            if not (np.isfinite(R).all() and np.isfinite(t).all() and np.isfinite(est.score)):
                raise ResultsError(f"{path}: line {line}: non-finite value in score, R or t")
            out.append(est)
    return out
