"""Loads (19)-(21) and Newmark integration of the modal equations (11)-(16)."""

from __future__ import annotations

from bisect import bisect_right
from dataclasses import dataclass, field

import numpy as np
from scipy.linalg import lapack
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree

from .affine import affine_fit_weights
from .surfaces import closest_on_band, closest_on_faces

__all__ = ["Newmark", "lifted", "LoadTargets", "ContourLoads", "contour_partners", "check_newmark",
           "UNMATCHED_RULES", "CARRIERS", "AFFINE_CARRIERS"]

UNMATCHED_RULES = ("arclength", "mean")

# Groups of (20) with at most this many (node, candidate) pairs share one vectorised pass.
_SMALL_GROUP = 256
# Target nodes per source node a stretch may hold and still be covered (method.md §4).
_COVER = 1.5
# Matched nodes (nearest, in the source) whose displacements carry a node of a contour
# without a partner: those of a 2D point set's rule (MorphOptions.neighbours' default).
CARRIERS = 6
# Matched nodes (at least) whose displacements' affine fit carries an unmatched node of a
# 3D point set or surface: the fit has 4 unknowns a coordinate. Measured on the matcher's
# pairs of an icosphere of 642 vertices onto an ellipsoid of 162 (480 nodes carried): with
# 6, the carried targets lay up to 16 tolerances off the target (median 2.9) and 11 faces
# of the target positions turned over, the morph cut itself at 8 of 9 steps (up to 71
# faces); with 12, none turned over (up to 9 tolerances off), one step cut (19 faces).
AFFINE_CARRIERS = 12


def check_newmark(alpha: float, delta: float) -> None:
    """Refuse Newmark parameters outside the unconditionally stable range (14).

    Newmark's method is unconditionally stable for ``2 alpha >= delta >= 0.5``.
    """
    if not (delta >= 0.5 and 2 * alpha >= delta):
        raise ValueError(
            f"Newmark alpha={alpha:g}, delta={delta:g} is not unconditionally stable: "
            f"need 2*alpha >= delta >= 0.5 (e.g. alpha=0.25, delta=0.5, or "
            f"alpha=(delta+0.5)**2/4 for delta > 0.5, (16))")


class LoadTargets:
    """Where each source node is pulled to: its partner, or a rule for unmatched nodes.

    Matched node ``i``: its partner on the target (19). Unmatched node ``B`` of an ordered
    contour between matched neighbours ``A`` and ``C`` (along the contour), pulled towards
    the target stretch from their partners ``A'`` to ``C'`` (the shorter way round a
    closed target):

    - ``rule="arclength"``: the point of that stretch at the same fraction of its arc
      length as ``B`` has along the source from ``A`` to ``C``. A run of unmatched nodes
      is laid evenly along the stretch, however long the run.
    - ``rule="mean"``: the paper's (20), the weighted mean of the target nodes ``B'``
      strictly between ``A'`` and ``C'`` (``A'`` and ``C'`` themselves when none lies
      between), with weights ``D_tot - D_B'`` normalised to sum to 1,
      ``D_B' = |X_B - X_2,B'|`` at the current shape. Every node of a long run is pulled
      to nearly the same point (the weights are nearly uniform), which folds the run.

    At the ends of an open contour, a node with one matched neighbour ``A`` moves with
    ``A`` (target ``X_1,B + A' - A``). For unordered 3D point sets and surfaces (either
    rule) the neighbours are the ``neighbours`` nearest matched nodes (Euclidean, in the
    source), and ``B`` is pulled to ``X_1,B`` plus the (20)-weighted mean of their
    displacements ``A' - A``.

    Parameters
    ----------
    source, target : ndarray, shape (m, d) and (n, d)
        Nodes in one common frame.
    pairs : ndarray of int, shape (K, 2)
        Matched (source, target) indices.
    ordered : bool
        Whether the objects are contours (else point sets or surfaces).
    closed : tuple of bool
        Whether the source and the target contours are closed.
    neighbours : int
        Number of matched neighbours for unordered objects (in 3D, where they are
        fitted by an affine map, at least ``AFFINE_CARRIERS``).
    rule : {"arclength", "mean"}
        The rule for unmatched nodes of a contour (above).
    faces : ndarray of int, shape (f, 3), optional
        The target's triangles, for a 3D point set or surface: its carried nodes are
        pulled to the closest point of them (of a coarser target, of the band between
        them and the smooth surface through its vertices: ``closest_on_band``) to where
        their neighbours carry them, on the target's surface, not off it between its
        vertices (method.md §5).
    """

    def __init__(self, source, target, pairs, *, ordered: bool, closed: tuple[bool, bool],
                 neighbours: int = 6, rule: str = "arclength",
                 faces: np.ndarray | None = None):
        if rule not in UNMATCHED_RULES:
            raise ValueError(f"unmatched must be one of {UNMATCHED_RULES}, got {rule!r}")
        if np.shape(closed) != (2,):
            raise ValueError(f"closed must be a (source, target) pair of bool, got {closed!r}")
        if faces is not None and ordered:
            raise ValueError("faces are the target surface's: contours have none")
        self.rule = rule
        closed, target_closed = closed
        m = len(source)
        self.source = source
        self.target = target
        self.matched = np.zeros(m, dtype=bool)
        self.matched[pairs[:, 0]] = True
        self.partner = np.full(m, -1)
        self.partner[pairs[:, 0]] = pairs[:, 1]
        self.turn = 0  # the way the partners run round a closed target: +1, -1, 0 unknown
        self._sorted = None  # the matched partners, sorted (_way)
        if ordered and target_closed:
            self.turn = _turn(self.partner[self.matched], len(target), closed) or (
                _orientation(source) * _orientation(target) if closed else 0)
        if ordered and rule == "arclength" and len(pairs) > 1:
            self._release_shared(closed)
            self._release_to_cover(closed, target_closed)
        elif not ordered and source.shape[1] == 3 and len(pairs) > 1:
            self._release_shared_points()
        un = np.flatnonzero(~self.matched)
        # For each unmatched node: its candidate target nodes (20), or its carriers.
        if un.size == 0:
            self._groups = []
        elif ordered:
            self._groups = self._contour_candidates(un, closed, target_closed, len(target))
        else:
            k = min(max(neighbours, AFFINE_CARRIERS if source.shape[1] == 3 else 0),
                    int(self.matched.sum()))
            idx_matched = np.flatnonzero(self.matched)
            _, nb = cKDTree(source[idx_matched]).query(source[un], k=k)
            nb = idx_matched[np.asarray(nb).reshape(len(un), k)]
            self._groups = [("carry", un, nb)]
        self._flatten()
        if faces is not None:
            onto = closest_on_band if m > len(target) else closest_on_faces
            self._fixed = [(nodes, onto(at, target, faces)) for nodes, at in self._fixed]

    @property
    def pairs(self) -> np.ndarray:
        """The (source, target) pairs pulled to each other by (19), (K, 2): the matching's,
        less those freed to cover the target (:meth:`_release_to_cover`)."""
        idx = np.flatnonzero(self.matched)
        return np.stack((idx, self.partner[idx]), axis=1)  # np.c_'s: 7 us, not 17

    def _release_shared(self, closed: bool) -> None:
        """Keep one source node per target node: of consecutive matched nodes that share
        a partner (a denser source; on a closed one, also past its last node), the middle
        one stays matched and the others join the arclength rule, which spreads them
        between the neighbouring partners: on one point they would fold."""
        midx = np.flatnonzero(self.matched)
        part = self.partner[midx]
        turns = np.flatnonzero(part[1:] != part[:-1])
        if closed and turns.size and part[0] == part[-1]:  # begin where a run begins
            midx, part = np.roll(midx, -turns[0] - 1), np.roll(part, -turns[0] - 1)
        start = np.r_[True, part[1:] != part[:-1]]
        run = np.cumsum(start) - 1  # run id of each matched node (consecutive, same partner)
        first = np.flatnonzero(start)
        length = np.diff(np.r_[first, len(midx)])
        free = length[run] > 1
        free[first + length // 2] = False  # the middle of each run stays
        self.matched[midx[free]] = False
        self.partner[midx[free]] = -1

    def _release_shared_points(self) -> None:
        """3D point sets and surfaces: of the matched nodes that share a partner (a denser
        source), the one nearest their centroid stays; the others move with their matched
        neighbours. On one point they bunch off the target's surface (an icosphere of 642
        vertices onto one of 162 stopped 1.6 % of the size off it, method.md §5)."""
        midx = np.flatnonzero(self.matched)
        part = self.partner[midx]
        order = np.argsort(part, kind="stable")
        part, midx = part[order], midx[order]
        start = np.r_[True, part[1:] != part[:-1]]
        group = np.cumsum(start) - 1
        centre = np.zeros((group[-1] + 1, self.source.shape[1]))
        np.add.at(centre, group, self.source[midx])
        centre /= np.bincount(group)[:, None]
        off = np.sum((self.source[midx] - centre[group]) ** 2, axis=1)
        nearest = np.lexsort((off, group))  # by group, the node nearest its centroid first
        free = np.ones(len(midx), bool)
        free[nearest[np.r_[True, group[nearest][1:] != group[nearest][:-1]]]] = False
        self.matched[midx[free]] = False
        self.partner[midx[free]] = -1

    def _release_to_cover(self, closed: bool, target_closed: bool) -> None:
        """Free the matched nodes at the ends of target stretches that the source nodes
        between them cannot cover, so that the arclength rule spreads more nodes there.

        Between consecutive matched source nodes ``a`` and ``c`` lie ``b`` source nodes;
        their partners bound a stretch of ``s`` target segments. When ``s / (b + 1)``
        exceeds ``_COVER`` times the target's nodes per source node (at least 1), target
        nodes there would be left off the shape (a serif, a fingertip the matcher left
        unpaired): ``a`` and ``c`` join the unmatched run, which then spans the stretches
        on both sides, until every stretch is covered or at most two matched nodes are
        left (at least one stays).
        """
        m, n = len(self.source), len(self.target)
        allowed = _COVER * max(n / m, 1.0)
        while True:
            midx = np.flatnonzero(self.matched)
            if len(midx) <= 2:
                return
            a, c = (midx, np.roll(midx, -1)) if closed else (midx[:-1], midx[1:])
            between = (c - a - 1) % m
            span = np.abs(self.partner[c] - self.partner[a])
            if target_closed:  # the partners' way round (the shorter where unknown)
                span = _span(self.partner[a], self.partner[c], n, self.turn)
            gap = span / (between + 1) > allowed
            if not gap.any():
                return
            free = np.union1d(a[gap], c[gap])
            if len(free) == len(midx):  # keep one: the arclength rule then goes round
                free = free[1:]
            self.matched[free] = False
            self.partner[~self.matched] = -1

    def _contour_candidates(self, un, closed, target_closed, n):
        midx = np.flatnonzero(self.matched)
        pos = np.searchsorted(midx, un)  # next matched index after each unmatched node
        groups = []
        by_key: dict[tuple[int, int], list[int]] = {}
        carry_nodes, carry_from = [], []
        for b, p in zip(un, pos, strict=True):
            if closed:
                a, c = midx[p - 1], midx[p % len(midx)]  # cyclic neighbours
            else:
                a = midx[p - 1] if p > 0 else -1
                c = midx[p] if p < len(midx) else -1
                if a < 0 or c < 0:  # an end of an open contour: move with the neighbour
                    carry_nodes.append(b)
                    carry_from.append(c if a < 0 else a)
                    continue
            by_key.setdefault((a, c), []).append(b)
        for (a, c), nodes in by_key.items():
            if self.rule == "arclength":
                groups.append(("fixed", *self._along(a, c, np.asarray(nodes), target_closed)))
            else:
                cand = _between(self.partner[a], self.partner[c], n, target_closed,
                                self._way(self.partner[a], self.partner[c], n))
                groups.append(("mean", np.asarray(nodes), cand))
        if carry_nodes and self.rule == "arclength" and not target_closed:
            groups += self._ends(np.asarray(carry_nodes), midx)
            carry_nodes = []
        if carry_nodes:
            groups.append(("carry", np.asarray(carry_nodes), np.asarray(carry_from)[:, None]))
        return groups

    def _flatten(self):
        """Flat (node, candidate) lists of the (20) groups, and the fixed targets of the
        nodes that move with their matched neighbours (they depend on the source only)."""
        # small groups go through one vectorised pass, large ones (long unmatched runs)
        # one by one, which keeps their (nodes x candidates) work in dense blocks
        mean = [(nodes, cand) for kind, nodes, cand in self._groups
                if kind == "mean" and len(nodes) * len(cand) <= _SMALL_GROUP]
        self._large = [(nodes, cand) for kind, nodes, cand in self._groups
                       if kind == "mean" and len(nodes) * len(cand) > _SMALL_GROUP]
        node_of = [np.repeat(nodes, len(cand)) for nodes, cand in mean]
        cand_of = [np.tile(cand, len(nodes)) for nodes, cand in mean]
        self._node_of = np.concatenate(node_of) if mean else np.zeros(0, np.intp)
        self._cand_of = np.concatenate(cand_of) if mean else np.zeros(0, np.intp)
        self._mean_nodes, self._seg = np.unique(self._node_of, return_inverse=True)
        self._fixed = []
        for kind, nodes, cand in self._groups:
            if kind == "fixed":  # arclength rule: cand holds the targets themselves
                self._fixed.append((nodes, cand))
            elif kind == "carry":  # where the matched neighbours' displacements take the node
                disp = self.target[self.partner[cand]] - self.source[cand]  # (b, k, d)
                self._fixed.append((nodes, self.source[nodes] + self._carried(nodes, cand,
                                                                              disp)))

    def _carried(self, nodes: np.ndarray, cand: np.ndarray, disp: np.ndarray) -> np.ndarray:
        """The displacement (b, d) of ``nodes`` carried by their matched neighbours
        ``cand`` (b, k), whose displacements are ``disp`` (b, k, d): in 3D, of 4 or more,
        their affine fit (a turn's or a stretch's displacement carried exactly: the mean
        (20) left the nodes of an icosphere of 642 vertices morphed onto one of 162,
        turned 43 deg, 1.3 % of the size off its surface, method.md §5); else (20)."""
        near = self.source[cand]
        D = np.linalg.norm(self.source[nodes, None, :] - near, axis=2)
        if self.source.shape[1] != 3 or cand.shape[1] < 4:
            return _weighted_mean(D, disp)
        w = affine_fit_weights(near, self.source[nodes],
                               np.maximum(D.mean(axis=1), np.finfo(float).tiny))
        return np.einsum("bk,bkd->bd", w, disp)

    def _ends(self, nodes: np.ndarray, midx: np.ndarray) -> list:
        """Arclength rule at the ends of an open contour onto an open target: the nodes
        before the first matched node (after the last) laid along the target from its
        own end (the one the order of the partners points to) to that node's partner."""
        n = len(self.target)
        forward = self.partner[midx[-1]] >= self.partner[midx[0]]
        groups = []
        for inner, run, end in ((midx[0], nodes[nodes < midx[0]], 0 if forward else n - 1),
                                (midx[-1], nodes[nodes > midx[-1]], n - 1 if forward else 0)):
            if not run.size:
                continue
            run = run[np.argsort(np.abs(run - inner))]  # outwards from the matched node
            p2 = self.partner[inner]
            path = self.target[np.arange(p2, end + 1) if end >= p2 else
                               np.arange(p2, end - 1, -1)]
            t, s = _fractions(self.source[np.r_[inner, run]])[1:], _fractions(path)
            groups.append(("fixed", run, np.column_stack(
                [np.interp(t, s, path[:, k]) for k in range(path.shape[1])])))
        return groups

    def _way(self, a2: int, c2: int, n: int) -> int:
        """The way from partner ``a2`` to ``c2`` round a closed target of ``n`` nodes:
        :attr:`turn`, unless a stretch that way holds another matched node's partner (a
        local inversion of the pairs, which the long way round would average the whole
        target over), then 0 (the shorter way)."""
        if self.turn == 0:
            return 0
        start, length = (a2, (c2 - a2) % n) if self.turn > 0 else (c2, (a2 - c2) % n)
        if self._sorted is None:  # the matched partners, sorted, once (after the releases)
            self._sorted = sorted(set(self.partner[self.matched].tolist()))
        after = self._sorted[bisect_right(self._sorted, start) % len(self._sorted)]
        return 0 if 0 < (after - start) % n < length else self.turn

    def _along(self, a: int, c: int, nodes: np.ndarray, target_closed: bool):
        """Arclength rule: the unmatched ``nodes`` between matched ``a`` and ``c`` laid
        along the target from ``a'`` to ``c'`` at their fractions of the source's arc
        length from ``a`` to ``c``. Returns the nodes and their targets (b, d)."""
        m, n = len(self.source), len(self.target)
        nodes = nodes[np.argsort((nodes - a) % m)]  # in order from a (cyclic)
        t = _fractions(self.source[np.concatenate(([a], nodes, [c]))])[1:-1]
        a2, c2 = self.partner[a], self.partner[c]
        if target_closed:
            fwd, bwd = (c2 - a2) % n, (a2 - c2) % n
            if a == c:  # one matched node: round the whole target, the source's way
                fwd = bwd = n
            ahead = _forward(fwd, bwd, self._way(a2, c2, n))
            path = (a2 + np.arange(fwd + 1)) % n if ahead else (a2 - np.arange(bwd + 1)) % n
        else:
            path = np.arange(a2, c2 + 1) if a2 <= c2 else np.arange(a2, c2 - 1, -1)
        pts = self.target[path]
        s = _fractions(pts)
        return nodes, np.column_stack([np.interp(t, s, pts[:, k]) for k in range(pts.shape[1])])

    def targets(self, current: np.ndarray) -> np.ndarray:
        """Target position of every node for the current shape ``current`` (m, d)."""
        out = current.copy()
        out[self.matched] = self.target[self.partner[self.matched]]  # (19)
        if self._node_of.size:  # (20), weights D_tot - D normalised to 1, all groups at once
            seg, k = self._seg, len(self._mean_nodes)
            pts = self.target[self._cand_of]
            D = np.linalg.norm(current[self._node_of] - pts, axis=1)
            w = np.bincount(seg, D, k)[seg] - D
            total = np.bincount(seg, w, k)[seg]
            count = np.bincount(seg, minlength=k)[seg]
            w = np.where(total > 0, w / np.where(total > 0, total, 1), 1.0 / count)
            out[self._mean_nodes] = np.column_stack(
                [np.bincount(seg, w * pts[:, a], k) for a in range(pts.shape[1])])
        for nodes, cand in self._large:
            pts = self.target[cand]  # (c, d)
            D = np.linalg.norm(current[nodes, None, :] - pts[None], axis=2)  # (b, c)
            out[nodes] = _weighted_mean(D, pts[None])
        for nodes, fixed in self._fixed:
            out[nodes] = fixed
        return out


def contour_partners(contour_of_a: np.ndarray, contour_of_b: np.ndarray,
                     pairs: np.ndarray) -> np.ndarray:
    """Partner contours (P, 2) of two objects from their node pairs (K, 2), given the
    contour of every node (``Shape.contour_of``): the assignment that keeps the most
    pairs (each source contour with the target contour it shares most pairs with);
    contours sharing no pair stay unpaired."""
    votes = np.zeros((int(contour_of_a.max()) + 1, int(contour_of_b.max()) + 1))
    np.add.at(votes, (contour_of_a[pairs[:, 0]], contour_of_b[pairs[:, 1]]), 1.0)
    r, c = linear_sum_assignment(votes, maximize=True)
    keep = votes[r, c] > 0
    return np.c_[r[keep], c[keep]].astype(np.intp)


class ContourLoads:
    """:class:`LoadTargets` of objects of several contours: each source contour pulled
    onto its partner target contour alone, by the pairs that join them and the rule for
    unmatched nodes along that contour; the nodes of a source contour without a partner
    (or without a pair) move with the ``CARRIERS`` nearest matched nodes of the source
    (the (20)-weighted mean of their displacements, as in 3D).

    Parameters
    ----------
    source, target : ndarray, shape (m, d) and (n, d)
        Nodes in one common frame.
    pairs : ndarray of int, shape (K, 2)
        Matched (source, target) indices (pairs joining non-partners are not pulled).
    slices : tuple of (list of slice, list of slice)
        The rows of each source and each target contour.
    partners : ndarray of int, shape (P, 2)
        ``(source contour, target contour)`` partners.
    closed : tuple of bool
        Whether the source and the target contours are closed.
    rule : {"arclength", "mean"}
        The rule for unmatched nodes along a contour.
    """

    def __init__(self, source, target, pairs, *, slices, partners, closed, rule):
        rows, cols = slices
        self.source, self.target = source, target
        self.parts = []  # (source rows, target rows, LoadTargets)
        for k, j in partners:
            rk, rj = rows[k], cols[j]
            inside = ((pairs[:, 0] >= rk.start) & (pairs[:, 0] < rk.stop)
                      & (pairs[:, 1] >= rj.start) & (pairs[:, 1] < rj.stop))
            if inside.any():
                local = pairs[inside] - [rk.start, rj.start]
                self.parts.append((rk, rj, LoadTargets(
                    source[rk], target[rj], local, ordered=True, closed=closed, rule=rule)))
        if not self.parts:
            raise ValueError("no pair joins partner contours: nothing pulls the source")
        self.partners = np.array([[rows.index(rk), cols.index(rj)]
                                  for rk, rj, _ in self.parts], dtype=np.intp)
        pulled = self.pairs
        free = np.ones(len(source), bool)
        for rk, _, _ in self.parts:
            free[rk] = False
        self.carried = np.flatnonzero(free)
        self._carry = None
        if self.carried.size:
            k = min(CARRIERS, len(pulled))
            dist, near = cKDTree(source[pulled[:, 0]]).query(source[self.carried], k=k)
            dist, near = np.reshape(dist, (-1, k)), np.reshape(near, (-1, k))
            disp = target[pulled[near, 1]] - source[pulled[near, 0]]  # (b, k, d)
            self._carry = source[self.carried] + _weighted_mean(dist, disp)

    @property
    def pairs(self) -> np.ndarray:
        """The (source, target) pairs pulled to each other by (19), (K', 2), in the rows of
        the whole objects."""
        return np.vstack([lt.pairs + [rk.start, rj.start] for rk, rj, lt in self.parts])

    def targets(self, current: np.ndarray) -> np.ndarray:
        """Target position of every node for the current shape ``current`` (m, d)."""
        out = current.copy()
        for rk, _, lt in self.parts:
            out[rk] = lt.targets(current[rk])
        if self._carry is not None:
            out[self.carried] = self._carry
        return out


def _fractions(path: np.ndarray) -> np.ndarray:
    """Cumulative arc length along a polyline (k, d) as a fraction of its length, (k,)
    (evenly spaced when the polyline has no length)."""
    cum = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))))
    return cum / cum[-1] if cum[-1] > 0 else np.linspace(0.0, 1.0, len(path))


def _turn(partners: np.ndarray, n: int, closed: bool) -> int:
    """+1 where the partners of a contour's matched nodes (in the source's order) run
    forwards round a closed target of ``n`` nodes, -1 backwards, 0 where it is a tie (any
    two matched nodes of a closed source: their two stretches make one round either way;
    two of an open source half the target apart): the way each stretch between partners
    is taken. The shorter way, taken alone, runs a stretch of more than half the target
    backwards: the stem of a sans-serif 'i' (4 nodes) onto a serif one (10) laid its
    foot's nodes on the serif's top, 21.6 units off its foot."""
    if len(partners) < 2:
        return 0
    ahead = np.concatenate((partners[1:], partners[:1])) if closed else partners[1:]  # roll
    here = partners if closed else partners[:-1]
    fwd, bwd = int(np.sum((ahead - here) % n)), int(np.sum((here - ahead) % n))
    return int(np.sign(bwd - fwd))


def _orientation(points: np.ndarray) -> int:
    """+1 for a 2D closed contour that runs anticlockwise (its signed area, y up), -1
    clockwise, 0 in 3D: the way partners run when pairs do not tell (:func:`_turn`: one
    or two nodes matched)."""
    if points.shape[1] != 2:
        return 0
    x, y = points.T
    return int(np.sign(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y)))


def _span(a2, c2, n: int, turn: int):
    """Target segments from ``a2`` to ``c2`` round a closed target of ``n`` nodes, the way
    ``turn`` says (:func:`_turn`), or the shorter way where it is 0."""
    fwd, bwd = (c2 - a2) % n, (a2 - c2) % n
    return fwd if turn > 0 else bwd if turn < 0 else np.minimum(fwd, bwd)


def _forward(fwd: int, bwd: int, turn: int) -> bool:
    """Whether a stretch of ``fwd`` target segments forwards (``bwd`` backwards) is
    walked forwards: the way ``turn`` says, or the shorter way where it is 0."""
    return turn > 0 or (turn == 0 and fwd <= bwd)


def _between(a2: int, c2: int, n: int, closed: bool, turn: int = 0) -> np.ndarray:
    """Target indices strictly between a2 and c2 (on a closed contour the way ``turn``
    says, :func:`_turn`, or the shorter way where it is 0); the two ends themselves when
    none lies between."""
    if closed:
        fwd = (c2 - a2) % n
        bwd = (a2 - c2) % n
        idx = (a2 + np.arange(1, fwd)) % n if _forward(fwd, bwd, turn) else \
            (c2 + np.arange(1, bwd)) % n
    else:
        lo, hi = sorted((a2, c2))
        idx = np.arange(lo + 1, hi)
    return idx if idx.size else np.array(sorted({a2, c2}))


def _weighted_mean(D: np.ndarray, values: np.ndarray) -> np.ndarray:
    """(20) with weights ``D_tot - D`` normalised to 1 (uniform when they vanish)."""
    w = D.sum(axis=1, keepdims=True) - D
    total = w.sum(axis=1, keepdims=True)
    w = np.where(total > 0, w / np.where(total > 0, total, 1), 1.0 / D.shape[1])
    return np.einsum("bc,bcd->bd", w, np.broadcast_to(values, (*D.shape, values.shape[-1])))


def lifted(K: np.ndarray, lift: float) -> np.ndarray:
    """``K + lift I``, a copy: ``K``'s diagonal lifted (the same numbers as adding the
    identity, without forming it)."""
    out = K.copy()
    out.flat[::len(out) + 1] += lift
    return out


@dataclass(frozen=True)
class Newmark:
    """Newmark's method (14)-(15) for ``x'' + C x' + K x = f`` in modal coordinates.

    ``C`` and ``K`` are (n, n) matrices (diagonal for uncoupled modes); ``lift``: the
    stiffness is ``K + lift I`` (its diagonal lifted, the loaded model's consistent springs
    on the elastic stiffness, without an (n, n) copy of it). ``alpha`` and
    ``delta`` are Newmark's parameters (beta and gamma in most texts), refused outside the
    unconditionally stable range (:func:`check_newmark`). The coefficients of (15) and the
    Cholesky factor of the effective stiffness are computed once, at construction.

    Raises
    ------
    ValueError
        For a time step that is not a positive finite number, ``K`` and ``C`` not square
        and of one size, unstable ``alpha`` and ``delta``, or an effective stiffness that
        is not positive definite.
    """

    K: np.ndarray
    C: np.ndarray
    dt: float
    alpha: float = 0.25
    delta: float = 0.5
    lift: float = 0.0
    # a0 .. a5 of (15), from alpha, delta and dt
    coefficients: tuple = field(init=False, repr=False, compare=False)
    # the Cholesky factor (lower) of K + a0 I + a1 C, the left side of (15)
    factor: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        if not (np.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"Newmark's time step must be a positive finite number, got "
                             f"dt={self.dt!r}")
        n = self.K.shape[0]
        if self.K.shape != (n, n) or self.C.shape != (n, n):
            raise ValueError(f"Newmark's K and C must be square and of one size, got "
                             f"{self.K.shape} and {self.C.shape}")
        check_newmark(self.alpha, self.delta)
        al, de, dt = self.alpha, self.delta, self.dt
        a0, a1 = 1.0 / (al * dt**2), de / (al * dt)
        a2, a3 = 1 / (al * dt), 1 / (2 * al) - 1
        a4, a5 = de / al - 1, dt / 2 * (de / al - 2)
        object.__setattr__(self, "coefficients", (a0, a1, a2, a3, a4, a5))
        # left side of (15), (K + a0 I) + a1 C in that order, made in one (n, n) array:
        # a1 C + K off the diagonal (the same sums), the diagonal redone in that order
        K_eff = np.multiply(a1, self.C, order="F")
        K_eff += self.K
        K_eff.flat[::n + 1] = (self.diagonal() + a0) + a1 * np.diagonal(self.C)
        # K_eff is SPD and well conditioned (a0 I dominates for small steps): factorised
        # once, each step solves with the factor (two triangular solves, as cheap as a
        # product with an inverse; forming the inverse cost 2x the factor at 500 modes)
        L, info = lapack.dpotrf(K_eff, lower=1, overwrite_a=1)
        if info != 0:
            raise ValueError("Newmark's effective stiffness is not positive definite: "
                             "check the damping and the time step")
        object.__setattr__(self, "factor", L)

    def diagonal(self) -> np.ndarray:
        """The stiffness's diagonal, ``K``'s lifted: ``diag(K) + lift``."""
        return np.diagonal(self.K) + self.lift

    def stiffness_dot(self, x: np.ndarray) -> np.ndarray:
        """``(K + lift I) x``: bitwise the product with the lifted matrix, which is formed
        (a copy) only for a lift and an ``x`` not all zero (then every product is a zero
        of the same sign, the diagonal's positive either way)."""
        if not self.lift or not np.any(x):
            return self.K @ x
        return lifted(self.K, self.lift) @ x

    def step(self, x, v, a, f):
        """One step: state (x, v, a) at t and load f at t + dt -> state at t + dt."""
        a0, a1, a2, a3, a4, a5 = self.coefficients
        rhs = f + (a0 * x + a2 * v + a3 * a) + self.C @ (a1 * x + a4 * v + a5 * a)  # (15)
        x1 = lapack.dpotrs(self.factor, rhs, lower=1)[0]
        a_new = a0 * (x1 - x) - a2 * v - a3 * a
        de, dt = self.delta, self.dt
        v1 = v + dt * ((1 - de) * a + de * a_new)  # (14)
        return x1, v1, a_new
