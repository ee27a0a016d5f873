"""Reference outputs of the notebooks, checked by nbval: what papermill does not check.

Papermill executes a notebook and fails when a cell raises; a change that silently alters what a notebook
finds passes. The cells whose output is deterministic (counts, table shapes, dataset statistics) carry the
line ``# NBVAL_CHECK_OUTPUT``; their sources and outputs, as one run of the graph printed them, are committed
as JSON in ``notebooks/reference/<profile>/NN_name.json`` (only those cells, and not as a notebook: every
committed notebook stays without outputs; :func:`read_reference` reads one). ``check`` takes each
executed notebook of ``notebooks/executed/<profile>/`` that has a reference, puts the reference outputs into
its marked cells and runs it again under ``pytest --nbval-lax`` (nbval's mode that compares the marked
cells only), so a marked cell that prints something else fails.

Usage (from the checkout's root; ``make nbval`` and ``make nbval-reference`` run them)::

    python -m sixdpose.reporting.nbcheck check    [--reference notebooks/reference] [--executed notebooks/executed]
    python -m sixdpose.reporting.nbcheck record   --executed notebooks/executed/smoke --out notebooks/reference/smoke

``check`` prepares the notebooks nbval runs in ``build/nbval/<profile>/`` (each starts in the directory the
graph executed it in, ``notebooks/``, like papermill's ``--cwd``), then runs pytest on them; a reference whose
executed notebook is missing, or whose marked cells no longer match the notebook's, is one line naming the
target that writes it (exit status 2). A profile without references is skipped with one line.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
from pathlib import Path

from ..errors import SixdposeError
from ..fileio import atomic_write_text

#: The nbval marker of a cell whose output is compared (a line of its own in the cell).
MARKER = "# NBVAL_CHECK_OUTPUT"


class NbcheckError(SixdposeError):
    """A reference cannot be checked (its executed notebook is missing, or the marked cells changed)."""


def marked(nb) -> list:
    """The code cells of ``nb`` (an nbformat notebook) that carry :data:`MARKER` on a line of their own."""
    return [c for c in nb.cells if c.cell_type == "code" and MARKER in (s.strip() for s in c.source.splitlines())]


def _read(path: Path):
    import nbformat

    try:
        return nbformat.read(path, as_version=4)
    except (OSError, ValueError) as e:
        raise NbcheckError(f"{path}: cannot read the notebook ({e})") from None


def read_reference(path: str | Path) -> list[dict]:
    """The marked cells of a reference file (``{"cells": [{"source": str, "outputs": [nbformat output]}]}``),
    as ``[{"source", "outputs"}]`` with the outputs as nbformat nodes.

    Raises:
        NbcheckError: unreadable file or bad content (one line naming the file and key).
    """
    import nbformat

    path = Path(path)
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        raise NbcheckError(f"{path}: cannot read the reference ({e})") from None
    cells = doc.get("cells") if isinstance(doc, dict) else None
    if not isinstance(cells, list):
        raise NbcheckError(f"{path}: key 'cells': expected a list of cells")
    out = []
    for i, c in enumerate(cells):
        if not (isinstance(c, dict) and isinstance(c.get("source"), str) and isinstance(c.get("outputs"), list)):
            raise NbcheckError(f"{path}: key 'cells[{i}]': expected {{'source': str, 'outputs': list}}")
        out.append({"source": c["source"], "outputs": [nbformat.from_dict(o) for o in c["outputs"]]})
    return out


def record(executed: str | Path, out: str | Path) -> list[Path]:
    """Write the reference of every executed notebook in ``executed`` that has marked cells: those cells
    alone (source and outputs, no execution counts or metadata) as JSON at ``out/<name>.json``.

    Returns:
        the references written.

    Raises:
        NbcheckError: ``executed`` holds no notebook, or a marked cell has no output or wrote to stderr
            (its output would not be deterministic).
    """
    executed, out = Path(executed), Path(out)
    nbs = sorted(executed.glob("[0-9][0-9]_*.ipynb"))
    if not nbs:
        raise NbcheckError(f"{executed}: no executed notebook (make reproduce PROFILE=... executes them)")
    written = []
    for p in nbs:
        cells = marked(_read(p))
        if not cells:
            continue
        ref = []
        for c in cells:
            if not c.outputs:
                raise NbcheckError(f"{p}: a cell marked {MARKER} has no output")
            if any(o.get("output_type") == "stream" and o.get("name") == "stderr" for o in c.outputs):
                raise NbcheckError(f"{p}: a cell marked {MARKER} writes to stderr (not a deterministic output)")
            ref.append({"source": c.source, "outputs": [_clean(o) for o in c.outputs]})
        out.mkdir(parents=True, exist_ok=True)
        dest = out / f"{p.stem}.json"
        # stable: recording the same outputs again writes the same file
        atomic_write_text(dest, json.dumps({"cells": ref}, indent=1, sort_keys=True) + "\n")
        written.append(dest)
    return written


def _clean(output):
    """An output without its execution count and metadata (what the reference keeps)."""
    import nbformat

    o = nbformat.from_dict(dict(output))
    if "metadata" in o:
        o.metadata = {}
    if o.output_type == "execute_result":
        o.execution_count = None
    return o


def prepare(reference: str | Path, executed: str | Path, out: str | Path, workdir: str | Path) -> list[Path]:
    """The notebooks nbval runs: for each ``reference/<profile>/<name>.json``, the executed notebook
    ``executed/<profile>/<name>.ipynb`` with the reference outputs in its marked cells and a first cell
    changing to ``workdir`` (where the graph executed it), written to ``out/<profile>/<name>.ipynb`` (``out``
    is emptied first).

    Returns:
        the notebooks written (none when there is no reference).

    Raises:
        NbcheckError: an executed notebook is missing, or its marked cells differ from the reference's
            in number or source (the reference must be recorded again).
    """
    import nbformat

    reference, executed, out = Path(reference), Path(executed), Path(out)
    if out.exists():
        shutil.rmtree(out)
    written = []
    for ref_path in sorted(reference.glob("*/[0-9][0-9]_*.json")):
        profile = ref_path.parent.name
        nb_path = executed / profile / f"{ref_path.stem}.ipynb"
        if not nb_path.is_file():
            raise NbcheckError(f"{nb_path}: not executed; `make {nb_path} PROFILE={profile}` executes it "
                               f"(its reference is {ref_path})")
        nb, ref_cells = _read(nb_path), read_reference(ref_path)
        cells = marked(nb)
        if len(cells) != len(ref_cells) or any(a.source.strip() != b["source"].strip()
                                              for a, b in zip(cells, ref_cells, strict=False)):
            raise NbcheckError(
                f"{ref_path}: the cells marked {MARKER} of {nb_path} differ from the reference's; check the "
                f"change, then `make nbval-reference PROFILE={profile}` records it again")
        for c in nb.cells:  # nbval compares the marked cells only; the others' outputs are not the reference
            if c.cell_type == "code":
                c.outputs = []
        for c, r in zip(cells, ref_cells, strict=True):
            c.outputs = r["outputs"]
        cd = nbformat.v4.new_code_cell(f"import os\nos.chdir({str(Path(workdir).resolve())!r})")
        cd.id = "nbcheck-chdir"
        nb.cells.insert(0, cd)
        for n, c in enumerate(c for c in nb.cells if c.cell_type == "code"):
            c.execution_count = n + 1  # a cell nbval takes as not run (no count) may hold no output
        dest = out / profile / nb_path.name
        dest.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(dest, nbformat.writes(nb, version=4) + "\n")
        written.append(dest)
    return written


def check(reference: str | Path, executed: str | Path, out: str | Path, workdir: str | Path,
          pytest_args: list[str] | None = None) -> int:
    """:func:`prepare`, then ``pytest --nbval-lax`` on the notebooks it wrote; returns pytest's exit status
    (0 when there is no reference to check)."""
    nbs = prepare(reference, executed, out, workdir)
    if not nbs:
        print(f"nbcheck: no reference in {reference}/<profile>/: nothing to check")
        return 0
    print(f"nbcheck: {len(nbs)} notebook(s) against {reference}/: " + ", ".join(str(p) for p in nbs))
    cmd = [sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "-p", "no:dash", "-q", "--nbval-lax",
           "--nbval-current-env", *(pytest_args or []), *map(str, nbs)]
    return subprocess.run(cmd).returncode


def main(argv: list[str] | None = None) -> int:
    """The command line (module docstring); returns the exit status."""
    ap = argparse.ArgumentParser(prog="python -m sixdpose.reporting.nbcheck", description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("check", help="run the executed notebooks again; compare their marked cells with the reference")
    c.add_argument("--reference", default="notebooks/reference", help="references, <profile>/NN_name.json")
    c.add_argument("--executed", default="notebooks/executed", help="executed notebooks, <profile>/NN_name.ipynb")
    c.add_argument("--out", default="build/nbval", help="where the notebooks nbval runs are written")
    c.add_argument("--workdir", default="notebooks", help="the directory the graph executed the notebooks in")
    r = sub.add_parser("record", help="write the references from executed notebooks")
    r.add_argument("--executed", required=True, help="the executed notebooks of one profile")
    r.add_argument("--out", required=True, help="notebooks/reference/<profile>")
    args = ap.parse_args(argv)
    try:
        if args.cmd == "record":
            for p in record(args.executed, args.out):
                print(f"nbcheck: recorded {p}")
            return 0
        return check(args.reference, args.executed, args.out, args.workdir)
    except SixdposeError as e:
        print(f"nbcheck: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
