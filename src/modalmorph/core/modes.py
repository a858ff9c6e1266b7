"""The vibration modes of a model (6), (13), as the eigensolvers return them, and Rayleigh
damping (5)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Modes", "rayleigh"]


@dataclass(frozen=True, eq=False, repr=False)
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

    def __repr__(self) -> str:
        f = self.frequencies
        return (f"Modes({len(f)} modes of {self.shapes.shape[0] // self.dim} nodes in "
                f"{self.dim}D, frequencies {f.min():.4g} .. {f.max():.4g})")

    @property
    def n(self) -> int:
        return self.frequencies.shape[0]

    @property
    def eigenvalues(self) -> np.ndarray:
        """``omega^2``, shape (n,)."""
        return self.frequencies**2

    @classmethod
    def unit_density(cls, w2: np.ndarray, psi: np.ndarray, phi: np.ndarray, rho: float,
                     dim: int) -> Modes:
        """The modes of a model of density ``rho`` from the solution for density 1:
        eigenvalues ``w2`` of ``K_g psi = w2 (I kron Gamma) psi`` with
        ``psi^T (I kron Gamma) psi = I`` and ``phi = (I kron G) psi``."""
        root = np.sqrt(rho)
        return cls(frequencies=np.sqrt(np.clip(w2 / rho, 0.0, None)), shapes=phi / root,
                   gaussian=psi / root, dim=dim)

    def node_shapes(self) -> np.ndarray:
        """Mode shapes per node, shape (m, d, n): displacement of node i in mode j."""
        d = self.dim
        return self.shapes.reshape(d, -1, self.n).transpose(1, 0, 2)


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
