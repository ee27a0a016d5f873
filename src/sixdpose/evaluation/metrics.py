"""Pose error metrics (bop_toolkit style pure functions), paper section V-A, eq. (4).

All functions take rotations as (3, 3) arrays and translations as (3,) arrays (or (3, 1)); ``pts`` are
the (N, 3) model points in the object frame. Lengths are returned in the unit of ``t`` and ``pts``
(metres in this package).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..constants import ADD_THRESHOLD


def transform_pts(pts: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Apply ``p -> R p + t`` to (N, 3) points; returns (N, 3)."""
    return np.asarray(pts, dtype=np.float64) @ np.asarray(R, dtype=np.float64).T + np.asarray(
        t, dtype=np.float64
    ).reshape(1, 3)


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


def is_correct(error: float, diameter: float, threshold: float = ADD_THRESHOLD) -> bool:
    """The paper's accuracy criterion: ``error < threshold * diameter`` (10 % of the diameter)."""
    return bool(error < threshold * diameter)


def rotation_error(R_est: np.ndarray, R_gt: np.ndarray) -> float:
    """Angle of ``R_est R_gt^T`` in degrees, in [0, 180]."""
    c = (np.trace(np.asarray(R_est) @ np.asarray(R_gt).T) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def translation_error(t_est: np.ndarray, t_gt: np.ndarray) -> float:
    """Euclidean distance between the translations (unit of the inputs)."""
    return float(
        np.linalg.norm(np.asarray(t_est, dtype=np.float64).reshape(3) - np.asarray(t_gt, dtype=np.float64).reshape(3))
    )


# --- BOP 2019 metrics ---
# Pose-error functions and average recall of the BOP challenge 2019/2020 (Hodaň et al. 2018, "BOP:
# Benchmark for 6D object pose estimation", ECCV; Hodaň et al. 2020, "BOP challenge 2020 on 6D object
# localization", ECCVW), following the reference implementation bop_toolkit (``misc``, ``pose_error``,
# ``visibility``, ``scripts/eval_bop19_pose.py``), and the ADD(-S) AUC of the YCB-Video protocol (Xiang
# et al. 2018, "PoseCNN"). Units: metres in memory (BOP files are millimetres: ``symmetry_transformations``
# converts its model_info entry, every other function takes metres), pixels for MSPD.

import math  # noqa: E402
from collections.abc import Mapping, Sequence  # noqa: E402
from numbers import Real  # noqa: E402

#: VSD misalignment tolerance ``delta`` of the visibility test, metres (BOP 2019: 15 mm for every
#: dataset of the core except ITODD, 5 mm).
BOP19_VSD_DELTA = 0.015
#: VSD misalignment tolerances ``tau``, fractions of the object diameter (0.05, 0.10, ..., 0.50).
BOP19_VSD_TAUS = tuple(np.arange(0.05, 0.51, 0.05).tolist())
#: VSD correctness thresholds ``theta`` (error < theta), dimensionless.
BOP19_VSD_THRESHOLDS = tuple(np.arange(0.05, 0.51, 0.05).tolist())
#: MSSD correctness thresholds ``theta``: correct if error / diameter < theta.
BOP19_MSSD_THRESHOLDS = tuple(np.arange(0.05, 0.51, 0.05).tolist())
#: MSPD correctness thresholds ``theta`` in pixels of a 640 px wide image: correct if
#: error * 640 / image_width < theta (i.e. error < theta * image_width / 640).
BOP19_MSPD_THRESHOLDS = tuple(float(x) for x in np.arange(5, 51, 5))
#: Reference image width of the MSPD thresholds, pixels.
BOP19_MSPD_REF_WIDTH = 640.0
#: Default discretisation of continuous symmetries (fraction of the diameter travelled per step).
BOP19_MAX_SYM_DISC_STEP = 0.01
#: Upper bound of the ADD(-S) AUC thresholds of the YCB-Video protocol, metres.
ADDS_AUC_MAX_THRESHOLD = 0.10


def _numbers(value, n: int, field: str) -> np.ndarray:
    """``value`` as a float64 (n,) array of finite numbers, else ValueError naming ``field``."""
    if isinstance(value, (str, bytes)) or not isinstance(value, (Sequence, np.ndarray)):
        raise ValueError(f"{field}: expected a list of {n} numbers, got {type(value).__name__}")
    items = list(np.asarray(value, dtype=object).reshape(-1)) if isinstance(value, np.ndarray) else list(value)
    if len(items) != n:
        raise ValueError(f"{field}: expected {n} numbers, got {len(items)}")
    for x in items:
        if isinstance(x, bool) or not isinstance(x, (Real, np.integer, np.floating)):
            raise ValueError(f"{field}: non-numeric value {x!r}")
    arr = np.asarray(items, dtype=np.float64)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{field}: non-finite value")
    return arr


def _axis_rotation(angle: float, axis: np.ndarray) -> np.ndarray:
    """(3, 3) rotation by ``angle`` (rad, right-handed) about the unit vector ``axis`` (Rodrigues)."""
    a = axis / np.linalg.norm(axis)
    c, s = math.cos(angle), math.sin(angle)
    kx = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    return c * np.eye(3) + s * kx + (1.0 - c) * np.outer(a, a)


def symmetry_transformations(
    model_info: dict, max_sym_disc_step: float = BOP19_MAX_SYM_DISC_STEP
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Symmetry transformations of an object model, as bop_toolkit ``misc.get_symmetry_transformations``.

    The set (Hodaň et al. 2020, sec. 2.2) is the identity, every ``symmetries_discrete`` entry and
    every ``symmetries_continuous`` entry discretised into ``n = ceil(pi / max_sym_disc_step)``
    rotations by ``i * 2 pi / n`` (i = 0 .. n-1) about ``axis`` through ``offset`` (so that the vertex
    farthest from the axis moves at most ``max_sym_disc_step * diameter`` per step), each continuous
    rotation combined with every discrete one (including the identity): ``R = R_c R_d``,
    ``t = R_c t_d + t_c``. Count: ``1 + len(discrete)`` without continuous symmetries, else
    ``(1 + len(discrete)) * n * len(continuous)``.

    Args:
        model_info: one entry of a BOP ``models_info.json`` (millimetres): optional
            ``symmetries_discrete`` (list of row-major 4x4 matrices as 16 numbers, translation in
            mm) and ``symmetries_continuous`` (list of ``{"axis": [3], "offset": [3] mm}``).
        max_sym_disc_step: maximum fraction of the diameter travelled by the farthest vertex
            between consecutive discretised rotations (BOP 2019: 0.01 -> 315 steps).
    Returns:
        List of ``(R (3, 3) float64, t (3,) float64 metres)``: ``x -> R x + t`` maps the model
        onto itself (in the object frame).
    Raises:
        ValueError: a malformed entry (wrong length, non-numeric, zero axis, missing key), naming the
            field, e.g. ``symmetries_continuous[0].axis``.
    """
    if not isinstance(model_info, Mapping):
        raise ValueError(f"model_info: expected a mapping, got {type(model_info).__name__}")
    if not (isinstance(max_sym_disc_step, Real) and math.isfinite(max_sym_disc_step) and max_sym_disc_step > 0):
        raise ValueError(f"max_sym_disc_step must be a positive number, got {max_sym_disc_step!r}")
    disc = [(np.eye(3), np.zeros(3))]
    entries = model_info.get("symmetries_discrete") or []
    if not isinstance(entries, (Sequence, np.ndarray)) or isinstance(entries, (str, bytes)):
        raise ValueError("symmetries_discrete: expected a list of 4x4 matrices")
    for i, sym in enumerate(entries):
        m = _numbers(sym, 16, f"symmetries_discrete[{i}]").reshape(4, 4)
        disc.append((m[:3, :3].copy(), m[:3, 3] / 1000.0))
    cont = []
    entries = model_info.get("symmetries_continuous") or []
    if not isinstance(entries, (Sequence, np.ndarray)) or isinstance(entries, (str, bytes)):
        raise ValueError("symmetries_continuous: expected a list of {axis, offset}")
    for i, sym in enumerate(entries):
        field = f"symmetries_continuous[{i}]"
        if not isinstance(sym, Mapping):
            raise ValueError(f"{field}: expected a mapping with 'axis' and 'offset'")
        for key in ("axis", "offset"):
            if key not in sym:
                raise ValueError(f"{field}.{key}: missing")
        axis = _numbers(sym["axis"], 3, f"{field}.axis")
        if np.linalg.norm(axis) < 1e-12:
            raise ValueError(f"{field}.axis: zero vector")
        offset = _numbers(sym["offset"], 3, f"{field}.offset") / 1000.0
        steps = int(np.ceil(np.pi / max_sym_disc_step))
        step = 2.0 * np.pi / steps
        for k in range(steps):
            R = _axis_rotation(k * step, axis)
            cont.append((R, offset - R @ offset))
    if not cont:
        return disc
    return [(Rc @ Rd, Rc @ td + tc) for Rd, td in disc for Rc, tc in cont]


def _sym_arrays(syms) -> tuple[np.ndarray, np.ndarray]:
    """Symmetries (list of ``(R, t)`` or bop_toolkit ``{"R", "t"}`` dicts; None = identity only)
    -> ``Rs (S, 3, 3)``, ``ts (S, 3)``."""
    if syms is None:
        return np.eye(3)[None], np.zeros((1, 3))
    Rs, ts = [], []
    for s in syms:
        R, t = (s["R"], s["t"]) if isinstance(s, Mapping) else s
        Rs.append(np.asarray(R, dtype=np.float64).reshape(3, 3))
        ts.append(np.asarray(t, dtype=np.float64).reshape(3))
    if not Rs:
        raise ValueError("syms: at least one transformation (the identity) is required")
    return np.stack(Rs), np.stack(ts)


def _chunks(n_syms: int, n_pts: int, budget: int = 1 << 21):
    """Slices over the symmetries so that a chunk holds about ``budget`` (point, symmetry) pairs."""
    size = max(1, budget // max(n_pts, 1))
    return [slice(i, min(i + size, n_syms)) for i in range(0, n_syms, size)]


def mssd(R_est, t_est, R_gt, t_gt, pts, syms) -> float:
    """Maximum Symmetry-aware Surface Distance (MSSD; Hodaň et al. 2020, eq. 2; bop_toolkit
    ``pose_error.mssd``).

    ``min_{S in syms} max_{x in pts} |(R_est x + t_est) - (R_gt (R_S x + t_S) + t_gt)|``.

    Args:
        R_est, t_est: estimated pose, (3, 3) and (3,) or (3, 1) metres.
        R_gt, t_gt: ground-truth pose, same shapes.
        pts: (N, 3) model points (object frame, metres), e.g. the mesh vertices.
        syms: symmetry transformations from :func:`symmetry_transformations` (list of ``(R, t)``
            with t in metres; bop_toolkit-style ``{"R", "t"}`` dicts also accepted); ``None`` = the
            identity only.
    Returns:
        The error in metres (unit of ``t`` and ``pts``).
    """
    pts = np.asarray(pts, dtype=np.float64).reshape(-1, 3)
    R_gt = np.asarray(R_gt, dtype=np.float64).reshape(3, 3)
    t_gt = np.asarray(t_gt, dtype=np.float64).reshape(3)
    est = transform_pts(pts, R_est, t_est)
    Rs, ts = _sym_arrays(syms)
    M = R_gt @ Rs  # (S, 3, 3): R_gt R_S
    c = ts @ R_gt.T + t_gt  # (S, 3): R_gt t_S + t_gt
    best = np.inf
    for sl in _chunks(len(Rs), len(pts)):
        gt = (pts @ M[sl].transpose(0, 2, 1)) + c[sl, None, :]
        e = np.sqrt(((gt - est[None]) ** 2).sum(axis=2).max(axis=1))
        best = min(best, float(e.min()))
    return best


def _project(X: np.ndarray, K: np.ndarray) -> np.ndarray:
    """(..., 3) camera-frame points -> (..., 2) pixel coordinates ``(K X)[:2] / (K X)[2]``."""
    p = X @ K.T
    return p[..., :2] / p[..., 2:3]


def mspd(R_est, t_est, R_gt, t_gt, K, pts, syms) -> float:
    """Maximum Symmetry-aware Projection Distance (MSPD; Hodaň et al. 2020, eq. 3; bop_toolkit
    ``pose_error.mspd``).

    ``min_{S in syms} max_{x in pts} |proj(K, R_est x + t_est) - proj(K, R_gt (R_S x + t_S) + t_gt)|``.

    Args:
        R_est, t_est, R_gt, t_gt: poses as in :func:`mssd` (metres).
        K: (3, 3) camera intrinsics (pixels).
        pts: (N, 3) model points, metres.
        syms: as in :func:`mssd`.
    Returns:
        The error in pixels (not normalised by the image width; :func:`ar_mspd` does that).
    """
    K = np.asarray(K, dtype=np.float64).reshape(3, 3)
    pts = np.asarray(pts, dtype=np.float64).reshape(-1, 3)
    R_gt = np.asarray(R_gt, dtype=np.float64).reshape(3, 3)
    t_gt = np.asarray(t_gt, dtype=np.float64).reshape(3)
    est = _project(transform_pts(pts, R_est, t_est), K)
    Rs, ts = _sym_arrays(syms)
    M = R_gt @ Rs
    c = ts @ R_gt.T + t_gt
    best = np.inf
    for sl in _chunks(len(Rs), len(pts)):
        gt = _project((pts @ M[sl].transpose(0, 2, 1)) + c[sl, None, :], K)
        e = np.sqrt(((gt - est[None]) ** 2).sum(axis=2).max(axis=1))
        best = min(best, float(e.min()))
    return best


def render_depth(vertices, faces, R, t, K, width: int, height: int) -> np.ndarray:
    """Depth image of a triangle mesh at pose ``(R, t)`` by ray casting (Open3D
    ``RaycastingScene``, CPU, no OpenGL).

    Pixel-centre convention: pixel ``(u, v)`` (column, row) has its centre at integer coordinates
    and is sampled by the ray through ``K^-1 [u, v, 1]``. The value is the depth along the optical
    axis (camera z), not the ray length. Both faces of each triangle are hit.

    Args:
        vertices: (V, 3) mesh vertices in the object frame, metres.
        faces: (F, 3) integer triangle indices.
        R, t: pose ``X_CO`` (``p_C = R p_O + t``): (3, 3) and (3,) metres.
        K: (3, 3) camera intrinsics.
        width, height: image size in pixels.
    Returns:
        (height, width) float32 depth in metres, 0 where no ray hits the mesh.
    """
    import open3d as o3d

    width, height = int(width), int(height)
    K = np.asarray(K, dtype=np.float64).reshape(3, 3)
    faces = np.asarray(faces).reshape(-1, 3)
    depth = np.zeros((height, width), np.float32)
    if len(faces) == 0 or width <= 0 or height <= 0:
        return depth
    vc = transform_pts(np.asarray(vertices, dtype=np.float64).reshape(-1, 3), R, t)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(np.ascontiguousarray(vc, dtype=np.float32)),
        o3d.core.Tensor(np.ascontiguousarray(faces, dtype=np.uint32)),
    )
    us, vs = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    dirs = np.stack([us, vs, np.ones_like(us)], axis=-1) @ np.linalg.inv(K).T
    dirs /= dirs[..., 2:3]  # unit z component: the hit distance is the depth
    rays = np.concatenate([np.zeros_like(dirs), dirs], axis=-1).astype(np.float32)
    t_hit = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()
    hit = np.isfinite(t_hit) & (t_hit > 0)
    depth[hit] = t_hit[hit]
    return depth


def depth_to_distance(depth, K) -> np.ndarray:
    """Distance image from a depth image, as bop_toolkit ``misc.depth_im_to_dist_im_fast``.

    Args:
        depth: (H, W) depth along the optical axis (metres), 0 = no measurement.
        K: (3, 3) camera intrinsics (pixel centres at integer coordinates).
    Returns:
        (H, W) float64 distance from the camera centre to the 3D point seen at each pixel
        (metres), 0 where ``depth`` is 0.
    """
    depth = np.asarray(depth)
    K = np.asarray(K, dtype=np.float64).reshape(3, 3)
    xs, ys = np.meshgrid(np.arange(depth.shape[1]), np.arange(depth.shape[0]))
    px = (xs - K[0, 2]) / K[0, 0]
    py = (ys - K[1, 2]) / K[1, 1]
    d = depth.astype(np.float64)
    return np.sqrt((px * d) ** 2 + (py * d) ** 2 + d**2)


def _visib_mask(d_test: np.ndarray, d_model: np.ndarray, delta: float) -> np.ndarray:
    """bop_toolkit ``visibility._estimate_visib_mask`` in ``bop19`` mode: the model surface is visible
    where it is rendered and not more than ``delta`` behind the test surface, or where the test
    depth is missing."""
    diff = d_model.astype(np.float32) - d_test.astype(np.float32)
    return ((diff <= delta) | (d_test == 0)) & (d_model > 0)


def vsd(
    R_est,
    t_est,
    R_gt,
    t_gt,
    depth_test,
    K,
    delta,
    taus,
    normalized_by_diameter,
    diameter,
    mesh_vertices,
    mesh_faces,
    cost_type="step",
) -> list[float]:
    """Visible Surface Discrepancy (VSD; Hodaň et al. 2018, sec. 2.2 and the BOP 2019 variant of
    Hodaň et al. 2020, eq. 1), as bop_toolkit ``pose_error.vsd``.

    The model is rendered (:func:`render_depth`) at both poses; depth images become distance images
    (:func:`depth_to_distance`); visibility masks are estimated with tolerance ``delta`` as
    bop_toolkit ``visibility.estimate_visib_mask_gt/est`` (``bop19`` mode: pixels without a test
    depth count as visible). With ``V = V_gt | V_est`` and ``I = V_gt & V_est``::

        e(tau) = (sum_{p in I} c(p, tau) + |V| - |I|) / |V|,   e = 1 if V is empty

    with ``c = [|D_gt - D_est| >= tau]`` (``"step"``) or ``min(1, |D_gt - D_est| / tau)``
    (``"tlinear"``), distances divided by ``diameter`` if ``normalized_by_diameter``.

    Args:
        R_est, t_est, R_gt, t_gt: poses, (3, 3) and (3,) metres.
        depth_test: (H, W) test depth image along the optical axis, metres, 0 (or NaN) = missing.
        K: (3, 3) camera intrinsics.
        delta: visibility tolerance, metres (BOP 2019: :data:`BOP19_VSD_DELTA` = 0.015).
        taus: misalignment tolerances (fractions of the diameter if normalised, else metres;
            BOP 2019: :data:`BOP19_VSD_TAUS`).
        normalized_by_diameter: divide the pixel distances by ``diameter``.
        diameter: object diameter, metres.
        mesh_vertices: (V, 3) model vertices (object frame, metres); mesh_faces: (F, 3) triangles.
        cost_type: ``"step"`` (BOP) or ``"tlinear"``.
    Returns:
        One error in [0, 1] per tau.
    Raises:
        ValueError: unknown ``cost_type`` or a depth image that is not 2-D.
    """
    if cost_type not in ("step", "tlinear"):
        raise ValueError(f"cost_type must be 'step' or 'tlinear', got {cost_type!r}")
    depth_test = np.nan_to_num(np.asarray(depth_test, dtype=np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    if depth_test.ndim != 2:
        raise ValueError(f"depth_test must be (H, W), got shape {depth_test.shape}")
    h, w = depth_test.shape
    depth_est = render_depth(mesh_vertices, mesh_faces, R_est, t_est, K, w, h)
    depth_gt = render_depth(mesh_vertices, mesh_faces, R_gt, t_gt, K, w, h)
    dist_test = depth_to_distance(depth_test, K)
    dist_gt = depth_to_distance(depth_gt, K)
    dist_est = depth_to_distance(depth_est, K)
    visib_gt = _visib_mask(dist_test, dist_gt, delta)
    visib_est = _visib_mask(dist_test, dist_est, delta) | (visib_gt & (dist_est > 0))
    inter = visib_gt & visib_est
    union_count = int((visib_gt | visib_est).sum())
    if union_count == 0:
        return [1.0] * len(taus)
    comp_count = union_count - int(inter.sum())
    dists = np.abs(dist_gt[inter] - dist_est[inter])
    if normalized_by_diameter:
        dists = dists / float(diameter)
    errors = []
    for tau in taus:
        costs = dists >= tau if cost_type == "step" else np.minimum(dists / tau, 1.0)
        errors.append(float((np.sum(costs) + comp_count) / float(union_count)))
    return errors


def _errors_1d(errors, name: str = "errors") -> np.ndarray:
    """Per-instance errors -> (M,) float64; ``None`` / NaN (missing estimate) -> +inf."""
    if isinstance(errors, np.ndarray) and errors.dtype != object:
        arr = errors.astype(np.float64)
    else:
        arr = np.array([np.inf if e is None else e for e in errors], dtype=np.float64)
    if arr.ndim != 1:
        raise ValueError(f"{name}: expected one error per instance (M,), got shape {arr.shape}")
    return np.where(np.isnan(arr), np.inf, arr)


def _errors_and_scale(errors, scale, name: str) -> tuple[np.ndarray, np.ndarray]:
    """``(e, s)``: :func:`_errors_1d` of ``errors`` (M,) and ``scale`` (scalar or (M,)) broadcast to (M,)
    float64; ``ValueError`` naming ``name`` unless every scale is positive."""
    e = _errors_1d(errors)
    s = np.broadcast_to(np.asarray(scale, dtype=np.float64), e.shape)
    if np.any(~(s > 0)):
        raise ValueError(f"{name} must be positive")
    return e, s


def accuracy_curve(errors, thresholds) -> np.ndarray:
    """Fraction of instances whose error is strictly below each threshold (BOP and paper
    convention ``error < threshold``).

    Args:
        errors: (M,) per-instance errors (any unit); ``None`` / NaN / inf = missing estimate.
        thresholds: (T,) thresholds, same unit.
    Returns:
        (T,) float64 accuracies in [0, 1] (zeros if M = 0).
    """
    e = np.sort(_errors_1d(errors))
    th = np.asarray(thresholds, dtype=np.float64).reshape(-1)
    if len(e) == 0:
        return np.zeros(len(th))
    return np.searchsorted(e, th, side="left") / float(len(e))


def ar_vsd(errors, thresholds=BOP19_VSD_THRESHOLDS) -> float:
    """Average recall of VSD (BOP 2019, AR_VSD; Hodaň et al. 2020, sec. 2.3).

    Recall over all instances, averaged over the VSD tolerances ``tau`` (the columns of
    ``errors``) and the correctness thresholds ``theta`` (correct if ``e < theta``).

    Args:
        errors: (M, T) VSD errors of M ground-truth instances, one column per tau (as returned by
            :func:`vsd` with :data:`BOP19_VSD_TAUS`); a row of ``None`` / NaN / inf, or ``None``
            instead of a row, marks a missing estimate.
        thresholds: correctness thresholds (default :data:`BOP19_VSD_THRESHOLDS`).
    Returns:
        AR_VSD in [0, 1] (0 for M = 0).
    """
    rows = list(errors) if not isinstance(errors, np.ndarray) else errors
    if isinstance(rows, list):
        width = next((len(r) for r in rows if r is not None), 1)
        rows = [[np.inf] * width if r is None else [np.inf if x is None else x for x in r] for r in rows]
    e = np.asarray(rows, dtype=np.float64)
    if e.size == 0:
        return 0.0
    if e.ndim != 2:
        raise ValueError(f"errors: expected shape (M, n_taus), got {e.shape}")
    return float(accuracy_curve(e.reshape(-1), thresholds).mean())


def ar_mssd(errors, diameters, thresholds=BOP19_MSSD_THRESHOLDS) -> float:
    """Average recall of MSSD (BOP 2019, AR_MSSD): correct if ``error / diameter < theta``, recall over
    all instances averaged over the thresholds.

    Args:
        errors: (M,) MSSD errors, metres (``None`` / NaN / inf = missing estimate).
        diameters: (M,) object diameters of the instances, metres (or one scalar for all).
        thresholds: fractions of the diameter (default :data:`BOP19_MSSD_THRESHOLDS`).
    Returns:
        AR_MSSD in [0, 1] (0 for M = 0).
    """
    e, d = _errors_and_scale(errors, diameters, "diameters")
    return float(accuracy_curve(e / d, thresholds).mean()) if len(e) else 0.0


def ar_mspd(errors, image_width=BOP19_MSPD_REF_WIDTH, thresholds=BOP19_MSPD_THRESHOLDS) -> float:
    """Average recall of MSPD (BOP 2019, AR_MSPD): correct if ``error * 640 / image_width < theta``
    (i.e. ``error < theta * r`` with ``r = image_width / 640``, as bop_toolkit
    ``eval_calc_scores``), recall over all instances averaged over the thresholds.

    Args:
        errors: (M,) MSPD errors, pixels (``None`` / NaN / inf = missing estimate).
        image_width: width of the test images in pixels (scalar or (M,)).
        thresholds: pixels at a 640 px width (default :data:`BOP19_MSPD_THRESHOLDS`, 5..50).
    Returns:
        AR_MSPD in [0, 1] (0 for M = 0).
    """
    e, w = _errors_and_scale(errors, image_width, "image_width")
    return float(accuracy_curve(e * (BOP19_MSPD_REF_WIDTH / w), thresholds).mean()) if len(e) else 0.0


def bop_average_recall(
    vsd_errors, mssd_errors, mspd_errors, diameters, image_width=BOP19_MSPD_REF_WIDTH
) -> dict[str, float]:
    """BOP 2019 average recall ``AR = (AR_VSD + AR_MSSD + AR_MSPD) / 3`` over one set of ground-truth
    instances (Hodaň et al. 2020, sec. 2.3), with the standard thresholds (module constants
    ``BOP19_*``).

    One row per ground-truth instance (the error of the estimate matched to it; a missing estimate
    is ``None`` / NaN / inf). Recall is pooled over all instances (as bop_toolkit over a dataset),
    not averaged per object.

    Args:
        vsd_errors: (M, 10) VSD errors at :data:`BOP19_VSD_TAUS` (delta :data:`BOP19_VSD_DELTA`).
        mssd_errors: (M,) MSSD errors, metres.
        mspd_errors: (M,) MSPD errors, pixels.
        diameters: (M,) object diameters, metres (or a scalar).
        image_width: test image width in pixels (scalar or (M,)).
    Returns:
        ``{"ar": AR, "ar_vsd": ..., "ar_mssd": ..., "ar_mspd": ...}``, each in [0, 1].
    Raises:
        ValueError: the three error lists have different lengths.
    """
    m = {len(vsd_errors), len(mssd_errors), len(mspd_errors)}
    if len(m) != 1:
        raise ValueError(
            f"one error per instance expected: got {len(vsd_errors)} VSD, {len(mssd_errors)} MSSD "
            f"and {len(mspd_errors)} MSPD rows"
        )
    a_vsd = ar_vsd(vsd_errors)
    a_mssd = ar_mssd(mssd_errors, diameters)
    a_mspd = ar_mspd(mspd_errors, image_width)
    return {"ar": (a_vsd + a_mssd + a_mspd) / 3.0, "ar_vsd": a_vsd, "ar_mssd": a_mssd, "ar_mspd": a_mspd}


def adds_auc(errors_m, max_threshold: float = ADDS_AUC_MAX_THRESHOLD, steps: int | None = 1000) -> float:
    """Area under the accuracy-vs-threshold curve of ADD-S (or ADD) errors, in percent (YCB-Video
    protocol of PoseCNN, Xiang et al. 2018: thresholds from 0 to 10 cm).

    ``AUC = 100 / T * integral_0^T accuracy(x) dx`` with ``accuracy(x)`` the fraction of errors below
    ``x`` (:func:`accuracy_curve`). With ``steps`` the integral is the mean accuracy at the ``steps``
    midpoints ``(k + 1/2) T / steps`` (deviation from the exact value at most ``50 / steps``
    percent); with ``steps=None`` it is exact: ``100 * mean(max(0, 1 - e / T))``. (The YCB-Video
    toolbox's ``VOCap`` sums the same step function but credits each error's interval one step
    early, overestimating by ``100 * e_max / (n T)`` with ``e_max`` the largest error below ``T``.)

    Args:
        errors_m: (M,) per-instance ADD-S / ADD errors, metres; ``None`` / NaN / inf = missing.
        max_threshold: T, metres (0.10).
        steps: number of thresholds sampled, or None for the exact integral.
    Returns:
        AUC in percent, in [0, 100] (0 for M = 0).
    """
    e = _errors_1d(errors_m)
    T = float(max_threshold)
    if not T > 0:
        raise ValueError(f"max_threshold must be positive, got {max_threshold!r}")
    if len(e) == 0:
        return 0.0
    if steps is None:
        return float(100.0 * np.clip(1.0 - e / T, 0.0, 1.0).mean())
    steps = int(steps)
    if steps < 1:
        raise ValueError(f"steps must be >= 1 or None, got {steps}")
    th = (np.arange(steps) + 0.5) * (T / steps)
    return float(100.0 * accuracy_curve(e, th).mean())
