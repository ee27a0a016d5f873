"""A tiny "shapes" dataset in the synthetic layout, for tests and benchmarks of this stage.

It is not a substitute for the generated dataset (no rendering, no real objects): each image shows a
few flat coloured shapes (one shape and colour per object class) on a noisy background, with exact
visible masks, written in the layout of :mod:`sixdpose.datasets.synthetic` so that it is read through
the normal reader. Poses are dummies (identity rotation, 1 m in front of the camera).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..constants import TARGET_OBJECTS
from ..datasets.layout import write_dataset

_COLORS = [(220, 40, 40), (40, 200, 60), (50, 80, 230), (230, 200, 30), (200, 50, 200), (30, 200, 210)]


def _shape_mask(kind: int, H: int, W: int, cx: float, cy: float, r: float, rng) -> np.ndarray:
    yy, xx = np.mgrid[0:H, 0:W]
    if kind == 0:  # disc
        return (xx - cx) ** 2 + (yy - cy) ** 2 <= r * r
    if kind == 1:  # axis-aligned rectangle, aspect 2:1
        return (np.abs(xx - cx) <= r) & (np.abs(yy - cy) <= r / 2)
    if kind == 2:  # triangle
        return (yy - cy <= r) & (yy - cy >= -r + 2 * np.abs(xx - cx))
    if kind == 3:  # ring
        d = (xx - cx) ** 2 + (yy - cy) ** 2
        return (d <= r * r) & (d >= (0.5 * r) ** 2)
    if kind == 4:  # cross
        return (((np.abs(xx - cx) <= r) & (np.abs(yy - cy) <= r / 4))
                | ((np.abs(yy - cy) <= r) & (np.abs(xx - cx) <= r / 4)))
    return (np.abs(xx - cx) + np.abs(yy - cy)) <= r  # diamond


def make_toy_dataset(
    root: str | Path,
    n_scenes: int = 2,
    views: int = 3,
    n_classes: int = 3,
    size: tuple[int, int] = (480, 640),
    instances: tuple[int, int] = (2, 4),
    seed: int = 0,
) -> Path:
    """Write a shapes dataset (synthetic layout) with ``n_scenes * views`` images to ``root``.

    Args:
        root: output directory (created).
        n_scenes, views: scenes and images per scene (image numbers 0, 1, ... overall).
        n_classes: object classes (at most 6), named/numbered as the first paper target objects.
        size: (H, W) of the images.
        instances: (min, max) instances per image (objects may repeat and overlap).
        seed: RNG seed.
    Returns:
        ``root`` as a Path.
    """
    if not 1 <= n_classes <= len(_COLORS):
        raise ValueError(f"n_classes must be in 1..{len(_COLORS)}")
    H, W = size
    rng = np.random.default_rng(seed)
    names = list(TARGET_OBJECTS[:n_classes])
    K = [[600.0, 0.0, (W - 1) / 2], [0.0, 600.0, (H - 1) / 2], [0.0, 0.0, 1.0]]
    images = []
    im = 0
    for scene in range(n_scenes):
        for _ in range(views):
            rgb = (rng.normal(110, 25, (H, W, 3))).clip(0, 255).astype(np.uint8)
            n = int(rng.integers(instances[0], instances[1] + 1))
            count = {}
            drawn = []  # (cls, inst, full mask) in painter's order
            for _ in range(n):
                c = int(rng.integers(n_classes))
                r = float(rng.uniform(0.09, 0.18) * H)
                cx, cy = rng.uniform(r, W - r), rng.uniform(r, H - r)
                m = _shape_mask(c, H, W, cx, cy, r, rng)
                k = count.get(c, 0)
                count[c] = k + 1
                col = np.array(_COLORS[c], float) * rng.uniform(0.85, 1.1)
                rgb[m] = (col + rng.normal(0, 8, (int(m.sum()), 3))).clip(0, 255).astype(np.uint8)
                drawn.append((c, k, m))
            objs = []
            occupied = np.zeros((H, W), bool)
            for c, k, m in reversed(drawn):  # later shapes occlude earlier ones
                vis = m & ~occupied
                occupied |= m
                objs.append({"obj_name": names[c], "obj_id": c + 1, "inst": k, "R": np.eye(3), "t": [0.0, 0.0, 1.0],
                             "mask": vis})
            images.append({"im_id": im, "scene_id": scene, "K": K, "rgb": rgb, "depth": np.ones((H, W), np.float32),
                           "instances": objs})
            im += 1
    models = {n: {"obj_id": i + 1, "diameter": 0.1, "symmetric": False} for i, n in enumerate(names)}
    return write_dataset(root, images, models, {"generator": "sixdpose.segmentation.toydata", "seed": seed})
