"""Synthetic dataset generation with Drake (paper section III)."""

from .config import PROFILES, CameraConfig, GenerationConfig, profile
from .runner import GenerationError, ensure_dataset, generate, render_scene

__all__ = ["PROFILES", "CameraConfig", "GenerationConfig", "profile", "GenerationError", "ensure_dataset", "generate", "render_scene"]
