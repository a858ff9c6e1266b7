"""The dense eigensolver: every mode of the exact model, LAPACK (6), (13)."""

from __future__ import annotations

import functools

import numpy as np
from scipy import linalg
from scipy.linalg import blas, lapack

from ..element import MAX_CONDITION, condition_bound, singular_gram
from ..modes import Modes

__all__ = ["solve", "symmetrize", "whitened"]

# Below this fraction of the spectrum, from this size up, LAPACK evr beats evd (method.md §7).
_SUBSET_FRACTION, _SUBSET_MIN = 0.15, 200
# Tiles of the in-place symmetrisation, 120 x 120 doubles (113 KiB, under glibc's default
# 128 KiB mmap threshold): at n = 2400, one thread, 6.2 ms against 7.0 with tiles of 64,
# 12.6-15.1 with 256-512 and 11.0 for the whole-array expression (n = 800: 0.52 / 0.63).
_TILE = 120
# dsyevd rescales a matrix whose largest entry lies outside [RMIN, RMAX] = [sqrt(tiny /
# eps), sqrt(eps / tiny)], dstevd a tridiagonal likewise; _evd_lowest runs where neither
# does (an n x n matrix's tridiagonal's largest entry is within n of the matrix's).
_SAFE_MIN = np.sqrt(np.finfo(float).tiny / np.finfo(float).eps)
_SAFE_MAX = 1.0 / _SAFE_MIN


def solve(model, n: int) -> Modes:
    """Solve ``K Phi = M Phi Omega^2`` (6) for the lowest ``n`` modes of a dense model.

    The problem is solved in the Gaussian basis, ``K_g psi = w^2 M_g psi`` with
    ``M_g = rho (I kron Gamma)``, which is the same problem without inverting G
    (method.md §1). A bound of Gamma's condition from its Cholesky factor
    (:func:`~modalmorph.core.element.condition_bound`), or where that is not small enough
    its eigenvalues, refuse a sigma too large for the node set with a clear error;
    the inverse of its Cholesky factor, ``W = L^-T``, whitens ``M_g``.

    ``model`` is a :class:`modalmorph.core.model.FEModel` (its dense ``gram``,
    ``gamma_condition`` and a work copy of ``K_g``, ``stiffness_gaussian_work``).
    """
    d, m = model.dim, model.m
    _, Linv, Kw = whitened(model)
    w2, Y = _eigh_lowest(Kw, n)
    psi = np.matmul(Linv.T, Y.reshape(d, m, n))  # (I kron W) Y, W = L^-T
    phi = np.matmul(model.gram[0], psi)  # Phi = (I kron G) psi
    return Modes.unit_density(w2, psi.reshape(d * m, n), phi.reshape(d * m, n),
                              model.material.rho, d)


def whitened(model) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(L, L^-1, K_w)``: the lower Cholesky factor of Gamma, its inverse, and the
    stiffness in the basis ``psi = I kron W``, ``W = L^-T`` (orthonormal in ``M_g`` of
    unit density), ``K_w = (I kron W)^T K_g (I kron W)``, exactly symmetric, in Fortran
    order (an eigensolver may overwrite it), after Gamma's conditioning check: a bound
    from its factor (:func:`~modalmorph.core.element.condition_bound`), or where that is
    not small enough its eigenvalues, refuse a sigma too large for the node set."""
    Gamma = model.gram[1]
    L, Linv, info, bound = model.take_gamma_factor()  # dpotrf, then dtrtri
    if info == 0 and bound is None:  # not made yet (sigma=None made it for its test)
        bound = condition_bound(Gamma, Linv)
    # the exact condition number only where the bound does not show it small enough
    if info != 0 or not bound < MAX_CONDITION:
        cond = model.gamma_condition
        if not cond < MAX_CONDITION or info != 0:
            raise singular_gram(model.shape, model.sigma, cond)
    return L, Linv, _whiten(model.stiffness_gaussian_work(), Linv, model.dim, model.m)


def _whiten(Kw: np.ndarray, Linv: np.ndarray, d: int, m: int) -> np.ndarray:
    """The whitened stiffness ``(I kron W)^T K_g (I kron W)``, ``W = L^-T``, by triangular
    products on the (m, m) blocks (BLAS trmm: half the flops of a GEMM, and 5.2x faster
    than the GEMMs on the reshaped blocks used before: 800 x 800, one thread, 56 ms ->
    11 ms, equal to 3e-16), in place in ``Kw`` (``K_g`` in Fortran order)."""
    for b in range(d):  # right factor: the columns of block b times L^-T
        Kw[:, b * m:(b + 1) * m] = blas.dtrmm(1.0, Linv, Kw[:, b * m:(b + 1) * m], side=1,
                                              lower=1, trans_a=1, overwrite_b=1)
    for a in range(d):  # left factor: L^-1 times the rows of block a
        Kw[a * m:(a + 1) * m] = blas.dtrmm(1.0, Linv, Kw[a * m:(a + 1) * m], lower=1)
    symmetrize(Kw)  # exactly symmetric, in LAPACK's (Fortran) order
    return Kw


def symmetrize(A: np.ndarray, tile: int = _TILE) -> None:
    """``A = (A + A^T) / 2`` in place, tile by tile (no (n, n) temporary; each entry is
    the same sum, so bitwise the whole-array expression)."""
    n = len(A)
    for i in range(0, n, tile):
        for j in range(i, n, tile):
            t = A[i:i + tile, j:j + tile] + A[j:j + tile, i:i + tile].T
            t /= 2
            A[i:i + tile, j:j + tile] = t
            A[j:j + tile, i:i + tile] = t.T


def _eigh_lowest(A: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``n`` smallest eigenpairs of the symmetric matrix ``A``, ascending."""
    N = A.shape[0]
    if n <= _SUBSET_FRACTION * N and N >= _SUBSET_MIN:
        return linalg.eigh(A, subset_by_index=(0, n - 1), driver="evr", check_finite=False,
                           overwrite_a=True)
    if n < N and _SAFE_MIN * N < np.abs(A).max() < _SAFE_MAX / N:
        return _evd_lowest(A, n)
    w, V = linalg.eigh(A, driver="evd", check_finite=False, overwrite_a=True)
    return w[:n], V[:, :n]


def _evd_lowest(A: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """LAPACK's ``dsyevd`` (lower) in its three steps, its last on ``n`` columns only:
    the tridiagonal reduction ``dsytrd``, every eigenpair of the tridiagonal by divide and
    conquer (``dstevd``: the ``dstedc`` that ``dsyevd`` calls) and the reflectors
    applied to the lowest ``n`` (``dormqr`` on the rows below the first, as ``dormtr``
    does), not to all of them. The same numbers as ``eigh(driver="evd")`` (bitwise on
    212 matching models of the speed corpus, 140 and 300 degrees of freedom) for ``A``
    within the range ``dsyevd`` does not rescale (:data:`_SAFE_MIN`, :data:`_SAFE_MAX`);
    140 x 140, 24 modes, one thread: 1.00 -> 0.85 ms. ``A`` is overwritten."""
    N = A.shape[0]
    c, d, e, tau, info = lapack.dsytrd(A, lower=1, lwork=_lwork(lapack.dsytrd_lwork, N, 1),
                                       overwrite_a=1)
    if info == 0:
        w, Z, info = lapack.dstevd(d, e, compute_v=1, overwrite_d=1, overwrite_e=1)
    if info != 0:
        raise linalg.LinAlgError(f"the dense eigensolver failed (LAPACK info {info})")
    Z = np.asfortranarray(Z[:, :n])  # Q = diag(1, Q1), Q1 the reflectors below the first row
    Z[1:], _, info = lapack.dormqr("L", "N", c[1:, :N - 1], tau[:N - 1], Z[1:],
                                   _dormqr_lwork(N, n), overwrite_c=1)
    if info != 0:
        raise linalg.LinAlgError(f"the dense eigensolver failed (LAPACK dormqr info {info})")
    return w[:n], Z


@functools.cache
def _lwork(query, *args) -> int:
    """The optimal workspace of a LAPACK routine (its ``*_lwork`` query), per size."""
    return int(query(*args)[0])


@functools.cache
def _dormqr_lwork(N: int, n: int) -> int:
    """``dormqr``'s optimal workspace for ``N - 1`` reflectors applied to ``n`` columns."""
    a = np.zeros((N - 1, N - 1), order="F")
    return int(lapack.dormqr("L", "N", a, np.zeros(N - 1), np.zeros((N - 1, n), order="F"),
                             -1)[1][0])
