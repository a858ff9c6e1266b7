"""Shared fixtures: real shapes from ../shared/data (bundled copies in the package)."""

from pathlib import Path

import numpy as np
import pytest

from modalmorph.core.shape import resample
from modalmorph.datasets import load_hand, load_heart

DATA = Path(__file__).parent / "data"


@pytest.fixture
def rng():
    return np.random.default_rng(20050328)


@pytest.fixture(scope="session")
def hand200():
    """The first shared hand outline resampled to 200 nodes by arc length."""
    return resample(load_hand(0), 200)


@pytest.fixture(scope="session")
def hearts():
    """The shared heart pair: end-diastole (247 nodes), end-systole (180 nodes)."""
    return load_heart("diastole"), load_heart("systole")


def sphere_points(n, rng, *, radii=(1.0, 1.0, 1.0)):
    """n points on a (deformed) ellipsoid, nearly uniform (Fibonacci lattice) plus jitter."""
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    theta = np.pi * (1 + 5**0.5) * i
    p = np.c_[np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)]
    return p * np.asarray(radii) + 0.01 * rng.standard_normal((n, 3))


def random_rotation(d, rng):
    """A uniformly random proper rotation (det +1) of R^d."""
    q, r = np.linalg.qr(rng.standard_normal((d, d)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def self_intersections(points, *, closed=True):
    """Number of pairs of non-adjacent polyline segments that properly cross."""
    p = np.asarray(points)
    q = np.roll(p, -1, axis=0) if closed else p[1:]
    p = p if closed else p[:-1]
    n = len(p)

    def orient(a, b, c):
        return np.sign((b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1])
                       - (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0]))

    A, B = p[:, None], q[:, None]
    C, D = p[None, :], q[None, :]
    cross = (orient(A, B, C) * orient(A, B, D) < 0) & (orient(C, D, A) * orient(C, D, B) < 0)
    i, j = np.triu_indices(n, k=2)
    keep = ~(closed & (i == 0) & (j == n - 1))  # first and last segments share a node
    return int(cross[i[keep], j[keep]].sum())


# Hypothesis profiles: "default" as hypothesis's own, reproducible; "long" (with
# --hypothesis-profile=long or MODALMORPH_FUZZ=long) runs 5000 examples per test (the fuzz
# tests of test_fuzz.py run at least 500 in any profile).
try:
    import os

    from hypothesis import HealthCheck, settings

    settings.register_profile("default", deadline=None, derandomize=True,
                              suppress_health_check=[HealthCheck.too_slow])
    settings.register_profile("long", max_examples=5000, deadline=None,
                              suppress_health_check=[HealthCheck.too_slow])
    settings.load_profile("long" if os.environ.get("MODALMORPH_FUZZ") == "long" else "default")
except ImportError:  # hypothesis is a test extra; the fuzz tests skip without it
    pass
