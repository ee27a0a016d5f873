"""The hybrid pose methods of section IV-B: RANSAC and FGR on FPFH features (Open3D), Super4PCS,
each optionally refined by ICP (point-to-point or point-to-plane, Open3D).

Every method has the same signature ``method(scene, ref, cfg) -> Registration``:

* ``scene``: a :class:`SceneCloud` (the masked camera-frame cloud, prepared by :func:`prepare_scene`),
* ``ref``: the object's :class:`~sixdpose.registration.geometry.Reference`,
* ``cfg``: a :class:`~sixdpose.registration.presets.RegistrationConfig`,

and returns the pose ``X_CO`` (4x4, metres) with its score and the seconds it took. Registration
runs scene -> model (every scene point has a counterpart on the full model; point-to-plane ICP uses the
model's exact normals) and the result is inverted. :func:`estimate_pose` runs the whole per-instance
pipeline (cloud preparation, method, ICP) and charges every step's time (normals, features,
downsampling, first-use model preparation) to the instance, except disk reads (paper section V-A).
``register`` and ``predict-pose`` then leave the first-use model preparation (the object's onboarding,
:class:`~sixdpose.registration.geometry.ReferenceCache`) out of the per-image time and record it apart.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np

from ..geometry import X_from
from ..registry import HYBRID_ALGORITHMS
from .geometry import Reference, ReferenceCache, compute_fpfh, estimate_normals, to_o3d
from .presets import RegistrationConfig

#: The global registration algorithms (:data:`sixdpose.registry.HYBRID_ALGORITHMS`).
METHODS = tuple(HYBRID_ALGORITHMS)


@dataclass
class SceneCloud:
    """A prepared masked scene cloud (camera frame, metres).

    Attributes:
        pcd: Open3D cloud with normals oriented toward the camera. voxel: the length unit (m) that
        scales feature radii and distances. fpfh: FPFH features or None. time: preparation seconds.
    """

    pcd: object
    voxel: float
    fpfh: object | None = None
    time: float = 0.0

    @property
    def points(self) -> np.ndarray:
        return np.asarray(self.pcd.points)

    @property
    def normals(self) -> np.ndarray:
        return np.asarray(self.pcd.normals)


@dataclass
class Registration:
    """Output of a method for one instance.

    Attributes:
        X_CO: (4, 4) pose of the object in the camera frame (metres). score: fitness in [0, 1]
        (inlier fraction of the scene cloud; LCP for Super4PCS). time: seconds, every step but disk
        reads. info: method-specific diagnostics.
    """

    X_CO: np.ndarray
    score: float
    time: float
    info: dict = field(default_factory=dict)


def voxel_sizes(cfg: RegistrationConfig, diameter: float) -> tuple[float | None, float, float]:
    """``(scene voxel or None, model voxel, feature unit)`` in metres for an object of ``diameter``."""
    scene_v = None if cfg.scene_voxel_rel is None else cfg.scene_voxel_rel * diameter
    model_v = cfg.model_voxel if cfg.model_voxel_rel is None else cfg.model_voxel_rel * diameter
    unit = scene_v if scene_v is not None else cfg.feature_voxel
    return scene_v, model_v, unit


def prepare_scene(points: np.ndarray, diameter: float, cfg: RegistrationConfig, features: bool) -> SceneCloud:
    """Gate, downsample, estimate normals (k=10 plane fit toward the camera) and optionally FPFH.

    Args:
        points: (N, 3) masked camera-frame points, metres. diameter: object diameter, metres.
        cfg: configuration. features: compute FPFH (RANSAC, FGR).
    Returns:
        :class:`SceneCloud` (its ``time`` covers this preparation).
    """
    t0 = time.perf_counter()
    pts = np.asarray(points, dtype=np.float64)
    if cfg.gate_rel is not None and len(pts):
        med = np.median(pts, axis=0)
        pts = pts[np.linalg.norm(pts - med, axis=1) <= cfg.gate_rel * diameter]
    scene_v, _, unit = voxel_sizes(cfg, diameter)
    pcd = to_o3d(pts)
    if scene_v is not None:
        pcd = pcd.voxel_down_sample(scene_v)
    estimate_normals(pcd, knn=cfg.normal_knn)
    feat = compute_fpfh(pcd, cfg.fpfh_radius_factor * unit, cfg.fpfh_max_nn) if features else None
    return SceneCloud(pcd, unit, feat, time.perf_counter() - t0)


def _invert(X_AB: np.ndarray) -> np.ndarray:
    """``X_BA`` from ``X_AB`` (rigid 4x4 inverse)."""
    return X_from(X_AB[:3, :3].T, -X_AB[:3, :3].T @ X_AB[:3, 3])


def register_ransac(scene: SceneCloud, ref: Reference, cfg: RegistrationConfig) -> Registration:
    """RANSAC on FPFH correspondences (Open3D ``registration_ransac_based_on_feature_matching``).

    Seeded with ``cfg.seed``; repeatable only when Open3D runs on one thread (the register runner
    sees to it). Returns the pose ``X_CO``; score = RANSAC fitness (inlier fraction of the scene cloud).
    """
    import open3d as o3d

    reg = o3d.pipelines.registration
    t0 = time.perf_counter()
    dist = cfg.ransac_distance_factor * scene.voxel
    o3d.utility.random.seed(cfg.seed)
    res = reg.registration_ransac_based_on_feature_matching(
        scene.pcd,
        ref.pcd,
        scene.fpfh,
        ref.fpfh,
        cfg.ransac_mutual_filter,
        dist,
        reg.TransformationEstimationPointToPoint(False),
        cfg.ransac_n,
        [
            reg.CorrespondenceCheckerBasedOnEdgeLength(cfg.ransac_edge_length),
            reg.CorrespondenceCheckerBasedOnDistance(dist),
        ],
        reg.RANSACConvergenceCriteria(cfg.ransac_max_iteration, cfg.ransac_confidence),
    )
    X_CO = _invert(np.asarray(res.transformation))  # Open3D returns X_OC (scene -> model)
    return Registration(X_CO, float(res.fitness), time.perf_counter() - t0, {"inlier_rmse": float(res.inlier_rmse)})


def register_fgr(scene: SceneCloud, ref: Reference, cfg: RegistrationConfig) -> Registration:
    """Fast Global Registration on FPFH features (Open3D ``registration_fgr_based_on_feature_matching``).

    Returns the pose ``X_CO``; score = fitness at the FGR distance (inlier fraction of the scene).
    """
    import open3d as o3d

    reg = o3d.pipelines.registration
    t0 = time.perf_counter()
    dist = cfg.fgr_distance_factor * scene.voxel
    o3d.utility.random.seed(cfg.seed)  # FGR draws random tuples from Open3D's global generator
    opt = reg.FastGlobalRegistrationOption(maximum_correspondence_distance=dist, iteration_number=cfg.fgr_iterations)
    res = reg.registration_fgr_based_on_feature_matching(scene.pcd, ref.pcd, scene.fpfh, ref.fpfh, opt)
    X_OC = np.asarray(res.transformation)  # scene (camera) -> model (object)
    ev = reg.evaluate_registration(scene.pcd, ref.pcd, max(dist, cfg.ransac_distance_factor * scene.voxel), X_OC)
    return Registration(_invert(X_OC), float(ev.fitness), time.perf_counter() - t0, {})


def register_super4pcs(scene: SceneCloud, ref: Reference, cfg: RegistrationConfig) -> Registration:
    """Super4PCS with normals (:func:`~sixdpose.registration.super4pcs.super4pcs`).

    The LCP is verified against a reference cloud 3x denser than ``ref`` when ``ref.extra`` has one
    (``"verify"``). Returns the pose ``X_CO``; score = LCP.
    """
    from .super4pcs import super4pcs

    t0 = time.perf_counter()
    delta = cfg.s4pcs_delta if cfg.s4pcs_delta_rel is None else cfg.s4pcs_delta_rel * ref.diameter
    ver = ref.extra.get("verify")
    res = super4pcs(scene.points, scene.normals, ref.points, ref.normals, cfg, delta=delta,
                    Q_verify=None if ver is None else ver[0], Qn_verify=None if ver is None else ver[1])
    info = {"n_bases": res.n_bases, "n_congruent": res.n_congruent, "n_verified": res.n_verified}
    # res.T maps scene onto model: X_OC
    return Registration(_invert(res.T), float(res.lcp), time.perf_counter() - t0, info)


def refine_icp(scene: SceneCloud, ref: Reference, X_CO: np.ndarray, cfg: RegistrationConfig) -> Registration:
    """ICP refinement (Open3D ``registration_icp``) of the pose ``X_CO`` (4x4).

    ``cfg.icp_kind``: ``"point_to_plane"`` (model normals) or ``"point_to_point"``; correspondence
    distance ``cfg.icp_distance_factor`` x the scene voxel. Returns the refined ``X_CO`` with the ICP
    fitness as score.
    """
    import open3d as o3d

    reg = o3d.pipelines.registration
    t0 = time.perf_counter()
    if cfg.icp_kind == "point_to_plane":
        est = reg.TransformationEstimationPointToPlane()
    elif cfg.icp_kind == "point_to_point":
        est = reg.TransformationEstimationPointToPoint(False)
    else:
        raise ValueError(f"icp_kind must be point_to_plane or point_to_point, got {cfg.icp_kind!r}")
    dist = cfg.icp_distance_factor * scene.voxel
    res = reg.registration_icp(
        scene.pcd, ref.pcd, dist, _invert(X_CO), est, reg.ICPConvergenceCriteria(max_iteration=cfg.icp_max_iteration)
    )
    return Registration(_invert(np.asarray(res.transformation)), float(res.fitness), time.perf_counter() - t0, {})


_FUNCS = {"ransac": register_ransac, "fgr": register_fgr, "super4pcs": register_super4pcs}


def get_reference(cache: ReferenceCache, obj_id: int, method: str, cfg: RegistrationConfig) -> tuple[Reference, float]:
    """The cached reference of ``obj_id`` for ``method`` (FPFH only for RANSAC/FGR; a 3x denser
    verification cloud for Super4PCS); returns ``(reference, seconds spent building it now)``."""
    model = cache.dataset.model(obj_id)
    scene_v, model_v, unit = voxel_sizes(cfg, model.diameter)
    feats = method in ("ransac", "fgr")
    ref, dt = cache.get(obj_id, model_v, cfg.fpfh_radius_factor * unit if feats else None)
    if method == "super4pcs" and "verify" not in ref.extra:
        t0 = time.perf_counter()
        dense, _ = cache.get(obj_id, model_v / 3.0, None)
        ref.extra["verify"] = (dense.points, dense.normals)
        dt += time.perf_counter() - t0
    return ref, dt


def refine_pose(
    X_CO: np.ndarray,
    points: np.ndarray,
    obj_id: int,
    cache: ReferenceCache,
    cfg: RegistrationConfig,
    *,
    icp: bool,
    colour_verify: bool,
    colors: np.ndarray | None = None,
    score: float = 0.0,
    scene: SceneCloud | None = None,
    ref: Reference | None = None,
    frame=None,
) -> Registration:
    """The refinement chain of section IV-B after any first pose: ICP -> colour check -> ICP again.

    ICP refines ``X_CO`` (when ``icp``); the colour check
    (:func:`~sixdpose.registration.verify.colour_search`, when ``colour_verify``, ``colors`` match
    ``points`` and the model is coloured) may replace it by a rotation about the centroid that agrees
    better with the colours, which ICP then refines again (when ``icp``). ``register`` (after a global
    method, :func:`estimate_pose`) and ``predict-pose`` (after the network,
    :class:`sixdpose.pose.Estimator`) both call this one function.

    Args:
        X_CO: (4, 4) initial pose of the object in the camera frame, metres.
        points: (N, 3) masked camera-frame points, metres. colors: optional (N, 3) colours in [0, 1].
        obj_id: object id (its model comes from ``cache.dataset``). cache: per-process
            :class:`~sixdpose.registration.geometry.ReferenceCache`. cfg: configuration.
        icp, colour_verify: which steps run. score: the score of ``X_CO`` (kept when ICP does not run).
        scene, ref: the prepared scene cloud and reference when the caller has them (else built here:
            the ``icp`` reference, a scene without features).
        frame: the instance's :class:`~sixdpose.registration.hypotheses.Frame`; with ``cfg.verify`` the
            pose, the colour search's other basins and their turns are verified against it
            (:func:`~sixdpose.registration.hypotheses.verify_hypotheses`, ICP on the best few) and the
            verification score becomes the score.
    Returns:
        :class:`Registration` with the refined ``X_CO``, the last ICP fitness (or ``score``), the
        seconds of this chain (including a scene or reference built here and the colour grid's first
        use) and ``info`` (``colour_changed``, ``colour_corr`` when the colour check ran).
    """
    t0 = time.perf_counter()
    if ref is None:
        ref, _ = get_reference(cache, obj_id, "icp", cfg)
    if scene is None and icp:
        scene = prepare_scene(points, ref.diameter, cfg, features=False)
    can_icp = icp and len(scene.points) >= 3
    info: dict = {}
    if can_icp:
        r = refine_icp(scene, ref, X_CO, cfg)
        X_CO, score = r.X_CO, r.score
    extra = None
    if colour_verify and colors is not None and len(colors) == len(points):
        grid, _ = cache.colour_grid(obj_id, cfg.cv_grid_cells, cfg.cv_smooth_rel)
        if grid is not None:
            from .verify import colour_search

            res = colour_search(X_CO, points, colors, grid, ref.diameter, cfg)
            info.update(colour_changed=res.changed, colour_corr=res.col)
            if res.candidates is not None:
                extra = res.candidates[: cfg.verify_extra]
            if res.changed:
                if extra is not None:  # the geometric pose becomes a further base of the verification
                    extra = np.concatenate([X_CO[None], extra])[: max(cfg.verify_extra, 1)]
                X_CO = res.X_CO
                if can_icp:
                    r = refine_icp(scene, ref, X_CO, cfg)
                    X_CO, score = r.X_CO, r.score
    if cfg.verify and frame is not None:
        from .hypotheses import model_surface, verify_hypotheses

        surf, _ = model_surface(cache, obj_id, cfg)
        icp_fn = None
        if can_icp and scene is not None:
            scene_c, ref_c = scene, ref

            def icp_fn(X: np.ndarray) -> np.ndarray:
                return refine_icp(scene_c, ref_c, X, cfg).X_CO

        v = verify_hypotheses(X_CO, surf, frame, cfg, extra=extra, icp=icp_fn, obj_id=obj_id)
        X_CO, score = v.X_CO, max(v.score, 0.0)
        info.update(verify_index=v.index, verify_hypotheses=v.n_hypotheses, verify_icp=v.n_icp)
    return Registration(X_CO, score, time.perf_counter() - t0, info)


def estimate_pose(
    points: np.ndarray,
    obj_id: int,
    method: str,
    cache: ReferenceCache,
    cfg: RegistrationConfig,
    icp: bool = False,
    colors: np.ndarray | None = None,
    frame=None,
) -> Registration:
    """Full per-instance pipeline: scene preparation, global registration, optional ICP.

    Args:
        points: (N, 3) masked camera-frame points (metres), N >= 3.
        obj_id: object id (its model comes from ``cache.dataset``).
        method: ``"ransac"``, ``"fgr"`` or ``"super4pcs"``.
        cache: per-process :class:`ReferenceCache`.
        cfg: configuration. icp: refine with ICP.
        colors: optional (N, 3) colours in [0, 1] of ``points``; with ``cfg.colour_verify`` (and a
            coloured model) the pose is then checked by colour and refined again (:func:`refine_pose`).
        frame: optional :class:`~sixdpose.registration.hypotheses.Frame` of the instance (hypothesis
            verification with ``cfg.verify``).
    Returns:
        :class:`Registration` whose ``time`` includes scene preparation, the first-use cost of the
        model's reference (charged once per process), the method and ICP.
    """
    if method not in _FUNCS:
        raise ValueError(f"unknown method {method!r} (choose from {', '.join(METHODS)})")
    ref, t_ref = get_reference(cache, obj_id, method, cfg)
    scene = prepare_scene(points, ref.diameter, cfg, features=method in ("ransac", "fgr"))
    if len(scene.points) < 3:
        return Registration(np.eye(4), 0.0, scene.time + t_ref, {"reason": "fewer than 3 points after gating"})
    est = _FUNCS[method](scene, ref, cfg)
    r = refine_pose(est.X_CO, points, obj_id, cache, cfg, icp=icp, colour_verify=cfg.colour_verify, colors=colors,
                    score=est.score, scene=scene, ref=ref, frame=frame)
    spent, retries = est.time + r.time, 0
    # a verified pose that fits the frame poorly (score below verify_retry_below) is searched for again: the
    # global method reseeded, up to verify_retries times, keeping the best verified pose (a global method
    # that lands in a wrong basin, an object upside down, lands elsewhere with other random draws)
    if cfg.verify and frame is not None and cfg.verify_retry_below > 0:
        while r.score < cfg.verify_retry_below and retries < cfg.verify_retries:
            retries += 1
            cfg_k = dataclasses.replace(cfg, seed=(cfg.seed + 1_000_003 * retries) % 2**31)
            est_k = _FUNCS[method](scene, ref, cfg_k)
            r_k = refine_pose(est_k.X_CO, points, obj_id, cache, cfg_k, icp=icp, colour_verify=cfg.colour_verify,
                              colors=colors, score=est_k.score, scene=scene, ref=ref, frame=frame)
            spent += est_k.time + r_k.time
            if r_k.score > r.score:
                est, r = est_k, r_k
    info = dict(est.info, global_score=est.score, n_scene=len(scene.points), **r.info)
    if retries:
        info["verify_retries"] = retries
    return Registration(r.X_CO, r.score, t_ref + scene.time + spent, info)
