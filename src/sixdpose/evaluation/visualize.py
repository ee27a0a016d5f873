"""Pose overlays for figures: model points projected at a pose over the image."""

from __future__ import annotations

import numpy as np

from ..datasets.geometry import project


def draw_pose(ax, rgb: np.ndarray, K: np.ndarray, points: np.ndarray, poses, title: str = "", max_points: int = 1500):
    """Show ``rgb`` on matplotlib axes ``ax`` with the model ``points`` projected at each pose.

    Args:
        poses: list of ``(R (3, 3), t (3,) metres, colour, label)``; e.g. GT in green, estimate in red.
    """
    ax.imshow(rgb)
    rng = np.random.default_rng(0)
    sel = points[rng.choice(len(points), min(len(points), max_points), replace=False)]
    for R, t, color, label in poses:
        uv, _ = project(sel, R, t, K)
        ax.scatter(uv[:, 0], uv[:, 1], s=0.3, c=color, alpha=0.5, label=label)
    ax.set_xlim(0, rgb.shape[1])
    ax.set_ylim(rgb.shape[0], 0)
    ax.set_title(title, fontsize=8)
    ax.axis("off")


def plot_cases(reader, result, n_good: int = 3, n_bad: int = 3, ncols: int = 3, title: str = "",
               max_points: int = 1500):
    """A grid of good and failed cases of an evaluation: GT (green) and estimate (red) model points
    projected over the image (the paper's Fig. 7 style).

    Args:
        reader: the :class:`~sixdpose.datasets.base.DatasetReader` that was evaluated.
        result: its :class:`~sixdpose.evaluation.evaluate.EvalResult` (``records`` carry the estimates).
        n_good, n_bad: cases of each kind (the first ones in image order). ncols: grid columns.
    Returns:
        the matplotlib ``Figure`` (``ceil((n_good + n_bad) / ncols)`` rows).
    """
    import math

    import matplotlib.pyplot as plt

    cases = [r for r in result.records if r.correct][:n_good] + [r for r in result.records if not r.correct][:n_bad]
    n = max(len(cases), 1)
    ncols = min(ncols, n)
    nrows = math.ceil(n / ncols)
    # constrained layout: tight_layout let each lower row's titles overlap the images above (fixed-aspect axes)
    fig, axes = plt.subplots(nrows, ncols, figsize=(3.4 * ncols, 2.8 * nrows), squeeze=False, layout="constrained")
    for ax in axes.flat:
        ax.axis("off")
    for ax, r in zip(axes.flat, cases, strict=False):  # the grid may have more axes than cases
        s = reader.load((r.scene_id, r.im_id), masks=False, depth=False)
        g, model = s.instances[r.gt_index], reader.model(r.obj_id)
        poses = [(g.R, g.t, "lime", "GT")]
        if r.estimate is not None:
            poses.append((r.estimate.R, r.estimate.t, "red", "estimate"))
        err = "no estimate" if r.estimate is None else f"err {r.error * 1000:.1f} mm"
        draw_pose(ax, s.rgb, s.K, model.points, poses, f"{'ok' if r.correct else 'fail'}: {model.obj_name} ({err})",
                  max_points=max_points)
    if title:
        fig.suptitle(title)
    return fig
