"""The searches that turn costs into pairs (method.md §2).

The paper's: :func:`mutual_best` over the affinity (8) and the rejection of an
assignment's implausible pairs (:func:`plausible`). The default search's: an
order-preserving dynamic programme for contours (:func:`ordered_pairs`, cyclic for a closed
target; :func:`monotone_totals` scores many problems at once for the pose search) and an
assignment for point sets, over the cost of a placed source (:class:`Costs`,
:func:`pairs_at`); the pairs trusted for the fits (:func:`trusted_pairs`), the search's
objective (:func:`total`, :func:`objective`) and the final pairs (:func:`final_pairs`,
which go round a closed target once).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.optimize import linear_sum_assignment

from .features import sq_dist

__all__ = ["SKIP", "REPEAT", "mutual_best", "plausible", "monotone_totals",
           "ordered_pairs", "Costs", "pairs_at", "trusted_pairs", "total", "objective",
           "final_pairs"]

# The default search's costs, in squared target node spacings.
SKIP = 16.0  # leaving a source node unmatched (not measured)
REPEAT = 4.0  # one target for two consecutive source nodes, a denser source (not measured)
_TRUST = 4.0  # pairs costing at most this are trusted for the fits (not measured)


def mutual_best(Z: np.ndarray) -> np.ndarray:
    """Pairs ``(i, j)`` with ``j`` best in row ``i`` and ``i`` best in column ``j``."""
    j = np.argmin(Z, axis=1)
    i = np.arange(Z.shape[0])
    keep = np.argmin(Z, axis=0)[j] == i
    return np.c_[i[keep], j[keep]]


def plausible(cost: np.ndarray, factor: float) -> np.ndarray:
    """Mask of the pairs whose cost is not implausibly high: at most ``factor`` times the
    median cost (and at least the median, so that a clean matching loses nothing)."""
    if cost.size == 0:
        return np.ones(0, bool)
    return cost <= factor * max(float(np.median(cost)), 1e-12)


def _monotone(C: np.ndarray, skip: float, repeat: float = np.inf, closed: bool = False
              ) -> tuple[np.ndarray, float]:
    """Order-preserving matching: ``j(i)`` non-decreasing in ``i``, each source node matched
    (cost ``C[i, j]``) or skipped (cost ``skip``), a target reused by consecutive source
    nodes at the extra cost ``repeat`` (``inf``: one-to-one); minimal total cost.

    ``C`` has shape (m, n); ``closed``: the target is closed and the search runs on it
    doubled (2n columns, ``C``'s twice over), so that it may start anywhere. Returns
    ``j`` (m,), -1 where the source node is unmatched, and the total cost. A dynamic
    programme compiled with numba (:mod:`._dp`), each row's work within its columns
    costing at most ``skip``.
    """
    from ._dp import ordered  # numba loads with the first search, not with the package
    j, best = ordered(np.ascontiguousarray(C, dtype=np.float64),
                      (float(skip), float(repeat), bool(closed)))
    return j, float(best)


def monotone_totals(C: np.ndarray, skip: float, repeat: float = np.inf,
                    closed: bool = False) -> np.ndarray:
    """The least total cost of :func:`_monotone` for a batch of problems ``C`` (..., m, n),
    shape (...,), in memory of two rows."""
    from ._dp import totals
    *batch, m, n = C.shape
    flat = np.ascontiguousarray(C, dtype=np.float64).reshape(-1, m, n)
    return totals(flat, (float(skip), float(repeat), bool(closed))).reshape(batch)


def ordered_pairs(C: np.ndarray, closed: bool, skip: float, repeat: float):
    """Order-preserving pairs over a cost (m, n), cyclic for a closed target. Returns j
    (m,) and the total cost."""
    j, best = _monotone(C, skip, repeat, closed)
    return np.where(j >= 0, j % C.shape[-1], -1), best


def _untangle(t: np.ndarray, cost: np.ndarray, n: int, skip: float, strict: bool
              ) -> np.ndarray:
    """Pairs of a cyclic order-preserving search that go round the target once.

    ``t`` (K,) are the partners, in source order, on a closed target of ``n`` nodes, and
    ``cost`` their costs. On the doubled target the search may step forward by nearly a
    whole turn, which is a step backwards on the closed target: there, and at the
    source's own cut, partners can overlap and cross. Each extra turn is removed at the
    largest step: unrolled from just after it, the pairs at the end that reach past where
    the first ones started are dropped, or the first ones they overlap, whichever keeps
    the search's objective (pair costs plus ``skip`` per unmatched node) lower. Returns a
    mask of the pairs kept.
    """
    keep = np.ones(len(t), bool)
    while True:
        idx = np.flatnonzero(keep)
        steps = np.diff(np.concatenate((t[idx], t[idx[:1]]))) % n  # to the next partner
        if idx.size < 2 or steps.sum() <= n:  # round once (or all on one target)
            return keep
        k = int(np.argmax(steps))  # the step back, seen as nearly a whole turn
        r = np.roll(idx, -(k + 1))
        u = t[r[0]] + np.concatenate(([0], np.cumsum(np.roll(steps, -(k + 1))[:-1])))
        first, last = u[0] + n, u[-1] - n  # how far each end may reach
        end = r[u >= first] if strict else r[u > first]
        start = r[u <= last] if strict else r[u < last]
        loss_end = skip * len(end) - cost[end].sum()  # change of the objective
        loss_start = skip * len(start) - cost[start].sum()
        keep[end if loss_end <= loss_start else start] = False


def _columns(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.stack([a, b], axis=1)`` of two index arrays, (k, 2) intp (3 us against
    np.stack's 7 and np.c_'s 17: 16 calls a match)."""
    out = np.empty((len(a), 2), dtype=np.intp)
    out[:, 0], out[:, 1] = a, b
    return out


def _pairs_from_j(j: np.ndarray, cost: np.ndarray, one_to_one: bool):
    """The pairs ``(i, j[i])`` where ``j[i] >= 0`` and their costs, from the partner and
    the pair's cost ``cost`` (m,) of every source node."""
    i = np.flatnonzero(j >= 0)
    pairs = _columns(i, j[i])
    # a cyclic search may reuse a target once across the cut (68 of the 142 searches of
    # the 16 heart pairs at 70 nodes; a count finds it, 10 us against the stable sort and
    # unique's 50; a loop over the shared targets instead was no faster)
    if one_to_one and len(pairs) and np.bincount(pairs[:, 1]).max() > 1:
        order = np.argsort(cost[i], kind="stable")
        _, first = np.unique(pairs[order, 1], return_index=True)
        pairs = pairs[np.sort(order[first])]
    return pairs, cost[pairs[:, 0]]


@dataclass(frozen=True, eq=False)
class Costs:
    """What one search compares: the source nodes ``x`` (m, d) placed somewhere, against
    the target ``y`` (n, d) in search order (reversed when the pose search reversed it)
    with the signature cost ``F`` (m, n) in the same order; ``h2`` the target's squared
    node spacing; ``repeat`` and ``many`` as in :func:`_monotone` and
    :func:`_pairs_from_j`."""

    x: np.ndarray
    y: np.ndarray
    F: np.ndarray
    h2: float
    ordered: bool
    closed: bool
    repeat: float = np.inf
    many: bool = False

    @cached_property
    def yy(self) -> np.ndarray:
        """The target nodes' squared norms (n,), as ``sq_dist`` sums them (made once for
        the alternation's rounds)."""
        return np.add.reduce(self.y**2, axis=1)


def pairs_at(costs: Costs, z: np.ndarray, rows: np.ndarray):
    """Pairs (row index, target index) for the source nodes ``rows`` (distinct, ascending)
    placed at ``z``, and their costs: order-preserving for contours (the cost of every
    row made inside the compiled search, :func:`._dp.placed_search`, bitwise
    ``sq_dist(z[rows], y) / h2 + F[rows]``), an assignment for point sets."""
    x, y = z[rows], costs.y
    if costs.ordered:
        from ._dp import placed_search
        xx = np.add.reduce(x**2, axis=1)  # as sq_dist
        j, cost = placed_search(xx, costs.yy, 2 * x @ y.T, costs.F, np.asarray(rows, np.intp),
                                float(costs.h2), (SKIP, float(costs.repeat), bool(costs.closed)))
        return _pairs_from_j(j, cost, one_to_one=not costs.many)
    C = sq_dist(x, y) / costs.h2 + costs.F[rows]
    r, c = linear_sum_assignment(C)
    return np.c_[r, c], C[r, c]


def _trusted(pairs: np.ndarray, cost: np.ndarray, d: int) -> np.ndarray:
    """The pairs trusted for the alignment and deformation fits: those costing at most
    ``_TRUST``, or all of them when too few are."""
    good = pairs[cost <= _TRUST]
    return pairs if len(good) < max(d + 1, len(pairs) // 4) else good


def trusted_pairs(costs: Costs, z: np.ndarray, sub: np.ndarray):
    """Search the source nodes ``sub`` placed at ``z``: the trusted pairs (source index,
    target index) and the total cost of all pairs."""
    pairs, cost = pairs_at(costs, z, sub)
    rows = _columns(sub[pairs[:, 0]], pairs[:, 1])
    return _trusted(rows, cost, z.shape[1]), cost.sum()


def total(found: tuple, m: int) -> float:
    """The search's objective from its pairs and their costs ``found``: pair costs plus
    ``SKIP`` for every one of the ``m`` source nodes left unmatched."""
    pairs, cost = found
    return float(cost.sum() + SKIP * (m - len(pairs)))


def objective(costs: Costs, z: np.ndarray) -> float:
    """The search's objective for every source node placed at ``z``."""
    return total(pairs_at(costs, z, np.arange(len(z))), len(z))


def final_pairs(final: Costs, z: np.ndarray, found: tuple, reject: float):
    """The pairs ``found`` by the search on every source node placed at ``z`` (pairs
    and their costs), less those costing more than ``reject`` and, on a closed target,
    those that would go round it twice. Returns the pairs (target indices in search
    order) and their costs."""
    pairs, cost = found
    keep = cost <= reject
    if final.closed:  # partners round the target once: none crossing at the cut or a step back
        keep &= _untangle(pairs[:, 1], cost, len(final.y), SKIP, strict=not final.many)
    return pairs[keep], cost[keep]
