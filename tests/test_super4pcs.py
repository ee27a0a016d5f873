"""Super4PCS on partial views with known poses (noise and outliers), and its building blocks."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sixdpose.evaluation.metrics import add
from sixdpose.registration import super4pcs as S
from sixdpose.registration.geometry import estimate_normals, to_o3d
from test_reg_helpers import make_shape


def _cfg(**kw):
    """Unbounded search settings (no time limit, large candidate caps, stop at LCP 0.98)."""
    from sixdpose.registration.presets import RegistrationConfig

    base = dict(s4pcs_samples=200, s4pcs_stop_lcp=0.98, s4pcs_max_candidates=200000, s4pcs_max_pairs=50000,
                s4pcs_max_time=None, s4pcs_delta_rel=None)
    base.update(kw)
    return RegistrationConfig(**base)

def _partial(P, N, R, t, noise, rng):
    pc, nc = P @ R.T + t, N @ R.T
    keep = np.einsum("ij,ij->i", nc, -pc) > 0.1 * np.linalg.norm(pc, axis=1)
    return pc[keep] + rng.normal(0, noise, (keep.sum(), 3))


def test_kabsch_batch_recovers_transforms():
    rng = np.random.default_rng(0)
    src = rng.normal(size=(4, 3))
    Rs = Rotation.random(5, random_state=1).as_matrix()
    ts = rng.normal(size=(5, 3))
    dst = np.einsum("mij,kj->mki", Rs, src) + ts[:, None]
    R, t = S.kabsch_batch(src, dst)
    np.testing.assert_allclose(R, Rs, atol=1e-9)
    np.testing.assert_allclose(t, ts, atol=1e-9)
    assert np.allclose(np.linalg.det(R), 1.0)


def test_pair_index_finds_pairs_by_length_both_orders():
    Q = np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.2, 0], [0.3, 0, 0]], float)
    Qn = np.tile([0, 0, 1.0], (4, 1))
    idx = S.PairIndex(Q, Qn)
    f, s, d = idx.ordered_pairs(0.1, 0.005, 0, 0, 1, 0.1)
    got = set(zip(f.tolist(), s.tolist(), strict=True))
    assert got == {(0, 1), (1, 0)}
    np.testing.assert_allclose(np.linalg.norm(Q[s] - Q[f], axis=1), 0.1)
    np.testing.assert_allclose(d, (Q[s] - Q[f]) / 0.1)


def test_select_base_is_coplanar_with_crossing_diagonals():
    rng = np.random.default_rng(0)
    P, _, _, _ = make_shape(0.01)
    base = S.select_base(P, 0.12, 0.002, rng)
    assert base is not None
    i, r1, r2 = base
    a, b, c, d = P[i]
    assert 0.1 < r1 < 0.9 and 0.1 < r2 < 0.9
    e1, e2 = a + r1 * (b - a), c + r2 * (d - c)
    assert np.linalg.norm(e1 - e2) < 0.002


@pytest.mark.parametrize("seed,outliers", [pytest.param(0, 0.0, marks=pytest.mark.slow),
                                           pytest.param(1, 0.0, marks=pytest.mark.slow), (2, 0.25), (3, 0.25)])
def test_super4pcs_partial_view_known_pose(seed, outliers):
    rng = np.random.default_rng(seed)
    Pm, Nm, _, diam = make_shape(0.003, seed=seed)
    R = Rotation.random(random_state=seed + 10).as_matrix()
    t = np.array([0.02, -0.01, 0.6])
    scene = _partial(Pm, Nm, R, t, 0.001, rng)
    if outliers:
        # mask bleeding: a patch of the background plane behind the object, plus scattered points
        n = int(outliers * len(scene))
        c = scene.mean(0)
        plane = np.c_[rng.uniform(-0.3, 0.3, (n, 2)) * diam + c[:2] + 0.25 * diam, np.full(n, scene[:, 2].max() + 0.02)]
        scatter = c + rng.uniform(-0.5, 0.5, (n // 10, 3)) * diam
        scene = np.vstack([scene, plane, scatter])
    pcd = to_o3d(scene).voxel_down_sample(0.006)
    estimate_normals(pcd)
    Qp = to_o3d(Pm, Nm).voxel_down_sample(0.006)
    res = S.super4pcs(np.asarray(pcd.points), np.asarray(pcd.normals), np.asarray(Qp.points), np.asarray(Qp.normals),
                      _cfg(s4pcs_overlap=0.5 if outliers else 0.7, seed=seed), delta=0.006, Q_verify=Pm, Qn_verify=Nm)
    T = np.linalg.inv(res.T)  # scene -> model inverted: X_CO
    err = add(T[:3, :3], T[:3, 3], R, t, Pm)
    assert err < 0.1 * diam, (err, res)
    assert res.lcp > (0.3 if outliers else 0.5)
    assert res.n_congruent > 0


def test_super4pcs_degenerate_inputs_fail_cleanly():
    res = S.super4pcs(np.zeros((2, 3)), None, np.zeros((10, 3)), None)
    assert res.lcp == 0.0 and np.allclose(res.T, np.eye(4))


def test_super4pcs_is_deterministic():
    Pm, Nm, _, _ = make_shape(0.006)
    R = Rotation.random(random_state=4).as_matrix()
    P = Pm @ R.T
    a = S.super4pcs(P, Nm @ R.T, Pm, Nm, _cfg(seed=7), delta=0.006)
    b = S.super4pcs(P, Nm @ R.T, Pm, Nm, _cfg(seed=7), delta=0.006)
    np.testing.assert_array_equal(a.T, b.T)
