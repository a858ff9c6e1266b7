"""Vibration modes of a model (6), (13) and Rayleigh damping (5)."""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from scipy import linalg, sparse
from scipy.linalg import lapack
from scipy.sparse import linalg as splinalg

__all__ = ["Modes", "solve_modes", "solve_modes_sparse", "rayleigh", "MAX_CONDITION"]

# Beyond this condition number of Gamma the mass-normalisation loses more than ~4 of its
# 16 digits (Phi^T M Phi = I is then only good to ~1e-4): refuse instead of returning noise.
MAX_CONDITION = 1e12


@dataclass(frozen=True, eq=False)
class Modes:
    """Mass-normalised vibration modes of one model.

    Attributes
    ----------
    frequencies : ndarray, shape (n,)
        Angular frequencies ``omega_i``, ascending (rad per unit time, normalised object).
    shapes : ndarray, shape (d*m, n)
        ``Phi``, one column per mode, degrees of freedom component-major (7): all x, then
        all y (then all z). ``Phi^T M Phi = I`` and ``Phi^T K Phi = diag(omega^2)`` (13).
    gaussian : ndarray, shape (d*m, n)
        The same modes in the Gaussian basis, ``psi`` with ``Phi = (I_d kron G) psi``.
    dim : int
        Spatial dimension d.
    """

    frequencies: np.ndarray
    shapes: np.ndarray
    gaussian: np.ndarray
    dim: int

    @property
    def n(self) -> int:
        return self.frequencies.shape[0]

    @property
    def eigenvalues(self) -> np.ndarray:
        """``omega^2``, shape (n,)."""
        return self.frequencies**2

    def node_shapes(self) -> np.ndarray:
        """Mode shapes per node, shape (m, d, n): displacement of node i in mode j."""
        d = self.dim
        return self.shapes.reshape(d, -1, self.n).transpose(1, 0, 2)


def solve_modes(model, n: int) -> Modes:
    """Solve ``K Phi = M Phi Omega^2`` (6) for the lowest ``n`` modes of a dense model.

    The problem is solved in the Gaussian basis, ``K_g psi = w^2 M_g psi`` with
    ``M_g = rho (I kron Gamma)``, which is the same problem without inverting G
    (method.md §1). Gamma's eigenvalues (without vectors, a fraction of the cost) give
    its condition, so a sigma too large for the node set is refused with a clear error;
    the inverse of its Cholesky factor, ``W = L^-T``, whitens ``M_g``.
    """
    from .element import _breakdown_message

    d, m = model.dim, model.m
    G, Gamma = model.gram
    cond = model.gamma_condition
    L, info = lapack.dpotrf(Gamma, lower=1, clean=1)
    if info == 0:
        Linv, info = lapack.dtrtri(L, lower=1)
    if not cond < MAX_CONDITION or info != 0:
        raise ValueError(_breakdown_message(model, cond))
    W = Linv.T  # W^T Gamma W = I
    # whitened stiffness (I kron W)^T K_g (I kron W): two GEMMs on the (d, m, d, m) blocks
    # (faster than triangular solves with L at every size measured, 70-300 nodes)
    Kw = model.stiffness_gaussian.reshape(d, m, d, m) @ W  # right factor, one GEMM
    Kw = np.matmul(Linv, Kw.reshape(d, m, d * m)).reshape(d * m, d * m)  # left, per block row
    Kw = (Kw + Kw.T) / 2
    w2, Y = _eigh_lowest(Kw, n)
    psi = np.matmul(W, Y.reshape(d, m, n)) / np.sqrt(model.material.rho)  # (I kron W) Y
    phi = np.matmul(G, psi)  # Phi = (I kron G) psi
    w2 = w2 / model.material.rho
    return Modes(frequencies=np.sqrt(np.clip(w2, 0.0, None)), shapes=phi.reshape(d * m, n),
                 gaussian=psi.reshape(d * m, n), dim=d)


# Below this fraction of the spectrum, and from this size up, LAPACK's MRRR with an index
# range (evr) beats the divide-and-conquer solver (evd), which always computes every
# eigenvector (OPENBLAS_NUM_THREADS=1, 24 and 48 of 140-800: evd 1.5/3.0/8.9/24/87 ms at
# 140/200/320/500/800, evr 24 modes 1.8/2.8/5.5/12/40 ms, evr 20 % 1.9/4.1/10/27/84 ms).
_SUBSET_FRACTION, _SUBSET_MIN = 0.15, 200


def _eigh_lowest(A: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``n`` smallest eigenpairs of the symmetric matrix ``A``, ascending."""
    N = A.shape[0]
    if n <= _SUBSET_FRACTION * N and N >= _SUBSET_MIN:
        return linalg.eigh(A, subset_by_index=(0, n - 1), driver="evr", check_finite=False,
                           overwrite_a=True)
    w, V = linalg.eigh(A, driver="evd", check_finite=False, overwrite_a=True)
    return w[:n], V[:, :n]


# Sparse solver: relative residual ||K_g psi - w^2 M_g psi|| / (||K_g|| ||psi||) above
# which a computed mode is rejected (ARPACK converges to ~1e-14 when the problem is sane).
SPARSE_RESIDUAL_TOL = 1e-8


def solve_modes_sparse(model, n: int) -> Modes:
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
    refused with a ValueError.
    """
    from .element import _breakdown_message

    d, m = model.dim, model.m
    rho = model.material.rho
    G, Gamma = model.gram_sparse
    Kg = model.stiffness_gaussian_sparse

    cond = _condition_spd(Gamma)
    if not cond < MAX_CONDITION:
        raise ValueError(_breakdown_message(model, cond))

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
        raise ValueError(_breakdown_message(model) + " (sparse eigensolver residuals "
                         f"{residual.max() / k_norm:.1e})")
    psi = psi / np.sqrt(rho)  # psi^T (rho M_g) psi = I
    phi = np.stack([G @ p for p in psi.reshape(d, m, n)]).reshape(d * m, n)
    w2 = w2 / rho
    return Modes(frequencies=np.sqrt(np.clip(w2, 0.0, None)), shapes=phi, gaussian=psi, dim=d)


def _spd_factor(A):
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


# Shift-invert Lanczos converges fast only when the shift lies close below the lowest
# eigenvalue: the low spectrum of the Gaussian element is a tight cluster (the lowest 50
# frequencies of a 16000-node contour lie within 0.3%), and a shift at 0 maps it to nearly
# equal values: 57 s against 2.7 s with a shift 1% below (measured on that contour).
# Eight LOBPCG steps (block of 8, preconditioned by the factor at ~0) put the lowest Ritz
# value within 0.02-1.1% above the lowest eigenvalue on contours of 1000-16000 nodes and
# ellipsoids of 800-2000 (measured); the shift is placed 2% below it.
_SHIFT_MARGIN = 0.02
_ESTIMATE_BLOCK, _ESTIMATE_STEPS = 8, 8


def _shifted_factor(Kg, Mg, model):
    """Factor ``K_g - s M_g`` for a shift ``s`` a little below the lowest eigenvalue.

    A few LOBPCG steps (preconditioned by the factor at ``s ~ 0``) give a Ritz value
    ``l1 >= w^2_1``; ``s = 0.98 l1`` is then checked by the inertia of its factor (no
    negative pivot means ``s < w^2_1``) and lowered if needed.
    """
    from .element import _breakdown_message

    scale = float(np.mean(Kg.diagonal()) / np.mean(Mg.diagonal()))  # upper spectrum
    base = -1e-6 * scale  # K_g is positive semi-definite: K_g - base M_g is SPD
    try:
        lu0 = _spd_factor(Kg - base * Mg)
    except RuntimeError:  # "Factor is exactly singular"
        raise ValueError(_breakdown_message(model)) from None
    if _negative_pivots(lu0):
        raise ValueError(_breakdown_message(model) + " (the truncated M_g or K_g is "
                         "indefinite; use a smaller cutoff)")
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
            lu = _spd_factor(Kg - shift * Mg)
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
        lu = _spd_factor(A)
    except RuntimeError:
        return np.inf
    inv = splinalg.LinearOperator(A.shape, matvec=lu.solve, dtype=np.float64)
    # the inverse's spectrum: its largest magnitude eigenvalue is 1 / lambda_min (or
    # negative when truncation broke positive definiteness)
    low = splinalg.eigsh(inv, k=1, which="LM", v0=v0, tol=1e-3, return_eigenvectors=False)[0]
    if not low > 0:
        return np.inf
    return float(top * low)


def rayleigh(xi1: float, xi2: float, w1: float, w2: float) -> tuple[float, float]:
    """Rayleigh coefficients ``(alpha, beta)`` with ``C = alpha M + beta K`` (5).

    Mode ``i`` then has the damping ratio ``xi_i = alpha / (2 w_i) + beta w_i / 2``, which
    equals ``xi1`` at ``w1`` and ``xi2`` at ``w2``.

    Parameters
    ----------
    xi1, xi2 : float
        Damping ratios (fractions of critical damping, e.g. 0.005 and 0.03), >= 0.
    w1, w2 : float
        The two angular frequencies where they hold, ``0 <= w1 < w2``.
    """
    xi1, xi2, w1, w2 = (np.float64(v) for v in (xi1, xi2, w1, w2))
    if not np.isfinite([xi1, xi2, w1, w2]).all():
        raise ValueError(f"Rayleigh damping needs finite values, got xi1={xi1}, xi2={xi2}, "
                         f"w1={w1}, w2={w2}")
    if xi1 < 0 or xi2 < 0:
        raise ValueError(f"damping ratios must be >= 0, got {xi1}, {xi2}")
    if not 0 <= w1 < w2:
        raise ValueError(f"need 0 <= w1 < w2 for Rayleigh damping, got w1={w1}, w2={w2}")
    with np.errstate(all="ignore"):
        den = w2**2 - w1**2
        alpha = 2 * w1 * w2 * (xi1 * w2 - xi2 * w1) / den
        beta = 2 * (xi2 * w2 - xi1 * w1) / den
    if not (np.isfinite(alpha) and np.isfinite(beta)):
        raise ValueError(f"Rayleigh coefficients overflow for w1={w1}, w2={w2}")
    return float(alpha), float(beta)
