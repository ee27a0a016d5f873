"""Random scene layouts and camera arcs (section III-B). Pure NumPy: no Drake here.

A scene is drawn from ``numpy.random.default_rng([seed, scene_index, attempt])`` so it depends only
on the seed and its index, never on the worker that draws it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..assets import PhysicalProperties
from ..constants import TARGET_OBJECTS
from ..geometry import X_from
from .config import GenerationConfig


@dataclass
class ObjectSpec:
    """One object dropped into a scene.

    Attributes:
        name: YCB name.
        role: ``"target"`` or ``"noise"``.
        inst: instance number among objects of the same name in the scene (0-based).
        X_WO: (4, 4) initial pose of the object (mesh) frame in the world, metres.
        off_table: dropped deliberately beyond the table edge.
    """

    name: str
    role: str
    inst: int
    X_WO: np.ndarray
    off_table: bool


def scene_rng(seed: int, scene: int, attempt: int = 0) -> np.random.Generator:
    """The random generator of one scene attempt."""
    return np.random.default_rng([int(seed), int(scene), int(attempt)])


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random rotation matrix (3, 3) from a normalised Gaussian quaternion."""
    q = rng.normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def face_down_rotation(rng: np.random.Generator) -> np.ndarray:
    """A rotation R_WO (3, 3) that puts one of the object frame's six axis directions (uniformly chosen)
    straight down (world -z), turned uniformly about the vertical: an object resting on a face of its
    axis-aligned bounding box."""
    a = int(rng.integers(3))
    d = np.zeros(3)
    d[a] = 1.0 if rng.random() < 0.5 else -1.0
    e = np.zeros(3)
    e[(a + 1) % 3] = 1.0
    A = np.stack([e, np.cross(d, e), d], axis=1)  # right-handed: e x (d x e) = d
    B = np.diag([1.0, -1.0, -1.0])  # their images: world x, -y, -z (right-handed)
    yaw = rng.uniform(0, 2 * np.pi)
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ B @ A.T


def draw_objects(
    rng: np.random.Generator, cfg: GenerationConfig, targets: list[str], noise: list[str]
) -> list[tuple[str, str]]:
    """Draw ``(name, role)`` of the scene's objects: targets and noise objects with repeats, at most
    ``cfg.max_instances`` of one name."""
    out: list[tuple[str, str]] = []
    counts: dict[str, int] = {}
    for pool, (lo, hi), role in ((targets, cfg.targets, "target"), (noise, cfg.noise, "noise")):
        n = int(rng.integers(lo, hi + 1))
        pool = list(pool)
        n = min(n, cfg.max_instances * len(pool))
        while n > 0 and pool:
            name = pool[int(rng.integers(len(pool)))]
            if counts.get(name, 0) >= cfg.max_instances:
                pool.remove(name)
                continue
            counts[name] = counts.get(name, 0) + 1
            out.append((name, role))
            n -= 1
    return out


def sample_scene(
    rng: np.random.Generator,
    cfg: GenerationConfig,
    props: dict[str, PhysicalProperties],
    targets: list[str],
    noise: list[str],
) -> list[ObjectSpec]:
    """Draw the objects of a scene and their initial poses above the table.

    Each object's bounding box is enclosed in a sphere; positions are re-drawn until no two spheres
    overlap, so no two objects start interpenetrating. With probability ``cfg.off_table_prob`` an
    object is placed beyond the table edge, so it falls to the ground. With probability
    ``cfg.placed_prob`` an object starts resting on a face of its bounding box
    (:func:`face_down_rotation`), else in a uniformly random orientation (when it is 0 no extra number
    is drawn, so the scenes are those of earlier versions).
    """
    names = draw_objects(rng, cfg, targets, noise)
    hx, hy = cfg.table_size[0] / 2, cfg.table_size[1] / 2
    top = cfg.table_height
    placed: list[tuple[np.ndarray, float]] = []
    specs: list[ObjectSpec] = []
    inst_count: dict[str, int] = {}
    for name, role in names:
        pr = props[name]
        r = float(np.linalg.norm(pr.box_size) / 2)
        off = bool(rng.random() < cfg.off_table_prob)
        for tries in range(10_000):
            if off:
                # a band 2-30 cm beyond a random table edge
                side = int(rng.integers(4))
                u = rng.uniform(-1, 1)
                d = rng.uniform(0.02, 0.3) + r
                x, y = {0: (hx + d, u * hy), 1: (-hx - d, u * hy), 2: (u * hx, hy + d), 3: (u * hx, -hy - d)}[side]
            else:
                x = rng.uniform(-hx + r * 0.5, hx - r * 0.5)
                y = rng.uniform(-hy + r * 0.5, hy - r * 0.5)
            z = top + r + 0.005 + rng.uniform(0, 0.1 + 0.002 * tries)
            p = np.array([x, y, z])
            if all(np.linalg.norm(p - q) > r + rq for q, rq in placed):
                break
        placed.append((p, r))
        placed_down = cfg.placed_prob > 0 and bool(rng.random() < cfg.placed_prob)
        R = face_down_rotation(rng) if placed_down else random_rotation(rng)
        X = X_from(R, p - R @ pr.box_center)  # the box centre sits at p
        inst = inst_count.get(name, 0)
        inst_count[name] = inst + 1
        specs.append(ObjectSpec(name, role, inst, X, off))
    return specs


def look_at(p_WC: np.ndarray, p_WT: np.ndarray, roll: float = 0.0) -> np.ndarray:
    """Pose X_WC (4, 4) of a camera at ``p_WC`` looking at ``p_WT`` (camera +z forward, +y down),
    rolled by ``roll`` radians about its optical axis. World +z is up."""
    z = p_WT - p_WC
    z = z / np.linalg.norm(z)
    down = np.array([0.0, 0.0, -1.0])
    y = down - (down @ z) * z
    if np.linalg.norm(y) < 1e-9:  # looking straight down
        y = np.array([0.0, 1.0, 0.0]) - z[1] * z
    y /= np.linalg.norm(y)
    x = np.cross(y, z)
    c, s = np.cos(roll), np.sin(roll)
    R = np.stack([x, y, z], axis=1) @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    return X_from(R, p_WC)


def camera_arc(rng: np.random.Generator, cfg: GenerationConfig) -> list[np.ndarray]:
    """``cfg.views`` camera poses X_WC along a random arc around the table, all looking at one
    random point of the table top."""
    cam = cfg.camera
    jx, jy = cam.target_jitter
    p_WT = np.array([rng.uniform(-jx, jx), rng.uniform(-jy, jy), cfg.table_height])
    a0 = rng.uniform(0, 2 * np.pi)
    span = np.deg2rad(rng.uniform(*cam.arc_span_deg)) * (1 if rng.random() < 0.5 else -1)
    d0, d1 = rng.uniform(*cam.distance_range, size=2)
    h0, h1 = rng.uniform(*cam.height_range, size=2)
    r0, r1 = np.deg2rad(rng.uniform(*cam.roll_deg, size=2))
    poses = []
    for i in range(cfg.views):
        s = i / (cfg.views - 1) if cfg.views > 1 else 0.0
        a, d, h, roll = a0 + s * span, d0 + s * (d1 - d0), h0 + s * (h1 - h0), r0 + s * (r1 - r0)
        p = p_WT + np.array([d * np.cos(a), d * np.sin(a), h])
        poses.append(look_at(p, p_WT, roll))
    return poses


def default_pools(catalog) -> tuple[list[str], list[str]]:
    """(targets, noise) object names: targets in the paper's order, noise in catalogue order.

    Raises:
        KeyError: a paper target object is missing from the catalogue.
    """
    missing = [n for n in TARGET_OBJECTS if n not in catalog]
    if missing:
        raise KeyError(f"target object(s) missing from the asset directory: {', '.join(missing)}")
    noise = [n for n, o in catalog.items() if n not in TARGET_OBJECTS]
    return list(TARGET_OBJECTS), noise
