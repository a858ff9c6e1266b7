"""The order-preserving dynamic programme of :mod:`.search`, compiled with numba.

Imported only when a search runs (``import modalmorph`` stays free of numba). The
recurrence, for a cost ``C`` (m, n), the cost ``skip`` of an unmatched source node and the
extra cost ``repeat`` of a target reused by consecutive source nodes (``inf``: never):

    F[0, j] = 0,  F[i + 1, 0] = skip (i + 1)
    T[i, j] = C[i, j] + min(F[i, 1 + j] + repeat, F[i, j])    (only F[i, j] for i = 0)
    F[i + 1, 1 + j] = min(F[i, 1 + j] + skip, min(T[i, :j + 1]))

``F[i, 1 + j]`` is the least cost of rows < i whose last target is <= j. Row i's work runs
over its candidate columns only, the first to the last whose cost is at most ``skip``: a
pair costing more is in no optimal matching (skipping the row is cheaper) and never decides
a minimum (``F`` does not increase along a row), so ``F`` is bit for bit that of whole rows.
The backtrack recomputes ``T`` on the columns it scans; ties go to the last column.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["ordered", "totals", "placed_costs"]


@numba.njit(cache=True, nogil=True)
def _span(row, skip):  # pragma: no cover - compiled
    """The first and last column of ``row`` costing at most ``skip`` (first > last where
    there is none)."""
    n = len(row)
    lo, hi = 0, n - 1
    while lo < n and not row[lo] <= skip:
        lo += 1
    while hi >= lo and not row[hi] <= skip:
        hi -= 1
    return lo, hi


@numba.njit(cache=True, nogil=True)
def _forward(C, skip, repeat, doubled, F, first, last):  # pragma: no cover - compiled
    """Fill ``F`` (m + 1 rows kept, or 2 alternating) and each row's candidate columns
    ``first[i]..last[i]`` (first > last where there is none). ``doubled``: the columns
    of ``C`` (m, n) twice over, the search's target a closed one doubled (2n columns)."""
    m, n = C.shape
    N = 2 * n if doubled else n
    keep = F.shape[0] == m + 1
    repeats = repeat < np.inf
    F[0, :] = 0.0
    for i in range(m):
        a, b = (i, i + 1) if keep else (i % 2, 1 - i % 2)
        Fa, Fn, row = F[a], F[b], C[i]
        lo, hi = _span(row, skip)
        if doubled and lo <= hi:
            hi += n
        first[i], last[i] = lo, hi
        Fn[0] = skip * (i + 1)
        for j in range(lo):  # before the candidates: row i skipped
            Fn[1 + j] = Fa[1 + j] + skip
        run = np.inf
        for j in range(lo, hi + 1):
            s = Fa[1 + j] + skip
            c = row[j - n] if j >= n else row[j]
            if c <= skip:  # a dearer pair never decides the minimum, as outside the span
                p = Fa[j]
                if repeats and i > 0:  # previous target < j, or == j at a price
                    q = Fa[1 + j] + repeat
                    p = q if q <= p else p
                t = c + p
                run = t if t < run else run
            Fn[1 + j] = s if s <= run else run
        for j in range(hi + 1, N):  # after them: skipped, or matched within them
            s = Fa[1 + j] + skip
            Fn[1 + j] = s if s <= run else run


@numba.njit(cache=True, nogil=True)
def ordered(C, skip, repeat, doubled):  # pragma: no cover - compiled
    """Order-preserving matching over ``C`` (m, n), C-contiguous float64, its columns
    twice over where ``doubled``. Returns ``j`` (m,), -1 where the source node is
    unmatched, and the least total cost."""
    m, n = C.shape
    N = 2 * n if doubled else n
    F = np.empty((m + 1, N + 1))
    first, last = np.empty(m, np.intp), np.empty(m, np.intp)
    _forward(C, skip, repeat, doubled, F, first, last)
    repeats = repeat < np.inf
    j = np.full(m, -1, np.intp)
    cur = N - 1
    for i in range(m - 1, -1, -1):
        if cur < 0:
            break
        lo, hi = first[i], min(last[i], cur)
        Fi, row = F[i], C[i]
        a, best = -1, np.inf
        for k in range(hi, lo - 1, -1):  # the last column of the least T[i, lo..hi]
            c = row[k - n] if k >= n else row[k]
            if c <= skip:
                p = Fi[k]
                if repeats and i > 0:
                    q = Fi[1 + k] + repeat
                    p = q if q <= p else p
                t = c + p
                if t < best:
                    a, best = k, t
        if a >= 0 and best < Fi[cur + 1] + skip:  # row i matched (else skipped)
            j[i] = a
            again = repeats and i > 0 and Fi[a + 1] + repeat < Fi[a]
            cur = a if again else a - 1
    return j, F[m, N]


@numba.njit(cache=True, nogil=True)
def totals(C, skip, repeat, doubled):  # pragma: no cover - compiled
    """The least total cost of :func:`ordered` for each problem of ``C`` (b, m, n), in
    memory of two rows of ``F``."""
    b, m, n = C.shape
    F = np.empty((2, (2 * n if doubled else n) + 1))
    first, last = np.empty(m, np.intp), np.empty(m, np.intp)
    out = np.empty(b)
    for k in range(b):
        _forward(C[k], skip, repeat, doubled, F, first, last)
        out[k] = F[m % 2, F.shape[1] - 1]
    return out


@numba.njit(cache=True, nogil=True)
def placed_costs(xx, yy, G2, S, rows, h2):  # pragma: no cover - compiled
    """``max(xx[i] + yy[j] - G2[i, j], 0) / h2 + S[rows[i], j]`` (m, n), with ``G2 = 2 x
    y^T``: the operations of numpy's ``sq_dist(x, y) / h2 + S[rows]`` in its order, so bit
    for bit, in one pass."""
    m, n = G2.shape
    C = np.empty((m, n))
    for i in range(m):
        s = S[rows[i]]
        for j in range(n):
            c = (xx[i] + yy[j]) - G2[i, j]
            c = c if c >= 0.0 or c != c else 0.0
            C[i, j] = c / h2 + s[j]
    return C
