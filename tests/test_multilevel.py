"""The multilevel solver (coarse start + LOBPCG) against the exact sparse model with the same
cutoff, its operators and its errors. The solver contract is tests/test_solvers.py."""

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.spatial import cKDTree

from modalmorph import FEModel, morph
from modalmorph.core.solvers import AUTO_MULTILEVEL_MIN_NODES
from modalmorph.core.solvers.multilevel import (
    _LANCZOS_STEPS,
    _RICHARDSON_ROOT,
    MULTILEVEL_CUTOFF,
    Operators,
    _patch_preconditioner,
    _richardson,
    _top_eigenvalue,
    solve,
)
from modalmorph.pipeline import SPARSE_MODES

from .conftest import sphere_points

N_MODES = 20
N_RANDOM = 50


@pytest.fixture(scope="module")
def models():
    """A 900-node ellipsoid: the exact sparse model and the multilevel one (same cutoff),
    with their lowest modes; the multilevel start comes from a 300-node model."""
    pts = sphere_points(900, np.random.default_rng(3), radii=(1.0, 0.7, 0.4))
    exact = FEModel(pts, solver="sparse", cutoff=MULTILEVEL_CUTOFF)
    multi = FEModel(pts, solver="multilevel")
    modes = solve(multi, N_MODES, coarse_nodes=300)
    return exact, multi, exact.modes(N_MODES + 1), modes


def test_subspace_close_to_exact(models):
    exact, _, me, mm = models
    Gamma = exact.gram_sparse[1]
    rho = exact.material.rho
    Mpsi = rho * np.concatenate([Gamma @ p for p in me.gaussian[:, :N_MODES]
                                 .reshape(3, exact.m, -1)])
    cosines = np.linalg.svd(mm.gaussian.T @ Mpsi, compute_uv=False)
    # principal angles between the lowest-20 subspaces in the M_g inner product; the gap
    # after mode 20 is 0.9%, so a residual of 5e-2 leaves angles of a few degrees in the
    # worst direction: measured 1 - cos = 1.6e-3 (a missing mode would give ~1)
    assert 1 - cosines.min() < 2e-2


def test_residuals_below_tolerance(models):
    _, model, _, mm = models
    Gamma = model.gram_sparse[1]
    rho = model.material.rho
    R = model.stiffness_gaussian_sparse @ mm.gaussian
    Mpsi = np.concatenate([Gamma @ p for p in mm.gaussian.reshape(3, model.m, -1)])
    R -= rho * Mpsi * mm.eigenvalues
    res = np.linalg.norm(R, axis=0) / (rho * mm.eigenvalues * np.linalg.norm(Mpsi, axis=0))
    assert np.all(res <= 5e-2 * (1 + 1e-6))  # the solver's own check, recomputed


def test_ritz_vectors_diagonalise_both_matrices(models):
    """The Gram blocks of the Ritz vectors and the directions are carried from one
    Rayleigh-Ritz step to the next as small products instead of formed from the tall
    blocks: the returned modes must still be a Rayleigh-Ritz basis of the true K_g and
    M_g. Measured 5e-15 (M) and 3e-15 (K, relative to the largest w^2), against 4e-12
    and 6e-12 with every block formed from the tall ones: round-off either way."""
    _, model, _, mm = models
    Gamma = model.gram_sparse[1]
    rho = model.material.rho
    psi = mm.gaussian
    Mpsi = rho * np.concatenate([Gamma @ p for p in psi.reshape(3, model.m, -1)])
    assert_allclose(psi.T @ Mpsi, np.eye(N_MODES), atol=1e-10)  # mass-normalised
    Kr = psi.T @ (model.stiffness_gaussian_sparse @ psi)
    assert_allclose(Kr, np.diag(mm.eigenvalues), atol=1e-10 * mm.eigenvalues.max())


def test_not_converged_is_an_error(models):
    _, model, _, _ = models
    with pytest.raises(ValueError, match="did not converge .* relative residual"):
        solve(model, N_MODES, coarse_nodes=300, maxiter=0)


def test_too_few_coarse_modes(models):
    _, model, _, _ = models
    with pytest.raises(ValueError, match="needs more than n=10 coarse modes"):
        solve(model, 10, coarse_nodes=3)


def test_selected_by_size():
    pts = sphere_points(AUTO_MULTILEVEL_MIN_NODES, np.random.default_rng(0))
    model = FEModel(pts)
    assert model.solver == "multilevel"
    assert model.cutoff == MULTILEVEL_CUTOFF
    assert FEModel(pts, solver="sparse").cutoff == 1e-10
    assert FEModel(pts[:2000]).solver == "sparse"
    assert FEModel(pts, cutoff=1e-8).cutoff == 1e-8
    with pytest.raises(ValueError, match=r"multilevel solver computes the lowest n modes"):
        model.modes()


@pytest.mark.parametrize("threads", [1, 2, 3])
def test_operators_match_model_matrices(models, threads):
    """The solver's own K_g, Gamma and G (k-d tree node order, rows split over threads)
    against the model's CSR K_g, G and Gamma."""
    _, model, _, _ = models
    d, m = model.dim, model.m
    order = cKDTree(model.points, leafsize=8).indices
    X = np.random.default_rng(2).standard_normal((d * m, 7))
    Xo = X.reshape(d, m, -1)[:, order].reshape(d * m, -1)  # the solver's node order
    back = np.argsort(order)
    G, Gamma = model.gram_sparse
    with ThreadPoolExecutor(threads) as pool:
        ops = Operators(model, order, pool, threads)
        assert len(ops.blocks) == threads
        KX = ops.stiffness(Xo).reshape(d, m, -1)[:, back].reshape(d * m, -1)
        MX = ops.mass(Xo).reshape(d, m, -1)[:, back].reshape(d * m, -1)
        GX = ops.gram(Xo).reshape(d, m, -1)[:, back].reshape(d * m, -1)
    expect = model.stiffness_gaussian_sparse @ X
    assert_allclose(KX, expect, atol=1e-12 * np.abs(expect).max())
    expect = np.concatenate([Gamma @ x for x in X.reshape(d, m, -1)])
    assert_allclose(MX, expect, atol=1e-12 * np.abs(expect).max())
    expect = np.concatenate([G @ x for x in X.reshape(d, m, -1)])
    assert_allclose(GX, expect, atol=1e-12 * np.abs(expect).max())


def test_threads_do_not_change_the_result(models):
    _, model, _, mm = models
    one = solve(model, N_MODES, coarse_nodes=300, threads=1)
    # each row's sums are the same whatever thread computes them
    assert_allclose(one.frequencies, mm.frequencies, rtol=1e-12)
    assert_allclose(one.gaussian, mm.gaussian, atol=1e-10 * np.abs(mm.gaussian).max())


def random_sphere(m, seed):
    """``m`` points drawn uniformly at random on the unit sphere (normalised Gaussian
    vectors): the lowest modes are localised where the nodes crowd, with many nearly equal
    frequencies, the hard case for the multilevel solver."""
    u = np.random.default_rng(seed).standard_normal((m, 3))
    return u / np.linalg.norm(u, axis=1, keepdims=True)


@pytest.fixture(scope="module")
def random_models():
    """Random points on an ellipsoid (3, 2, 1) (random directions scaled by the axes, so
    denser near the ends of the long axis), multilevel with every default (the automatic
    choice at this size) and the exact sparse model with the same cutoff."""
    pts = random_sphere(AUTO_MULTILEVEL_MIN_NODES, 7) * [3.0, 2.0, 1.0]
    auto = FEModel(pts)
    exact = FEModel(pts, solver="sparse", cutoff=MULTILEVEL_CUTOFF)
    return auto, auto.modes(N_RANDOM), exact.modes(N_RANDOM)


def test_random_points_converge_with_defaults(random_models):
    auto, mm, me = random_models
    assert auto.solver == "multilevel"
    err = mm.frequencies / me.frequencies - 1
    assert np.all(err > -1e-9)  # Rayleigh-Ritz upper bounds
    # measured 9.0e-3 at most, median 3.9e-3 (8.6e-3 / 3.9e-3 without the Richardson
    # step after the patch solves, 2026-11-24), while the 50 frequencies span 20% and
    # mode 51 is 0.3% above mode 50: on random nodes the lowest modes are localised and
    # the residual tolerance 5e-2 leaves about twice the frequency error it leaves on
    # quasi-uniform nodes (4.8e-3 at most)
    assert err.max() < 1e-2


def test_morph_auto_picks_multilevel():
    """solver="auto" on a 3D model of AUTO_MULTILEVEL_MIN_NODES nodes (model_nodes; the
    default 300 gives the dense solver) solves the lowest SPARSE_MODES modes with the
    multilevel solver (it used to ask for all 7500 and raise); 6 s measured."""
    rng = np.random.default_rng(11)
    m = AUTO_MULTILEVEL_MIN_NODES
    a = sphere_points(m, rng, radii=(1.0, 0.8, 0.6))
    b = a * np.array([1.2, 0.7, 0.9]) + 0.1 * np.sin(3 * a[:, [1, 2, 0]])
    r = morph(a, b, matching=np.c_[np.arange(m), np.arange(m)], model_nodes=m)
    assert r.resolved.solver == "multilevel" and r.resolved.modes == SPARSE_MODES
    assert np.all(np.isfinite(r.shapes))
    # measured 0.216 -> 0.119 (equilibrium: 100 of 7500 modes; see the test above)
    assert r.mean_distance[-1] < 0.7 * r.mean_distance[0]


def test_preconditioner_positive_definite_and_top_estimate(models):
    """The patch solves P followed by the Richardson step form a symmetric positive
    definite preconditioner (its polynomial positive over the spectrum of P K_g), and the
    Lanczos estimate of the top of P K_g lies within 1% of the dense value (from below)."""
    _, model, _, _ = models
    d, m = model.dim, model.m
    order = cKDTree(model.points, leafsize=8).indices
    eye = np.eye(d * m)
    with ThreadPoolExecutor(1) as pool:
        ops = Operators(model, order, pool, 1)
        patches = _patch_preconditioner(model, order, pool, 1)
        estimate = _top_eigenvalue(ops, patches, _LANCZOS_STEPS)
        P = patches(eye, slice(None), np.empty_like(eye))
        step = _richardson(patches, ops, _RICHARDSON_ROOT / (estimate - 1))
        T = step(eye, slice(None), np.empty_like(eye))
        K = ops.stiffness(eye)
    C = np.linalg.cholesky((P + P.T) / 2)
    top = np.linalg.eigvalsh(C.T @ K @ C)[-1]
    assert top * (1 - 1e-2) < estimate <= top * (1 + 1e-9)
    assert_allclose(T, T.T, atol=1e-10 * np.abs(T).max())
    assert np.linalg.eigvalsh((T + T.T) / 2).min() > 0
