"""Lowest modes of a large model without a sparse factorisation: coarse start + LOBPCG.

The sparse solver (:func:`modalmorph.core.solvers.sparse.solve`) factorises
``K_g - s M_g``; for 3D point sets, where each node has some 200-300 neighbours within the
cutoff radius, that factor does not fit in memory beyond a few thousand nodes. This solver
only multiplies by the full model's sparse matrices:

1. **Coarse start.** A model of the same object on ``coarse_nodes`` nodes
   (:meth:`FEModel.coarsened`, the dense or sparse solver) gives its lowest ``k``
   modes; their displacement fields, evaluated at the fine nodes
   (:meth:`FEModel.field`), are smooth, and so are the fine model's low modes in the
   Gaussian basis: their span is the starting subspace.
2. **Rayleigh-Ritz** with the full model's ``K_g`` and ``M_g = rho (I kron Gamma)``.
3. **LOBPCG** (Knyazev's locally optimal block preconditioned conjugate gradient) on
   ``K_g psi = w^2 M_g psi`` with a block of ``k > n`` vectors, preconditioned by exact
   solves ``P`` with ``K_g`` restricted to small patches of neighbouring nodes (block
   Jacobi) and one damped Richardson step ``w = P r + omega P (r - K_g P r)`` (``omega``
   from a Lanczos estimate of the largest eigenvalue of ``P K_g``, so that the step's
   polynomial stays positive: 34 -> 20 iterations on 100 000 random ellipsoid points),
   until every wanted mode's relative residual
   ``||K_g psi - w^2 M_g psi|| / (w^2 ||M_g psi||)`` is below ``tol``, for as long as
   the largest of them keeps falling (at most ``maxiter`` iterations): the block
   LOBPCG of :mod:`modalmorph.core.solvers.lobpcg` (soft locking; the Gram blocks of the
   Ritz vectors and the previous directions carried from one Rayleigh-Ritz step to the
   next as small products).

Work and memory are linear in the number of pairs within the cutoff (``model.pairs``).
The solver assembles its own matrices from them, on its own node order (the leaves of a
k-d tree, so that neighbours are close in memory): the blocks
``K_g^ab_ij = s_ij (-(lambda + mu) / 4 r_a r_b + delta_ab t_ij)`` (``r = x_j - x_i``,
``s_ij = Gamma_ij / sigma^4``, ``t_ij = (lambda + mu) sigma^2 / 2 + mu (d sigma^2 / 2 -
|r|^2 / 4)``: :func:`modalmorph.core.element.stiffness_components`) are symmetric in ``(a, b)``,
so ``K_g`` is its ``d (d + 1) / 2`` distinct scalar components,
six CSR data arrays in 3D over one index structure, and ``M_g`` is the scalar ``Gamma``
over the same structure (never the d-fold block-diagonal copy);
``(K_g X)_a = sum_b K^ab X_b``.
Scalar products with many columns run about 2.5 times faster per flop than the d x d
block (BSR) product, and the rows are split into blocks that run on ``threads`` threads
(scipy's sparse products release the GIL). ``G`` is only needed for
``Phi = (I kron G) psi`` at the end: it is formed then from ``Gamma``'s entries, a block
of rows at a time, after ``K_g`` is freed. A run that does not reach ``tol`` raises a
:class:`~modalmorph.errors.ModelError`: the solver never returns modes it has not checked.

Measured (``benchmarks/scale.py``, 2 cores, ``OPENBLAS_NUM_THREADS=1``): 100k 3D nodes
(198 neighbours each), lowest 50 modes in 25 s and 3.0 GB peak (3 iterations), against
62 s and 4.9 GB with the BSR ``K_g`` and one thread. Nodes drawn at random are harder:
the lowest modes are localised where the nodes crowd, hundreds of frequencies lie within a
few percent, neither the smooth coarse start nor the patch preconditioner sees them, and
LOBPCG needs some 20 iterations (``benchmarks/multilevel.py``: 100k random points on an
ellipsoid, 20 iterations, 54 CPU-s with one thread at load 5, 2.5 GB; the frequencies are
within 8.6e-3 of the exact solver's at 2500 such nodes). Measured at
20 000 random nodes on the ellipsoid and not kept (docs/issue25/scale.md): 50 guard
vectors instead of 12 (22 iterations instead of 28) and 64-node patches (23) take longer
in all; a shift in the
patches, a coarse-space correction on aggregated patches and a start from the patches'
own lowest modes saved at most 2 iterations at 3000 nodes.
"""

from __future__ import annotations

import logging
import os
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from scipy import linalg, sparse
from scipy.spatial import cKDTree

from ...errors import ModelError
from ..element import (
    gaussian,
    gaussian_from_overlap,
    singular_gram,
    stiffness_component_pairs,
    stiffness_components,
    stiffness_entries,
)
from ..modes import Modes
from .lobpcg import Rows, lobpcg

__all__ = ["solve", "Operators", "COARSE_NODES", "MULTILEVEL_CUTOFF", "MULTILEVEL_TOL",
           "MULTILEVEL_MAXITER", "THREADS"]

logger = logging.getLogger(__name__)

# Multilevel cutoff: 8.1 sigma, 190 neighbours; frequencies move by 3e-6 (method.md §7).
MULTILEVEL_CUTOFF = 1e-6

# Nodes of the coarse model that gives the starting subspace: its 3 * 1000 degrees of
# freedom are solved densely in about a second (benchmarks/model.py).
COARSE_NODES = 1000
# Relative residual below which a mode counts as converged (see the module's docstring
# for what it means for the frequencies, measured against the exact solvers).
MULTILEVEL_TOL = 5e-2
# LOBPCG iterations at most (100k random ellipsoid points need 20; method.md §7).
MULTILEVEL_MAXITER = 100
# Nodes per preconditioner patch: dense (d * 32)^2 inverses, 9 * 32 doubles per
# 3D node in all (0.23 GB at 100k nodes).
_PATCH_NODES = 32
# Patches per batched product in the preconditioner (a few MB of temporaries each).
_PATCH_BATCH = 256
# Rows per block of the sparse products: products of 100 000 nodes times 62 columns in
# blocks of 6250 rows take 536 ms (K_g) against 582 in one block, one thread (the
# products' results stay small and are reused instead of mapped afresh).
_SPARSE_ROWS = 8192
# Points per chunk of the coarse modes' fields at the fine nodes (consecutive in the
# solver's order, so close together: 256 of 100 000 random ellipsoid points meet 348 of
# 1000 coarse nodes on average; 0.40 s for all, 1024 points per chunk 0.59 s).
_FIELD_CHUNK = 256
# The Richardson step after the patch solves: omega = _RICHARDSON_ROOT / (top - 1), top
# the estimate of P K_g's largest eigenvalue, so that the step's polynomial
# 1 + omega (1 - t) falls to 1 - _RICHARDSON_ROOT at t = top (top 4.0-4.05 on random
# ellipsoid points, 3.6-5.5 on other clouds). 100 000 ellipsoid points, one thread: 34
# iterations without the step, 25 with omega = 0.29 (1 - 0.88), 19-20 with 0.318 (this
# root); 20 000: 25 without, 19 / 16 with 0.25 / 0.33; omega = 0.42 and 0.5 (the
# polynomial negative at the top) stalled (docs/issue25/scale.md, session 14).
_RICHARDSON_ROOT = 0.97
# Lanczos steps of that estimate: 20 steps within 0.4% of 80 on ellipsoid, sphere, scan,
# blob and cube clouds of 20 000-30 000 points (0.15 s at 20 000 ellipsoid points).
_LANCZOS_STEPS = 20
# Threads of the sparse and dense block products (2 cores; results equal to round-off).
THREADS = 2


# Fewest nodes of a model (a shape has at least 3): the coarse model's floor.
_MIN_COARSE = 3


def _guard(n: int) -> int:
    """Extra vectors in the block beyond the ``n`` wanted: the block's convergence rate is
    set by the gap between mode ``n`` and mode ``n + guard + 1``."""
    return max(8, n // 4)


def solve(model, n: int, *, coarse_nodes: int = COARSE_NODES, tol: float = MULTILEVEL_TOL,
          maxiter: int = MULTILEVEL_MAXITER, threads: int = THREADS) -> Modes:
    """The lowest ``n`` modes of a large sparse model by a coarse start and LOBPCG.

    Parameters
    ----------
    model : FEModel
        The full model (its ``pairs``; ``model.coarsened`` gives the coarse one).
    n : int
        Number of modes.
    coarse_nodes : int, optional
        Nodes of the coarse model giving the starting subspace.
    tol : float, optional
        Largest relative residual ``||K_g psi - w^2 M_g psi|| / (w^2 ||M_g psi||)`` of a
        returned mode.
    maxiter : int, optional
        LOBPCG iterations at most; a run stops earlier, and raises, when its largest
        residual has not fallen by 10% over the last 10 iterations.
    threads : int, optional
        Threads for the sparse products (each takes a block of rows); the result does not
        depend on it beyond round-off.

    Returns
    -------
    Modes
        With ``psi^T (rho I kron Gamma) psi = I`` to round-off (Rayleigh-Ritz).

    Raises
    ------
    ModelError
        When a residual is above ``tol`` when the iterations stop, or the coarse model fails.
    """
    d, m = model.dim, model.m
    clock = _Clock()
    # the solver's node order: leaves of a k-d tree, so that a node's neighbours are close
    # in memory and the preconditioner's patches are consecutive nodes
    order = cKDTree(model.points, leafsize=8).indices
    threads = max(1, int(threads))
    with ThreadPoolExecutor(threads) as pool:
        start = [_coarse_start(model, n, coarse_nodes, order, pool)]
        clock("coarse start")
        ops = Operators(model, order, pool, threads)
        clock("K_g and Gamma")
        # dense products (BLAS) on the threads too, unless BLAS runs threads of its own:
        # concurrent calls into a multithreaded OpenBLAS are several times slower
        dense = threads if _blas_single_threaded() else 1
        precondition = _preconditioner(model, order, ops, pool, dense)
        clock("preconditioner")
        w2, psi, res, its = lobpcg(ops, precondition, start, n, tol, maxiter,
                                    Rows(pool, dense, d * m), clock)
        del precondition
        _check_converged(model, res[:n], tol, its, maxiter)
        psi = psi[:, :n]
        ops.drop_stiffness()
        phi = ops.gram(psi)  # Phi = (I kron G) psi, G assembled a block of rows at a time
        clock("Phi")
    logger.info("multilevel: %d modes of %d nodes in %d iterations, max residual %.1e",
                n, m, its, res[:n].max())
    return Modes.unit_density(w2[:n], _model_order(psi, order, d), _model_order(phi, order, d),
                              model.material.rho, d)


def _coarse_start(model, n: int, coarse_nodes: int, order: np.ndarray,
                  pool: ThreadPoolExecutor) -> np.ndarray:
    """The starting block (d*m, kc): the lowest ``kc`` modes (``n`` and the guard) of a
    model of the same object on at most ``coarse_nodes`` nodes, as displacement fields at
    the fine nodes (in the solver's node order)."""
    if model.m // 2 < _MIN_COARSE:
        raise ModelError(f"solver='multilevel' needs at least {2 * _MIN_COARSE} nodes (its "
                         f"coarse model has half of them, and a model at least "
                         f"{_MIN_COARSE}), this shape has {model.m}: use solver='dense' or "
                         f"'sparse'")
    cmodel = model.coarsened(min(coarse_nodes, model.m // 2))
    k = min(n + _guard(n), model.dim * model.m // 2)
    kc = min(k, cmodel.dim * cmodel.m - 2)
    if kc <= n:
        raise ModelError(f"the multilevel solver needs more than n={n} coarse modes; this "
                         f"{model.m}-node shape is small enough for solver='sparse' or "
                         f"'dense'")
    points = cmodel.shape.to_normalized(model.shape.points[order])
    return _coarse_fields(cmodel, cmodel.modes(kc), points, pool)


def _check_converged(model, res: np.ndarray, tol: float, its: int, maxiter: int) -> None:
    """Raise unless every wanted mode's residual ``res`` is below ``tol``."""
    if np.all(res <= tol):
        return
    bad = int(np.argmax(res))
    singular = (" " + str(singular_gram(model.shape, model.sigma))
                if not np.all(np.isfinite(res)) else "")
    raise ModelError(
        f"the multilevel solver did not converge for this {model.m}-node shape: mode {bad} "
        f"has relative residual {res[bad]:.1e} > tol={tol:g} after {its} iterations "
        f"({'stalled' if its < maxiter else 'maxiter'}); raise maxiter or coarse_nodes, or "
        f"use solver='sparse' on fewer nodes.{singular}")


def _blas_single_threaded() -> bool:
    """Whether BLAS is told to use one thread (the usual environment variables)."""
    return any(os.environ.get(v, "").strip() == "1" for v in
               ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"))


def _coarse_fields(cmodel, cmodes, points: np.ndarray, pool: ThreadPoolExecutor):
    """``cmodel.modes_at(cmodes, points)`` (component-major, (d * p, n)) for points in the
    solver's order (a chunk of consecutive ones lies close together): per chunk of
    ``_FIELD_CHUNK`` points, the element's field ``g_k(x_p)`` (zero beyond the cutoff
    radius, as :meth:`FEModel.field`) as a dense block over the coarse nodes within the
    cutoff of the chunk, times the modes of those nodes, every component in one product
    (100 000 points, 1000 coarse nodes, 62 modes: 0.4 s against 2.1 s through the sparse
    field of a k-d tree's distance matrix, one thread)."""
    d, p, m = cmodel.dim, len(points), cmodel.m
    k = cmodes.gaussian.shape[1]
    psi = cmodes.gaussian.reshape(d, m, k).transpose(1, 0, 2).reshape(m, d * k)
    nodes, reach = cmodel.points, cmodel.cutoff_radius
    tree = cKDTree(nodes)
    V = np.empty((d, p, k))

    def work(s):
        x = points[s:s + _FIELD_CHUNK]
        centre = x.mean(axis=0)
        near = np.sort(tree.query_ball_point(
            centre, np.sqrt(np.max(np.sum((x - centre) ** 2, axis=1))) + reach))
        y = nodes[near]
        r2 = (x[:, :1] - y[:, 0]) ** 2
        for a in range(1, d):
            r2 += (x[:, a:a + 1] - y[:, a]) ** 2
        g = np.where(r2 <= reach ** 2, gaussian(r2, cmodel.width), 0.0)
        if not np.all(np.any(g > 0, axis=1)):
            raise ModelError("a node lies beyond the cutoff radius of every node of the "
                             "multilevel solver's coarse model: use more coarse_nodes")
        V[:, s:s + len(x)] = (g @ psi[near]).reshape(len(x), d, k).transpose(1, 0, 2)

    for _ in pool.map(work, range(0, p, _FIELD_CHUNK)):
        pass
    return V.reshape(d * p, k)


class _Clock:
    """Debug log of the solver's phases: seconds since the start."""

    def __init__(self):
        self.start = time.perf_counter()

    def __call__(self, phase: str) -> None:
        logger.debug("multilevel phase %s: done at %.2f s", phase,
                     time.perf_counter() - self.start)


def _model_order(X: np.ndarray, order: np.ndarray, d: int) -> np.ndarray:
    """Component-major rows in the solver's node order -> the model's node order."""
    out = np.empty_like(X)
    out.reshape(d, len(order), -1)[:, order] = X.reshape(d, len(order), -1)
    return out


class Operators:
    """The full model's ``K_g`` and ``Gamma`` on the solver's node order, for blocks
    ``X`` of shape (d*m, c), component-major.

    ``K_g`` is stored as its ``d (d + 1) / 2`` distinct scalar m x m components
    ``K^ab`` (:func:`modalmorph.core.element.stiffness_components`), ``Gamma`` as one more, all
    over one sparse structure (the pairs within the cutoff and the diagonal). The rows are
    split into blocks of about equal nonzeros (a multiple of ``threads`` of them, at most
    ``_SPARSE_ROWS`` rows each), each with its own index arrays; a product runs the
    blocks on ``threads`` threads (scipy's sparse products release the GIL), each block
    computing ``(K X)_a = sum_b K^ab X_b`` for its rows.
    """

    def __init__(self, model, order: np.ndarray, pool: ThreadPoolExecutor, threads: int):
        self.d, self.m, self.pool = model.dim, model.m, pool
        self.sigma = model.width
        d, m = self.d, self.m
        lam, mu = model.lame
        self.x = x = model.points[order]
        rank = np.empty(m, dtype=model.pairs.dtype)
        rank[order] = np.arange(m, dtype=rank.dtype)
        i, j = rank[model.pairs[:, 0]], rank[model.pairs[:, 1]]
        diag = np.arange(m, dtype=i.dtype)
        pattern = sparse.coo_array(
            (np.ones(2 * len(i) + m, dtype=np.int8), (np.r_[i, j, diag], np.r_[j, i, diag])),
            shape=(m, m)).tocsr()
        del i, j, diag, rank
        indptr, indices = pattern.indptr, pattern.indices
        del pattern
        nnz = int(indptr[-1])
        # blocks of at most _SPARSE_ROWS rows, a multiple of threads of them
        parts = threads * -(-m // (threads * _SPARSE_ROWS))
        cuts = np.searchsorted(indptr, np.arange(parts + 1) * (nnz / parts))
        cuts[0], cuts[-1] = 0, m
        cuts = np.unique(cuts)
        self.blocks = []
        for r0, r1 in zip(cuts[:-1], cuts[1:], strict=True):
            p0, p1 = indptr[r0], indptr[r1]
            # own arrays, not views: scipy copies a slice of a much larger array
            self.blocks.append((int(r0), int(r1), indptr[r0:r1 + 1] - p0,
                                indices[p0:p1].copy()))
        del indptr, indices
        comps = stiffness_component_pairs(d)
        self.index = {}
        for q, (a, b) in enumerate(comps):
            self.index[a, b] = self.index[b, a] = q

        def build(block):
            r0, r1, bptr, bidx = block
            data = [np.empty(len(bidx)) for _ in range(len(comps) + 1)]
            for s0, s1, r in _chunks(x, r0, bptr, bidx):
                values, data[-1][s0:s1] = stiffness_components(r, self.sigma, lam, mu)
                for q, v in enumerate(values):
                    data[q][s0:s1] = v
            return [sparse.csr_array((v, bidx, bptr), shape=(r1 - r0, m)) for v in data]

        mats = list(pool.map(build, self.blocks))
        self.K = [b[:-1] for b in mats]
        self.Gamma = [b[-1] for b in mats]

    def _run(self, work) -> None:
        for _ in self.pool.map(work, range(len(self.blocks))):
            pass

    def stiffness(self, X: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """``K_g X`` (into ``out``, of X's shape, when given)."""
        d, m = self.d, self.m
        Xs = X.reshape(d, m, -1)
        Y = np.empty_like(Xs) if out is None else out.reshape(Xs.shape)

        def work(t):
            r0, r1 = self.blocks[t][:2]
            K = self.K[t]
            for a in range(d):
                y = K[a] @ Xs[a]
                for b in range(d):
                    if b != a:
                        y += K[self.index[a, b]] @ Xs[b]
                Y[a, r0:r1] = y

        self._run(work)
        return Y.reshape(X.shape)

    def mass(self, X: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """``(I kron Gamma) X`` (without rho; into ``out`` when given)."""
        d, m = self.d, self.m
        Xs = X.reshape(d, m, -1)
        Y = np.empty_like(Xs) if out is None else out.reshape(Xs.shape)

        def work(t):
            r0, r1 = self.blocks[t][:2]
            for a in range(d):
                Y[a, r0:r1] = self.Gamma[t] @ Xs[a]

        self._run(work)
        return Y.reshape(X.shape)

    def drop_stiffness(self) -> None:
        self.K = None

    def gram(self, X: np.ndarray) -> np.ndarray:
        """``(I kron G) X``, G from Gamma's entries
        (:func:`modalmorph.core.element.gaussian_from_overlap`), one block of rows at a time."""
        d, m = self.d, self.m
        Xs = X.reshape(d, m, -1)
        Y = np.empty_like(Xs)

        def work(t):
            r0, r1, bptr, bidx = self.blocks[t]
            G = sparse.csr_array((gaussian_from_overlap(self.Gamma[t].data, self.sigma, d),
                                  bidx, bptr), shape=(r1 - r0, m))
            for a in range(d):
                Y[a, r0:r1] = G @ Xs[a]

        self._run(work)
        return Y.reshape(X.shape)


_CHUNK = 1 << 19  # entries per chunk of the matrix assembly


def _chunks(x, r0, bptr, bidx):
    """Chunks of whole rows of a row block's entries, about ``_CHUNK`` entries each:
    ``(s0, s1, r)``: entries ``s0:s1`` and their offsets ``r = x_j - x_i``."""
    nrows = len(bptr) - 1
    bounds = np.unique(np.r_[np.searchsorted(bptr, np.arange(0, bptr[-1], _CHUNK),
                                             side="right") - 1, nrows])
    for a0, a1 in zip(bounds[:-1], bounds[1:], strict=True):
        s0, s1 = int(bptr[a0]), int(bptr[a1])
        rows = np.repeat(np.arange(r0 + a0, r0 + a1), np.diff(bptr[a0:a1 + 1]))
        yield s0, s1, x[bidx[s0:s1]] - x[rows]


def _patch_preconditioner(model, order: np.ndarray, pool: ThreadPoolExecutor,
                          threads: int):
    """Block Jacobi ``P``: exact solves with ``K_g`` restricted to patches of
    ``_PATCH_NODES`` consecutive nodes of the solver's order (leaves of a k-d tree, so
    neighbours), on component-major blocks. Each patch's inverse ``A^-1 = L^-T L^-1`` (from
    its Cholesky factor) is stored and the solves are batched products ``A^-1 R``, batches
    of patches over the threads."""
    d, m = model.dim, model.m
    lam, mu = model.lame
    x = model.points[order]
    P = _PATCH_NODES
    starts = list(range(0, m, P))
    full = m // P  # patches of P nodes; the last one may have fewer

    def inverse_factor(s: int) -> np.ndarray:
        y = x[s:s + P]
        blocks = stiffness_entries(y[None, :, :] - y[:, None, :], model.width, lam, mu)
        A = blocks.transpose(2, 0, 3, 1).reshape(d * len(y), d * len(y))
        A[np.diag_indices_from(A)] *= 1 + 1e-8  # K_g is only semi-definite numerically
        L = linalg.cholesky(A, lower=True, check_finite=False)
        Li = linalg.solve_triangular(L, np.eye(len(L)), lower=True, check_finite=False)
        return Li.T @ Li  # A^-1: one product per solve instead of two triangular ones

    Ainv = np.stack([inverse_factor(s) for s in starts[:full]])
    last = inverse_factor(full * P) if full * P < m else None
    batches = [(b, min(b + _PATCH_BATCH, full)) for b in range(0, full, _PATCH_BATCH)]

    def apply(R: np.ndarray, cols, out: np.ndarray) -> np.ndarray:
        """The solves for the columns ``cols`` of ``R``, into ``out``."""
        k = out.shape[1]
        Rs = R.reshape(d, m, -1)
        out = out.reshape(d, m, k)

        def work(t):
            for b0, b1 in batches[t::threads]:
                # (d, patches, P, k) -> (patches, d*P, k): each patch component-major
                Rp = Rs[:, b0 * P:b1 * P][..., cols].reshape(d, b1 - b0, P, k).transpose(
                    1, 0, 2, 3)
                Y = np.matmul(Ainv[b0:b1], Rp.reshape(b1 - b0, d * P, k))
                out[:, b0 * P:b1 * P] = Y.reshape(b1 - b0, d, P, k).transpose(
                    1, 0, 2, 3).reshape(d, (b1 - b0) * P, k)

        for _ in pool.map(work, range(threads)):
            pass
        if last is not None:
            r = Rs[:, full * P:][..., cols].reshape(-1, k)
            out[:, full * P:] = (last @ r).reshape(d, m - full * P, k)
        return out.reshape(-1, k)

    return apply


def _preconditioner(model, order: np.ndarray, ops: Operators, pool: ThreadPoolExecutor,
                    threads: int):
    """The patch solves ``P`` (:func:`_patch_preconditioner`) and one Richardson step
    (:func:`_richardson`) with ``omega = _RICHARDSON_ROOT / (top - 1)``, ``top`` the
    Lanczos estimate of the largest eigenvalue of ``P K_g``; the patch solves alone when
    that is 1 (one patch: ``P K_g = I``, the step adds nothing)."""
    patches = _patch_preconditioner(model, order, pool, threads)
    top = _top_eigenvalue(ops, patches, _LANCZOS_STEPS)
    if top <= 1 + 1e-6:
        return patches
    return _richardson(patches, ops, _RICHARDSON_ROOT / (top - 1))


def _top_eigenvalue(ops: Operators, patches, steps: int) -> float:
    """An estimate (from below) of the largest eigenvalue of ``P K_g`` (``patches``: the
    solves ``P``), self-adjoint in the inner product ``<x, y> = x^T K_g y``: ``steps``
    steps of Lanczos in that inner product from a fixed random vector, one product with
    ``K_g`` and one solve each (single columns: 100 000 nodes, 0.04 s a step)."""
    v = np.random.default_rng(0).standard_normal((ops.d * ops.m, 1))
    Kv = ops.stiffness(v)
    norm = np.sqrt(float(np.vdot(v, Kv)))
    v, Kv = v / norm, Kv / norm
    prev = np.zeros_like(v)
    alphas, betas = [], [0.0]
    for _ in range(steps):
        u = patches(Kv, slice(None), np.empty_like(v))
        alphas.append(float(np.vdot(Kv, u)))
        u -= alphas[-1] * v + betas[-1] * prev
        Ku = ops.stiffness(u)
        beta = np.sqrt(max(float(np.vdot(u, Ku)), 0.0))
        if beta <= 1e-12 * abs(alphas[-1]):
            break
        prev, v, Kv = v, u / beta, Ku / beta
        betas.append(beta)
    return float(linalg.eigvalsh_tridiagonal(np.array(alphas), np.array(betas[1:len(alphas)]),
                                             select="i", select_range=(len(alphas) - 1,
                                                                       len(alphas) - 1))[0])


def _richardson(patches, ops: Operators, omega: float):
    """The patch solves ``P`` and one damped Richardson step on ``K_g w = r``:
    ``w = P r + omega P (r - K_g P r)``, the polynomial ``(1 + omega (1 - t)) P`` of
    ``t = P K_g``, positive while ``t < 1 + 1 / omega``. Its two work blocks are made once
    and reused."""
    buffers = {}

    def buffer(name: str, shape) -> np.ndarray:
        size = shape[0] * shape[1]
        if name not in buffers or buffers[name].size < size:
            buffers[name] = np.empty(size)
        return buffers[name][:size].reshape(shape)

    def apply(R: np.ndarray, cols, out: np.ndarray) -> np.ndarray:
        W = patches(R, cols, out)
        T = ops.stiffness(W, buffer("T", W.shape))
        np.subtract(R[:, cols], T, out=T)
        U = patches(T, slice(None), buffer("U", W.shape))
        U *= omega
        W += U
        return W

    return apply
