"""Hypothesis verification against the frame: several poses per instance, scored by projection.

Global registration, ICP and the colour search each give one pose; on real frames the wrong one often
fits the masked cloud as well as the right one (a turn about a near-symmetric axis that only the
texture decides, a flip of a partly occluded object). :func:`verify_hypotheses` keeps several
hypotheses per instance (the input pose, the colour search's other basins, the global method's, and
their turns about the model's principal axes through its centroid), scores each against the frame
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
* **texture**: over the agreeing samples inside the mask, the mean of the normalised cross-correlation of
  grey values and of the centred correlation of chromaticity (model vertex colours against the frame's
  pixels): both insensitive to the gain and offset of the lighting.

``score = (w_depth * depth + w_mask * iou + w_tex * texture) / (w_depth + w_mask + w_tex)`` (texture in
[-1, 1], the rest in [0, 1]). A model without colours is scored on depth and mask alone (logged once).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

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


@dataclass
class Surface:
    """Model surface samples for verification (object frame, metres).

    Attributes:
        points, normals: (M, 3) uniform surface samples with outward unit normals. spacing: their
        spacing (m). grey, chroma: (M,) grey values and (M, 3) chromaticities of the model's colours
        at the samples, or None for a model without colours. axes: (3, 3) principal axes (columns).
        centroid: (3,). diameter: metres.
    """

    points: np.ndarray
    normals: np.ndarray
    spacing: float
    grey: np.ndarray | None
    chroma: np.ndarray | None
    axes: np.ndarray
    centroid: np.ndarray
    diameter: float


def grey_of(rgb: np.ndarray) -> np.ndarray:
    """Luma (Rec. 601) of (..., 3) colours in [0, 1] -> (...)."""
    return rgb @ np.array([0.299, 0.587, 0.114])


def build_surface(points: np.ndarray, normals: np.ndarray, spacing: float, diameter: float,
                  model_points: np.ndarray | None = None, model_colors: np.ndarray | None = None) -> Surface:
    """A :class:`Surface` from (M, 3) samples and normals (object frame, m) at ``spacing`` metres; the
    colours (N, 3 in [0, 1]) of the model points ``model_points`` (N, 3) are read at the nearest one."""
    from .verify import chroma

    grey = ch = None
    if model_colors is not None and model_points is not None and len(model_colors) == len(model_points):
        from scipy.spatial import cKDTree

        _, idx = cKDTree(model_points).query(points, k=1)
        col = np.asarray(model_colors, dtype=np.float64)[idx]
        grey, ch = grey_of(col), chroma(col)
    c = points.mean(axis=0)
    _, vecs = np.linalg.eigh(np.cov((points - c).T))
    return Surface(np.asarray(points, np.float64), np.asarray(normals, np.float64), float(spacing), grey, ch,
                   vecs[:, ::-1].copy(), c, float(diameter))


def model_surface(cache: ReferenceCache, obj_id: int, cfg: RegistrationConfig) -> tuple[Surface, float]:
    """The cached :class:`Surface` of ``obj_id`` (the registration reference at ``verify_voxel_rel`` x
    the diameter, with the model's colours); returns ``(surface, seconds spent building it now)``."""
    import time

    key = ("surface", int(obj_id), float(cfg.verify_voxel_rel))
    hit = cache.extra.get(key)
    if hit is not None:
        return hit, 0.0
    t0 = time.perf_counter()
    model = cache.dataset.model(obj_id)
    spacing = cfg.verify_voxel_rel * model.diameter
    ref, _ = cache.get(obj_id, spacing, None)
    surf = build_surface(ref.points, ref.normals, spacing, model.diameter, model.points, model.colors)
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
            X = np.eye(4)
            X[:3, :3] = S
            X[:3, 3] = c - S @ c
            out.append(X)
    return np.stack(out)


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


def _frame_colours(rgb: np.ndarray, v: np.ndarray, u: np.ndarray) -> np.ndarray:
    c = rgb[v, u]
    return c.astype(np.float64) / 255.0 if c.dtype == np.uint8 else c.astype(np.float64)


def score_hypotheses(Xs: np.ndarray, surface: Surface, frame: Frame, cfg: RegistrationConfig) -> Scores:
    """Score poses ``Xs`` (H, 4, 4; object in camera, metres) of ``surface`` against ``frame``.

    The terms are described in the module docstring; ``cfg.verify_tau_rel`` (depth tolerance /
    diameter), ``verify_w_depth``, ``verify_w_mask``, ``verify_w_texture`` (weights) and
    ``verify_max_cells`` (cells along the longer side of the grid, at most) are the parameters.
    Returns:
        :class:`Scores`; ``score`` in [-1, 1] (a hypothesis with no visible sample scores -1).
    """
    from .verify import chroma

    Xs = np.asarray(Xs, dtype=np.float64)
    H = len(Xs)
    Hh, Ww = frame.mask.shape
    K = np.asarray(frame.K, dtype=np.float64)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    R, t = Xs[:, :3, :3], Xs[:, :3, 3]
    P = np.einsum("hij,nj->hni", R, surface.points) + t[:, None, :]
    Nc = np.einsum("hij,nj->hni", R, surface.normals)
    z = P[..., 2]
    zs = np.where(z > 1e-6, z, 1.0)
    uf = fx * P[..., 0] / zs + cx
    vf = fy * P[..., 1] / zs + cy
    valid = (z > 1e-6) & (np.einsum("hni,hni->hn", Nc, P) < 0) & (uf >= 0) & (uf < Ww) & (vf >= 0) & (vf < Hh)
    u = np.clip(uf, 0, Ww - 1).astype(np.int64)
    v = np.clip(vf, 0, Hh - 1).astype(np.int64)
    # the grid: the mask's bounding box and every hypothesis's projection
    mv, mu = np.nonzero(frame.mask)
    if len(mu) == 0:
        raise ValueError("empty instance mask")
    uu, vv = u[valid], v[valid]
    x0 = min(int(mu.min()), int(uu.min()) if len(uu) else Ww)
    x1 = max(int(mu.max()), int(uu.max()) if len(uu) else 0) + 1
    y0 = min(int(mv.min()), int(vv.min()) if len(vv) else Hh)
    y1 = max(int(mv.max()), int(vv.max()) if len(vv) else 0) + 1
    zmed = float(np.median(z[valid])) if valid.any() else 1.0
    cell = max(1, math.ceil(max(fx, fy) * surface.spacing / max(zmed, 1e-3)),
               math.ceil(max(x1 - x0, y1 - y0) / cfg.verify_max_cells))
    gw, gh = math.ceil((x1 - x0) / cell), math.ceil((y1 - y0) / cell)
    G = gw * gh
    ci = ((v - y0) // cell) * gw + (u - x0) // cell
    flat = np.arange(H)[:, None] * G + np.clip(ci, 0, G - 1)
    zbuf = np.full(H * G, np.inf)
    np.minimum.at(zbuf, flat[valid], z[valid])
    tau = cfg.verify_tau_rel * surface.diameter
    visible = valid & (z <= zbuf[flat] + tau)
    D = np.asarray(frame.depth, dtype=np.float64)[v, u]
    known = np.isfinite(D) & (D > 0)
    inm = frame.mask[v, u]
    dz = np.where(known, z - D, 0.0)
    agree = visible & known & (np.abs(dz) <= tau)
    wrong = visible & known & ((dz < -tau) | (inm & (dz > tau)))
    occluded = visible & known & ~inm & (dz > tau)
    n_agree = agree.sum(axis=1)
    n_wrong = wrong.sum(axis=1)
    depth = n_agree / np.maximum(n_agree + n_wrong, 1)
    # silhouette against the mask's cells
    sil = np.zeros(H * G, dtype=bool)
    sil[flat[visible & ~occluded]] = True
    sil = sil.reshape(H, G)
    mcell = np.zeros(G, dtype=bool)
    mcell[((mv - y0) // cell) * gw + (mu - x0) // cell] = True
    inter = (sil & mcell).sum(axis=1)
    union = (sil | mcell).sum(axis=1)
    iou = inter / np.maximum(union, 1)
    # texture: agreeing samples inside the mask
    texture = np.zeros(H)
    textured = surface.grey is not None and frame.rgb is not None
    if textured:
        sel = agree & inm
        w = sel.astype(np.float64)
        n = np.maximum(w.sum(axis=1), 1.0)
        col_f = _frame_colours(frame.rgb, v, u)  # (H, N, 3)
        g_f = grey_of(col_f)
        g_m = np.broadcast_to(surface.grey, g_f.shape)
        texture = 0.5 * (_ncc(g_m[..., None], g_f[..., None], w, n) + _ncc(
            np.broadcast_to(surface.chroma, col_f.shape), chroma(col_f.reshape(-1, 3)).reshape(col_f.shape), w, n))
        texture = np.where(sel.sum(axis=1) >= 3, texture, 0.0)
    wd, wm, wt = cfg.verify_w_depth, cfg.verify_w_mask, (cfg.verify_w_texture if textured else 0.0)
    score = (wd * depth + wm * iou + wt * texture) / max(wd + wm + wt, 1e-12)
    n_vis = visible.sum(axis=1)
    score = np.where(n_vis > 0, score, -1.0)
    return Scores(score, depth, iou, texture, n_vis, textured)


def _ncc(a: np.ndarray, b: np.ndarray, w: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Weighted correlation over axis 1 of (H, N, C) features ``a`` and ``b`` (weights (H, N), their
    sums ``n`` (H,)): the channels' centred products summed -> (H,) in [-1, 1]."""
    ma = np.einsum("hn,hnc->hc", w, a) / n[:, None]
    mb = np.einsum("hn,hnc->hc", w, b) / n[:, None]
    da, db = a - ma[:, None, :], b - mb[:, None, :]
    num = np.einsum("hn,hnc,hnc->h", w, da, db)
    den = np.sqrt(np.einsum("hn,hnc,hnc->h", w, da, da) * np.einsum("hn,hnc,hnc->h", w, db, db))
    return num / (den + 1e-12)


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
            the best is ICP'd when it leads the second by this much).
        extra: optional (E, 4, 4) further poses (other basins of the colour search, the global
            method's); their turns are scored too.
        icp: ``icp(X_CO) -> X_CO`` refinement (None: no ICP). obj_id: for the textureless log line.
    Returns:
        :class:`Verified`.
    """
    bases = [np.asarray(X_CO, dtype=np.float64)]
    if extra is not None:
        bases += [np.asarray(e, dtype=np.float64) for e in extra]
    T = turns(surface, cfg.verify_turns) if cfg.verify_turns > 1 else np.eye(4)[None]
    Xs = np.einsum("bij,tjk->btik", np.stack(bases), T).reshape(-1, 4, 4)
    sc = score_hypotheses(Xs, surface, frame, cfg)
    if not sc.textured and surface.grey is None and obj_id not in _TEXTURELESS_LOGGED:
        _TEXTURELESS_LOGGED.add(obj_id)
        log.warning("object %s: model without colours, hypotheses verified on depth and mask alone", obj_id)
    order = np.argsort(-sc.score, kind="stable")
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
    return Verified(best_X, best_s, best_i, len(Xs), n_icp, sc.textured)
