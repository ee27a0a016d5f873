"""Hypothesis verification with colour: resolve the rotations that geometry cannot tell apart.

Geometry alone cannot orient a sphere (YCB baseball, tennis ball), a cube (Rubik's cube) or a box
(pudding box), and partial views of many other objects fit a flipped model equally well. After the
geometric pose ``X_CO`` (global registration + ICP), :func:`colour_search` scores a fixed set of
rotations ``S`` of the model about its centroid ``c`` (the candidate pose is ``X_CN = X_CO @ X_ON``, the
candidate object frame N in the object frame O being ``X_ON(x) = S (x - c) + c``) by

* ``geo``: the soft fraction of scene points on the model surface (mean of ``exp(-d^2 / 2 sigma^2)``,
  ``d`` the distance to the nearest model point), and
* ``col``: the correlation between the scene points' chromaticity and the model's chromaticity at
  the nearest model point (chromaticity ``rgb / (r + g + b + 0.05)`` minus its mean: insensitive to
  the shading, which only scales the intensity).

Both are looked up in a per-object voxel grid (distance to the surface, smoothed and sharp model
chromaticity; :class:`ColourGrid`, built once per object and cached), so thousands of rotations cost
milliseconds. The score is ``col + geo_weight * geo``. A coarse pass ranks uniformly random rotations
on *smoothed* colours (a wide basin, about 20 degrees) with a wide ``sigma``; the best few, at least
``nms_deg`` apart (distinct basins), plus the input pose are refined by local rotation perturbations
of decreasing size, first on smoothed colours, then on *sharp* colours with the fine ``sigma``. The
result replaces the input pose only if it scores ``min_gain`` higher than the input pose itself.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numba
import numpy as np
from scipy.spatial import cKDTree

from ..geometry import X_from, neighbourhood_means

if TYPE_CHECKING:
    from .presets import RegistrationConfig


def chroma(colors: np.ndarray) -> np.ndarray:
    """Chromaticity ``rgb / (r + g + b + 0.05)`` of (N, 3) colours in [0, 1]."""
    c = np.asarray(colors, dtype=np.float64)
    return c / (c.sum(axis=1, keepdims=True) + 0.05)


@dataclass
class ColourGrid:
    """Voxel grid around one model (object frame): distance to the nearest model point and the
    sharp / smoothed chromaticity there.

    Attributes:
        origin (3,), cell (m), shape (3,), dist (X*Y*Z,) float32, sharp, smooth (X*Y*Z, 3) float32,
        centroid (3,) model centroid; the grid is a cube around it, and points closer than ``radius``
        to the centroid stay inside it under any rotation about it. time: seconds to build.
    """

    origin: np.ndarray
    cell: float
    shape: np.ndarray
    dist: np.ndarray
    sharp: np.ndarray
    smooth: np.ndarray
    centroid: np.ndarray
    radius: float
    time: float = 0.0

    def __post_init__(self):
        self._w: dict = {}

    def cells_of(self, q: np.ndarray) -> np.ndarray:
        """Flat cell indices of points ``q`` (..., 3) that lie inside the grid (not checked)."""
        ijk = ((q - self.origin) * (1.0 / self.cell)).astype(np.int32)
        return (ijk[..., 0] * int(self.shape[1]) + ijk[..., 1]) * int(self.shape[2]) + ijk[..., 2]

    def weights(self, sigma: float) -> np.ndarray:
        """Per-cell soft surface agreement ``exp(-d^2 / 2 sigma^2)`` (float32, cached per sigma)."""
        key = round(float(sigma), 9)
        if key not in self._w:
            self._w[key] = np.exp(-0.5 * np.minimum(self.dist / sigma, 10.0) ** 2).astype(np.float32)
        return self._w[key]


def build_grid(
    points: np.ndarray, colors: np.ndarray, diameter: float, cells: int = 64, smooth_rel: float = 0.1
) -> ColourGrid:
    """Build the :class:`ColourGrid` of a coloured model (object frame, metres).

    Args:
        points, colors: (M, 3) model points and colours in [0, 1]. diameter: metres.
        cells: grid cells along the diameter. smooth_rel: smoothing radius / diameter.
    """
    t0 = time.perf_counter()
    cell = diameter / cells
    centroid = points.mean(axis=0)
    # a cube around the centroid holding the ball of radius ``half``: a point within ``half - cell``
    # of the centroid stays inside for every rotation about it (no clipping while searching)
    half = float(np.linalg.norm(points - centroid, axis=1).max()) + 3 * cell
    n_side = int(np.ceil(2 * half / cell))
    lo = centroid - 0.5 * n_side * cell
    shape = np.array([n_side] * 3, dtype=np.int64)
    from scipy.ndimage import distance_transform_edt, gaussian_filter

    n = int(np.prod(shape))
    ijk = np.clip(np.floor((points - lo) / cell).astype(np.int64), 0, shape - 1)
    flat = (ijk[:, 0] * shape[1] + ijk[:, 1]) * shape[2] + ijk[:, 2]
    # distance to the nearest model point: exact (KD-tree) within 4 cells of an occupied cell, where
    # the fine surface term lives; farther out the distance between cell centres (Euclidean distance
    # transform, error < 1 cell = d / cells), enough for the coarse term, which vanishes beyond ~0.15 d
    occ = np.zeros(n, dtype=bool)
    occ[flat] = True
    edt, inds = distance_transform_edt(~occ.reshape(tuple(shape)), return_indices=True)
    edt = edt.reshape(-1)
    near_occ = (inds[0] * shape[1] + inds[1]).reshape(-1) * shape[2] + inds[2].reshape(-1)
    # a representative model point per occupied cell (the last one written)
    rep = np.zeros(n, dtype=np.int64)
    rep[flat] = np.arange(len(points))
    nn = rep[near_occ]
    d = edt * cell
    idx = np.flatnonzero(edt <= 4.0)
    ii, jj, kk = np.unravel_index(idx, tuple(shape))
    centres = lo + (np.stack([ii, jj, kk], axis=1) + 0.5) * cell
    d[idx], nn[idx] = cKDTree(points).query(centres, k=1)
    ch = chroma(colors)
    # smoothed chromaticity: Gaussian-filtered per-cell sums of the model points, read at the cell of
    # each grid cell's nearest model point
    sig = 0.5 * smooth_rel * diameter / cell  # about the spread of a ball of radius smooth_rel * d
    cnt = gaussian_filter(np.bincount(flat, minlength=n).reshape(shape).astype(np.float64), sig, mode="constant")
    sm = np.stack(
        [
            gaussian_filter(np.bincount(flat, weights=ch[:, k], minlength=n).reshape(shape), sig, mode="constant")
            for k in range(3)
        ],
        axis=-1,
    ).reshape(n, 3) / np.maximum(cnt.reshape(n, 1), 1e-12)
    return ColourGrid(lo, cell, shape, d.astype(np.float32), ch[nn].astype(np.float32), sm[flat[nn]].astype(np.float32),
                      centroid, half - cell, time.perf_counter() - t0)


_ROT_CACHE: dict = {}


def random_rotations(n: int, seed: int = 0) -> np.ndarray:
    """``n`` uniformly random rotations (n, 3, 3) (fixed per seed, cached), the first one the identity."""
    key = (n, seed)
    if key not in _ROT_CACHE:
        if len(_ROT_CACHE) >= 8:  # one seed per instance: keep a few sets only (drawing one takes ~0.2 ms)
            _ROT_CACHE.clear()
        from scipy.spatial.transform import Rotation

        R = Rotation.random(n, random_state=seed).as_matrix()
        R[0] = np.eye(3)
        _ROT_CACHE[key] = R
    return _ROT_CACHE[key]


def _small_rotations(n: int, angle_deg: float, rng: np.random.Generator) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    ax = rng.normal(size=(n, 3))
    ax /= np.linalg.norm(ax, axis=1, keepdims=True)
    ang = np.radians(angle_deg) * rng.random(n) ** (1 / 3)
    return Rotation.from_rotvec(ax * ang[:, None]).as_matrix()


@numba.njit(cache=True, fastmath=True, nogil=True)
def _score_kernel(v, S, c, origin, inv_cell, ny, nz, weights, feat, fs, out_geo, out_col):  # pragma: no cover - njit
    """For each rotation ``S[m]``: rotate the points ``v`` (K, 3; object frame about the centroid
    ``c``) as ``v @ S[m] + c``, look up their grid cells, and accumulate the mean surface weight
    (``out_geo[m]``) and the correlation of the centred scene features ``fs`` (K, 3) with the
    cells' model features ``feat`` (``out_col[m]``). One pass, no temporaries."""
    K = v.shape[0]
    sfs0 = 0.0
    sfs1 = 0.0
    sfs2 = 0.0
    fs2 = 0.0
    for k in range(K):
        sfs0 += fs[k, 0]
        sfs1 += fs[k, 1]
        sfs2 += fs[k, 2]
        fs2 += fs[k, 0] * fs[k, 0] + fs[k, 1] * fs[k, 1] + fs[k, 2] * fs[k, 2]
    for m in range(S.shape[0]):
        sw = 0.0
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        sq = 0.0
        dot = 0.0
        for k in range(K):
            x = v[k, 0] * S[m, 0, 0] + v[k, 1] * S[m, 1, 0] + v[k, 2] * S[m, 2, 0] + c[0]
            y = v[k, 0] * S[m, 0, 1] + v[k, 1] * S[m, 1, 1] + v[k, 2] * S[m, 2, 1] + c[1]
            z = v[k, 0] * S[m, 0, 2] + v[k, 1] * S[m, 1, 2] + v[k, 2] * S[m, 2, 2] + c[2]
            i = int((x - origin[0]) * inv_cell)
            j = int((y - origin[1]) * inv_cell)
            kz = int((z - origin[2]) * inv_cell)
            idx = (i * ny + j) * nz + kz
            sw += weights[idx]
            f0 = feat[idx, 0]
            f1 = feat[idx, 1]
            f2 = feat[idx, 2]
            s0 += f0
            s1 += f1
            s2 += f2
            sq += f0 * f0 + f1 * f1 + f2 * f2
            dot += fs[k, 0] * f0 + fs[k, 1] * f1 + fs[k, 2] * f2
        out_geo[m] = sw / K
        # sum_k fs_k . (fm_k - mean fm) and sum_k |fm_k - mean fm|^2
        num = dot - (s0 * sfs0 + s1 * sfs1 + s2 * sfs2) / K
        var = sq - (s0 * s0 + s1 * s1 + s2 * s2) / K
        out_col[m] = num / (math.sqrt(fs2 * max(var, 0.0)) + 1e-12)


@numba.njit(cache=True, fastmath=True, nogil=True)
def _poses_kernel(P, R, t, gc, radius, origin, inv_cell, ny, nz, weights, feat, fs, geo_weight,
                  out):  # pragma: no cover - njit
    """:func:`_score_kernel`'s two terms for each candidate pose ``(R[m], t[m])`` (object in camera) of the
    scene points ``P`` (K, 3, camera frame) at once: the points are taken to the object frame, those within
    ``radius`` of the grid's centroid ``gc`` kept (the sums of the centred scene features ``fs`` (K, 3) over
    them too), and ``out[m] = col + geo_weight * geo * kept / K`` (``-inf`` with fewer than 4 kept), as
    :func:`colour_scores` combines them. One pass per candidate, no temporaries."""
    K = P.shape[0]
    r2 = radius * radius
    for m in range(R.shape[0]):
        n = 0
        sfs0 = 0.0
        sfs1 = 0.0
        sfs2 = 0.0
        fs2 = 0.0
        sw = 0.0
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        sq = 0.0
        dot = 0.0
        for k in range(K):
            d0 = P[k, 0] - t[m, 0]
            d1 = P[k, 1] - t[m, 1]
            d2 = P[k, 2] - t[m, 2]
            x = d0 * R[m, 0, 0] + d1 * R[m, 1, 0] + d2 * R[m, 2, 0]
            y = d0 * R[m, 0, 1] + d1 * R[m, 1, 1] + d2 * R[m, 2, 1]
            z = d0 * R[m, 0, 2] + d1 * R[m, 1, 2] + d2 * R[m, 2, 2]
            if (x - gc[0]) ** 2 + (y - gc[1]) ** 2 + (z - gc[2]) ** 2 >= r2:
                continue
            n += 1
            sfs0 += fs[k, 0]
            sfs1 += fs[k, 1]
            sfs2 += fs[k, 2]
            fs2 += fs[k, 0] * fs[k, 0] + fs[k, 1] * fs[k, 1] + fs[k, 2] * fs[k, 2]
            idx = (int((x - origin[0]) * inv_cell) * ny + int((y - origin[1]) * inv_cell)) * nz \
                + int((z - origin[2]) * inv_cell)
            sw += weights[idx]
            f0 = feat[idx, 0]
            f1 = feat[idx, 1]
            f2 = feat[idx, 2]
            s0 += f0
            s1 += f1
            s2 += f2
            sq += f0 * f0 + f1 * f1 + f2 * f2
            dot += fs[k, 0] * f0 + fs[k, 1] * f1 + fs[k, 2] * f2
        if n < 4:
            out[m] = -np.inf
            continue
        num = dot - (s0 * sfs0 + s1 * sfs1 + s2 * sfs2) / n
        var = sq - (s0 * s0 + s1 * s1 + s2 * s2) / n
        col = num / (math.sqrt(fs2 * max(var, 0.0)) + 1e-12)
        out[m] = col + geo_weight * (sw / n) * (n / K)


def warmup() -> None:
    """Compile :func:`_score_kernel` and :func:`_poses_kernel` (or load them from Numba's on-disk cache) on a
    tiny input, so the first instance's time is not charged with it (a process start-up cost, like the
    imports)."""
    g = np.zeros(8, np.float32)
    _score_kernel(np.zeros((1, 3), np.float32), np.eye(3, dtype=np.float32)[None], np.zeros(3, np.float32),
                  np.zeros(3, np.float32), np.float32(1.0), 2, 2, g, np.zeros((8, 3), np.float32),
                  np.zeros((1, 3), np.float32), np.empty(1), np.empty(1))
    _poses_kernel(np.zeros((1, 3)), np.eye(3)[None], np.zeros((1, 3)), np.zeros(3), 1.0, np.zeros(3), 1.0, 2, 2, g,
                  np.zeros((8, 3), np.float32), np.zeros((1, 3)), 0.5, np.empty(1))


def _corr(fs: np.ndarray, fm: np.ndarray) -> np.ndarray:
    """NumPy reference of the kernel's colour term (tests): correlation of the centred scene features
    (K, 3) with model features (M, K, 3) -> (M,)."""
    fm = fm - fm.mean(axis=1, keepdims=True)
    num = np.einsum("kc,mkc->m", fs, fm)
    den = np.sqrt((fs * fs).sum() * np.einsum("mkc,mkc->m", fm, fm)) + 1e-12
    return num / den


#: points pooled (at random) by :func:`colour_scores` for the scene's smoothed colours, and neighbours averaged
SMOOTH_POOL, SMOOTH_K = 2000, 32


def colour_scores(
    X_CO: np.ndarray,
    points: np.ndarray,
    colors: np.ndarray,
    grid: ColourGrid,
    diameter: float,
    cfg: RegistrationConfig | None = None,
) -> np.ndarray:
    """Score given candidate poses by colour agreement, as the coarse pass of :func:`colour_search` does
    (smoothed chromaticity, the wide surface term): for choosing among a few poses that geometry cannot
    tell apart (a box's turns), without searching.

    Args:
        X_CO: (K, 4, 4) candidate poses (object in camera, metres). points, colors: (N, 3) masked scene
            points (camera frame, m) and their colours in [0, 1]. grid: the object's :class:`ColourGrid`.
            diameter: metres. cfg: as in :func:`colour_search` (``cv_points``, ``cv_smooth_rel``,
            ``cv_coarse_sigma_rel``, ``cv_geo_weight``, ``seed``).
    Returns:
        (K,) ``col + cv_geo_weight * geo`` per candidate (higher is better); ``-inf`` for a candidate with
        fewer than 4 of the points inside the model's grid.
    """
    if cfg is None:
        from .presets import PRESETS

        cfg = PRESETS["default"]
    X = np.asarray(X_CO, dtype=np.float64).reshape(-1, 4, 4)
    P = np.asarray(points, dtype=np.float64)
    out = np.full(len(X), -np.inf)
    if len(P) < 4 or len(colors) != len(P):
        return out
    rng = np.random.default_rng(cfg.seed)
    # smoothed scene chromaticity at cv_points of them: the mean over the (up to) SMOOTH_K nearest of at most
    # SMOOTH_POOL points within the smoothing radius (vectorised: milliseconds on a large mask)
    pool = rng.choice(len(P), size=min(len(P), SMOOTH_POOL), replace=False)
    sel = pool[: min(len(pool), cfg.cv_points)]
    ch = chroma(np.asarray(colors)[pool])  # row by row: only the pooled rows are needed
    k = min(SMOOTH_K, len(pool))
    dist, nb = cKDTree(P[pool]).query(P[sel], k=k, distance_upper_bound=cfg.cv_smooth_rel * diameter)
    dist, nb = dist.reshape(len(sel), k), nb.reshape(len(sel), k)
    ok = np.isfinite(dist)  # the point itself is always among them
    fs = (ch[np.where(ok, nb, 0)] * ok[..., None]).sum(axis=1) / ok.sum(axis=1, keepdims=True)
    fs -= fs.mean(axis=0)
    # every candidate in one compiled pass (the points within the grid's radius of its centroid, per candidate)
    _poses_kernel(P[sel], np.ascontiguousarray(X[:, :3, :3]), np.ascontiguousarray(X[:, :3, 3]),
                  np.asarray(grid.centroid, np.float64), float(grid.radius), np.asarray(grid.origin, np.float64),
                  float(1.0 / grid.cell), int(grid.shape[1]), int(grid.shape[2]),
                  grid.weights(cfg.cv_coarse_sigma_rel * diameter), np.asarray(grid.smooth, np.float32),
                  np.asarray(fs, np.float64), float(cfg.cv_geo_weight), out)
    return out


@dataclass
class SearchResult:
    """Output of :func:`colour_search`: ``X_CO`` (4, 4), ``geo``, ``col`` (sharp), ``changed``;
    ``candidates``: (k, 4, 4) the refined candidates (distinct basins), best first (hypotheses for
    :mod:`~sixdpose.registration.hypotheses`), or None."""

    X_CO: np.ndarray
    geo: float
    col: float
    changed: bool
    candidates: np.ndarray | None = None


def colour_search(
    X_CO: np.ndarray,
    points: np.ndarray,
    colors: np.ndarray,
    grid: ColourGrid,
    diameter: float,
    cfg: RegistrationConfig | None = None,
) -> SearchResult:
    """Search the rotations of the model about its centroid for the best colour agreement.

    Args:
        X_CO: (4, 4) geometric pose (object in camera, metres). points, colors: (N, 3) masked scene
            points (camera frame, m) and their colours in [0, 1]. grid: the object's
            :class:`ColourGrid`. diameter: metres.
        cfg: a :class:`~sixdpose.registration.presets.RegistrationConfig` (default: the ``default``
            preset); its ``cv_*`` fields are the parameters and ``seed`` the random seed:
            ``cv_rotations`` coarse rotations (uniform on SO(3)); ``cv_points`` / ``cv_points_fine``
            scene points of the coarse search / the refinement; ``cv_tol_rel`` and
            ``cv_coarse_sigma_rel`` surface tolerance (Gaussian sigma) / diameter of the fine and
            coarse surface terms; ``cv_geo_weight`` weight of the surface term (in [0, 1]) against
            the colour correlation (in [-1, 1]); ``cv_smooth_rel`` colour smoothing radius / diameter;
            ``cv_keep`` coarse candidates refined, at least ``cv_nms_deg`` apart; ``cv_refine``
            rounds of ``cv_perturbations`` perturbations of at most ``cv_refine_deg`` (halved each
            round); ``cv_min_gain``: the best candidate replaces ``X_CO`` only if it scores this
            much higher.
    Returns:
        :class:`SearchResult` (``X_CO`` itself when nothing scores better).
    """
    if cfg is None:
        from .presets import PRESETS

        cfg = PRESETS["default"]
    n_rot, n_points, n_points_fine = cfg.cv_rotations, cfg.cv_points, cfg.cv_points_fine
    tol_rel, coarse_sigma_rel, geo_weight = cfg.cv_tol_rel, cfg.cv_coarse_sigma_rel, cfg.cv_geo_weight
    smooth_rel, n_keep, nms_deg, n_refine = cfg.cv_smooth_rel, cfg.cv_keep, cfg.cv_nms_deg, cfg.cv_refine
    n_pert, refine_deg, min_gain, seed = cfg.cv_perturbations, cfg.cv_refine_deg, cfg.cv_min_gain, cfg.seed
    rng = np.random.default_rng(seed)
    P = np.asarray(points, dtype=np.float64)
    sel_f = rng.choice(len(P), size=min(len(P), n_points_fine), replace=False)
    sel = sel_f[:n_points]
    # scene features: sharp and smoothed chromaticity, centred
    ch = chroma(colors)
    nb = cKDTree(P).query_ball_point(P[sel], smooth_rel * diameter)
    fs_smooth = neighbourhood_means(ch, nb)
    fs_sharp = ch[sel_f]
    fs_smooth -= fs_smooth.mean(axis=0)
    fs_sharp -= fs_sharp.mean(axis=0)
    R_CO, t_CO = X_CO[:3, :3], X_CO[:3, 3]
    c = grid.centroid
    v_f = (P[sel_f] - t_CO) @ R_CO - c  # object frame, relative to the centroid
    # points beyond the grid's radius cannot lie on the model under any rotation about the
    # centroid: they count as misses (surface term) and are left out of the colour correlation
    inside = np.linalg.norm(v_f, axis=1) < grid.radius
    frac_f = inside.mean()
    frac_c = inside[: len(sel)].mean()
    keep_c = inside[: len(sel)]
    v_c, fs_smooth = v_f[: len(sel)][keep_c], fs_smooth[keep_c]
    v_f, fs_sharp = v_f[inside], fs_sharp[inside]
    if len(v_c) < 4 or len(v_f) < 4:
        return SearchResult(X_CO, 0.0, 0.0, False)

    v_c32, v_f32, c32 = v_c.astype(np.float32), v_f.astype(np.float32), c.astype(np.float32)

    inv_cell = np.float32(1.0 / grid.cell)
    origin32 = grid.origin.astype(np.float32)
    ny, nz = int(grid.shape[1]), int(grid.shape[2])
    fs_smooth32, fs_sharp32 = fs_smooth.astype(np.float32), fs_sharp.astype(np.float32)

    def score(S, smooth: bool, sigma: float):
        """combined score = colour correlation + geo_weight x soft surface agreement."""
        S32 = np.ascontiguousarray(S, dtype=np.float32)
        geo = np.empty(len(S32), dtype=np.float64)
        col = np.empty(len(S32), dtype=np.float64)
        _score_kernel(v_c32 if smooth else v_f32, S32, c32, origin32, inv_cell, ny, nz, grid.weights(sigma),
                      grid.smooth if smooth else grid.sharp, fs_smooth32 if smooth else fs_sharp32, geo, col)
        geo *= frac_c if smooth else frac_f
        return col + geo_weight * geo, geo, col

    S = random_rotations(n_rot, seed)
    sc, geo, col = score(S, True, coarse_sigma_rel * diameter)
    # the best n_keep coarse rotations at least nms_deg apart (distinct basins, e.g. both poses of
    # a 180-degree colour near-symmetry), plus the input pose itself
    cos_min = 2.0 * math.cos(math.radians(nms_deg)) + 1.0  # trace(Ra^T Rb) above this: closer than nms_deg
    kept: list[int] = []
    for i in np.argsort(-sc)[: 50 * n_keep]:
        if not kept or (np.einsum("ij,mij->m", S[i], S[kept]) < cos_min).all():
            kept.append(int(i))
            if len(kept) == n_keep:
                break
    best = np.concatenate([np.eye(3)[None], S[kept]])
    sigma = tol_rel * diameter
    sigma_c = coarse_sigma_rel * diameter
    # local refinement: the first rounds on smoothed colours (wide basin), the rest on sharp ones
    ang = refine_deg
    n_smooth = n_refine // 2
    for r in range(n_refine):
        smooth = r < n_smooth
        sg = sigma_c if smooth else sigma
        if r == 0 or r == n_smooth:
            best_s, _, _ = score(best, smooth, sg)
        pert = _small_rotations(n_pert, ang, rng)
        trial = np.einsum("mij,pjk->mpik", best, pert).reshape(-1, 3, 3)
        s2, _, _ = score(trial, smooth, sg)
        s2 = s2.reshape(len(best), -1)
        k = np.argmax(s2, axis=1)
        rows = np.arange(len(best))
        better = s2[rows, k] > best_s
        best[better] = trial.reshape(len(best), -1, 3, 3)[rows[better], k[better]]
        best_s[better] = s2[rows[better], k[better]]
        ang /= 2.0
    if n_refine <= n_smooth:
        best_s, _, _ = score(best, False, sigma)
    s0, g0, c0 = score(np.eye(3)[None], False, sigma)
    m = int(np.argmax(best_s))
    order = np.argsort(-best_s, kind="stable")
    cands = np.stack([X_CO @ X_from(best[i], c - best[i] @ c) for i in order])
    if best_s[m] <= s0[0] + min_gain:
        return SearchResult(X_CO, float(g0[0]), float(c0[0]), False, cands)
    Sb = best[m]
    X_ON = X_from(Sb, c - Sb @ c)  # the best candidate's object frame N in the object frame O
    _, gb, cb = score(Sb[None], False, sigma)
    return SearchResult(X_CO @ X_ON, float(gb[0]), float(cb[0]), True, cands)
