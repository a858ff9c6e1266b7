"""The order-preserving dynamic programme of :mod:`.search`, compiled with numba.

Imported only when a search runs (``import modalmorph`` stays free of numba). The
recurrence, for a cost ``C`` (m, n), the cost ``skip`` of an unmatched source node and the
extra cost ``repeat`` of a target reused by consecutive source nodes (``inf``: never):

    F[0, j] = 0,  F[i + 1, 0] = skip (i + 1)
    T[i, j] = C[i, j] + min(F[i, 1 + j] + repeat, F[i, j])    (only F[i, j] for i = 0)
    F[i + 1, 1 + j] = min(F[i, 1 + j] + skip, min(T[i, :j + 1]))

``F[i, 1 + j]`` is the least cost of rows < i whose last target is <= j; the total is
``F[m, n]``. A closed target is searched doubled (2n columns, ``C``'s twice over) so that
the pairs may start anywhere. A pair costing more than ``skip`` is in no optimal matching
(skipping the row is cheaper) and never decides a minimum (``F`` does not increase along a
row), so the work of a row runs over its pairs costing at most ``skip`` and ``F`` is bit for
bit that of whole rows. The backtrack takes, of the least ``T[i, :cur + 1]``, the last
column (ties), and matches row i there if that is cheaper than skipping it; it needs of
each row only the columns where that least ``T`` so far moves (events: the column, whether
the previous row may end there too, the first column from which skipping is cheaper), so
``F`` keeps two rows.
"""

from __future__ import annotations

import warnings

import numba
import numpy as np

__all__ = ["ordered", "totals", "placed_search", "pose_costs", "shared_weights",
           "band_sq_dist"]


def _compiled(fn):
    """``fn`` compiled, its machine code cached beside this file or in the user's cache
    folder; where neither can be written (a read-only install and no home), compiled
    anew in each process, said once."""
    try:
        return numba.njit(cache=True, nogil=True)(fn)
    except RuntimeError as exc:  # numba: "cannot cache function ...: no locator available"
        if not _compiled.warned:
            _compiled.warned = True
            warnings.warn(f"modalmorph's compiled searches cannot be cached ({exc}); each "
                          "process compiles them anew (about 5 s): set NUMBA_CACHE_DIR to a "
                          "writable folder", RuntimeWarning, stacklevel=2)
        return numba.njit(nogil=True)(fn)


_compiled.warned = False


@_compiled
def _candidates(row, skip, cand):  # pragma: no cover - compiled
    """Write the columns of ``row`` costing at most ``skip`` into ``cand``, ascending;
    returns how many."""
    nc = 0
    for k in range(len(row)):
        if row[k] <= skip:
            cand[nc] = k
            nc += 1
    return nc


@_compiled
def _fill(out, value):  # pragma: no cover - compiled
    for k in range(len(out)):  # from 0: no negative index to wrap, so vectorised
        out[k] = value


@_compiled
def _add(a, value, out):  # pragma: no cover - compiled
    for k in range(len(out)):
        out[k] = a[k] + value


@_compiled
def _row(row, cand, i, rule, F, events, e):  # pragma: no cover - compiled
    """Row ``i`` of the programme under ``rule = (skip, repeat, doubled)``: row i + 1 of
    ``F`` from row i (``F`` keeps two rows, ``F[i % 2]`` is row i), the costs ``row`` (n,)
    and its columns ``cand`` costing at most ``skip``; its events from ``events[:, e]`` on
    where ``events`` has room. Between two candidates the least
    ``T`` so far is fixed: ``F`` is that, until skipping the row is cheaper, then skipping
    (``F[i]`` does not rise along the row: the column where skipping wins is bisected,
    the rest are two vectorised fills).
    Returns the next free event."""
    skip, repeat, doubled = rule
    n, nc, Fa, Fn = len(row), len(cand), F[i % 2], F[1 - i % 2]
    N = 2 * n if doubled else n
    repeats = repeat < np.inf and i > 0
    record = events.shape[1] > 0
    Fn[0] = skip * (i + 1)
    run, skipping, open_ = np.inf, True, False  # open_: the last event not yet skipped
    j, last = 0, 2 * nc if doubled else nc
    for h in range(last + 1):
        stop = N if h == last else cand[h] if h < nc else cand[h - nc] + n
        if not skipping:  # matched at the least T so far, until skipping is cheaper
            a, b = j, stop  # F[i, 1 + j] + skip does not rise: bisect for that column
            while a < b:
                mid = (a + b) // 2
                if Fa[1 + mid] + skip <= run:
                    b = mid
                else:
                    a = mid + 1
            _fill(Fn[1 + j:1 + a], run)
            j = a
            if j < stop:
                skipping = True
                if open_:
                    events[2, e - 1] = j
                    open_ = False
        _add(Fa[1 + j:1 + stop], skip, Fn[1 + j:1 + stop])  # skipped: only falls
        if h == last:
            break
        p = Fa[stop]  # the candidate: previous target < stop, or == stop at a price
        if repeats:
            q = Fa[1 + stop] + repeat
            p = q if q <= p else p
        t = (row[stop - n] if stop >= n else row[stop]) + p
        if t <= run:  # the last column of the least T so far
            run, skipping = t, False
            if record:
                if open_:
                    events[2, e - 1] = stop
                events[0, e] = stop
                events[1, e] = repeats and Fa[stop + 1] + repeat < Fa[stop]
                e += 1
                open_ = True
        s = Fa[1 + stop] + skip
        if s <= run:
            Fn[1 + stop] = s
            skipping = True
            if open_:
                events[2, e - 1] = stop
                open_ = False
        else:
            Fn[1 + stop] = run
        j = stop + 1
    if open_:
        events[2, e - 1] = N
    return e


@_compiled
def _room(events, e, n):  # pragma: no cover - compiled
    """``events`` with room for one more row of ``n`` columns doubled after ``e``."""
    if e + 2 * n <= events.shape[1]:
        return events
    grown = np.empty((3, 2 * (e + 2 * n)), np.intp)
    for r in range(3):  # loops: a 2D slice assignment takes numba 5 s to compile
        for k in range(e):
            grown[r, k] = events[r, k]
    return grown


@_compiled
def _backtrack(events, starts, N):  # pragma: no cover - compiled
    """``j`` (m,) from the events of each row (row i's from ``starts[i]``)."""
    m = len(starts) - 1
    j = np.full(m, -1, np.intp)
    cur = N - 1
    for i in range(m - 1, -1, -1):
        if cur < 0:
            break
        e0, e1 = starts[i], starts[i + 1]
        e = e0 + np.searchsorted(events[0, e0:e1], cur, side="right") - 1
        if e >= e0 and cur < events[2, e]:  # row i matched (else skipped)
            j[i] = a = events[0, e]
            cur = a if events[1, e] else a - 1
    return j


@_compiled
def ordered(C, rule):  # pragma: no cover - compiled
    """Order-preserving matching over ``C`` (m, n), C-contiguous float64, under ``rule =
    (skip, repeat, doubled)`` (``doubled``: its columns twice over). Returns ``j`` (m,),
    -1 where the source node is unmatched (columns of the doubled target: 0..2n - 1), and
    the least total cost."""
    m, n = C.shape
    N = 2 * n if rule[2] else n
    F = np.empty((2, N + 1))
    F[0, :] = 0.0
    events = np.empty((3, 4 * m + 2 * n), np.intp)
    starts = np.zeros(m + 1, np.intp)
    cand = np.empty(n, np.intp)
    for i in range(m):
        nc = _candidates(C[i], rule[0], cand)
        events = _room(events, starts[i], n)
        starts[i + 1] = _row(C[i], cand[:nc], i, rule, F, events, starts[i])
    return _backtrack(events, starts, N), F[m % 2, N]


@_compiled
def totals(C, rule):  # pragma: no cover - compiled
    """The least total cost of :func:`ordered` for each problem of ``C`` (b, m, n)."""
    b, m, n = C.shape
    F = np.empty((2, (2 * n if rule[2] else n) + 1))
    none = np.empty((3, 0), np.intp)
    cand = np.empty(n, np.intp)
    out = np.empty(b)
    for k in range(b):
        F[0, :] = 0.0
        for i in range(m):
            nc = _candidates(C[k, i], rule[0], cand)
            _row(C[k, i], cand[:nc], i, rule, F, none, 0)
        out[k] = F[m % 2, F.shape[1] - 1]
    return out


@_compiled
def placed_cost(xx, yy, G2, S, r, i, j, h2):  # pragma: no cover - compiled
    """``max(xx[i] + yy[j] - G2[i, j], 0) / h2 + S[r, j]``: numpy's ``sq_dist(x, y) / h2 +
    S[rows]`` (``G2 = 2 x y^T``) in its order of operations, so bit for bit."""
    c = (xx[i] + yy[j]) - G2[i, j]
    c = c if c >= 0.0 or c != c else 0.0
    return c / h2 + S[r, j]


@_compiled
def placed_search(xx, yy, G2, S, rows, h2, rule):  # pragma: no cover - compiled
    """:func:`ordered` over the cost of source nodes placed at ``x`` against the target
    ``y``, :func:`placed_cost`, each row made when the search reaches it (no (m, n) cost
    array), and only where the squared distance alone does not exceed ``skip`` (the
    signature cost ``S`` is a squared distance, >= 0: no division elsewhere). Returns
    ``j`` (m,) on the target itself (0..n - 1) and the cost of each pair (m,) (``inf``
    where unmatched)."""
    m, n = G2.shape
    skip = rule[0]
    N = 2 * n if rule[2] else n
    F = np.empty((2, N + 1))
    F[0, :] = 0.0
    row, cand = np.empty(n), np.empty(n, np.intp)
    events = np.empty((3, 4 * m + 2 * n), np.intp)
    starts = np.zeros(m + 1, np.intp)
    near = skip * h2 * (1.0 + 1e-12)  # S >= 0: a pair farther than this costs > skip
    close = np.empty(n, np.bool_)
    for i in range(m):
        x2, g = xx[i], G2[i]
        for k in range(n):  # vectorised: which pairs may cost at most skip
            close[k] = (x2 + yy[k]) - g[k] <= near
        nc = 0
        for k in range(n):  # the row's candidates; the others' costs are never read
            if close[k]:
                row[k] = c = placed_cost(xx, yy, G2, S, rows[i], i, k, h2)
                if c <= skip:
                    cand[nc] = k
                    nc += 1
        events = _room(events, starts[i], n)
        starts[i + 1] = _row(row, cand[:nc], i, rule, F, events, starts[i])
    j = _backtrack(events, starts, N)
    cost = np.full(m, np.inf)
    for i in range(m):
        if j[i] >= n:
            j[i] -= n
        if j[i] >= 0:
            cost[i] = placed_cost(xx, yy, G2, S, rows[i], i, j[i], h2)
    return j, cost


@_compiled
def pose_costs(rots, x, y, h2, S):  # pragma: no cover - compiled
    """The pose search's cost (r, m, n) of 2D nodes ``x`` (m, 2) turned by each of
    ``rots`` (r, 2, 2) against ``y`` (n, 2): ``|R x_i - y_j|^2 / h2 + S[i, j]`` with
    numpy's operations in its order (``sq_dist`` of the turned nodes), bit for bit, in one
    pass; and each row's least (r, m), ``D.min(axis=2)``'s (NaN when one is)."""
    r, m, n = len(rots), len(x), len(y)
    yy = np.empty(n)
    for j in range(n):
        yy[j] = y[j, 0] ** 2 + y[j, 1] ** 2
    D = np.empty((r, m, n))
    low = np.empty((r, m))
    for k in range(r):
        for i in range(m):
            z0 = rots[k, 0, 0] * x[i, 0] + rots[k, 0, 1] * x[i, 1]
            z1 = rots[k, 1, 0] * x[i, 0] + rots[k, 1, 1] * x[i, 1]
            zz = z0**2 + z1**2
            least = np.inf
            for j in range(n):
                zy = z0 * y[j, 0] + z1 * y[j, 1]
                v = ((zz + yy[j]) - 2 * zy) / h2 + S[i, j]
                D[k, i, j] = v
                if v < least or v != v:
                    least = v
            low[k, i] = least
    return D, low


_TINY = np.finfo(np.float64).tiny


@_compiled
def shared_weights(E, valid, band, n):  # pragma: no cover - compiled
    """The coherent pass's E-step after the exponential ``E`` (k, b): ``K = E`` where
    ``valid`` (else 0), each of the ``n`` target nodes' ``share`` of it (``np.bincount``
    in its order) and ``P = K / max(share[band], tiny)``, bit for bit numpy's."""
    k, w = E.shape
    share = np.zeros(n)
    for i in range(k):
        for j in range(w):
            if valid[i, j]:
                share[band[i, j]] += E[i, j]
    P = np.zeros((k, w))
    for i in range(k):
        for j in range(w):
            if valid[i, j]:
                s = share[band[i, j]]
                P[i, j] = E[i, j] / (s if s >= _TINY or s != s else _TINY)
    return P


@_compiled
def band_sq_dist(z, yb):  # pragma: no cover - compiled
    """``np.sum((z[:, None, :] - yb) ** 2, axis=2)`` (k, b) for 2D ``z`` (k, 2) and
    ``yb`` (k, b, 2), bit for bit (numpy adds the two squares in order)."""
    k, w = yb.shape[0], yb.shape[1]
    D = np.empty((k, w))
    for i in range(k):
        for j in range(w):
            D[i, j] = (z[i, 0] - yb[i, j, 0]) ** 2 + (z[i, 1] - yb[i, j, 1]) ** 2
    return D
