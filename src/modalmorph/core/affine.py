"""Moving least squares with linear precision: the weights that evaluate, at a point, the
Gaussian-weighted least-squares affine fit of values at its neighbours (method.md §7).

Every affine field (translations, rotations' displacements ``(R - I) x``, stretches) is
reproduced at any point, unlike a weighted mean of the neighbours' values (exact for
constants only) or a Gaussian interpolant (which ripples between its nodes).
"""

from __future__ import annotations

import numpy as np

__all__ = ["AFFINE_RIDGE", "affine_fit_weights"]

# The fit's gradient damped by this (in units of the Gaussian's width): neighbours nearly
# in a plane (a surface) leave the gradient across it undetermined. Measured on the bunny
# (1839 nodes, its 400-node reduced model's nodes as neighbours): a 90 deg turn's
# displacement is reproduced to 6e-4 sizes at worst (1e-4 with 1e-5; 0.02 with 1e-2).
AFFINE_RIDGE = 1e-4


def affine_fit_weights(near: np.ndarray, points: np.ndarray, width) -> np.ndarray:
    """Weights (p, k) such that ``sum_j w_pj f(near_pj)`` is the value at ``points[p]``
    of the least-squares affine fit of ``f`` at its ``k`` neighbours ``near[p]``,
    weighted by ``exp(-r^2 / (2 width^2))`` (``width``: a scalar or one per point).

    Parameters
    ----------
    near : ndarray, shape (p, k, d)
    points : ndarray, shape (p, d)
    width : float or ndarray, shape (p,)
    """
    p, k, d = near.shape
    width = np.broadcast_to(np.asarray(width, dtype=np.float64), (p,))[:, None]
    rel = (near - points[:, None, :]) / width[:, :, None]
    w = np.exp(-0.5 * np.einsum("pki,pki->pk", rel, rel))
    w /= w.sum(axis=1, keepdims=True)
    P = np.concatenate([np.ones((p, k, 1)), rel], axis=2)  # the affine basis [1, x - p]
    A = np.einsum("pk,pki,pkj->pij", w, P, P)
    A[:, 1:, 1:] += AFFINE_RIDGE * np.eye(d)
    e0 = np.zeros((p, d + 1, 1))
    e0[:, 0] = 1.0
    c = np.linalg.solve(A, e0)[..., 0]  # the fit's value at the point: e_0^T A^-1 P^T W
    return w * np.einsum("pki,pi->pk", P, c)
