"""Rigid transforms and small array helpers shared by every layer (base layer: numpy only).

A pose is named by its frames: ``X_AB`` (4, 4) is frame B expressed in frame A, ``p_A = X_AB @ p_B`` in
homogeneous coordinates, with rotation ``R`` (3, 3) and translation ``t`` (3,) in metres; ``X_CO`` is an
object O in the camera C.
"""

from __future__ import annotations

import math

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


def neighbourhood_means(values: np.ndarray, neighbours) -> np.ndarray:
    """The mean of ``values`` over each neighbourhood: ``out[i] = values[neighbours[i]].mean(axis=0)``.

    Args:
        values: (N, ...) array. neighbours: a sequence of index lists, each non-empty (as
            ``cKDTree.query_ball_point`` returns for query points that are among the tree's points).
    Returns:
        (len(neighbours), ...) float64 array; one pass over all neighbours (``np.add.reduceat``) instead
        of one ``mean`` per point.
    Raises:
        ValueError: an empty neighbourhood.
    """
    import itertools

    lens = np.fromiter(map(len, neighbours), dtype=np.int64, count=len(neighbours))
    if len(lens) == 0:
        return np.zeros((0, *np.shape(values)[1:]))
    if lens.min() < 1:
        raise ValueError("neighbourhood_means: an empty neighbourhood")
    flat = np.fromiter(itertools.chain.from_iterable(neighbours), dtype=np.int64, count=int(lens.sum()))
    starts = np.zeros(len(lens), dtype=np.int64)
    np.cumsum(lens[:-1], out=starts[1:])
    sums = np.add.reduceat(np.asarray(values, dtype=np.float64)[flat], starts, axis=0)
    return sums / lens.reshape(-1, *([1] * (sums.ndim - 1)))


def hemisphere_axes(n: int) -> np.ndarray:
    """``n`` unit axes spread evenly over the upper hemisphere (``z > 0``; a Fibonacci lattice), for searches
    over axes where ``a`` and ``-a`` are the same (a half-turn about ``a``, a normal's double cone).

    Args:
        n: number of axes (>= 1).
    Returns:
        (n, 3) float64 unit vectors, ``z`` from near 1 down to near 0.
    """
    i = np.arange(n) + 0.5
    z = 1.0 - i / n
    r = np.sqrt(np.maximum(1.0 - z * z, 0.0))
    phi = math.pi * (1.0 + math.sqrt(5.0)) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)
