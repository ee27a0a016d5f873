"""Result artifacts: the figures a benchmark or an evaluation measured, with the commit, date, hardware
and command that produced them. This module is the one writer and the one reader of ``results/``;
the README's generated tables (:mod:`sixdpose.reporting.readme`) are built from these files only.

One result is ``<results_dir>/<name>.json`` (and, when it has a table, ``<name>.csv`` with the same rows
for spreadsheets; the JSON is the record). JSON, UTF-8, format version 1::

    {
     "format": "sixdpose-result", "version": 1,
     "name": "eval_learned_it0",
     "description": "one line: what was measured, on what",
     "figures": {"accuracy": 30.67, ...},        # scalars (may be empty)
     "rows": [{"obj_id": 1, ...}, ...],           # a table, one dict per row (may be empty)
     "units": {"accuracy": "%", "fps": "frames/s", ...},   # unit of each figure / column that has one
     "provenance": {
       "commit": "<40 hex>" | null,               # HEAD of the source checkout the code ran from
       "dirty": false | true | null,              # tracked files modified at that moment
       "date": "2026-11-22T02:40:00Z",            # UTC, when the result was written
       "sixdpose": "0.1.0", "python": "3.11.9",
       "hardware": {"cpu": "...", "cpu_count": 2, "cpus_available": 2, "ram_gib": 7.8,
                    "gpus": ["NVIDIA H100 80GB HBM3"], "machine": "x86_64", "os": "Linux"},
       "load_avg": [1.9, 1.7, 1.6],               # 1, 5, 15 min load when written (shared machines)
       "command": ["sixdpose", "evaluate", "--data", "data/test", ...],
       "env": {"OMP_NUM_THREADS": "1"}            # thread / device variables that were set
     },
     "config": {...} | null,                      # the configuration that produced the figures
     "inputs": [{"path": "...", "bytes": 277963, "sha256": "..."}],   # files the figures were computed from
     "notes": "free text" | null
    }

No host name, user name or working directory is recorded. Floats that are NaN or infinite are stored as
``null`` (JSON has neither). Every file is written atomically (:mod:`sixdpose.fileio`), so a reader sees
the old result or the new one, never half of one.
"""

from __future__ import annotations

import csv
import datetime as _dt
import hashlib
import io
import json
import math
import os
import platform
import re
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import SixdposeError
from ..fileio import atomic_write_text

FORMAT = "sixdpose-result"
VERSION = 1
#: Default results directory of a command run from a checkout (relative to the working directory).
DEFAULT_DIR = "results"
#: Environment variables worth recording: they change what a timing means.
ENV_KEYS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS",
            "CUDA_VISIBLE_DEVICES", "SIXDPOSE_PROFILE")
PROVENANCE_KEYS = ("commit", "dirty", "date", "hardware", "command")
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")
_SRC = Path(__file__).resolve().parents[1]  # .../sixdpose


class ResultError(SixdposeError):
    """A result file is missing, corrupt or not a result, or a result cannot be written (bad name or value)."""


@dataclass
class Result:
    """One result artifact as read back (see the module docstring for the meaning of each field).

    Attributes:
        name: the result's name (file stem). figures: scalar figures. rows: table rows (dicts).
        units: unit per figure / column. provenance: commit, dirty, date, hardware, command, ...
        description, config, inputs, notes: as written. path: the JSON file read.
    """

    name: str
    figures: dict
    rows: list
    units: dict
    provenance: dict
    description: str = ""
    config: dict | None = None
    inputs: list = field(default_factory=list)
    notes: str | None = None
    path: Path | None = None

    def column(self, key: str) -> list:
        """The values of column ``key`` over :attr:`rows` (``None`` where a row lacks it)."""
        return [r.get(key) for r in self.rows]

    def row(self, **match) -> dict:
        """The one row whose values equal ``match`` (e.g. ``row(obj_id="all")``).

        Raises:
            ResultError: no row or more than one row matches (the message names the file).
        """
        hits = [r for r in self.rows if all(r.get(k) == v for k, v in match.items())]
        if len(hits) != 1:
            raise ResultError(f"{self.path or self.name}: {len(hits)} rows match {match} (expected one)")
        return hits[0]


# --------------------------------------------------------------------------------------------
# provenance
# --------------------------------------------------------------------------------------------
def _git(args: list[str], cwd: Path) -> str | None:
    try:
        p = subprocess.run(["git", *args], cwd=cwd, capture_output=True, text=True, timeout=20)
    except (OSError, subprocess.SubprocessError):
        return None
    return p.stdout.strip() if p.returncode == 0 else None


def source_root() -> Path | None:
    """The git checkout the running ``sixdpose`` package comes from (``<root>/src/sixdpose``), or None
    for an installed copy (a wheel in site-packages records no commit)."""
    top = _git(["rev-parse", "--show-toplevel"], _SRC)
    if not top:
        return None
    root = Path(top).resolve()
    return root if (root / "src" / "sixdpose").resolve() == _SRC else None


def git_state(root: Path | None = None) -> tuple[str | None, bool | None]:
    """``(commit, dirty)`` of ``root`` (default: :func:`source_root`): HEAD's full hash and whether
    tracked files differ from it (untracked files, such as new results, do not count); ``(None, None)``
    outside a git checkout or without git."""
    root = source_root() if root is None else root
    if root is None:
        return None, None
    commit = _git(["rev-parse", "HEAD"], root)
    status = _git(["status", "--porcelain", "--untracked-files=no"], root)
    return commit, (None if status is None else bool(status))


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            if key.strip() in ("model name", "Hardware", "Processor", "cpu model") and value.strip():
                return value.strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


def _ram_gib() -> float | None:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal:"):
                return round(int(line.split()[1]) / 2**20, 1)  # kB -> GiB
    except (OSError, ValueError, IndexError):
        pass
    try:
        return round(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30, 1)
    except (ValueError, OSError, AttributeError):
        return None


def _gpus() -> list[str]:
    """Names of the CUDA devices torch sees (empty without torch or without a GPU).

    torch is imported only where it can see a device: already loaded by the process, or an NVIDIA
    driver is installed (``nvidia-smi`` on the PATH). A CPU-only machine answers at once (importing
    torch to learn that there is no GPU costs seconds per ``sixdpose evaluate``)."""
    import shutil

    if "torch" not in sys.modules and shutil.which("nvidia-smi") is None:
        return []
    try:
        import torch
    except ImportError:
        return []
    try:
        if not torch.cuda.is_available():
            return []
        return [torch.cuda.get_device_name(i) for i in range(torch.cuda.device_count())]
    except Exception:  # noqa: BLE001 - a broken driver must not lose the result
        return []


def hardware() -> dict:
    """The machine, without its name: ``cpu`` (model, from /proc/cpuinfo or :mod:`platform`),
    ``cpu_count`` (logical CPUs), ``cpus_available`` (CPUs this process may run on), ``ram_gib``
    (total memory, GiB), ``gpus`` (CUDA device names seen by torch), ``machine``, ``os``."""
    try:
        avail = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        avail = os.cpu_count()
    return {"cpu": _cpu_model(), "cpu_count": os.cpu_count(), "cpus_available": avail, "ram_gib": _ram_gib(),
            "gpus": _gpus(), "machine": platform.machine(), "os": platform.system()}


def machine_text(prov: dict) -> str:
    """The machine of a result's provenance in one line, e.g. ``"AMD EPYC 7B13 (2 CPUs, 23.5 GiB), no GPU"``
    (CPUs: those the process could use)."""
    hw = prov.get("hardware") or {}
    gpus = hw.get("gpus") or []
    cpus = hw.get("cpus_available") or hw.get("cpu_count")
    ram = f", {hw['ram_gib']:g} GiB" if hw.get("ram_gib") else ""
    return f"{hw.get('cpu', '?')} ({cpus} CPUs{ram}), " + (", ".join(gpus) if gpus else "no GPU")


def _command(argv: list[str]) -> list[str]:
    """``argv`` with its program shortened: the console script as ``sixdpose``, a script inside the
    source checkout relative to it (``benchmarks/pose.py``), anything else by its base name."""
    if not argv:
        return []
    prog = Path(argv[0])
    root = source_root()
    if prog.name == "sixdpose":
        first = ["sixdpose"]
    elif prog.suffix == ".py" and prog.resolve().is_relative_to(_SRC):  # python -m sixdpose.x
        mod = prog.resolve().relative_to(_SRC.parent).with_suffix("")
        first = ["python", "-m", ".".join(mod.parts[:-1] if mod.name == "__main__" else mod.parts)]
    elif root is not None and prog.is_absolute() and prog.resolve().is_relative_to(root):
        first = ["python", str(prog.resolve().relative_to(root))]
    elif prog.suffix == ".py":
        first = ["python", str(prog) if not prog.is_absolute() else prog.name]
    else:
        first = [prog.name]
    return first + [str(a) for a in argv[1:]]


def script_command(script: str | Path, argv: list[str] | None = None) -> list[str]:
    """The command line of a script's ``main(argv)``: ``["python", <script, relative to the checkout>,
    *argv]`` (``argv`` None: this process' arguments, as ``argparse`` would take them)."""
    return _command([str(Path(script).resolve())] + [str(a) for a in (sys.argv[1:] if argv is None else argv)])


def provenance(command: list[str] | None = None) -> dict:
    """The provenance block of a result written now (see the module docstring).

    Args:
        command: the command line that produced the figures (default: ``sys.argv``, its program shortened).
    """
    from .. import __version__

    commit, dirty = git_state()
    try:
        load = [round(x, 2) for x in os.getloadavg()]
    except (AttributeError, OSError):
        load = None
    return {
        "commit": commit,
        "dirty": dirty,
        "date": _dt.datetime.now(_dt.UTC).replace(microsecond=0).isoformat().replace("+00:00", "Z"),
        "sixdpose": __version__,
        "python": platform.python_version(),
        "hardware": hardware(),
        "load_avg": load,
        "command": list(command) if command is not None else _command(sys.argv),
        "env": {k: os.environ[k] for k in ENV_KEYS if k in os.environ},
    }


def file_input(path: str | Path) -> dict:
    """``{"path", "bytes", "sha256"}`` of an input file (path as given), for :func:`write_result`'s ``inputs``."""
    path = Path(path)
    h = hashlib.sha256()
    try:
        with open(path, "rb") as f:
            for chunk in iter(lambda: f.read(1 << 20), b""):
                h.update(chunk)
    except OSError as e:
        raise ResultError(f"{path}: cannot read input file ({e.strerror or e})") from None
    return {"path": str(path), "bytes": path.stat().st_size, "sha256": h.hexdigest()}


# --------------------------------------------------------------------------------------------
# writer and reader
# --------------------------------------------------------------------------------------------
def _plain(v, where: str):
    """JSON-ready copy of ``v``: numpy scalars/arrays, tuples and paths converted, NaN/inf -> None."""
    if v is None or isinstance(v, (bool, str)):
        return v
    if isinstance(v, int):
        return int(v)
    if isinstance(v, float):
        return v if math.isfinite(v) else None
    if isinstance(v, Path):
        return str(v)
    if isinstance(v, dict):
        return {str(k): _plain(x, f"{where}.{k}") for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x, f"{where}[{i}]") for i, x in enumerate(v)]
    if hasattr(v, "tolist"):  # numpy scalar or array
        return _plain(v.tolist(), where)
    if hasattr(v, "to_dict"):  # a Config
        return _plain(v.to_dict(), where)
    raise ResultError(
        f"result value {where} has type {type(v).__name__}, which cannot be stored (numbers, strings, lists, dicts)"
    )


def result_path(name: str, results_dir: str | Path = DEFAULT_DIR) -> Path:
    """``<results_dir>/<name>.json``.

    Raises:
        ResultError: ``name`` is not a plain file stem (letters, digits, ``_ - .``; no directory part).
    """
    if not isinstance(name, str) or not _NAME.match(name) or name.endswith(".json"):
        raise ResultError(f"result name {name!r}: use letters, digits, '_', '-' and '.' (it becomes a file name)")
    return Path(results_dir) / f"{name}.json"


def _csv_text(rows: list[dict]) -> str:
    cols: list[str] = []
    for r in rows:
        cols += [k for k in r if k not in cols]
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for r in rows:
        w.writerow(
            ["" if r.get(c) is None else (json.dumps(r[c]) if isinstance(r[c], (list, dict)) else r[c]) for c in cols]
        )
    return buf.getvalue()


def write_result(name: str, content=None, *, rows=None, units: dict | None = None, description: str = "",
                 results_dir: str | Path = DEFAULT_DIR, command: list[str] | None = None, config=None,
                 inputs: list | None = None, notes: str | None = None, csv_table: bool = True) -> Path:
    """Write result ``name`` to ``<results_dir>/<name>.json`` atomically, with its provenance.

    Args:
        name: file stem (letters, digits, ``_ - .``), e.g. ``"registration_val"``.
        content: the figures: a dict of scalars, or a list of row dicts (or a ``pandas.DataFrame``) when
            the result is a table only.
        rows: the table when ``content`` is a dict of figures (e.g. an evaluation's per-object rows).
        units: unit of each figure / column that has one, e.g. ``{"accuracy": "%", "fps": "frames/s"}``.
        description: one line saying what was measured on what.
        results_dir: directory (created). command: the producing command line (default ``sys.argv``).
        config: the configuration (a dict or a :class:`~sixdpose.config.Config`), stored as plain data.
        inputs: files the figures were computed from: paths (hashed with :func:`file_input`) or dicts.
        notes: free text (e.g. "timings measured while another job used the second core").
        csv_table: also write ``<name>.csv`` with the rows (when there are rows).
    Returns:
        the JSON path.
    Raises:
        ResultError: a bad name, or a value that is not plain data.
    """
    path = result_path(name, results_dir)
    if hasattr(content, "to_dict") and not isinstance(content, dict):  # pandas.DataFrame
        content = content.to_dict("records")
    if hasattr(rows, "to_dict"):
        rows = rows.to_dict("records")
    if isinstance(content, list):
        if rows is not None:
            raise ResultError(f"result {name}: give the table either as content or as rows, not both")
        figures, rows = {}, content
    elif content is None or isinstance(content, dict):
        figures, rows = dict(content or {}), list(rows or [])
    else:
        raise ResultError(
            f"result {name}: content must be a dict of figures or a list of row dicts, not {type(content).__name__}"
        )
    if not all(isinstance(r, dict) for r in rows):
        raise ResultError(f"result {name}: every row must be a dict (column -> value)")
    doc = {
        "format": FORMAT,
        "version": VERSION,
        "name": path.stem,
        "description": description,
        "figures": _plain(figures, "figures"),
        "rows": _plain(rows, "rows"),
        "units": _plain(dict(units or {}), "units"),
        "provenance": provenance(command),
        "config": _plain(config, "config"),
        "inputs": [file_input(i) if isinstance(i, (str, Path)) else _plain(i, "inputs") for i in (inputs or [])],
        "notes": notes,
    }
    text = json.dumps(doc, indent=1, allow_nan=False) + "\n"
    if csv_table and doc["rows"]:
        atomic_write_text(path.with_suffix(".csv"), _csv_text(doc["rows"]))
    atomic_write_text(path, text)
    return path


def read_result(name: str | Path, results_dir: str | Path = DEFAULT_DIR) -> Result:
    """Read result ``name`` (``<results_dir>/<name>.json``), or the result file at path ``name`` when it
    is a :class:`~pathlib.Path` or a string ending in ``.json``.

    Raises:
        ResultError: the file is missing, not JSON, not a sixdpose result, of a newer format version, or
            lacks a field; the one-line message names the file.
    """
    is_path = isinstance(name, Path) or str(name).endswith(".json")
    path = Path(name) if is_path else result_path(str(name), results_dir)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ResultError(f"{path}: no such result file (run the benchmark or evaluation that writes it)") from None
    except (OSError, UnicodeDecodeError) as e:
        raise ResultError(f"{path}: cannot read result file ({getattr(e, 'strerror', None) or e})") from None
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as e:
        raise ResultError(f"{path}: corrupt result file (invalid JSON at line {e.lineno}: {e.msg})") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise ResultError(f"{path}: not a sixdpose result file (no \"format\": \"{FORMAT}\")")
    if not isinstance(doc.get("version"), int) or doc["version"] > VERSION:
        raise ResultError(
            f"{path}: result format version {doc.get('version')!r} is not supported (this sixdpose reads <= {VERSION})"
        )
    prov = doc.get("provenance")
    missing = [k for k in PROVENANCE_KEYS if not isinstance(prov, dict) or k not in prov]
    if missing:
        raise ResultError(f"{path}: corrupt result file (provenance lacks {', '.join(missing)})")
    figures, rows, units = doc.get("figures", {}), doc.get("rows", []), doc.get("units", {})
    if not isinstance(figures, dict) or not isinstance(units, dict) or not isinstance(rows, list) \
            or not all(isinstance(r, dict) for r in rows):
        raise ResultError(f"{path}: corrupt result file (figures and units must be objects, rows a list of objects)")
    return Result(name=doc.get("name") or path.stem, figures=figures, rows=rows, units=units, provenance=prov,
                  description=doc.get("description") or "", config=doc.get("config"), inputs=doc.get("inputs") or [],
                  notes=doc.get("notes"), path=path)


def earlier_rows(name: str, new_rows: list[dict], key: str = "run",
                 results_dir: str | Path = DEFAULT_DIR) -> list[dict]:
    """The rows of result ``name`` already in ``results_dir`` whose ``key`` none of ``new_rows`` has: what a
    benchmark's ``--keep`` carries over when it adds runs beside ones measured earlier (copies; ``[]``
    without the file). Raises :class:`ResultError` for a corrupt file, as :func:`read_result`."""
    path = result_path(name, results_dir)
    if not path.is_file():
        return []
    given = {r.get(key) for r in new_rows}
    return [dict(r) for r in read_result(path).rows if r.get(key) not in given]


def list_results(results_dir: str | Path = DEFAULT_DIR) -> list[str]:
    """Names of the result files in ``results_dir`` (sorted; empty if it does not exist)."""
    d = Path(results_dir)
    return sorted(p.stem for p in d.glob("*.json")) if d.is_dir() else []


# --------------------------------------------------------------------------------------------
# command-line helpers shared by the benchmark scripts
# --------------------------------------------------------------------------------------------
def add_result_arguments(parser, default_name: str | None, default_dir: str | Path = DEFAULT_DIR,
                         name_help: str | None = None) -> None:
    """Add ``--results-dir DIR``, ``--result-name NAME`` and ``--no-result`` to a benchmark's parser.

    Args:
        default_name: the result name when ``--result-name`` is not given (None: the script sets it
            after parsing, e.g. from the dataset; describe it in ``name_help``).
        default_dir: the default results directory (benchmarks: the checkout's ``results/``).
    """
    g = parser.add_argument_group("result artifact")
    g.add_argument("--results-dir", default=str(default_dir),
                   help=f"write the figures, with commit, date, hardware and command line, to DIR/NAME.json (+ .csv) "
                        f"(default: {default_dir})")
    from ..options import Name

    g.add_argument("--result-name", default=default_name, type=Name(),
                   help=f"result name (default: {name_help or default_name})")
    g.add_argument("--no-result", action="store_true", help="only print the figures; write no result file")


def save_from_args(args, content=None, **kw) -> Path | None:
    """:func:`write_result` with the ``--results-dir`` / ``--result-name`` / ``--no-result`` of
    :func:`add_result_arguments`; prints where the result went. Returns the path (None with ``--no-result``)."""
    if args.no_result:
        return None
    p = write_result(args.result_name, content, results_dir=args.results_dir, **kw)
    print(f"result -> {p}")
    return p
