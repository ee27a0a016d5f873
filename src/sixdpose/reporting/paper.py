"""The paper's own published figures, as constants, each with the table it comes from.

These are the only numbers in the package that were not computed by its code. They are quoted beside
ours (always in a column labelled as the paper's) and never used in a computation. Source: the paper
(``paper/``; text in ``../shared/paper/paper.txt``), section V, Tables I-III. Row labels are the paper's.

Settings differ from ours, so a paper figure and ours are comparable only in kind: Table III is on the
authors' generated dataset restricted to images without repeated objects, with Mask R-CNN masks; Tables I
and II are on LINEMOD-Occlusion, Table II timed on an Intel i9-12900K with an RTX 3090 Ti.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..registry import METHOD


@dataclass(frozen=True)
class PaperTable:
    """One table of the paper.

    Attributes:
        key: ``"I"``, ``"II"`` or ``"III"``. caption: what it reports (shortened). unit: unit of every value.
        rows: the paper's row label -> value, in the paper's order.
    """

    key: str
    caption: str
    unit: str
    rows: dict

    @property
    def citation(self) -> str:
        """How a README or notebook cites it, e.g. ``"paper Table III"``."""
        return f"paper Table {self.key}"


TABLES: dict[str, PaperTable] = {
    "I": PaperTable("I", "ADD(-S) accuracy on LINEMOD-Occlusion", "%", {
        "PoseCNN": 24.9, "PoseCNN+ICP": 78.0, "PVNet": 40.8, "HybridPose": 47.5,
        "EfficientPose (phi = 0)": 79.04, "EfficientPose (phi = 3)": 83.98, "RNNPose": 60.65,
        "Ours Hybrid(RANSAC + ICP)": 9.38, "Ours Hybrid(FGR + ICP)": 7.21, "Ours Hybrid(Super4PCS)": 40.33,
        "Ours Full Learning (No Refinement)": 53.02, "Ours Full Learning (Iterative)": 80.67,
    }),
    "II": PaperTable("II", "average FPS on LINEMOD-Occlusion, Intel i9-12900K and RTX 3090Ti", "frames/s", {
        "EfficientPose (phi = 0)": 29.06, "EfficientPose (phi = 3)": 15.57,
        "Ours Hybrid(RANSAC + ICP)": 0.88, "Ours Hybrid(FGR)": 0.97, "Ours Hybrid(Super4PCS)": 0.08,
        "Ours Full Learning (No Refinement)": 16.23, "Ours Full Learning": 14.97,
    }),
    "III": PaperTable("III", "ADD(-S) accuracy on the paper's generated dataset", "%", {
        "EfficientPose (phi = 0)": 33.68, "EfficientPose (phi = 3)": 32.85,
        "Ours Hybrid(RANSAC + ICP)": 53.55, "Ours Hybrid(FGR + ICP)": 40.69, "Ours Hybrid(Super4PCS)": 57.32,
        "Ours Full Learning (No Refinement)": 18.58, "Ours Full Learning (Iterative)": 26.87,
    }),
}

def paper_figure(table: str, method: str) -> float | None:
    """The paper's figure for ``method`` (a method key of :data:`sixdpose.registry.METHODS`, whose row
    label is its ``paper_fps`` in Table II and its ``paper_acc`` in Tables I and III, or a row label of the
    table) in Table ``table`` (``"I"``, ``"II"``, ``"III"``); None when the paper has no such row."""
    m = METHOD.get(method)
    label = method if m is None else (m.paper_fps if table == "II" else m.paper_acc)
    return None if label is None else TABLES[table].rows.get(label)
