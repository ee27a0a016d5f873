"""The figures the write-up (``paper/paper.tex``) includes: what draws each and what it needs, and the
placeholders the PDF shows for those that are not in ``figures/<profile>/``.

``make tables`` / ``make paper`` build the write-up from the result files that are here (the committed
``results/cpu`` on a fresh clone) and never run a stage. A figure drawn from a dataset (Fig. 2 and Fig. 3
from the training data, Fig. 7 from the test split and a results CSV) is then skipped: the PDF gets a
placeholder saying which command makes it (:func:`write_placeholders`), and ``figures/<profile>/`` stays
without it.

Usage (the PDF rule of ``mk/reproduce.mk`` runs it before latexmk)::

    python -m sixdpose.reporting.writeup --profile cpu --figures figures/cpu --out paper/build/cpu/missing
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class WriteupFigure:
    """A figure of the write-up.

    Attributes:
        name: the file name (``\\includegraphics`` argument, in ``figures/<profile>/``).
        what: what it shows. drawn_by: the notebook or module that draws it.
        needs: what it is drawn from. make: the command that makes it (``{profile}`` stands for the profile).
    """

    name: str
    what: str
    drawn_by: str
    needs: str
    make: str

    def how(self, profile: str) -> str:
        """One line: what the figure needs and the command that makes it at ``profile``."""
        return f"{self.what} needs {self.needs}: `{self.make.format(profile=profile)}` makes it"


#: The figures ``paper/paper.tex`` includes (``tests/test_paper.py`` checks the list against it).
FIGURES: tuple[WriteupFigure, ...] = (
    WriteupFigure("fig2_lmo_vs_ours.png", "Fig. 2 (LM-O frames beside the training data's)",
                  "notebook 02, sixdpose.reporting.fig2", "the training data of the profile",
                  "make fig2 PROFILE={profile} RECOMPUTE=yes"),
    WriteupFigure("fig3_random_images.png", "Fig. 3 (random images of the training data)", "notebook 02",
                  "the training data of the profile",
                  "make notebooks/executed/{profile}/02_dataset_overview.ipynb PROFILE={profile}"),
    WriteupFigure("accuracy_threshold.png", "the accuracy against the threshold", "notebook 07",
                  "the result files", "make tables PROFILE={profile}"),
    WriteupFigure("fig7.png", "Fig. 7 (estimated poses over the images)", "notebook 07",
                  "the test split and the results CSV its result names", "make reproduce PROFILE={profile}"),
)
FIGURE = {f.name: f for f in FIGURES}


def missing(figures_dir: str | Path) -> list[WriteupFigure]:
    """The write-up's figures that are not in ``figures_dir``."""
    return [f for f in FIGURES if not (Path(figures_dir) / f.name).is_file()]


def write_placeholders(figures_dir: str | Path, out: str | Path, profile: str) -> list[str]:
    """A placeholder PNG in ``out`` for each figure missing from ``figures_dir`` (saying what makes it);
    placeholders of figures that are there now are removed. Returns one line per placeholder."""
    import matplotlib

    matplotlib.use("Agg")
    from .charts import save
    from .report import placeholder_figure

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    lines = []
    gone = missing(figures_dir)
    for f in FIGURES:
        if f not in gone:
            (out / f.name).unlink(missing_ok=True)
    for f in gone:
        save(placeholder_figure(f"{f.what} is not drawn at the {profile} profile here.\n{f.how(profile)}.",
                                size=(7.0, 1.4)), out / f.name)
        lines.append(f"{Path(figures_dir) / f.name} is not here (placeholder in the PDF): {f.how(profile)}")
    return lines


def main(argv: list[str] | None = None) -> int:
    """Write the placeholders (module docstring); returns the exit status."""
    ap = argparse.ArgumentParser(prog="python -m sixdpose.reporting.writeup", description=__doc__.splitlines()[0])
    ap.add_argument("--profile", required=True, help="the profile of the graph")
    ap.add_argument("--figures", required=True, help="figures/<profile>")
    ap.add_argument("--out", required=True, help="where the placeholders go (on TEXINPUTS after --figures)")
    args = ap.parse_args(argv)
    for line in write_placeholders(args.figures, args.out, args.profile):
        print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
