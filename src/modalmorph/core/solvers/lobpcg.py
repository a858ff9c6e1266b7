"""Block LOBPCG on tall blocks, for the multilevel solver
(:mod:`modalmorph.core.solvers.multilevel`, which gives it its operators, preconditioner
and starting block).

Knyazev's locally optimal block preconditioned conjugate gradient for the lowest
eigenpairs of ``K x = w^2 M x``: the products with K and M are done once per new block
and carried through the Ritz updates, in place; the new directions are made only for the
columns not yet converged, and the previous directions kept only for those (soft
locking, as scipy's ``lobpcg``); the Gram blocks of the Ritz vectors and the previous
directions are carried from one Rayleigh-Ritz step to the next as small products
(:func:`_carried`), so that each iteration forms from the tall blocks only those of the
new directions. Dense work is done a chunk of rows at a time (:class:`Rows`).
"""

from __future__ import annotations

import logging
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from scipy import linalg
from scipy.linalg import blas

__all__ = ["lobpcg", "Rows", "rayleigh_ritz"]

logger = logging.getLogger(__name__)

_dgemm = blas.dgemm

# Stalled: the residual fell by less than _STALL_FACTOR over this many iterations (method.md §7).
# 10 raised on a slow crawl that converges: 20 000 random ellipsoid points, 300 coarse
# nodes, "stalled" at 5.1e-2 against 5e-2 after 32 iterations (1 of 12 runs at 150-1000
# coarse nodes, 2 seeds); 100 000 points, 700 coarse nodes, at 5.7e-2 after 33. With 20:
# those converge (in 10-12 CPU-s at 20 000, as the others), and a stuck run still stops.
_STALL_WINDOW = 20
_STALL_FACTOR = 0.9
# Rows per chunk of the dense block operations (a few MB of temporaries each).
_ROWS = 4096


def rayleigh_ritz(A: np.ndarray, B: np.ndarray, k: int):
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


class Rows:
    """Dense operations on tall blocks (N, c), a chunk of ``_ROWS`` rows at a time and the
    chunks spread over the threads: no temporary of a block's full size, and the chunks'
    temporaries in buffers of each thread made once (a fresh 2 MB temporary per chunk
    costs its page faults: the Ritz update of three blocks of 300 000 x 62, one thread,
    593-795 ms with fresh temporaries and the columns copied, 525-531 ms with these)."""

    def __init__(self, pool: ThreadPoolExecutor, threads: int, N: int):
        self.pool, self.threads = pool, threads
        self.chunks = [slice(s, min(s + _ROWS, N)) for s in range(0, N, _ROWS)]
        self.scratch = [_Scratch(_ROWS) for _ in range(threads)]

    def map(self, fn):
        """``[fn(rows, tmp) for rows in the chunks]`` summed per thread: one result per
        thread; ``tmp(name, c)`` is a (rows, c) buffer of the thread's."""
        def work(t):
            out, scratch = None, self.scratch[t]
            for rows in self.chunks[t::self.threads]:
                v = fn(rows, lambda name, c, n=rows.stop - rows.start: scratch(name, c, n))
                if v is not None:
                    out = v if out is None else out + v
            return out

        return [v for v in self.pool.map(work, range(self.threads)) if v is not None]

    def inner(self, S: list, T: list, symmetric: bool = False) -> np.ndarray:
        """The block matrix ``[[a.T @ b for b in T] for a in S]``; with ``symmetric``
        (``S[i].T @ T[j] = (S[j].T @ T[i]).T``) only the blocks ``j >= i`` are computed.
        An entry of ``S`` may be a pair ``(array, columns)``: those columns of it."""
        def part(rows, tmp):
            blocks = [[None] * len(T) for _ in S]
            for i, a in enumerate(S):
                a = _take(a, rows, tmp)
                for j, b in enumerate(T):
                    if not symmetric or j >= i:
                        blocks[i][j] = a.T @ b[rows]
            for i in range(len(S)):
                for j in range(i if symmetric else 0):
                    blocks[i][j] = blocks[j][i].T
            return np.block(blocks)

        return sum(self.map(part))

    def residuals(self, KX: np.ndarray, MX: np.ndarray, w2: np.ndarray, R: np.ndarray):
        """``(R, res)`` in one pass: the residuals ``R = K X - M X diag(w2)`` (into ``R``)
        and their relative norms ``||R|| / (|w2| ||M X||)``, column by column."""

        def part(rows, tmp):
            r = R[rows]
            np.multiply(MX[rows], w2, out=r)
            np.subtract(KX[rows], r, out=r)
            return np.stack([np.einsum("ij,ij->j", r, r),
                             np.einsum("ij,ij->j", MX[rows], MX[rows])])

        r2, m2 = np.sqrt(sum(self.map(part)))
        return R, r2 / (np.abs(w2) * m2)

    def times(self, Y: np.ndarray, C: np.ndarray) -> None:
        """``Y <- Y C`` in place (C square)."""
        def part(rows, tmp):
            Y[rows] = np.matmul(Y[rows], C, out=tmp("q", C.shape[1]))

        self.map(part)

    def subtract(self, W: np.ndarray, X: np.ndarray, H: np.ndarray) -> None:
        """``W <- W - X H`` in place."""
        def part(rows, tmp):
            _gemm_into(W[rows], X[rows], H, -1.0)

        self.map(part)

    def ritz_update(self, blocks, Cx: np.ndarray, Cw: np.ndarray,
                    Cp: np.ndarray | None, cols=slice(None)) -> None:
        """For each ``(Y, Z, Q)`` of ``blocks``, in place: ``Q <- Z Cw + Q[:, cols] Cp``
        (left out when ``Cp`` is None) and then ``Y <- Y Cx + Q``."""
        k = Cx.shape[1]

        def part(rows, tmp):
            for Y, Z, Q in blocks:
                q = np.matmul(Z[rows], Cw, out=tmp("q", k))
                if Cp is not None:
                    _gemm_into(q, _take((Q, cols), rows, tmp), Cp)
                Q[rows] = q
                Y[rows] = _gemm_into(q, Y[rows], Cx)

        self.map(part)


def lobpcg(ops, precondition, V, n, tol, maxiter, rows, clock):
    """LOBPCG for the lowest ``n`` eigenpairs of ``(K, M)``, block ``V[0].shape[1]``,
    started from the span of ``V[0]`` (a list, emptied here so that the block is freed
    once used). ``ops.stiffness(X, out)`` and ``ops.mass(X, out)`` apply K and M (a
    :class:`~modalmorph.core.solvers.multilevel.Operators`), ``precondition(R, cols,
    out)`` the preconditioner to the columns ``cols`` of ``R``; ``rows`` is a
    :class:`Rows` and ``clock`` is called with the name of each phase. The iterations
    stop when the wanted residuals are below ``tol``, at ``maxiter``, or when the largest
    has not fallen by ``1 - _STALL_FACTOR`` over ``_STALL_WINDOW`` iterations. Returns
    ``(w2, X, residuals, iterations)``."""
    K, apply_m = ops.stiffness, ops.mass
    X = V.pop()
    k = X.shape[1]
    KX, MX = K(X), apply_m(X)
    A, B = rows.inner([X], [KX], symmetric=True), rows.inner([X], [MX], symmetric=True)
    w2, C = rayleigh_ritz(A, B, k)
    for Y in (X, KX, MX):
        rows.times(Y, C)
    known = _carried(A, B, C, 0)
    P = KP = MP = None
    scratch = _Scratch(len(X))
    best = []  # the lowest largest wanted residual so far, per iteration
    for it in range(maxiter + 1):
        # relative residuals ||K x - w2 M x|| / (w2 ||M x||)
        R, res = rows.residuals(KX, MX, w2, scratch("R", k))
        clock(f"LOBPCG {it}")
        logger.debug("LOBPCG %d: residuals of the wanted modes max %.1e, median %.1e; "
                     "%d of %d columns not converged", it, res[:n].max(), np.median(res[:n]),
                     np.count_nonzero(res > tol), k)
        best.append(min(res[:n].max(), best[-1]) if best else res[:n].max())
        stalled = it >= _STALL_WINDOW and best[-1] > _STALL_FACTOR * best[-1 - _STALL_WINDOW]
        if (np.all(res[:n] <= tol) or it == maxiter or stalled
                or not np.all(np.isfinite(res))):
            return w2, X, res, it
        # soft locking: new directions only for the columns not yet converged
        active = np.flatnonzero(res > tol)
        a = len(active)
        cols = active if a < k else slice(None)  # a slice: no copies of the columns
        W = precondition(R, cols, scratch("W", a))
        rows.subtract(W, X, rows.inner([MX], [W]))  # M-orthogonal to the Ritz vectors
        KW, MW = K(W, scratch("KW", a)), apply_m(W, scratch("MW", a))
        # and the directions P of those columns only (those of the others left out)
        S = [X] if P is None else [X, (P, cols)]
        if P is not None:
            idx = np.r_[np.arange(k), k + active]
            known = tuple(G[np.ix_(idx, idx)] for G in known)
        # X^T M W = 0: W was made M-orthogonal to X above
        HM = rows.inner(S[1:] + [W], [MW])
        A = _bordered(known[0], rows.inner(S + [W], [KW]))
        B = _bordered(known[1], np.vstack([np.zeros((k, HM.shape[1])), HM]))
        del S, HM
        w2, C = rayleigh_ritz(A, B, k)
        known = _carried(A, B, C, a)
        Cx, Cw, Cp = C[:k], C[-a:], (C[k:k + a] if P is not None else None)
        if P is None:
            P, KP, MP = (np.empty_like(X) for _ in range(3))
        # P <- W Cw + P Cp, X <- X Cx + P: in place, a chunk of rows at a time
        rows.ritz_update(((X, W, P), (KX, KW, KP), (MX, MW, MP)), Cx, Cw, Cp, cols)
        del W, KW, MW
    raise AssertionError("unreachable")


class _Scratch:
    """Work blocks reused from one iteration to the next: ``scratch(name, c, n)`` is a
    contiguous (n, c) view of a buffer of ``rows * c`` doubles or more, made once per name
    (made again when a wider one is asked for); ``n`` defaults to ``rows``. At 100 000
    nodes a block of 150 MB made afresh costs its page faults every time: 18-84 ms against
    10-21 ms to fill a reused one."""

    def __init__(self, rows: int):
        self.rows, self.buffers = rows, {}

    def __call__(self, name: str, c: int, n: int | None = None) -> np.ndarray:
        n = self.rows if n is None else n
        if name not in self.buffers or len(self.buffers[name]) < n * c:
            self.buffers[name] = np.empty(self.rows * c)
        return self.buffers[name][:n * c].reshape(n, c)


def _take(a, rows, tmp):
    """``a[rows]``, or for a pair ``(array, columns)`` those columns of ``array[rows]``
    (into the thread's buffer ``tmp`` when ``columns`` is not a slice)."""
    if not isinstance(a, tuple):
        return a[rows]
    a, cols = a
    if isinstance(cols, slice):
        return a[rows][:, cols]
    return np.take(a[rows], cols, axis=1, out=tmp("take", len(cols)))


def _gemm_into(C: np.ndarray, A: np.ndarray, B: np.ndarray, alpha: float = 1.0):
    """``C <- C + alpha A B`` in place, no temporary (BLAS's ``dgemm`` with ``beta = 1``
    on the transposes; C is C-contiguous)."""
    out = _dgemm(alpha, B, A.T, beta=1.0, c=C.T, trans_a=1, overwrite_c=1)
    if not np.shares_memory(out, C):  # copied by f2py after all
        C[...] = out.T
    return C


def _bordered(G: np.ndarray, H: np.ndarray) -> np.ndarray:
    """The Gram matrix of the basis ``[S, W]`` from that of ``S`` (``G``, q x q) and the
    products of ``[S, W]`` with the new block (``H``, (q + a) x a)."""
    q = len(G)
    Hw = H[q:]
    return np.block([[G, H[:q]], [H[:q].T, (Hw + Hw.T) / 2]])


def _carried(A: np.ndarray, B: np.ndarray, C: np.ndarray, a: int):
    """The Gram matrices ``(E^T A E, E^T B E)`` of the next basis's known part
    ``[X, P]``, ``X = S C`` and ``P = S D`` (``D``: ``C`` with the rows of the old ``X``
    set to zero; ``a`` columns in the new block, 0 at the first step, when there is no
    ``P`` yet): products of small matrices instead of tall blocks (to round-off; the
    tolerance is some 1e12 times larger)."""
    k = C.shape[1]
    if a == 0:
        E = C
    else:
        D = C.copy()
        D[:k] = 0
        E = np.hstack([C, D])
    out = []
    for G in (A, B):
        F = E.T @ G @ E
        out.append((F + F.T) / 2)
    return tuple(out)
