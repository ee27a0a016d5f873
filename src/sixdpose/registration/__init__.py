"""Hybrid pose estimation (paper section IV-B): masked depth -> point cloud -> global registration
(RANSAC or FGR on FPFH features, or Super4PCS) -> optional ICP. See :mod:`.methods`."""

from .methods import METHODS, PoseEstimate, estimate_pose, prepare_scene, refine_icp, register_fgr, register_ransac, register_super4pcs
from .presets import PRESETS, RegistrationConfig, get_preset
from .runner import load_predicted_masks, run_registration, write_results

__all__ = [
    "METHODS", "PRESETS", "PoseEstimate", "RegistrationConfig", "estimate_pose", "get_preset", "load_predicted_masks",
    "prepare_scene", "refine_icp", "register_fgr", "register_ransac", "register_super4pcs", "run_registration", "write_results",
]
