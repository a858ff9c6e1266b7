"""The Gaussian element: closed forms against quadrature, and properties of M and K."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from modalmorph import POLYETHYLENE, FEModel, Material
from modalmorph.core.element import (
    gram_entries,
    self_entries,
    stiffness_component_pairs,
    stiffness_components,
    stiffness_entries,
    stiffness_matrix,
)

from .conftest import sphere_points


def _grid(centres, sigma, n):
    """Uniform grid covering every Gaussian to 9 sigma; the trapezoid rule on a
    uniform grid is spectrally accurate for Gaussians."""
    lo = centres.min(axis=0) - 9 * sigma
    hi = centres.max(axis=0) + 9 * sigma
    axes = [np.linspace(a, b, n) for a, b in zip(lo, hi, strict=True)]
    mesh = np.meshgrid(*axes, indexing="ij")
    x = np.stack([g.ravel() for g in mesh], axis=1)
    w = np.prod([(b - a) / (n - 1) for a, b in zip(lo, hi, strict=True)])
    return x, w


def _quadrature(centres, sigma, lam, mu, n):
    """Gamma and the elastic bilinear form by brute-force quadrature of the definitions."""
    x, w = _grid(centres, sigma, n)
    diff = x[:, None, :] - centres[None, :, :]  # (q, m, d)
    g = np.exp(-np.sum(diff**2, axis=2) / (2 * sigma**2))  # (2)
    dg = -diff / sigma**2 * g[:, :, None]  # dg_i/dx_a, (q, m, d)
    gamma = w * g.T @ g
    D = w * np.einsum("qia,qjb->abij", dg, dg)  # D^ab_ij
    d = centres.shape[1]
    # a(u, v) = int lambda div u div v + mu (grad u : grad v + grad u : grad v^T)
    # for u = g_i e_a, v = g_j e_b:
    K = np.empty((centres.shape[0], centres.shape[0], d, d))
    for a in range(d):
        for b in range(d):
            K[:, :, a, b] = lam * D[a, b] + mu * ((a == b) * np.trace(D) + D[b, a])
    return gamma, K


@pytest.mark.parametrize("d, n", [(2, 301), (3, 61)])
def test_closed_forms_match_quadrature(d, n, rng):
    centres = rng.uniform(-1, 1, (5, d))
    sigma, lam, mu = 0.7, 1.3, 0.8
    gamma_q, K_q = _quadrature(centres, sigma, lam, mu, n)
    r = centres[None, :, :] - centres[:, None, :]
    _, gamma = gram_entries(r, sigma)
    K = stiffness_entries(r, sigma, lam, mu)
    # quadrature error of the uniform trapezoid rule on Gaussians is far below 1e-10
    assert_allclose(gamma, gamma_q, rtol=1e-10, atol=1e-12 * np.abs(gamma_q).max())
    assert_allclose(K, K_q, rtol=1e-9, atol=1e-10 * np.abs(K_q).max())


@pytest.mark.parametrize("d", [2, 3])
def test_stiffness_components_are_the_entries(d, rng):
    r = rng.standard_normal((50, d))
    blocks = stiffness_entries(r, 0.7, 2.0, 1.5)
    comps, gamma = stiffness_components(r, 0.7, 2.0, 1.5)
    for (a, b), v in zip(stiffness_component_pairs(d), comps, strict=True):
        assert np.array_equal(v, blocks[:, a, b])  # the same operations
        assert_allclose(v, blocks[:, b, a], rtol=1e-15)  # K^ab = K^ba up to the last bit
    assert np.array_equal(gamma, gram_entries(r, 0.7)[1])


@pytest.mark.parametrize("d", [2, 3])
def test_stiffness_matrix_in_fortran_order_is_the_same_numbers(d, rng):
    """K_g laid out for LAPACK (written from the transposed offsets) holds bit for bit the
    numbers of the C-ordered one, block (a, b) and (b, a) alike (they differ in the last
    bit from each other, not between the layouts)."""
    x = rng.standard_normal((40, d))
    r = x[None, :, :] - x[:, None, :]
    c = stiffness_matrix(r, 0.7, 2.0, 1.5)
    f = stiffness_matrix(r, 0.7, 2.0, 1.5, order="F")
    assert f.flags.f_contiguous and c.flags.c_contiguous
    assert np.array_equal(c, f)


@pytest.mark.parametrize("d", [2, 3])
def test_self_entries(d):
    sigma, lam, mu = 0.7, 2.0, 1.5
    k, gamma = self_entries(sigma, d, lam, mu)
    V = (np.pi * sigma**2) ** (d / 2)
    assert_allclose(gamma, V, rtol=1e-15)
    assert_allclose(k, V / sigma**2 * ((lam + mu) / 2 + mu * d / 2), rtol=1e-14)
    blocks = stiffness_entries(np.zeros((1, d)), sigma, lam, mu)[0]
    assert_allclose(blocks, k * np.eye(d), rtol=1e-15, atol=0)  # isotropic at offset 0


def test_gram_is_interpolation_basis(hand200):
    model = FEModel(hand200)
    G, _ = model.gram
    assert_allclose(np.diag(G), 1.0)  # h_i(X_j) = delta_ij needs g_i(X_i) = 1
    assert_allclose(G, G.T)


def _check_matrices(model):
    M, K = model.mass, model.stiffness
    scale_m, scale_k = np.abs(M).max(), np.abs(K).max()
    assert_allclose(M, M.T, atol=1e-12 * scale_m)  # symmetric
    assert_allclose(K, K.T, atol=1e-12 * scale_k)
    assert np.linalg.eigvalsh(M).min() > 0  # M positive definite
    # K positive semi-definite, up to round-off relative to its largest eigenvalue
    ek = np.linalg.eigvalsh(K)
    assert ek.min() > -1e-10 * ek.max()


def test_matrices_hand(hand200):
    _check_matrices(FEModel(hand200))


def test_matrices_heart(hearts):
    for h in hearts:
        _check_matrices(FEModel(h))


def test_matrices_3d(rng):
    _check_matrices(FEModel(sphere_points(150, rng, radii=(1.0, 0.7, 0.4))))


def test_plane_strain_is_stiffer(hand200):
    stress = FEModel(hand200, plane="stress").modes(5).frequencies
    strain = FEModel(hand200, plane="strain").modes(5).frequencies
    assert np.all(strain > stress)  # lambda >= lambda*, so K grows


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"sigma": 0.0}, "sigma must be None"),
        ({"sigma": np.nan}, "sigma must be None"),
        ({"material": "steel"}, "material must be a Material"),
        ({"plane": "membrane"}, "plane must be 'stress' or 'strain'"),
    ],
)
def test_bad_options(hand200, kwargs, match):
    with pytest.raises(ValueError, match=match):
        FEModel(hand200, **kwargs)


def test_sigma_too_large_is_reported(hand200):
    model = FEModel(hand200, sigma=4.0)
    with pytest.raises(ValueError, match="too large .* numerically singular"):
        model.modes()


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"E": -1.0, "nu": 0.3, "rho": 1.0}, "E .* must be > 0"),
        ({"E": 1.0, "nu": 0.5, "rho": 1.0}, r"nu .* must be in \(-1, 0.5\)"),
        ({"E": 1.0, "nu": 0.3, "rho": 0.0}, "rho .* must be > 0"),
        ({"E": float("nan"), "nu": 0.3, "rho": 1.0}, "E must be a finite number"),
    ],
)
def test_material_validation(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Material(**kwargs)


def test_polyethylene_preset():
    assert POLYETHYLENE.name == "polyethylene"
    lam_star, mu = POLYETHYLENE.lame_2d("stress")
    E, nu = POLYETHYLENE.E, POLYETHYLENE.nu
    assert_allclose(lam_star, E * nu / (1 - nu**2))  # plane stress lambda*
    assert_allclose(mu, E / (2 * (1 + nu)))


@pytest.mark.parametrize("sigma", [1.0, 2.0])
def test_condition_bound_is_an_upper_bound(hand200, sigma):
    """condition_bound, which lets the dense solver skip Gamma's eigenvalues, is never
    below Gamma's condition number, and within the node count of it."""
    from scipy.linalg import lapack

    from modalmorph.core.element import condition_bound
    model = FEModel(hand200, sigma=sigma)
    gamma = model.gram[1]
    L, info = lapack.dpotrf(gamma, lower=1, clean=1)
    l_inv, info2 = lapack.dtrtri(L, lower=1)
    assert info == info2 == 0
    bound = condition_bound(gamma, l_inv)
    assert model.gamma_condition * (1 - 1e-9) <= bound <= model.m * model.gamma_condition


def test_coincident_nodes_are_named():
    """Two nodes closer than the narrowest width: the error names them, not sigma."""
    t = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    ring = np.c_[np.cos(t), np.sin(t)]
    ring[10] = ring[9] + 1e-9
    with pytest.raises(ValueError, match="nodes 9 and 10 .* nearly coincident"):
        FEModel(ring, sigma=None).modes()


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("order", ["C", "F"])
@pytest.mark.parametrize("chunk", [1, 3 * 8 * 23, 10**9])
def test_stiffness_matrix_by_rows_is_the_whole_array_bitwise(monkeypatch, d, order, chunk):
    """K_g written a few rows at a time (one row, 3 rows of 23 nodes, all rows at once)
    holds the numbers of stiffness_entries's whole-array evaluation, bit for bit, in the
    order asked; the offsets, r2 and gamma passed are left as they were."""
    import modalmorph.core.element as element

    monkeypatch.setattr(element, "_CHUNK_BYTES", chunk)
    x = np.random.default_rng(d).normal(size=(23, d))
    r = x[None, :, :] - x[:, None, :]
    r2 = np.einsum("...a,...a->...", r, r)
    gamma = gram_entries(r, 0.9, r2)[1]
    kept = [a.copy() for a in (r, r2, gamma)]
    whole = stiffness_entries(r, 0.9, 1.2, 0.4).transpose(2, 0, 3, 1).reshape(23 * d, -1)
    for kw in ({}, {"r2": r2, "gamma": gamma}):
        K = stiffness_matrix(r, 0.9, 1.2, 0.4, order=order, **kw)
        assert K.flags[f"{order}_CONTIGUOUS"]
        assert np.array_equal(K, whole)
    for a, b in zip((r, r2, gamma), kept, strict=True):
        assert np.array_equal(a, b)


@pytest.mark.parametrize("nominal", [2.0, 3.5])
def test_auto_sigma_on_the_model_s_own_factor(hand200, monkeypatch, nominal):
    """FEModel(sigma=None) takes auto_sigma's width whether its own Gamma shows the
    nominal one well conditioned (2.0) or not (3.5: regula falsi below it); a dense model
    at the nominal width factors Gamma once, for the check and the whitening both, and
    the whitening made twice is the same numbers."""
    from scipy.linalg import lapack

    from modalmorph.core import model as model_module
    from modalmorph.core.element import auto_sigma
    from modalmorph.core.solvers import dense
    from modalmorph.core.solvers.dense import whitened

    calls, bounds = [], []
    real = lapack.dpotrf
    monkeypatch.setattr(lapack, "dpotrf", lambda *a, **k: calls.append(1) or real(*a, **k))
    for module in (model_module, dense):  # the condition bound, made once too
        monkeypatch.setattr(module, "condition_bound", lambda *a, real=module.condition_bound:
                            bounds.append(1) or real(*a))
    model = FEModel(hand200, sigma=None, nominal_sigma=nominal)
    first = whitened(model)
    monkeypatch.setattr(lapack, "dpotrf", real)
    assert model.sigma == auto_sigma(hand200, nominal)
    if nominal == 2.0:
        assert model.sigma == nominal and len(calls) == 1 and len(bounds) == 1
    else:
        assert model.sigma < nominal
    for a, b in zip(first, whitened(model), strict=True):
        assert np.array_equal(a, b)


def test_model_offsets_and_squared_norms_as_broadcast_and_einsum():
    """FEModel's offset table, made a component at a time, and its 2D squared norms from
    the components: the broadcast difference and :func:`squared_norms` bit for bit."""
    from modalmorph.core.element import squared_norms
    from modalmorph.core.model import FEModel

    rng = np.random.default_rng(5)
    for m, d in ((7, 2), (70, 2), (33, 3)):
        model = FEModel(rng.normal(size=(m, d)) * rng.uniform(0.1, 10))
        x = model.points
        r = x[None, :, :] - x[:, None, :]
        assert np.array_equal(model._offsets, r)  # exact: the same subtractions
        assert model._offsets.flags.c_contiguous
        assert np.array_equal(model._r2, squared_norms(r))  # exact: einsum's sums
