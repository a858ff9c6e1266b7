"""Loads (19)-(20) and Newmark (14)-(15) on their own."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from modalmorph import dynamics
from modalmorph.datasets import load_hand
from modalmorph.dynamics import LoadTargets, Newmark


def _pair(n=120):
    idx = np.linspace(0, 1590, n, endpoint=False).astype(int)
    return load_hand(0)[idx], load_hand(3)[idx]


@pytest.mark.parametrize("small", [0, 10**9])
def test_neighbourhood_rule_same_in_both_passes(monkeypatch, small):
    """The vectorised pass over small groups and the per-group pass give one answer."""
    a, b = _pair()
    rng = np.random.default_rng(3)
    keep = np.sort(rng.choice(120, 50, replace=False))
    pairs = np.c_[keep, keep]
    reference = LoadTargets(a, b, pairs, ordered=True, closed=True).targets(a + 1.0)
    monkeypatch.setattr(dynamics, "_SMALL_GROUP", small)
    got = LoadTargets(a, b, pairs, ordered=True, closed=True).targets(a + 1.0)
    assert_allclose(got, reference, rtol=1e-12)


def test_weights_are_a_weighted_mean():
    """(20) normalised: an unmatched node's target is a convex combination of the target
    nodes between its neighbours' partners, so it lies in their bounding box."""
    a, b = _pair()
    pairs = np.c_[[0, 10], [0, 10]]
    t = LoadTargets(a, b, pairs, ordered=True, closed=False).targets(a)
    inner = t[1:10]
    box = b[1:10]
    assert np.all(inner >= box.min(axis=0) - 1e-9) and np.all(inner <= box.max(axis=0) + 1e-9)


def test_newmark_free_oscillator_conserves_energy():
    """delta = 1/2, alpha = 1/4 (average acceleration): no numerical damping."""
    w = np.array([1.0, 3.0])
    nm = Newmark(np.diag(w**2), np.zeros((2, 2)), dt=0.05)
    x, v = np.array([1.0, 0.5]), np.zeros(2)
    a = -(w**2) * x
    e0 = 0.5 * (v**2 + w**2 * x**2)
    for _ in range(2000):
        x, v, a = nm.step(x, v, a, np.zeros(2))
    assert_allclose(0.5 * (v**2 + w**2 * x**2), e0, rtol=1e-10)
