"""No number typed by hand in the README and the pages of docs/: every measured percentage or count
(``n/N``) sits in a block generated from ``results/`` (:mod:`sixdpose.reporting.readme`, checked by
tests/test_results.py); outside those blocks only the paper's own figures may appear, each on
:data:`PAPER_FIGURES` with where the paper gives it (/work/shared/paper/paper.txt)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from sixdpose.reporting.readme import blocks, default_pages

REPO = Path(__file__).resolve().parents[1]

#: A percentage (``12 %``, ``92.49%``) or a count out of a total (``53/140``).
FIGURE = re.compile(r"\d+(\.\d+)? ?%|\d+/\d+")

#: The paper's figures the README quotes outside generated blocks: figure -> where the paper gives it.
PAPER_FIGURES = {
    "10 %": "section V-A: a pose is correct if its ADD(-S) is below 10% of the object's diameter",
    "10%": "the same threshold (section V-A)",
    "90/10": "section IV-A: a random 90%-10% split of the synthetic data for Mask R-CNN",
}


def figures_outside_blocks(text: str) -> list[tuple[int, str]]:
    """``(line, figure)`` of every :data:`FIGURE` match of ``text`` outside its generated blocks."""
    spans = [(start, end) for _, start, end in blocks(text)]
    return [(text.count("\n", 0, m.start()) + 1, m.group(0)) for m in FIGURE.finditer(text)
            if not any(a <= m.start() < b for a, b in spans)]


@pytest.mark.parametrize("page", [p.relative_to(REPO) for p in default_pages(REPO)], ids=str)
def test_no_figure_typed_by_hand_in_the_readme(page):
    """The README and every page of docs/ (the README's detailed sections moved there)."""
    text = (REPO / page).read_text()
    found = [(line, f) for line, f in figures_outside_blocks(text) if f not in PAPER_FIGURES]
    assert found == [], (f"{page}: figures outside generated blocks (put them in a block generated from results/, "
                         f"or remove them; the paper's own go on PAPER_FIGURES): {found}")


def test_the_readme_is_an_overview():
    """The README stays short (the details are pages of docs/, each linked from it or from docs/README.md)."""
    text = (REPO / "README.md").read_text()
    assert len(text.splitlines()) <= 300
    index = (REPO / "docs" / "README.md").read_text()
    for page in sorted((REPO / "docs").glob("*.md")):
        if page.name != "README.md":
            assert f"({page.name})" in index, f"docs/{page.name} is not listed in docs/README.md"
    for link in re.findall(r"\]\((docs/[^)#]+)", text) + re.findall(r"\]\((figures/[^)#]+)", text):
        assert (REPO / link).exists(), f"README links to {link}, which is not there"


def test_the_scan_sees_figures_and_skips_blocks():
    text = ("ADD(-S) 92.49 % here, 53/140 there, 7% too\n<!-- results:x -->\n42.0 % 1/2\n<!-- /results:x -->\n"
            "after 10 %\n")
    assert figures_outside_blocks(text) == [(1, "92.49 %"), (1, "53/140"), (1, "7%"), (5, "10 %")]
