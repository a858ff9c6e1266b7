"""The sparse (truncated) model against the dense one, and the solver selection.

The solver contract (frequencies, (13), truncation) is tests/test_solvers.py."""

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy import sparse

from modalmorph import FEModel
from modalmorph.core.element import AUTO_DENSE_MAX_DOF, cutoff_radius
from modalmorph.core.model import DENSE_MAX_DOF
from modalmorph.core.shape import resample
from modalmorph.datasets import load_hand

from .conftest import sphere_points

N_MODES = 20


@pytest.fixture(scope="module", params=["2d", "3d"])
def both(request):
    """The same object modelled by both solvers, with their lowest modes."""
    if request.param == "2d":
        pts = resample(load_hand(0), 600)
    else:
        pts = sphere_points(400, np.random.default_rng(7), radii=(1.0, 0.8, 0.5))
    dense, sparse_ = FEModel(pts, solver="dense"), FEModel(pts, solver="sparse")
    return dense, sparse_, dense.modes(N_MODES + 1), sparse_.modes(N_MODES)


def test_mode_subspaces_agree(both):
    dense, _, md, ms = both
    # The exact model's M: the sparse modes are M-orthonormal up to the truncation
    C = md.shapes[:, :N_MODES].T @ dense.mass @ ms.shapes
    f = md.frequencies
    gaps = np.diff(f) / f[1:]  # gaps[i]: between modes i and i + 1
    separated = (gaps[:N_MODES] > 1e-3) & (np.r_[1.0, gaps[:N_MODES - 1]] > 1e-3)
    assert separated.sum() >= 3  # the check below must check something
    # separated modes: the same vector up to sign; a truncation of 1e-10 moves a mode
    # by about 1e-10 / gap, far below 1e-6
    assert_allclose(np.abs(np.diag(C))[separated], 1.0, atol=1e-6)
    # whole subspace (modes 20 and 21 are apart): all principal cosines near 1. Measured
    # 1 - 3e-13 (2D) and 1 - 7e-13 (3D), i.e. angles near 1e-6 rad; 1e-9 allows 4e-5 rad
    if gaps[N_MODES - 1] > 1e-3:
        cosines = np.linalg.svd(C, compute_uv=False)
        assert_allclose(cosines, 1.0, atol=1e-9)


def test_sparse_matrices_are_truncated_dense(both):
    dense, model, _, _ = both
    G, Gamma = model.gram_sparse
    Kg = model.stiffness_gaussian_sparse
    assert sparse.issparse(G) and sparse.issparse(Kg)
    assert Kg.shape == (dense.dim * dense.m,) * 2
    rel = model.cutoff  # every dropped entry is below cutoff x the diagonal
    assert np.abs(G.toarray() - dense.gram[0]).max() <= rel
    assert np.abs(Gamma.toarray() - dense.gram[1]).max() <= rel * dense.gram[1][0, 0]
    Kd = dense.stiffness_gaussian
    assert np.abs(Kg.toarray() - Kd).max() <= rel * Kd[0, 0]
    # and what is kept is exact
    kept = Kg.toarray() != 0
    assert_allclose(Kg.toarray()[kept], Kd[kept], rtol=1e-13, atol=0)


def test_apply_matches_dense_matrices(hand200, rng):
    model = FEModel(hand200)
    U = rng.standard_normal((400, 3))
    assert_allclose(model.apply_mass(U), model.mass @ U, rtol=1e-8,
                    atol=1e-10 * np.abs(model.mass @ U).max())
    assert_allclose(model.apply_stiffness(U), model.stiffness @ U, rtol=1e-8,
                    atol=1e-10 * np.abs(model.stiffness @ U).max())


def test_cutoff_radius():
    # 2 x exp(-x) = cutoff at x = (r / 2 sigma)^2
    for cutoff in (1e-4, 1e-10, 1e-14):
        x = (cutoff_radius(1.0, cutoff) / 2) ** 2
        assert_allclose(2 * x * np.exp(-x), cutoff, rtol=1e-9)
    assert_allclose(cutoff_radius(0.1), 1.0395, rtol=1e-4)  # 10.4 sigma by default
    with pytest.raises(ValueError, match=r"cutoff must be in \(0, 1\)"):
        cutoff_radius(1.0, 0.0)


def test_auto_picks_by_size():
    small = np.column_stack([np.cos(t := np.linspace(0, 2 * np.pi, 100, endpoint=False)),
                             np.sin(t)])
    assert FEModel(small).solver == "dense"
    m = AUTO_DENSE_MAX_DOF // 2 + 1
    t = np.linspace(0, 2 * np.pi, m, endpoint=False)
    large = np.column_stack([np.cos(t), 0.5 * np.sin(t)])
    assert FEModel(large).solver == "sparse"
    assert FEModel(large, solver="dense").solver == "dense"
    assert FEModel(small, solver="sparse").solver == "sparse"


def test_sparse_large_contour_runs():
    """A contour above the auto threshold: sparse by default, modes mass-normalised."""
    pts = resample(load_hand(0), 4000)
    model = FEModel(pts)
    assert model.solver == "sparse"
    modes = model.modes(10)
    assert np.all(np.diff(modes.frequencies) >= 0)
    MPhi = model.mass_times_modes(modes)
    assert np.abs(modes.shapes.T @ MPhi - np.eye(10)).max() <= 1e-8  # (13)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"solver": "lapack"},
         r"solver must be one of \('auto', 'dense', 'sparse', 'multilevel'\)"),
        ({"solver": None}, "solver must be one of"),
        ({"cutoff": 0.0}, r"cutoff must be a number in \(0, 1\)"),
        ({"cutoff": 1.5}, r"cutoff must be a number in \(0, 1\)"),
    ],
)
def test_bad_solver_options(hand200, kwargs, match):
    with pytest.raises(ValueError, match=match):
        FEModel(hand200, **kwargs)


def test_sparse_mode_count(hand200):
    model = FEModel(hand200, solver="sparse")
    with pytest.raises(ValueError, match=r"pass n \(e.g. modes\(50\)\)"):
        model.modes()
    with pytest.raises(ValueError, match="at most 398 modes"):
        model.modes(399)


def test_sparse_sigma_too_large_is_reported(hand200):
    model = FEModel(hand200, sigma=4.0, solver="sparse")
    with pytest.raises(ValueError, match="too large .* numerically singular"):
        model.modes(10)


def test_dense_matrices_refused_when_huge():
    m = DENSE_MAX_DOF // 2 + 1
    t = np.linspace(0, 2 * np.pi, m, endpoint=False)
    model = FEModel(np.column_stack([np.cos(t), np.sin(t)]))
    for attr in ("mass", "stiffness", "gram", "stiffness_gaussian"):
        with pytest.raises(ValueError, match="too large .* use modes\\(n\\), apply_mass"):
            getattr(model, attr)
