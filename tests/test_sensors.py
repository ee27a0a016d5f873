"""Depth-sensor simulation (sixdpose.generation.sensors) against its published formulas.

Analytic scenes only (no rendering engine), 640x480, K = [[615, 0, 319], [0, 615, 239], [0, 0, 1]]:
fronto-parallel planes, a plane tilted about the camera's y axis, and a box (a raised rectangle
nearer the camera) on a plane.

Tolerances of the noise checks: a standard deviation estimated from N Gaussian samples has a
relative standard error of 1 / sqrt(2 N); over a 640x480 plane (N ~ 3e5) that is 0.13 %, over the
smaller regions below at most 0.4 %. The 2 % (3 % for ratios and the tilted plane) tolerances are
therefore > 5 standard errors, while a wrong constant in a formula (e.g. 0.0019 -> 0.0029, a missing
quantisation term, sigma in the wrong units) moves the figure by 10 % or more.
"""

from __future__ import annotations

import numpy as np
import pytest

from sixdpose.generation import sensors as S
from sixdpose.generation.sensors import (
    KINECT_SIMKINECT,
    SENSORS,
    azure,
    kinect,
    realsense,
    sensor_rng,
    simulate_depth,
    surface_angle,
)

H, W = 480, 640
F = 615.0
K = np.array([[F, 0.0, 319.0], [0.0, F, 239.0], [0.0, 0.0, 1.0]])
U = np.arange(W, dtype=np.float64)[None, :]
V = np.arange(H, dtype=np.float64)[:, None]
RX = (U - K[0, 2]) / F  # (1, W)
RY = (V - K[1, 2]) / F  # (H, 1)
NOISY = ("kinect", "realsense", "azure")

BOX = (slice(160, 320), slice(240, 400))  # rows, columns of the raised rectangle
Z_NEAR, Z_FAR = 0.8, 1.0


def plane(z0: float) -> np.ndarray:
    """Fronto-parallel plane at depth z0 (float32)."""
    return np.full((H, W), z0, dtype=np.float32)


def tilted(z0: float, alpha_deg: float, zmax: float = 4.0) -> np.ndarray:
    """Plane Z = z0 + tan(alpha) X (rotated by alpha about the camera's y axis, through (0, 0, z0)).

    On the ray through pixel (u, v), z = z0 / (1 - tan(alpha) r_x); depth is 0 where the plane is
    behind the camera or beyond ``zmax``."""
    den = 1.0 - np.tan(np.deg2rad(alpha_deg)) * RX
    z = np.where(den > 0, z0 / np.where(den > 0, den, 1.0), 0.0) * np.ones((H, 1))
    z[(z > zmax)] = 0.0
    return z.astype(np.float32)


def tilted_theta(alpha_deg: float) -> np.ndarray:
    """Analytic angle between the tilted plane's normal (-tan a, 0, 1) and the viewing rays."""
    t = np.tan(np.deg2rad(alpha_deg))
    cos = np.abs(1.0 - t * RX) / (np.sqrt(1 + t * t) * np.sqrt(RX**2 + RY**2 + 1))
    return np.arccos(np.clip(cos, 0, 1)) * np.ones((H, W))


def box_scene() -> np.ndarray:
    """A plane at Z_FAR with a raised rectangle (box top) at Z_NEAR over BOX."""
    d = plane(Z_FAR)
    d[BOX] = Z_NEAR
    return d


def nguyen(z, theta):
    return 0.0012 + 0.0019 * (z - 0.4) ** 2 + (0.0001 / np.sqrt(z)) * theta**2 / (np.pi / 2 - theta) ** 2


def kinect_quant_sigma(z, step=1 / 8, baseline=0.075):
    """Std of rounding the disparity to ``step`` px, in depth: step z^2 / (f B) / sqrt(12)."""
    return step * z**2 / (F * baseline) / np.sqrt(12)


def fronto_theta() -> np.ndarray:
    """Angle between a fronto-parallel plane's normal (0, 0, 1) and the viewing rays."""
    return np.arccos(1 / np.sqrt(RX**2 + RY**2 + 1)) * np.ones((H, W))


def run(sensor, depth, seed=0, **kw):
    return simulate_depth(depth, K, sensor, sensor_rng(seed, 0, 0), **kw)


# ------------------------------------------------------------------------------------------------
# geometry


def test_surface_angle_matches_analytic_planes():
    """theta from depth gradients equals the analytic angle on a fronto and a 60 deg plane, is 0
    where depth is 0 and on isolated pixels, and about pi/2 across a depth step."""
    th = surface_angle(plane(1.0), K)
    np.testing.assert_allclose(th, fronto_theta(), atol=1e-4)
    d = tilted(1.0, 60.0)
    th = surface_angle(d, K)
    ok = d > 0
    inner = ok.copy()
    inner[:, 1:] &= ok[:, :-1]
    inner[:, :-1] &= ok[:, 1:]
    assert inner.sum() > 0.5 * H * W
    np.testing.assert_allclose(th[inner], tilted_theta(60.0)[inner], atol=2e-3)
    assert np.all(th[~ok] == 0)
    iso = np.zeros((5, 5), np.float32)
    iso[2, 2] = 1.0
    assert surface_angle(iso, K).max() == 0.0
    th = surface_angle(box_scene(), K)
    assert th[240, 239] > np.deg2rad(85) and th[240, 240] > np.deg2rad(85)
    assert th[240, 300] < np.deg2rad(10)


# ------------------------------------------------------------------------------------------------
# noise against the formulas


@pytest.mark.parametrize("z0", [0.8, 1.5])
def test_kinect_flat_noise_matches_nguyen_plus_quantisation(z0):
    """Flat plane: all pixels valid; std(noisy - true) = sqrt(sigma_Nguyen^2 + q^2), q the 1/8 px
    disparity rounding (step z^2 / (f B) / sqrt(12)); the noise dithers the rounding (sigma/step
    >= 0.5 here, so its error is uniform and independent to < 0.1 %)."""
    d = plane(z0)
    out = run("kinect", d)
    assert out.dtype == np.float32 and out.shape == d.shape
    assert (out > 0).mean() == 1.0
    res = out.astype(np.float64) - z0
    expected = np.sqrt(np.mean(nguyen(z0, fronto_theta()) ** 2) + kinect_quant_sigma(z0) ** 2)
    assert res.std() == pytest.approx(expected, rel=0.02)
    assert abs(res.mean()) < 0.1 * expected  # unbiased


def test_kinect_quantisation_grid():
    """Without noise and jitter the output is the true depth rounded on the disparity grid
    fB / (k / 8): within half a step of the truth; with the full model every output value still lies
    on that grid (the noisy depth is quantised too)."""
    fb = F * 0.075
    d = tilted(1.0, 10.0)  # depths 0.92..1.1 m: disparity changes by 0.1 step per column
    clean = kinect(d, K, sensor_rng(0, 0, 0), pixel_shift_sigma=0.0, noise_scale=0.0)
    for out in (clean, run("kinect", d)):
        v = out[out > 0].astype(np.float64)
        k = fb / v * 8
        assert np.abs(k - np.round(k)).max() < 2e-3
    m = clean > 0
    half_step = 0.5 * (1 / 8) * d[m].astype(np.float64) ** 2 / fb
    assert np.all(np.abs(clean[m] - d[m]) <= half_step * 1.01 + 1e-6)
    assert np.unique(clean[m]).size < 0.2 * np.unique(d[m]).size  # genuinely quantised (~70 levels)


def test_kinect_pixel_jitter_is_rounded_gaussian():
    """Lateral jitter alone (noise and quantisation off) on a depth ramp of 1 mm per column: the
    column shift read back from the depth is round(N(0, 0.5^2)): P(0) = 0.683, P(+1) = P(-1) =
    0.157, P(|k| >= 2) = 0.003 (SE of each fraction < 0.001 over 3e5 pixels)."""
    d = (1.0 + 0.001 * U * np.ones((H, 1))).astype(np.float32)
    out = kinect(d, K, sensor_rng(0, 0, 0), noise_scale=0.0, disparity_step=0.0)
    inner = (slice(None), slice(4, W - 4))
    k = np.round((out[inner].astype(np.float64) - d[inner]) / 0.001)
    assert (out[inner] > 0).all()
    from scipy.special import ndtr

    p0, p1 = ndtr(1.0) - ndtr(-1.0), ndtr(3.0) - ndtr(1.0)
    assert (k == 0).mean() == pytest.approx(p0, abs=0.005)
    assert (k == 1).mean() == pytest.approx(p1, abs=0.005) and (k == -1).mean() == pytest.approx(p1, abs=0.005)
    assert (np.abs(k) >= 2).mean() < 0.005


def test_kinect_noise_grows_with_depth_and_tilt():
    """std at 1.5 m / std at 0.8 m equals the formulas' ratio (about 2.5); on a plane tilted by 70
    deg (jitter off, which would mix depths) the normalised residual has unit std and the noise is
    larger than on a fronto plane at the same depth, as the theta term of Nguyen et al. says."""
    s = {z0: (run("kinect", plane(z0)) - z0).std() for z0 in (0.8, 1.5)}
    f = {z0: np.sqrt(np.mean(nguyen(z0, fronto_theta()) ** 2) + kinect_quant_sigma(z0) ** 2) for z0 in (0.8, 1.5)}
    assert s[1.5] / s[0.8] == pytest.approx(f[1.5] / f[0.8], rel=0.03)
    assert s[1.5] / s[0.8] > 2.0

    d = tilted(1.0, 70.0)
    out = kinect(d, K, sensor_rng(0, 0, 0), pixel_shift_sigma=0.0).astype(np.float64)
    reg = (slice(100, 380), slice(240, 400))  # around the principal point, theta 67..73 deg
    z, o = d[reg].astype(np.float64), out[reg]
    assert (o > 0).mean() == 1.0
    expected = np.sqrt(nguyen(z, tilted_theta(70.0)[reg]) ** 2 + kinect_quant_sigma(z) ** 2)
    assert ((o - z) / expected).std() == pytest.approx(1.0, rel=0.03)
    # same depths, fronto-parallel: compare the raw noise in a 3-column band around u = cx (z ~ 1 m)
    band = (slice(100, 380), slice(318, 321))
    tilt_std = (out[band] - d[band]).std()
    flat_std = (run("kinect", plane(1.0))[band] - 1.0).std()
    ratio = np.sqrt(nguyen(1.0, np.deg2rad(70)) ** 2 + kinect_quant_sigma(1.0) ** 2) / np.sqrt(
        nguyen(1.0, 0.0) ** 2 + kinect_quant_sigma(1.0) ** 2
    )
    assert tilt_std / flat_std == pytest.approx(ratio, rel=0.1)  # 840 pixels each: SE ~ 3.5 %
    assert tilt_std > 1.4 * flat_std


@pytest.mark.parametrize("z0", [0.8, 1.5])
def test_realsense_flat_noise_matches_rms_formula(z0):
    """Flat plane: all valid; std = z^2 s / (f B) with s = 0.08 px, B = 0.05 m (1.7 mm at 0.8 m,
    5.9 mm at 1.5 m)."""
    out = run("realsense", plane(z0))
    assert (out > 0).mean() == 1.0
    res = out.astype(np.float64) - z0
    assert res.std() == pytest.approx(z0**2 * 0.08 / (F * 0.05), rel=0.02)
    assert abs(res.mean()) < 0.01 * res.std() * 10


def test_realsense_noise_grows_quadratically_and_grazing_is_invalid():
    """std ratio 1.5 m / 0.8 m = (1.5/0.8)^2; a plane at 80 deg (> 75 deg) gives no depth near the
    principal point, one at 60 deg does."""
    s = {z0: (run("realsense", plane(z0)) - z0).std() for z0 in (0.8, 1.5)}
    assert s[1.5] / s[0.8] == pytest.approx((1.5 / 0.8) ** 2, rel=0.03)
    reg = (slice(200, 280), slice(280, 360))
    assert (run("realsense", tilted(1.0, 80.0))[reg] > 0).mean() < 0.01
    assert (run("realsense", tilted(1.0, 60.0))[reg] > 0).mean() == 1.0


@pytest.mark.parametrize("z0", [0.8, 1.5])
def test_azure_flat_noise_matches_model(z0):
    """Flat plane: all valid; std = 0.5 mm + 1 mm/m (z - 0.5) (0.8 mm at 0.8 m, 1.5 mm at 1.5 m)."""
    out = run("azure", plane(z0))
    assert (out > 0).mean() == 1.0
    res = out.astype(np.float64) - z0
    assert res.std() == pytest.approx(0.0005 + 0.001 * (z0 - 0.5), rel=0.02)
    assert (run("azure", plane(1.5)) - 1.5).std() / (run("azure", plane(0.8)) - 0.8).std() == pytest.approx(
        1.5 / 0.8, rel=0.03
    )


def test_azure_sigma_floor():
    """Below 0.5 m the model's sigma stays at its 0.5 mm floor (not 0.5 mm - ...)."""
    res = run("azure", plane(0.3)).astype(np.float64) - 0.3
    assert res.std() == pytest.approx(0.0005, rel=0.02)


# ------------------------------------------------------------------------------------------------
# hole patterns


def _rows_invalid(out, cols):
    """Per-row count of invalid pixels over ``cols`` in the rows away from the box's corners."""
    return (out[180:300, cols] == 0).sum(axis=1)


def test_kinect_holes_projector_shadow_and_edges():
    """Box at 0.8 m on a plane at 1.0 m. Projector at +x (B = 7.5 cm): the background just left of
    the box (-x side, light from +x casts its shadow towards -x) is shadowed over
    f B (1/0.8 - 1/1.0) = 11.5 px, plus the window filter's erosion (<= window // 2 = 4 px); the right
    edge (no shadow) loses only the window filter's pixels on both sides (1 to 4 px each, 5 where
    the +-1 px jitter moved the edge). Far from the box nothing is lost. simkinect's window
    (:data:`KINECT_SIMKINECT`), whose erosion is wide enough to measure per side."""
    out = run("kinect", box_scene(), **KINECT_SIMKINECT)
    band = F * 0.075 * (1 / Z_NEAR - 1 / Z_FAR)
    left_bg = _rows_invalid(out, slice(200, 240))
    right_bg = _rows_invalid(out, slice(400, 440))
    left_box, right_box = _rows_invalid(out, slice(240, 280)), _rows_invalid(out, slice(360, 400))
    assert np.all(left_bg >= np.floor(band)) and np.all(left_bg <= band + 4 + 1)
    for side in (right_bg, left_box, right_box):
        assert np.all((side >= 1) & (side <= 4 + 1)) and np.median(side) <= 4
    assert np.median(left_bg) >= np.median(right_bg) + np.floor(band) - 1
    # holes along the top and bottom edges too, none away from the box
    assert (out[150:160, 260:380] == 0).mean() > 0.3 and (out[320:330, 260:380] == 0).mean() > 0.3
    far = np.ones((H, W), bool)
    far[140:340, 200:420] = False
    assert (out[far] > 0).all()


def test_kinect_negative_baseline_moves_shadow_to_plus_x():
    """With the projector at -x the shadow band moves to the box's +x side."""
    out = kinect(box_scene(), K, sensor_rng(0, 0, 0), baseline=-0.075, **KINECT_SIMKINECT)
    band = F * 0.075 * (1 / Z_NEAR - 1 / Z_FAR)
    assert np.all(_rows_invalid(out, slice(400, 440)) >= np.floor(band))
    assert np.all(_rows_invalid(out, slice(200, 240)) <= 4 + 1)


def test_realsense_occlusion_band_left_of_box():
    """Right camera at +x (B = 5 cm): the left camera's occlusion band lies on the -x side of the
    box, f B (1/0.8 - 1/1.0) = 7.7 px wide (7 whole pixels); the other side and the box's own rim
    lose only the 1 px whose depth gradient spans the step (grazing)."""
    out = run("realsense", box_scene())
    band = F * 0.05 * (1 / Z_NEAR - 1 / Z_FAR)
    left_bg = _rows_invalid(out, slice(200, 240))
    assert np.all(np.abs(left_bg - band) <= 1.0)
    assert np.all(_rows_invalid(out, slice(400, 440)) == 1)
    assert np.all(_rows_invalid(out, slice(240, 280)) == 1) and np.all(_rows_invalid(out, slice(360, 400)) == 1)
    assert np.all(out[240, 233:240] == 0) and out[240, 231] > 0
    far = np.ones((H, W), bool)
    far[150:330, 225:410] = False
    assert (out[far] > 0).all()


def test_azure_flying_pixels_at_box_edges_only():
    """Both pixels across every box edge (step 0.2 m > 0.03 m) are removed, symmetric (no shadow);
    a 2 cm step (below the threshold) keeps every pixel."""
    out = run("azure", box_scene())
    inv = out == 0
    assert inv[240, [239, 240, 399, 400]].all() and not inv[240, [237, 242, 397, 402]].any()
    assert inv[[159, 160, 319, 320], 300].all() and not inv[[157, 162, 317, 322], 300].any()
    # 8-connectivity: the diagonal neighbour of the box's corner is removed too
    assert inv[159, 239] and inv[320, 400]
    n_edge = inv.sum()
    assert n_edge == pytest.approx(2 * (2 * 160 + 2 * 160) + 4, abs=8)
    d = plane(1.0)
    d[BOX] = 0.98
    assert (run("azure", d) > 0).all()
    four = azure(box_scene(), K, sensor_rng(0, 0, 0), flying_connectivity=4)
    assert four[159, 239] != 0 and (four[240, 239] == 0)


def test_azure_dark_pixel_dropout():
    """Luminance 13/255 = 0.051 (half the 0.1 threshold) drops 1 - 0.051/0.1 = 49 % of pixels, black
    drops all, bright (200) none; without rgb there is no dropout."""
    d = plane(1.0)
    rgb = np.full((H, W, 3), 200, np.uint8)
    rgb[:, :200] = 13
    rgb[:, 200:300] = 0
    out = simulate_depth(d, K, "azure", sensor_rng(0, 0, 0), rgb=rgb)
    p = 1 - (13 / 255) / 0.1
    assert (out[:, :200] == 0).mean() == pytest.approx(p, abs=0.01)  # SE 0.0016
    assert (out[:, 200:300] == 0).all()
    assert (out[:, 300:] > 0).all()
    assert (run("azure", d) > 0).all()


# ------------------------------------------------------------------------------------------------
# determinism and robustness


def test_ideal_identical_bytes_and_no_randomness():
    d = box_scene()
    rng = sensor_rng(0, 0, 0)
    state = rng.bit_generator.state
    out = simulate_depth(d, K, "ideal", rng)
    assert out.tobytes() == d.tobytes() and out.dtype == np.float32 and out is not d
    assert rng.bit_generator.state == state


@pytest.mark.parametrize("sensor", NOISY)
def test_reproducible_per_seed_scene_view(sensor):
    """Same (seed, scene, view) -> identical bytes, whatever else ran before (worker split);
    any other triple -> different output."""
    d = box_scene()
    a = simulate_depth(d, K, sensor, sensor_rng(7, 3, 5))
    simulate_depth(d, K, sensor, sensor_rng(7, 3, 4))  # another view in between
    b = simulate_depth(d, K, sensor, sensor_rng(7, 3, 5))
    assert a.tobytes() == b.tobytes()
    for other in ((7, 3, 6), (7, 4, 5), (8, 3, 5)):
        assert a.tobytes() != simulate_depth(d, K, sensor, sensor_rng(*other)).tobytes()
    assert np.array_equal(
        sensor_rng(7, 3, 5).random(4), np.random.default_rng([7, 3, 5, S.SENSOR_RNG_TAG]).random(4)
    )
    assert not np.array_equal(sensor_rng(7, 3, 5).random(4), np.random.default_rng([7, 3, 5]).random(4))


@pytest.mark.parametrize("sensor", SENSORS)
def test_nan_inf_negative_and_small_inputs(sensor):
    """NaN/inf/negative input pixels are 'no measurement'; outputs are float32, finite, >= 0 and 0
    there; depths so close that noise crosses 0 are dropped, not negative; any size works. The
    kinect's lateral jitter (round(N(0, 0.5^2)) px per axis) may move a neighbour's depth up to
    ``reach`` = 3 px into a hole (P(|shift| > 3) < 1e-9), which its calibrated 3 x 3 validity window
    does not always remove: there only pixels farther than that from any valid input must stay 0."""
    from scipy import ndimage

    reach = 3 if sensor == "kinect" else 0

    def far_from_valid(z):
        bad = ~(np.isfinite(z) & (z > 0))
        return ndimage.binary_erosion(bad, np.ones((3, 3), bool), iterations=reach, border_value=1) if reach else bad

    d = box_scene().astype(np.float64)
    d[10:20, 10:20] = np.nan
    d[30:40, 30:40] = np.inf
    d[50:60, 50:60] = -1.0
    d[400:, :] = 0.0015  # noise (>= 0.5 mm) may push these below 0
    out = run(sensor, d)
    assert out.dtype == np.float32 and out.shape == d.shape
    assert np.isfinite(out).all() and (out >= 0).all()
    holes = far_from_valid(d)
    assert holes[10:20, 10:20].sum() == (10 - 2 * reach) ** 2 and (out[:100, :100][holes[:100, :100]] == 0).all()
    rng = np.random.default_rng(1)
    for shape in ((1, 1), (1, 7), (7, 1), (2, 2), (3, 5), (17, 23), (64, 48)):
        crop = (rng.uniform(0.5, 1.5, shape) * (rng.random(shape) > 0.3)).astype(np.float32)
        o = simulate_depth(crop, K, sensor, sensor_rng(0, 0, 0))
        assert o.shape == shape and o.dtype == np.float32 and np.isfinite(o).all() and (o >= 0).all()
        assert (o[far_from_valid(crop)] == 0).all()
    assert simulate_depth(np.zeros((0, 5), np.float32), K, sensor, sensor_rng(0, 0, 0)).shape == (0, 5)
    assert (simulate_depth(np.zeros((8, 8), np.float32), K, sensor, sensor_rng(0, 0, 0)) == 0).all()


def test_input_not_modified():
    d = box_scene()
    d[0, 0] = np.nan
    before = d.copy()
    for sensor in SENSORS:
        simulate_depth(d, K, sensor, sensor_rng(0, 0, 0))
    np.testing.assert_array_equal(d, before)


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda d, r: simulate_depth(d, K, "kinect2", r), "valid choices: ideal, kinect, realsense, azure"),
        (lambda d, r: simulate_depth(d[None], K, "kinect", r), "2-D"),
        (lambda d, r: simulate_depth(d.astype(np.uint16), K, "ideal", r), "float"),
        (lambda d, r: simulate_depth(list(d), K, "azure", r), "numpy array"),
        (lambda d, r: simulate_depth(d, K[:2], "realsense", r), r"\(3, 3\)"),
        (lambda d, r: simulate_depth(d, np.diag([0.0, 615.0, 1.0]), "kinect", r), "positive focal"),
        (lambda d, r: simulate_depth(d, K, "kinect", 0), "Generator"),
        (lambda d, r: simulate_depth(d, K, "azure", r, rgb=np.zeros((H, W, 3), np.float32)), "uint8"),
        (lambda d, r: simulate_depth(d, K, "kinect", r, rgb=np.zeros((H, W), np.uint8)), "uint8 array of shape"),
        (lambda d, r: simulate_depth(d, K, "ideal", r, rgb=np.zeros((10, 10, 3), np.uint8)), "matching depth"),
        (lambda d, r: simulate_depth(d, K, "ideal", r, baseline=0.1), "takes no parameters"),
        (lambda d, r: kinect(d, K, r, baseline=0.0), "baseline"),
        (lambda d, r: kinect(d, K, r, window=8), "odd"),
        (lambda d, r: kinect(d, K, r, pixel_shift_sigma=-1), "pixel_shift_sigma"),
        (lambda d, r: kinect(d, K, r, max_angle=2.0), "max_angle"),
        (lambda d, r: realsense(d, K, r, subpixel=float("nan")), "subpixel"),
        (lambda d, r: azure(d, K, r, dark_dropout=1.5), "dark_dropout"),
        (lambda d, r: azure(d, K, r, flying_connectivity=6), "4 or 8"),
        (lambda d, r: sensor_rng(-1, 0, 0), "seed"),
        (lambda d, r: sensor_rng(0, 1.5, 0), "scene"),
    ],
)
def test_bad_arguments_raise_value_error(call, match):
    with pytest.raises(ValueError, match=match):
        call(plane(1.0), sensor_rng(0, 0, 0))


def test_unknown_keyword_raises_type_error():
    """A misspelt model parameter is not silently ignored."""
    with pytest.raises(TypeError):
        simulate_depth(plane(1.0), K, "kinect", sensor_rng(0, 0, 0), baseline_m=0.1)


# ------------------------------------------------------------------------------------------------
# calibration measurement (sixdpose.generation.checks)


def _square_case():
    """A 10 x 10 mask in a 20 x 20 image; with a 3 px rim its interior is the central 4 x 4. Holes:
    a 2 x 2 block inside (0 depth), 3 rim pixels (NaN, inf, -1) and 5 pixels outside the mask."""
    depth = np.full((20, 20), 0.8, np.float32)
    mask = np.zeros((20, 20), bool)
    mask[5:15, 5:15] = True
    depth[9:11, 9:11] = 0.0
    depth[5, 5], depth[14, 8], depth[7, 13] = np.nan, np.inf, -1.0
    depth[0, :5] = 0.0
    return depth, mask


def test_mask_hole_counts_hand_made():
    """Counts of a hand-made mask and depth: 100 masked px, 84 in the 3 px rim, 16 inside; holes 3 in
    the rim, 4 inside, none counted outside the mask; edge_px=0 puts every pixel in the interior."""
    from sixdpose.generation.checks import mask_hole_counts

    depth, mask = _square_case()
    assert mask_hole_counts(depth, mask, 3) == {"px": 100, "holes": 7, "edge_px": 84, "edge_holes": 3,
                                                "interior_px": 16, "interior_holes": 4}
    c = mask_hole_counts(depth, mask, 1)
    assert (c["edge_px"], c["edge_holes"], c["interior_px"], c["interior_holes"]) == (36, 2, 64, 5)
    assert mask_hole_counts(depth, mask, 0)["interior_holes"] == 7
    full = np.ones((20, 20), bool)  # the image border counts as the mask's boundary
    assert mask_hole_counts(depth, full, 3)["edge_px"] == 400 - 14 * 14
    with pytest.raises(ValueError, match="same"):
        mask_hole_counts(depth, mask[:10], 3)


def test_depth_hole_stats_pools_instances_and_depth_fn():
    """depth_hole_stats pools the pixels of every instance of every image (not a mean of ratios) and
    a depth_fn replaces the stored depth."""
    from sixdpose.datasets.base import Instance, KeyedImages, Sample
    from sixdpose.generation.checks import depth_hole_stats

    depth, mask = _square_case()
    small = np.zeros((20, 20), bool)
    small[0:2, 0:10] = True  # 20 px, all rim; 5 holes (row 0, columns 0-4)
    inst = [Instance("a", 1, 0, np.eye(3), np.zeros(3), mask), Instance("b", 2, 0, np.eye(3), np.zeros(3), small)]

    class Reader(KeyedImages):
        location, has_depth, has_masks, manifest = "mem", True, True, {}

        def load(self, key, *, masks=True, rgb=True, depth=True):
            return Sample(key[0], key[1], None, _square_case()[0], np.eye(3), list(inst))

        def model(self, obj_id):
            raise KeyError(obj_id)

        @property
        def object_ids(self):
            return {1: "a", 2: "b"}

    r = Reader()
    r._keys, r.load_masks = [(0, 0), (0, 1)], True
    st = depth_hole_stats(r)
    assert (st["images"], st["instances"], st["px"]) == (2, 4, 240)
    assert st["hole"] == pytest.approx(2 * 12 / 240)
    assert st["edge_hole"] == pytest.approx(2 * 8 / (2 * 104))
    assert st["interior_hole"] == pytest.approx(4 / 16)
    st = depth_hole_stats(r, depth_fn=lambda s: np.zeros((20, 20), np.float32), scenes=[0], max_images=1)
    assert (st["images"], st["hole"], st["edge_hole"], st["interior_hole"]) == (1, 1.0, 1.0, 1.0)
    assert depth_hole_stats(r, scenes=[5])["instances"] == 0


def test_kinect_calibrated_window_erodes_one_pixel():
    """The calibrated defaults (3 x 3 window) lose at most window // 2 = 1 px (+1 where the jitter
    moved the edge) each side of an unshadowed depth step, where simkinect's 9 x 9 loses up to 4."""
    out = run("kinect", box_scene())
    for cols in (slice(400, 440), slice(240, 280), slice(360, 400)):
        side = _rows_invalid(out, cols)
        assert np.all(side <= 2) and np.median(side) <= 1
    band = F * 0.075 * (1 / Z_NEAR - 1 / Z_FAR)
    assert np.all(_rows_invalid(out, slice(200, 240)) >= np.floor(band) - 1)
