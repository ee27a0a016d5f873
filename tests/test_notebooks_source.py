"""Notebooks come from one kind of source: jupytext percent-format ``notebooks/NN_*.py`` twins, the
``.ipynb`` committed without outputs and in sync with them; parameters cells hold plain literals; the
notebooks hold no logic (no functions or classes: that lives in the package)."""

from __future__ import annotations

import ast
from pathlib import Path

import nbformat
import pytest

NB = Path(__file__).resolve().parents[1] / "notebooks"
PAIRS = sorted(p.stem for p in NB.glob("[0-9][0-9]_*.ipynb"))


def test_every_notebook_has_a_percent_twin():
    assert PAIRS and sorted(p.stem for p in NB.glob("[0-9][0-9]_*.py")) == PAIRS


@pytest.mark.parametrize("name", PAIRS)
def test_notebook_matches_its_source_and_has_no_outputs(name):
    import jupytext

    src = jupytext.read(NB / f"{name}.py")
    nb = nbformat.read(NB / f"{name}.ipynb", as_version=4)
    strip = lambda cells: [(c.cell_type, c.source.strip()) for c in cells]  # noqa: E731
    assert strip(nb.cells) == strip(src.cells), f"run `make notebooks-sync` after editing notebooks/{name}.py"
    for c in nb.cells:
        if c.cell_type == "code":
            assert not c.outputs and c.execution_count is None


@pytest.mark.parametrize("name", PAIRS)
def test_parameters_are_literals_and_no_logic(name):
    nb = nbformat.read(NB / f"{name}.ipynb", as_version=4)
    params = [c for c in nb.cells if "parameters" in c.metadata.get("tags", [])]
    assert len(params) == 1
    for stmt in ast.parse(params[0].source).body:
        assert isinstance(stmt, ast.Assign), ast.dump(stmt)
        ast.literal_eval(stmt.value)  # raises on anything but a plain value
    for c in nb.cells:
        if c.cell_type == "code":
            for node in ast.walk(ast.parse(c.source)):
                assert not isinstance(node, (ast.FunctionDef, ast.ClassDef, ast.While)), (
                    f"{name}: logic belongs in the package"
                )


@pytest.mark.parametrize("name", PAIRS)
def test_notebooks_read_what_make_writes(name):
    """Datasets, trained networks and results of record are make targets (mk/reproduce.mk): a notebook
    never generates a dataset, trains, or writes a result artifact (it requires them: sixdpose.graph)."""
    import re

    src = (NB / f"{name}.py").read_text() + (NB / f"{name}.ipynb").read_text()
    found = re.findall(r"\b(write_result|generate|ensure_dataset|ensure_trained|run_ablation|segment)\(", src)
    assert found == [], f"{name}: {sorted(set(found))} belong to a make rule (mk/reproduce.mk)"
