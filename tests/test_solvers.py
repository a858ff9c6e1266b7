"""The eigensolver contract, once for every solver: the lowest modes of the dense
reference, mass-normalised, truncation flagged, and a morph through each."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

import modalmorph
from modalmorph import FEModel
from modalmorph.core.shape import resample
from modalmorph.datasets import load_hand

from .conftest import sphere_points

N_MODES = 20

# Lowest N_MODES frequencies against the dense reference, relative, (below, above):
# - dense: the index-subset route (MRRR) against all modes (divide and conquer): round-off,
#   measured 1e-14;
# - sparse: the default cutoff 1e-10 drops entries below 1e-10 of the diagonal, measured
#   4e-11 (2D) and 1e-10 (3D); a truncation or solver fault shows at 1e-6 and above;
# - multilevel: Rayleigh-Ritz values, upper bounds of its truncated model's frequencies,
#   whose cutoff 1e-6 moves them by up to 3e-6 (README); the residual tolerance 5e-2
#   leaves them above by 2e-4 to 2e-3 (2D) and 9e-4 to 6e-3 (3D, measured); 1e-2 fails
#   on a solver that stops early or loses a mode.
TOLERANCE = {"dense": (1e-12, 1e-12), "sparse": (1e-8, 1e-8), "multilevel": (1e-5, 1e-2)}


@pytest.fixture(scope="module", params=["2d", "3d"])
def points(request):
    if request.param == "2d":
        return resample(load_hand(0), 600)
    return sphere_points(400, np.random.default_rng(7), radii=(1.0, 0.8, 0.5))


@pytest.fixture(scope="module")
def reference(points):
    """All modes of the dense model (divide and conquer)."""
    model = FEModel(points, solver="dense")
    return model, model.modes()


@pytest.mark.parametrize("solver", ["dense", "sparse", "multilevel"])
def test_solver_contract(solver, points, reference):
    exact, ref = reference
    model = FEModel(points, solver=solver)
    modes = model.modes(N_MODES)
    # truncation: n asked, the n lowest returned, ascending, and the flag says which
    assert model.solver == solver and model.truncated == (solver != "dense")
    assert modes.n == N_MODES and modes.shapes.shape == (model.dim * model.m, N_MODES)
    assert np.all(np.diff(modes.frequencies) >= 0)
    below, above = TOLERANCE[solver]
    err = modes.frequencies / ref.frequencies[:N_MODES] - 1
    assert np.all(err >= -below) and np.all(err <= above), (err.min(), err.max())
    # (13) with the model's own M and K (the truncated ones for a truncated model), by
    # solves with G; every solver ends with a Rayleigh-Ritz step: measured 1e-15 to 9e-13
    Phi, w2 = modes.shapes, modes.eigenvalues
    MPhi = model.apply_mass(Phi)
    assert np.abs(Phi.T @ MPhi - np.eye(N_MODES)).max() <= 1e-10
    assert np.abs(Phi.T @ model.apply_stiffness(Phi) - np.diag(w2)).max() <= 1e-10 * w2.max()
    # the cheap product M Phi = (I kron A) rho (I kron Gamma) psi (method.md §1)
    assert_allclose(model.mass_times_modes(modes), MPhi, atol=1e-10 * np.abs(MPhi).max())
    # Phi = (I kron G) psi (1)-(4), G of the model's own kind
    G = model.gram_sparse[0] if model.truncated else model.gram[0]
    psi = modes.gaussian.reshape(model.dim, model.m, -1)
    assert_allclose(Phi, np.concatenate([G @ p for p in psi]), atol=1e-12 * np.abs(Phi).max())


@pytest.mark.parametrize("solver", ["dense", "sparse", "multilevel"])
def test_truncated_needs_a_mode_count(solver, points):
    model = FEModel(points, solver=solver)
    total = model.dim * model.m
    if model.truncated:
        with pytest.raises(ValueError, match=f"{solver} solver computes the lowest n modes"):
            model.modes()
        with pytest.raises(ValueError, match=f"computes at most {total - 2} modes"):
            model.modes(total - 1)
    else:
        assert model.modes(total).n == total


@pytest.mark.parametrize("solver", ["dense", "sparse", "multilevel"])
def test_morph_through_solver(solver):
    """A 200-node circle into a bulging ellipse: every solver's modes (the sparse and
    multilevel ones the lowest 100 of 400) reach the target. Measured: 5 steps, mean
    distance 0.12 -> 0.005 (dense), 0.007 (sparse, multilevel)."""
    t = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    source = np.c_[np.cos(t), np.sin(t)]
    target = np.c_[1.3 * np.cos(t), 0.8 * np.sin(t) + 0.1 * np.cos(2 * t)]
    result = modalmorph.morph(source, target, solver=solver)
    assert result.resolved.solver == solver
    assert result.converged
    assert result.mean_distance[-1] < 0.1 * result.mean_distance[0]


@pytest.mark.parametrize("n", [5, 150, 399])
def test_dense_routes(hand200, n):
    """Both LAPACK routes of the dense solver (an index subset below 15% of the spectrum,
    all modes sliced above) return the lowest n."""
    model = FEModel(hand200)
    assert_allclose(model.modes(n).frequencies, model.modes().frequencies[:n], rtol=1e-9)


def test_whitening_in_place_is_the_whole_array_expression(hand200, rng):
    """The dense solver whitens K_g in its own Fortran array and symmetrises it tile by
    tile: bit for bit ``(W^T K_g W + (W^T K_g W)^T) / 2`` made with whole arrays, and the
    cached K_g is left as it was."""
    from scipy.linalg import blas

    from modalmorph.core.solvers.dense import symmetrize, whitened

    A = rng.standard_normal((301, 301))
    want = (A + A.T) / 2
    symmetrize(A, tile=64)
    assert np.array_equal(A, want)
    model = FEModel(hand200)
    K = model.stiffness_gaussian.copy()
    _, l_inv, Kw = whitened(model)
    assert Kw.flags.f_contiguous and np.array_equal(model.stiffness_gaussian, K)
    d, m = model.dim, model.m
    W = np.array(K, order="F")
    for b in range(d):
        W[:, b * m:(b + 1) * m] = blas.dtrmm(1.0, l_inv, W[:, b * m:(b + 1) * m], side=1,
                                             lower=1, trans_a=1)
    for a in range(d):
        W[a * m:(a + 1) * m] = blas.dtrmm(1.0, l_inv, W[a * m:(a + 1) * m], lower=1)
    assert np.array_equal(Kw, (W + W.T) / 2)
    fresh = FEModel(hand200)  # K_g not kept: made in Fortran order, the matcher's path
    _, _, Kw_fresh = whitened(fresh)
    assert Kw_fresh.flags.f_contiguous and np.array_equal(Kw_fresh, Kw)
    assert "stiffness_gaussian" not in fresh.__dict__
