"""Vibration modes of a model (6), (13) and Rayleigh damping (5)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import linalg

__all__ = ["Modes", "solve_modes", "rayleigh", "MAX_CONDITION"]

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
    (method.md §1). Gamma is diagonalised once: that whitens ``M_g`` and measures its
    condition, so a sigma too large for the node set is refused with a clear error.
    """
    from .element import _breakdown_message

    d, m = model.dim, model.m
    Gamma = model.gram[1]
    lam_g, Q = linalg.eigh(Gamma, check_finite=False)
    cond = lam_g[-1] / lam_g[0] if lam_g[0] > 0 else np.inf
    if not cond < MAX_CONDITION:
        raise ValueError(_breakdown_message(model, cond))
    W = Q / np.sqrt(lam_g)  # W^T Gamma W = I
    Kg = model.stiffness_gaussian.reshape(d, m, d, m)
    # whitened stiffness: (I kron W)^T K_g (I kron W), block by block
    Kw = np.einsum("ip,aibj,jq->apbq", W, Kg, W, optimize=True).reshape(d * m, d * m)
    Kw = (Kw + Kw.T) / 2
    subset = None if n == d * m else (0, n - 1)
    w2, Y = linalg.eigh(Kw, subset_by_index=subset, check_finite=False,
                        driver="evr" if subset else "evd")
    psi = (W @ Y.reshape(d, m, n).transpose(1, 0, 2).reshape(m, -1))  # (I kron W) Y
    psi = psi.reshape(m, d, n).transpose(1, 0, 2).reshape(d * m, n) / np.sqrt(model.material.rho)
    phi = _apply_blockwise(model.gram[0], psi, d)  # Phi = (I kron G) psi
    w2 = w2 / model.material.rho
    return Modes(frequencies=np.sqrt(np.clip(w2, 0.0, None)), shapes=phi, gaussian=psi, dim=d)


def _apply_blockwise(B: np.ndarray, X: np.ndarray, d: int) -> np.ndarray:
    """``(I_d kron B) X`` for B (m, m) and X (d*m, n)."""
    m = B.shape[0]
    return np.einsum("ij,ajn->ain", B, X.reshape(d, m, -1)).reshape(X.shape)


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
    if xi1 < 0 or xi2 < 0:
        raise ValueError(f"damping ratios must be >= 0, got {xi1}, {xi2}")
    if not 0 <= w1 < w2:
        raise ValueError(f"need 0 <= w1 < w2 for Rayleigh damping, got w1={w1}, w2={w2}")
    den = w2**2 - w1**2
    alpha = 2 * w1 * w2 * (xi1 * w2 - xi2 * w1) / den
    beta = 2 * (xi2 * w2 - xi1 * w1) / den
    return alpha, beta
