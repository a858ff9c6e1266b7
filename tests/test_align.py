"""Horn's similarity (method.md §3): exact recovery, no reflections, inverse, errors."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from modalmorph.core.align import Similarity, align

from .conftest import random_rotation, sphere_points


@pytest.mark.parametrize("d", [2, 3])
def test_recovers_known_similarity(d, rng, hand200):
    pts = hand200 if d == 2 else sphere_points(80, rng, radii=(1.0, 0.7, 0.4))
    for _ in range(20):
        R, s, t = random_rotation(d, rng), rng.uniform(0.5, 2.0), rng.uniform(-50, 50, d)
        sim = align(pts, s * pts @ R.T + t)
        # exact data: recovered to rounding (1e-10 absolute, coordinates up to ~500)
        assert_allclose(sim.rotation, R, atol=1e-10)
        assert abs(sim.scale - s) <= 1e-10
        assert_allclose(sim.translation, t, atol=1e-10)
        assert_allclose(sim.apply(pts), s * pts @ R.T + t, atol=1e-9)


@pytest.mark.parametrize("d", [2, 3])
def test_half_turn_in_2d_and_3d(d, rng):
    pts = rng.standard_normal((30, d))
    R = -np.eye(d) if d == 2 else np.diag([-1.0, -1.0, 1.0])  # rotation by pi
    assert_allclose(align(pts, pts @ R.T).rotation, R, atol=1e-10)


@pytest.mark.parametrize("d", [2, 3])
def test_never_a_reflection(d, rng):
    for _ in range(20):
        pts = rng.standard_normal((25, d))
        mirrored = pts * np.r_[-1.0, np.ones(d - 1)]
        for target in (mirrored, rng.standard_normal((25, d))):
            R = align(pts, target).rotation
            assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)
            assert_allclose(R.T @ R, np.eye(d), atol=1e-12)  # orthogonal


def test_rigid_when_scale_false(rng):
    pts = rng.standard_normal((10, 3))
    sim = align(pts, 3.0 * pts, scale=False)
    assert sim.scale == 1.0
    assert_allclose(sim.rotation, np.eye(3), atol=1e-12)


@pytest.mark.parametrize("d", [2, 3])
def test_inverse_and_matrix(d, rng):
    pts = rng.standard_normal((15, d))
    sim = Similarity(rotation=random_rotation(d, rng), scale=1.7,
                     translation=rng.standard_normal(d))
    assert_allclose(sim.inverse().apply(sim.apply(pts)), pts, atol=1e-12)
    homog = np.c_[pts, np.ones(len(pts))] @ sim.matrix.T
    assert_allclose(homog[:, :d], sim.apply(pts), atol=1e-12)
    assert_allclose(Similarity.identity(d).apply(pts), pts, atol=0)


def test_bad_input():
    with pytest.raises(ValueError, match="same shape"):
        align(np.zeros((4, 2)), np.zeros((5, 2)))
    with pytest.raises(ValueError, match=r"target_points must have shape \(k, 2\) or \(k, 3\)"):
        align(np.zeros((4, 2)), np.zeros((4, 4)))
    with pytest.raises(ValueError, match="at least 2"):
        align(np.zeros((1, 2)), np.zeros((1, 2)))
    with pytest.raises(ValueError, match="coincide"):
        align(np.ones((4, 2)), np.eye(4, 2))
    with pytest.raises(ValueError, match="finite"):
        align(np.full((4, 2), np.nan), np.zeros((4, 2)))
    with pytest.raises(ValueError, match="coordinates per row"):
        Similarity.identity(2).apply(np.zeros((3, 3)))
