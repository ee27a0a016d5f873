"""Named parameter sets of the hybrid methods (:class:`RegistrationConfig`).

``paper``
    The settings of section IV-B: the *full* masked scene cloud (no downsampling), reference model
    voxel-downsampled at 2 mm, FPFH + RANSAC / FGR with the Open3D tutorial parameters (voxel 2 mm:
    FPFH radius 5 x voxel, RANSAC distance 1.5 x voxel, 100000 iterations, confidence 0.999; FGR
    distance 0.5 x voxel), normals by a plane fit on 10 neighbours, Super4PCS with overlap 0.7,
    delta 1 cm and 200 samples, point-to-plane ICP.

``default``
    Chosen by measurement on the generated VALIDATION split ``data/val_s100`` (``sixdpose generate
    --profile demo --scenes 6 --seed 100``: 120 images, 1161 target instances with >= 400 visible
    pixels; tuning used every 5th of them, 233 instances, GT masks, one process, ``OMP_NUM_THREADS=1``;
    the test split ``data/test_s200`` was never used for tuning). Lengths are relative to the object
    diameter ``d``:

    * scene and model voxel 0.03 d (FPFH radius 5 voxels, RANSAC distance 1.5 voxels, ICP distance
      2 voxels, point-to-plane), scene gated to one diameter around its median point;
    * RANSAC: 50,000 iterations, confidence 0.999, edge-length 0.9 + distance checkers, no mutual filter;
    * FGR: distance 0.5 voxel, 64 iterations (Open3D tutorial values, not re-tuned);
    * Super4PCS: overlap 0.9, delta 0.03 d, 200 samples, normal tolerance 25 deg, early stop at
      LCP 0.8, at most 0.5 s, at most 5,000 candidate pairs per base diagonal;
    * colour verification (:mod:`~sixdpose.registration.verify`, new; not in the paper): after the
      geometric pose (+ ICP), 2,048 rotations about the model centroid scored by surface agreement +
      chromaticity correlation on smoothed colours (150 points), the best 8 basins (>= 30 deg apart)
      refined in 5 rounds of 48 perturbations (30 deg halving; smoothed colours, then sharp ones on
      600 points), 64-cell grid per object; replaces the pose if the score gains >= 0.02, then ICP again.
      Geometry cannot orient the baseball, the Rubik's cube or the pudding box, nor tell flipped
      partial views apart; colour can.

    Measurements that chose them (ADD(-S) accuracy on the 233 validation instances; instances/s on
    one core, first-use model preparation included, the machine shared with other jobs so +-30 %):

    ======================================================  =========  =======
    RANSAC + ICP variant                                    ADD(-S)    inst/s
    ======================================================  =========  =======
    previous default (voxel .04 d, 100k iterations)         57.1 %     8.5
    + mutual filter                                         53.6 %     9.1
    voxel .03 d (no colour)                                 66.5 %     3.5
    colour verification, voxel .04 d                        82.4 %     4.2
    colour verification, voxel .03 d, 100k iterations       89.3 %     3.7
    same, 20k iterations                                    86.7 %     5.5
    same, lighter search (1024 rot., keep 6, 32 pert.)      85.4 %     8.0
    final search (basins 30 deg apart, 5 rounds), 20k it.   85.8 %     4.8
    final search, 50k iterations  (= default)               90.6 %     4.8
    ======================================================  =========  =======

    Baseball alone (20 validation instances, search from the RANSAC+ICP pose): grid 40 cells 42 %,
    64 cells 84 %, 80 cells 76 % (from a random rotation at the GT centre); 4096 rotations / keep 12-16
    / 64 perturbations / 6 rounds did not beat the default (50-65 %): its seam is nearly symmetric
    under 180 deg turns, the remaining failures are mostly such flips.

    Super4PCS (no ICP, colour verification on): time limit 10 s, stop .9, 50k pairs: 77.5 % at 0.41
    inst/s (80 instances); limit 0.5 s, stop .8: 80.0 % at 0.56 inst/s (60); + 5,000 pairs (the
    spheres produced millions of congruent sets in one base): 80.0 % at 2.6 inst/s (60), 71.7 % at
    3.8 inst/s on all 233. FGR + ICP with these defaults: 69.5 % at 5.3 inst/s.

    Not re-measured on the validation split (kept from the previous defaults or the Open3D tutorial):
    FPFH radius factor and neighbour cap, RANSAC distance / edge / n, FGR distance and iterations, ICP
    distance and iterations, normal k, scene gate, Super4PCS overlap / delta / samples / normal
    tolerance, and the colour-search tolerances (surface sigma 0.02 d fine / 0.05 d coarse, smoothing
    0.1 d, weight 1, gain 0.02).

    For reference only (not used to choose anything): ``data/test_s200`` (seed 200), every 4th image,
    266 instances, GT masks, one core (``taskset -c 1``, ``OMP_NUM_THREADS=1``): RANSAC + ICP 93.2 %
    at 5.4 inst/s, FGR + ICP 74.4 % at 7.4 inst/s, Super4PCS 65.8 % at 5.9 inst/s (that subset holds
    a single baseball, the weakest object; on validation it is 12 % of the instances). Rerun
    ``benchmarks/registration.py --data data/val_s100 --stride 10`` when the generator changes and
    update this table.
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

    scene_voxel_rel: float | None = 0.03
    model_voxel: float = 0.002
    model_voxel_rel: float | None = 0.03
    feature_voxel: float = 0.002
    gate_rel: float | None = 1.0
    normal_knn: int = 10
    fpfh_radius_factor: float = 5.0
    fpfh_max_nn: int = 100
    ransac_distance_factor: float = 1.5
    ransac_max_iteration: int = 50000
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
    s4pcs_max_pairs: int = 5000
    s4pcs_max_time: float | None = 0.5
    icp_kind: str = "point_to_plane"
    icp_distance_factor: float = 2.0
    icp_max_iteration: int = 30
    colour_verify: bool = True
    cv_rotations: int = 2048
    cv_points: int = 150
    cv_points_fine: int = 600
    cv_tol_rel: float = 0.02
    cv_coarse_sigma_rel: float = 0.05
    cv_geo_weight: float = 1.0
    cv_smooth_rel: float = 0.1
    cv_keep: int = 8
    cv_refine: int = 5
    cv_perturbations: int = 48
    cv_refine_deg: float = 30.0
    cv_min_gain: float = 0.02
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
        s4pcs_max_pairs=50000,
        s4pcs_max_time=30.0,
        ransac_max_iteration=100000,
        colour_verify=False,
    ),
    "default": RegistrationConfig(),
}


def get_preset(name: str, **overrides) -> RegistrationConfig:
    """The preset ``name`` (``paper`` or ``default``) with optional field overrides."""
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r} (choose from {', '.join(PRESETS)})")
    return PRESETS[name].with_overrides(**overrides) if overrides else PRESETS[name]
