"""ADD / ADD-S / accuracy / rotation and translation errors against brute-force references."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sixdpose.evaluation import metrics


def _brute_add(Re, te, Rg, tg, pts):
    return np.mean([np.linalg.norm((Rg @ x + tg) - (Re @ x + te)) for x in pts])


def _brute_adds(Re, te, Rg, tg, pts):
    est = [Re @ x + te for x in pts]
    return np.mean([min(np.linalg.norm((Rg @ x + tg) - e) for e in est) for x in pts])


@pytest.fixture
def case():
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(150, 3)) * [0.05, 0.03, 0.02]
    Rg = Rotation.random(random_state=1).as_matrix()
    Re = Rotation.random(random_state=2).as_matrix()
    return Re, np.array([0.01, -0.02, 0.6]), Rg, np.array([0.0, 0.0, 0.61]), pts


def test_add_matches_brute_force(case):
    assert metrics.add(*case) == pytest.approx(_brute_add(*case), rel=1e-10)


def test_adds_matches_brute_force(case):
    assert metrics.adds(*case) == pytest.approx(_brute_adds(*case), rel=1e-10)


def test_adds_le_add_and_zero_for_identity(case):
    Re, te, Rg, tg, pts = case
    assert metrics.adds(*case) <= metrics.add(*case)
    assert metrics.add(Rg, tg, Rg, tg, pts) == pytest.approx(0.0, abs=1e-12)
    assert metrics.adds(Rg, tg, Rg, tg, pts) == pytest.approx(0.0, abs=1e-12)


def test_adds_invariant_to_symmetry():
    # points of a square in the xy plane: a 90 degree turn about z is a symmetry
    pts = np.array([[1, 1, 0], [-1, 1, 0], [-1, -1, 0], [1, -1, 0]], float) * 0.05
    Rz = Rotation.from_euler("z", 90, degrees=True).as_matrix()
    t = np.array([0, 0, 0.5])
    assert metrics.adds(Rz, t, np.eye(3), t, pts) == pytest.approx(0.0, abs=1e-12)
    assert metrics.add(Rz, t, np.eye(3), t, pts) > 0.05
    assert metrics.add_or_adds(Rz, t, np.eye(3), t, pts, symmetric=True) == pytest.approx(0.0, abs=1e-12)
    assert metrics.add_or_adds(Rz, t, np.eye(3), t, pts, symmetric=False) == metrics.add(Rz, t, np.eye(3), t, pts)


def test_add_pure_translation_equals_offset():
    pts = np.random.default_rng(0).normal(size=(50, 3))
    assert metrics.add(np.eye(3), np.array([0.003, 0.004, 0]), np.eye(3), np.zeros(3), pts) == pytest.approx(0.005)


def test_is_correct_threshold():
    assert metrics.is_correct(0.0099, 0.1)
    assert not metrics.is_correct(0.0101, 0.1)
    assert not metrics.is_correct(0.02, 0.1)
    assert metrics.is_correct(0.019, 0.1, threshold=0.2)


def test_rotation_and_translation_error():
    Rg = Rotation.random(random_state=5).as_matrix()
    Re = Rotation.from_euler("x", 30, degrees=True).as_matrix() @ Rg
    assert metrics.rotation_error(Re, Rg) == pytest.approx(30.0, abs=1e-6)
    assert metrics.rotation_error(Rg, Rg) == pytest.approx(0.0, abs=1e-5)
    R180 = Rotation.from_euler("y", 180, degrees=True).as_matrix()
    assert metrics.rotation_error(R180, np.eye(3)) == pytest.approx(180.0, abs=1e-6)
    assert metrics.translation_error([0.0, 0.003, 0.004], np.zeros(3)) == pytest.approx(0.005)
