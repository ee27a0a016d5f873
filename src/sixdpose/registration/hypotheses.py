"""Hypothesis verification against the frame: several poses per instance, scored by projection.

Global registration, ICP and the colour search each give one pose; on real frames the wrong one often
fits the masked cloud as well as the right one (a turn about a near-symmetric axis that only the
texture decides, a flip of a partly occluded object). :func:`verify_hypotheses` keeps several
hypotheses per instance (the input pose, the colour search's other basins, the global method's, and
their turns about the model's principal axes through its centroid, optionally each slid along the
model's longest axis, and for a ball, whose geometry leaves its turn open, the turns a coarse-to-fine
search by texture finds: :func:`texture_search`), scores each against the frame
without rendering but with occlusion reasoning, ICPs the best few and keeps the highest score.

Scoring (:func:`score_hypotheses`), batched over hypotheses: the model's surface samples with normals
(:class:`Surface`, cached per object) are posed, back-facing ones dropped, projected with the frame's
``K`` into a grid of cells at the instance's bounding box (cell size about the projected sample spacing,
so the splatted points leave no holes), and a z-buffer per hypothesis keeps the nearest samples. For the
visible samples and the observed depth ``D`` at their pixels (``tau = verify_tau_rel * diameter``):

* **depth** (VSD-style): inside the instance mask a sample agrees when ``|z - D| <= tau`` and is wrong
  otherwise; outside the mask a sample in front of the observed surface (``z < D - tau``) is wrong (the
  model would hide what the camera sees), one behind it is *occluded*, not wrong (left out, also from
  the silhouette). ``depth = agree / (agree + wrong)``.
* **mask**: IoU of the projected silhouette (visible, not occluded cells) with the instance mask's cells.
* **texture**: over the agreeing samples inside the mask, the centred correlation of chromaticity
  (``rgb / (r + g + b)``: insensitive to shading and to the light's gain) of the model's vertex colours
  against the frame's pixels, blended with the normalised cross-correlation of grey values by
  ``verify_grey_share`` (default 0: grey follows the shading, which the model's colours do not hold,
  and on the real sample it preferred a flipped mustard bottle).

``score = (w_depth * depth + w_mask * iou + w_tex * texture) / (w_depth + w_mask + w_tex)`` (texture in
[-1, 1], the rest in [0, 1]). A model without colours is scored on depth and mask alone (logged once).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numba
import numpy as np

from ..geometry import X_from, hemisphere_axes

if TYPE_CHECKING:
    from .geometry import ReferenceCache
    from .presets import RegistrationConfig

log = logging.getLogger(__name__)
_TEXTURELESS_LOGGED: set = set()


@dataclass
class Frame:
    """The frame an instance is verified against.

    Attributes:
        depth: (H, W) float depth in metres (0 or NaN: unknown). K: (3, 3) intrinsics.
        mask: (H, W) bool instance mask. rgb: (H, W, 3) uint8 or float in [0, 1], or None.
    """

    depth: np.ndarray
    K: np.ndarray
    mask: np.ndarray
    rgb: np.ndarray | None = None

    def __post_init__(self):
        self._detail: dict = {}
        self._arrays: tuple | None = None

    def arrays(self) -> tuple[tuple[np.ndarray, np.ndarray], np.ndarray, np.ndarray]:
        """``((v, u), mask, depth)``: the mask's pixel rows and columns (``np.nonzero``), the mask as a
        C-contiguous bool array and the depth as float32, computed once per frame (every scoring of the
        instance's hypotheses reads them; the frame is not to be changed after it was made)."""
        if self._arrays is None:
            mask = np.ascontiguousarray(self.mask, dtype=np.bool_)
            depth = self.depth if self.depth.dtype == np.float32 else self.depth.astype(np.float32)
            self._arrays = (np.nonzero(mask), mask, depth)
        return self._arrays

    def box(self, pad_px: int) -> tuple[int, int, int, int] | None:
        """``(v0, v1, u0, u1)``: the mask's bounding box grown by ``pad_px`` pixels on every side and clipped
        to the image (rows ``v0:v1``, columns ``u0:u1``); None for an empty mask."""
        vv, uu = np.nonzero(self.mask)
        if not len(vv):
            return None
        H, W = self.mask.shape
        return (max(int(vv.min()) - pad_px, 0), min(int(vv.max()) + pad_px + 1, H),
                max(int(uu.min()) - pad_px, 0), min(int(uu.max()) + pad_px + 1, W))

    def rgb_crop(self, box: tuple[int, int, int, int], dtype=np.float32) -> np.ndarray:
        """The colours inside ``box`` (from :meth:`box`) as ``dtype`` in [0, 1] (uint8 divided by 255)."""
        v0, v1, u0, u1 = box
        assert self.rgb is not None
        out = np.asarray(self.rgb[v0:v1, u0:u1], dtype=dtype)
        return out / dtype(255.0) if self.rgb.dtype == np.uint8 else out

    def detail(self, radius_px: float) -> np.ndarray:
        """(H, W) float32 grey detail inside the mask: the grey value minus its mean over the mask's
        pixels within about ``radius_px`` (a normalised box filter, so neither the background nor the
        slow shading across the object counts); 0 outside the mask's box. Cached per radius."""
        r = max(1, int(round(radius_px)))
        if r in self._detail:
            return self._detail[r]
        from scipy.ndimage import uniform_filter

        out = np.zeros(self.mask.shape, np.float32)
        box = self.box(2 * r)
        if self.rgb is not None and box is not None:
            v0, v1, u0, u1 = box
            rgb = self.rgb_crop(box, np.float64)
            m = self.mask[v0:v1, u0:u1].astype(np.float64)
            g = grey_of(rgb)
            mean = uniform_filter(g * m, 2 * r + 1) / np.maximum(uniform_filter(m, 2 * r + 1), 1e-6)
            out[v0:v1, u0:u1] = np.where(m > 0, g - mean, 0.0)
        self._detail[r] = out
        return out


@dataclass
class Surface:
    """Model surface samples for verification (object frame, metres).

    Attributes:
        points, normals: (M, 3) uniform surface samples with outward unit normals. spacing: their
        spacing (m). grey, chroma: (M,) grey values and (M, 3) chromaticities of the model's colours
        at the samples, or None for a model without colours. axes: (3, 3) principal axes (columns).
        centroid: (3,). diameter: metres. detail: (M,) grey minus its mean over the samples within
        ``detail_radius`` (m) on the surface (the printing, not the albedo's slow changes), or None.
    """

    points: np.ndarray
    normals: np.ndarray
    spacing: float
    grey: np.ndarray | None
    chroma: np.ndarray | None
    axes: np.ndarray
    centroid: np.ndarray
    diameter: float
    detail: np.ndarray | None = None
    detail_radius: float = 0.0

    def __post_init__(self):
        self._f32: dict = {}
        self._near: dict = {}  # near_symmetries() by its arguments, and slides()' principal extents

    def cast(self, name: str) -> np.ndarray:
        """The attribute ``name`` as a contiguous float32 array (cached: the Numba kernel's input)."""
        if name not in self._f32:
            self._f32[name] = np.ascontiguousarray(getattr(self, name), dtype=np.float32)
        return self._f32[name]


def grey_of(rgb: np.ndarray) -> np.ndarray:
    """Luma (Rec. 601) of (..., 3) colours in [0, 1] -> (...)."""
    return rgb @ np.array([0.299, 0.587, 0.114])


def build_surface(points: np.ndarray, normals: np.ndarray, spacing: float, diameter: float,
                  model_points: np.ndarray | None = None, model_colors: np.ndarray | None = None,
                  detail_rel: float = 0.05) -> Surface:
    """A :class:`Surface` from (M, 3) samples and normals (object frame, m) at ``spacing`` metres; the
    colours (N, 3 in [0, 1]) of the model points ``model_points`` (N, 3) are read at the nearest one;
    the grey detail is taken over ``detail_rel`` x ``diameter``."""
    from ..geometry import neighbourhood_means
    from .verify import chroma

    grey = ch = det = None
    radius = detail_rel * diameter
    if model_colors is not None and model_points is not None and len(model_colors) == len(model_points):
        from scipy.spatial import cKDTree

        _, idx = cKDTree(model_points).query(points, k=1)
        col = np.asarray(model_colors, dtype=np.float64)[idx]
        grey, ch = grey_of(col), chroma(col)
        if radius > 0:
            nb = cKDTree(points).query_ball_point(points, radius)
            det = grey - neighbourhood_means(grey, nb)
    c = points.mean(axis=0)
    _, vecs = np.linalg.eigh(np.cov((points - c).T))
    return Surface(np.asarray(points, np.float64), np.asarray(normals, np.float64), float(spacing), grey, ch,
                   vecs[:, ::-1].copy(), c, float(diameter), det, float(radius))


def model_surface(cache: ReferenceCache, obj_id: int, cfg: RegistrationConfig) -> tuple[Surface, float]:
    """The cached :class:`Surface` of ``obj_id`` (the registration reference at ``verify_voxel_rel`` x
    the diameter, with the model's colours); returns ``(surface, seconds spent building it now)``."""
    import time

    key = ("surface", int(obj_id), float(cfg.verify_voxel_rel), float(cfg.verify_detail_rel))
    hit = cache.extra.get(key)
    if isinstance(hit, Surface):
        return hit, 0.0
    t0 = time.perf_counter()
    with cache.onboarding():
        model = cache.dataset.model(obj_id)
        spacing = cfg.verify_voxel_rel * model.diameter
        ref, _ = cache.get(obj_id, spacing, None)
        surf = build_surface(ref.points, ref.normals, spacing, model.diameter, model.points, model.colors,
                             cfg.verify_detail_rel)
    cache.extra[key] = surf
    return surf, time.perf_counter() - t0


def turns(surface: Surface, n_turns: int) -> np.ndarray:
    """Rigid motions ``X_ON`` (T, 4, 4) of the object frame: the identity, then the turns by ``k * 360 /
    n_turns`` degrees (k = 1 .. n_turns - 1) about each principal axis through the centroid."""
    from scipy.spatial.transform import Rotation

    out = [np.eye(4)]
    c = surface.centroid
    for a in range(3):
        for k in range(1, n_turns):
            S = Rotation.from_rotvec(surface.axes[:, a] * (2 * math.pi * k / n_turns)).as_matrix()
            out.append(X_from(S, c - S @ c))
    return np.stack(out)


def slides(surface: Surface, n_slides: int, step_rel: float, min_elong: float = 0.0) -> np.ndarray:
    """Rigid motions ``X_ON`` (2 * n_slides, 4, 4) of the object frame: translations by ``k * step_rel`` x
    the samples' extent along the longest principal axis, along that axis, ``k = +-1 .. +-n_slides``
    (the identity is not included). None (shape (0, 4, 4)) when the model's extent along that axis is less
    than ``min_elong`` times its extent along the second axis (a model not elongated). The extents are
    computed once per surface (cached on it, as :func:`near_symmetries`)."""
    extent = surface._near.get("principal_extents")
    if extent is None:
        proj = (surface.points - surface.centroid) @ surface.axes[:, :2]
        extent = surface._near["principal_extents"] = proj.max(axis=0) - proj.min(axis=0)
    if extent[0] < min_elong * extent[1]:
        return np.zeros((0, 4, 4))
    a = surface.axes[:, 0]
    step = step_rel * float(extent[0])
    out = [X_from(np.eye(3), sgn * k * step * a) for k in range(1, n_slides + 1) for sgn in (1.0, -1.0)]
    return np.stack(out) if out else np.zeros((0, 4, 4))


def model_slides(cache: ReferenceCache, obj_id: int, cfg: RegistrationConfig, n_slides: int) -> np.ndarray:
    """The :func:`slides` (S, 4, 4) of ``obj_id``'s model (its cached :func:`model_surface`), ``n_slides`` each
    way by ``cfg.verify_slide_rel`` x its extent, none when it is not ``cfg.verify_slide_min_elong`` times as
    long along its first principal axis as along its second (the learned stage's colour-named slides)."""
    surface, _ = model_surface(cache, obj_id, cfg)
    return slides(surface, n_slides, cfg.verify_slide_rel, cfg.verify_slide_min_elong)


class _ColourGrid:
    """A voxel grid over a model's samples ``P`` (M, 3) with colours ``C`` (M, 3): per cell the distance to
    the nearest sample and that sample's colour, so that posing the samples and reading the grid replaces a
    nearest-neighbour query (:func:`near_symmetries`' dense scans)."""

    def __init__(self, P: np.ndarray, C: np.ndarray, tree, spacing: float, tol: float):
        self.h = float(spacing)
        self.lo = P.min(axis=0) - 2 * tol
        self.shape = np.ceil((P.max(axis=0) + 2 * tol - self.lo) / self.h).astype(np.int64) + 1
        idx = np.indices(tuple(self.shape)).reshape(3, -1).T
        d, j = tree.query(self.lo + idx * self.h, distance_upper_bound=tol, workers=-1)
        self.near = (d < tol).reshape(tuple(self.shape))
        self.colour = np.asarray(C, dtype=np.float32)[np.minimum(j, len(P) - 1)].reshape(*self.shape, 3)

    def fit_corr(self, Q: np.ndarray, CQ: np.ndarray, Rs: np.ndarray, c: np.ndarray,
                 batch: int = 16) -> tuple[np.ndarray, np.ndarray]:
        """For each rotation ``Rs[k]`` about ``c``, applied to the centred samples ``Q`` (N, 3) of colours
        ``CQ``: the share of them that lands near the surface, and the correlation of their colours with
        the colours they land on (0 where fewer than 10 land)."""
        fits, corrs = np.empty(len(Rs)), np.empty(len(Rs))
        A = np.asarray(CQ - CQ.mean(axis=0), np.float32)
        AA = (A * A).sum(axis=1)
        nx, ny, nz = (int(v) for v in self.shape)
        Q32, off = np.asarray(Q, np.float32), (c - self.lo).astype(np.float32)
        near, colour = self.near.ravel(), self.colour.reshape(-1, 3)
        for b in range(0, len(Rs), batch):
            R = np.asarray(Rs[b:b + batch], np.float32)
            X = np.matmul(Q32, R.transpose(0, 2, 1)) + off
            ijk = np.rint(X / self.h).astype(np.int64)
            ok = ((ijk >= 0) & (ijk < self.shape)).all(axis=2)
            lin = np.where(ok, (ijk[..., 0] * ny + ijk[..., 1]) * nz + ijk[..., 2], 0)
            w = (ok & near[lin]).astype(np.float32)  # (B, N)
            col = colour[lin]  # (B, N, 3)
            n = w.sum(axis=1)
            fits[b:b + batch] = n / len(Q)
            wc = w[..., None] * col
            r = _corr_from_sums(np.maximum(n, 1.0), w @ A, wc.sum(axis=1), w @ AA, (wc * col).sum(axis=(1, 2)),
                                np.einsum("bnc,nc->b", wc, A))
            corrs[b:b + batch] = np.where(n > 10, r, 0.0)
        return fits, corrs


def near_symmetries(surface: Surface, n_axes: int = 150, keep: int = 6, min_fit: float = 0.7,
                    n_points: int = 300, iterations: int = 6, seed: int = 0, n_dense: int = 3000) -> np.ndarray:
    """The model's near-symmetries: rigid motions ``X_ON`` (K, 4, 4) of the object frame, other than
    the identity, that map the model's surface onto itself, the flips that the masked cloud cannot
    tell apart from the true pose (a box's half-turns, a screwdriver about its shaft, a pitcher about
    its body with the handle the only difference, a ball's seams).

    A half-turn about each of ``n_axes`` axes through the centroid is refined by ICP of ``n_points``
    surface samples onto the surface (``iterations`` point-to-plane steps). A motion is a
    near-symmetry when at least ``min_fit`` of the samples land within 2 % of the diameter of the
    surface; the kept ones (``keep`` at most, 20 degrees apart and from the identity) are ordered by
    that fraction. Where the geometry alone keeps more than ``keep`` of them (a ball, a can: the shape
    maps onto itself in many ways) and the model has colours, the texture decides instead: half-turns
    about ``n_dense`` axes (a lattice about 2.6 degrees apart for 3,000) that keep ``min_fit`` of the
    samples on the surface are ranked by the correlation of the samples' chromaticities with those they
    land on (read from a voxel grid of the surface), and the best ``keep``, 20 degrees apart, are refined
    on two finer local lattices and polished by the same ICP, ordered by that correlation, so the turns
    the texture also keeps (a ball's three seam turns) come first. Cached on ``surface`` (about 1 s per
    object, 3 s for a ball). Not in the paper.
    """
    key = ("near_symmetries", n_axes, keep, min_fit, n_points, iterations, seed, n_dense)
    hit = surface._near.get(key)
    if hit is not None:
        return hit
    from scipy.spatial import cKDTree
    from scipy.spatial.transform import Rotation

    from ..evaluation.metrics import rotation_error
    from .super4pcs import kabsch_batch

    P, C = surface.points, surface.chroma
    rng = np.random.default_rng(seed)
    sub = rng.choice(len(P), min(n_points, len(P)), replace=False)
    Ps = P[sub]
    C_sub = None if C is None else C[sub]
    tree = cKDTree(P)
    tol = 0.02 * surface.diameter

    Nrm = surface.normals

    def icp(R: np.ndarray, t: np.ndarray, query, plane: bool) -> tuple[np.ndarray, np.ndarray]:
        for _ in range(iterations):
            Q = Ps @ R.T + t
            d, j = query(Q)
            inl = d < 3 * tol
            if inl.sum() < 10:
                break
            if plane:  # point-to-plane, linearised (slides along a box's faces in a step or two)
                q, p, n = Q[inl], P[j[inl]], Nrm[j[inl]]
                A = np.hstack([np.cross(q, n), n])
                x = np.linalg.solve(A.T @ A + 1e-9 * np.eye(6), A.T @ ((p - q) * n).sum(axis=1))
                dR = Rotation.from_rotvec(x[:3]).as_matrix()
                dt = x[3:]
            else:
                dRs, dts = kabsch_batch(Q[inl], P[j[inl]][None])
                dR, dt = dRs[0], dts[0]
            R, t = dR @ R, dR @ t + dt
        return R, t

    def fit_of(R: np.ndarray, t: np.ndarray) -> tuple[float, float]:
        d, j = tree.query(Ps @ R.T + t)
        g = d < tol
        corr = 0.0
        if C is not None and C_sub is not None and g.sum() > 10:
            A = C_sub[g] - C_sub[g].mean(axis=0)
            B = C[j[g]] - C[j[g]].mean(axis=0)
            corr = float((A * B).sum() / math.sqrt((A * A).sum() * (B * B).sum() + 1e-12))
        return float(g.mean()), corr

    def distinct(found: list) -> list:
        kept: list = []
        for f in found:
            if rotation_error(f[2], np.eye(3)) >= 20 and all(rotation_error(f[2], k[2]) >= 20 for k in kept):
                kept.append(f)
        return kept

    c = surface.centroid
    found = []
    for a in hemisphere_axes(n_axes):
        R = Rotation.from_rotvec(math.pi * a).as_matrix()
        R, t = icp(R, c - R @ c, tree.query, True)
        fit, corr = fit_of(R, t)
        if fit >= min_fit:
            found.append((round(fit, 1), corr, R, t))
    found.sort(key=lambda f: (-f[0], -f[1]))
    kept = distinct(found)
    if len(kept) > keep and C is not None and C_sub is not None:
        # the shape maps onto itself in too many ways to keep them all (a ball, a can): scan half-turns about
        # a dense lattice of axes by the colour agreement of the samples they move (the shape keeping them),
        # then refine the best on a finer local lattice; a voxel grid of the surface's distance and colour
        # makes each turn a gather (ICP from a 20-degree lattice with the colours as extra coordinates lost
        # the narrow peaks of a ball's seam turns, a few degrees wide)
        grid = _ColourGrid(P, C, tree, surface.spacing, tol)
        sub2 = rng.choice(len(P), min(10 * n_points, len(P)), replace=False)
        sub3 = rng.choice(len(P), min(20 * n_points, len(P)), replace=False)
        axes = hemisphere_axes(n_dense)
        Rs = Rotation.from_rotvec(math.pi * axes).as_matrix()
        fits, corrs = grid.fit_corr(P[sub2] - c, C[sub2], Rs, c)
        order = [i for i in np.argsort(-corrs) if fits[i] >= min_fit]
        step = math.degrees(math.sqrt(2 * math.pi / n_dense))  # the lattice's spacing (degrees)
        again: list = []
        for i in order:
            if len(again) >= keep:
                break
            R = Rs[i]
            if rotation_error(R, np.eye(3)) < 20 or any(rotation_error(R, k[2]) < 20 for k in again):
                continue
            best = -1.0
            for scale in (step, step / 3):  # two finer local lattices on more of the samples
                g = np.radians(scale) * np.linspace(-1.0, 1.0, 5)
                local = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
                trial = Rotation.from_rotvec(local).as_matrix() @ R
                f2, c2 = grid.fit_corr(P[sub3] - c, C[sub3], trial, c)
                c2 = np.where(f2 >= min_fit, c2, -np.inf)
                j = int(np.argmax(c2))
                if c2[j] > best:
                    best, R = float(c2[j]), trial[j]
            R2, t2 = icp(R, c - R @ c, tree.query, True)
            fit2 = fit_of(R2, t2)[0]
            if fit2 >= min_fit:  # (fit, colour correlation, R, t), as ``found``
                again.append((round(fit2, 1), best, R2, t2))
        kept = sorted(again, key=lambda f: -f[1])
    kept = kept[:keep]
    out = np.stack([X_from(f[2], f[3]) for f in kept]) if kept else np.zeros((0, 4, 4))
    surface._near[key] = out
    return out


@dataclass
class Scores:
    """Per-hypothesis terms of :func:`score_hypotheses`: ``score``, ``depth``, ``iou``, ``texture``,
    ``n_visible`` (each (H,)); ``textured``: whether the texture term was used."""

    score: np.ndarray
    depth: np.ndarray
    iou: np.ndarray
    texture: np.ndarray
    n_visible: np.ndarray
    textured: bool


@numba.njit(cache=True, fastmath=True, nogil=True)
def _score_kernel(pts, nrm, grey, chrom, gdet, textured, detailed, Rs, ts, fx, fy, cx, cy, depth, mask, rgb, fdet,
                  cell, gw, gh, mcell, tau, zbuf, sil, su, sv, sz, out):  # pragma: no cover - njit
    """Per hypothesis ``h`` (pose ``Rs[h]``, ``ts[h]``): project the front-facing samples ``pts``
    (normals ``nrm``) into the image's cell grid (``cell`` pixels, ``gw`` x ``gh``), keep the nearest
    per cell (``zbuf``), then classify the visible samples against ``depth`` and ``mask`` and accumulate
    into ``out[h]``: agree, wrong, visible, silhouette cells, silhouette & mask cells, then the texture
    sums of the agreeing samples in the mask (n; grey: sum m, sum f, sum m^2, sum f^2, sum m f;
    chromaticity: sum m (3), sum f (3), sum |m|^2, sum |f|^2, sum m . f; with ``detailed``, grey detail
    ``gdet`` against ``fdet``: sum m, sum f, sum m^2, sum f^2, sum m f)."""
    N = pts.shape[0]
    Hh, Ww = depth.shape
    G = gw * gh
    for h in range(Rs.shape[0]):
        for g in range(G):
            zbuf[g] = np.inf
            sil[g] = False
        for k in range(N):
            x = Rs[h, 0, 0] * pts[k, 0] + Rs[h, 0, 1] * pts[k, 1] + Rs[h, 0, 2] * pts[k, 2] + ts[h, 0]
            y = Rs[h, 1, 0] * pts[k, 0] + Rs[h, 1, 1] * pts[k, 1] + Rs[h, 1, 2] * pts[k, 2] + ts[h, 1]
            z = Rs[h, 2, 0] * pts[k, 0] + Rs[h, 2, 1] * pts[k, 1] + Rs[h, 2, 2] * pts[k, 2] + ts[h, 2]
            sz[k] = -1.0
            if z <= 1e-6:
                continue
            nx = Rs[h, 0, 0] * nrm[k, 0] + Rs[h, 0, 1] * nrm[k, 1] + Rs[h, 0, 2] * nrm[k, 2]
            ny = Rs[h, 1, 0] * nrm[k, 0] + Rs[h, 1, 1] * nrm[k, 1] + Rs[h, 1, 2] * nrm[k, 2]
            nz = Rs[h, 2, 0] * nrm[k, 0] + Rs[h, 2, 1] * nrm[k, 1] + Rs[h, 2, 2] * nrm[k, 2]
            if nx * x + ny * y + nz * z >= 0:  # back-facing
                continue
            # pixel (u, v) has its centre at integer coordinates: the nearest pixel is the rounded one
            uf = fx * x / z + cx + 0.5
            vf = fy * y / z + cy + 0.5
            if uf < 0 or vf < 0 or uf >= Ww or vf >= Hh:
                continue
            u = int(uf)
            v = int(vf)
            su[k] = u
            sv[k] = v
            sz[k] = z
            c = (v // cell) * gw + u // cell
            if z < zbuf[c]:
                zbuf[c] = z
        agree = 0.0
        wrong = 0.0
        nvis = 0.0
        acc = np.zeros(20)
        for k in range(N):
            z = sz[k]
            if z < 0:
                continue
            u = su[k]
            v = sv[k]
            c = (v // cell) * gw + u // cell
            if z > zbuf[c] + tau:  # hidden by the model's own nearer surface
                continue
            nvis += 1.0
            d = depth[v, u]
            inm = mask[v, u]
            if not (d > 0):  # unknown depth (0 or NaN)
                if inm:
                    sil[c] = True
                continue
            dz = z - d
            if dz > tau and not inm:  # behind the observed surface: occluded, not wrong
                continue
            sil[c] = True
            if abs(dz) <= tau:
                agree += 1.0
                if inm and textured:
                    r = rgb[v, u, 0] / 255.0
                    g = rgb[v, u, 1] / 255.0
                    b = rgb[v, u, 2] / 255.0
                    gf = 0.299 * r + 0.587 * g + 0.114 * b
                    gm = grey[k]
                    acc[0] += 1.0
                    acc[1] += gm
                    acc[2] += gf
                    acc[3] += gm * gm
                    acc[4] += gf * gf
                    acc[5] += gm * gf
                    s = r + g + b + 0.05
                    for ch in range(3):
                        cf = (r if ch == 0 else (g if ch == 1 else b)) / s
                        cm = chrom[k, ch]
                        acc[6 + ch] += cm
                        acc[9 + ch] += cf
                        acc[12] += cm * cm
                        acc[13] += cf * cf
                        acc[14] += cm * cf
                    if detailed:
                        dm = gdet[k]
                        df = fdet[v, u]
                        acc[15] += dm
                        acc[16] += df
                        acc[17] += dm * dm
                        acc[18] += df * df
                        acc[19] += dm * df
            else:
                wrong += 1.0
        nsil = 0.0
        ninter = 0.0
        nmask = 0.0
        for g in range(G):
            if mcell[g]:
                nmask += 1.0
            if sil[g]:
                nsil += 1.0
                if mcell[g]:
                    ninter += 1.0
        out[h, 0] = agree
        out[h, 1] = wrong
        out[h, 2] = nvis
        out[h, 3] = ninter
        out[h, 4] = nsil + nmask - ninter
        for j in range(20):
            out[h, 5 + j] = acc[j]


def _corr_from_sums(n, sa, sb, saa, sbb, sab):
    """Correlation from sums (n, sum a, sum b, sum a^2, sum b^2, sum ab; arrays or scalars); channels
    summed when ``sa``, ``sb`` are (..., C)."""
    ca = saa - (sa * sa).sum(axis=-1) / n
    cb = sbb - (sb * sb).sum(axis=-1) / n
    cab = sab - (sa * sb).sum(axis=-1) / n
    # a flat colour on either side (variance lost in rounding): no evidence, correlation 0
    flat = (ca <= 1e-6 * n) | (cb <= 1e-6 * n)
    r = cab / np.sqrt(np.where(flat, 1.0, ca * cb))
    return np.where(flat, 0.0, np.clip(r, -1.0, 1.0))


def warmup() -> None:
    """Compile :func:`_score_kernel` (or load it from Numba's cache) on a tiny input."""
    f4 = np.float32
    _score_kernel(np.zeros((1, 3), f4), np.zeros((1, 3), f4), np.zeros(1, f4), np.zeros((1, 3), f4),
                  np.zeros(1, f4), True, True, np.eye(3, dtype=f4)[None], np.zeros((1, 3), f4), 1.0, 1.0, 0.0, 0.0,
                  np.zeros((2, 2), f4), np.zeros((2, 2), np.bool_), np.zeros((2, 2, 3), np.uint8),
                  np.zeros((2, 2), f4), 1, 2, 2, np.zeros(4, np.bool_), 0.01, np.zeros(4), np.zeros(4, np.bool_),
                  np.zeros(1, np.int64), np.zeros(1, np.int64), np.zeros(1), np.zeros((1, 25)))


def score_hypotheses(Xs: np.ndarray, surface: Surface, frame: Frame, cfg: RegistrationConfig) -> Scores:
    """Score poses ``Xs`` (H, 4, 4; object in camera, metres) of ``surface`` against ``frame``.

    The terms are described in the module docstring; ``cfg.verify_tau_rel`` (depth tolerance /
    diameter), ``verify_w_depth``, ``verify_w_mask``, ``verify_w_texture`` (weights) and
    ``verify_max_cells`` (cells along the image's longer side, at most) are the parameters. One Numba
    pass per hypothesis (no (H, N) temporaries).
    Returns:
        :class:`Scores`; ``score`` in [-1, 1] (a hypothesis with no visible sample scores -1).
    Raises:
        ValueError: an empty instance mask.
    """
    Xs = np.asarray(Xs, dtype=np.float64).reshape(-1, 4, 4)
    H = len(Xs)
    Hh, Ww = frame.mask.shape
    (mv, mu), mask_c, depth = frame.arrays()
    if len(mu) == 0:
        raise ValueError("empty instance mask")
    K = np.asarray(frame.K, dtype=np.float64)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    zmed = float(np.median(Xs[:, 2, 3]))
    # cells about the projected sample spacing (no holes between splatted samples), at most max_cells a side
    cell = max(1, math.ceil(max(fx, fy) * surface.spacing / max(zmed, 1e-3)),
               math.ceil(max(Hh, Ww) / cfg.verify_max_cells))
    gw, gh = math.ceil(Ww / cell), math.ceil(Hh / cell)
    G = gw * gh
    mcell = np.zeros(G, dtype=np.bool_)
    mcell[(mv // cell) * gw + mu // cell] = True
    textured = surface.grey is not None and frame.rgb is not None
    rgb = np.zeros((1, 1, 3), np.uint8)
    if textured and frame.rgb is not None:
        rgb = frame.rgb
    if rgb.dtype != np.uint8:
        rgb = np.clip(np.asarray(rgb) * 255.0 + 0.5, 0, 255).astype(np.uint8)
    f4 = np.float32
    Np = len(surface.points)
    pts, nrm = surface.cast("points"), surface.cast("normals")
    grey = surface.cast("grey") if textured else np.zeros(1, f4)
    chrom = surface.cast("chroma") if textured else np.zeros((1, 3), f4)
    dshare = cfg.verify_detail_share if (textured and surface.detail is not None) else 0.0
    if dshare > 0:
        gdet = surface.cast("detail")
        fdet = frame.detail(max(fx, fy) * surface.detail_radius / max(zmed, 1e-3))
    else:  # not read by the kernel
        gdet, fdet = np.zeros(1, f4), np.zeros((1, 1), f4)
    out = np.zeros((H, 25))
    _score_kernel(pts, nrm, grey, chrom, gdet, textured, dshare > 0, Xs[:, :3, :3].astype(f4),
                  Xs[:, :3, 3].astype(f4), fx, fy, cx, cy, depth, mask_c,
                  np.ascontiguousarray(rgb), fdet, cell, gw, gh, mcell, cfg.verify_tau_rel * surface.diameter,
                  np.empty(G), np.empty(G, np.bool_), np.empty(Np, np.int64), np.empty(Np, np.int64), np.empty(Np),
                  out)
    agree, wrong, n_vis, inter, union = out[:, 0], out[:, 1], out[:, 2], out[:, 3], out[:, 4]
    depth_s = agree / np.maximum(agree + wrong, 1.0)
    iou = inter / np.maximum(union, 1.0)
    texture = np.zeros(H)
    if textured:
        n = np.maximum(out[:, 5], 1.0)
        ncc_g = _corr_from_sums(n, out[:, 6:7], out[:, 7:8], out[:, 8], out[:, 9], out[:, 10])
        ncc_c = _corr_from_sums(n, out[:, 11:14], out[:, 14:17], out[:, 17], out[:, 18], out[:, 19])
        share = cfg.verify_grey_share
        tex = share * ncc_g + (1.0 - share) * ncc_c
        if dshare > 0:
            ncc_d = _corr_from_sums(n, out[:, 20:21], out[:, 21:22], out[:, 22], out[:, 23], out[:, 24])
            tex = (1.0 - dshare) * tex + dshare * ncc_d
        texture = np.where(out[:, 5] >= 3, tex, 0.0)
    wd, wm, wt = cfg.verify_w_depth, cfg.verify_w_mask, (cfg.verify_w_texture if textured else 0.0)
    score = (wd * depth_s + wm * iou + wt * texture) / max(wd + wm + wt, 1e-12)
    score = np.where(n_vis > 0, score, -1.0)
    return Scores(score, depth_s, iou, texture, n_vis, textured)


def recentred(Xs: np.ndarray, surface: Surface, frame: Frame) -> np.ndarray:
    """Copies of the poses ``Xs`` (H, 4, 4) moved so that the centroid of their camera-facing samples
    lies on the centroid of the observed masked cloud (a turned hypothesis keeps the model's centroid,
    which for a partial view is often centimetres from where the turned model fits, beyond ICP's reach).
    """
    from ..datasets.geometry import backproject

    obs, _, _ = backproject(frame.depth, frame.K, frame.mask, None)
    if len(obs) == 0:
        return Xs[:0]
    c_obs = obs.mean(axis=0)
    R, t = Xs[:, :3, :3], Xs[:, :3, 3]
    P = np.matmul(surface.points, R.transpose(0, 2, 1)) + t[:, None, :]
    front = (np.matmul(surface.normals, R.transpose(0, 2, 1)) * P).sum(axis=2) < 0
    n = np.maximum(front.sum(axis=1), 1)[:, None]
    c_front = (P * front[..., None]).sum(axis=1) / n
    out = Xs.copy()
    out[:, :3, 3] += c_obs - c_front
    return out


def turn_search(Xs: np.ndarray, scores: np.ndarray, surface: Surface, frame: Frame, cfg: RegistrationConfig,
                rng: np.random.Generator, n: int, deg: float, rounds: int,
                recentre: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Improve poses ``Xs`` (H, 4, 4) of scores ``scores`` (H,) by turns about the model's centroid:
    ``rounds`` rounds of ``n`` random rotations of at most ``deg`` degrees (halved each round) per pose,
    each also recentred on the observed cloud (:func:`recentred`) when ``recentre``; a pose moves when a
    trial scores higher. Returns ``(poses, scores)``, new arrays."""
    from .verify import _small_rotations

    Xs, scores = Xs.copy(), np.asarray(scores, dtype=np.float64).copy()
    c = surface.centroid
    ang = deg
    for _ in range(rounds):
        S = _small_rotations(n, ang, rng)
        X_ON = np.stack([X_from(Si, c - Si @ c) for Si in S])
        trial = np.einsum("hij,njk->hnik", Xs, X_ON).reshape(-1, 4, 4)
        if recentre:
            trial = np.concatenate([trial, recentred(trial, surface, frame)])
        k = 1 + int(recentre)
        st = score_hypotheses(trial, surface, frame, cfg).score.reshape(k, len(Xs), n)
        trial = trial.reshape(k, len(Xs), n, 4, 4)
        for h in range(len(Xs)):
            a, j = np.unravel_index(int(np.argmax(st[:, h])), (k, n))
            if st[a, h, j] > scores[h]:
                Xs[h], scores[h] = trial[a, h, j], st[a, h, j]
        ang /= 2.0
    return Xs, scores


def local_search(Xs: np.ndarray, scores: np.ndarray, surface: Surface, frame: Frame, cfg: RegistrationConfig,
                 seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Improve poses ``Xs`` (H, 4, 4) of scores ``scores`` (H,) by rotations about the model's centroid:
    ``verify_search_rounds`` rounds of ``verify_search_n`` random rotations of at most
    ``verify_search_deg`` degrees (halved each round) per pose, each also recentred on the observed
    cloud (:func:`recentred`); a pose moves when a trial scores higher (:func:`turn_search`). Returns
    ``(poses, scores)``."""
    return turn_search(Xs, scores, surface, frame, cfg, np.random.default_rng(seed), cfg.verify_search_n,
                       cfg.verify_search_deg, cfg.verify_search_rounds, recentre=True)


def rotation_free(surface: Surface, min_fit: float = 0.9, n: int = 32, seed: int = 0) -> bool:
    """Whether the model's geometry leaves its turn open (a ball): at least ``min_fit`` of the surface
    samples stay within two sample spacings of the surface under at least nine in ten of ``n`` random
    rotations about the centroid. Cached on ``surface``."""
    key = ("rotation_free", float(min_fit), int(n), int(seed))
    hit = surface._near.get(key)
    if hit is not None:
        return bool(hit)
    from scipy.spatial import cKDTree
    from scipy.spatial.transform import Rotation

    tree = cKDTree(surface.points)
    c = surface.centroid
    fits = []
    for R in Rotation.random(n, random_state=seed).as_matrix():
        d, _ = tree.query((surface.points - c) @ R.T + c, distance_upper_bound=2 * surface.spacing)
        fits.append(float(np.mean(d <= 2 * surface.spacing)))
    surface._near[key] = out = bool(np.mean(np.asarray(fits) >= min_fit) >= 0.9)
    return out


#: The coarse-to-fine schedule of :func:`texture_search`: (blur radius / diameter, search angle in
#: degrees, rounds); the first level scores the lattice, the others refine by random turns of at most the
#: angle (halved each round). Chosen on ``data/val``'s baseball (docs/pose.md, "Texture search").
TEXTURE_LEVELS: tuple[tuple[float, float, int], ...] = ((0.15, 0.0, 0), (0.08, 20.0, 4), (0.04, 8.0, 3),
                                                        (0.0, 4.0, 3))
#: random turns per hypothesis and round of :func:`texture_search`'s refinement
TEXTURE_TRIALS = 48


def _blurred_surface(surface: Surface, rel: float) -> Surface:
    """``surface`` with its colours averaged over the samples within ``rel`` x the diameter (cached)."""
    if rel <= 0 or surface.chroma is None:
        return surface
    key = ("blurred", float(rel))
    hit = surface._near.get(key)
    if hit is not None:
        return hit
    import dataclasses

    from scipy.spatial import cKDTree

    from ..geometry import neighbourhood_means

    nb = cKDTree(surface.points).query_ball_point(surface.points, rel * surface.diameter)
    chroma = np.stack([neighbourhood_means(surface.chroma[:, k], nb) for k in range(3)], axis=1)
    grey = neighbourhood_means(surface.grey, nb) if surface.grey is not None else None
    out = dataclasses.replace(surface, chroma=chroma, grey=grey, detail=None)
    surface._near[key] = out
    return out


def _blurred_frame(frame: Frame, sigma_px: float) -> Frame:
    """``frame`` with its colours Gaussian-blurred by ``sigma_px`` inside the mask's box (a margin around)."""
    if sigma_px <= 0 or frame.rgb is None:
        return frame
    from scipy.ndimage import gaussian_filter

    box = frame.box(int(4 * sigma_px) + 2)
    if box is None:
        return frame
    v0, v1, u0, u1 = box
    src = frame.rgb_crop(box, np.float32)
    rgb = np.zeros((*frame.mask.shape, 3), np.float32)
    rgb[v0:v1, u0:u1] = np.stack([gaussian_filter(src[..., k], sigma_px) for k in range(3)], axis=-1)
    return Frame(frame.depth, frame.K, frame.mask, rgb)


def _ball_centre(surface: Surface, frame: Frame, iterations: int = 10) -> np.ndarray | None:
    """The centre (3,) in the camera frame of a ball of the model's radius (the samples' median distance
    to their centroid) fitted to the frame's masked cloud by Gauss-Newton on ``|p - x| - radius``; None
    for fewer than 10 points."""
    from ..datasets.geometry import backproject

    obs, _, _ = backproject(frame.depth, frame.K, frame.mask, None)
    if len(obs) < 10:
        return None
    radius = float(np.median(np.linalg.norm(surface.points - surface.centroid, axis=1)))
    m = obs.mean(axis=0)
    x = m + radius * m / max(float(np.linalg.norm(m)), 1e-9)  # behind the visible cap, seen from the camera
    for _ in range(iterations):
        d = obs - x
        n = np.maximum(np.linalg.norm(d, axis=1), 1e-9)
        J = -d / n[:, None]
        step, *_ = np.linalg.lstsq(J, -(n - radius), rcond=None)
        x = x + step
        if np.linalg.norm(step) < 1e-5:
            break
    return x


def texture_search(X_CO: np.ndarray, surface: Surface, frame: Frame, cfg: RegistrationConfig,
                   seed: int = 0) -> np.ndarray:
    """Poses (K, 4, 4) of an object whose geometry leaves its turn open, its turn found by texture alone.

    ``X_CO`` (4, 4), its centre first moved onto the centre of a ball of the model's radius fitted to the
    masked cloud, is turned about the model's centroid by ``verify_texture_lattice`` random rotations,
    scored (:func:`score_hypotheses`) with the model's colours and the frame's blurred over
    ``TEXTURE_LEVELS[0]``'s radius (a ball's seam, a few millimetres wide, has a basin of a few degrees;
    blurred, of some 30), and the best ``verify_texture_keep`` are refined level by level of
    :data:`TEXTURE_LEVELS` as the blur shrinks to none (random turns, :data:`TEXTURE_TRIALS` per pose and
    round, a pose moving when a turn scores higher). Returns the refined poses, best first. Not in the
    paper."""
    from scipy.spatial.transform import Rotation

    c = surface.centroid
    f_px = float(frame.K[0, 0])
    z = max(float(X_CO[2, 3]), 1e-3)

    def level(rel: float) -> tuple[Surface, Frame]:
        return _blurred_surface(surface, rel), _blurred_frame(frame, rel * surface.diameter * f_px / z / 2)

    key = ("texture_lattice", int(cfg.verify_texture_lattice))
    X_ON = surface._near.get(key)
    if X_ON is None:
        Rs = Rotation.random(cfg.verify_texture_lattice, random_state=7).as_matrix()
        X_ON = surface._near[key] = np.stack([X_from(R, c - R @ c) for R in Rs])
    rel0 = TEXTURE_LEVELS[0][0]
    # the model's centre onto the centre of the ball fitted to the observed cloud first: a turn about the
    # centre cannot mend a misplaced centre, and the input's may be far off when its turn was wrong
    X0 = np.asarray(X_CO, np.float64).copy()
    centre = _ball_centre(surface, frame)
    if centre is not None:
        X0[:3, 3] = centre - X0[:3, :3] @ c
    Xs = np.concatenate([X0[None], np.einsum("ij,njk->nik", X0, X_ON)])
    sc = score_hypotheses(Xs, *level(rel0), cfg).score
    top = np.argsort(-sc, kind="stable")[: cfg.verify_texture_keep]
    Xs = Xs[top].copy()
    rng = np.random.default_rng(seed)
    for rel, deg, rounds in TEXTURE_LEVELS[1:]:
        surf_l, frame_l = level(rel)
        sc = score_hypotheses(Xs, surf_l, frame_l, cfg).score
        Xs, sc = turn_search(Xs, sc, surf_l, frame_l, cfg, rng, TEXTURE_TRIALS, deg, rounds)
    return Xs[np.argsort(-sc, kind="stable")]


@dataclass
class Verified:
    """Output of :func:`verify_hypotheses`: the kept pose ``X_CO`` (4, 4), its ``score`` (in [-1, 1]),
    the index of the kept hypothesis among those scored (``index``; 0 is the input pose), how many were
    scored (``n_hypotheses``) and ICP'd (``n_icp``), and whether the texture term was used."""

    X_CO: np.ndarray
    score: float
    index: int
    n_hypotheses: int
    n_icp: int
    textured: bool


def verify_hypotheses(
    X_CO: np.ndarray,
    surface: Surface,
    frame: Frame,
    cfg: RegistrationConfig,
    extra: np.ndarray | None = None,
    icp=None,
    obj_id: int | None = None,
) -> Verified:
    """Keep the best of several hypotheses of one instance (see the module docstring).

    Args:
        X_CO: (4, 4) the pose so far (object in camera, metres). surface: the object's :class:`Surface`.
        frame: the :class:`Frame`. cfg: ``verify_*`` fields (``verify_turns``: turns per principal
            axis, 0 or 1 for none; ``verify_icp``: hypotheses ICP'd at most; ``verify_margin``: only
            the best is ICP'd when it leads the second by this much; ``verify_min_gain``: another
            hypothesis replaces ``X_CO`` only when it scores this much higher).
        extra: optional (E, 4, 4) further poses (other basins of the colour search, the global
            method's); their turns are scored too.
        icp: ``icp(X_CO) -> X_CO`` refinement (None: no ICP). obj_id: for the textureless log line.
    Returns:
        :class:`Verified`.
    """
    bases = [np.asarray(X_CO, dtype=np.float64)]
    if extra is not None:
        bases += [np.asarray(e, dtype=np.float64) for e in extra]
    if cfg.verify_texture_lattice > 0 and surface.chroma is not None and frame.rgb is not None \
            and rotation_free(surface, cfg.verify_texture_min_fit):
        bases += list(texture_search(bases[0], surface, frame, cfg, seed=cfg.seed))
    T = turns(surface, cfg.verify_turns) if cfg.verify_turns > 1 else np.eye(4)[None]
    if cfg.verify_near_symmetries > 0:
        T = np.concatenate([T, near_symmetries(surface, keep=cfg.verify_near_symmetries)])
    Xs = np.einsum("bij,tjk->btik", np.stack(bases), T).reshape(-1, 4, 4)
    if cfg.verify_slides > 0:  # after the input pose (index 0 stays the input)
        S = slides(surface, cfg.verify_slides, cfg.verify_slide_rel, cfg.verify_slide_min_elong)
        Xs = np.concatenate([Xs, np.einsum("hij,sjk->hsik", Xs, S).reshape(-1, 4, 4)])
    if cfg.verify_recentre:
        Xs = np.concatenate([Xs, recentred(Xs[1:], surface, frame)])
    sc = score_hypotheses(Xs, surface, frame, cfg)
    if not sc.textured and surface.grey is None and obj_id not in _TEXTURELESS_LOGGED:
        _TEXTURELESS_LOGGED.add(obj_id)
        log.warning("object %s: model without colours, hypotheses verified on depth and mask alone", obj_id)
    order = np.argsort(-sc.score, kind="stable")
    if cfg.verify_search_rounds > 0:
        Xs, score = Xs.copy(), sc.score.copy()
        top = order[: cfg.verify_icp]
        Xs[top], score[top] = local_search(Xs[top], score[top], surface, frame, cfg)
        order = np.argsort(-score, kind="stable")
    n_icp = 0
    best_i, best_X, best_s = int(order[0]), Xs[order[0]], float(sc.score[order[0]])
    if icp is not None:
        k = min(cfg.verify_icp, len(order))
        if k > 1 and sc.score[order[0]] - sc.score[order[1]] >= cfg.verify_margin:
            k = 1  # one hypothesis clearly wins: stop early
        refined = np.stack([icp(Xs[i]) for i in order[:k]])
        n_icp = k
        s2 = score_hypotheses(refined, surface, frame, cfg).score
        j = int(np.argmax(s2))
        best_i, best_X, best_s = int(order[j]), refined[j], float(s2[j])
    # the input pose stays unless another scores clearly higher (near-ties are common on real frames:
    # a flat bottle's front and back; the pose so far already fits the masked cloud)
    if best_i != 0 and best_s < sc.score[0] + cfg.verify_min_gain:
        best_i, best_X, best_s = 0, Xs[0], float(sc.score[0])
    return Verified(best_X, best_s, best_i, len(Xs), n_icp, sc.textured)
