"""Lowest modes of a large model without a sparse factorisation: coarse start + LOBPCG.

The sparse solver (:func:`modalmorph.modes.solve_modes_sparse`) factorises
``K_g - s M_g``; for 3D point sets, where each node has some 200-300 neighbours within the
cutoff radius, that factor does not fit in memory beyond a few thousand nodes. This solver
only multiplies by the full model's sparse matrices:

1. **Coarse start.** A model of the same object on ``coarse_nodes`` nodes
   (:func:`modalmorph.shape.coarsen`, the dense or sparse solver) gives its lowest ``k``
   modes; their displacement fields, evaluated at the fine nodes
   (:meth:`FEModel.modes_at`), are smooth, and so are the fine model's low modes in the
   Gaussian basis: their span is the starting subspace.
2. **Rayleigh-Ritz** with the full model's ``K_g`` and ``M_g = rho (I kron Gamma)``.
3. **LOBPCG** (Knyazev's locally optimal block preconditioned conjugate gradient) on
   ``K_g psi = w^2 M_g psi`` with a block of ``k > n`` vectors, preconditioned by exact
   solves with ``K_g`` restricted to small patches of neighbouring nodes (block Jacobi),
   until every wanted mode's relative residual
   ``||K_g psi - w^2 M_g psi|| / (w^2 ||M_g psi||)`` is below ``tol``.

Work and memory are linear in the number of pairs within the cutoff: ``K_g`` is stored
once per pair as a d x d block (:attr:`FEModel.stiffness_gaussian_blocks`, node-major),
``M_g`` as the scalar ``Gamma`` (never the d-fold block-diagonal copy). A run that does not
reach ``tol`` raises a ValueError: the solver never returns modes it has not checked.
"""

from __future__ import annotations

import logging

import numpy as np
from scipy import linalg
from scipy.spatial import cKDTree

__all__ = ["solve_modes_multilevel", "COARSE_NODES", "MULTILEVEL_TOL", "MULTILEVEL_MAXITER"]

logger = logging.getLogger(__name__)

# Nodes of the coarse model that gives the starting subspace: its 3 * 1000 degrees of
# freedom are solved densely in about a second (benchmarks/model.py).
COARSE_NODES = 1000
# Relative residual below which a mode counts as converged (see solve_modes_multilevel
# for what it means for the frequencies, measured against the exact solvers).
MULTILEVEL_TOL = 5e-2
MULTILEVEL_MAXITER = 20
# Nodes per preconditioner patch: dense (d * 32)^2 Cholesky factors, 9 * 32 doubles per
# 3D node in all (0.23 GB at 100k nodes).
_PATCH_NODES = 32


def _guard(n: int) -> int:
    """Extra vectors in the block beyond the ``n`` wanted: the block's convergence rate is
    set by the gap between mode ``n`` and mode ``n + guard + 1``."""
    return max(8, n // 4)


def solve_modes_multilevel(model, n: int, *, coarse_nodes: int = COARSE_NODES,
                           tol: float = MULTILEVEL_TOL, maxiter: int = MULTILEVEL_MAXITER):
    """The lowest ``n`` modes of a large sparse model by a coarse start and LOBPCG.

    Parameters
    ----------
    model : FEModel
        The full model (its pairs within ``model.cutoff_radius``).
    n : int
        Number of modes.
    coarse_nodes : int, optional
        Nodes of the coarse model giving the starting subspace.
    tol : float, optional
        Largest relative residual ``||K_g psi - w^2 M_g psi|| / (w^2 ||M_g psi||)`` of a
        returned mode.
    maxiter : int, optional
        LOBPCG iterations at most.

    Returns
    -------
    Modes
        With ``psi^T (rho I kron Gamma) psi = I`` to round-off (Rayleigh-Ritz).

    Raises
    ------
    ValueError
        When a mode's residual is still above ``tol`` after ``maxiter`` iterations, or the
        coarse model fails.
    """
    from .element import FEModel, _breakdown_message
    from .modes import Modes
    from .shape import coarsen

    d, m = model.dim, model.m
    rho = model.material.rho
    k = min(n + _guard(n), d * m // 2)
    Kb = model.stiffness_gaussian_blocks
    G, Gamma = model.gram_sparse

    # 1. coarse start: displacement fields of the coarse modes at the fine nodes
    coarse = coarsen(model.shape, min(coarse_nodes, m // 2))
    cmodel = FEModel(coarse, sigma=model.sigma_rel, material=model.material,
                     plane=model.plane, cutoff=model.cutoff)
    kc = min(k, d * coarse.m - 2)
    cmodes = cmodel.modes(kc)
    V = cmodel.modes_at(cmodes, coarse.to_normalized(model.shape.points))
    V = _node_major(V, d, m)
    if kc <= n:
        raise ValueError(f"the multilevel solver needs more than n={n} coarse modes; this "
                         f"{m}-node shape is small enough for solver='sparse' or 'dense'")

    def apply_m(X):
        return (Gamma @ X.reshape(m, -1)).reshape(X.shape)

    precondition = _patch_preconditioner(model)
    w2, psi, res, its = _lobpcg(Kb, apply_m, precondition, V, n, tol, maxiter)
    if not np.all(res[:n] <= tol):
        bad = int(np.argmax(res[:n]))
        raise ValueError(
            f"the multilevel solver did not converge for this {m}-node shape: mode {bad} "
            f"has relative residual {res[bad]:.1e} > tol={tol:g} after {its} iterations; "
            f"raise maxiter or coarse_nodes, or use solver='sparse' on fewer nodes. "
            + (_breakdown_message(model) if not np.all(np.isfinite(res)) else ""))
    logger.info("multilevel: %d modes of %d nodes in %d iterations, max residual %.1e",
                n, m, its, res[:n].max())
    psi = _component_major(psi[:, :n], d, m) / np.sqrt(rho)  # psi^T (rho M_g) psi = I
    phi = np.stack([G @ p for p in psi.reshape(d, m, n)]).reshape(d * m, n)
    return Modes(frequencies=np.sqrt(np.clip(w2[:n] / rho, 0.0, None)), shapes=phi,
                 gaussian=psi, dim=d)


def _node_major(X: np.ndarray, d: int, m: int) -> np.ndarray:
    return np.ascontiguousarray(X.reshape(d, m, -1).transpose(1, 0, 2).reshape(d * m, -1))


def _component_major(X: np.ndarray, d: int, m: int) -> np.ndarray:
    return np.ascontiguousarray(X.reshape(m, d, -1).transpose(1, 0, 2).reshape(d * m, -1))


def _patch_preconditioner(model):
    """Block Jacobi: exact solves with ``K_g`` restricted to patches of about
    ``_PATCH_NODES`` neighbouring nodes (consecutive leaves of a k-d tree), node-major."""
    from .element import stiffness_entries

    d, m = model.dim, model.m
    lam, mu = model.lame
    order = cKDTree(model.points, leafsize=8).indices
    patches = [np.sort(order[s:s + _PATCH_NODES]) for s in range(0, m, _PATCH_NODES)]
    factors = []
    for idx in patches:
        x = model.points[idx]
        blocks = stiffness_entries(x[None, :, :] - x[:, None, :], model.sigma, lam, mu)
        A = blocks.transpose(0, 2, 1, 3).reshape(d * len(idx), d * len(idx))
        A[np.diag_indices_from(A)] *= 1 + 1e-8  # K_g is only semi-definite numerically
        factors.append(linalg.cho_factor(A, lower=True, check_finite=False))

    def apply(R: np.ndarray) -> np.ndarray:
        k = R.shape[1]
        Rn, out = R.reshape(m, d, k), np.empty_like(R)
        On = out.reshape(m, d, k)
        for idx, fac in zip(patches, factors, strict=True):
            On[idx] = linalg.cho_solve(fac, Rn[idx].reshape(-1, k),
                                       check_finite=False).reshape(len(idx), d, k)
        return out

    return apply


def _rayleigh_ritz(A: np.ndarray, B: np.ndarray, k: int):
    """Lowest ``k`` eigenpairs of the pencil ``(A, B)``, B semi-definite: directions B
    cannot tell apart from 0 (relative 1e-12 after scaling to unit diagonal) are dropped."""
    scale = 1 / np.sqrt(np.diag(B))
    A, B = A * scale * scale[:, None], B * scale * scale[:, None]
    bw, bv = linalg.eigh((B + B.T) / 2, check_finite=False)
    keep = bw > 1e-12 * bw[-1]
    T = bv[:, keep] / np.sqrt(bw[keep])
    At = T.T @ A @ T
    w, C = linalg.eigh((At + At.T) / 2, subset_by_index=(0, k - 1), check_finite=False)
    return w, (T @ C) * scale[:, None]


def _lobpcg(K, apply_m, precondition, V, n, tol, maxiter):
    """LOBPCG for the lowest ``n`` eigenpairs of ``(K, M)``, block ``V.shape[1]``, started
    from the span of ``V``. Products with K and M are done once per new block and carried
    through the Ritz updates. Returns ``(w2, X, residuals, iterations)``."""
    k = V.shape[1]
    KV, MV = K @ V, apply_m(V)
    A, B = V.T @ KV, V.T @ MV
    w2, C = _rayleigh_ritz(A, B, k)
    X, KX, MX = V @ C, KV @ C, MV @ C
    del V, KV, MV
    P = KP = MP = None
    for it in range(maxiter + 1):
        R = KX - MX * w2
        res = np.linalg.norm(R, axis=0) / (np.abs(w2) * np.linalg.norm(MX, axis=0))
        logger.debug("LOBPCG %d: residuals of the wanted modes max %.1e, median %.1e",
                     it, res[:n].max(), np.median(res[:n]))
        if np.all(res[:n] <= tol) or it == maxiter or not np.all(np.isfinite(res)):
            return w2, X, res, it
        # soft locking: new directions only for the columns not yet converged
        W = precondition(R[:, res > tol])
        del R
        W -= X @ (MX.T @ W)  # M-orthogonal to the current Ritz vectors
        KW, MW = K @ W, apply_m(W)
        S = [X, W] if P is None else [X, W, P]
        KS = [KX, KW] if P is None else [KX, KW, KP]
        MS = [MX, MW] if P is None else [MX, MW, MP]
        A = np.block([[a.T @ b for b in KS] for a in S])
        B = np.block([[a.T @ b for b in MS] for a in S])
        w2, C = _rayleigh_ritz(A, B, k)
        a = W.shape[1]
        Cx, Cw = C[:k], C[k:k + a]
        # P_new = W Cw (+ P Cp), X_new = X Cx + P_new: no copy of the whole basis
        if P is None:
            P, KP, MP = W @ Cw, KW @ Cw, MW @ Cw
        else:
            Cp = C[k + a:]
            P = P @ Cp
            P += W @ Cw
            KP = KP @ Cp
            KP += KW @ Cw
            MP = MP @ Cp
            MP += MW @ Cw
        del W, KW, MW
        X = X @ Cx  # one block at a time: each old one is freed before the next
        X += P
        KX = KX @ Cx
        KX += KP
        MX = MX @ Cx
        MX += MP
    raise AssertionError("unreachable")
