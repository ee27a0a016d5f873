"""Typed configuration of the synthetic dataset generator, with named profiles.

Units: metres, seconds, degrees where the name says ``_deg``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import yaml


@dataclass(frozen=True)
class CameraConfig:
    """Random camera arc around the table (section III-B).

    The camera looks at a random point of the table top; along the arc the azimuth, horizontal
    distance, height above the table and roll about the optical axis are interpolated linearly
    between random start and end values.
    """

    width: int = 640
    height: int = 480
    fov_y_deg: float = 45.0
    distance_range: tuple[float, float] = (0.55, 1.3)  #: horizontal distance to the look-at point
    height_range: tuple[float, float] = (0.25, 1.1)  #: height above the table top
    arc_span_deg: tuple[float, float] = (45.0, 180.0)  #: azimuth swept between first and last view
    roll_deg: tuple[float, float] = (-30.0, 30.0)  #: roll about the optical axis (not upright)
    target_jitter: tuple[float, float] = (0.25, 0.2)  #: look-at point within +-(x, y) of table centre
    near: float = 0.05  #: depth range: nearer/further pixels have no measurement (0.0)
    far: float = 8.0


@dataclass(frozen=True)
class GenerationConfig:
    """Everything that determines a dataset (saved as ``config.yml`` in it).

    Execution settings (workers, executor) are not part of it: they never change the output.
    """

    scenes: int = 10
    views: int = 20
    seed: int = 0
    targets: tuple[int, int] = (5, 20)  #: target instances per scene (inclusive range)
    noise: tuple[int, int] = (5, 10)  #: noise objects per scene (inclusive range)
    max_instances: int = 4  #: at most this many instances of one object in a scene
    off_table_prob: float = 0.1  #: probability that an object is dropped beyond the table edge
    table_size: tuple[float, float] = (1.2, 0.8)
    table_height: float = 0.75  #: height of the table top above the ground
    time_step: float = 5e-3  #: discrete MultibodyPlant step
    sim_time: float = 5.0  #: simulated seconds (stops early once everything is at rest)
    rest_speed: float = 0.02  #: at rest: every generalized velocity below this (m/s, rad/s)
    contact_points_per_edge: int = 3  #: contact spheres per box edge (see generation.sim)
    table_edge_spacing: float = 0.05  #: spacing of the contact spheres along the table top's edges
    scene_radius: float = 3.0  #: objects further than this from the table centre have left the scene
    max_attempts: int = 6  #: re-draws of a scene that does not come to rest
    model_points: int = 20000  #: points of each reference model cloud
    camera: CameraConfig = field(default_factory=CameraConfig)

    def to_dict(self) -> dict:
        """Plain-data form (tuples as lists) for YAML/JSON."""
        return _plain(dataclasses.asdict(self))

    @classmethod
    def from_dict(cls, d: dict) -> "GenerationConfig":
        """Inverse of :meth:`to_dict`; unknown keys raise ``ValueError``."""
        d = dict(d)
        cam = CameraConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.pop("camera", {}).items()})
        known = {f.name for f in dataclasses.fields(cls)}
        bad = set(d) - known
        if bad:
            raise ValueError(f"unknown config keys {sorted(bad)}")
        return cls(camera=cam, **{k: tuple(v) if isinstance(v, list) else v for k, v in d.items()})

    def to_yaml(self) -> str:
        """YAML text of :meth:`to_dict`."""
        return yaml.safe_dump(self.to_dict(), sort_keys=True)

    def validate(self) -> None:
        """Raise ``ValueError`` with a one-line message if any value is out of range."""
        if self.scenes < 0:
            raise ValueError(f"--scenes must be >= 0, got {self.scenes}")
        if self.views < 1:
            raise ValueError(f"--views must be >= 1, got {self.views}")
        if self.seed < 0:
            raise ValueError(f"--seed must be >= 0, got {self.seed}")
        for name in ("targets", "noise"):
            lo, hi = getattr(self, name)
            if not 0 <= lo <= hi:
                raise ValueError(f"{name} range must satisfy 0 <= min <= max, got {(lo, hi)}")
        if not 0 <= self.off_table_prob <= 1:
            raise ValueError("off_table_prob must be in [0, 1]")
        if self.camera.width < 8 or self.camera.height < 8:
            raise ValueError("image size must be at least 8x8")


def _plain(x):
    if isinstance(x, dict):
        return {k: _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    return x


#: Named profiles. ``smoke``: CI-sized; ``demo``: the laptop-CPU default of ``make demo``;
#: ``paper``: 25,000 images as in section III-C. ``val`` (seed 100) and ``test`` (seed 300): the fixed
#: splits on which the hybrid methods' defaults are chosen and then measured (never tuned on ``test``).
PROFILES: dict[str, GenerationConfig] = {
    "smoke": GenerationConfig(scenes=2, views=3, targets=(5, 8), noise=(3, 5)),
    "demo": GenerationConfig(scenes=12, views=20),
    "val": GenerationConfig(scenes=6, views=20, seed=100),
    "test": GenerationConfig(scenes=10, views=20, seed=300),
    "paper": GenerationConfig(scenes=1250, views=20),
}


def profile(name: str, **overrides) -> GenerationConfig:
    """The named profile with fields replaced by ``overrides`` (None values are ignored)."""
    if name not in PROFILES:
        raise ValueError(f"unknown profile {name!r} (choose from {', '.join(PROFILES)})")
    return dataclasses.replace(PROFILES[name], **{k: v for k, v in overrides.items() if v is not None})
