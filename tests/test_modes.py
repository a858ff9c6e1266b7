"""Modes: invariance, the mode count, the element's field, Rayleigh damping (5).

The solver contract ((13), the lowest modes) is tests/test_solvers.py."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from modalmorph import FEModel, Material, rayleigh

from .conftest import random_rotation, sphere_points


@pytest.mark.parametrize("d", [2, 3])
def test_frequencies_invariant_to_similarity(d, hand200, rng):
    pts = hand200 if d == 2 else sphere_points(100, rng, radii=(1.0, 0.6, 0.3))
    moved = 37.5 * pts @ random_rotation(d, rng).T + rng.uniform(-100, 100, d)
    f0 = FEModel(pts).modes().frequencies
    f1 = FEModel(moved).modes().frequencies
    # the model works in the normalised frame: rotation, translation and units vanish
    assert_allclose(f1, f0, rtol=1e-8)


def test_frequencies_scale_with_material(hand200):
    a = FEModel(hand200, material=Material(E=1.0, nu=0.3, rho=1.0)).modes(10).frequencies
    b = FEModel(hand200, material=Material(E=4.0, nu=0.3, rho=1.0)).modes(10).frequencies
    assert_allclose(b, 2 * a, rtol=1e-10)  # omega ~ sqrt(E / rho)


def test_bad_mode_count(hand200):
    model = FEModel(hand200)
    with pytest.raises(ValueError, match="n must be between 1 and 400"):
        model.modes(401)


def test_rayleigh_reproduces_ratios():
    w1, w2, xi1, xi2 = 2.0, 30.0, 0.005, 0.03
    alpha, beta = rayleigh(xi1, xi2, w1, w2)
    xi = lambda w: alpha / (2 * w) + beta * w / 2  # noqa: E731 damping ratio of a mode
    assert_allclose([xi(w1), xi(w2)], [xi1, xi2], rtol=1e-12)


def test_rayleigh_diagonal_in_modes(hand200):
    model = FEModel(hand200)
    modes = model.modes()
    alpha, beta = rayleigh(0.005, 0.03, modes.frequencies[0], modes.frequencies[-1])
    C = alpha * model.mass + beta * model.stiffness
    PCP = modes.shapes.T @ C @ modes.shapes
    expected = alpha + beta * modes.eigenvalues  # Phi^T C Phi = alpha I + beta Omega^2
    assert np.abs(PCP - np.diag(expected)).max() <= 1e-8 * expected.max()


def test_rayleigh_rejects_bad_input():
    with pytest.raises(ValueError, match="w1 < w2"):
        rayleigh(0.01, 0.01, 3.0, 3.0)
    with pytest.raises(ValueError, match="damping ratios must be >= 0"):
        rayleigh(-0.01, 0.01, 1.0, 3.0)


def test_modes_at_own_nodes_is_phi(hand200):
    model = FEModel(hand200)
    modes = model.modes(12)
    # u(X_j) = sum_k g_k(X_j) psi_k = (G psi)_j: exactly Phi, up to the 1e-10 cutoff of g
    assert_allclose(model.modes_at(modes, model.points), modes.shapes,
                    atol=1e-8 * np.abs(modes.shapes).max())


def test_modes_at_far_point_is_refused(hand200):
    model = FEModel(hand200)
    with pytest.raises(ValueError, match="beyond the cutoff radius"):
        model.modes_at(model.modes(3), np.array([[50.0, 50.0]]))
