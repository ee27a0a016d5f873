"""Synthetic dataset generation with Drake (paper section III)."""

from .config import PROFILES, CameraConfig, GenerationConfig, camera_from_bop, profile
from .objects import ObjectSet, SceneObject, resolve_objects
from .runner import GenerationError, ensure_dataset, generate, render_scene

__all__ = ["PROFILES", "CameraConfig", "GenerationConfig", "camera_from_bop", "profile", "ObjectSet", "SceneObject",
           "resolve_objects", "GenerationError", "ensure_dataset", "generate", "render_scene"]
