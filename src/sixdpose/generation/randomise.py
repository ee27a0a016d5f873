"""Domain randomisation of rendered views (``GenerationConfig.randomise``). Pure NumPy: no Drake here.

Per scene: random diffuse colours for the table (top and legs), the floor and every noise (distractor)
object, and a random colour for the empty background; per view: a random exposure gain, gamma, white
balance and a directional light falloff across the image. The target objects keep their textures
(only the per-view camera and light changes reach them). Geometry, depth, masks and poses are untouched.

Why in image space: Drake's ``RenderEngineVtk`` takes its lights, exposure and background colour in
``RenderEngineVtkParams`` when the engine is made (once per worker process, see
:class:`~sixdpose.generation.sim.PoolRenderer`), and a geometry's ``("phong", "diffuse")`` perception
property is fixed when the geometry is registered (a textured mesh's MTL texture overrides it), so
changing them per scene or view would mean reloading every mesh. Instead the rendered colour is
recoloured through the label image. For a Lambertian surface of diffuse colour ``d`` the rendered
colour is ``d * s`` (``s`` the shading), so ``rgb * d_new / d`` is exactly the render with diffuse colour
``d_new``: that is what the table and floor get (their default colours are known, :data:`TABLE_RGB`,
:data:`GROUND_RGB`). A textured noise object gets its luminance (the texture's light and dark
pattern and the shading, scaled to 1 at its brightest tenth) times a random colour, and with
probability one half a random two-colour noise texture instead. The table, floor and background also get
a noise texture with random contrast (per scene, a coin flip each). Noise textures are drawn in image
space per view: they do not follow the surface from view to view.

Strength ``s = randomise`` in [0, 1] scales everything: colours are ``(1 - s) default + s random``,
texture contrast, exposure, gamma, white-balance and light ranges are multiplied by ``s``; ``s = 0``
changes nothing (the generator then skips this module, so images are byte-identical to before).

Streams: ``np.random.default_rng([seed, scene, DR_RNG_TAG])`` per scene and
``[seed, scene, view, DR_RNG_TAG]`` per view: independent of the scene layout stream (``scene_rng``),
the sensor stream (:func:`~sixdpose.generation.sensors.sensor_rng`), the worker count and order.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .sim import EMPTY_LABEL, GROUND_LABEL, GROUND_RGB, TABLE_LABEL, TABLE_RGB

__all__ = ["DR_RNG_TAG", "SceneLook", "ViewLook", "scene_look", "view_look", "randomise_view"]

#: Last word of the randomisation streams' seeds (ASCII "DRND").
DR_RNG_TAG = 0x44524E44
#: Drake's ``RenderEngineVtkParams.default_clear_color`` (the empty background), RGB in [0, 1].
BACKGROUND_RGB = (204 / 255, 229 / 255, 255 / 255)

#: Ranges at strength 1: exposure gain factor (log-uniform), gamma (log-uniform), white-balance gain per
#: channel (log-uniform), light falloff amplitude across the image (uniform), texture contrast.
EXPOSURE = (0.6, 1.5)
GAMMA = (0.75, 1.35)
WHITE_BALANCE = (0.92, 1.08)
LIGHT_FALLOFF = (0.0, 0.5)
_LUMA = np.array([0.299, 0.587, 0.114], dtype=np.float32)


@dataclass
class SceneLook:
    """The random colours of one scene (RGB in [0, 1]).

    Attributes:
        table, ground, background: (3,) diffuse colours of the table, the floor and the empty background.
        texture: (3,) contrast of a noise texture on the table, the floor and the background.
        noise: scene label (k + 1 of the scene's object k) -> ``(colour (3,), second colour (3,) or
            None)``: a flat colour, or a two-colour noise texture when the second is given.
        strength: the ``randomise`` strength the look was drawn with.
    """

    table: np.ndarray
    ground: np.ndarray
    background: np.ndarray
    texture: np.ndarray
    noise: dict = field(default_factory=dict)
    strength: float = 1.0


@dataclass
class ViewLook:
    """The random camera and light of one view.

    Attributes:
        gain: exposure factor. gamma: output gamma. white_balance: (3,) per-channel gains.
        light_dir: (2,) unit direction in the image (u, v) towards which the light falls off.
        falloff: relative brightness change from the image centre to its edge along ``light_dir``.
        texture_seed: seed of the view's noise textures.
    """

    gain: float
    gamma: float
    white_balance: np.ndarray
    light_dir: np.ndarray
    falloff: float
    texture_seed: int


def _check_strength(strength: float) -> float:
    s = float(strength)
    if not 0.0 <= s <= 1.0:
        raise ValueError(f"randomise strength must be in [0, 1], got {strength!r}")
    return s


def _colour(rng: np.random.Generator) -> np.ndarray:
    """A random diffuse colour: uniform hue, saturation 0-0.9, value 0.15-0.95 (HSV), as RGB."""
    h, s, v = rng.random(), rng.uniform(0.0, 0.9), rng.uniform(0.15, 0.95)
    k = (np.array([5.0, 3.0, 1.0]) + 6.0 * h) % 6.0
    return (v - v * s * np.clip(np.minimum(k, 4.0 - k), 0.0, 1.0)).astype(np.float32)


def scene_look(seed: int, scene: int, noise_labels, strength: float) -> SceneLook:
    """Draw the colours of one scene.

    Args:
        seed, scene: the dataset seed and scene index (ints >= 0).
        noise_labels: the scene labels (k + 1) of its noise objects.
        strength: ``randomise`` in [0, 1].
    Returns:
        a :class:`SceneLook`; deterministic in (seed, scene, noise_labels, strength).
    """
    s = _check_strength(strength)
    rng = np.random.default_rng([int(seed), int(scene), DR_RNG_TAG])

    def mix(default):
        return ((1.0 - s) * np.asarray(default, np.float32) + s * _colour(rng)).astype(np.float32)

    table, ground, background = mix(TABLE_RGB), mix(GROUND_RGB), mix(BACKGROUND_RGB)
    texture = (s * rng.uniform(0.0, 0.6, 3) * (rng.random(3) < 0.5)).astype(np.float32)
    look = SceneLook(table, ground, background, texture, strength=s)
    for lab in sorted(int(x) for x in noise_labels):
        c = _colour(rng)
        second = _colour(rng) if rng.random() < 0.5 else None
        look.noise[lab] = (c, second)
    return look


def view_look(seed: int, scene: int, view: int, strength: float) -> ViewLook:
    """Draw the camera and light of one view (ranges :data:`EXPOSURE`, :data:`GAMMA`,
    :data:`WHITE_BALANCE`, :data:`LIGHT_FALLOFF` scaled by ``strength``, log-uniform for the factors).

    Returns:
        a :class:`ViewLook`; deterministic in (seed, scene, view, strength).
    """
    s = _check_strength(strength)
    rng = np.random.default_rng([int(seed), int(scene), int(view), DR_RNG_TAG])

    def logu(lo, hi, size=None):
        return np.exp(s * rng.uniform(np.log(lo), np.log(hi), size))

    gain, gamma = float(logu(*EXPOSURE)), float(logu(*GAMMA))
    wb = logu(*WHITE_BALANCE, 3).astype(np.float32)
    a = rng.uniform(0.0, 2.0 * np.pi)
    falloff = float(s * rng.uniform(*LIGHT_FALLOFF))
    return ViewLook(gain, gamma, wb, np.array([np.cos(a), np.sin(a)]), falloff, int(rng.integers(2**31)))


def _noise_field(rng: np.random.Generator, H: int, W: int, cells: int) -> np.ndarray:
    """A smooth random field in [0, 1] (H, W): uniform values on a ``cells``-wide grid, bilinear."""
    gh, gw = max(2, H * cells // max(H, W) + 2), max(2, W * cells // max(H, W) + 2)
    g = rng.random((gh, gw)).astype(np.float32)
    y = np.linspace(0, gh - 1.001, H, dtype=np.float32)
    x = np.linspace(0, gw - 1.001, W, dtype=np.float32)
    y0, x0 = y.astype(int), x.astype(int)
    fy, fx = (y - y0)[:, None], (x - x0)[None, :]
    top = g[y0][:, x0] * (1 - fx) + g[y0][:, x0 + 1] * fx
    bot = g[y0 + 1][:, x0] * (1 - fx) + g[y0 + 1][:, x0 + 1] * fx
    return top * (1 - fy) + bot * fy


def randomise_view(rgb: np.ndarray, label: np.ndarray, scene: SceneLook, view: ViewLook) -> np.ndarray:
    """Recolour one rendered view.

    Args:
        rgb: (H, W, 3) uint8 render. label: (H, W) int scene labels (object k: k + 1; table
            :data:`TABLE_LABEL`, floor :data:`GROUND_LABEL`, empty :data:`EMPTY_LABEL`).
        scene, view: the looks (:func:`scene_look`, :func:`view_look`).
    Returns:
        a new (H, W, 3) uint8 image; target pixels keep their colours up to the view's exposure,
        gamma, white balance and light falloff.
    """
    if rgb.dtype != np.uint8 or rgb.ndim != 3 or rgb.shape[2] != 3 or label.shape != rgb.shape[:2]:
        raise ValueError(f"rgb must be (H, W, 3) uint8 with a matching (H, W) label, got {rgb.shape} "
                         f"{rgb.dtype} and {label.shape}")
    H, W = label.shape
    s = scene.strength
    x = rgb.astype(np.float32) / 255.0
    tex_rng = np.random.default_rng([view.texture_seed, DR_RNG_TAG])
    for i, (lab, colour) in enumerate(((TABLE_LABEL, scene.table / np.asarray(TABLE_RGB, np.float32)),
                                       (GROUND_LABEL, scene.ground / np.asarray(GROUND_RGB, np.float32)),
                                       (EMPTY_LABEL, None))):
        m = label == lab
        if not m.any():
            continue
        if colour is None:  # the empty background: shading-free, the colour itself
            x[m] = scene.background
        else:
            x[m] *= colour
        if scene.texture[i] > 0:
            t = _noise_field(tex_rng, H, W, int(tex_rng.integers(8, 80)))[m]
            x[m] *= (1.0 + scene.texture[i] * (2.0 * t - 1.0))[:, None]
    for lab, (c, second) in scene.noise.items():
        m = label == lab
        if not m.any():
            continue
        lum = x[m] @ _LUMA
        lum /= max(float(np.percentile(lum, 90)), 1e-3)  # shading x texture pattern, 1 where brightest
        new = lum[:, None] * c[None, :]
        if second is not None:
            t = _noise_field(tex_rng, H, W, int(tex_rng.integers(4, 40)))[m][:, None]
            new = new * (1 - t) + lum[:, None] * second[None, :] * t
        x[m] = (1.0 - s) * x[m] + s * new
    if view.falloff > 0:
        u = (np.arange(W, dtype=np.float32) - (W - 1) / 2) / (max(H, W) / 2)
        v = (np.arange(H, dtype=np.float32) - (H - 1) / 2) / (max(H, W) / 2)
        light = 1.0 - view.falloff * (u[None, :] * view.light_dir[0] + v[:, None] * view.light_dir[1])
        x *= np.clip(light, 0.0, None)[..., None]
    x *= (view.gain * view.white_balance)[None, None, :]
    np.clip(x, 0.0, 1.0, out=x)
    if view.gamma != 1.0:
        np.power(x, 1.0 / view.gamma, out=x)
    return np.rint(x * 255.0).astype(np.uint8)
