"""The paper's tables and figures rebuilt from result artifacts (notebook 07 and the write-up).

Input: a results directory of the ``make reproduce`` graph (``results/<profile>/``), one result per
``<split>_<masks>_<method>.json`` written by ``sixdpose evaluate --result-name``:

* ``split``: ``test`` (the multi-instance held-out split, objects may repeat), ``single`` (the
  single-instance subset of paper section V-D, the setting of Table III) or ``lmo`` (LINEMOD-Occlusion,
  Table I);
* ``masks``: ``gt`` (ground-truth masks) or ``pred`` (the graph's Mask R-CNN);
* ``method``: one of :data:`sixdpose.registry.METHODS`.

Other result files in the directory (ablations, benchmarks) are ignored here. Every function is pure
(results in, tables / figures / LaTeX text out) except the ``write_*`` ones, which write through
:mod:`sixdpose.artifacts.tables` and :mod:`sixdpose.fileio`. The paper's own figures come from
:mod:`sixdpose.reporting.paper` and always stand in a column labelled as the paper's.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

from ..artifacts.results import Result, list_results, machine_text, read_result
from ..artifacts.tables import tex_escape, write_table
from ..constants import ADD_THRESHOLD, MIN_VISIBLE_PX
from ..errors import SixdposeError
from ..fileio import atomic_write_text
from ..registry import HYBRID_ALGORITHMS, METHOD, METHODS, REAL_METHODS, Method
from .paper import TABLES


class ReportError(SixdposeError):
    """A results directory cannot be turned into the report (the message names the file or field)."""


#: Data splits of the graph and how the tables name them.
SPLITS = {"test": "multi-instance", "single": "single-instance", "lmo": "LM-O"}
#: Mask sources and how the tables name them.
MASKS = {"gt": "GT masks", "pred": "predicted masks"}
_NAME = re.compile(r"^(?P<split>test|single|lmo)_(?P<masks>gt|pred)_(?P<method>[a-z0-9_]+)$")


def parse_name(name: str) -> tuple[str, str, str] | None:
    """``(split, masks, method)`` of a graph result name such as ``single_pred_super4pcs``; None for any
    other name (an ablation, a benchmark)."""
    m = _NAME.match(name)
    if m is None or m.group("method") not in METHOD:
        return None
    return m.group("split"), m.group("masks"), m.group("method")


@dataclass
class Entry:
    """One evaluation of the graph: a method on a split with a mask source, and its result file.

    Attributes:
        split, masks, method: the parts of the name. result: the :class:`~sixdpose.artifacts.results.Result`.
    """

    split: str
    masks: str
    method: str
    result: Result

    @property
    def name(self) -> str:
        """The result's name, ``<split>_<masks>_<method>``."""
        return f"{self.split}_{self.masks}_{self.method}"

    def figure(self, key: str) -> float | None:
        """A scalar figure of the evaluation (``accuracy`` in %, ``fps``, ...), None if absent or not finite."""
        v = self.result.figures.get(key)
        return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) else None

    @property
    def curve(self) -> tuple[list[float], list[float]] | None:
        """``(thresholds in % of the diameter, accuracy in %)``, or None for a result written before
        ``evaluate`` recorded the curve."""
        c = self.result.figures.get("curve")
        if not isinstance(c, dict) or not c.get("threshold_pct"):
            return None
        return [float(x) for x in c["threshold_pct"]], [math.nan if y is None else float(y) for y in c["accuracy"]]


def load_entries(results_dir: str | Path) -> dict[tuple[str, str, str], Entry]:
    """Every graph result of ``results_dir``, keyed by ``(split, masks, method)`` (empty if there are none).

    Raises:
        ResultError: a graph result file is corrupt (one line naming it).
    """
    out = {}
    for name in list_results(results_dir):
        key = parse_name(name)
        if key is not None:
            out[key] = Entry(*key, read_result(name, results_dir))
    return out


def _acc(entries: dict, split: str, masks: str, method: str, key: str = "accuracy") -> float | None:
    e = entries.get((split, masks, method))
    return None if e is None else e.figure(key)


# --------------------------------------------------------------------------------------------
# tables (rows as dicts; None where there is no result)
# --------------------------------------------------------------------------------------------
#: Columns of Table III: (column key, split, masks, header).
TABLE3_COLUMNS = (("single_pred", "single", "pred", "single, pred."), ("single_gt", "single", "gt", "single, GT"),
                  ("test_pred", "test", "pred", "multi, pred."), ("test_gt", "test", "gt", "multi, GT"))


def _shown(entries: dict, splits) -> list[Method]:
    """The methods of a table on ``splits``: every one of ours, and a paper-settings rerun (``preset``
    ``paper``) only where one of its results on those splits exists."""
    return [m for m in METHODS
            if m.preset != "paper" or any(k[0] in splits and k[2] == m.key for k in entries)]


def table3(entries: dict) -> list[dict]:
    """Table III: ADD(-S) % of every method on our generated data. Columns ``paper`` (the paper's Table
    III: its own dataset, predicted masks, single-instance subset) and, ours, ``single_pred`` (the
    paper's setting), ``single_gt``, ``test_pred``, ``test_gt`` (multi-instance split). The paper-settings reruns
    (``preset == "paper"``) are rows only where one of their results exists."""
    rows = []
    for m in _shown(entries, ("test", "single")):
        row = {"method": m.label, "paper": TABLES["III"].rows.get(m.paper_acc) if m.paper_acc else None}
        for col, split, masks, _ in TABLE3_COLUMNS:
            row[col] = _acc(entries, split, masks, m.key)
        rows.append(row)
    return rows


def table1(entries: dict) -> list[dict]:
    """Table I: the paper's LM-O rows (every method it lists) with its figure in ``paper``, then ours on
    LM-O where the graph ran it (``lmo_gt``, ``lmo_pred``; None otherwise). Our methods without a
    paper row are appended."""
    ours = {m.paper_acc: m for m in METHODS if m.paper_acc}
    rows = []
    for label, value in TABLES["I"].rows.items():
        m = ours.get(label)
        rows.append({"method": label if m is None else m.label, "paper": value,
                     "lmo_gt": _acc(entries, "lmo", "gt", m.key) if m else None,
                     "lmo_pred": _acc(entries, "lmo", "pred", m.key) if m else None})
    for m in METHODS:
        if m.paper_acc is None and any((("lmo", k, m.key) in entries) for k in MASKS):
            rows.append({"method": m.label, "paper": None, "lmo_gt": _acc(entries, "lmo", "gt", m.key),
                         "lmo_pred": _acc(entries, "lmo", "pred", m.key)})
    return rows


def machines(entries: dict) -> dict[str, str]:
    """Machine description -> letter (``a``, ``b``, ...) over the entries' provenance, in order of appearance."""
    out: dict[str, str] = {}
    for e in entries.values():
        out.setdefault(machine_text(e.result.provenance), "abcdefghijklmnopqrstuvwxyz"[len(out) % 26])
    return out


def table2(entries: dict, split: str = "test") -> list[dict]:
    """Table II: frames per second of each method's pose stage on ``split`` (GT and predicted masks), the
    instances per second, and the machine (a letter of :func:`machines`); the paper's FPS (LM-O, an
    i9-12900K with an RTX 3090 Ti) in ``paper``. FPS = images / the sum of their per-image times,
    measured by ``register`` / ``predict-pose`` (disk reads excluded, segmentation not included)."""
    letters = machines(entries)
    rows = []
    for m in _shown(entries, (split,)):
        row = {"method": m.label, "paper": TABLES["II"].rows.get(m.paper_fps) if m.paper_fps else None}
        hw = []
        for masks in MASKS:
            e = entries.get((split, masks, m.key))
            row[f"fps_{masks}"] = None if e is None else e.figure("fps")
            row[f"ips_{masks}"] = None if e is None else e.figure("instances_per_s")
            if e is not None:
                hw.append(letters[machine_text(e.result.provenance)])
        row["machine"] = ",".join(sorted(set(hw))) or None
        rows.append(row)
    return rows


def per_object(entries: dict, split: str, masks: str) -> list[dict]:
    """ADD(-S) % per object (rows) and method (columns, by key) on ``split`` with ``masks``; the last two
    rows are the mean over instances and over objects. Empty when no method ran there."""
    have = [m for m in METHODS if (split, masks, m.key) in entries]
    if not have:
        return []
    objects: dict = {}
    for m in have:
        for r in entries[(split, masks, m.key)].result.rows:
            objects.setdefault(
                r.get("obj_id"), {"obj_id": r.get("obj_id"), "name": r.get("name"), "n_gt": r.get("n_gt")}
            )
    order = sorted(
        (k for k in objects if k not in ("all", "objects")),
        key=lambda k: (not isinstance(k, int), str(k) if not isinstance(k, int) else k),
    )
    rows = []
    for k in order + [k for k in ("all", "objects") if k in objects]:
        row = dict(objects[k])
        for m in METHODS:
            hit = [r for r in entries[(split, masks, m.key)].result.rows if r.get("obj_id") == k] if m in have else []
            row[m.key] = hit[0].get("add_s_accuracy") if hit else None
        rows.append(row)
    return rows


# --------------------------------------------------------------------------------------------
# writers: CSV + LaTeX through sixdpose.artifacts.tables
# --------------------------------------------------------------------------------------------
def _sources(entries: dict, keys=None) -> str:
    used = [e for k, e in entries.items() if keys is None or k in keys]
    commits = sorted(
        {
            (e.result.provenance.get("commit") or "unknown")[:7] + ("+" if e.result.provenance.get("dirty") else "")
            for e in used
        }
    )
    return (
        f"generated by sixdpose.evaluation.report from {len(used)} result file(s); commits {', '.join(commits) or '-'}"
    )


def write_table3(entries: dict, csv_path, tex_path) -> list[dict]:
    """Write :func:`table3` as CSV and LaTeX; returns its rows."""
    rows = table3(entries)
    cols = ["method", "paper"] + [c for c, *_ in TABLE3_COLUMNS]
    sup = (
        "& \\multicolumn{1}{c}{paper} & \\multicolumn{2}{c}{single-instance subset} "
        "& \\multicolumn{2}{c}{multi-instance split} \\\\"
        "\n\\cmidrule(lr){2-2}\\cmidrule(lr){3-4}\\cmidrule(lr){5-6}"
    )
    write_table(rows, cols, csv_path, tex_path,
                headers=["Method", "Table III", "pred.", "GT", "pred.", "GT"], super_header=sup, align="lrrrrr",
                comment=_sources(entries, [k for k in entries if k[0] in ("test", "single")]))
    return rows


def write_table1(entries: dict, csv_path, tex_path) -> list[dict]:
    """Write :func:`table1` as CSV and LaTeX; returns its rows."""
    rows = table1(entries)
    write_table(
        rows,
        ["method", "paper", "lmo_gt", "lmo_pred"],
        csv_path,
        tex_path,
        headers=["Method", "paper Table I", "ours, GT masks", "ours, pred. masks"],
        align="lrrr",
        comment=_sources(entries, [k for k in entries if k[0] == "lmo"]),
    )
    return rows


def write_table2(entries: dict, csv_path, tex_path, split: str = "test") -> list[dict]:
    """Write :func:`table2` as CSV and LaTeX (the machines listed in ``%`` lines); returns its rows."""
    rows = table2(entries, split)
    sup = ("& \\multicolumn{1}{c}{paper} & \\multicolumn{2}{c}{GT masks} & \\multicolumn{2}{c}{pred. masks} & \\\\"
           "\n\\cmidrule(lr){2-2}\\cmidrule(lr){3-4}\\cmidrule(lr){5-6}")
    hw = "\n".join(f"machine {v}: {k}" for k, v in machines(entries).items())
    write_table([dict(r, machine=r["machine"] or "--") for r in rows],
                ["method", "paper", "fps_gt", "ips_gt", "fps_pred", "ips_pred", "machine"], csv_path, tex_path,
                headers=["Method", "Table II FPS", "FPS", "inst/s", "FPS", "inst/s", "machine"], super_header=sup,
                align="lrrrrrc", comment=_sources(entries) + ("\n" + hw if hw else ""))
    return rows


def write_per_object(entries: dict, split: str, masks: str, csv_path, tex_path) -> list[dict]:
    """Write :func:`per_object` for ``split`` / ``masks`` as CSV and LaTeX (method columns by short label;
    without results, one row says so); returns its rows."""
    rows = per_object(entries, split, masks)
    methods = [m for m in METHODS if rows and any(r.get(m.key) is not None for r in rows)]
    table = rows or [{"obj_id": "", "name": f"no results for {split} / {masks}", "n_gt": ""}]
    two = "\\shortstack[r]{{{}\\\\{}}}".format  # a header on two lines keeps the columns as narrow as the numbers
    short = {"ransac": "RANSAC", "ransac_icp": two("RANSAC", "+ICP"), "fgr": "FGR", "fgr_icp": two("FGR", "+ICP"),
             "super4pcs": "S4PCS", "super4pcs_icp": two("S4PCS", "+ICP"), "learned_it0": "L0", "learned_it2": "L2",
             "learned_it2_icp": two("L2", "+ICP"), "learned_it2_colour": two("L2", "+col."),
             "ransac_icp_paper": two("RANSAC", "+ICP (p.)"), "fgr_icp_paper": two("FGR", "+ICP (p.)"),
             "super4pcs_paper": two("S4PCS", "(p.)"), "dense": "D", "dense_icp": two("D", "+ICP"),
             "dense_icp_verify": two("D", "+ICP+ver.")}
    cols = ["obj_id", "name", "n_gt"] + [m.key for m in methods]
    write_table(
        [{c: r.get(c) for c in cols} for r in table],
        cols,
        csv_path,
        tex_path,
        headers=["Id", "Object", "GT"] + [short[m.key] for m in methods],
        digits=1,
        align="llr" + "r" * len(methods),
        comment=_sources(entries, [k for k in entries if k[:2] == (split, masks)]),
    )
    return rows


# --------------------------------------------------------------------------------------------
# figures
# --------------------------------------------------------------------------------------------
def plot_curves(entries: dict, splits=("test", "single"), masks=("gt", "pred"), title: str = ""):
    """Accuracy (% of GT instances) against the ADD(-S) threshold (0-20 % of the diameter), one panel per
    split and mask source, one line per method; the paper's 10 % dashed. Results without a recorded
    curve are left out (named in the panel).

    Returns:
        the matplotlib ``Figure``.
    """
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(splits), len(masks), figsize=(5.2 * len(masks), 3.6 * len(splits)), squeeze=False,
                             sharex=True, sharey=True)
    cmap = plt.get_cmap("tab10")
    for i, split in enumerate(splits):
        for j, mk in enumerate(masks):
            ax = axes[i][j]
            missing = []
            for n, m in enumerate(METHODS):
                e = entries.get((split, mk, m.key))
                if e is None:
                    continue
                if e.curve is None:
                    missing.append(m.label)
                    continue
                x, y = e.curve
                ax.plot(x, y, color=cmap(n % 10), ls="-" if m.kind == "hybrid" else "--", lw=1.4, label=m.label)
            ax.axvline(10, color="0.5", lw=0.8, ls=":")
            ax.set_title(f"{SPLITS[split]} split, {MASKS[mk]}", fontsize=9)
            ax.set_xlim(0, 20)
            ax.set_ylim(0, 100)
            ax.grid(alpha=0.3)
            if missing:
                ax.text(0.98, 0.02, "no curve recorded: " + ", ".join(missing), transform=ax.transAxes, ha="right",
                        va="bottom", fontsize=6, color="0.4", wrap=True)
            if i == len(splits) - 1:
                ax.set_xlabel("threshold (% of the object's diameter)")
            if j == 0:
                ax.set_ylabel("ADD(-S) accuracy (%)")
    handles: dict = {}
    for ax in axes.flat:
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            handles.setdefault(lab, h)
    if handles:
        fig.legend(list(handles.values()), list(handles.keys()), loc="lower center", ncol=4, fontsize=7, frameon=False)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout(rect=(0, 0.1 if handles else 0, 1, 1))
    return fig


def fig7(entry: Entry, root: str | Path = ".", n_good: int = 3, n_bad: int = 3, ncols: int = 3):
    """The paper's Fig. 7 for one evaluation: estimated poses (red) and ground truth (green) over the
    images, good cases first, from the results CSV and dataset the result names (paths relative to
    ``root``, the checkout the graph ran in).

    Returns:
        ``(figure, None)``, or ``(None, reason)`` when the results CSV or the dataset is not there
        (committed results whose runs were made on another machine).
    """
    from ..artifacts.poses import read_results
    from ..datasets.readers import open_dataset
    from ..evaluation.evaluate import evaluate
    from ..evaluation.visualize import plot_cases

    cfg = entry.result.config or {}
    data, csv = cfg.get("data"), cfg.get("results")
    if not data or not csv:
        return None, f"{entry.result.path}: its config names no dataset or results CSV"
    data, csv = Path(root) / data, Path(root) / csv
    for p in (data, csv):
        if not p.exists():
            return None, f"{p} is not here (the run that wrote {entry.name} was made elsewhere)"
    ds = open_dataset(data, split=cfg.get("split") or "test")
    keys = ds.keys()
    images = keys[: cfg["limit"]] if cfg.get("limit") else keys
    res = evaluate(ds, read_results(csv), min_px=cfg.get("min_px", MIN_VISIBLE_PX),
                   threshold=cfg.get("threshold", ADD_THRESHOLD), images=images)
    m = METHOD[entry.method]
    fig = plot_cases(ds, res, n_good=n_good, n_bad=n_bad, ncols=ncols,
                     title=f"{m.label}, {MASKS[entry.masks]}, {SPLITS[entry.split]} split: GT (green), estimate (red)")
    return fig, None


def placeholder_figure(text: str, size=(6.0, 1.2)):
    """A small figure that only says ``text`` (where a figure cannot be drawn, the document says why)."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=size)
    ax.axis("off")
    ax.text(0.5, 0.5, text, ha="center", va="center", wrap=True, fontsize=9)
    return fig


def draw_fig7(entries: dict, name: str, root: str | Path = ".", **kw):
    """Fig. 7 for the evaluation ``name`` (e.g. ``test_gt_learned_it2``) with :func:`fig7`.

    Returns:
        ``(figure, reason)``: the figure, and None; or a :func:`placeholder_figure` saying why it could not
        be drawn, and that reason.
    """
    key = parse_name(name)
    entry = entries.get(key) if key else None
    fig, why = (None, f"no result {name} among the evaluations") if entry is None else fig7(entry, root, **kw)
    if fig is None:
        return placeholder_figure(f"Fig. 7 not drawn: {why}"), why
    return fig, None


def _manifest(path: Path) -> dict | None:
    import json

    try:
        return json.loads((path / "manifest.json").read_text())
    except (OSError, ValueError):
        return None


def _images(n) -> str:
    # plain text (a \\val value is escaped for LaTeX): the thousands comma needs no braces outside maths
    return "n/a" if n is None else f"{int(n):,} image{'' if n == 1 else 's'}"


def dataset_values(entries: dict, root: str | Path = ".", train_data: str | Path | None = None) -> dict[str, str]:
    """Sizes of the datasets behind the results, for the write-up's ``\\val{...}`` macros:
    ``images@<split>`` (``"200 images"``) and ``seed@<split>`` for each split with results (from the
    manifest of the dataset the result names, relative to ``root``), and ``images@train`` from
    ``train_data``; ``n/a`` where the dataset is not here."""
    out: dict[str, str] = {}
    for split in ("test", "single"):
        e = next((e for k, e in sorted(entries.items()) if k[0] == split), None)
        data = (e.result.config or {}).get("data") if e is not None else None
        man = _manifest(Path(root) / data) if data else None
        out[f"images@{split}"] = _images(man.get("num_images")) if man else "n/a"
        out[f"seed@{split}"] = str(man.get("seed")) if man and man.get("seed") is not None else "n/a"
    man = _manifest(Path(train_data)) if train_data else None
    out["images@train"] = _images(man.get("num_images")) if man else "n/a"
    return out


_VAL_LINE = re.compile(r"^\\expandafter\\def\\csname sdp@val@(?P<name>[^\\]+)\\endcsname\{(?P<value>.*)\}$")


def previous_values(macros_path: str | Path) -> dict[str, str]:
    """The ``\\val`` values of an existing macro file (name -> LaTeX text; empty when there is none)."""
    try:
        text = Path(macros_path).read_text(encoding="utf-8")
    except OSError:
        return {}
    return {m.group("name"): m.group("value") for m in map(_VAL_LINE.match, text.splitlines()) if m}


def keep_known(values: dict[str, str], macros_path: str | Path) -> tuple[dict[str, str], list[str]]:
    """``values`` (e.g. :func:`dataset_values`) with each ``n/a`` replaced by the value the existing macro
    file ``macros_path`` holds under the same name: the sizes of datasets that are not here (a fresh clone
    builds the write-up from the committed results) stay what the build that had them wrote. Only plain
    values are kept (text that LaTeX escaping leaves as it is).

    Returns:
        the values, and the names whose value was kept.
    """
    old = previous_values(macros_path)
    out, kept = dict(values), []
    for k, v in values.items():
        prev = old.get(k)
        if v == "n/a" and prev not in (None, "n/a") and tex_escape(prev) == prev:
            out[k] = prev
            kept.append(k)
    return out, kept


# --------------------------------------------------------------------------------------------
# the macro file of the write-up: every number of its prose
# --------------------------------------------------------------------------------------------
#: Figures of a result exposed as ``\res{<name>}{<field>}``: field -> (figure key, decimals).
MACRO_FIELDS = {
    "acc": ("accuracy", 2),
    "accobj": ("mean_object_accuracy", 2),
    "ngt": ("n_gt", 0),
    "ncorrect": ("n_correct", 0),
    "fps": ("fps", 2),
    "ips": ("instances_per_s", 2),
    "nimages": ("n_images", 0),
}
SMALL_PROFILES = ("smoke", "demo")


def _num(v, digits: int) -> str:
    if v is None:
        return "n/a"
    return f"{v:,.0f}".replace(",", "{,}") if digits == 0 else f"{v:.{digits}f}"


def _def(name: str, value: str) -> str:
    return f"\\expandafter\\def\\csname {name}\\endcsname{{{value}}}"


def _best(entries: dict, split: str, masks: str, kind: str,
          preset: str = "default") -> tuple[Method | None, float | None]:
    """The most accurate method of ``kind`` (hybrid ones of registration ``preset``; learned ones are all
    ``default``) on ``split`` / ``masks`` and its accuracy (tied methods named together); ``(None, None)``
    without results."""
    cands = [(e.figure("accuracy"), METHOD[m]) for (s, k, m), e in entries.items()
             if s == split and k == masks and METHOD[m].kind == kind and METHOD[m].preset == preset
             and e.figure("accuracy") is not None]
    if not cands:
        return None, None
    acc = max(c[0] for c in cands)
    tied = [m for m in METHODS if any(c[1] == m and round(c[0], 2) == round(acc, 2) for c in cands)]
    if len(tied) == 1:
        return tied[0], acc
    names = [m.label for m in tied]
    label = " and ".join(names) if len(names) == 2 else f"{names[0]}, {names[1]} and {len(names) - 2} more"
    return Method(tied[0].key, f"{label} (tied)", kind, tied[0].command), acc


def macros(entries: dict, profile: str, extra: dict | None = None) -> str:
    """The LaTeX macro file of the write-up (``paper/generated/<profile>/macros.tex``).

    Defines ``\\res{name}{field}`` (a result's figure: ``acc``, ``accobj`` in %, ``ngt``, ``ncorrect``,
    ``fps``, ``ips``, ``nimages``; ``n/a`` and a LaTeX warning when the result is missing),
    ``\\paperres{table}{method key}`` (the paper's figure), ``\\method{key}`` (a method's label),
    ``\\best{split}{masks}{kind}`` / ``\\bestacc{...}`` (the best method of a kind and its accuracy),
    ``\\profile``, the ``\\ifsmallprofile`` / ``\\iflmo`` switches, the commits, dates and machines of the
    results, and ``extra`` (name -> text, e.g. dataset sizes) as ``\\val{name}``.
    """
    lines = [
        "% Generated by notebook 07 (sixdpose.evaluation.report.macros) from the result files; do not edit.",
        "% Every number in the write-up's prose comes from here.",
        "\\makeatletter",
        "\\newcommand{\\res}[2]{\\ifcsname sdp@res@#1@#2\\endcsname\\csname sdp@res@#1@#2\\endcsname"
        "\\else\\textbf{n/a}\\PackageWarning{sixdpose}{no result #1 (#2)}\\fi}",
        "\\newcommand{\\paperres}[2]{\\ifcsname sdp@paper@#1@#2\\endcsname\\csname sdp@paper@#1@#2\\endcsname"
        "\\else\\textbf{??}\\PackageWarning{sixdpose}{no paper figure #1 #2}\\fi}",
        "\\newcommand{\\method}[1]{\\csname sdp@method@#1\\endcsname}",
        "\\newcommand{\\best}[3]{\\ifcsname sdp@best@#1@#2@#3\\endcsname"
        "\\csname sdp@best@#1@#2@#3\\endcsname\\else n/a\\fi}",
        "\\newcommand{\\bestacc}[3]{\\ifcsname sdp@bestacc@#1@#2@#3\\endcsname"
        "\\csname sdp@bestacc@#1@#2@#3\\endcsname\\else n/a\\fi}",
        "\\newcommand{\\val}[1]{\\ifcsname sdp@val@#1\\endcsname\\csname sdp@val@#1\\endcsname"
        "\\else\\textbf{??}\\PackageWarning{sixdpose}{no value #1}\\fi}",
        f"\\newcommand{{\\profile}}{{{tex_escape(profile)}}}",
        "\\newif\\ifsmallprofile" + ("\\smallprofiletrue" if profile in SMALL_PROFILES else "\\smallprofilefalse"),
        "\\newif\\iflmo" + ("\\lmotrue" if any(k[0] == "lmo" for k in entries) else "\\lmofalse"),
    ]
    for m in METHODS:
        lines.append(_def(f"sdp@method@{m.key}", tex_escape(m.label)))
    for (_split, _masks, _method), e in sorted(entries.items()):
        for field_, (key, digits) in MACRO_FIELDS.items():
            lines.append(_def(f"sdp@res@{e.name}@{field_}", _num(e.figure(key), digits)))
    for t, keyattr in (("III", "paper_acc"), ("I", "paper_acc"), ("II", "paper_fps")):
        for m in METHODS:
            label = getattr(m, keyattr)
            if label and label in TABLES[t].rows:
                lines.append(_def(f"sdp@paper@{t}@{m.key}", f"{TABLES[t].rows[label]:.2f}"))
    for split in SPLITS:
        for masks in MASKS:
            for kind in ("hybrid", "learned"):
                m, acc = _best(entries, split, masks, kind)
                if m is not None:
                    lines.append(_def(f"sdp@best@{split}@{masks}@{kind}", tex_escape(m.label)))
                    lines.append(_def(f"sdp@bestacc@{split}@{masks}@{kind}", _num(acc, 2)))
    provs = [e.result.provenance for e in entries.values()]
    commits = sorted({(p.get("commit") or "unknown")[:7] + (" (modified)" if p.get("dirty") else "") for p in provs})
    dates = sorted({str(p.get("date", "?"))[:10] for p in provs})
    vals = {"nresults": str(len(entries)), "commits": ", ".join(commits) or "none",
            "dates": (dates[0] if len(dates) == 1 else f"{dates[0]} to {dates[-1]}") if dates else "none",
            "machines": "; ".join(f"({v}) {k}" for k, v in machines(entries).items()) or "none"}
    vals.update(findings(entries))
    vals.update(extra or {})
    for k, v in vals.items():
        lines.append(_def(f"sdp@val@{k}", tex_escape(v) if not str(v).startswith("\\") else v))
    lines.append("\\makeatother")
    return "\n".join(lines) + "\n"


def _cmp(d: float) -> str:
    """``"3.20 points higher than"``, ``"3.20 points lower than"`` or ``"equal to"`` (``d`` in points, 2 decimals)."""
    if round(d, 2) == 0:
        return "equal to"
    return f"{abs(d):.2f} points {'higher' if d > 0 else 'lower'} than"


def _mean_change(entries: dict, pairs: list[tuple[tuple, tuple]]) -> tuple[float, int, tuple | None] | None:
    """Mean of ``acc(b) - acc(a)`` over the pairs where both exist, their number, and the pair of the largest change."""
    diffs = []
    for a, b in pairs:
        va, vb = _acc(entries, *a), _acc(entries, *b)
        if va is not None and vb is not None:
            diffs.append((vb - va, a, b))
    if not diffs:
        return None
    big = max(diffs, key=lambda d: abs(d[0]))
    return sum(d[0] for d in diffs) / len(diffs), len(diffs), (big[0], big[1])


def findings(entries: dict) -> dict[str, str]:
    """Sentences of computed comparisons for the write-up's "beyond the paper" section (each a
    ``\\val{finding@...}`` macro; ``n/a`` text where a result is missing). Keys: ``setting`` (best hybrid
    against best learned in the paper's setting, with the paper's own comparison), ``repeated``
    (single-instance against multi-instance, GT masks), ``masks`` (predicted against GT masks,
    single-instance), ``icp`` (hybrid methods with ICP against without), ``refine`` (2 refinement
    iterations against none), ``colour`` (colour verification after refinement), ``threshold`` (the paper's
    setting at 5 and 20 % of the diameter), ``paper_settings`` (the hybrid rows rerun with the paper's
    registration settings against ours, over every split and mask source where both ran)."""
    out = {}
    mh, ah = _best(entries, "single", "pred", "hybrid")
    ml, al = _best(entries, "single", "pred", "learned")
    ph = max(v for k, v in TABLES["III"].rows.items() if "Hybrid" in k)
    pl = max(v for k, v in TABLES["III"].rows.items() if "Full Learning" in k)
    if mh is not None and ml is not None:
        out["setting"] = (f"the best hybrid method ({mh.label}, {ah:.2f} %) is {_cmp(ah - al)} the best learned one "
                          f"({ml.label}, {al:.2f} %); in the paper the best hybrid row is {_cmp(ph - pl)} the best "
                          f"learned one ({ph:.2f} against {pl:.2f} %)")
    else:
        out["setting"] = "n/a (the single-instance, predicted-mask results of a hybrid and a learned method are needed)"

    def mean_sentence(pairs, b, a, what):
        r = _mean_change(entries, pairs)
        if r is None:
            return f"n/a (no {what} pair of results)"
        mean, n, (d, k) = r
        if n == 1:
            return f"ADD(-S) accuracy {b} is {_cmp(mean)} {a}"
        return (f"ADD(-S) accuracy {b} is {_cmp(mean)} {a} on average over {n} methods "
                f"(largest change: {METHOD[k[2]].label}, {d:+.2f} points)")

    keys = [m.key for m in METHODS]
    out["repeated"] = mean_sentence(
        [(("test", "gt", k), ("single", "gt", k)) for k in keys],
        "on the single-instance subset",
        "on the multi-instance split (GT masks)",
        "multi/single-instance",
    )
    out["masks"] = mean_sentence([(("single", "gt", k), ("single", "pred", k)) for k in keys],
                                 "with predicted masks", "with GT masks (single-instance subset)", "GT/predicted-mask")
    out["icp"] = mean_sentence(
        [(("test", "gt", k), ("test", "gt", k + "_icp")) for k in HYBRID_ALGORITHMS],
        "with ICP",
        "without (hybrid methods, multi-instance split, GT masks)",
        "ICP",
    )
    out["refine"] = mean_sentence(
        [(("test", "gt", "learned_it0"), ("test", "gt", "learned_it2"))],
        "after 2 refinement iterations",
        "without refinement (multi-instance split, GT masks)",
        "refinement",
    )
    out["colour"] = mean_sentence(
        [(("test", "gt", "learned_it2"), ("test", "gt", "learned_it2_colour"))],
        "with colour verification",
        "without (learned + 2 iterations, multi-instance split, GT masks)",
        "colour-verification",
    )
    out["paper_settings"] = mean_sentence(
        [((s, k, m.key.removesuffix("_paper")), (s, k, m.key)) for m in METHODS if m.preset == "paper"
         for s, k in (("single", "pred"), ("single", "gt"), ("test", "gt"), ("test", "pred"))],
        "with the paper's registration settings (rerun)",
        "with ours (tuned on the validation split)",
        "paper-settings/ours",
    )
    best = entries.get(("single", "pred", mh.key)) if mh is not None else None
    if best is not None and best.curve is not None:
        x, y = best.curve
        at = {t: y[x.index(t)] for t in (5.0, 10.0, 20.0) if t in x}
        out["threshold"] = (
            f"{mh.label} goes from {at.get(5.0, math.nan):.2f} % at 5 % of the diameter to "
            f"{at.get(20.0, math.nan):.2f} % at 20 % ({at.get(10.0, math.nan):.2f} % at the paper's 10 %)"
        )
    else:
        out["threshold"] = "n/a (no accuracy curve recorded for the paper's setting)"
    return {f"finding@{k}": v for k, v in out.items()}


def write_macros(entries: dict, profile: str, path, extra: dict | None = None) -> Path:
    """Write :func:`macros` atomically to ``path``."""
    return atomic_write_text(path, macros(entries, profile, extra))


# --------------------------------------------------------------------------------------------
# beyond the paper: the synthetic-to-real branch and the pose ablation (other result files of the graph)
# --------------------------------------------------------------------------------------------
#: The kinect / ideal-depth pairs of :data:`sixdpose.registry.REAL_METHODS` beyond the networks alone (both
#: networks of a pair trained alike, the same stage after both), for the write-up's sensor sentence:
#: ``(kinect key, ideal key, what the pair is)``.
SENSOR_PAIRS = (
    ("learned_e12", "learned_ideal_e12", "trained 12 epochs instead of 6"),
    ("learned_it2", "learned_ideal_it2", "after 2 refinement iterations (each network with its own refiner)"),
    ("learned_icp", "learned_ideal_icp", "after ICP"),
    ("learned_colour", "learned_ideal_colour", "after colour verification"),
)


def _optional(results_dir, name: str) -> Result | None:
    return read_result(name, results_dir) if (Path(results_dir) / f"{name}.json").is_file() else None


def real_table(results_dir: str | Path, name: str = "ycbv") -> list[dict]:
    """The methods on real frames (``<name>_gt_<method>.json`` of the graph's synthetic-to-real branch):
    rows ``method, trained_on, accuracy, n_gt, ar, adds_auc`` for the results that exist (empty: none)."""
    rows = []
    for m in REAL_METHODS:
        r = _optional(results_dir, f"{name}_gt_{m.key}")
        if r is None:
            continue
        f, b = r.figures, r.figures.get("bop") or {}
        rows.append(
            {
                "method": m.label,
                "trained_on": m.trained_on or "--",
                "accuracy": f.get("accuracy"),
                "n_gt": f.get("n_gt"),
                "ar": b.get("ar"),
                "adds_auc": b.get("adds_auc"),
            }
        )
    return rows


def write_real_table(results_dir: str | Path, csv_path, tex_path, name: str = "ycbv") -> list[dict]:
    """Write :func:`real_table` as CSV and LaTeX (one row saying so when there are no results); returns its rows."""
    rows = real_table(results_dir, name)
    table = rows or [{"method": "not run at this profile (make ycbv PROFILE=cpu)", "trained_on": "", "accuracy": None,
                      "n_gt": None, "ar": None, "adds_auc": None}]
    write_table(table, ["method", "trained_on", "accuracy", "n_gt", "ar", "adds_auc"], csv_path, tex_path,
                headers=["Method", "trained only on", "ADD(-S)", "GT", "AR", "ADD-S AUC"], align="llrrrr",
                comment=f"generated by sixdpose.evaluation.report from {len(rows)} result file(s) {name}_gt_*")
    return rows


#: The result of ``benchmarks/table2_fps.py --out <results dir>/table2_fps.json``: Table II as the paper
#: measured it (end-to-end, segmentation and every overhead included).
TABLE2_BENCH = "table2_fps"


def table2_e2e(results_dir: str | Path) -> list[dict]:
    """Table II end to end: per method of the benchmark ``table2_fps`` (when it ran into ``results_dir``),
    ``method`` (label), ``paper`` (the paper's Table II FPS, where it has the row), ``e2e_fps`` (Mask R-CNN
    + the pose stage, disk reads excluded), ``pose_fps`` (the pose stage alone, GT masks), ``seg_ms``
    (Mask R-CNN per frame), ``instances`` (per frame). Empty when the benchmark has not run there.

    Raises:
        ReportError: a row names no method of :data:`sixdpose.registry.METHODS` (one line naming the file).
    """
    r = _optional(results_dir, TABLE2_BENCH)
    if r is None:
        return []
    rows = []
    for row in r.rows:
        m = METHOD.get(str(row.get("method")))
        if m is None:
            raise ReportError(f"{r.path}: method {row.get('method')!r} is not a method of the graph")
        n = row.get("frames") or 0
        rows.append({"method": m.label, "paper": TABLES["II"].rows.get(m.paper_fps) if m.paper_fps else None,
                     "e2e_fps": row.get("e2e_fps"), "pose_fps": row.get("pose_fps"),
                     "seg_ms": row.get("seg_ms_per_frame"),
                     "instances": (row.get("instances") or 0) / n if n else None})
    return rows


def write_table2_e2e(results_dir: str | Path, csv_path, tex_path) -> list[dict]:
    """Write :func:`table2_e2e` as CSV and LaTeX (one row saying how to run it when it has not run); returns
    its rows."""
    rows = table2_e2e(results_dir)
    table = rows or [{"method": "not run (python benchmarks/table2_fps.py --out RESULTS/table2_fps.json)",
                      "paper": None, "e2e_fps": None, "pose_fps": None, "seg_ms": None, "instances": None}]
    write_table(table, ["method", "paper", "e2e_fps", "pose_fps", "seg_ms", "instances"], csv_path, tex_path,
                headers=["Method", "Table II FPS", "end-to-end FPS", "pose-stage FPS", "Mask R-CNN ms",
                         "inst./frame"], align="lrrrrr", digits=3,
                comment=f"generated by sixdpose.evaluation.report from {TABLE2_BENCH} ({len(rows)} rows)")
    return rows


def table2_e2e_note(results_dir: str | Path) -> str:
    """One sentence on how the end-to-end Table II was measured (frames, data, networks, machine, date),
    or that it has not run; for the write-up's ``\\val{finding@fps_e2e}``."""
    r = _optional(results_dir, TABLE2_BENCH)
    if r is None:
        return ("The end-to-end benchmark has not run at this profile (python benchmarks/table2_fps.py --out "
                "results/<profile>/table2_fps.json), so the table is empty.")
    c = r.config or {}
    frames = max((row.get("frames") or 0 for row in r.rows), default=0)
    return (f"Measured by benchmarks/table2_fps.py on {frames} frames of {Path(str(c.get('data', '?'))).name} "
            f"({c.get('split', '?')}), loaded into memory first; Mask R-CNN: {c.get('segmentation', '?')}; "
            f"learned networks: {c.get('pose', '?')}; registration preset {c.get('preset', '?')}; on "
            f"{machine_text(r.provenance)}, {str(r.provenance.get('date', '?'))[:10]}"
            + (f" ({r.notes})." if r.notes else "."))


#: Columns of the ablation tables (the ``sixdpose pose-ablation`` results ``pose_ablation_<profile>`` and, over
#: seeds, ``pose_ablation_seeds_<profile>``: ``val_add`` is then the mean over the seeds, ``val_add_std`` their
#: spread; absent in a one-seed result).
ABLATION_COLUMNS = ("variant", "network", "translation", "rotation", "norm", "steps", "train_seconds", "val_add",
                    "val_add_std", "seeds", "n_val")
#: The result names of the two ablations, the one the claims prefer first: over seeds, then each option
#: alone (one seed).
ABLATIONS = ("pose_ablation_seeds", "pose_ablation")


def ablation_table(results_dir: str | Path, profile: str, name: str = "pose_ablation") -> list[dict]:
    """The rows of ``<name>_<profile>.json`` (empty when the profile's ablation has not run); a row without
    ``network`` (a result from before the refiner rows) is a ``pose`` row, one without ``seeds`` has 1."""
    r = _optional(results_dir, f"{name}_{profile}")
    if r is None:
        return []
    defaults = {"network": "pose", "seeds": 1}
    return [{c: row.get(c, defaults.get(c)) for c in ABLATION_COLUMNS} for row in r.rows]


def write_ablation_table(results_dir: str | Path, profile: str, csv_path, tex_path,
                         name: str = "pose_ablation") -> list[dict]:
    """Write :func:`ablation_table` as CSV and LaTeX (one row saying so when it has not run); returns its rows."""
    rows = ablation_table(results_dir, profile, name)
    table = rows or [{"variant": "not run at this profile", **{c: None for c in ABLATION_COLUMNS[1:]}}]
    write_table(table, list(ABLATION_COLUMNS), csv_path, tex_path,
                headers=["Variant", "network", "translation", "rotation", "norm", "steps", "train s",
                         "val ADD(-S)", "std", "seeds", "val GT"],
                align="lllllrrrrrr", comment=f"generated by sixdpose.evaluation.report from {name}_{profile}")
    return rows


def beyond_findings(results_dir: str | Path, profile: str, name: str = "ycbv") -> dict[str, str]:
    """Sentences for the write-up on the real frames (``finding@real``, ``finding@sensor``), the ablation
    (``finding@ablation``) and the end-to-end Table II (``finding@fps_e2e``, :func:`table2_e2e_note`),
    computed from the result files. Each is a whole sentence (or empty where it has nothing to compare),
    saying so where the profile did not run the results it needs."""
    out = {}
    real = {m.key: _optional(results_dir, f"{name}_gt_{m.key}") for m in REAL_METHODS}
    acc = {k: (r.figures.get("accuracy") if r else None) for k, r in real.items()}
    auc = {k: ((r.figures.get("bop") or {}).get("adds_auc") if r else None) for k, r in real.items()}
    if acc["learned"] is not None:
        hybrid = [(acc[m.key], m.label) for m in REAL_METHODS if m.kind == "hybrid" and acc[m.key] is not None]
        s = (f"The network trained only on generated data reaches {acc['learned']:.2f} % ADD(-S) on "
             f"{real['learned'].figures.get('n_gt')} real instances")
        if acc["learned_colour"] is not None:
            s += f", and {acc['learned_colour']:.2f} % with the hybrid stage's colour verification after it"
        if hybrid:
            h = max(hybrid)
            s += f"; the best hybrid method, which needs no training data, reaches {h[0]:.2f} % ({h[1]})"
        out["real"] = s + "."
    else:
        out["real"] = ("This profile does not run that branch (the cpu and paper profiles do, and make ycbv runs it "
                       "alone), so the table is empty.")
    if acc["learned"] is not None and acc["learned_ideal"] is not None:
        s = (f"Trained on the kinect sensor model's depth, the network scores {acc['learned']:.2f} % ADD(-S), "
             f"{_cmp(acc['learned'] - acc['learned_ideal'])} the same network trained on ideal depth "
             f"({acc['learned_ideal']:.2f} %)")
        if auc["learned"] is not None and auc["learned_ideal"] is not None:
            s += (
                f"; its ADD-S AUC, which rewards every millimetre, is {auc['learned']:.2f}, "
                f"{_cmp(auc['learned'] - auc['learned_ideal'])} the ideal-depth network's ({auc['learned_ideal']:.2f})"
            )
        s += "."
        pairs = [(label, acc[k], acc[k_ideal]) for k, k_ideal, label in SENSOR_PAIRS
                 if acc[k] is not None and acc[k_ideal] is not None]
        if pairs:
            s += (" Kinect against ideal depth in the other pairs (both networks of a pair trained alike, the same "
                  "stage after both): ") + "; ".join(
                f"{a:.2f} % {label}, {_cmp(a - b)} the ideal-depth pair ({b:.2f} %)" for label, a, b in pairs) + "."
        out["sensor"] = s
    else:
        out["sensor"] = ""
    out["fps_e2e"] = table2_e2e_note(results_dir)
    rows = ablation_table(results_dir, profile)
    scored = [r for r in rows if r.get("val_add") is not None]
    if scored:
        best = max(scored, key=lambda r: r["val_add"])
        paper = next((r for r in scored if str(r["variant"]).startswith("paper")), None)
        s = f"The best of {len(scored)} variants on the validation split is {best['variant']} ({best['val_add']:.2f} %)"
        if paper is not None:
            s += f"; the paper's choices reach {paper['val_add']:.2f} %"
        out["ablation"] = s + "."
    else:
        out["ablation"] = "This profile has not run the ablation, so the table is empty."
    seeded = [r for r in ablation_table(results_dir, profile, "pose_ablation_seeds") if r.get("val_add") is not None]
    if seeded:
        out["ablation_seeds"] = (f"Over {min(int(r.get('seeds') or 1) for r in seeded)} seeds: " + "; ".join(
            f"{r['variant']} {r['val_add']:.2f} +- {float(r.get('val_add_std') or 0):.2f} %" for r in seeded) + ".")
    else:
        out["ablation_seeds"] = "This profile has not run the ablation over seeds, so its table is empty."
    return {f"finding@{k}": v for k, v in out.items()}


def shape_summary(entries: dict, tables: dict) -> str:
    """Counts and shapes only (deterministic for given result files; no figure, time or path): the
    evaluations per split and mask source, and per table (name -> rows as dicts, or objects with a
    ``__dict__``) its rows, columns and filled cells. Notebook 07 prints it in the cell CI compares
    (:mod:`sixdpose.reporting.nbcheck`)."""
    lines = [f"{len(entries)} evaluations"]
    for split in SPLITS:
        for masks in MASKS:
            keys = sorted(k[2] for k in entries if k[:2] == (split, masks))
            if keys:
                lines.append(f"  {split}/{masks}: {len(keys)} ({', '.join(keys)})")
    for name, rows in tables.items():
        rows = [r if isinstance(r, dict) else vars(r) for r in rows]
        cols = sorted({c for r in rows for c in r})
        filled = sum(1 for r in rows for v in r.values() if v is not None and v != "")
        lines.append(f"{name}: {len(rows)} rows x {len(cols)} columns, {filled} cells filled")
    return "\n".join(lines)


def write_dataset_table(stats_csv: str | Path, tex_path, how: str) -> str:
    """The write-up's dataset table from notebook 02's statistics when they are here (:func:`dataset_table`);
    else the table already at ``tex_path`` is kept (written where the dataset was; its time is updated);
    else a one-row table says what makes it (``how``, e.g. the make target of notebook 02).

    Returns:
        one line saying which of the three happened.
    """
    stats_csv, tex_path = Path(stats_csv), Path(tex_path)
    if stats_csv.is_file():
        dataset_table(stats_csv, tex_path)
        return f"{tex_path.name}: from {stats_csv}"
    if tex_path.is_file():
        tex_path.touch()  # made by this build (for make: newer than the results it was built beside)
        return f"{tex_path.name}: kept as it is ({stats_csv} is not here; {how} writes it)"
    write_table([{"quantity": f"not computed: {how}", "paper": "", "this dataset": ""}],
                ["quantity", "paper", "this dataset"], None, tex_path,
                headers=["Quantity", "Paper (section III)", "This dataset"],
                align="p{0.34\\linewidth}p{0.28\\linewidth}p{0.28\\linewidth}",
                comment=f"{stats_csv.name} (notebook 02) was not here")
    return f"{tex_path.name}: not computed ({stats_csv} is not here; {how} writes it)"


def dataset_table(stats_csv: str | Path, tex_path) -> Path:
    """The dataset statistics of notebook 02 (``dataset_statistics.csv``: quantity, paper, this dataset)
    as a LaTeX table (``p{}`` columns; text escaped).

    Raises:
        ReportError: the CSV is missing or lacks those columns (one line naming it).
    """
    import csv

    stats_csv = Path(stats_csv)
    try:
        with open(stats_csv, newline="", encoding="utf-8") as f:
            rows = list(csv.DictReader(f))
    except OSError as e:
        raise ReportError(
            f"{stats_csv}: cannot read the dataset statistics ({e.strerror or e}); run notebook 02"
        ) from None
    need = ("quantity", "paper", "this dataset")
    if not rows or any(c not in rows[0] for c in need):
        raise ReportError(f"{stats_csv}: expected the columns {', '.join(need)}")
    write_table(
        rows,
        list(need),
        None,
        tex_path,
        headers=["Quantity", "Paper (section III)", "This dataset"],
        align="p{0.34\\linewidth}p{0.28\\linewidth}p{0.28\\linewidth}",
        comment=f"from {stats_csv.name} (notebook 02)",
    )
    return Path(tex_path)
