"""Rigid transforms shared by every layer (base layer: numpy only).

A pose is named by its frames: ``X_AB`` (4, 4) is frame B expressed in frame A, ``p_A = X_AB @ p_B`` in
homogeneous coordinates, with rotation ``R`` (3, 3) and translation ``t`` (3,) in metres; ``X_CO`` is an
object O in the camera C.
"""

from __future__ import annotations

import numpy as np


def X_from(R, t) -> np.ndarray:
    """The 4x4 rigid transform of rotation ``R`` and translation ``t``.

    Args:
        R: (3, 3) rotation (any array-like). t: (3,) translation in metres (any array-like).
    Returns:
        (4, 4) float64 array ``[[R, t], [0, 0, 0, 1]]``.
    """
    X = np.eye(4)
    X[:3, :3] = R
    X[:3, 3] = np.reshape(t, 3)
    return X
