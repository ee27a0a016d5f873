"""Figures of the learned pose stage: training curves and accuracy against refinement iterations."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def plot_training(run_dir: str | Path, out: str | Path | None = None, title: str | None = None):
    """Loss per logged step (metres: the ADD / chamfer loss) and epoch means, plus the validation
    ADD(-S) accuracy per epoch when the run had ``--val``.

    Returns:
        the matplotlib figure.
    """
    import matplotlib.pyplot as plt

    from .train import read_metrics

    rows = read_metrics(run_dir)
    fig, ax = plt.subplots(figsize=(7, 3.6))
    steps = [r for r in rows if r.get("loss") is not None]
    ax.plot([r["step"] for r in steps], [r["loss"] for r in steps], color="k", lw=0.8, label="loss (m)")
    epochs = sorted({r["epoch"] for r in steps})
    means = [
        (max(r["step"] for r in steps if r["epoch"] == e), np.mean([r["loss"] for r in steps if r["epoch"] == e]))
        for e in epochs
    ]
    ax.plot([m[0] for m in means], [m[1] for m in means], "o-", color="tab:red", ms=3, lw=1, label="epoch mean")
    ax.set_yscale("log")
    ax.set_xlabel("step")
    ax.set_ylabel("loss (m)")
    val = [r for r in rows if r.get("val_add") is not None]
    if val:
        ax2 = ax.twinx()
        ax2.plot(
            [r["step"] for r in val], [r["val_add"] for r in val], "s--", color="tab:blue", ms=3, label="val ADD(-S) %"
        )
        ax2.set_ylabel("validation ADD(-S) (%)")
        ax2.legend(fontsize=7, loc="upper right")
    ax.legend(fontsize=7, loc="upper left")
    ax.set_title(title or f"training ({Path(run_dir).name})")
    fig.tight_layout()
    if out is not None:
        Path(out).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(out, dpi=120)
    return fig


def plot_iterations(table, out: str | Path | None = None):
    """ADD(-S) accuracy against the number of refinement iterations (``table``: rows with
    ``iterations`` and ``add_s``). Returns the figure."""
    import matplotlib.pyplot as plt

    rows = table.to_dict("records") if hasattr(table, "to_dict") else list(table)
    fig, ax = plt.subplots(figsize=(4.5, 3.2))
    ax.plot([r["iterations"] for r in rows], [r["add_s"] for r in rows], "o-")
    ax.set_xlabel("refinement iterations")
    ax.set_ylabel("ADD(-S) accuracy (%)")
    ax.set_xticks([r["iterations"] for r in rows])
    ax.grid(alpha=0.3)
    fig.tight_layout()
    if out is not None:
        Path(out).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(out, dpi=120)
    return fig
