"""Sclaroff's isoparametric Gaussian element: Gram integrals, mass and stiffness (1)-(4).

Every integral is over all of R^d and has a closed form (method.md §1). With
``r = X_j - X_i``, ``e_ij = exp(-|r|^2 / (4 sigma^2))`` and ``V = (pi sigma^2)^(d/2)``:

- ``Gamma_ij = V e_ij``                           (integral of g_i g_j)
- ``D^ab_ij = V e_ij / sigma^4 (delta_ab sigma^2 / 2 - r_a r_b / 4)``  (of dg_i/dx_a dg_j/dx_b)

The physical matrices use ``A = G^-1``: ``M = rho (I_d kron A Gamma A)`` and
``K_ab = A [(lambda + mu) D^ab + mu delta_ab sum_c D^cc] A``. ``A`` is never formed: the
eigenproblem is solved in the Gaussian basis (see :mod:`modalmorph.modes`), and the dense
``mass``/``stiffness`` properties use triangular solves with ``G``'s Cholesky factor.
"""

from __future__ import annotations

from functools import cached_property

import numpy as np
from scipy import linalg

from .material import POLYETHYLENE, Material
from .shape import Shape, as_shape

__all__ = ["FEModel", "DEFAULT_SIGMA", "gram_entries", "stiffness_entries"]

# sigma in units of the mean nearest-neighbour spacing; chosen by measurement, see README.
DEFAULT_SIGMA = 1.0


def gram_entries(r: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """Entries of ``G`` (1)-(2) and ``Gamma`` for node offsets ``r`` (..., d).

    Returns ``(g, gamma)``, each of shape ``r.shape[:-1]``.
    """
    d = r.shape[-1]
    r2 = np.einsum("...a,...a->...", r, r)
    g = np.exp(-r2 / (2 * sigma**2))  # (2) g_j(X_i)
    gamma = (np.pi * sigma**2) ** (d / 2) * np.exp(-r2 / (4 * sigma**2))
    return g, gamma


def stiffness_entries(r: np.ndarray, sigma: float, lam: float, mu: float) -> np.ndarray:
    """Blocks of the stiffness in the Gaussian basis, ``K_g[..., a, b]``, for offsets ``r``.

    ``K_g^ab = (lambda + mu) D^ab + mu delta_ab sum_c D^cc``, shape ``r.shape + (d,)``.
    """
    d = r.shape[-1]
    r2 = np.einsum("...a,...a->...", r, r)
    scale = (np.pi * sigma**2) ** (d / 2) * np.exp(-r2 / (4 * sigma**2)) / sigma**4
    out = (-(lam + mu) / 4) * r[..., :, None] * r[..., None, :]
    diag = (lam + mu) * sigma**2 / 2 + mu * (d * sigma**2 / 2 - r2 / 4)
    idx = np.arange(d)
    out[..., idx, idx] += diag[..., None]
    out *= scale[..., None, None]
    return out


class FEModel:
    """The physical model of one object with Sclaroff's Gaussian element.

    Parameters
    ----------
    shape : Shape or array_like, shape (m, d)
        The object. It is modelled in its normalised frame (centroid at the origin, unit
        RMS radius), so the model does not depend on position, orientation or units.
    sigma : float, optional
        Width of the Gaussians as a multiple of the mean nearest-neighbour spacing of the
        nodes (scale-free). Larger values couple nodes further apart (smoother low modes)
        but make the Gram matrices ill-conditioned; see the README for the measurements
        behind the default.
    material : Material, optional
        The material filling the object (default: polyethylene, the paper's choice).
    plane : {"stress", "strain"}, optional
        2D idealisation: plane stress (thin sheet, the default) or plane strain.

    Raises
    ------
    ValueError
        For an invalid shape, a non-positive sigma, or a sigma so large that the Gram
        matrix is numerically singular for this node set.
    """

    def __init__(self, shape, *, sigma: float = DEFAULT_SIGMA,
                 material: Material = POLYETHYLENE, plane: str = "stress"):
        self.shape: Shape = as_shape(shape)
        if not np.isfinite(sigma) or sigma <= 0:
            raise ValueError(f"sigma must be a positive finite number, got {sigma}")
        if not isinstance(material, Material):
            raise ValueError(f"material must be a Material, got {type(material).__name__}")
        self.sigma_rel = float(sigma)
        self.material = material
        self.plane = plane
        if self.dim == 2:
            self.lame = material.lame_2d(plane)
        else:
            if plane not in ("stress", "strain"):
                raise ValueError(f"plane must be 'stress' or 'strain', got {plane!r}")
            self.lame = material.lame
        self._modes = {}

    @property
    def dim(self) -> int:
        return self.shape.dim

    @property
    def m(self) -> int:
        return self.shape.m

    @property
    def points(self) -> np.ndarray:
        """Nodes in the normalised frame, shape (m, d)."""
        return self.shape.normalized

    @cached_property
    def sigma(self) -> float:
        """Absolute Gaussian width in the normalised frame."""
        return self.sigma_rel * self.shape.spacing

    @cached_property
    def _offsets(self) -> np.ndarray:
        x = self.points
        return x[None, :, :] - x[:, None, :]  # r_ij = X_j - X_i

    @cached_property
    def gram(self) -> tuple[np.ndarray, np.ndarray]:
        """Dense ``(G, Gamma)``, each (m, m)."""
        return gram_entries(self._offsets, self.sigma)

    @cached_property
    def stiffness_gaussian(self) -> np.ndarray:
        """Dense stiffness in the Gaussian basis, ``K_g`` (dm, dm), component-major (7)."""
        lam, mu = self.lame
        blocks = stiffness_entries(self._offsets, self.sigma, lam, mu)  # (m, m, d, d)
        dm = self.dim * self.m
        return np.ascontiguousarray(blocks.transpose(2, 0, 3, 1).reshape(dm, dm))

    @cached_property
    def _g_factor(self):
        G = self.gram[0]
        try:
            return linalg.cho_factor(G, lower=True, check_finite=False)
        except linalg.LinAlgError:
            raise ValueError(_breakdown_message(self)) from None

    def solve_gram(self, B: np.ndarray) -> np.ndarray:
        """``(I_d kron A) B`` for B of shape (dm, k) or (dm,), by solves with G's factor."""
        d, m = self.dim, self.m
        flat = np.asarray(B).reshape(d, m, -1).transpose(1, 0, 2).reshape(m, -1)
        X = linalg.cho_solve(self._g_factor, flat, check_finite=False)
        return X.reshape(m, d, -1).transpose(1, 0, 2).reshape(np.shape(B))

    def _sandwich(self, B: np.ndarray) -> np.ndarray:
        """``(I kron A) B (I kron A)`` for a symmetric (dm, dm) matrix."""
        out = self.solve_gram(self.solve_gram(B).T)
        return (out + out.T) / 2

    @property
    def mass(self) -> np.ndarray:
        """Dense mass matrix ``M = rho (I_d kron A Gamma A)``, (dm, dm), component-major."""
        Mg = self.material.rho * np.kron(np.eye(self.dim), self.gram[1])
        return self._sandwich(Mg)

    @property
    def stiffness(self) -> np.ndarray:
        """Dense stiffness matrix ``K = (I kron A) K_g (I kron A)``, (dm, dm)."""
        return self._sandwich(self.stiffness_gaussian)

    def modes(self, n: int | None = None):
        """The lowest ``n`` modes (all when ``None``) of ``K Phi = M Phi Omega^2`` (6).

        Returns
        -------
        Modes
            Frequencies ascending and mass-normalised mode shapes.
        """
        from .modes import solve_modes

        total = self.dim * self.m
        n = total if n is None else int(n)
        if not 1 <= n <= total:
            raise ValueError(f"n must be between 1 and {total} (d * m), got {n}")
        if n not in self._modes:
            self._modes[n] = solve_modes(self, n)
        return self._modes[n]

    def __repr__(self) -> str:
        return (f"FEModel(m={self.m}, d={self.dim}, sigma={self.sigma_rel:g}, "
                f"material={self.material.name})")


def _breakdown_message(model: FEModel, cond: float | None = None) -> str:
    what = f" (condition number {cond:.1e})" if cond is not None else ""
    return (f"sigma={model.sigma_rel:g} (x mean node spacing) is too large for this "
            f"{model.m}-node shape: the Gaussian Gram matrix is numerically singular{what}. "
            f"Use a smaller sigma (e.g. 1-2) or fewer nodes.")
