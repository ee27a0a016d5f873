"""Figures of a dataset: views with masks, the paper's Fig. 3 grid, GT projections (matplotlib)."""

from __future__ import annotations

import numpy as np

from .base import Sample
from .geometry import project


def _colors(n: int) -> np.ndarray:
    import matplotlib

    cmap = matplotlib.colormaps["tab20"]
    return np.array([cmap(i % 20)[:3] for i in range(n)])


def overlay_masks(sample: Sample, alpha: float = 0.5) -> np.ndarray:
    """RGB image (H, W, 3) uint8 with every instance mask tinted in its own colour."""
    img = sample.rgb.astype(np.float64) / 255.0
    for c, inst in zip(_colors(len(sample.instances)), sample.instances, strict=True):
        if inst.mask is not None:
            img[inst.mask] = (1 - alpha) * img[inst.mask] + alpha * c
    return (img * 255).round().astype(np.uint8)


def draw_pose(ax, sample: Sample, points_O: np.ndarray, R: np.ndarray, t: np.ndarray, color="lime", n: int = 1500,
              s: float = 0.5):
    """Scatter ``n`` model points projected at pose (R, t) onto ``ax`` (image coordinates)."""
    idx = np.linspace(0, len(points_O) - 1, min(n, len(points_O))).astype(int)
    uv, z = project(points_O[idx], R, t, sample.K)
    ok = z > 0
    ax.scatter(uv[ok, 0], uv[ok, 1], s=s, c=color, linewidths=0)


def _grid(n: int, ncols: int, cell: tuple[float, float]):
    """A figure with ``n`` image axes (axis lines off) in rows of ``ncols``; returns (fig, axes list)."""
    import matplotlib.pyplot as plt

    nrows = max(1, int(np.ceil(n / ncols)))
    fig, axes = plt.subplots(nrows, ncols, figsize=(cell[0] * ncols, cell[1] * nrows), squeeze=False)
    for ax in axes.ravel():
        ax.axis("off")
    return fig, list(axes.ravel())


def plot_views(samples: list[Sample], ncols: int = 3, masks: bool = True, title: str | None = None):
    """A grid of images (with masks if ``masks``), e.g. one scene's views or the paper's Fig. 3."""
    fig, axes = _grid(len(samples), ncols, (4, 3))
    for ax, s in zip(axes, samples, strict=False):  # the grid may have more axes than samples
        ax.imshow(overlay_masks(s) if masks else s.rgb)
        ax.set_title(f"image {s.im_id} (scene {s.scene_id}), {len(s.instances)} targets", fontsize=8)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return fig


def plot_gt_projection(samples: list[Sample], model_points: dict[int, np.ndarray], ncols: int = 2):
    """Images with every annotated instance's model points projected at its GT pose.

    Args:
        model_points: obj_id -> (N, 3) model points (metres, object frame).
    """
    fig, axes = _grid(len(samples), ncols, (6, 4.5))
    for ax, s in zip(axes, samples, strict=False):  # the grid may have more axes than samples
        ax.imshow(s.rgb)
        for c, inst in zip(_colors(len(s.instances)), s.instances, strict=True):
            draw_pose(ax, s, model_points[inst.obj_id], inst.R, inst.t, color=[c])
        ax.set_xlim(0, s.rgb.shape[1])
        ax.set_ylim(s.rgb.shape[0], 0)
        ax.set_title(f"image {s.im_id}: model points at the GT pose", fontsize=9)
    fig.tight_layout()
    return fig
