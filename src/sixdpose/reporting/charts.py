"""Charts of the tables of notebook 07, drawn from the result files alone (no dataset, no run directory),
so the committed ``results/<profile>/`` draw them on a fresh clone (``make tables``).

Every ``plot_*`` function is pure: rows of :mod:`sixdpose.reporting.report` (or its entries) in, a
matplotlib ``Figure`` out, or None when there is nothing to draw (then no file is written: a chart of
nothing would only say so). :func:`write_charts` draws them all into a figures directory and returns the
file names it wrote and, for each chart it skipped, why. :func:`save` writes a PNG without the matplotlib
version in its metadata, so the same results give the same bytes.
"""

from __future__ import annotations

import math
from pathlib import Path

from ..registry import METHODS, REAL_METHODS
from .report import MASKS, SPLITS, TABLE3_COLUMNS, ablation_table, per_object, real_table, table2, table3

#: Colours of the bars of one group (the paper's column first, always grey).
_PAPER_COLOUR = "0.6"


def _num(v) -> float | None:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) else None


def save(fig, path: str | Path, dpi: int = 110) -> Path:
    """Write ``fig`` as a PNG at ``path`` (parents made; no software tag in the metadata) and close it."""
    import matplotlib.pyplot as plt

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi, metadata={"Software": None})
    plt.close(fig)
    return path


def _bars(labels: list[str], series: list[tuple[str, list[float | None], str]], xlabel: str, title: str,
          log: bool = False, width_in: float = 7.0):
    """Horizontal grouped bars: one group per label (top to bottom), one bar per series ``(name, values,
    colour)``; a missing value leaves its slot empty. Values are printed at the end of their bars."""
    import matplotlib.pyplot as plt

    n, k = len(labels), len(series)
    fig, ax = plt.subplots(figsize=(width_in, 0.9 + n * (0.18 * k + 0.12)))
    h = 0.8 / k
    for j, (name, values, colour) in enumerate(series):
        ys = [i + (j - (k - 1) / 2) * h for i in range(n)]
        pts = [(y, v) for y, v in zip(ys, values, strict=True) if v is not None]
        if not pts:
            continue
        ax.barh([y for y, _ in pts], [v for _, v in pts], height=h * 0.92, color=colour, label=name)
        for y, v in pts:
            ax.text(v, y, f" {v:.1f}" if v < 100 or log else f" {v:.0f}", va="center", fontsize=6)
    ax.set_yticks(range(n))
    ax.set_yticklabels(labels, fontsize=8)
    ax.invert_yaxis()
    if log:
        ax.set_xscale("log")
    ax.set_xlabel(xlabel, fontsize=8)
    ax.tick_params(axis="x", labelsize=7)
    ax.grid(axis="x", alpha=0.3)
    ax.set_title(title, fontsize=9)
    handles, names = ax.get_legend_handles_labels()
    fig.legend(handles, names, fontsize=7, loc="lower center", ncol=min(len(names), 2), frameon=False)
    fig.tight_layout(rect=(0, 0.03 + 0.035 * math.ceil(len(names) / 2), 1, 1))
    return fig


def plot_table3(rows: list[dict], title: str = ""):
    """Table III as bars (:func:`sixdpose.reporting.report.table3` rows): per method the paper's figure
    and ours in each setting that has a result. None when no method of ours has a result."""
    cols = [(c, head) for c, _s, _m, head in TABLE3_COLUMNS if any(_num(r.get(c)) is not None for r in rows)]
    shown = [r for r in rows if any(_num(r.get(c)) is not None for c, _ in cols)]
    if not cols or not shown:
        return None
    colours = {"single_pred": "tab:blue", "single_gt": "tab:cyan", "test_pred": "tab:orange", "test_gt": "tab:red"}
    series = [("paper (its data, pred. masks, single-instance)", [_num(r.get("paper")) for r in shown], _PAPER_COLOUR)]
    series += [(f"ours: {head}", [_num(r.get(c)) for r in shown], colours.get(c, "tab:olive")) for c, head in cols]
    return _bars([r["method"] for r in shown], series, "ADD(-S) accuracy (%)",
                 title or "Table III: ADD(-S) on the generated data (paper beside ours)")


def plot_table2(rows: list[dict], title: str = ""):
    """Table II as bars on a log axis (:func:`sixdpose.reporting.report.table2` rows): frames per second
    of each method's pose stage with GT and predicted masks, the paper's figure beside. None without a
    measured FPS."""
    shown = [r for r in rows if _num(r.get("fps_gt")) is not None or _num(r.get("fps_pred")) is not None]
    if not shown:
        return None
    series = [("paper (LM-O, i9-12900K + RTX 3090 Ti)", [_num(r.get("paper")) for r in shown], _PAPER_COLOUR),
              ("ours, GT masks", [_num(r.get("fps_gt")) for r in shown], "tab:blue"),
              ("ours, predicted masks", [_num(r.get("fps_pred")) for r in shown], "tab:orange")]
    return _bars([r["method"] for r in shown], series, "frames per second of the pose stage (log scale)",
                 title or "Table II: frames per second (ours: the machine of each result's provenance)", log=True)


def plot_per_object(rows: list[dict], title: str = ""):
    """ADD(-S) % per object (rows) and method (columns) as a heat map with the numbers in the cells
    (:func:`sixdpose.reporting.report.per_object` rows, the two mean rows last). None when empty."""
    import matplotlib.pyplot as plt
    import numpy as np

    methods = [m for m in METHODS if any(_num(r.get(m.key)) is not None for r in rows)]
    if not rows or not methods:
        return None
    names = [("mean over instances" if r["obj_id"] == "all" else "mean over objects" if r["obj_id"] == "objects"
              else f"{r['obj_id']} {r['name']}") for r in rows]
    grid = np.array([[_num(r.get(m.key)) if _num(r.get(m.key)) is not None else np.nan for m in methods]
                     for r in rows])
    fig, ax = plt.subplots(figsize=(2.4 + 0.75 * len(methods), 0.9 + 0.24 * len(rows)))
    im = ax.imshow(np.ma.masked_invalid(grid), cmap="viridis", vmin=0, vmax=100, aspect="auto")
    for i in range(grid.shape[0]):
        for j in range(grid.shape[1]):
            v = grid[i, j]
            ax.text(j, i, "–" if np.isnan(v) else f"{v:.0f}", ha="center", va="center", fontsize=6,
                    color="white" if np.isnan(v) or v < 60 else "black")
    ax.set_xticks(range(len(methods)))
    ax.set_xticklabels([m.label for m in methods], rotation=35, ha="right", fontsize=7)
    ax.set_yticks(range(len(rows)))
    ax.set_yticklabels(names, fontsize=7)
    n_obj = sum(1 for r in rows if r["obj_id"] not in ("all", "objects"))
    ax.axhline(n_obj - 0.5, color="white", lw=1.5)
    fig.colorbar(im, ax=ax, fraction=0.03, pad=0.02).set_label("ADD(-S) %", fontsize=7)
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    return fig


def plot_real(rows: list[dict], title: str = ""):
    """The methods on real frames (:func:`sixdpose.reporting.report.real_table` rows) as bars: ADD(-S) %
    and the BOP average recall AR per method and training data. None without results."""
    if not rows:
        return None
    labels = [r["method"] + ("" if r["trained_on"] in ("", "--") else f" [{r['trained_on'].split()[0]}]")
              for r in rows]
    series = [("ADD(-S) %", [_num(r.get("accuracy")) for r in rows], "tab:blue"),
              ("AR (BOP)", [_num(r.get("ar")) for r in rows], "tab:green")]
    n_gt = next((r.get("n_gt") for r in rows if r.get("n_gt")), None)
    return _bars(labels, series, "% (ADD(-S) accuracy; BOP average recall)",
                 title or f"Real YCB-Video frames, {n_gt} GT instances\n"
                 "(learned: trained only on the generated data in [])")


def plot_real_curves(results_dir: str | Path, name: str = "ycbv", title: str = ""):
    """ADD(-S) accuracy against the threshold (0-20 % of the diameter) on the real frames, one line per
    method of the synthetic-to-real branch with a recorded curve (colour: the stage; dashed: trained on
    kinect depth, dotted: on ideal depth; solid: hybrid), the 10 % threshold marked. None without curves."""
    import matplotlib.pyplot as plt

    from ..artifacts.results import read_result

    curves = []
    for m in REAL_METHODS:
        p = Path(results_dir) / f"{name}_gt_{m.key}.json"
        if "jitter" in m.key or not p.is_file():
            continue
        c = read_result(p).figures.get("curve")
        if isinstance(c, dict) and c.get("threshold_pct"):
            curves.append((m, c["threshold_pct"], [math.nan if y is None else y for y in c["accuracy"]]))
    if not curves:
        return None
    stages = sorted({m.label for m, _, _ in curves}, key=[m.label for m, _, _ in curves].index)
    cmap = plt.get_cmap("tab10")
    fig, ax = plt.subplots(figsize=(9.0, 4.2))
    for m, x, y in curves:
        ls = "-" if m.kind == "hybrid" else ("--" if "ideal" not in m.key else ":")
        ax.plot(x, y, ls=ls, lw=1.4, color=cmap(stages.index(m.label) % 10),
                label=m.label + ("" if m.kind == "hybrid" else f" [{m.trained_on.split()[0]}]"))
    ax.axvline(10, color="0.5", lw=0.8, ls=":")
    ax.set_xlim(0, 20)
    ax.set_ylim(0, 100)
    ax.grid(alpha=0.3)
    ax.set_xlabel("threshold (% of the object's diameter)", fontsize=8)
    ax.set_ylabel("ADD(-S) accuracy (%)", fontsize=8)
    ax.legend(fontsize=6, loc="center left", bbox_to_anchor=(1.01, 0.5), frameon=False)
    ax.set_title(title or "Real frames: accuracy against the threshold (the paper's 10 % dotted)", fontsize=9)
    fig.tight_layout()
    return fig


def plot_ablation(rows: list[dict], title: str = ""):
    """The pose ablation (:func:`sixdpose.reporting.report.ablation_table` rows) as bars of the validation
    ADD(-S) per variant. None when it has not run."""
    shown = [r for r in rows if _num(r.get("val_add")) is not None]
    if not shown:
        return None
    steps = sorted({str(r["steps"]) for r in shown if r.get("steps") is not None})
    return _bars([str(r["variant"]) for r in shown], [("validation ADD(-S) %", [_num(r["val_add"]) for r in shown],
                                                        "tab:purple")],
                 "ADD(-S) accuracy on the validation split (%)",
                 title or f"Ablation of the network's choices ({', '.join(steps)} training steps each)")


def plot_speed_accuracy(rows: list[dict], title: str = "", speed_label: str = "instances per second per core"):
    """Accuracy against speed, one marker per row and an arrow from each method's row with a switch off to
    its row with it on (the verification benchmark: ``benchmarks/verify_ycbv_sample.py --figure``).

    Args:
        rows: dicts with ``method`` (str), ``verify`` (``"on"`` / ``"off"``), ``accuracy`` (%) and
            ``inst_per_s`` (instances per second per core; ``inst_per_s_median``, the median over repeated
            runs, instead where a row has it); rows without both numbers are left out.
    Returns:
        a matplotlib Figure, or None when no row has both numbers.
    """
    import matplotlib.pyplot as plt

    pts: list[tuple[str, str, float, float]] = []
    for r in rows:
        x = _num(r.get("inst_per_s_median"))
        x, y = (_num(r.get("inst_per_s")) if x is None else x), _num(r.get("accuracy"))
        if x is not None and y is not None:
            pts.append((str(r["method"]), str(r.get("verify", "")), x, y))
    if not pts:
        return None
    fig, ax = plt.subplots(figsize=(6.0, 4.0 + 0.13 * len(pts)))
    colours: dict[str, str] = {}
    for method, on, x, y in pts:
        c = colours.setdefault(method, f"C{len(colours)}")
        ax.scatter([x], [y], color=c, marker="o" if on == "on" else "s", zorder=3,
                   label=f"{method}, verification {on}")
        ax.annotate(f"{y:.1f}", (x, y), textcoords="offset points", xytext=(4, 4), fontsize=7)
    for method in colours:
        off = [(x, y) for m, on, x, y in pts if m == method and on == "off"]
        on_ = [(x, y) for m, on, x, y in pts if m == method and on == "on"]
        if off and on_:
            ax.annotate("", xy=on_[0], xytext=off[0], arrowprops={"arrowstyle": "->", "color": colours[method]})
    ax.set_xscale("log")
    from matplotlib.ticker import FormatStrFormatter

    for axis in (ax.xaxis,):  # plain numbers on the log axis (2, 3, 4, ... not 3 x 10^0)
        axis.set_major_formatter(FormatStrFormatter("%g"))
        axis.set_minor_formatter(FormatStrFormatter("%g"))
    ax.set_xlabel(f"{speed_label} (log scale)", fontsize=8)
    ax.set_ylabel("ADD(-S) accuracy (%)", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.grid(alpha=0.3)
    ax.set_title(title or "Hypothesis verification: accuracy against speed", fontsize=9)
    # below the axes, so that it hides no point
    ax.legend(fontsize=6, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=1, frameon=False)
    fig.tight_layout()
    return fig


def write_charts(entries: dict, results_dir: str | Path, profile: str, figures: str | Path) -> tuple[list[str], dict]:
    """Draw every chart of the results into ``figures``: ``table3.png``, ``table2_fps.png``,
    ``per_object_<split>_<masks>.png`` (each split and mask source with results), ``real_frames.png``,
    ``real_threshold.png`` (the synthetic-to-real branch) and ``ablation.png``.

    Returns:
        ``(written, skipped)``: the file names written, and file name -> why it was not drawn.
    """
    figures = Path(figures)
    tag = f" ({profile} profile)"
    todo = {
        "table3.png": (plot_table3(table3(entries), "Table III: ADD(-S) on the generated data" + tag),
                       "no result of ours on the test or single split"),
        "table2_fps.png": (plot_table2(table2(entries), "Table II: frames per second of the pose stage" + tag),
                           "no FPS measured on the test split"),
    }
    for split in ("test", "single", "lmo"):
        for masks in MASKS:
            rows = per_object(entries, split, masks)
            todo[f"per_object_{split}_{masks}.png"] = (
                plot_per_object(rows, f"ADD(-S) % per object: {SPLITS[split]} split, {MASKS[masks]}{tag}")
                if rows else None, f"no result on the {split} split with {masks} masks")
    todo["real_frames.png"] = (plot_real(real_table(results_dir)), "the synthetic-to-real branch has not run")
    todo["real_threshold.png"] = (plot_real_curves(results_dir), "no real-frame result with a recorded curve")
    todo["ablation.png"] = (plot_ablation(ablation_table(results_dir, profile)), "the ablation has not run")
    written, skipped = [], {}
    for fname, (fig, why) in todo.items():
        if fig is None:
            skipped[fname] = why
        else:
            save(fig, figures / fname)
            written.append(fname)
    return written, skipped

