"""Depth-sensor simulation: published noise models applied to a rendered, perfect depth map.

Every model is a pure function ``model(depth, K, rng, **params) -> depth`` (bop_toolkit style):

* ``depth``: (H, W) float depth along the optical axis in metres; 0 = no measurement (NaN, inf and
  negative values are read as 0, the package's convention, see :mod:`sixdpose.datasets.geometry`).
* ``K``: (3, 3) intrinsics, pixel-centre convention: pixel (u, v) = (column, row) back-projects to
  ``((u - cx) z / fx, (v - cy) z / fy, z)``; camera axes +x right, +y down, +z forward.
* ``rng``: a :class:`numpy.random.Generator` (:func:`sensor_rng` gives per-view reproducibility).
* returns a new (H, W) float32 array in metres, 0.0 where the simulated sensor gives no
  measurement; never NaN or negative. The input is never modified.

Models (:data:`SENSORS`, dispatched by :func:`simulate_depth`):

* ``ideal``: the input as it is.
* ``kinect``: structured light (Kinect v1): the simkinect model of Barron & Malik 2013 (used for
  ICL-NUIM, Handa et al. 2014) with the axial noise of Nguyen, Izadi & Lovell 2012 (:func:`kinect`).
* ``realsense``: active stereo (Intel RealSense D400): RMS error ``z^2 s / (f B)`` of
  Grunnet-Jepsen et al., grazing-angle and occlusion holes (:func:`realsense`).
* ``azure``: time of flight (Azure Kinect DK): Gaussian axial noise (Tolgyessy et al. 2021),
  dark-pixel dropout and the flying-pixel filter (:func:`azure`).

Every model works on any image size (training crops included). Speed: a 640x480 view costs about
10-30 ms on one core (``benchmarks/sensors.py``); the code is vectorised and works in a few
preallocated float32 buffers, since a fresh 1.2 MB array costs about as much in page faults as
several arithmetic passes over it.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "SENSORS",
    "SENSOR_RNG_TAG",
    "simulate_depth",
    "sensor_rng",
    "surface_angle",
    "nguyen_sigma",
    "azure_sigma",
    "kinect",
    "KINECT_SIMKINECT",
    "realsense",
    "azure",
]

SENSORS = ("ideal", "kinect", "realsense", "azure")
#: Last word of every :func:`sensor_rng` seed (ASCII "SENS"): keeps the sensor streams apart from
#: the generator's other streams (``scene_rng`` seeds with ``[seed, scene, attempt]``).
SENSOR_RNG_TAG = 0x53454E53

#: simkinect's own validity-window settings (Barron & Malik 2013): a 9 x 9 window, at least 1/1.2 of it
#: valid, disparity within 0.3 px of the window mean. :func:`kinect`'s defaults are instead calibrated
#: on the YCB-Video sample (``benchmarks/sensor_calibration.py``); pass these to get simkinect's filter.
KINECT_SIMKINECT = {"window": 9, "min_valid_fraction": 1 / 1.2, "edge_threshold": 0.3}

_F32 = np.float32
_HALF_PI = _F32(np.pi / 2)
# Abramowitz & Stegun 4.4.46: arccos(x) = sqrt(1 - x) sum_k a_k x^k on [0, 1], |error| <= 2e-8 rad
_ACOS_COEFFS = tuple(
    _F32(c)
    for c in (1.5707963050, -0.2145988016, 0.0889789874, -0.0501743046,
              0.0308918810, -0.0170881256, 0.0066700901, -0.0012624911)
)


# --------------------------------------------------------------------------------------------------
# argument checks


def _as_depth(depth) -> tuple[np.ndarray, np.ndarray]:
    """A float32 copy of ``depth`` (H, W) with NaN/inf/negative set to 0, and its mask ``z > 0``."""
    if not isinstance(depth, np.ndarray):
        raise ValueError(f"depth must be a numpy array of shape (H, W), got {type(depth).__name__}")
    if depth.ndim != 2:
        raise ValueError(f"depth must be 2-D (H, W), got shape {depth.shape}")
    if depth.dtype.kind != "f":
        raise ValueError(f"depth must be a float array (metres), got dtype {depth.dtype}")
    z = depth.astype(_F32, copy=True)
    valid = z > 0  # False for NaN
    valid &= z < np.inf
    np.copyto(z, _F32(0.0), where=~valid)
    return z, valid


def _intrinsics(K) -> tuple[float, float, float, float]:
    """(fx, fy, cx, cy) of a validated (3, 3) intrinsics matrix."""
    try:
        K = np.asarray(K, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"K must be a numeric (3, 3) intrinsics matrix, got {type(K).__name__}") from None
    if K.shape != (3, 3):
        raise ValueError(f"K must be a (3, 3) intrinsics matrix, got shape {K.shape}")
    if not np.all(np.isfinite(K)):
        raise ValueError("K must be finite")
    fx, fy, cx, cy = float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])
    if fx <= 0 or fy <= 0:
        raise ValueError(f"K must have positive focal lengths, got fx={fx}, fy={fy}")
    return fx, fy, cx, cy


def _check_rng(rng) -> None:
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator (see sensor_rng), got {type(rng).__name__}")


def _check_rgb(rgb, shape) -> np.ndarray | None:
    if rgb is None:
        return None
    if not isinstance(rgb, np.ndarray) or rgb.dtype != np.uint8 or rgb.shape != (*shape, 3):
        got = f"{rgb.dtype} {rgb.shape}" if isinstance(rgb, np.ndarray) else type(rgb).__name__
        raise ValueError(f"rgb must be a uint8 array of shape {(*shape, 3)} matching depth, got {got}")
    return rgb


def _check(name: str, value, hi: float = np.inf) -> float:
    """``value`` as a float, or ValueError unless finite and in [0, hi]."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not np.isfinite(v) or v < 0 or v > hi:
        rng = f"in [0, {hi:g}]" if np.isfinite(hi) else ">= 0"
        raise ValueError(f"{name} must be finite and {rng}, got {value!r}")
    return v


def _check_baseline(baseline) -> float:
    try:
        b = float(baseline)
    except (TypeError, ValueError):
        raise ValueError(f"baseline must be a number (metres), got {baseline!r}") from None
    if not np.isfinite(b) or b == 0:
        raise ValueError(f"baseline must be a finite non-zero distance in metres, got {baseline!r}")
    return b


def _stereo_inputs(depth, K, rng, baseline) -> tuple[np.ndarray, np.ndarray, tuple[float, float, float, float], float]:
    """The checked arguments every baseline-based model shares, checked in this order.

    Returns:
        ``(z, valid, (fx, fy, cx, cy), baseline)``: :func:`_as_depth`'s float32 depth copy (H, W, metres)
        and its mask, :func:`_intrinsics` of ``K``, and the baseline in metres.
    """
    z, valid = _as_depth(depth)
    intrinsics = _intrinsics(K)
    _check_rng(rng)
    return z, valid, intrinsics, _check_baseline(baseline)


def _check_angle(name: str, value) -> float:
    v = _check(name, value)
    if v >= np.pi / 2:
        raise ValueError(f"{name} must be an angle in radians below pi/2, got {value!r}")
    return v


# --------------------------------------------------------------------------------------------------
# geometry kernels (float32, writing into caller-provided (H, W) buffers)


def _derivative(z: np.ndarray, valid: np.ndarray, axis: int, out: np.ndarray) -> np.ndarray:
    """dz per pixel along ``axis`` (1: u, 0: v) into ``out``: the central difference where both
    neighbours are valid, one-sided where one is, 0 where none is. Returns ``defined`` (bool).

    The central difference is taken over the whole image; the few valid pixels lacking a valid
    neighbour (hole rims, image borders) are fixed up through index arrays."""
    n = z.shape[axis]
    defined = np.zeros(z.shape, dtype=bool)
    if n < 2:
        out.fill(0.0)
        return defined

    def s(a, b):
        return (slice(None), slice(a, b)) if axis == 1 else (slice(a, b), slice(None))

    inner = out[s(1, -1)]
    np.subtract(z[s(2, None)], z[s(None, -2)], out=inner)
    inner *= _F32(0.5)
    out[s(None, 1)] = 0.0
    out[s(-1, None)] = 0.0
    np.logical_and(valid[s(2, None)], valid[s(None, -2)], out=defined[s(1, -1)])
    fix = np.nonzero(valid & ~defined)
    if fix[0].size:
        i = fix[axis]
        prev, nxt = list(fix), list(fix)
        prev[axis] = np.maximum(i - 1, 0)
        nxt[axis] = np.minimum(i + 1, n - 1)
        prev, nxt = tuple(prev), tuple(nxt)
        lok = (i > 0) & valid[prev]
        rok = (i < n - 1) & valid[nxt]
        zc, zl, zr = z[fix], z[prev], z[nxt]
        out[fix] = np.where(lok & rok, _F32(0.5) * (zr - zl), np.where(lok, zc - zl, np.where(rok, zr - zc, _F32(0.0))))
        defined[fix] = lok | rok
    return defined


def _cos_angle(z, valid, fx, fy, cx, cy, a, b, c, t) -> np.ndarray:
    """cos(theta) of :func:`surface_angle` into ``a`` (1 where theta is undefined); b, c, t scratch.
    Returns a bool mask of the pixels where theta is defined."""
    H, W = z.shape
    du = _derivative(z, valid, 1, a)
    dv = _derivative(z, valid, 0, b)
    rx = ((np.arange(W, dtype=np.float64) - cx) / fx).astype(_F32)[None, :]
    ry = ((np.arange(H, dtype=np.float64) - cy) / fy).astype(_F32)[:, None]
    a *= _F32(fx)  # fx z_u
    b *= _F32(fy)  # fy z_v
    np.multiply(a, rx, out=c)
    np.multiply(b, ry, out=t)
    c += t
    c += z  # n_z = fx z_u r_x + fy z_v r_y + z
    a *= a
    b *= b
    a += b
    c *= c
    a += c  # |n|^2
    np.add(rx * rx, ry * ry + _F32(1.0), out=t)  # |r|^2
    a *= t
    np.sqrt(a, out=a)
    du |= dv
    du &= valid
    with np.errstate(divide="ignore", invalid="ignore"):
        np.divide(z, a, out=a, where=du)
    np.copyto(a, _F32(1.0), where=~du)
    np.clip(a, _F32(0.0), _F32(1.0), out=a)
    return du


def _acos01(x: np.ndarray, out: np.ndarray, tmp: np.ndarray) -> np.ndarray:
    """arccos of x in [0, 1] into ``out`` (Abramowitz & Stegun 4.4.46, |error| <= 2e-8 rad; about
    three times faster than ``np.arccos`` on float32). ``tmp`` is scratch; ``x`` is kept."""
    c = _ACOS_COEFFS
    np.multiply(x, c[7], out=out)
    for ck in c[6:0:-1]:
        out += ck
        out *= x
    out += c[0]
    np.subtract(_F32(1.0), x, out=tmp)
    np.sqrt(tmp, out=tmp)
    out *= tmp
    return out


def _hidden(z, valid, fx, baseline, p, m) -> np.ndarray:
    """Pixels seen by the camera but hidden from a second, rectified view with the same intrinsics
    displaced by ``baseline`` metres along +x (along -x if negative): the projector or the other
    stereo camera. ``p`` and ``m`` are scratch. Returns a bool mask.

    The second view sees pixel (u, v) at column ``p = u - fx B / z``. Along a row a visible surface
    keeps the order of p; a point is hidden when a nearer point on its +x side maps to a column
    before its own: ``min_{u' > u} p(u') < p(u)`` (a suffix minimum, vectorised). The hidden band
    lies on the -x side of a nearer object and is ``fx B (1/z_near - 1/z_far)`` px wide."""
    if baseline < 0:
        return _hidden(z[:, ::-1], valid[:, ::-1], fx, -baseline, p[:, ::-1], m[:, ::-1])[:, ::-1]
    H, W = z.shape
    hidden = np.zeros(z.shape, dtype=bool)
    if W < 2:
        return hidden
    np.divide(_F32(fx * baseline), z, out=p, where=valid)
    np.subtract(np.arange(W, dtype=_F32)[None, :], p, out=p)
    np.copyto(p, _F32(np.inf), where=~valid)
    np.minimum.accumulate(p[:, ::-1], axis=1, out=m[:, ::-1])
    p -= _F32(1e-3)  # a tolerance for float32 rounding on planes seen edge-on
    np.less(m[:, 1:], p[:, :-1], out=hidden[:, :-1])
    hidden &= valid
    return hidden


def _rounded_normal(rng: np.random.Generator, shape: tuple[int, ...], sigma: float) -> np.ndarray:
    """int16 samples of ``round(N(0, sigma^2))``: the inverse CDF of the rounded Gaussian applied to
    16-bit uniform integers (probabilities resolved to 1/65536; several times cheaper than drawing
    float Gaussians and rounding them)."""
    kmax = int(np.ceil(6 * sigma + 0.5))
    from scipy.special import ndtr  # scipy only when a sensor model runs (the generator imports this module)

    t = np.rint(ndtr((np.arange(-kmax, kmax) + 0.5) / sigma) * 65536)  # P(K <= k) for k < kmax
    x = rng.integers(0, 65536, size=shape, dtype=np.uint16)
    k = np.full(shape, -kmax + int(np.sum(t <= 0)), dtype=np.int16)
    for tj in t[(t > 0) & (t < 65536)]:
        k += x >= np.uint16(tj)
    return k


def _nguyen_into(z: np.ndarray, theta: np.ndarray, tmp: np.ndarray) -> np.ndarray:
    """:func:`nguyen_sigma` computed in place: ``theta`` (< pi/2) becomes sigma_z; ``tmp`` scratch.
    Pixels with z = 0 get inf/NaN (callers mask them)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        np.subtract(_HALF_PI, theta, out=tmp)
        theta /= tmp
        theta *= theta
        np.sqrt(z, out=tmp)
        theta /= tmp
        theta *= _F32(0.0001)
        np.subtract(z, _F32(0.4), out=tmp)
        tmp *= tmp
        tmp *= _F32(0.0019)
        theta += tmp
        theta += _F32(0.0012)
    return theta


def _box_filter(src: np.ndarray, window: int, out: np.ndarray) -> np.ndarray:
    """Mean over window x window neighbourhoods (mirror-reflected at the image border) into ``out``."""
    from scipy import ndimage

    return ndimage.uniform_filter(src, window, output=out, mode="reflect")


# --------------------------------------------------------------------------------------------------
# public API


def sensor_rng(seed: int, scene: int, view: int) -> np.random.Generator:
    """The random generator of the sensor noise of one view.

    ``np.random.default_rng([seed, scene, view, SENSOR_RNG_TAG])``: the noise of a view depends only
    on (seed, scene, view), not on the number of workers or the order views are made in, and is
    independent of the generator's scene stream (``scene_rng``, a 3-word seed).

    Args:
        seed: dataset seed (int >= 0).
        scene: scene index (int >= 0).
        view: view index within the scene (int >= 0).
    Returns:
        a fresh :class:`numpy.random.Generator`.
    Raises:
        ValueError: a negative or non-integer argument.
    """
    words = []
    for name, x in (("seed", seed), ("scene", scene), ("view", view)):
        if isinstance(x, bool) or not isinstance(x, (int, np.integer)) or x < 0:
            raise ValueError(f"{name} must be an integer >= 0, got {x!r}")
        words.append(int(x))
    return np.random.default_rng([*words, SENSOR_RNG_TAG])


def surface_angle(depth: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Angle between the surface normal and the viewing ray at every pixel.

    The normal is the cross product of the gradients of the back-projected point map
    ``P(u, v) = z(u, v) r(u, v)``, ``r = ((u - cx)/fx, (v - cy)/fy, 1)``. With
    ``dP/du = z_u r + z e_x / fx`` and ``dP/dv = z_v r + z e_y / fy``, the (scaled) normal is
    ``n = (-fx z_u, -fy z_v, fx z_u r_x + fy z_v r_y + z)`` with ``n . r = z``, so
    ``cos(theta) = z / (|n| |r|)``. ``z_u``, ``z_v`` are central differences of depth where both
    neighbours are valid, one-sided where one is; a direction without a valid neighbour counts as
    flat, and theta is 0 where neither direction has one (isolated pixels, 1x1 images) or depth is 0.
    Across a depth discontinuity the difference spans the jump and theta approaches pi/2.

    Args:
        depth: (H, W) float depth in metres, 0 = no measurement (NaN/inf/negative read as 0).
        K: (3, 3) intrinsics.
    Returns:
        theta (H, W) float32 in radians, in [0, pi/2].
    """
    z, valid = _as_depth(depth)
    fx, fy, cx, cy = _intrinsics(K)
    a, b, c, t = (np.empty_like(z) for _ in range(4))
    _cos_angle(z, valid, fx, fy, cx, cy, a, b, c, t)
    return _acos01(a, out=b, tmp=c)


def nguyen_sigma(z: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Kinect v1 axial noise of Nguyen, Izadi & Lovell 2012 ("Modeling Kinect sensor noise for
    improved 3D reconstruction and tracking", 3DIMPVT):

        sigma_z(z, theta) = 0.0012 + 0.0019 (z - 0.4)^2 + (0.0001 / sqrt(z)) theta^2 / (pi/2 - theta)^2

    Args:
        z: depth in metres (> 0), any shape.
        theta: angle between surface normal and viewing ray in radians, same shape, in [0, pi/2).
    Returns:
        sigma_z in metres, float32, same shape (0 where z <= 0).
    """
    z = np.asarray(z, dtype=_F32)
    theta = np.array(theta, dtype=_F32)  # a copy: computed in place
    if theta.shape != z.shape:
        raise ValueError(f"theta shape {theta.shape} does not match z shape {z.shape}")
    s = _nguyen_into(z, theta, np.empty_like(theta))
    return np.where(z > 0, s, _F32(0.0))


def azure_sigma(z: np.ndarray, *, sigma_0: float = 0.0005, sigma_slope: float = 0.001, z_0: float = 0.5) -> np.ndarray:
    """Azure Kinect DK random depth error used here: ``sigma = max(sigma_0 + sigma_slope (z - z_0), sigma_0)``,
    by default 0.5 mm + 1 mm/m (z - 0.5 m), at least 0.5 mm: well inside the hardware
    specification's "random error std. dev. <= 17 mm" and of the order Tolgyessy et al. 2021 measured.

    Args:
        z: depth in metres, any shape.
        sigma_0: sigma at and below ``z_0``, metres (0.0005).
        sigma_slope: growth of sigma with depth, metres per metre (0.001).
        z_0: depth where the growth starts, metres (0.5).
    Returns:
        sigma in metres, float32, same shape.
    """
    z = np.asarray(z, dtype=_F32)
    return np.maximum(_F32(sigma_0) + _F32(sigma_slope) * (z - _F32(z_0)), _F32(sigma_0))


def kinect(
    depth: np.ndarray,
    K: np.ndarray,
    rng: np.random.Generator,
    *,
    baseline: float = 0.075,
    pixel_shift_sigma: float = 0.5,
    disparity_step: float = 1 / 8,
    window: int = 3,
    edge_threshold: float = 0.25,
    min_valid_fraction: float = 1 / 2,
    max_angle: float = float(np.deg2rad(80.0)),
    noise_scale: float = 1.0,
) -> np.ndarray:
    """Structured-light sensor (Kinect v1): simkinect with Nguyen et al.'s axial noise.

    Pipeline after simkinect (Barron & Malik 2013, "Intrinsic scene properties from a single RGB-D
    image", CVPR; used for ICL-NUIM by Handa, Whelan, McDonald, Davison 2014, "A benchmark for RGB-D
    visual odometry, 3D reconstruction and SLAM", ICRA):

    1. projector shadow: points hidden from the projector, displaced ``baseline`` along +x, get no
       dots and no depth: a band on the -x side of nearer objects (light from +x casts its shadow
       towards -x), ``fx B (1/z_near - 1/z_far)`` px wide;
    2. lateral jitter: depth (shadow holes included) and theta are resampled, nearest, at
       ``(u, v) + N(0, s^2)`` per axis, ``s = pixel_shift_sigma`` = 0.5 px;
    3. disparity ``d = fx B / z`` rounded to ``disparity_step`` = 1/8 px;
    4. dot-pattern validity filter (a vectorised stand-in for simkinect's 9x9 window test): a pixel
       is kept if at least ``min_valid_fraction`` of its ``window`` x ``window`` neighbourhood has
       depth and its quantised disparity is within ``edge_threshold`` px of the window's mean valid
       disparity. A plane's disparity is affine in (u, v), so its window mean is the centre value
       and tilted planes pass (up to the quantisation of step 3, which steep planes feel at a
       small threshold); both sides of a depth step lose up to ``window // 2`` px, and holes grow.
       simkinect's values (9, 1/1.2, 0.3 px; :data:`KINECT_SIMKINECT`) make about twice the holes
       of the YCB-Video sample's real frames on generated ``ycbv`` scenes; the defaults (3, 1/2,
       0.25 px) are calibrated on the sample's scene 000000 so that the hole fractions inside
       the objects' masks, at their 3 px rim and inside it, match
       (:func:`sixdpose.generation.checks.depth_hole_stats`, ``benchmarks/sensor_calibration.py``);
    5. axial noise (Nguyen, Izadi & Lovell 2012, 3DIMPVT; :func:`nguyen_sigma`):
       ``z += sigma_z(z, theta) N(0, 1)``, ``sigma_z = 0.0012 + 0.0019 (z - 0.4)^2 +
       (0.0001 / sqrt(z)) theta^2 / (pi/2 - theta)^2`` m, theta from :func:`surface_angle`
       clamped to ``max_angle`` (the formula diverges at pi/2, which the depth-gradient normal
       reaches across depth steps; step 4 removes those pixels anyway);
    6. the noisy depth is quantised through its disparity as in step 3, so every output lies on the
       grid ``fx B / (k * disparity_step)``, k integer; the rounding adds a standard deviation of
       about ``disparity_step z^2 / (fx B) / sqrt(12)`` m.

    Args:
        depth: (H, W) float depth in metres, 0 = no measurement.
        K: (3, 3) intrinsics; fx is the disparity focal length.
        rng: random generator (:func:`sensor_rng`).
        baseline: projector-camera baseline B in metres (0.075); negative puts the projector at -x.
        pixel_shift_sigma: std of the lateral jitter in pixels (0.5; 0 disables).
        disparity_step: disparity quantisation in pixels (1/8; 0 disables).
        window: side of the validity window in pixels (3, calibrated; simkinect 9; odd; 1 disables
            the filter).
        edge_threshold: largest deviation of a pixel's disparity from its window mean, pixels
            (0.25, calibrated; simkinect 0.3).
        min_valid_fraction: fraction of the window that must have depth, in [0, 1] (1/2,
            calibrated; simkinect 1/1.2).
        max_angle: clamp of theta in the noise formula, radians, below pi/2 (80 deg).
        noise_scale: factor on sigma_z (1; 0 disables the axial noise).
    Returns:
        (H, W) float32 depth in metres, 0 where invalid.
    """
    z, valid, (fx, fy, cx, cy), baseline = _stereo_inputs(depth, K, rng, baseline)
    shift_sigma = _check("pixel_shift_sigma", pixel_shift_sigma)
    step = _check("disparity_step", disparity_step)
    if isinstance(window, bool) or not isinstance(window, (int, np.integer)) or window < 1 or window % 2 == 0:
        raise ValueError(f"window must be an odd integer >= 1, got {window!r}")
    edge_threshold = _check("edge_threshold", edge_threshold)
    min_valid_fraction = _check("min_valid_fraction", min_valid_fraction, hi=1.0)
    max_angle = _check_angle("max_angle", max_angle)
    noise_scale = _check("noise_scale", noise_scale)
    H, W = z.shape
    if z.size == 0:
        return z

    # theta (into A) and the projector shadow, on the true geometry
    A, B, C, D = (np.empty_like(z) for _ in range(4))
    _cos_angle(z, valid, fx, fy, cx, cy, A, B, C, D)
    theta = _acos01(A, out=D, tmp=B)  # D
    hidden = _hidden(z, valid, fx, baseline, B, C)
    z[hidden] = 0.0

    # 2. lateral jitter, nearest neighbour: z -> B, theta -> C
    if shift_sigma > 0:
        iu = np.add(_rounded_normal(rng, (H, W), shift_sigma), np.arange(W, dtype=np.int32)[None, :], dtype=np.int32)
        iv = np.add(_rounded_normal(rng, (H, W), shift_sigma), np.arange(H, dtype=np.int32)[:, None], dtype=np.int32)
        np.clip(iu, 0, W - 1, out=iu)
        np.clip(iv, 0, H - 1, out=iv)
        iv *= np.int32(W)
        iv += iu
        del iu
        np.take(z.ravel(), iv, out=B)
        np.take(theta.ravel(), iv, out=C)
        del iv
        z, B, theta, C, D = B, z, C, D, None
    valid = z > 0

    # 3. quantised disparity in units of the step, d / step = fx B / (step z) -> B
    unit = step if step > 0 else 1.0
    scale = _F32(fx * abs(baseline) / unit)
    disp = B
    disp.fill(0.0)
    np.divide(scale, z, out=disp, where=valid)
    if step > 0:
        np.rint(disp, out=disp)
    ok = disp > 0

    # 5. axial noise: theta -> sigma_z -> z (the window test below uses the clean disparity)
    if noise_scale > 0:
        np.minimum(theta, _F32(max_angle), out=theta)
        sigma = _nguyen_into(z, theta, A)
        if noise_scale != 1:
            sigma *= _F32(noise_scale)
        sigma *= rng.standard_normal(out=A, dtype=_F32)
        np.add(z, sigma, out=z, where=valid)

    # 4. validity window: fraction of valid pixels (A) and mean disparity (C)
    if window > 1:
        np.copyto(C, valid)
        frac = _box_filter(C, window, A)
        ok &= frac >= _F32(min_valid_fraction - 1e-4)
        mean = _box_filter(disp, window, C)  # sum / window^2 over all pixels (0 where invalid)
        with np.errstate(divide="ignore", invalid="ignore"):
            mean /= frac  # mean over the valid pixels (NaN where none: compares False)
        mean -= disp
        np.abs(mean, out=mean)
        ok &= mean <= _F32(edge_threshold / unit)

    # 6. quantise the noisy depth; the output goes into z's buffer
    if noise_scale > 0:
        ok &= z > 0
        disp.fill(0.0)
        np.divide(scale, z, out=disp, where=ok)
        if step > 0:
            np.rint(disp, out=disp)
        ok &= disp > 0
    z.fill(0.0)
    np.divide(scale, disp, out=z, where=ok)
    return z


def realsense(
    depth: np.ndarray,
    K: np.ndarray,
    rng: np.random.Generator,
    *,
    baseline: float = 0.05,
    subpixel: float = 0.08,
    max_angle: float = float(np.deg2rad(75.0)),
    noise_scale: float = 1.0,
) -> np.ndarray:
    """Active-stereo sensor (Intel RealSense D400).

    * Axial noise, the D400 depth RMS error (Grunnet-Jepsen, Sweetser, Winer, Takagi, Woodfill,
      "Projectors for Intel RealSense depth cameras D4xx", Intel white paper 2018; Intel, "Tuning
      depth cameras for best performance"): ``sigma_z = z^2 s / (f B)`` metres, ``s`` the subpixel
      disparity RMS (0.08 px), ``f = fx`` in pixels, ``B`` the stereo baseline (0.05 m);
      ``z += sigma_z N(0, 1)``.
    * Grazing angles: no depth where theta (:func:`surface_angle`) > ``max_angle`` (75 deg): the
      projected pattern is too foreshortened to match. Depth steps count as grazing (1 px each side).
    * Left-camera occlusion band: depth is computed in the left (reference) camera; pixels it sees
      but the right camera, displaced by ``baseline`` along +x, does not, have no depth: a band on
      the -x side of nearer objects, ``fx B (1/z_near - 1/z_far)`` px wide.

    Args:
        depth: (H, W) float depth in metres, 0 = no measurement.
        K: (3, 3) intrinsics of the left (depth) camera.
        rng: random generator (:func:`sensor_rng`).
        baseline: stereo baseline in metres (0.05); negative puts the matching camera at -x.
        subpixel: subpixel disparity RMS in pixels (0.08).
        max_angle: largest valid theta, radians, below pi/2 (75 deg).
        noise_scale: factor on sigma_z (1; 0 disables the noise).
    Returns:
        (H, W) float32 depth in metres, 0 where invalid.
    """
    z, valid, (fx, fy, cx, cy), baseline = _stereo_inputs(depth, K, rng, baseline)
    subpixel = _check("subpixel", subpixel)
    max_angle = _check_angle("max_angle", max_angle)
    noise_scale = _check("noise_scale", noise_scale)
    if z.size == 0:
        return z
    A, B, C, D = (np.empty_like(z) for _ in range(4))
    _cos_angle(z, valid, fx, fy, cx, cy, A, B, C, D)
    ok = A >= _F32(np.cos(max_angle))  # noqa: SIM300 (A is an array, not a constant)
    ok &= valid
    ok &= ~_hidden(z, valid, fx, baseline, B, C)
    if noise_scale > 0 and subpixel > 0:
        np.multiply(z, z, out=A)
        A *= _F32(noise_scale * subpixel / (fx * abs(baseline)))
        A *= rng.standard_normal(out=B, dtype=_F32)
        z += A
        ok &= z > 0
    np.copyto(z, _F32(0.0), where=~ok)
    return z


def _edge_pixels(z: np.ndarray, valid: np.ndarray, threshold: float, connectivity: int, tmp: np.ndarray) -> np.ndarray:
    """Pixels whose depth differs by more than ``threshold`` from a valid 4- or 8-neighbour."""
    H, W = z.shape
    out = np.zeros(z.shape, dtype=bool)
    offsets = [(0, 1), (1, 0)] + ([(1, 1), (1, -1)] if connectivity == 8 else [])
    t = _F32(threshold)
    for dv, du in offsets:
        if dv >= H or abs(du) >= W:
            continue
        a = (slice(0, H - dv), slice(max(0, -du), W - max(0, du)))
        b = (slice(dv, H), slice(max(0, du), W - max(0, -du)))
        diff = tmp[: H - dv, : W - abs(du)]
        np.subtract(z[a], z[b], out=diff)
        np.abs(diff, out=diff)
        jump = diff > t
        jump &= valid[a]
        jump &= valid[b]
        out[a] |= jump
        out[b] |= jump
    return out


def azure(
    depth: np.ndarray,
    K: np.ndarray,
    rng: np.random.Generator,
    *,
    rgb: np.ndarray | None = None,
    sigma_0: float = 0.0005,
    sigma_slope: float = 0.001,
    z_0: float = 0.5,
    flying_threshold: float = 0.03,
    flying_connectivity: int = 8,
    dark_threshold: float = 0.1,
    dark_dropout: float = 1.0,
    noise_scale: float = 1.0,
) -> np.ndarray:
    """Time-of-flight sensor (Azure Kinect DK).

    * Axial noise: ``z += sigma N(0, 1)``, ``sigma = max(0.5 mm + 1 mm/m (z - 0.5 m), 0.5 mm)``
      (:func:`azure_sigma`; Azure Kinect DK hardware specification: random error std. dev.
      <= 17 mm; Tolgyessy, Dekan, Chovanec, Hubinsky 2021, "Evaluation of the Azure Kinect and its
      comparison to Kinect V1 and Kinect V2", Sensors 21(2):413).
    * Flying pixels: a ToF pixel straddling a depth step mixes both returns and the sensor's filter
      invalidates it. Here: no depth where the true depth differs from a valid 4- or 8-neighbour by
      more than ``flying_threshold`` (0.03 m, a few centimetres at table scale): one pixel on each
      side of every step.
    * Dark pixels (only when ``rgb`` is given): low-albedo surfaces return too little light.
      Luminance ``Y = (0.299 R + 0.587 G + 0.114 B) / 255`` (Rec. 601 luma of the 8-bit image);
      dropout probability ``dark_dropout * clip(1 - Y / dark_threshold, 0, 1)``: 0 at and above the
      threshold (0.1), rising linearly to ``dark_dropout`` (1) at black. No dropout without rgb.

    Args:
        depth: (H, W) float depth in metres, 0 = no measurement.
        K: (3, 3) intrinsics (validated; the model is per pixel).
        rng: random generator (:func:`sensor_rng`).
        rgb: optional (H, W, 3) uint8 colour image registered to depth.
        sigma_0: noise at and below ``z_0``, metres (0.0005).
        sigma_slope: noise growth, metres per metre of depth (0.001).
        z_0: depth where the growth starts, metres (0.5).
        flying_threshold: depth step that invalidates the pixels on both sides, metres (0.03).
        flying_connectivity: 4 or 8 neighbours (8).
        dark_threshold: luminance in [0, 1] below which pixels may drop out (0.1).
        dark_dropout: dropout probability at luminance 0, in [0, 1] (1.0).
        noise_scale: factor on sigma (1; 0 disables the noise).
    Returns:
        (H, W) float32 depth in metres, 0 where invalid.
    """
    z, valid = _as_depth(depth)
    _intrinsics(K)
    _check_rng(rng)
    rgb = _check_rgb(rgb, z.shape)
    sigma_0 = _check("sigma_0", sigma_0)
    sigma_slope = _check("sigma_slope", sigma_slope)
    flying_threshold = _check("flying_threshold", flying_threshold)
    dark_threshold = _check("dark_threshold", dark_threshold, hi=1.0)
    dark_dropout = _check("dark_dropout", dark_dropout, hi=1.0)
    noise_scale = _check("noise_scale", noise_scale)
    try:
        z_0 = float(z_0)
    except (TypeError, ValueError):
        z_0 = np.nan
    if not np.isfinite(z_0):
        raise ValueError("z_0 must be a finite depth in metres")
    if flying_connectivity not in (4, 8):
        raise ValueError(f"flying_connectivity must be 4 or 8, got {flying_connectivity!r}")
    if z.size == 0:
        return z
    A, B = np.empty_like(z), np.empty_like(z)
    ok = ~_edge_pixels(z, valid, flying_threshold, flying_connectivity, A)
    ok &= valid
    if rgb is not None and dark_threshold > 0 and dark_dropout > 0:
        k = _F32(1.0 / (255.0 * dark_threshold))
        np.multiply(rgb[..., 0], _F32(0.299) * k, out=A)
        for ch, w in ((1, 0.587), (2, 0.114)):
            np.multiply(rgb[..., ch], _F32(w) * k, out=B)
            A += B
        np.subtract(_F32(1.0), A, out=A)  # 1 - Y / threshold
        np.clip(A, _F32(0.0), _F32(1.0), out=A)
        A *= _F32(dark_dropout)
        ok &= rng.random(out=B, dtype=_F32) >= A
    if noise_scale > 0:
        np.subtract(z, _F32(z_0), out=A)
        A *= _F32(sigma_slope)
        A += _F32(sigma_0)
        np.maximum(A, _F32(sigma_0), out=A)
        A *= _F32(noise_scale)
        A *= rng.standard_normal(out=B, dtype=_F32)
        z += A
        ok &= z > 0
    np.copyto(z, _F32(0.0), where=~ok)
    return z


_MODELS = {"kinect": kinect, "realsense": realsense, "azure": azure}


def simulate_depth(
    depth: np.ndarray, K: np.ndarray, sensor: str, rng: np.random.Generator, rgb: np.ndarray | None = None, **params
) -> np.ndarray:
    """Simulate what ``sensor`` measures of a perfect depth map.

    Args:
        depth: (H, W) float depth in metres along the optical axis, 0 = no measurement (NaN, inf and
            negative values are read as 0).
        K: (3, 3) intrinsics, pixel-centre convention.
        sensor: one of :data:`SENSORS`: ``"ideal"`` (the input as float32, unchanged: the same bytes
            for a float32 input without NaN/inf/negatives; no randomness drawn), ``"kinect"``
            (:func:`kinect`), ``"realsense"`` (:func:`realsense`), ``"azure"`` (:func:`azure`).
        rng: random generator (:func:`sensor_rng`); required for every sensor, untouched by ``ideal``.
        rgb: optional (H, W, 3) uint8 colour image registered to depth; used by ``azure`` (dark-pixel
            dropout), validated and ignored by the others.
        **params: keyword parameters of the sensor's model (e.g. ``baseline``, ``noise_scale``).
    Returns:
        a new (H, W) float32 array in metres, 0.0 where invalid, never NaN or negative.
    Raises:
        ValueError: unknown sensor, or bad depth / K / rgb / rng / parameters.
    """
    if not isinstance(sensor, str) or sensor not in SENSORS:
        raise ValueError(f"unknown sensor {sensor!r}; valid choices: {', '.join(SENSORS)}")
    if sensor == "ideal":
        z, _ = _as_depth(depth)
        _intrinsics(K)
        _check_rng(rng)
        _check_rgb(rgb, z.shape)
        if params:
            raise ValueError(f"sensor 'ideal' takes no parameters, got {sorted(params)}")
        return z
    if sensor == "azure":
        return azure(depth, K, rng, rgb=rgb, **params)
    if rgb is not None:
        if not isinstance(depth, np.ndarray) or depth.ndim != 2:
            _as_depth(depth)  # raises the depth error first
        _check_rgb(rgb, depth.shape)
    return _MODELS[sensor](depth, K, rng, **params)
