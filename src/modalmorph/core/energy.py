"""Strain energy of a deformation, globally (22) and per node (25)."""

from __future__ import annotations

import numpy as np

__all__ = ["strain_energy", "node_energy"]


def strain_energy(x: np.ndarray, eigenvalues: np.ndarray) -> np.ndarray:
    """Global strain energy ``E = U^T K U`` (22) of ``U = Phi x``, in modal coordinates.

    With ``Phi^T K Phi = Omega^2`` (13), ``E = x^T Omega^2 x``: a sum of non-negative terms,
    so the global energy is never negative. The paper's definition omits the usual 1/2.

    Parameters
    ----------
    x : ndarray, shape (..., n)
        Modal displacements.
    eigenvalues : ndarray, shape (n,)
        ``omega^2`` of the modes.
    """
    return np.einsum("...n,n,...n->...", x, eigenvalues, x)


def node_energy(U: np.ndarray, KU: np.ndarray, dim: int) -> np.ndarray:
    """Local strain energy per node, ``e_i = sum_a u_(a,i) (K U)_(a,i)`` (24)-(25).

    Parameters
    ----------
    U, KU : ndarray, shape (..., d*m)
        Nodal displacements and their elastic forces ``K U``, component-major (7).
    dim : int
        Spatial dimension d.

    Returns
    -------
    ndarray, shape (..., m)
        Energy per node, summed over its d degrees of freedom. Local values may be
        negative; they add up to the global energy (22).
    """
    prod = U * KU
    return prod.reshape(*prod.shape[:-1], dim, -1).sum(axis=-2)
