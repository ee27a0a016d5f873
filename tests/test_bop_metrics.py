"""BOP 2019 metrics (appended to sixdpose.evaluation.metrics) against brute-force references."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sixdpose.evaluation import metrics as M

# ------------------------------------------------------------------------------------------
# brute-force references (plain loops, written independently of the implementation)
# ------------------------------------------------------------------------------------------
K = np.array([[450.0, 0.0, 32.0], [0.0, 450.0, 24.0], [0.0, 0.0, 1.0]])
W, H = 64, 48


def _brute_mssd(Re, te, Rg, tg, pts, syms):
    best = math.inf
    for Rs, ts in syms:
        worst = 0.0
        for x in pts:
            a = Re @ x + te
            b = Rg @ (Rs @ x + ts) + tg
            worst = max(worst, math.dist(a, b))
        best = min(best, worst)
    return best


def _proj(X):
    u = K[0, 0] * X[0] / X[2] + K[0, 1] * X[1] / X[2] + K[0, 2]
    v = K[1, 1] * X[1] / X[2] + K[1, 2]
    return np.array([u, v])


def _brute_mspd(Re, te, Rg, tg, pts, syms):
    best = math.inf
    for Rs, ts in syms:
        worst = 0.0
        for x in pts:
            worst = max(worst, math.dist(_proj(Re @ x + te), _proj(Rg @ (Rs @ x + ts) + tg)))
        best = min(best, worst)
    return best


def _brute_vsd(depth_test, depth_est, depth_gt, delta, taus, diameter, cost_type):
    """Per-pixel VSD (bop19 visibility) from three depth images."""

    def dist(d, u, v):
        X = (u - K[0, 2]) / K[0, 0] * d
        Y = (v - K[1, 2]) / K[1, 1] * d
        return math.sqrt(X * X + Y * Y + d * d)

    def visible(dt, dm):
        return dm > 0 and (float(np.float32(dm) - np.float32(dt)) <= delta or dt == 0)

    n_union, n_inter, dists = 0, 0, []
    for v in range(depth_test.shape[0]):
        for u in range(depth_test.shape[1]):
            dt = dist(float(depth_test[v, u]), u, v)
            de = dist(float(depth_est[v, u]), u, v)
            dg = dist(float(depth_gt[v, u]), u, v)
            vg = visible(dt, dg)
            ve = visible(dt, de) or (vg and de > 0)
            if vg or ve:
                n_union += 1
            if vg and ve:
                n_inter += 1
                dists.append(abs(dg - de) / diameter)
    if n_union == 0:
        return [1.0] * len(taus)
    out = []
    for tau in taus:
        c = sum(1.0 for d in dists if d >= tau) if cost_type == "step" else sum(min(1.0, d / tau) for d in dists)
        out.append((c + n_union - n_inter) / n_union)
    return out


def _brute_recall(errors, thresholds):
    """Mean over thresholds of the fraction of errors strictly below the threshold."""
    total = 0.0
    for th in thresholds:
        total += sum(1 for e in errors if e < th) / len(errors)
    return total / len(thresholds)


def _brute_auc(errors, T=0.1):
    """Exact area under the step curve acc(x) = #(e < x)/n on [0, T], in percent."""
    es = sorted(e for e in errors if e < T)
    n = len(errors)
    area, prev = 0.0, 0.0
    for k, e in enumerate(es):  # on [prev, e) accuracy is k / n
        area += (e - prev) * k / n
        prev = e
    area += (T - prev) * len(es) / n
    return 100.0 * area / T


def _box(half):
    """Axis-aligned box mesh centred at the origin: (8, 3) vertices, (12, 3) triangles."""
    hx, hy, hz = half
    v = np.array([[sx * hx, sy * hy, sz * hz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)
    f = np.array(
        [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
         [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]
    )
    return v, f


# ------------------------------------------------------------------------------------------
# symmetry transformations
# ------------------------------------------------------------------------------------------
def test_symmetry_transformations_hand_example():
    info = {
        "diameter": 100.0,
        "symmetries_discrete": [[-1, 0, 0, 10, 0, -1, 0, 20, 0, 0, 1, 0, 0, 0, 0, 1]],
        "symmetries_continuous": [{"axis": [0, 0, 2], "offset": [5, 0, 0]}],
    }
    # max step 2 -> ceil(pi / 2) = 2 continuous steps: rotations by 0 and pi about z through (5, 0, 0) mm
    syms = M.symmetry_transformations(info, max_sym_disc_step=2.0)
    Rpi = np.diag([-1.0, -1.0, 1.0])
    expected = [
        (np.eye(3), [0, 0, 0]),  # identity x identity
        (Rpi, [0.010, 0, 0]),  # continuous pi: t = o - R o = (10, 0, 0) mm
        (Rpi, [0.010, 0.020, 0]),  # identity x discrete
        (np.eye(3), [0.010 - 0.010, -0.020, 0]),  # pi x discrete: R td + tc
    ]
    assert len(syms) == 4
    for (R, t), (Re, te) in zip(syms, expected, strict=True):
        np.testing.assert_allclose(R, Re, atol=1e-12)
        np.testing.assert_allclose(t, te, atol=1e-12)
        assert t.shape == (3,)


def test_symmetry_transformations_count_and_orthogonality():
    cont = {"symmetries_continuous": [{"axis": [1, 1, 0], "offset": [0, 0, 30]}]}
    syms = M.symmetry_transformations(cont)  # default step 0.01
    assert len(syms) == 315 == math.ceil(math.pi / 0.01)
    axis = np.array([1, 1, 0]) / math.sqrt(2)
    o = np.array([0, 0, 0.030])
    angles = []
    for R, t in syms:
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)
        np.testing.assert_allclose(R @ axis, axis, atol=1e-12)  # rotation about the axis ...
        np.testing.assert_allclose(R @ o + t, o, atol=1e-12)  # ... through the offset (metres)
        angles.append(Rotation.from_matrix(R).as_rotvec() @ axis)
    steps = np.diff(np.sort(np.mod(angles, 2 * np.pi)))
    np.testing.assert_allclose(steps, 2 * np.pi / 315, atol=1e-9)
    assert len(M.symmetry_transformations({})) == 1
    disc = {"symmetries_discrete": [np.eye(4).ravel().tolist()] * 2}
    assert len(M.symmetry_transformations(disc)) == 3
    both = dict(cont, **disc)
    assert len(M.symmetry_transformations(both, 0.05)) == 3 * math.ceil(math.pi / 0.05)


@pytest.mark.parametrize(
    "info, field",
    [
        ({"symmetries_discrete": [[1, 0, 0]]}, "symmetries_discrete[0]"),
        ({"symmetries_discrete": [list(range(16)), ["a"] * 16]}, "symmetries_discrete[1]"),
        ({"symmetries_discrete": [[True] * 16]}, "symmetries_discrete[0]"),
        ({"symmetries_continuous": [{"axis": [0, 0, 0], "offset": [0, 0, 0]}]}, "symmetries_continuous[0].axis"),
        ({"symmetries_continuous": [{"axis": [0, 0, 1], "offset": [0, 0]}]}, "symmetries_continuous[0].offset"),
        ({"symmetries_continuous": [{"axis": [0, 0, 1]}]}, "symmetries_continuous[0].offset"),
        ({"symmetries_continuous": [{"axis": "z", "offset": [0, 0, 0]}]}, "symmetries_continuous[0].axis"),
        (
            {"symmetries_continuous": [{"axis": [0, float("nan"), 1], "offset": [0, 0, 0]}]},
            "symmetries_continuous[0].axis",
        ),
    ],
)
def test_symmetry_transformations_malformed(info, field):
    with pytest.raises(ValueError) as ei:
        M.symmetry_transformations(info)
    assert field in str(ei.value)


# ------------------------------------------------------------------------------------------
# MSSD / MSPD
# ------------------------------------------------------------------------------------------
@pytest.fixture
def sym_object():
    """A point set symmetric under a 180 degree turn about the z axis through (10, 20, 0) mm."""
    rng = np.random.default_rng(7)
    c = np.array([0.010, 0.020, 0.0])
    half = rng.normal(size=(20, 3)) * [0.04, 0.03, 0.05]
    Rz = np.diag([-1.0, -1.0, 1.0])
    pts = np.vstack([half, (half - c) @ Rz.T + c])
    info = {"symmetries_discrete": [[-1, 0, 0, 20, 0, -1, 0, 40, 0, 0, 1, 0, 0, 0, 0, 1]]}
    Rg = Rotation.from_euler("xyz", [20, -35, 60], degrees=True).as_matrix()
    tg = np.array([0.05, -0.03, 0.7])
    return pts, M.symmetry_transformations(info), Rg, tg


def test_mssd_mspd_zero_for_symmetric_pose(sym_object):
    pts, syms, Rg, tg = sym_object
    Rs, ts = syms[1]
    Re, te = Rg @ Rs, Rg @ ts + tg  # the GT pose composed with the object's symmetry
    assert M.mssd(Re, te, Rg, tg, pts, syms) == pytest.approx(0.0, abs=1e-12)
    assert M.mspd(Re, te, Rg, tg, K, pts, syms) == pytest.approx(0.0, abs=1e-9)
    # without the symmetry the same pose is far off
    assert M.mssd(Re, te, Rg, tg, pts, None) > 0.05
    assert M.mspd(Re, te, Rg, tg, K, pts, syms[:1]) > 20.0
    # bop_toolkit-style dict symmetries and (3, 1) translations are accepted too
    dsyms = [{"R": R, "t": t.reshape(3, 1)} for R, t in syms]
    assert M.mssd(Re, te.reshape(3, 1), Rg, tg.reshape(3, 1), pts, dsyms) == pytest.approx(0.0, abs=1e-12)


def test_mssd_mspd_match_brute_force(sym_object):
    pts, syms, Rg, tg = sym_object
    for seed in range(4):
        Re = Rotation.from_rotvec(np.random.default_rng(seed).normal(size=3) * 0.3).as_matrix() @ Rg
        te = tg + np.random.default_rng(100 + seed).normal(size=3) * 0.01
        assert M.mssd(Re, te, Rg, tg, pts, syms) == pytest.approx(_brute_mssd(Re, te, Rg, tg, pts, syms), rel=1e-12)
        assert M.mspd(Re, te, Rg, tg, K, pts, syms) == pytest.approx(_brute_mspd(Re, te, Rg, tg, pts, syms), rel=1e-10)
        ident = syms[:1]
        assert M.mssd(Re, te, Rg, tg, pts, ident) == pytest.approx(_brute_mssd(Re, te, Rg, tg, pts, ident), rel=1e-12)
        assert M.mssd(Re, te, Rg, tg, pts, ident) >= M.mssd(Re, te, Rg, tg, pts, syms)


def test_mssd_mspd_continuous_symmetry():
    rng = np.random.default_rng(11)
    pts = rng.normal(size=(30, 3)) * [0.03, 0.03, 0.06] + [0.0, 0.0, 0.01]
    info = {"symmetries_continuous": [{"axis": [0, 0, 1], "offset": [0, 0, 10]}]}
    syms = M.symmetry_transformations(info, max_sym_disc_step=0.05)  # 63 steps
    assert len(syms) == 63
    Rg = Rotation.from_euler("zyx", [10, 50, -20], degrees=True).as_matrix()
    tg = np.array([0.0, 0.02, 0.6])
    r_max = np.linalg.norm(pts[:, :2], axis=1).max()
    # a turn about the symmetry axis that is not on the discretisation grid: small, not zero
    Rz = Rotation.from_euler("z", 37, degrees=True).as_matrix()
    Re, te = Rg @ Rz, tg
    e = M.mssd(Re, te, Rg, tg, pts, syms)
    assert 0 < e <= r_max * (math.pi / 63) + 1e-12
    assert e == pytest.approx(_brute_mssd(Re, te, Rg, tg, pts, syms), rel=1e-12)
    assert M.mspd(Re, te, Rg, tg, K, pts, syms) == pytest.approx(_brute_mspd(Re, te, Rg, tg, pts, syms), rel=1e-10)
    # a turn about the axis on the grid (k * 2 pi / 63): exactly zero
    Rk = Rotation.from_euler("z", 5 * 2 * math.pi / 63).as_matrix()
    assert M.mssd(Rg @ Rk, tg, Rg, tg, pts, syms) == pytest.approx(0.0, abs=1e-12)
    # a turn about another axis is not a symmetry
    Rx = Rotation.from_euler("x", 90, degrees=True).as_matrix()
    assert M.mssd(Rg @ Rx, tg, Rg, tg, pts, syms) > 0.05
    assert M.mspd(Rg @ Rx, tg, Rg, tg, K, pts, syms) > 30.0


# ------------------------------------------------------------------------------------------
# rendering
# ------------------------------------------------------------------------------------------
def test_render_depth_box_analytic_and_pixel_centres():
    a = 0.0105  # half side: the front face projects to u in 32 +- 10.5, v in 24 +- 10.5 px
    v, f = _box((a, a, a))
    depth = M.render_depth(v, f, np.eye(3), [0, 0, 0.45 + a], K, W, H)
    assert depth.shape == (H, W) and depth.dtype == np.float32
    expected = np.zeros((H, W), bool)
    expected[14:35, 22:43] = True  # pixel centres at integer coordinates: 21.5 < u < 42.5, 13.5 < v < 34.5
    np.testing.assert_array_equal(depth > 0, expected)
    np.testing.assert_allclose(depth[expected], 0.45, atol=1e-6)


def test_render_depth_tilted_plane_is_z_not_ray_length():
    v = np.array([[-0.5, -0.5, 0], [0.5, -0.5, 0], [0.5, 0.5, 0], [-0.5, 0.5, 0]], float)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    R = Rotation.from_euler("xy", [30, -20], degrees=True).as_matrix()
    t = np.array([0.01, -0.02, 0.8])
    depth = M.render_depth(v, f, R, t, K, W, H)
    n = R[:, 2]
    us, vs = np.meshgrid(np.arange(W), np.arange(H))
    d = np.stack([(us - K[0, 2]) / K[0, 0], (vs - K[1, 2]) / K[1, 1], np.ones_like(us, float)], axis=-1)
    z = (n @ t) / (d @ n)  # plane n.(X - t) = 0 with X = z d
    assert np.all(depth > 0)
    np.testing.assert_allclose(depth, z, atol=1e-5)
    assert np.ptp(depth) > 0.01  # really tilted
    # behind the camera: nothing
    assert not np.any(M.render_depth(v, f, R, -t, K, W, H))


# ------------------------------------------------------------------------------------------
# VSD
# ------------------------------------------------------------------------------------------
@pytest.fixture
def vsd_scene():
    v, f = _box((0.015, 0.01, 0.02))
    Rg = Rotation.from_euler("xyz", [25, 40, 10], degrees=True).as_matrix()
    tg = np.array([0.002, -0.001, 0.5])
    depth = M.render_depth(v, f, Rg, tg, K, W, H).astype(np.float64)
    depth[depth == 0] = 0.65  # background plane
    diameter = 2 * np.linalg.norm([0.015, 0.01, 0.02])
    return v, f, Rg, tg, depth, diameter


def test_vsd_zero_for_gt_and_positive_for_shift(vsd_scene):
    v, f, Rg, tg, depth, diam = vsd_scene
    taus = M.BOP19_VSD_TAUS
    e0 = M.vsd(Rg, tg, Rg, tg, depth, K, M.BOP19_VSD_DELTA, taus, True, diam, v, f)
    assert len(e0) == len(taus) and e0 == [0.0] * len(taus)
    e1 = M.vsd(Rg, tg + [0.008, 0, 0], Rg, tg, depth, K, M.BOP19_VSD_DELTA, taus, True, diam, v, f)
    assert all(0 < e <= 1 for e in e1)
    assert all(x >= y for x, y in zip(e1, e1[1:], strict=False))  # non-increasing in tau
    # an estimate outside the image: nothing in common with the GT -> 1
    e2 = M.vsd(Rg, tg + [1.0, 0, 0], Rg, tg, depth, K, M.BOP19_VSD_DELTA, taus, True, diam, v, f)
    assert e2 == [1.0] * len(taus)


@pytest.mark.parametrize("cost_type", ["step", "tlinear"])
def test_vsd_matches_brute_force(vsd_scene, cost_type):
    v, f, Rg, tg, depth, diam = vsd_scene
    rng = np.random.default_rng(5)
    test = depth + rng.normal(scale=0.002, size=depth.shape)
    test[rng.random(depth.shape) < 0.1] = 0.0  # missing measurements
    test[10:20, 25:40] = 0.45  # an occluder in front of part of the object
    Re = Rotation.from_euler("y", 12, degrees=True).as_matrix() @ Rg
    te = tg + [0.004, 0.002, 0.006]
    taus = [0.02, 0.05, 0.1, 0.3, 0.5]
    got = M.vsd(Re, te, Rg, tg, test, K, 0.015, taus, True, diam, v, f, cost_type=cost_type)
    d_est = M.render_depth(v, f, Re, te, K, W, H)
    d_gt = M.render_depth(v, f, Rg, tg, K, W, H)
    ref = _brute_vsd(test, d_est, d_gt, 0.015, taus, diam, cost_type)
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-12)
    assert 0 < got[-1] < got[0] < 1
    # not normalised: taus in metres
    got_m = M.vsd(Re, te, Rg, tg, test, K, 0.015, [t * diam for t in taus], False, diam, v, f, cost_type=cost_type)
    np.testing.assert_allclose(got_m, ref, rtol=1e-9, atol=1e-12)


def test_depth_to_distance_brute_force():
    rng = np.random.default_rng(2)
    d = rng.uniform(0.3, 1.0, size=(5, 7))
    d[1, 2] = 0
    dist = M.depth_to_distance(d, K)
    for v in range(5):
        for u in range(7):
            X = np.array([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], 1.0]) * d[v, u]
            assert dist[v, u] == pytest.approx(np.linalg.norm(X), rel=1e-12, abs=1e-15)


# ------------------------------------------------------------------------------------------
# average recall
# ------------------------------------------------------------------------------------------
def test_threshold_constants():
    np.testing.assert_allclose(M.BOP19_VSD_TAUS, np.arange(1, 11) * 0.05)
    np.testing.assert_allclose(M.BOP19_VSD_THRESHOLDS, np.arange(1, 11) * 0.05)
    np.testing.assert_allclose(M.BOP19_MSSD_THRESHOLDS, np.arange(1, 11) * 0.05)
    np.testing.assert_array_equal(M.BOP19_MSPD_THRESHOLDS, np.arange(1, 11) * 5.0)
    assert M.BOP19_VSD_DELTA == 0.015


def test_ar_hand_made():
    # MSSD: diameter 1 m; 0 -> 10/10 thresholds, 0.12 -> 8/10, 0.26 -> 5/10, missing -> 0
    assert M.ar_mssd([0.0, 0.12, 0.26, None], [1.0] * 4) == pytest.approx(23 / 40, abs=1e-15)
    # same in a 0.2 m object
    assert M.ar_mssd(np.array([0.0, 0.024, 0.052, np.nan]), 0.2) == pytest.approx(23 / 40, abs=1e-15)
    # MSPD at 640 px: 3 -> 10, 10 -> 8 (strict: 10 is not < 10), 60 -> 0, inf -> 0
    assert M.ar_mspd([3.0, 10.0, 60.0, np.inf]) == pytest.approx(18 / 40, abs=1e-15)
    # a 1280 px wide image doubles the thresholds: 3 -> 10, 10 -> 9, 60 -> 4 (35..50), inf -> 0
    assert M.ar_mspd([3.0, 10.0, 60.0, np.inf], image_width=1280) == pytest.approx(23 / 40, abs=1e-15)
    # VSD: rows over the 10 taus
    vsd_err = [
        [0.0] * 10,  # 1
        [0.12] * 10,  # 0.8
        [1.0] * 5 + [0.0] * 5,  # 0.5
        None,  # missing -> 0
    ]
    assert M.ar_vsd(vsd_err) == pytest.approx(2.3 / 4, abs=1e-15)
    res = M.bop_average_recall(vsd_err, [0.0, 0.12, 0.26, None], [3.0, 10.0, 60.0, np.inf], 1.0)
    assert res["ar_vsd"] == pytest.approx(0.575)
    assert res["ar_mssd"] == pytest.approx(0.575)
    assert res["ar_mspd"] == pytest.approx(0.45)
    assert res["ar"] == pytest.approx((0.575 + 0.575 + 0.45) / 3)
    assert M.ar_mssd([], []) == 0.0
    with pytest.raises(ValueError):
        M.bop_average_recall(vsd_err, [0.0], [1.0], 1.0)


def test_ar_matches_brute_force():
    rng = np.random.default_rng(9)
    n = 200
    diam = rng.uniform(0.05, 0.3, n)
    e_mssd = rng.uniform(0, 0.6, n) * diam
    e_mspd = rng.uniform(0, 60, n)
    e_vsd = rng.uniform(0, 0.6, (n, 10))
    e_mssd[::17] = np.inf
    assert M.ar_mssd(e_mssd, diam) == pytest.approx(_brute_recall(e_mssd / diam, M.BOP19_MSSD_THRESHOLDS), abs=1e-14)
    assert M.ar_mspd(e_mspd, 720) == pytest.approx(
        _brute_recall(e_mspd, [t * 720 / 640 for t in M.BOP19_MSPD_THRESHOLDS]), abs=1e-14
    )
    per_tau = [_brute_recall(e_vsd[:, k], M.BOP19_VSD_THRESHOLDS) for k in range(10)]
    assert M.ar_vsd(e_vsd) == pytest.approx(np.mean(per_tau), abs=1e-14)
    curve = M.accuracy_curve(e_mspd, [0, 10, 30, 100])
    np.testing.assert_allclose(curve, [np.mean(e_mspd < x) for x in (0, 10, 30, 100)])


# ------------------------------------------------------------------------------------------
# ADD(-S) AUC
# ------------------------------------------------------------------------------------------
def test_adds_auc_known_sets():
    assert M.adds_auc(np.zeros(10)) == pytest.approx(100.0, abs=1e-12)
    assert M.adds_auc([0.1, 0.2, np.inf, None, np.nan]) == pytest.approx(0.0, abs=1e-12)
    u = np.linspace(0, 0.1, 1001)
    assert M.adds_auc(u) == pytest.approx(50.0, abs=0.1)
    assert M.adds_auc(u, steps=None) == pytest.approx(50.0, abs=1e-9)
    assert M.adds_auc([0.05]) == pytest.approx(50.0, abs=0.06)
    assert M.adds_auc([0.0, np.inf]) == pytest.approx(50.0, abs=1e-12)
    assert M.adds_auc([]) == 0.0


def test_adds_auc_matches_brute_force():
    rng = np.random.default_rng(4)
    e = rng.exponential(0.03, 300)
    ref = _brute_auc(e)
    assert M.adds_auc(e, steps=None) == pytest.approx(ref, abs=1e-9)
    assert M.adds_auc(e) == pytest.approx(ref, abs=50 / 1000 + 1e-9)
    assert M.adds_auc(e, max_threshold=0.05, steps=None) == pytest.approx(_brute_auc(e, 0.05), abs=1e-9)
