"""The dense head of the learned stage (the project's own method, beside the paper's network): per-point
object coordinates, their training targets under object symmetries, the loss, and the robust pose fit.

The network (:class:`~sixdpose.pose.model.PoseNet` with ``head="dense"``) predicts for every sampled
point ``x_i`` of the masked cloud (camera frame, metres) its coordinates ``y_i`` in the model frame
(metres) and a confidence ``c_i`` in (0, 1). The pose ``X_CO`` is then the rigid transform mapping the
``y_i`` onto the ``x_i``: weighted Kabsch inside RANSAC (:func:`ransac_kabsch`).

Targets (:func:`coordinate_targets`): ``y_i = R^T (x_i - t)`` under the ground-truth pose ``(R, t)``.
Symmetric objects (:class:`Symmetry`) have several equivalent poses ``X_CO S`` (``S`` maps the model
onto itself), hence several target sets:

* discrete symmetries (BOP ``symmetries_discrete``, the identity included): one candidate target set
  per symmetry; the loss takes the minimum over them (per instance);
* a continuous symmetry (BOP ``symmetries_continuous``: rotations about ``axis`` through ``offset``):
  the equivalent poses are canonicalised, i.e. the rotation about the axis is chosen so that the
  camera centre, seen in the object frame, lies in the half-plane of a fixed reference direction
  ``ref`` perpendicular to the axis. Every equivalent ground-truth pose gives the same targets, and
  they are a function of what the image shows, so the network can learn them.

Objects flagged symmetric without a BOP annotation (the synthetic layout only has a ``symmetric`` flag)
get their symmetries from the model's shape (:func:`discover_symmetries`): rotations about its principal
axes that map the model points onto themselves within 2 % of the diameter.

Shape flips (``PoseConfig.flips > 0``): an object flagged asymmetric can still have a symmetric shape
(a box turned by 180 degrees, a can upside down); its turns are told apart by texture alone, and a coordinate
regression asked for the one true set of coordinates under such a turn learns it slowly (the boxes of the
first dense recipe came out turned). :func:`shape_flips` finds those turns (the shape's discrete symmetries);
the coordinates are then regressed in the frame of one canonical turn, chosen by :func:`canonical_flip` from
the pose alone (so a function of what the image shows, learnable from geometry), and a classifier names the
turn (:func:`flip_loss`); :func:`unflip` maps the fitted canonical pose back.

Loss (DenseFusion, Wang et al. 2019): ``mean_i (d_i c_i - w log c_i)`` with ``d_i = ||y^_i - y_i||``
(metres) and ``w = 0.015`` (:func:`dense_loss`, ``mode="densefusion"``). Its gradient on a point's
coordinates is scaled by that point's confidence, which settles near ``w / d_i``: the points that are
hardest early on (the two sides of a flip that texture alone decides) get the least gradient and can stay
unlearnt. ``mode="decoupled"`` trains the coordinates on the plain mean distance and the confidences on
the DenseFusion term with the distances detached (the confidence still learns to predict the error).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

from ..geometry import hemisphere_axes
from ..registration import kabsch_batch
from .config import DENSE_LOSSES

#: Weight of the confidence regulariser of the loss (DenseFusion's ``w``).
CONF_WEIGHT = 0.015
#: Largest mean point distance (fraction of the diameter) of a rotation accepted as a shape symmetry.
SYMMETRY_TOL = 0.02
#: Angles (radians) tried about each principal axis by :func:`discover_symmetries`.
_DISCRETE_ANGLES = tuple(k * math.pi / 6 for k in range(1, 12))


@dataclass(frozen=True)
class Symmetry:
    """The symmetries of one object model (object frame, metres).

    Attributes:
        R: (S, 3, 3) and t: (S, 3): the discrete symmetries ``x -> R x + t``, the identity first.
        axis: (3,) unit axis of the continuous symmetry, or None. offset: (3,) a point on the axis.
        ref: (3,) unit reference direction perpendicular to ``axis`` (canonicalisation), or None.
    """

    R: np.ndarray
    t: np.ndarray
    axis: np.ndarray | None = None
    offset: np.ndarray | None = None
    ref: np.ndarray | None = None

    @classmethod
    def none(cls) -> Symmetry:
        """No symmetry (the identity alone)."""
        return cls(np.eye(3)[None], np.zeros((1, 3)))

    @classmethod
    def build(cls, discrete: list[tuple[np.ndarray, np.ndarray]], axis=None, offset=None) -> Symmetry:
        """From a list of discrete ``(R, t)`` (the identity is prepended unless first) and an optional axis."""
        mats = [(np.asarray(R, float), np.asarray(t, float)) for R, t in discrete]
        if not mats or not (np.allclose(mats[0][0], np.eye(3)) and np.allclose(mats[0][1], 0)):
            mats.insert(0, (np.eye(3), np.zeros(3)))
        ref = None
        if axis is not None:
            axis = np.asarray(axis, float) / np.linalg.norm(axis)
            e = np.eye(3)[int(np.argmin(np.abs(axis)))]
            ref = e - (e @ axis) * axis
            ref /= np.linalg.norm(ref)
            offset = np.zeros(3) if offset is None else np.asarray(offset, float)
        return cls(np.stack([m[0] for m in mats]), np.stack([m[1] for m in mats]), axis, offset, ref)

    @property
    def trivial(self) -> bool:
        """Whether the object has no symmetry at all."""
        return self.axis is None and len(self.R) == 1


def rotation_about(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation matrix (3, 3) by ``angle`` radians about the unit ``axis`` (3,) (right-hand rule)."""
    a = np.asarray(axis, float)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def discover_symmetries(points: np.ndarray, diameter: float, tol: float = SYMMETRY_TOL, max_points: int = 1500,
                        seed: int = 0, normals: np.ndarray | None = None) -> Symmetry:
    """Symmetries of a model found from its shape (for models flagged symmetric without annotations, and the
    shape flips of :func:`shape_flips`).

    Rotations by multiples of 30 degrees about each principal axis through the centroid are kept when the
    mean distance from the rotated points to the nearest model point is below ``tol * diameter`` (and
    below twice the points' own spacing otherwise: sampling noise); an axis about which all 11 of them
    pass is the continuous symmetry (the first such axis), the others are discrete ones.

    A shape whose principal moments are (nearly) equal (a cube) has no defined principal axes, so its
    symmetry axes need not be the ones ``eigh`` returns. When two moments are within
    :data:`DEGENERATE_MOMENTS` of each other and no continuous axis was found, the dominant directions of the
    surface ``normals`` (:func:`normal_frame`: a box's face normals) are tried as well, and the rotations
    found are closed under composition (each product checked against the shape), so a cube gets its 24
    turns, not the 3 about arbitrary axes that pass nothing. Products that do not close within
    :data:`MAX_SYMMETRIES` (the loose near-turns of a thin shape about its long axis) are not a group: the
    first search's rotations are kept then.
    A shape with distinct moments has only half turns about its principal axes, which the first search finds.

    Args:
        points: (M, 3) model points, metres. diameter: metres. tol: fraction of the diameter.
        max_points: subsample of the points used (deterministic, ``seed``).
        normals: (M, 3) unit normals of ``points`` (rows of zeros: unknown), or None (also taken when its
            shape is not the points').
    Returns:
        the :class:`Symmetry` (the identity alone when nothing passes).
    """
    from scipy.spatial import cKDTree

    P = np.asarray(points, float)
    Nm = None if normals is None else np.asarray(normals, float)
    if Nm is not None and Nm.shape != P.shape:  # not the points' normals: unknown
        Nm = None
    if len(P) > max_points:
        idx = np.random.default_rng(seed).choice(len(P), max_points, replace=False)
        P = P[idx]
        Nm = None if Nm is None else Nm[idx]
    tree = cKDTree(P)
    spacing = float(np.median(tree.query(P, k=2)[0][:, 1]))
    limit = max(tol * diameter, 2.0 * spacing)
    c = P.mean(axis=0)
    evals, vecs = np.linalg.eigh(np.cov((P - c).T))

    def fits(R: np.ndarray) -> bool:
        return float(tree.query((P - c) @ R.T + c)[0].mean()) <= limit

    axis: np.ndarray | None = None
    found: list[np.ndarray] = []
    for k in range(3):
        a = vecs[:, k]
        ok = [fits(rotation_about(a, ang)) for ang in _DISCRETE_ANGLES]
        if all(ok) and axis is None:
            axis = a
            continue
        found.extend(rotation_about(a, ang) for ang, good in zip(_DISCRETE_ANGLES, ok, strict=True) if good)
    gaps = np.diff(np.maximum(evals, 0.0)) / max(float(evals.max()), 1e-12)
    if axis is None and Nm is not None and float(gaps.min()) < DEGENERATE_MOMENTS:
        extra = [rotation_about(a, ang) for a in normal_frame(Nm) for ang in _DISCRETE_ANGLES]
        group = _group_closure([np.eye(3)] + found + [R for R in extra if fits(R)], fits)
        if len(group) < MAX_SYMMETRIES:  # a finite group; products that never close are the tolerance's
            found = group[1:]  # near-turns of a thin shape (a hammer's), not symmetries: keep the first search's
    return Symmetry.build([(R, c - R @ c) for R in found], axis, c if axis is not None else None)


#: Largest gap between two principal moments (variances, as a fraction of the largest) for which the principal
#: axes count as undefined in :func:`discover_symmetries` (a cube's, a sphere's).
DEGENERATE_MOMENTS = 0.1
#: Most rotations :func:`discover_symmetries` keeps when closing a group (a cube has 24, an icosahedron 60).
MAX_SYMMETRIES = 64


def normal_frame(normals: np.ndarray, cone_deg: float = 15.0, min_share: float = 0.1) -> list[np.ndarray]:
    """Candidate symmetry axes of a shape from its surface normals: the dominant normal direction (as an
    axis: a normal and its opposite count together) and, when there is one, the next dominant direction
    perpendicular to it (within 5 degrees), made exactly perpendicular, and their cross product. For a box
    these are its three face normals, an orthonormal frame, so turns about them compose exactly.

    Args:
        normals: (M, 3) unit normals (rows of length below 0.5 are ignored).
        cone_deg: half-angle (degrees) of the cone that counts the normals around a direction.
        min_share: the least share of the normals an axis's double cone must hold.
    Returns:
        a list of 0, 1 or 3 unit axes (3,).
    """
    N = np.asarray(normals, float)
    n = np.linalg.norm(N, axis=1)
    N = N[n > 0.5] / n[n > 0.5, None]
    if len(N) < 20:
        return []
    dirs = hemisphere_axes(400)  # a normal and its opposite count together: a hemisphere of directions
    cone = math.cos(math.radians(cone_deg))
    counts = (np.abs(N @ dirs.T) > cone).sum(axis=0).astype(float)

    def refined(a: np.ndarray) -> np.ndarray:
        for _ in range(3):  # the mean of the normals in the double cone, their signs aligned with a
            d = N @ a
            sel = np.abs(d) > cone
            if not sel.any():
                break
            a = (N[sel] * np.sign(d[sel])[:, None]).sum(axis=0)
            a = a / np.linalg.norm(a)
        return a

    if counts.max() < min_share * len(N):
        return []
    a1 = refined(dirs[int(np.argmax(counts))])
    perp = np.abs(dirs @ a1) < math.sin(math.radians(5.0))
    if not perp.any() or counts[perp].max() < min_share * len(N):
        return [a1]
    a2 = refined(dirs[perp][int(np.argmax(counts[perp]))])
    a2 = a2 - (a2 @ a1) * a1
    if np.linalg.norm(a2) < 1e-6:
        return [a1]
    a2 /= np.linalg.norm(a2)
    if abs(float(refined(a2) @ a1)) > math.sin(math.radians(5.0)):  # not a perpendicular face after all
        return [a1]
    return [a1, a2, np.cross(a1, a2)]


def _group_closure(rots: list[np.ndarray], fits, tol: float = 1e-6) -> list[np.ndarray]:
    """The rotations ``rots`` (the identity first) and their products that ``fits`` (a shape test) accepts,
    until no new one passes or :data:`MAX_SYMMETRIES` are held; duplicates (within ``tol``) dropped."""
    out: list[np.ndarray] = []
    for R in rots:
        if all(np.abs(R - Q).max() > tol for Q in out):
            out.append(R)
    grew = True
    while grew and len(out) < MAX_SYMMETRIES:
        grew = False
        for A in list(out):
            for B in list(out):
                C = A @ B
                if len(out) < MAX_SYMMETRIES and all(np.abs(C - Q).max() > tol for Q in out) and fits(C):
                    out.append(C)
                    grew = True
    return out


def model_symmetry(model) -> Symmetry:
    """The :class:`Symmetry` of an :class:`~sixdpose.datasets.base.ObjectModel`: its BOP annotation
    (``symmetries_discrete``; the first ``symmetries_continuous`` entry) when it has one, else the
    shape's symmetries when it is flagged ``symmetric``, else none."""
    if model.symmetries:
        from ..evaluation.metrics import symmetry_transformations

        disc = symmetry_transformations({"symmetries_discrete": model.symmetries.get("symmetries_discrete") or []})
        cont = model.symmetries.get("symmetries_continuous") or []
        if cont:
            return Symmetry.build(disc, cont[0]["axis"], np.asarray(cont[0].get("offset", [0, 0, 0]), float) / 1000.0)
        return Symmetry.build(disc)
    if model.symmetric:
        return discover_symmetries(model.points, float(model.diameter), normals=model.normals)
    return Symmetry.none()


def _closed(R: np.ndarray, tol: float = 1e-3) -> bool:
    """Whether the rotations R (K, 3, 3) are closed under composition (a group)."""
    return all(np.abs(R - a @ b).reshape(len(R), -1).max(axis=1).min() < tol for a in R for b in R)


def shape_flips(model, max_flips: int) -> Symmetry:
    """The shape flips of an object model flagged asymmetric: its shape's discrete symmetries
    (:func:`discover_symmetries`), the identity first, at most ``max_flips`` of them and closed under
    composition (the longest closed prefix). A shape with a continuous axis (a can) keeps the identity and one
    half turn (upside down), and carries the axis (``axis``, ``offset``) for :func:`canonical_flip`; the turn
    about the axis is left to the coordinate regression. An object with symmetries of its own (BOP annotation
    or ``symmetric`` flag) has none: its targets already cover them.

    Args:
        model: :class:`~sixdpose.datasets.base.ObjectModel` (points metres, diameter metres).
        max_flips: the most turns kept (>= 1).
    Returns:
        a :class:`Symmetry` whose discrete elements are the flips (the identity alone when there are none).
    """
    if max_flips < 1:
        raise ValueError(f"max_flips must be >= 1, got {max_flips}")
    if model.symmetric or model.symmetries:
        return Symmetry.none()
    g = discover_symmetries(model.points, float(model.diameter), normals=model.normals)
    k = min(len(g.R), max_flips, 2 if g.axis is not None else len(g.R))
    while k > 1 and not _closed(g.R[:k]):
        k -= 1
    return Symmetry(g.R[:k], g.t[:k], g.axis if k > 1 else None, g.offset if k > 1 else None)


#: Reference direction (camera frame) of :func:`canonical_flip` for shapes with a continuous axis.
_AXIS_REF = np.array([0.3, -0.8, -0.5]) / np.linalg.norm([0.3, -0.8, -0.5])


def canonical_flip(R: np.ndarray, flips: Symmetry, frame: np.ndarray | None = None) -> int:
    """Index of the canonical turn of a pose, the same for every equivalent pose of the shape (up to ties), so
    a function of what the image shows: the flip ``S_d`` whose pose ``X S_d`` has the rotation closest to the
    camera's axes (largest ``trace(R R_d)``); for a shape with a continuous axis ``a``, the one whose axis
    ``R R_d a`` points most along a fixed camera-frame direction (``_AXIS_REF``).

    Args:
        R: (3, 3) rotation of ``X_CO``. flips: the object's :func:`shape_flips`.
        frame: (3, 3) the frame the network sees the cloud in (its columns in the camera frame:
            :func:`~sixdpose.pose.model.pca_frame` with ``input_frame = "pca"``); its axes then take the
            camera's place. None: the camera frame.
    Returns:
        d in ``range(len(flips.R))``.
    """
    R = np.asarray(R, float)
    if frame is not None:
        R = np.asarray(frame, float).T @ R
    if flips.axis is not None:
        return int(np.argmax((R @ flips.R @ flips.axis) @ _AXIS_REF))
    return int(np.argmax(np.einsum("ij,dji->d", R, flips.R)))


#: Reference direction (object frame) of :func:`view_flip`: a generic one, so that ties between turns are rare.
_VIEW_REF = np.array([0.36, 0.48, 0.80]) / np.linalg.norm([0.36, 0.48, 0.80])


def flip_centre(flips: Symmetry) -> np.ndarray:
    """The point (object frame, metres) that every turn of ``flips`` leaves in place (``R_d c + t_d = c``; the
    least-squares one, the shortest where the turns leave a line fixed). Returns (3,)."""
    if len(flips.R) < 2:
        return np.zeros(3) if flips.offset is None else np.asarray(flips.offset, float)
    A = np.concatenate([np.eye(3) - Rd for Rd in flips.R[1:]])
    return np.linalg.lstsq(A, np.concatenate(list(flips.t[1:])), rcond=None)[0]


def view_flip(R: np.ndarray, t: np.ndarray, flips: Symmetry) -> int:
    """Index of the canonical turn of a pose chosen by where the camera is, seen from the object: the flip
    ``S_d`` whose pose ``X S_d`` puts the camera centre, in its object frame and relative to the turns' fixed
    point (:func:`flip_centre`), furthest along a fixed object-frame direction (``_VIEW_REF``; for a shape with a
    continuous axis, along the axis). Every equivalent pose names the same canonical pose (up to ties), as with
    :func:`canonical_flip`, and which sides of the object face the camera is what its visible surface shows,
    whatever frame the network sees the cloud in (the way :func:`coordinate_targets` canonicalises a continuous
    symmetry). A cube's turn then follows from its seen faces, not from principal axes that it does not have.

    Args:
        R: (3, 3), t: (3,) metres, ``X_CO``. flips: the object's :func:`shape_flips`.
    Returns:
        d in ``range(len(flips.R))``.
    """
    R, t = np.asarray(R, float), np.asarray(t, float)
    cam = (-t) @ R  # the camera centre in the object frame of X
    c = flip_centre(flips)
    # the camera centre in the frame of X S_d, from the fixed point: R_d^T (cam - t_d) - c = R_d^T (cam - c)
    u = np.einsum("dji,j->di", flips.R, cam - c)
    ref = _VIEW_REF if flips.axis is None else np.asarray(flips.axis, float)
    return int(np.argmax(u @ ref))


def unflip(R: np.ndarray, t: np.ndarray, Rd: np.ndarray, td: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pose ``X`` from the pose of its turn ``X S_d`` (``S_d = (Rd, td)``, ``x -> Rd x + td``, metres):
    ``X = (X S_d) S_d^-1``. Returns ``(R (3, 3), t (3,))``."""
    R2 = np.asarray(R, float) @ np.asarray(Rd, float).T
    return R2, np.asarray(t, float) - R2 @ np.asarray(td, float)


def flip_loss(logits: torch.Tensor, labels: torch.Tensor) -> torch.Tensor:
    """Per-instance cross-entropy of the flip classifier: logits (N, F) (-inf past a class's count),
    labels (N,) long. Instances whose class has a single turn get 0. Returns (N,)."""
    several = torch.isfinite(logits).sum(dim=1) > 1
    ce = F.cross_entropy(logits.masked_fill(~torch.isfinite(logits), -1e4), labels, reduction="none")
    return torch.where(several, ce, torch.zeros_like(ce))


def coordinate_targets(cloud: np.ndarray, R: np.ndarray, t: np.ndarray, sym: Symmetry) -> np.ndarray:
    """Candidate object coordinates of the points of one instance under its equivalent ground-truth poses.

    For every discrete symmetry ``S_d = (R_d, t_d)`` the pose ``X_CO S_d`` is taken, canonicalised about
    the continuous axis if there is one (see the module docstring), and the points are expressed in
    its object frame.

    Args:
        cloud: (P, 3) camera-frame points, metres. R: (3, 3), t: (3,) ground-truth ``X_CO``.
        sym: the object's :class:`Symmetry`.
    Returns:
        (S, P, 3) float32 object coordinates, metres, one set per discrete symmetry (S = 1 without).
    """
    R, t = np.asarray(R, float), np.asarray(t, float)
    y = (np.asarray(cloud, float) - t) @ R  # R^T (x - t) for row vectors
    out = []
    for Rd, td in zip(sym.R, sym.t, strict=True):
        # X S_d: p_C = R (R_d p + t_d) + t, so the coordinates are S_d^-1 y = R_d^T (y - t_d)
        yd = (y - td) @ Rd
        if sym.axis is not None and sym.ref is not None:
            a, o = sym.axis, sym.offset
            cam = (-t) @ R  # the camera centre in the frame of X
            cam = (cam - td) @ Rd - o  # ... in the frame of X S_d, relative to the axis point
            w = cam - (cam @ a) * a
            phi = math.atan2(float(np.cross(sym.ref, w) @ a), float(sym.ref @ w)) if np.linalg.norm(w) > 1e-9 else 0.0
            yd = (yd - o) @ rotation_about(a, -phi).T + o
        out.append(yd)
    return np.stack(out).astype(np.float32)


def dense_loss(coords: torch.Tensor, conf_logit: torch.Tensor, targets: torch.Tensor,
               w: float = CONF_WEIGHT, mode: str = "densefusion") -> tuple[torch.Tensor, torch.Tensor]:
    """Per-instance dense loss, minimised over the candidate target sets.

    ``densefusion``: ``mean_i (d_i c_i - w log c_i)``; ``decoupled``: ``mean_i d_i + mean_i (sg(d_i) c_i -
    w log c_i)`` (``sg``: no gradient), so every point's coordinates get the full gradient.

    Args:
        coords: (N, P, 3) predicted object coordinates, metres. conf_logit: (N, P) confidence logits
            (``c = sigmoid``). targets: (N, S, P, 3) candidate targets (:func:`coordinate_targets`,
            padded by repeating a set). w: confidence weight. mode: one of :data:`DENSE_LOSSES`.
    Returns:
        ``(loss (N,), dist (N,))``: the loss and the mean point distance (metres) of the chosen set.
    """
    d = (coords[:, None] - targets).norm(dim=3)  # (N, S, P)
    best = d.mean(dim=2).argmin(dim=1)
    d = d[torch.arange(len(d), device=d.device), best]  # (N, P)
    c = torch.sigmoid(conf_logit)
    if mode == "decoupled":
        loss = d.mean(dim=1) + (d.detach() * c - w * F.logsigmoid(conf_logit)).mean(dim=1)
    elif mode == "densefusion":
        loss = (d * c - w * F.logsigmoid(conf_logit)).mean(dim=1)
    else:
        raise ValueError(f"dense loss mode must be one of {DENSE_LOSSES}, got {mode!r}")
    return loss, d.mean(dim=1)


def weighted_kabsch(src: np.ndarray, dst: np.ndarray,
                    weights: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Rigid transform minimising ``sum_k w_k |R src_k + t - dst_k|^2`` (weighted Kabsch / Umeyama, no scale).

    Args:
        src: (K, 3). dst: (K, 3). weights: (K,) >= 0, not all zero (None: equal).
    Returns:
        R (3, 3) proper rotation, t (3,).
    """
    src, dst = np.asarray(src, float), np.asarray(dst, float)
    w = np.ones(len(src)) if weights is None else np.asarray(weights, float)
    w = w / w.sum()
    cs, cd = w @ src, w @ dst
    H = ((src - cs) * w[:, None]).T @ (dst - cd)
    U, _, Vt = np.linalg.svd(H)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0])
    R = Vt.T @ D @ U.T
    return R, cd - R @ cs


def ransac_kabsch(src: np.ndarray, dst: np.ndarray, weights: np.ndarray | None = None, *, threshold: float = 0.015,
                  iterations: int = 128, rng: np.random.Generator | None = None,
                  refits: int = 2) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Robust rigid fit of correspondences ``src_k -> dst_k`` with outliers.

    ``iterations`` hypotheses from 3 correspondences each (drawn with probability proportional to
    ``weights``; batched Kabsch of the registration stage), scored by the summed weight of their inliers
    (``|R src + t - dst| < threshold``); the best is refitted ``refits`` times by :func:`weighted_kabsch`
    on its inliers.

    Args:
        src: (K, 3) e.g. predicted object coordinates, metres. dst: (K, 3) e.g. the camera-frame cloud.
        weights: (K,) > 0 confidences (None: equal). threshold: inlier distance, metres.
        iterations: hypotheses. rng: numpy generator (default seed 0). refits: refinement rounds.
    Returns:
        ``(R (3, 3), t (3,), inliers (K,) bool)`` with ``dst ~ R src + t``.
    Raises:
        ValueError: fewer than 3 correspondences.
    """
    src, dst = np.asarray(src, float), np.asarray(dst, float)
    K = len(src)
    if K < 3:
        raise ValueError(f"a rigid fit needs >= 3 correspondences, got {K}")
    rng = rng or np.random.default_rng(0)
    w = np.ones(K) if weights is None else np.clip(np.asarray(weights, float), 1e-12, None)
    p = w / w.sum()
    idx = rng.choice(K, size=(iterations, 3), p=p)  # a triplet with a repeated point scores low: no need to redraw
    Rs, ts = kabsch_batch(src[idx], dst[idx])
    # |R s + t - d|^2 = |s|^2 + |d|^2 + |t|^2 - 2 d.t + 2 s.(R^T t) - 2 d.(R s) (R keeps lengths): every
    # hypothesis against every correspondence in three small matrix products, (K, M), no (K, M, 3) array
    M = len(Rs)
    sq = ((src * src).sum(1) + (dst * dst).sum(1))[:, None] + (ts * ts).sum(1)[None]
    sq += 2.0 * (src @ np.einsum("mji,mj->im", Rs, ts) - dst @ ts.T)
    # (a contiguous right operand: OpenBLAS takes milliseconds on the transposed view of this shape)
    sq -= 2.0 * (dst[:, :, None] * src[:, None, :]).reshape(K, 9) @ np.ascontiguousarray(Rs.reshape(M, 9).T)
    inside = sq < threshold * threshold  # (K, M): |R src + t - dst| < threshold
    score = w @ inside
    best = int(np.argmax(score))
    R, t = Rs[best], ts[best]
    inl = inside[:, best]
    for _ in range(refits):
        if inl.sum() < 3:
            break
        R, t = weighted_kabsch(src[inl], dst[inl], w[inl])
        inl = np.linalg.norm(src @ R.T + t - dst, axis=1) < threshold
    return R, t, inl
