"""Camera geometry on the reader interface: depth pixels <-> camera-frame points.

Convention (every dataset here): pixel (u, v) = (column, row) has its centre at integer coordinates,
``u = fx x / z + cx``; camera axes +x right, +y down, +z forward; metres.
"""

from __future__ import annotations

import numpy as np


def mask_box(mask: np.ndarray) -> tuple[int, int, int, int] | None:
    """The bounding box ``(v0, v1, u0, u1)`` (rows ``v0:v1``, columns ``u0:u1``, ends exclusive) of the true
    pixels of an (H, W) bool mask, or ``None`` when it has none (two axis reductions instead of a full
    ``nonzero``: a few times faster on a 640x480 mask holding one object)."""
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if len(rows) == 0:
        return None
    return int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1


def backproject(
    depth: np.ndarray, K: np.ndarray, mask: np.ndarray | None = None, rgb: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """Back-project the valid depth pixels under ``mask`` to camera-frame 3D points.

    Args:
        depth: (H, W) depth along the optical axis in metres; 0, negative, NaN or inf = no measurement.
        K: (3, 3) intrinsics (pixel-centre convention: ``u = fx * x / z + cx``).
        mask: optional (H, W) bool mask of the pixels to use (default: all).
        rgb: optional (H, W, 3) uint8 image for per-point colours.
    Returns:
        points (N, 3) float64 in metres (camera frame, OpenCV axes), colours (N, 3) float64 in [0, 1]
        or ``None``, pixels (N, 2) int64 as (v, u) = (row, column).
    Raises:
        ValueError: shapes do not agree.
    """
    depth = np.asarray(depth)
    if depth.ndim != 2:
        raise ValueError(f"depth must be (H, W), got shape {depth.shape}")
    v0, u0 = 0, 0
    if mask is not None:
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != depth.shape:
            raise ValueError(f"mask shape {mask.shape} does not match depth shape {depth.shape}")
        box = mask_box(mask)  # work inside the mask's box only: the same points, in the same order
        v0, v1, u0, u1 = box if box is not None else (0, 0, 0, 0)
        sub = depth[v0:v1, u0:u1]
        valid = np.isfinite(sub) & (sub > 0) & mask[v0:v1, u0:u1]
    else:
        valid = np.isfinite(depth) & (depth > 0)
    v, u = np.nonzero(valid)
    v, u = v + v0, u + u0
    z = depth[v, u].astype(np.float64)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    pts = np.empty((len(z), 3), dtype=np.float64)
    pts[:, 0] = (u - cx) * z / fx
    pts[:, 1] = (v - cy) * z / fy
    pts[:, 2] = z
    col = None
    if rgb is not None:
        if rgb.shape[:2] != depth.shape:
            raise ValueError(f"rgb shape {rgb.shape} does not match depth shape {depth.shape}")
        col = rgb[v, u, :3].astype(np.float64) / 255.0
    return pts, col, np.stack([v, u], axis=1)


def project(points_O: np.ndarray, R: np.ndarray, t: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Project object points (N, 3) at pose (R, t) with intrinsics K.

    Returns:
        uv (N, 2) pixel coordinates (integer-centre convention) and depth z (N,) in metres.
    """
    p_C = points_O @ R.T + t
    z = p_C[:, 2]
    uv = (p_C @ K.T)[:, :2] / np.maximum(z[:, None], 1e-9)
    return uv, z
