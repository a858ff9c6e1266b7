"""The sparse eigensolver: the lowest modes of the truncated model by shift-invert Lanczos."""

from __future__ import annotations

import warnings

import numpy as np
from scipy import linalg, sparse
from scipy.sparse import linalg as splinalg

from ..element import MAX_CONDITION, singular_gram
from ..modes import Modes

__all__ = ["solve", "spd_factor", "SPARSE_RESIDUAL_TOL"]

# Sparse solver: relative residual ||K_g psi - w^2 M_g psi|| / (||K_g|| ||psi||) above
# which a computed mode is rejected (ARPACK converges to ~1e-14 when the problem is sane).
SPARSE_RESIDUAL_TOL = 1e-8


def solve(model, n: int) -> Modes:
    """The lowest ``n`` modes of the truncated (sparse) model, by shift-invert Lanczos.

    ``K_g psi = w^2 M_g psi`` with sparse ``K_g`` and ``M_g = rho (I kron Gamma)``
    truncated at ``model.cutoff_radius``. With a shift ``s`` just below the lowest
    eigenvalue (estimated by a few LOBPCG steps, checked by Sylvester's inertia),
    ``K_g - s M_g`` is positive definite; it is factorised (SuperLU, symmetric mode) and
    ARPACK finds the eigenvalues of ``(K_g - s M_g)^-1 M_g`` of largest magnitude, i.e.
    the lowest ``w^2``. A final
    Rayleigh-Ritz step in the computed subspace makes ``psi^T M_g psi = I`` exact to
    round-off. No dense m x m matrix is formed.

    Ill-conditioning (sigma too large for the node set, or a cutoff too coarse for
    Gamma's condition) is detected by the condition number of the truncated Gamma
    (estimated with two Lanczos runs), a failed factorisation, or large residuals, and
    refused with a :class:`~modalmorph.errors.ModelError`. ``model`` is a
    :class:`modalmorph.core.model.FEModel` (its ``gram_sparse`` and
    ``stiffness_gaussian_sparse``).
    """
    d, m = model.dim, model.m
    G, Gamma = model.gram_sparse
    Kg = model.stiffness_gaussian_sparse

    cond = _condition_spd(Gamma)
    if not cond < MAX_CONDITION:
        raise singular_gram(model.shape, model.sigma, cond)

    Mg = sparse.block_diag([Gamma] * d, format="csr")
    lu, shift = _shifted_factor(Kg, Mg, model)
    OPinv = splinalg.LinearOperator(Kg.shape, matvec=lu.solve, dtype=np.float64)
    v0 = np.random.default_rng(0).standard_normal(d * m)  # same inputs, same outputs
    w2, psi = splinalg.eigsh(Kg, k=n, M=Mg, sigma=shift, which="LM", OPinv=OPinv, v0=v0,
                             ncv=min(d * m, max(2 * n + 1, 20)))
    # Rayleigh-Ritz in the computed subspace: exact M_g-orthonormality, sorted values
    MgPsi = Mg @ psi
    KgPsi = Kg @ psi
    Mr, Kr = psi.T @ MgPsi, psi.T @ KgPsi
    w2, R = linalg.eigh((Kr + Kr.T) / 2, (Mr + Mr.T) / 2, check_finite=False)
    psi, MgPsi, KgPsi = psi @ R, MgPsi @ R, KgPsi @ R
    residual = np.linalg.norm(KgPsi - MgPsi * w2, axis=0)
    k_norm = splinalg.norm(Kg, 1)
    if not np.all(residual <= SPARSE_RESIDUAL_TOL * k_norm * np.linalg.norm(psi, axis=0)):
        raise singular_gram(model.shape, model.sigma, detail=" (sparse eigensolver "
                            f"residuals {residual.max() / k_norm:.1e})")
    phi = np.stack([G @ p for p in psi.reshape(d, m, n)]).reshape(d * m, n)
    return Modes.unit_density(w2, psi, phi, model.material.rho, d)


def spd_factor(A):
    """Sparse LU of a symmetric matrix with a symmetric ordering and no pivoting
    (SuperLU's symmetric mode): ``P A P^T = L D L^T`` with ``D = diag(U)``."""
    return splinalg.splu(A.tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                         options={"SymmetricMode": True})


def _negative_pivots(lu) -> int | None:
    """Eigenvalues below 0 of the factorised matrix (Sylvester's inertia), or None when
    the factorisation pivoted and the count cannot be read from it."""
    if not np.array_equal(lu.perm_r, lu.perm_c):
        return None
    return int(np.count_nonzero(lu.U.diagonal() < 0))


# Shift-invert 2% below an 8-step LOBPCG estimate of the lowest eigenvalue (method.md §7).
_SHIFT_MARGIN = 0.02
_ESTIMATE_BLOCK, _ESTIMATE_STEPS = 8, 8


def _shifted_factor(Kg, Mg, model):
    """Factor ``K_g - s M_g`` for a shift ``s`` a little below the lowest eigenvalue.

    A few LOBPCG steps (preconditioned by the factor at ``s ~ 0``) give a Ritz value
    ``l1 >= w^2_1``; ``s = 0.98 l1`` is then checked by the inertia of its factor (no
    negative pivot means ``s < w^2_1``) and lowered if needed.
    """
    scale = float(np.mean(Kg.diagonal()) / np.mean(Mg.diagonal()))  # upper spectrum
    base = -1e-6 * scale  # K_g is positive semi-definite: K_g - base M_g is SPD
    try:
        lu0 = spd_factor(Kg - base * Mg)
    except RuntimeError:  # "Factor is exactly singular"
        raise singular_gram(model.shape, model.sigma) from None
    if _negative_pivots(lu0):
        raise singular_gram(model.shape, model.sigma, detail=" (the truncated M_g or "
                            "K_g is indefinite; use a smaller cutoff)")
    N = Kg.shape[0]
    b = min(_ESTIMATE_BLOCK, N // 5)
    if b < 1:
        return lu0, base
    solve = lambda X: lu0.solve(np.asfortranarray(X))  # noqa: E731
    T = splinalg.LinearOperator(Kg.shape, matvec=solve, matmat=solve, dtype=np.float64)
    X = np.random.default_rng(1).standard_normal((N, b))
    with warnings.catch_warnings():  # an estimate: not converging is expected
        warnings.simplefilter("ignore")
        ritz, _ = splinalg.lobpcg(Kg, X, B=Mg, M=T, largest=False,
                                  maxiter=_ESTIMATE_STEPS, tol=1e-12)
    l1 = float(np.min(ritz))
    if not (np.isfinite(l1) and l1 > base):
        return lu0, base
    shift = l1 * (1 - _SHIFT_MARGIN)
    for _ in range(3):
        try:
            lu = spd_factor(Kg - shift * Mg)
        except RuntimeError:
            lu = None
        if lu is not None and _negative_pivots(lu) == 0:
            return lu, shift
        shift = l1 - 4 * (l1 - shift)  # below w^2_1 after all: step further down
        if shift <= base:
            break
    return lu0, base


def _condition_spd(A: sparse.csr_array) -> float:
    """2-norm condition number of a sparse symmetric positive definite matrix (Lanczos on
    A for the largest eigenvalue, and on A^-1, by sparse LU, for the smallest)."""
    v0 = np.random.default_rng(0).standard_normal(A.shape[0])
    top = splinalg.eigsh(A, k=1, which="LA", v0=v0, tol=1e-3, return_eigenvectors=False)[0]
    try:
        lu = spd_factor(A)
    except RuntimeError:
        return np.inf
    inv = splinalg.LinearOperator(A.shape, matvec=lu.solve, dtype=np.float64)
    # the inverse's spectrum: its largest magnitude eigenvalue is 1 / lambda_min (or
    # negative when truncation broke positive definiteness)
    low = splinalg.eigsh(inv, k=1, which="LM", v0=v0, tol=1e-3, return_eigenvectors=False)[0]
    if not low > 0:
        return np.inf
    return float(top * low)


