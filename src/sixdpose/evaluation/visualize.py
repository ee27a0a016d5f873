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
