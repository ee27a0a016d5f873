"""nbval on the executed notebooks (:mod:`sixdpose.reporting.nbcheck`, ``make nbval``): the cells marked
``# NBVAL_CHECK_OUTPUT`` must print what ``notebooks/reference/<profile>/`` holds, so a change that silently
alters a notebook's counts fails; the references match the notebooks' marked cells."""

from __future__ import annotations

import json
from pathlib import Path

import nbformat
import pytest

from sixdpose.reporting import nbcheck

REPO = Path(__file__).resolve().parents[1]
REFERENCE = REPO / "notebooks" / "reference"


def _executed(path: Path, source: str, output: str) -> None:
    """An executed notebook: a parameters cell, a marked cell that printed ``output``, and an unmarked cell
    whose stale output nbval-lax does not compare."""
    nb = nbformat.v4.new_notebook()
    params = nbformat.v4.new_code_cell("N = 3")
    marked = nbformat.v4.new_code_cell(source)
    marked.outputs = [nbformat.v4.new_output("stream", name="stdout", text=output)]
    loose = nbformat.v4.new_code_cell("import time\nprint(time.time())")
    loose.outputs = [nbformat.v4.new_output("stream", name="stdout", text="12.5\n")]
    nb.cells = [params, marked, loose]
    nb.metadata = {"kernelspec": {"name": "python3", "display_name": "Python 3", "language": "python"}}
    path.parent.mkdir(parents=True, exist_ok=True)
    nbformat.write(nb, path)


@pytest.mark.slow
def test_nbval_fails_when_a_checked_output_changes(tmp_path):
    executed, reference = tmp_path / "executed", tmp_path / "reference"
    source = "# NBVAL_CHECK_OUTPUT\nprint(f'{N * 2} rows')"
    _executed(executed / "p" / "01_x.ipynb", source, "6 rows\n")
    assert nbcheck.record(executed / "p", reference / "p") == [reference / "p" / "01_x.json"]
    # the recorded output is what the notebook prints again: nbval passes
    args = (reference, executed, tmp_path / "run", tmp_path)
    assert nbcheck.check(*args) == 0
    # a reference that differs from what the notebook prints (the notebook's result changed): nbval fails
    ref = json.loads((reference / "p" / "01_x.json").read_text())
    ref["cells"][0]["outputs"][0]["text"] = "7 rows\n"
    (reference / "p" / "01_x.json").write_text(json.dumps(ref))
    assert nbcheck.check(*args) != 0


def test_references_and_marked_cells(tmp_path):
    executed, reference = tmp_path / "executed", tmp_path / "reference"
    _executed(executed / "p" / "01_x.ipynb", "# NBVAL_CHECK_OUTPUT\nprint(N)", "3\n")
    nbcheck.record(executed / "p", reference / "p")
    ref = nbcheck.read_reference(reference / "p" / "01_x.json")
    assert len(ref) == 1 and ref[0]["outputs"][0]["text"] == "3\n"  # the marked cell alone
    again = (reference / "p" / "01_x.json").read_text()
    nbcheck.record(executed / "p", reference / "p")
    assert (reference / "p" / "01_x.json").read_text() == again  # recording again writes the same file
    out = tmp_path / "run"
    (nb,) = nbcheck.prepare(reference, executed, out, tmp_path)
    cells = nbformat.read(nb, as_version=4).cells
    assert str(tmp_path) in cells[0].source and "os.chdir" in cells[0].source  # starts where the graph ran it
    # the marked cell changed since the reference was recorded: one line saying how to record it again
    _executed(executed / "p" / "01_x.ipynb", "# NBVAL_CHECK_OUTPUT\nprint(N + 1)", "4\n")
    with pytest.raises(nbcheck.NbcheckError, match="make nbval-reference PROFILE=p"):
        nbcheck.prepare(reference, executed, out, tmp_path)
    (executed / "p" / "01_x.ipynb").unlink()
    with pytest.raises(nbcheck.NbcheckError, match="not executed"):
        nbcheck.prepare(reference, executed, out, tmp_path)
    # a marked cell writing to stderr is not a deterministic output
    _executed(executed / "q" / "02_y.ipynb", "# NBVAL_CHECK_OUTPUT\nprint(N)", "3\n")
    nb = nbformat.read(executed / "q" / "02_y.ipynb", as_version=4)
    nb.cells[1].outputs.append(nbformat.v4.new_output("stream", name="stderr", text="warning\n"))
    nbformat.write(nb, executed / "q" / "02_y.ipynb")
    with pytest.raises(nbcheck.NbcheckError, match="stderr"):
        nbcheck.record(executed / "q", reference / "q")
    # a reference with bad content: one line naming the file and the key
    (reference / "p" / "01_x.json").write_text('{"cells": [{"source": 1}]}')
    with pytest.raises(nbcheck.NbcheckError, match=r"01_x.json: key 'cells\[0\]'"):
        nbcheck.read_reference(reference / "p" / "01_x.json")
    # no reference at all: nothing to check
    assert nbcheck.check(tmp_path / "none", executed, out, tmp_path) == 0


@pytest.mark.parametrize("ref", sorted(REFERENCE.glob("*/[0-9][0-9]_*.json")),
                         ids=lambda p: f"{p.parent.name}/{p.stem}")
def test_the_committed_references_match_the_notebooks(ref):
    """Each reference holds the marked cells of its notebook, as they are now (else `make nbval` stops
    with "record it again"), and only stdout."""
    nb = nbformat.read(REPO / "notebooks" / f"{ref.stem}.ipynb", as_version=4)
    cells = nbcheck.read_reference(ref)
    assert [c.source.strip() for c in nbcheck.marked(nb)] == [c["source"].strip() for c in cells], (
        f"{ref}: the marked cells of notebooks/{ref.stem}.ipynb changed; `make nbval-reference "
        f"PROFILE={ref.parent.name}` after the notebook ran records them again")
    assert all(o.get("name") == "stdout" for c in cells for o in c["outputs"])


def test_the_cpu_write_up_has_a_reference():
    """`make test` checks notebook 07 on the committed results (`make tables PROFILE=cpu`) at least."""
    assert (REFERENCE / "cpu" / "07_evaluation.json").is_file()
