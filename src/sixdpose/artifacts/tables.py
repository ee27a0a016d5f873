"""Result tables: one writer for every CSV + LaTeX table of the project (evaluation, notebooks,
benchmarks), so the numbers in a paper table are the numbers in its CSV."""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path

from ..fileio import atomic_write_text


def tex_escape(s: str) -> str:
    """Escape LaTeX special characters (``\\ _ & % # $ { } ~ ^``) in plain text."""
    rep = {"\\": r"\textbackslash{}", "_": r"\_", "&": r"\&", "%": r"\%", "#": r"\#", "$": r"\$",
           "{": r"\{", "}": r"\}", "~": r"\textasciitilde{}", "^": r"\textasciicircum{}"}
    return "".join(rep.get(c, c) for c in str(s))


def _fmt(v, digits: int) -> str:
    if v is None:
        return "--"
    if isinstance(v, float):
        return "--" if math.isnan(v) else f"{v:.{digits}f}"
    return str(v)


def write_table(rows, columns: list[str], csv_path: str | Path | None, tex_path: str | Path | None = None,
                headers: list[str] | None = None, digits: int = 2, comment: str | None = None,
                super_header: str | None = None, align: str | None = None) -> None:
    """Write a table as CSV and optionally as a LaTeX ``tabular`` (booktabs), both atomically.

    Args:
        rows: list of dicts (or a ``pandas.DataFrame``) holding at least ``columns``.
        columns: keys to write, in order. csv_path, tex_path: outputs (either may be None: not written).
        headers: LaTeX column headers (default: ``columns``, escaped); LaTeX in them is kept.
        digits: decimals of floats in the LaTeX table; the CSV gets ``digits + 2`` decimals.
        comment: a ``%`` line appended to the LaTeX file (several lines: one ``%`` line each).
        super_header: raw LaTeX put above the header row (e.g. ``\\multicolumn`` groups and ``\\cmidrule``).
        align: the LaTeX column alignment (default: ``l`` up to the first numeric column, then ``r``).
    A missing value (None) is empty in the CSV and ``--`` in the LaTeX table (NaN: ``nan`` and ``--``).
    """
    if hasattr(rows, "to_dict"):  # pandas.DataFrame
        rows = rows.to_dict("records")
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(columns)
    for r in rows:
        w.writerow([("" if r[c] is None
                     else f"{r[c]:.{digits + 2}f}" if isinstance(r[c], float) and not math.isnan(r[c])
                     else r[c]) for c in columns])
    if csv_path is not None:
        atomic_write_text(csv_path, buf.getvalue())
    if tex_path is None:
        return
    if align is None:
        first_numeric = next((i for i, c in enumerate(columns) if rows and isinstance(rows[0][c], (int, float))),
                             len(columns))
        align = "l" * max(first_numeric, 1) + "r" * (len(columns) - max(first_numeric, 1))
    head = headers if headers is not None else [tex_escape(c) for c in columns]
    lines = ["\\begin{tabular}{" + align + "}", "\\toprule"] + ([super_header] if super_header else [])
    lines += [" & ".join(head) + " \\\\", "\\midrule"]
    lines += [" & ".join(tex_escape(_fmt(r[c], digits)) for c in columns) + " \\\\" for r in rows]
    lines += ["\\bottomrule", "\\end{tabular}"]
    if comment:
        lines += ["% " + line for line in comment.splitlines()]
    atomic_write_text(tex_path, "\n".join(lines) + "\n")
