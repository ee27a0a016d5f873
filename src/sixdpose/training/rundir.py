"""The run directory of a training run: claim and resume rules, the run's status and data
fingerprint, resume hygiene (stale temporary files, a crash-cut ``metrics.csv``) and metrics rows.

Files the engine keeps in ``RUN`` (besides the stage's own)::

    config.json   the run's config (a :class:`~sixdpose.training.schedule.TrainSchedule` subclass)
    status.json   {"finished": bool, "epoch": completed epochs, "epochs": planned epochs,
                   "data": training data location, "data_sha256": fingerprint of the training data}
    metrics.csv   one row per logged step (and per validation), appended after every epoch
    last.pt / model.pt   resumable checkpoint after every epoch / final model
"""

from __future__ import annotations

import csv
import hashlib
import json
import logging
from pathlib import Path

from ..errors import SixdposeError
from ..fileio import atomic_write_bytes, atomic_write_json, claim_output_dir
from ..runs import FINAL, LAST
from .schedule import RESUMABLE

log = logging.getLogger("sixdpose.training")

STATUS = "status.json"
METRICS = "metrics.csv"
#: Annotation files whose bytes enter the data fingerprint (images count by name and size).
_TEXT_SUFFIXES = {".json", ".yml", ".yaml", ".csv", ".txt"}


class TrainingError(SixdposeError):
    """Training cannot start or continue (bad run directory, other data on resume, diverged loss, ...)."""


# -- config decision ------------------------------------------------------------------------------
def prepare_run_dir(run_dir: Path, resume: bool, cls, new_config, profile: str | None, overrides: dict,
                    command: str, cfg=None):
    """Decide the config of a new or resumed run and check the directory's state.

    Args:
        run_dir: the run directory. resume: continue the run in it. cls: the config class.
        new_config: ``f(profile, overrides) -> config`` of a new run (profile None: the default one).
        profile: the profile asked for (on resume it must be the run's own). overrides: config fields.
        command: the CLI command that owns the directory (``train-pose``). cfg: an explicit config
            (new run: used instead of the profile; resume: must equal the saved one up to
            :data:`~sixdpose.training.schedule.RESUMABLE` fields).
    Returns:
        the config (a new run's directory is claimed; nothing else is written).
    Raises:
        TrainingError: nothing to resume, a run already there, or a forbidden change on resume.
    """
    cfg_path = run_dir / "config.json"
    if resume:
        if not cfg_path.is_file():
            raise TrainingError(f"{run_dir}: nothing to resume (no config.json); start a new run without --resume")
        saved = cls.load(cfg_path)
        if cfg is not None and cfg.replace(**{k: getattr(saved, k) for k in RESUMABLE}) != saved:
            raise TrainingError(f"{run_dir}: the given config differs from the saved one; resume uses the saved config")
        if profile and profile != getattr(saved, "profile", profile):
            raise TrainingError(f"{run_dir}: the run was started with profile {saved.profile!r}, not {profile!r}")
        bad = sorted(k for k, v in overrides.items() if k not in RESUMABLE and getattr(saved, k, None) != v)
        if bad:
            raise TrainingError(f"cannot change {', '.join(bad)} when resuming (only {', '.join(RESUMABLE)})")
        return saved.replace(**{k: v for k, v in overrides.items() if k in RESUMABLE})
    if (run_dir / LAST).exists() or (run_dir / FINAL).exists() or cfg_path.exists():
        raise TrainingError(f"{run_dir}: already holds a run; use --resume to continue it or choose another --out")
    claim_output_dir(run_dir, command)
    if cfg is not None:
        return cfg.replace(**overrides) if overrides else cfg
    return new_config(profile, overrides)


# -- status and data fingerprint --------------------------------------------------------------------
def data_fingerprint(reader, extra=None) -> str:
    """sha256 (hex) of a training set: its image keys, object ids, manifest, the names and sizes of the
    files under ``reader.location`` and the bytes of its annotation files (``.json``/``.yml``/...
    up to 4 MB), plus ``extra`` (e.g. the run's split). Cheap: no image is decoded or read."""
    h = hashlib.sha256()
    keys = reader.keys()
    head = {"keys": [list(map(int, k)) for k in keys], "objects": sorted(map(int, reader.object_ids)),
            "manifest": reader.manifest or {}, "extra": extra}
    h.update(json.dumps(head, sort_keys=True, default=str).encode())
    root = Path(reader.location)
    if root.is_dir():
        for p in sorted(root.rglob("*")):
            if not p.is_file():
                continue
            size = p.stat().st_size
            h.update(f"{p.relative_to(root).as_posix()}\0{size}\n".encode())
            if p.suffix.lower() in _TEXT_SUFFIXES and size <= 4 << 20:
                h.update(hashlib.sha256(p.read_bytes()).digest())
    return h.hexdigest()


_STATUS_TYPES = {"finished": bool, "epoch": int, "epochs": int, "data": str, "data_sha256": str}


def read_status(run_dir: str | Path) -> dict | None:
    """``RUN/status.json`` as a dict, or None: a run of an older version or not started (no file), or a
    damaged file (then one warning line naming it: the status is rebuilt at the next checkpoint, and
    the data check of a resume cannot be made)."""
    path = Path(run_dir) / STATUS
    if not path.is_file():
        return None
    try:
        st = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        log.warning("%s: unreadable (%s); ignored", path, str(e).splitlines()[0] if str(e) else type(e).__name__)
        return None
    bad = [k for k, t in _STATUS_TYPES.items()
           if not isinstance(st, dict) or (k in st and not (isinstance(st[k], t) and (t is bool or not
                                                                                       isinstance(st[k], bool))))]
    if bad:
        log.warning("%s: %s not of the expected type; ignored", path, ", ".join(bad))
        return None
    return st


def write_status(run_dir: Path, *, finished: bool, epoch: int, epochs: int, data: str, data_sha256: str) -> None:
    """Write ``RUN/status.json`` atomically (see the module docstring)."""
    atomic_write_json(run_dir / STATUS, {"finished": bool(finished), "epoch": int(epoch), "epochs": int(epochs),
                                         "data": str(data), "data_sha256": data_sha256})


def check_same_data(run_dir: Path, location: str, fingerprint: str) -> None:
    """Refuse to resume a run on other training data than it started on (runs without a recorded
    fingerprint are not checked).

    Raises:
        TrainingError: one line naming both datasets.
    """
    st = read_status(run_dir)
    if st and st.get("data_sha256") and st["data_sha256"] != fingerprint:
        raise TrainingError(f"{run_dir}: the run was trained on {st.get('data')}, not on {location} (other files or "
                            "images); resume it with its own --data or start a new run")


# -- resume hygiene ----------------------------------------------------------------------------------
def repair_metrics(path: Path) -> bool:
    """Cut a ``metrics.csv`` that a crash left with NUL bytes or a half-written line back to its last
    complete line (one warning line); returns True if the file was changed."""
    if not path.is_file():
        return False
    data = path.read_bytes()
    good = data.split(b"\0", 1)[0]
    if not good.endswith(b"\n"):
        good = good[: good.rfind(b"\n") + 1]
    if good == data:
        return False
    if b"\n" not in good:  # not even the header survived
        path.unlink()
    else:
        atomic_write_bytes(path, good)
    log.warning("%s: cut by a crash (%d damaged byte(s)); repaired to its last complete line", path,
                len(data) - len(good))
    return True


# -- metrics rows ------------------------------------------------------------------------------------
def read_metrics(run_dir: str | Path) -> list[dict]:
    """The rows of ``RUN/metrics.csv``: ``epoch``/``step`` as int, other numbers as float, empty cells None.

    Raises:
        TrainingError: no metrics file (training has not completed an epoch).
    """
    path = Path(run_dir) / METRICS
    if not path.is_file():
        raise TrainingError(f"{path}: no metrics (training has not completed an epoch)")
    with open(path, newline="") as f:
        return [{k: (None if v in ("", None) else int(v) if k in ("epoch", "step") else float(v)) for k, v in r.items()}
                for r in csv.DictReader(f)]
