"""Pose error metrics (bop_toolkit style pure functions), paper section V-A, eq. (4).

All functions take rotations as (3, 3) arrays and translations as (3,) arrays (or (3, 1)); ``pts`` are
the (N, 3) model points in the object frame. Lengths are returned in the unit of ``t`` and ``pts``
(metres in this package).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def transform_pts(pts: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Apply ``p -> R p + t`` to (N, 3) points; returns (N, 3)."""
    return np.asarray(pts, dtype=np.float64) @ np.asarray(R, dtype=np.float64).T + np.asarray(t, dtype=np.float64).reshape(1, 3)


def add(R_est: np.ndarray, t_est: np.ndarray, R_gt: np.ndarray, t_gt: np.ndarray, pts: np.ndarray) -> float:
    """Average Distance of model points (ADD, Hinterstoisser et al. 2012; paper eq. 4, asymmetric case).

    ``mean_j |(R_gt x_j + t_gt) - (R_est x_j + t_est)|`` over the (N, 3) model points ``pts``.
    """
    return float(np.linalg.norm(transform_pts(pts, R_gt, t_gt) - transform_pts(pts, R_est, t_est), axis=1).mean())


def adds(R_est: np.ndarray, t_est: np.ndarray, R_gt: np.ndarray, t_gt: np.ndarray, pts: np.ndarray) -> float:
    """ADD-S (paper eq. 4, symmetric case): mean over GT-posed points of the distance to the nearest
    estimate-posed point, ``mean_j min_k |(R_gt x_j + t_gt) - (R_est x_k + t_est)|``.

    Nearest neighbours by a KD-tree (O(N log N), not an N x N matrix).
    """
    est = transform_pts(pts, R_est, t_est)
    gt = transform_pts(pts, R_gt, t_gt)
    d, _ = cKDTree(est).query(gt, k=1)
    return float(d.mean())


def add_or_adds(R_est, t_est, R_gt, t_gt, pts, symmetric: bool) -> float:
    """ADD(-S), the paper's eq. (4): :func:`adds` if ``symmetric`` else :func:`add` (metres)."""
    return (adds if symmetric else add)(R_est, t_est, R_gt, t_gt, pts)


def is_correct(error: float, diameter: float, threshold: float = 0.1) -> bool:
    """The paper's accuracy criterion: ``error < threshold * diameter`` (10 % of the diameter)."""
    return bool(error < threshold * diameter)


def rotation_error(R_est: np.ndarray, R_gt: np.ndarray) -> float:
    """Angle of ``R_est R_gt^T`` in degrees, in [0, 180]."""
    c = (np.trace(np.asarray(R_est) @ np.asarray(R_gt).T) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def translation_error(t_est: np.ndarray, t_gt: np.ndarray) -> float:
    """Euclidean distance between the translations (unit of the inputs)."""
    return float(np.linalg.norm(np.asarray(t_est, dtype=np.float64).reshape(3) - np.asarray(t_gt, dtype=np.float64).reshape(3)))
