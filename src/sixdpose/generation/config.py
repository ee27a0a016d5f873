"""Typed configuration of the synthetic dataset generator, with named profiles.

Units: metres, seconds, degrees where the name says ``_deg``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ..config import Config, from_profile
from .sensors import SENSORS


@dataclass(frozen=True)
class CameraConfig(Config):
    """Random camera arc around the table (section III-B).

    The camera looks at a random point of the table top; along the arc the azimuth, horizontal
    distance, height above the table and roll about the optical axis are interpolated linearly
    between random start and end values.

    Attributes:
        width, height: image size in pixels (640 x 480).
        fov_y_deg: vertical field of view, degrees.
        distance_range: (min, max) horizontal distance to the look-at point, metres.
        height_range: (min, max) camera height above the table top, metres.
        arc_span_deg: (min, max) azimuth swept between the first and the last view, degrees.
        roll_deg: (min, max) roll about the optical axis, degrees (the camera is not upright).
        target_jitter: the look-at point lies within +-(x, y) metres of the table centre.
        near, far: depth range in metres; nearer or farther pixels have no measurement (0.0).
    """

    width: int = 640
    height: int = 480
    fov_y_deg: float = 45.0
    distance_range: tuple[float, float] = (0.55, 1.3)
    height_range: tuple[float, float] = (0.25, 1.1)
    arc_span_deg: tuple[float, float] = (45.0, 180.0)
    roll_deg: tuple[float, float] = (-30.0, 30.0)
    target_jitter: tuple[float, float] = (0.25, 0.2)
    near: float = 0.05
    far: float = 8.0

    def validate(self) -> None:
        """Raise ``ValueError`` with a one-line message if any value is out of range."""
        if self.width < 8 or self.height < 8:
            raise ValueError("image size must be at least 8x8")
        if not 0 < self.fov_y_deg < 180:
            raise ValueError(f"fov_y_deg must be in (0, 180), got {self.fov_y_deg}")
        if not 0 < self.near < self.far:
            raise ValueError(f"need 0 < near < far, got near={self.near}, far={self.far}")


@dataclass(frozen=True)
class GenerationConfig(Config):
    """Everything that determines a dataset (saved as ``config.yml`` in it).

    Execution settings (workers, executor) are not part of it: they never change the output.

    Attributes:
        scenes: number of scenes. views: camera views (images) per scene. seed: random seed; a
            scene is drawn from ``(seed, scene index)``.
        targets: (min, max) target instances per scene (inclusive).
        noise: (min, max) noise objects per scene (inclusive).
        max_instances: at most this many instances of one object in a scene.
        off_table_prob: probability that an object is dropped beyond the table edge.
        table_size: table top (x, y) size, metres. table_height: height of the table top above the
            ground, metres.
        time_step: discrete MultibodyPlant step, seconds.
        sim_time: simulated seconds (stops early once everything is at rest).
        rest_speed: at rest when every generalized velocity is below this (m/s, rad/s).
        contact_points_per_edge: contact spheres per box edge (see :mod:`sixdpose.generation.sim`).
        table_edge_spacing: spacing of the contact spheres along the table top's edges, metres.
        scene_radius: objects farther than this (metres) from the table centre have left the scene.
        max_attempts: re-draws of a scene that does not come to rest.
        model_points: points of each reference model cloud.
        sensor: depth sensor model applied to every rendered view before it is written
            (:mod:`sixdpose.generation.sensors`: ``ideal`` (the paper's perfect depth), ``kinect``,
            ``realsense``, ``azure``), seeded from (seed, scene, view); masks and poses stay exact.
        camera: the :class:`CameraConfig`.
    """

    scenes: int = 10
    views: int = 20
    seed: int = 0
    targets: tuple[int, int] = (5, 20)
    noise: tuple[int, int] = (5, 10)
    max_instances: int = 4
    off_table_prob: float = 0.1
    table_size: tuple[float, float] = (1.2, 0.8)
    table_height: float = 0.75
    time_step: float = 5e-3
    sim_time: float = 5.0
    rest_speed: float = 0.02
    contact_points_per_edge: int = 3
    table_edge_spacing: float = 0.05
    scene_radius: float = 3.0
    max_attempts: int = 6
    model_points: int = 20000
    sensor: str = "ideal"
    camera: CameraConfig = field(default_factory=CameraConfig)

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
        if self.sensor not in SENSORS:
            raise ValueError(f"sensor must be one of {', '.join(SENSORS)}, got {self.sensor!r}")
        if self.max_instances < 1:
            raise ValueError(f"max_instances must be >= 1, got {self.max_instances}")


#: Named profiles. ``smoke``: CI-sized; ``demo``: the laptop-CPU default of ``make demo``;
#: ``paper``: 25,000 images as in section III-C. ``val`` (seed 100) and ``test`` (seed 300): the fixed
#: splits on which the hybrid methods' defaults are chosen and then measured (never tuned on ``test``).
PROFILES: dict[str, GenerationConfig] = {
    "smoke": GenerationConfig(scenes=2, views=3, targets=(5, 8), noise=(3, 5)),
    "demo": GenerationConfig(scenes=12, views=20),
    "val": GenerationConfig(scenes=6, views=20, seed=100),
    "test": GenerationConfig(scenes=10, views=20, seed=300),
    "train": GenerationConfig(scenes=60, views=20, seed=500),
    "paper": GenerationConfig(scenes=1250, views=20),
}


def profile(name: str, **overrides) -> GenerationConfig:
    """The named profile with fields replaced by ``overrides`` (None values are ignored; dotted keys
    such as ``camera.fov_y_deg`` reach the camera). Raises :class:`~sixdpose.errors.ConfigError`."""
    return from_profile(PROFILES, name, {k: v for k, v in overrides.items() if v is not None})
