"""Rotation parameterisations and pose composition for the learned stage (torch, batched).

Poses are ``X_CO`` (object O in camera C): ``p_C = R_CO @ p_O + t_CO``, metres. Batched tensors carry a
leading batch dimension N.
"""

from __future__ import annotations

import math

import numpy as np
import torch


def quaternion_to_matrix(q: torch.Tensor) -> torch.Tensor:
    """Rotation matrices of quaternions ``(w, x, y, z)`` (normalised here).

    Args:
        q: (N, 4) quaternions, any non-zero norm.
    Returns:
        (N, 3, 3) rotation matrices.
    """
    q = q / q.norm(dim=-1, keepdim=True).clamp_min(1e-8)
    w, x, y, z = q.unbind(-1)
    return torch.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ], dim=-1).reshape(q.shape[:-1] + (3, 3))


def sixd_to_matrix(d6: torch.Tensor) -> torch.Tensor:
    """Rotation matrices of the continuous 6D representation (Zhou et al. 2019, Gram-Schmidt).

    Args:
        d6: (N, 6): two 3-vectors a1, a2 (any non-parallel pair).
    Returns:
        (N, 3, 3) rotations whose first two columns are normalise(a1) and the part of a2 orthogonal to it.
    """
    a1, a2 = d6[..., :3], d6[..., 3:]
    b1 = a1 / a1.norm(dim=-1, keepdim=True).clamp_min(1e-8)
    a2 = a2 - (b1 * a2).sum(-1, keepdim=True) * b1
    b2 = a2 / a2.norm(dim=-1, keepdim=True).clamp_min(1e-8)
    b3 = torch.cross(b1, b2, dim=-1)
    return torch.stack([b1, b2, b3], dim=-1)


def rotation_from_output(x: torch.Tensor, kind: str) -> torch.Tensor:
    """(N, 4) quaternion or (N, 6) 6D output -> (N, 3, 3) rotations (``kind``: quaternion | 6d)."""
    if kind == "quaternion":
        return quaternion_to_matrix(x)
    if kind == "6d":
        return sixd_to_matrix(x)
    raise ValueError(f"unknown rotation kind {kind!r}")


def rotation_dim(kind: str) -> int:
    """Output size of a rotation parameterisation: 4 (quaternion) or 6 (6d)."""
    return {"quaternion": 4, "6d": 6}[kind]


def axis_angle_to_matrix(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rodrigues: (N, 3) unit axes and (N,) angles (radians) -> (N, 3, 3) rotations (numpy)."""
    axis = np.asarray(axis, dtype=np.float64)
    a = np.asarray(angle, dtype=np.float64)[:, None, None]
    Kx = np.zeros((len(axis), 3, 3))
    Kx[:, 0, 1], Kx[:, 0, 2], Kx[:, 1, 2] = -axis[:, 2], axis[:, 1], -axis[:, 0]
    Kx[:, 1, 0], Kx[:, 2, 0], Kx[:, 2, 1] = axis[:, 2], -axis[:, 1], axis[:, 0]
    return np.eye(3) + np.sin(a) * Kx + (1 - np.cos(a)) * Kx @ Kx


def perturb_poses(R: np.ndarray, t: np.ndarray, rot_deg: float, trans: float, rng: np.random.Generator):
    """Noisy copies of poses for refiner training.

    Each rotation is left-multiplied by a rotation about a uniformly random axis by an angle drawn
    from N(0, ``rot_deg``) degrees; each translation gets N(0, ``trans``) metres per axis.

    Args:
        R: (N, 3, 3), t: (N, 3) poses ``X_CO`` (metres). rng: numpy generator.
    Returns:
        (R', t') with the same shapes.
    """
    n = len(R)
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True).clip(1e-12)
    ang = np.deg2rad(rng.normal(0.0, rot_deg, size=n)) if rot_deg > 0 else np.zeros(n)
    dR = axis_angle_to_matrix(axis, ang)
    dt = rng.normal(0.0, trans, size=(n, 3)) if trans > 0 else np.zeros((n, 3))
    return dR @ R, t + dt


def to_object_frame(points_C: torch.Tensor, R_CO: torch.Tensor, t_CO: torch.Tensor) -> torch.Tensor:
    """Express camera-frame points in the (estimated) object frame: ``p_O = R_CO^T (p_C - t_CO)``.

    Args:
        points_C: (N, P, 3). R_CO: (N, 3, 3). t_CO: (N, 3). Metres.
    Returns:
        (N, P, 3) points in the object frame.
    """
    return torch.bmm(points_C - t_CO[:, None, :], R_CO)


def compose_refinement(R_CO: torch.Tensor, t_CO: torch.Tensor, R_r: torch.Tensor, t_r: torch.Tensor):
    """Apply a refiner correction predicted in the estimated object frame (DenseFusion's composition).

    The refiner sees the cloud ``p_O' = R_CO^T (p_C - t_CO)``; if that cloud is the model under the
    residual pose ``X_O'O = (R_r, t_r)``, the corrected pose is ``X_CO <- X_CO X_O'O``::

        R <- R_CO R_r,     t <- R_CO t_r + t_CO

    Args:
        R_CO, R_r: (N, 3, 3). t_CO, t_r: (N, 3). Metres.
    Returns:
        (R, t) of the corrected pose.
    """
    return torch.bmm(R_CO, R_r), torch.bmm(R_CO, t_r[:, :, None])[:, :, 0] + t_CO


def rotation_angle_deg(R_a: np.ndarray, R_b: np.ndarray) -> float:
    """Angle of ``R_a R_b^T`` in degrees."""
    c = (np.trace(np.asarray(R_a) @ np.asarray(R_b).T) - 1.0) / 2.0
    return float(math.degrees(math.acos(min(1.0, max(-1.0, c)))))
