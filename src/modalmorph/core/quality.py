"""Quality measures of a morph: distances between curves, self-crossings, roughness and
the rotation a correspondence implies.

These measure a result (the matcher uses only :func:`area`, to refuse a flat contour). They
are fast enough to run on every time step of a morph (see ``benchmarks/realdata.py``).
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.spatial import cKDTree

from ..errors import ShapeError
from .align import align
from .shape import check_once, resample

__all__ = ["Polyline", "area", "check_contours", "correspondence_rotation",
           "curve_distances", "roughness", "self_crossings", "crossing_segments", "LOOP_AREA",
           "check_simple", "check_flat", "FLAT", "step_crossings", "knot_count", "LOOP_LENGTH",
           "KNOT_SLACK"]

# Vertices whose segments curve_distances tests first (4: 2.5x faster than 8; method.md §5).
_K_NEAREST = 4
# roughness: resampled to this many nodes, smoothed over _ROUGH_SIGMA spacings (method.md §5).
_ROUGH_NODES = 512
_ROUGH_SIGMA = 4.0
# Pairs of segments tested at once in self_crossings (memory: ~50 bytes a pair).
_CHUNK = 1_000_000


def _points(points, name: str, dims=(2, 3)) -> np.ndarray:
    p = np.asarray(getattr(points, "points", points), dtype=np.float64)
    if p.ndim != 2 or p.shape[1] not in dims or len(p) < 2:
        want = " or ".join(f"(m, {d})" for d in dims)
        raise ValueError(f"{name} must have shape {want} with m >= 2, got {p.shape}")
    if not np.isfinite(p).all():
        raise ValueError(f"{name} must be finite (no NaN or inf)")
    return p


def area(points) -> float:
    """Signed shoelace area of a closed polygon (m, 2): positive when its nodes run
    counter-clockwise in its axes."""
    x, y = _points(points, "points", dims=(2,)).T
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from points ``p`` to segments ``a``-``b`` (broadcast over leading axes)."""
    ab = b - a  # np.sum and np.linalg.norm's numbers, by the ufuncs they call
    den = np.add.reduce(ab * ab, axis=-1)
    t = np.add.reduce((p - a) * ab, axis=-1) / np.where(den > 0, den, 1.0)
    t = np.clip(t, 0.0, 1.0)[..., None]
    r = p - (a + t * ab)
    return np.sqrt(np.add.reduce(r * r, axis=-1))


class Polyline:
    """A polyline (n, d) ready for repeated distance queries (its k-d tree built once).

    Parameters
    ----------
    points : ndarray, shape (n, d)
    closed : bool
        Whether the last node connects back to the first.
    """

    def __init__(self, points: np.ndarray, closed: bool):
        self.points = points
        n = len(points)
        self.n_seg = n if closed else n - 1
        self.closed = closed
        self.end = np.concatenate([points[1:], points[:1]])  # segment j: node j to j + 1
        self.reach2 = 0.25 * float(np.maximum.reduce(np.add.reduce(
            (self.end[:self.n_seg] - points[:self.n_seg]) ** 2, axis=1)))
        self.tree = cKDTree(points)

    def distance(self, p: np.ndarray) -> np.ndarray:
        """Exact distance from every row of ``p`` to the polyline."""
        n, n_seg, start, end = len(self.points), self.n_seg, self.points, self.end
        k = min(_K_NEAREST, n)
        r, idx = self.tree.query(p, k=k)
        r, idx = r.reshape(len(p), k), idx.reshape(len(p), k)
        # the segments on either side of each of the k nearest vertices
        seg = np.concatenate([idx, idx - 1], axis=1)
        if self.closed:  # every segment index valid
            seg %= n
            best = _segment_distance(p[:, None, :], start[seg], end[seg]).min(axis=1)
        else:
            valid = (seg >= 0) & (seg < n_seg)
            seg = np.where(valid, seg, 0)
            d = _segment_distance(p[:, None, :], start[seg], end[seg])
            best = np.where(valid, d, np.inf).min(axis=1)
        # Exactness: the nearest point q of the polyline lies on a segment of length
        # L <= L_max. If q is inside it, p - q is perpendicular to it, so the nearer end e
        # has |p - e|^2 = |p - q|^2 + |q - e|^2 <= best^2 + L_max^2 / 4 (q at an end:
        # |p - e| = |p - q| <= best). If the k-th nearest vertex is farther than that, e
        # is among the k tested; otherwise test every segment with an end in that ball.
        reach = np.sqrt(best**2 + self.reach2)
        unsure = np.flatnonzero((k < n) & (r[:, -1] <= reach))
        if len(unsure):
            near = self.tree.query_ball_point(p[unsure], reach[unsure], return_sorted=False)
            count = np.fromiter(map(len, near), dtype=np.intp, count=len(unsure))
            vert = np.concatenate(near).astype(np.intp)
            seg = np.concatenate([vert, vert - 1])  # both segments at each vertex
            row = np.concatenate([np.repeat(unsure, count)] * 2)
            if self.closed:
                seg %= n
            ok = (seg >= 0) & (seg < n_seg)
            row, seg = row[ok], seg[ok]
            np.minimum.at(best, row, _segment_distance(p[row], start[seg], end[seg]))
        return best


def curve_distances(a, b, *, closed_a: bool = True, closed_b: bool = True,
                    ordered: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Distances from each node of one curve to the other curve, both ways.

    Parameters
    ----------
    a, b : array_like or Shape, shape (m, d) and (n, d)
        Ordered contours (2D) or polylines (3D), or point clouds when ``ordered=False``.
    closed_a, closed_b : bool, optional
        Whether the polyline through ``a`` (``b``) has the closing segment.
    ordered : bool, optional
        ``True``: distances to the polyline through the other nodes (its segments).
        ``False``: to the nearest node of the other set.

    Returns
    -------
    d_ab : ndarray, shape (m,)
        Distance from each node of ``a`` to ``b``.
    d_ba : ndarray, shape (n,)
        Distance from each node of ``b`` to ``a``.

    Notes
    -----
    Exact, not approximate. A k-d tree gives the ``k`` nearest vertices of the other curve
    and the segments on either side of them are measured exactly; call the smallest
    distance ``D``. The nearest point ``q`` of the polyline lies on some segment of length
    ``L <= L_max``, within ``L/2`` of its nearer end ``e``; when ``q`` is inside the
    segment the node-to-``q`` line is perpendicular to it, so ``|node - e|^2 <= D^2 +
    L_max^2/4``. When the ``k``-th nearest vertex lies farther than that, the segment is
    among those measured; for the few nodes where it does not (long segments next to short
    ones, sharp turns), every segment with an end in that ball is measured. Cost
    ``O((m + n) log n)`` for evenly sampled curves.
    """
    pa, pb = _points(a, "a"), _points(b, "b")
    if pa.shape[1] != pb.shape[1]:
        raise ValueError(f"a and b must have the same dimension, got {pa.shape[1]} and "
                         f"{pb.shape[1]}")
    if not ordered:
        return cKDTree(pb).query(pa)[0], cKDTree(pa).query(pb)[0]
    return Polyline(pb, closed_b).distance(pa), Polyline(pa, closed_a).distance(pb)


def _candidate_pairs(lo: np.ndarray, hi: np.ndarray):
    """Pairs (i, j), i < j in x-order, whose x-extents [lo, hi] overlap, in chunks."""
    order = np.argsort(lo, kind="stable")
    lo_s, hi_s = lo[order], hi[order]
    stop = np.searchsorted(lo_s, hi_s, side="right")  # j < stop[i]: lo_j <= hi_i
    count = np.maximum(stop - np.arange(len(lo)) - 1, 0)
    cum = np.cumsum(count)
    first = 0
    while first < len(lo):
        last = int(np.searchsorted(cum, cum[first] - count[first] + _CHUNK, side="right"))
        last = min(max(last, first + 1), len(lo))
        i = np.repeat(np.arange(first, last), count[first:last])
        offset = np.arange(len(i)) - np.repeat(cum[first:last] - count[first:last]
                                               - (cum[first] - count[first]),
                                               count[first:last])
        yield order[i], order[i + 1 + offset]
        first = last


def self_crossings(points, closed: bool = True) -> int:
    """Number of pairs of non-adjacent segments of a 2D polyline that properly cross
    (the length of :func:`crossing_segments`).

    Parameters
    ----------
    points : array_like or Shape, shape (m, 2)
        Ordered nodes of a contour.
    closed : bool, optional
        Whether the segment from the last node to the first belongs to the polyline.

    Returns
    -------
    int
        0 for a simple polygon, 1 for a figure eight, ``n (k - 1)`` for the star polygon
        ``{n/k}``. Segments that share a node never count; two segments count when each
        one's ends lie strictly on opposite sides of the other's line, so a node that lies
        exactly on another segment (a touch, or a collinear overlap) is not counted.

    Notes
    -----
    Candidate pairs are those whose x-extents overlap (sweep over segments sorted by their
    left end, :func:`numpy.searchsorted`), filtered by their y-extents, then tested with the
    orientation signs. A 2000-node hand has 11 000 candidate pairs (of 2 million) and
    takes 0.4 ms.
    """
    return len(crossing_segments(points, closed))


def crossing_segments(points, closed: bool = True, *, edges=None) -> np.ndarray:
    """The pairs of segments of a 2D polyline that properly cross, (c, 2) of int, each row
    ``(i, j)`` with ``i < j`` for the segments from node ``i`` to ``i + 1`` and from ``j``
    to ``j + 1`` (modulo ``m`` when closed); see :func:`self_crossings`. With ``edges``
    (e, 2) (a :attr:`Shape.edges` of several contours), the segments are those rows and
    ``i``, ``j`` index them; segments sharing a node never count as crossing."""
    p = _points(points, "points", dims=(2,))
    m = len(p)
    if edges is None:
        i = np.arange(m if closed else m - 1)
        edges = np.stack([i, (i + 1) % m], axis=1)
    edges = np.asarray(edges, dtype=np.intp)
    a, b = p[edges[:, 0]], p[edges[:, 1]]
    lo_x, hi_x = np.minimum(a[:, 0], b[:, 0]), np.maximum(a[:, 0], b[:, 0])
    lo_y, hi_y = np.minimum(a[:, 1], b[:, 1]), np.maximum(a[:, 1], b[:, 1])

    def orient(o, q, r):  # sign of the turn o -> q -> r
        return np.sign((q[:, 0] - o[:, 0]) * (r[:, 1] - o[:, 1])
                       - (q[:, 1] - o[:, 1]) * (r[:, 0] - o[:, 0]))

    found = []
    for i, j in _candidate_pairs(lo_x, hi_x):
        shared = ((edges[i, 0] == edges[j, 0]) | (edges[i, 0] == edges[j, 1])
                  | (edges[i, 1] == edges[j, 0]) | (edges[i, 1] == edges[j, 1]))
        keep = (i != j) & ~shared & (lo_y[i] <= hi_y[j]) & (lo_y[j] <= hi_y[i])
        i, j = i[keep], j[keep]
        cross = ((orient(a[i], b[i], a[j]) * orient(a[i], b[i], b[j]) < 0)
                 & (orient(a[j], b[j], a[i]) * orient(a[j], b[j], b[i]) < 0))
        if cross.any():  # most contours cross nowhere: no sort, no unique (15 us at 70 nodes)
            found.append(np.sort(np.c_[i[cross], j[cross]], axis=1))
    return np.unique(np.vstack(found), axis=0).astype(np.intp) if found else \
        np.empty((0, 2), dtype=np.intp)


# Loops above this x size^2 make a contour not simple (hands' noise < 4e-5; method.md §5).
LOOP_AREA = 1e-3
# So do loops longer than this x the RMS radius (the hands' knots at most 0.073, their
# node spacing 0.01; a figure eight's lobe ~3).
LOOP_LENGTH = 0.2
# A step of a morph between inputs carrying k knots of noise's size as given carries up to
# this x k such loops before they count as folds (the 56 morphs between the shared hands:
# at most 1.33 x the two inputs' knots at any step).
KNOT_SLACK = 2
# Nodes whose spread across their principal line is at most this x their spread along it
# lie on one line (rounding of a straight line's nodes: ~1e-14; the thinnest glyph outline
# of 15 thin characters in six fonts, cmr10's bar: 0.026).
FLAT = 1e-9


def check_flat(points, name: str) -> None:
    """Refuse a closed 2D contour whose nodes lie on one line: it encloses no area, and
    resampled it doubles back over itself."""
    p = np.asarray(points, dtype=np.float64)
    spread = np.linalg.svd(p - p.mean(axis=0), compute_uv=False)
    if not spread[-1] > FLAT * spread[0]:
        raise ShapeError(f"{name}: a closed contour with no area (its nodes lie on one "
                         "line): a closed contour must enclose an area; for an open curve "
                         "pass Shape(points, closed=False), or read the file with "
                         "open_curves=True")


def check_simple(points, name: str, closed: bool = True) -> None:
    """Refuse a 2D contour that crosses itself beyond tiny loops (a figure eight, a star):
    :class:`~modalmorph.errors.ShapeError` names the first two crossing segments and
    where they cross; and a closed one with no area (:func:`check_flat`). Loops enclosing
    at most :data:`LOOP_AREA` times the squared RMS radius (the tracing noise of real
    outlines) are accepted."""
    p = _points(points, name, dims=(2,))
    m = len(p)
    for i, j, x in _folds(p, crossing_segments(p, closed), closed):
        raise ShapeError(
            f"{name} crosses itself: the segment from node {i} to {(i + 1) % m} crosses "
            f"the one from node {j} to {(j + 1) % m} at ({x[0]:.4g}, {x[1]:.4g}); a "
            "contour must be one simple closed curve (a figure eight or a star is not)")
    if closed:
        check_flat(p, name)


def _folds(p: np.ndarray, pairs: np.ndarray, closed: bool):
    """The crossing segment pairs ``(i, j)`` of the contour ``p`` (rows of
    :func:`crossing_segments`) whose smaller loop is more than tracing noise: encloses
    more than :data:`LOOP_AREA` times the squared RMS radius, or runs longer than
    :data:`LOOP_LENGTH` times it (a thin sliver, or lobes of opposite turn whose areas
    cancel), each with where they cross: ``(i, j, x)``."""
    m, scale = len(p), np.mean(np.sum((p - p.mean(axis=0)) ** 2, axis=1))
    run = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(p, axis=0, append=p[:1]), axis=1))]
    for i, j in pairs:
        a, b, c, e = p[i], p[(i + 1) % m], p[j], p[(j + 1) % m]
        u, den = b - a, (b[0] - a[0]) * (e[1] - c[1]) - (b[1] - a[1]) * (e[0] - c[0])
        s = ((c[0] - a[0]) * (e[1] - c[1]) - (c[1] - a[1]) * (e[0] - c[0])) / den \
            if den else 0.5  # den = 0: nearly collinear nodes of a flat outline
        x = a + s * u  # where segments i and j cross
        inner = run[j] - run[i + 1]  # the path from node i + 1 to node j
        length = min(inner, run[-1] - inner if closed else np.inf)
        inside = np.vstack([x, p[i + 1:j + 1]])
        outside = np.vstack([x, p[j + 1:], p[:i + 1]])
        loop = min(abs(area(inside)), abs(area(outside)) if closed else np.inf)
        if loop > LOOP_AREA * scale or length > LOOP_LENGTH * np.sqrt(scale):
            yield int(i), int(j), x


def check_contours(shape, name: str) -> None:
    """:func:`check_simple` on every contour of a 2D ordered :class:`Shape`, and no
    contour crossing another (a ring's hole must stay inside it): ShapeError naming the
    two contours and where they cross. Checked once for the same points and topology
    (:func:`~modalmorph.core.shape.check_once`: a morph after a match of one pair)."""
    check_once("contours", shape.points, lambda: _check_contours(shape, name),
               shape.closed, shape.contours)


def crossed_contours(shape) -> tuple[list[int], list[tuple[int, int]]]:
    """What :func:`check_contours` refuses in a 2D ordered :class:`Shape`: the contours
    that cross themselves beyond tiny loops, and the pairs of contours that cross."""
    own = [k for k, rows in enumerate(shape.slices)
           if next(_folds(shape.points[rows], crossing_segments(shape.points[rows],
                                                                shape.closed),
                          shape.closed), None) is not None]
    both = set()
    if len(shape.sizes) > 1:
        part = shape.contour_of[shape.edges[:, 0]]
        both = {(int(part[i]), int(part[j])) for i, j in
                crossing_segments(shape.points, edges=shape.edges) if part[i] != part[j]}
    return own, sorted(both)


def _check_contours(shape, name: str) -> None:
    if len(shape.sizes) == 1:
        check_simple(shape.points, name, shape.closed)
        return
    for k, rows in enumerate(shape.slices):
        check_simple(shape.points[rows], f"{name} contour {k}", shape.closed)
    edges, part = shape.edges, shape.contour_of[shape.edges[:, 0]]
    for i, j in crossing_segments(shape.points, edges=edges):
        if part[i] != part[j]:
            x = shape.points[edges[i, 0]]
            raise ShapeError(f"{name}: contour {part[i]} crosses contour {part[j]} near "
                             f"({x[0]:.4g}, {x[1]:.4g}); contours of one shape must not "
                             "cross (a hole lies inside its outer boundary)")


def step_crossings(shapes, shape, inputs: tuple = ()) -> np.ndarray:
    """The folds of a 2D ordered :class:`Shape`'s topology on the nodes of every step,
    shape (T+1,), int: the pairs of segments that cross (:func:`crossing_segments`)
    between two contours or, within one, closing a loop larger than tracing noise
    (:func:`check_simple`'s), and the loops of noise's size beyond :data:`KNOT_SLACK`
    times those the 2D contours ``inputs`` carry as given (:func:`knot_count`, counted
    only where a step crosses: the shared hands 9-17 each, which every step of a morph
    between two of them carries, some of both); on inputs with none, every loop is a
    fold (two nodes swapped).

    Up to :data:`_SWEPT_TOGETHER` segments, the crossings of the steps are found
    together, :data:`_STEP_SEGMENTS` segments at a time (the same candidate pairs and
    tests as :func:`crossing_segments`, which runs once a step above); one pass over the
    segment pairs that overlap at any step instead took 24 ms at 250 nodes and 4 s at
    1000 for a half turn, which sweeps the shape over itself."""
    edges = np.asarray(shape.edges, dtype=np.intp)
    if len(edges) > _SWEPT_TOGETHER:
        crossed = np.array([len(crossing_segments(points, edges=edges)) for points in shapes],
                           dtype=np.int64)
    else:
        p = np.asarray(shapes, dtype=np.float64)
        per = max(1, _STEP_SEGMENTS // max(len(edges), 1))  # steps swept together
        crossed = np.concatenate([_steps_crossed(p[s:s + per], edges)
                                  for s in range(0, len(p), per)] or [np.zeros(0, np.int64)])
    knots = None
    for t in np.flatnonzero(crossed):  # which crossings are folds (most steps have none)
        big, tiny = _fold_count(shapes[t], shape, crossing_segments(shapes[t], edges=edges))
        if knots is None:
            knots = sum(knot_count(s) for s in inputs if s.dim == 2 and s.ordered)
        crossed[t] = big + max(0, tiny - KNOT_SLACK * knots)
    return crossed


def knot_count(shape) -> int:
    """The loops of tracing noise's size a 2D ordered :class:`Shape` carries as given
    (crossings that :func:`check_simple` accepts)."""
    big, tiny = _fold_count(shape.points, shape,
                            crossing_segments(shape.points, edges=shape.edges))
    return tiny


def _fold_count(points: np.ndarray, shape, pairs: np.ndarray) -> tuple[int, int]:
    """Of the crossing segment pairs ``pairs`` (rows of ``shape.edges``) of the nodes
    ``points``: how many are folds (between contours, or loops larger than noise) and
    how many loops of noise's size (:func:`step_crossings`)."""
    if not len(pairs):
        return 0, 0
    starts = shape.edges[:, 0]
    part = shape.contour_of[starts]
    between = part[pairs[:, 0]] != part[pairs[:, 1]]
    big = int(between.sum())
    for k in np.unique(part[pairs[~between, 0]]):
        rows = shape.slices[k]
        within = pairs[~between & (part[pairs[:, 0]] == k)]
        local = np.sort(starts[within] - rows.start, axis=1)
        big += sum(1 for _ in _folds(points[rows], local, shape.closed))
    return big, len(pairs) - big


# step_crossings sweeps the steps together up to this many segments, this many segments
# x steps at a time: a heart pair's straight path, one thread, against one
# crossing_segments a step: 70 nodes, 6 steps 0.38 -> 0.09 ms; 250, 12 steps 0.95 ->
# 0.32; 500, 15 steps 1.49 -> 0.94; 700 nodes 1.67 -> 1.46; 1000 nodes 2.9 -> 2.8-3.7
# (batches of 4000: 0.5-3.7 ms, of 20 000: 5.8 ms): above, a step at a time. With at
# most 600 a step, 6 steps of every pair overlapping (a horizontal zigzag) are ~1 million
# candidates, crossing_segments' _CHUNK.
_SWEPT_TOGETHER, _STEP_SEGMENTS = 600, 4000


def _steps_crossed(p: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """The crossing segment pairs of every step ``p`` (T, m, 2), counted (T,): each
    step's sweep over the segments sorted by their left end (the candidates of
    :func:`_candidate_pairs`, x-extents overlapping), done for all steps at once."""
    T, e = len(p), len(edges)
    a, b = p[:, edges[:, 0]], p[:, edges[:, 1]]  # (T, e, 2)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    order = np.argsort(lo[:, :, 0], axis=1, kind="stable")
    lo_s, hi_s = (np.take_along_axis(v[:, :, 0], order, axis=1) for v in (lo, hi))
    # stop[t, i]: how many left ends lo_s[t] <= hi_s[t, i] (searchsorted 'right'), from
    # one stable sort of both, left ends first among equal values
    merged = np.argsort(np.concatenate([lo_s, hi_s], axis=1), axis=1, kind="stable")
    lows = np.cumsum(merged < e, axis=1)
    stop = np.empty((T, e), dtype=np.intp)
    np.put_along_axis(stop, merged[merged >= e].reshape(T, e) - e,
                      lows[merged >= e].reshape(T, e), axis=1)
    count = np.maximum(stop - np.arange(e) - 1, 0).ravel()
    row = np.repeat(np.arange(T * e), count)  # (step, sorted position) of segment i
    offset = np.arange(len(row)) - np.repeat(np.cumsum(count) - count, count)
    t = row // e
    i, j = order.ravel()[row], order.ravel()[row + 1 + offset]
    e0, e1 = edges[:, 0], edges[:, 1]
    shared = (e0[i] == e0[j]) | (e0[i] == e1[j]) | (e1[i] == e0[j]) | (e1[i] == e1[j])
    keep = ~shared & (lo[t, i, 1] <= hi[t, j, 1]) & (lo[t, j, 1] <= hi[t, i, 1])
    t, i, j = t[keep], i[keep], j[keep]
    ai, bi, aj, bj = a[t, i], b[t, i], a[t, j], b[t, j]
    cross = ((_orient(ai, bi, aj) * _orient(ai, bi, bj) < 0)
             & (_orient(aj, bj, ai) * _orient(aj, bj, bi) < 0))
    return np.bincount(t[cross], minlength=T).astype(np.int64)


def _orient(o: np.ndarray, q: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Sign of the turn o -> q -> r (rows (n, 2)), as :func:`crossing_segments`'s."""
    return np.sign((q[:, 0] - o[:, 0]) * (r[:, 1] - o[:, 1])
                   - (q[:, 1] - o[:, 1]) * (r[:, 0] - o[:, 0]))


def roughness(points, closed: bool = True) -> float:
    """Small-scale wiggle of a contour or polyline, independent of its pose, size and
    node count.

    The curve is resampled to 512 nodes evenly spaced by arc length
    (:func:`modalmorph.core.shape.resample`) and smoothed along its length by a Gaussian of 4
    node spacings (0.8 % of the length; wrap-around for closed curves, point reflection
    about the end nodes for open ones). The roughness is the RMS distance between the
    resampled and the smoothed nodes divided by the RMS radius of the resampled nodes.

    Parameters
    ----------
    points : array_like or Shape, shape (m, d)
        Ordered nodes, ``d`` in {2, 3}.
    closed : bool, optional
        Whether the last node connects back to the first.

    Returns
    -------
    float
        >= 0. Smooth curvature contributes a little (a circle scores
        ``1 - exp(-(2 pi 4 / 512)^2 / 2) = 0.0024``), corners and noise more: a
        pixel-traced heart about 0.004, 1 % noise on a 200-node circle about 0.007.
    """
    p = _points(points, "points")
    if len(p) < 3:
        raise ValueError(f"points must have at least 3 nodes, got {len(p)}")
    x = resample(p, _ROUGH_NODES, closed=closed)
    if closed:
        smooth = gaussian_filter1d(x, _ROUGH_SIGMA, axis=0, mode="wrap")
    else:  # odd extension: a straight end stays straight
        w = int(4 * _ROUGH_SIGMA) + 1
        ext = np.vstack([2 * x[0] - x[w:0:-1], x, 2 * x[-1] - x[-2:-w - 2:-1]])
        smooth = gaussian_filter1d(ext, _ROUGH_SIGMA, axis=0, mode="nearest")[w:-w]
    radius = np.sqrt(np.mean(np.sum((x - x.mean(axis=0)) ** 2, axis=1)))
    if radius == 0:
        raise ValueError("points all coincide: roughness is undefined")
    return float(np.sqrt(np.mean(np.sum((x - smooth) ** 2, axis=1))) / radius)


def correspondence_rotation(source, target, pairs) -> float:
    """Rotation, in degrees, of the similarity that best maps paired source nodes onto
    their target partners (Horn, :func:`modalmorph.core.align`).

    Parameters
    ----------
    source, target : array_like or Shape, shape (m, d) and (n, d)
    pairs : array_like of int, shape (K, 2), or a Matching
        (source index, target index), ``K >= 2``.

    Returns
    -------
    float
        2D: the signed angle in (-180, 180], counter-clockwise positive (in the axes of the
        data). 3D: the rotation angle in [0, 180].
    """
    src, tgt = _points(source, "source"), _points(target, "target")
    pairs = np.asarray(getattr(pairs, "pairs", pairs))
    if pairs.ndim != 2 or pairs.shape[1] != 2 or not np.issubdtype(pairs.dtype, np.integer):
        raise ValueError(f"pairs must be an integer array of shape (K, 2), got "
                         f"{pairs.dtype} {pairs.shape}")
    sim = align(src[pairs[:, 0]], tgt[pairs[:, 1]], scale=True)
    if src.shape[1] == 2:
        R = sim.rotation
        angle = float(np.degrees(np.arctan2(R[1, 0], R[0, 0])))
        return 180.0 if angle <= -180.0 else angle
    return sim.angle
