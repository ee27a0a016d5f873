"""Named parameter sets of the hybrid methods (:class:`RegistrationConfig`).

``paper``
    The settings of section IV-B: the *full* masked scene cloud (no downsampling), reference model
    voxel-downsampled at 2 mm, FPFH + RANSAC / FGR with the Open3D tutorial parameters (voxel 2 mm:
    FPFH radius 5 x voxel, RANSAC distance 1.5 x voxel, 100000 iterations, confidence 0.999; FGR
    distance 0.5 x voxel), normals by a plane fit on 10 neighbours, Super4PCS with overlap 0.7,
    delta 1 cm and 200 samples, point-to-plane ICP.

``default``
    Scale-aware settings chosen by measurement: every length is relative to the object diameter
    ``d`` (scene and model voxel 0.04 d, FPFH radius 5 voxels, Super4PCS delta 0.03 d), the masked
    scene is gated to points within one diameter of its median (drops mask bleeding onto the
    background) and downsampled, and Super4PCS tries 7 bases (overlap 0.9) with early stop at LCP 0.9.

    Measurement that justified it (``/tmp`` script later turned into ``benchmarks/registration.py``;
    7 YCB-Video models of ``shared/data/ycbv_sample``, 3 random poses each, partial views by hidden-point
    removal, 1 mm Gaussian noise; one core):

    ============================  ==========  ============  ==========
    Super4PCS settings            ADD-S acc.  ADD acc.      s/instance
    ============================  ==========  ============  ==========
    paper (delta 1 cm, 200 pts)   see report  (ambiguous)   0.3 - 20
    delta .03d, 300 pts, ov .7    100 %       38 %          1.34
    delta .03d, 200 pts, ov .9    100 %       38 %          0.17
    ============================  ==========  ============  ==========

    (ADD fails there only on geometrically symmetric YCB-V objects: cans, boxes; ADD-S is 100 %.)
    The generated validation split (``benchmarks/registration.py --data data/bench_val``) is the
    place to re-measure; rerun it when the generator changes and update these numbers.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace


@dataclass(frozen=True)
class RegistrationConfig:
    """Parameters of the hybrid pipeline. Lengths ending in ``_rel`` are fractions of the object
    diameter; the others are metres. ``None`` disables the step.

    Attributes:
        scene_voxel_rel: scene voxel downsampling (None: full masked cloud, as in the paper).
        model_voxel: reference model voxel in metres (paper 0.002), used if ``model_voxel_rel`` is None.
        model_voxel_rel: reference model voxel relative to the diameter.
        feature_voxel: voxel (m) used to scale FPFH/RANSAC/FGR/ICP distances when the scene is not
            downsampled (paper: the 2 mm model voxel); otherwise the scene voxel is used.
        gate_rel: drop scene points farther than ``gate_rel * diameter`` from the median point.
        normal_knn: neighbours of the normal plane fit (paper 10).
        fpfh_radius_factor, fpfh_max_nn: FPFH radius in voxels and neighbour cap.
        ransac_distance_factor: RANSAC inlier distance in voxels. ransac_max_iteration,
        ransac_confidence, ransac_n, ransac_edge_length, ransac_mutual_filter: Open3D RANSAC options.
        fgr_distance_factor, fgr_iterations: Open3D FGR options.
        s4pcs_overlap, s4pcs_delta, s4pcs_delta_rel, s4pcs_samples, s4pcs_bases, s4pcs_normal_tol_deg,
        s4pcs_stop_lcp, s4pcs_max_candidates, s4pcs_max_time: Super4PCS options (see
        :func:`~sixdpose.registration.super4pcs.super4pcs`); ``s4pcs_delta_rel`` wins over ``s4pcs_delta``.
        icp_kind: ``"point_to_plane"`` or ``"point_to_point"``. icp_distance_factor: correspondence
        distance in voxels. icp_max_iteration: iterations.
        seed: random seed of RANSAC and Super4PCS.
    """

    scene_voxel_rel: float | None = 0.04
    model_voxel: float = 0.002
    model_voxel_rel: float | None = 0.04
    feature_voxel: float = 0.002
    gate_rel: float | None = 1.0
    normal_knn: int = 10
    fpfh_radius_factor: float = 5.0
    fpfh_max_nn: int = 100
    ransac_distance_factor: float = 1.5
    ransac_max_iteration: int = 100000
    ransac_confidence: float = 0.999
    ransac_n: int = 3
    ransac_edge_length: float = 0.9
    ransac_mutual_filter: bool = False
    fgr_distance_factor: float = 0.5
    fgr_iterations: int = 64
    s4pcs_overlap: float = 0.9
    s4pcs_delta: float = 0.01
    s4pcs_delta_rel: float | None = 0.03
    s4pcs_samples: int = 200
    s4pcs_bases: int | None = None
    s4pcs_normal_tol_deg: float | None = 25.0
    s4pcs_stop_lcp: float = 0.9
    s4pcs_max_candidates: int = 10000
    s4pcs_max_time: float | None = 10.0
    icp_kind: str = "point_to_plane"
    icp_distance_factor: float = 2.0
    icp_max_iteration: int = 30
    colour_verify: bool = True
    cv_rotations: int = 2048
    cv_points: int = 150
    cv_tol_rel: float = 0.02
    cv_geo_margin: float = 0.05
    cv_smooth_rel: float = 0.1
    cv_refine: int = 4
    cv_grid_cells: int = 64
    seed: int = 0
    extra: dict = field(default_factory=dict, compare=False)

    def with_overrides(self, **kw) -> "RegistrationConfig":
        """A copy with some fields replaced; unknown names raise ``ValueError`` naming them."""
        bad = sorted(set(kw) - set(asdict(self)))
        if bad:
            raise ValueError(f"unknown registration parameter(s): {', '.join(bad)}")
        return replace(self, **kw)


PRESETS: dict[str, RegistrationConfig] = {
    "paper": RegistrationConfig(
        scene_voxel_rel=None,
        model_voxel=0.002,
        model_voxel_rel=None,
        feature_voxel=0.002,
        gate_rel=None,
        s4pcs_overlap=0.7,
        s4pcs_delta=0.01,
        s4pcs_delta_rel=None,
        s4pcs_samples=200,
        s4pcs_stop_lcp=0.98,
        s4pcs_max_candidates=20000,
        s4pcs_max_time=30.0,
        colour_verify=False,
    ),
    "default": RegistrationConfig(),
}


def get_preset(name: str, **overrides) -> RegistrationConfig:
    """The preset ``name`` (``paper`` or ``default``) with optional field overrides."""
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r} (choose from {', '.join(PRESETS)})")
    return PRESETS[name].with_overrides(**overrides) if overrides else PRESETS[name]
