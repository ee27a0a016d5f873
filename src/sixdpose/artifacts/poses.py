"""Pose results: one :class:`PoseEstimate` type and the BOP 2019 results CSV that stores it.

Written by the hybrid stage (``sixdpose register``) and the learned stage (``sixdpose predict-pose``),
read by ``sixdpose evaluate``. Format (BOP challenge, https://bop.felk.cvut.cz/challenges/)::

    scene_id,im_id,obj_id,score,R,t,time

``R``: the 9 row-major entries of the rotation of ``X_CO`` separated by spaces; ``t``: translation of
``X_CO`` in **millimetres**; ``time``: seconds spent on the whole image (every instance, every step but
disk reads), repeated on each row of the image. In memory translations are metres. An instance whose
input was unusable has score 0 (identity pose); its ``reason`` is kept in memory and logged, not
written (the BOP format has no column for it).

Beside every results CSV the command that wrote it saves its settings, ``<stem>.config.yml``
(:func:`results_config_path`; read by :func:`read_results_config`).
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


def results_config_path(path: str | Path) -> Path:
    """The settings file of a results CSV: ``<dir>/<stem>.config.yml`` (written by ``register`` and
    ``predict-pose`` beside the CSV)."""
    path = Path(path)
    return path.with_name(path.stem + ".config.yml")


def write_results_config(path: str | Path, settings: dict) -> Path:
    """Write the settings a results CSV was made with to its :func:`results_config_path` (YAML, keys
    sorted, atomically); ``path`` is the CSV's. Returns the settings file's path."""
    import yaml

    return atomic_write_text(results_config_path(path), yaml.safe_dump(settings, sort_keys=True))


def read_results_config(path: str | Path) -> dict | None:
    """The settings a results CSV was made with (its :func:`results_config_path`), or None when that file is
    missing, unreadable or not a YAML mapping."""
    import yaml

    try:
        cfg = yaml.safe_load(results_config_path(path).read_text())
    except (OSError, yaml.YAMLError, UnicodeDecodeError):
        return None
    return cfg if isinstance(cfg, dict) else None


def results_verification(cfg: dict | None) -> dict | None:
    """The hypothesis-verification settings of a results CSV's config (:func:`read_results_config`):
    ``register`` keeps ``verify`` and the ``verify_*`` fields flat, ``predict-pose`` ``verify`` and a nested
    ``verify_config``. Returns the ``verify_*`` fields, ``{}`` when not verified, None without a config."""
    if cfg is None:
        return None
    if not cfg.get("verify"):
        return {}
    nested = cfg.get("verify_config")
    fields: dict = nested if isinstance(nested, dict) else cfg
    return {k: v for k, v in fields.items() if str(k).startswith("verify_")}


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
    def failed(cls, scene_id: int, im_id: int, obj_id: int, reason: str) -> PoseEstimate:
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

    Each row is checked: integer ``scene_id``, ``im_id``, ``obj_id`` (>= 0), a finite ``score``, 9
    finite numbers in ``R``, 3 in ``t``, and a finite ``time`` >= 0 (seconds). Whether ``R`` is a rotation
    is checked by ``sixdpose evaluate`` (such rows are rejected there, not credited).

    Raises:
        ResultsError: missing file, missing column, or a malformed row (the message names the line and
            the column).
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
            est = _parse_row(row, f"{path}: line {line}")
            if not (np.isfinite(est.R).all() and np.isfinite(est.t).all() and np.isfinite(est.score)):
                raise ResultsError(f"{path}: line {line}: non-finite value in score, R or t")
            if not (np.isfinite(est.time) and est.time >= 0):
                raise ResultsError(f"{path}: line {line}: time: expected seconds >= 0, got {row['time']!r}")
            out.append(est)
    return out


def _parse_row(row: dict, where: str) -> PoseEstimate:
    """One CSV row (strings) as a :class:`PoseEstimate` (t in metres); :class:`ResultsError` naming
    ``where`` and the column otherwise."""

    def number_list(col: str, n: int) -> np.ndarray:
        text = row.get(col)
        try:
            vals = [float(v) for v in (text or "").split()]
        except ValueError:
            raise ResultsError(f"{where}: {col}: expected {n} numbers separated by spaces, got {text!r}") from None
        if len(vals) != n:
            raise ResultsError(f"{where}: {col}: expected {n} numbers separated by spaces, got {len(vals)}")
        return np.array(vals, dtype=np.float64)

    def integer(col: str) -> int:
        text = row.get(col)
        try:
            v = int(str(text))
        except (TypeError, ValueError):
            raise ResultsError(f"{where}: {col}: expected an integer >= 0, got {text!r}") from None
        if v < 0:
            raise ResultsError(f"{where}: {col}: expected an integer >= 0, got {v}")
        return v

    def number(col: str) -> float:
        text = row.get(col)
        try:
            return float(str(text))
        except (TypeError, ValueError):
            raise ResultsError(f"{where}: {col}: expected a number, got {text!r}") from None

    ids = [integer(c) for c in ("scene_id", "im_id", "obj_id")]
    score = number("score")
    R = number_list("R", 9).reshape(3, 3)
    t = number_list("t", 3) / 1000.0
    return PoseEstimate(ids[0], ids[1], ids[2], score, R, t, number("time"))


def merge_by_score(tables, names=None) -> tuple[list[PoseEstimate], list[int]]:
    """Keep, for every instance, the estimate with the highest score among several results tables.

    Pose-source fusion at the artifact level: tables written by ``register --verify`` and
    ``predict-pose --verify`` on the same frames and masks carry the same verification score (depth with
    occlusion, mask overlap, texture; :mod:`sixdpose.registration.hypotheses`), so the higher score is
    the pose that agrees better with the frame. Both commands write one row per instance in the
    instance order of the mask source, so the tables are paired row by row; they must list the same
    ``(scene_id, im_id, obj_id)`` sequence. A tie keeps the earlier table's row. The merged row's
    ``time`` is the sum of the tables' times of its image (every source ran), so frames/s stay honest.

    Args:
        tables: two or more lists of :class:`PoseEstimate` (e.g. :func:`read_results` of each CSV).
        names: optional labels of the tables for error messages (default ``table 1``, ``table 2``...).
    Returns:
        ``(rows, chosen)``: the merged rows (in the tables' order) and, per table, how many rows came
        from it.
    Raises:
        ResultsError: fewer than two tables, or tables of different instances (the message names the
            first differing row).
    """
    tables = [list(t) for t in tables]
    names = list(names) if names is not None else [f"table {k + 1}" for k in range(len(tables))]
    if len(tables) < 2:
        raise ResultsError(f"merging needs at least two results tables, got {len(tables)}")
    first = tables[0]
    for name, tab in zip(names[1:], tables[1:], strict=True):
        if len(tab) != len(first):
            raise ResultsError(f"{name}: {len(tab)} rows, {names[0]}: {len(first)}: the tables are not of the "
                               "same instances (run both commands on the same data, split and masks)")
        for i, (a, b) in enumerate(zip(first, tab, strict=True)):
            ka, kb = (a.scene_id, a.im_id, a.obj_id), (b.scene_id, b.im_id, b.obj_id)
            if ka != kb:
                raise ResultsError(f"{name}: row {i + 1} is (scene_id, im_id, obj_id) {kb}, {names[0]} has {ka}: "
                                   "the tables are not of the same instances")
    # seconds per image of each table (its rows of one image share it)
    image_time = [{(r.scene_id, r.im_id): r.time for r in tab} for tab in tables]
    rows, chosen = [], [0] * len(tables)
    for i in range(len(first)):
        k = max(range(len(tables)), key=lambda j: (tables[j][i].score, -j))
        r = tables[k][i]
        key = (r.scene_id, r.im_id)
        rows.append(PoseEstimate(r.scene_id, r.im_id, r.obj_id, r.score, r.R, r.t,
                                 sum(t[key] for t in image_time), r.reason))
        chosen[k] += 1
    return rows, chosen
