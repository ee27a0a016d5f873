"""Hybrid pose estimation (paper section IV-B): masked depth -> point cloud -> global registration
(RANSAC or FGR on FPFH features, or Super4PCS) -> optional ICP -> optional colour verification.
See :mod:`.methods` (per instance) and :mod:`.runner` (over a dataset)."""

from ..lazy import by_module, lazy_getattr
from .geometry import ReferenceCache
from .methods import (
    METHODS,
    Registration,
    estimate_pose,
    prepare_scene,
    refine_icp,
    refine_pose,
    register_fgr,
    register_ransac,
    register_super4pcs,
)
from .presets import LEARNED_VERIFY, PRESETS, RegistrationConfig, get_preset
from .runner import RegistrationError, instance_seed, run_registration

__all__ = [
    "LEARNED_VERIFY", "METHODS", "PRESETS", "Frame", "ReferenceCache", "Registration", "RegistrationConfig",
    "RegistrationError",
    "estimate_pose", "get_preset", "instance_seed", "kabsch_batch", "prepare_scene", "refine_icp", "refine_pose",
    "register_fgr", "register_ransac", "register_super4pcs", "run_registration", "verify_hypotheses", "colour_scores",
    "warmup_colour", "model_slides",
]

# lazy: super4pcs imports scipy.spatial and hypotheses Numba, which building the CLI parser need not load
__getattr__ = lazy_getattr(__name__, by_module(super4pcs=("kabsch_batch",),
                                                  hypotheses=("Frame", "model_slides", "verify_hypotheses"),
                                                  verify=("colour_scores",)))


def warmup_colour() -> None:
    """Compile the colour-scoring kernel of :func:`colour_scores` and the colour search now (or load it from
    Numba's on-disk cache): a start-up cost, so that the first instance's time is not charged with it."""
    from .verify import warmup

    warmup()
