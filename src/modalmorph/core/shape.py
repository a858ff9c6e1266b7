"""Shapes: ordered node sets in 2D or 3D, validated once at the boundary."""

from __future__ import annotations

import hashlib
import os
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from scipy.spatial import cKDTree

from ..errors import ShapeError
from .nearest import nearest_distances

__all__ = ["CURVE_DIMENSION", "CURVE_JUMP", "CURVE_STEP", "FPS_POOL", "FPS_TREE", "GRID_ROUNDS",
           "HUGE", "ImageFrame", "PASSED_KEPT", "Shape", "as_shape", "check_once", "check_pairs",
           "coarsen", "curve_dimension", "even_subset", "forget_checks", "resample",
           "resampled_counts", "share", "spread_indices", "traces_curve"]

# Two nodes closer than this fraction of the object's RMS radius are "the same node".
_REPEAT_TOL = 1e-9
# Coordinates beyond this magnitude are refused: sums of squared distances between such
# nodes (up to 1e6 of them) would overflow float64 (1.8e308): (2e150)^2 * 1e6 = 4e306.
MAX_COORDINATE = 1e150
# An object whose RMS radius is below this fraction of its coordinates' magnitude is a point.
_POINT_TOL = 1e-10
GRID_ROUNDS = 6  # cell sizes even_subset tries: within 10 % of m on icospheres (method.md §5)
HUGE = 200_000  # unordered sets above this: farthest points among an even_subset (§7)
# A 3D point set of estimated dimension below this is a curve, not a surface
# (curve_dimension: log 4 / log(r12 / r3), r_k the distance to the k-th nearest point,
# median over up to CURVE_SAMPLE points in order). Curves (an ellipse in z = 0, a helix,
# a noisy helix; 1000 and 10 000 points): 1.14-1.26; surfaces (7 meshes shipped with
# pymeshlab, a range scan's 85 849 points, even and uneven ellipsoids, discs, scan rows 3
# spacings apart; 100-85 849 points): 1.70-3.05. A helix of 100 points on three turns
# gives 2.05: at that sampling its neighbours span the next turns, as a surface's would.
CURVE_DIMENSION = 1.5
CURVE_SAMPLE = 4096
# Points in the order given trace one curve where their median step to the next point is
# at most CURVE_STEP times the median distance to the second nearest (in order 1.0; the
# points shuffled, steps across the whole object), and no step is longer than CURVE_JUMP
# times the median step: an ellipse, a helix, a noisy helix (100-10 000 points) 1.0-2.1;
# a stack of slice contours written one after another 6.5-8.1, raster rows 199. A curve
# sampled at random spacing (4.8-8.1) stays a point set (its stop test still a curve's).
CURVE_STEP, CURVE_JUMP = 1.5, 4.0
FPS_POOL = 20  # its candidates per point chosen (§7)
# Farthest points through a k-d tree above this many points (ellipsoid points, 3000 of
# 100 000: 6.6 -> 0.22 s; 1000 of 20 000: 0.57 -> 0.09 s; 400 of 2000: 32 -> 10 ms; 400 of
# 600: 10 -> 13 ms); the same points either way.
FPS_TREE = 1000
_BALL_MARGIN = 1.0 + 1e-9  # the ball's radius widened past rounding (relative)
# Checks passed that are remembered (check_once): the objects of a few calls (match then
# morph of one pair validate the same two; a pair's checks cost 0.3-0.5 ms at 70 nodes).
PASSED_KEPT = 32
_passed: dict = {}  # check_once's keys, the least recently used first
_passed_lock = threading.Lock()


def check_once(check: str, points: np.ndarray, run: Callable[[], None], *key) -> None:
    """Run ``run`` (a check of ``points`` that raises on invalid input) unless the check
    named ``check`` passed lately on the same numbers (and ``key``): a digest of the
    points' bytes identifies them, and the :data:`PASSED_KEPT` used most recently are
    kept. An input that fails is checked again every time (and its error names the
    caller's argument)."""
    pts = np.ascontiguousarray(points)
    k = (check, pts.dtype.str, pts.shape, key,
         hashlib.blake2b(pts.view(np.uint8), digest_size=16).digest())
    with _passed_lock:
        if k in _passed:
            _passed[k] = _passed.pop(k)  # the most recent last: the least recent goes
            return
    run()
    with _passed_lock:
        _passed[k] = None
        while len(_passed) > PASSED_KEPT:
            del _passed[next(iter(_passed))]


@dataclass(frozen=True)
class ImageFrame:
    """Image coordinates: where a shape's numbers come from, for drawing it.

    Shapes read from images and SVG (and the bundled real data, traced on images) have
    ``(x, y) = (column, row)`` in pixels, y pointing down; figures draw them that way, over
    the image when there is one.

    Attributes
    ----------
    unit : str
        Unit of the coordinates, for axis labels (``"px"``, ``"SVG user units"``).
    image : str or None
        The image file the shape was traced on (drawn under it), if any.
    size : (int, int) or None
        ``(height, width)`` of that image in pixels; pixel ``(r, c)`` covers
        ``[c - 0.5, c + 0.5] x [r - 0.5, r + 0.5]``.
    y_down : bool
        Whether y points down (image rows), as in every image format.
    """

    unit: str = "px"
    image: str | None = None
    size: tuple[int, int] | None = None
    y_down: bool = True


@dataclass(frozen=True, eq=False, repr=False)
class Shape:
    """An object to be modelled: an ordered set of ``m`` nodes in 2D or 3D.

    Parameters
    ----------
    points : array_like, shape (m, d)
        Node coordinates, one node per row, ``d`` in {2, 3}, in the user's units.
    closed : bool, optional
        For ordered contours (2D, or 3D polylines): whether the last node connects back to
        the first. Ignored when ``faces`` are given.
    ordered : bool, optional
        Whether the row order is meaningful (a contour or polyline). ``False`` for point
        clouds, whose neighbourhoods then come from ``faces`` or nearest neighbours.
        Defaults to ``True`` in 2D; in 3D without ``faces``, to ``True`` for points that
        trace a curve in the order given (:func:`traces_curve`: a contour written with
        a z column, a centreline), else ``False``.
    faces : array_like of int, shape (f, 3), optional
        Triangles of a 3D surface (indices into ``points``); none (0, 3) is None.
    frame : ImageFrame, optional
        For shapes in image coordinates (read from an image or SVG): their unit,
        orientation (y down) and source image, used by the figures. None: plain
        coordinates in the input's units, y up.
    contours : sequence of int, optional
        For ordered shapes of several contours (a myocardium ring: its outer boundary and
        its hole; a footprint: heel, forefoot and toes): the node count of each contour,
        in row order, summing to ``m``; every contour is closed (or open) as ``closed``
        says. ``None``: one contour (stored so; ``(m,)`` is the same).

    Raises
    ------
    ShapeError
        If the points are not finite, not of shape (m, 2) or (m, 3), fewer than 3, contain
        repeated nodes, or all lie (nearly) at one point; if ``closed`` or ``ordered``
        is not a boolean; or if ``contours`` do not split the nodes into contours of at
        least 3 nodes (2 for open ones) of an ordered shape without faces.
    """

    points: np.ndarray
    closed: bool = True
    ordered: bool | None = None
    faces: np.ndarray | None = field(default=None)
    frame: ImageFrame | None = None
    contours: tuple[int, ...] | None = None

    def __post_init__(self):
        for name in ("closed", "ordered"):  # "no" is a true string: refuse it by name
            value = getattr(self, name)
            if not isinstance(value, bool | np.bool_) and not (name == "ordered"
                                                               and value is None):
                raise ShapeError(f"{name} must be True or False, got {value!r}")
        pts = _validate_points(self.points, "points")
        pts.setflags(write=False)
        object.__setattr__(self, "points", pts)
        if self.ordered is None:
            object.__setattr__(self, "ordered", pts.shape[1] == 2 or (
                self.faces is None and traces_curve(pts)))
        if self.faces is not None:
            faces = np.asarray(self.faces)
            integer = np.issubdtype(faces.dtype, np.integer)
            if faces.ndim != 2 or faces.shape[1] != 3 or not integer:
                raise ShapeError(f"faces must be an integer array of shape (f, 3), got "
                                 f"{faces.dtype} {faces.shape}")
            if faces.size and (faces.min() < 0 or faces.max() >= len(pts)):
                raise ShapeError(f"faces index nodes outside 0..{len(pts) - 1}")
            faces = faces.astype(np.intp)
            faces.setflags(write=False)
            object.__setattr__(self, "faces", faces if len(faces) else None)
        if self.frame is not None and not isinstance(self.frame, ImageFrame):
            raise ShapeError(f"frame must be an ImageFrame or None, got {self.frame!r}")
        object.__setattr__(self, "contours", self._checked_contours())

    def _checked_contours(self) -> tuple[int, ...] | None:
        """``contours`` as a tuple of ints, None for one contour; ShapeError if invalid."""
        if self.contours is None:
            return None
        sizes = np.asarray(self.contours)
        if sizes.ndim != 1 or not len(sizes) or not np.issubdtype(sizes.dtype, np.integer):
            raise ShapeError(f"contours must be a sequence of node counts, got "
                             f"{self.contours!r}")
        if not self.ordered or self.faces is not None:
            raise ShapeError("contours split an ordered shape (contours or polylines); "
                             "a point set or a surface has none")
        least = 3 if self.closed else 2
        if sizes.min() < least or int(sizes.sum()) != self.m:
            raise ShapeError(f"contours must be node counts of at least {least} summing to "
                             f"the {self.m} nodes, got {sizes.tolist()}")
        return None if len(sizes) == 1 else tuple(int(k) for k in sizes)

    @property
    def has_faces(self) -> bool:
        """Whether the shape is a triangle surface (``faces`` is not None)."""
        return self.faces is not None

    @property
    def m(self) -> int:
        """Number of nodes."""
        return self.points.shape[0]

    @property
    def dim(self) -> int:
        """Spatial dimension, 2 or 3."""
        return self.points.shape[1]

    @cached_property
    def centroid(self) -> np.ndarray:
        """Mean of the nodes, shape (d,)."""
        return self.points.mean(axis=0)

    @cached_property
    def size(self) -> float:
        """RMS distance of the nodes to their centroid (the object's size)."""
        return float(np.sqrt(np.mean(np.sum((self.points - self.centroid) ** 2, axis=1))))

    @cached_property
    def normalized(self) -> np.ndarray:
        """Nodes centred on their centroid and scaled to unit RMS radius, shape (m, d).

        Every physical computation runs on these, so results do not depend on where the
        object is or on the units of its coordinates.
        """
        out = (self.points - self.centroid) / self.size
        out.setflags(write=False)
        return out

    @cached_property
    def spacing(self) -> float:
        """Mean nearest-neighbour distance in normalised units (see :attr:`normalized`)."""
        return float(nearest_distances(self.normalized).mean())

    def to_user(self, normalized_points: np.ndarray) -> np.ndarray:
        """Map points from this shape's normalised frame back to the user's coordinates."""
        return np.asarray(normalized_points) * self.size + self.centroid

    def to_normalized(self, points: np.ndarray) -> np.ndarray:
        """Map points in the user's coordinates into this shape's normalised frame."""
        return (np.asarray(points, dtype=np.float64) - self.centroid) / self.size

    @property
    def sizes(self) -> tuple[int, ...]:
        """Node count of each contour of an ordered shape (``(m,)`` for one contour);
        ``()`` for point sets and surfaces."""
        if not self.ordered or self.faces is not None:
            return ()
        return self.contours or (self.m,)

    @property
    def slices(self) -> list[slice]:
        """The rows of each contour (see :attr:`sizes`)."""
        ends = np.cumsum(self.sizes, dtype=np.intp)
        return [slice(int(e - k), int(e)) for k, e in zip(self.sizes, ends, strict=True)]

    @cached_property
    def contour_of(self) -> np.ndarray:
        """The contour of every node, shape (m,) (all 0 for one contour or no contour)."""
        out = np.repeat(np.arange(len(self.sizes)), self.sizes) if self.sizes else \
            np.zeros(self.m, dtype=np.intp)
        out.setflags(write=False)
        return out

    @cached_property
    def edges(self) -> np.ndarray:
        """Node pairs (e, 2) joined by the shape's topology: each contour's segments (the
        last node back to the first when closed), a surface's triangle edges (unique,
        sorted), none for a point set."""
        if self.faces is not None:
            e = np.sort(self.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
            out = np.unique(e, axis=0) if len(e) else np.empty((0, 2), dtype=np.intp)
        elif self.ordered:
            parts = [_contour_edges(s.start, s.stop, self.closed) for s in self.slices]
            out = np.vstack(parts)
        else:
            out = np.empty((0, 2), dtype=np.intp)
        out = out.astype(np.intp)
        out.setflags(write=False)
        return out

    def contour(self, k: int) -> Shape:
        """Contour ``k`` alone, as a shape of one contour (same ``closed`` and frame)."""
        return Shape(self.points[self.slices[k]], closed=self.closed, ordered=True,
                     frame=self.frame)

    def __repr__(self) -> str:
        kind = ("surface" if self.faces is not None else "closed contour" if self.ordered
                and self.closed else "open curve" if self.ordered else "point set")
        if self.contours:
            kind = f"{kind.replace('contour', 'contours').replace('curve', 'curves')} " \
                   f"x{len(self.contours)}"
        frame = "" if self.frame is None else f", in {self.frame.unit}"
        return f"Shape({self.m} nodes, {self.dim}D {kind}{frame})"

    def with_points(self, points: np.ndarray) -> Shape:
        """The same topology (closed, ordered, faces, contours) and frame on other node
        coordinates."""
        return Shape(points, closed=self.closed, ordered=self.ordered, faces=self.faces,
                     frame=self.frame, contours=self.contours)


def _contour_edges(start: int, stop: int, closed: bool) -> np.ndarray:
    """Segments of the contour on rows ``start:stop``, closing back when ``closed``."""
    i = np.arange(start, stop if closed else stop - 1)
    j = i + 1
    if closed:
        j[-1] = start
    return np.c_[i, j]


def forget_checks() -> None:
    """Forget the checks :func:`check_once` remembers (a benchmark times each call as the
    first one on its objects)."""
    with _passed_lock:
        _passed.clear()


def _validate_points(points, name: str) -> np.ndarray:
    if np.iscomplexobj(points):
        raise ShapeError(f"{name} must be real coordinates, got complex numbers")
    try:
        pts = np.array(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ShapeError(f"{name} must be numeric coordinates: {exc}") from None
    if pts.ndim != 2 or pts.shape[1] not in (2, 3):
        raise ShapeError(f"{name} must have shape (m, 2) or (m, 3), got {pts.shape}")
    if pts.shape[0] < 3:
        raise ShapeError(f"{name} must have at least 3 nodes, got {pts.shape[0]}")
    check_once("points", pts, lambda: _check_values(pts, name))
    return pts


def _check_values(pts: np.ndarray, name: str) -> None:
    """Refuse non-finite or huge coordinates, a point, repeated nodes."""
    bad = ~np.isfinite(pts).all(axis=1)
    if bad.any():
        raise ShapeError(f"{name} has non-finite coordinates (NaN or inf) at node(s) "
                         f"{np.flatnonzero(bad)[:10].tolist()}")
    big = np.abs(pts).max(axis=1) > MAX_COORDINATE
    if big.any():
        raise ShapeError(f"{name} has coordinates beyond +-{MAX_COORDINATE:g} at node(s) "
                         f"{np.flatnonzero(big)[:10].tolist()}: too large to compute with")
    centred = pts - pts.mean(axis=0)
    size = np.sqrt(np.mean(np.sum(centred**2, axis=1)))
    magnitude = max(1.0, float(np.abs(pts).max()))
    if size <= _POINT_TOL * magnitude:
        raise ShapeError(f"{name}: all {pts.shape[0]} nodes lie (nearly) at one point")
    pairs = cKDTree(pts).query_pairs(_REPEAT_TOL * size, output_type="ndarray")
    if len(pairs):
        i, j = pairs[0]
        raise ShapeError(f"{name} has repeated nodes: node {i} and node {j} coincide "
                         f"({len(pairs)} repeated pair(s) in all)")


def as_shape(obj, name: str = "shape") -> Shape:
    """Return ``obj`` if it is a :class:`Shape`, else build one from an (m, d) array."""
    if isinstance(obj, Shape):
        return obj
    if isinstance(obj, str | os.PathLike):
        raise ShapeError(f"{name} is a file name ({os.fspath(obj)!r}), not coordinates: read "
                         f"it with modalmorph.read_shape(path), or give an (m, 2) or (m, 3) "
                         f"array or a Shape")
    try:
        return Shape(obj)
    except ValueError as exc:
        msg = str(exc)
        raise ShapeError(msg.replace("points", name, 1) if msg.startswith("points") else
                         f"{name}: {msg}") from None


def resample(points, n: int, *, closed: bool = True):
    """Resample a polyline to ``n`` nodes equally spaced by arc length.

    Parameters
    ----------
    points : array_like, shape (m, d), or Shape
        Ordered nodes; or an ordered :class:`Shape`, whose contours are resampled each,
        ``n`` nodes shared among them by length (:func:`resampled_counts`).
    n : int
        Number of nodes wanted, >= 3 (2 for an open polyline; per contour of a Shape).
    closed : bool, optional
        Whether the polyline closes on itself (then the first node is kept and the last
        segment is included); a Shape's own is used.

    Returns
    -------
    ndarray, shape (n, d), or Shape
    """
    if isinstance(points, Shape):
        if not points.ordered:
            raise ShapeError("resample takes ordered contours; coarsen() spreads a subset "
                             "of a point set")
        least = (3 if points.closed else 2) * len(points.sizes)
        if n < least:
            raise ShapeError(f"n must be >= {least} for {len(points.sizes)} "
                             f"{'closed' if points.closed else 'open'} contour(s), got {n}")
        counts = resampled_counts([points.points[r] for r in points.slices], n, points.closed)
        parts = [resample(points.points[r], c, closed=points.closed)
                 for r, c in zip(points.slices, counts, strict=True)]
        return Shape(np.vstack(parts), closed=points.closed, frame=points.frame,
                     contours=tuple(counts) if len(counts) > 1 else None)
    pts = np.asarray(points, dtype=np.float64)
    if n < (3 if closed else 2):
        raise ShapeError(f"n must be >= {3 if closed else 2} for a "
                         f"{'closed' if closed else 'open'} polyline, got {n}")
    path = np.vstack([pts, pts[:1]]) if closed else pts
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))]
    t = np.linspace(0.0, s[-1], n, endpoint=not closed)
    return np.column_stack([np.interp(t, s, path[:, a]) for a in range(pts.shape[1])])


def spread_indices(shape: Shape, n: int) -> np.ndarray:
    """Indices of at most ``n`` nodes spread evenly over a shape, ascending.

    Ordered shapes: evenly along the order. Unordered point sets: farthest-point sampling
    from the node nearest the centroid (deterministic), among the ``FPS_POOL * n`` nodes
    of :func:`even_subset` above ``HUGE`` nodes (its cost is then linear in ``m``).
    """
    m = shape.m
    if m <= n:
        return np.arange(m)
    if shape.ordered:
        counts = share(shape, n)
        return np.concatenate([
            r.start + np.unique(np.linspace(0, k, c, endpoint=not shape.closed)
                                .astype(np.intp) % k)
            for r, k, c in zip(shape.slices, shape.sizes, counts, strict=True)])
    x = shape.normalized
    pool = None
    if m > HUGE and m > FPS_POOL * n:  # linear cost, not m n: among an even subset
        pool = even_subset(x, FPS_POOL * n)
        x = x[pool]
    chosen = _farthest_points(x, n)
    return np.sort(chosen if pool is None else pool[chosen])


def _farthest_points(x: np.ndarray, n: int) -> np.ndarray:
    """Farthest-point sampling of ``n`` of the points ``x`` (m, d), from the point nearest
    the origin. Above ``FPS_TREE`` points each new point updates only the distances within
    the current largest one (a k-d tree's ball): the same points, in time about
    ``m log n`` instead of ``m n``."""
    chosen = np.empty(n, dtype=np.intp)
    chosen[0] = np.argmin(np.sum(x**2, axis=1))
    dist = np.sum((x - x[chosen[0]]) ** 2, axis=1)
    tree = cKDTree(x) if len(x) > FPS_TREE else None
    for i in range(1, n):
        c = chosen[i] = np.argmax(dist)
        if tree is None:
            dist = np.minimum(dist, np.sum((x - x[c]) ** 2, axis=1))
            continue
        # a point nearer the new one than its distance lies within the largest distance
        # (widened past rounding: the extra points keep their distance)
        near = tree.query_ball_point(x[c], np.sqrt(dist[c]) * _BALL_MARGIN,
                                     return_sorted=False)
        near = np.asarray(near, dtype=np.intp)
        dist[near] = np.minimum(dist[near], np.sum((x[near] - x[c]) ** 2, axis=1))
    return chosen


def even_subset(points: np.ndarray, m: int) -> np.ndarray:
    """Indices of about ``m`` of ``points`` (n, d) spread evenly over them, ascending: the
    point nearest the centre of each occupied cell of a cubic grid, of the ``GRID_ROUNDS``
    cell sizes tried (each corrected towards ``m`` occupied cells: a surface's count of
    cells falls as the square of their size) the one nearest ``m``. Deterministic,
    O(n log n)."""
    n = len(points)
    if m >= n:
        return np.arange(n)
    low = points.min(axis=0)
    extent = float(np.max(points.max(axis=0) - low)) or 1.0
    cell = extent / np.sqrt(m)
    tried = []  # (|count - m|, cell)
    for _ in range(GRID_ROUNDS):
        count = len(np.unique(_cell_keys(points, low, cell)[0]))
        tried.append((abs(count - m), cell))
        cell *= np.sqrt(count / m)
    keys, grid = _cell_keys(points, low, min(tried)[1])
    offset = np.linalg.norm(grid - np.floor(grid) - 0.5, axis=1)
    order = np.lexsort((offset, keys))  # by cell, the point nearest its centre first
    first = np.r_[True, np.diff(keys[order]) != 0]
    return np.sort(order[first])


def _cell_keys(points: np.ndarray, low: np.ndarray, cell: float):
    """One integer per point naming its grid cell, and the points in cell units."""
    grid = (points - low) / cell
    index = np.floor(grid).astype(np.int64)
    span = index.max(axis=0) + 1
    return np.ravel_multi_index(index.T, span), grid


def coarsen(shape: Shape, n: int) -> Shape:
    """At most ``n`` nodes spread evenly over a shape, for a reduced physical model.

    Ordered contours are resampled by arc length (:func:`resample`); unordered point sets
    and surfaces keep the subset :func:`spread_indices` chooses. A shape with at most
    ``n`` nodes is returned as it is.
    """
    if shape.m <= n:
        return shape
    if shape.ordered:
        counts = share(shape, n)
        pts = [resample(shape.points[r], c, closed=shape.closed)
               for r, c in zip(shape.slices, counts, strict=True)]
        return Shape(np.vstack(pts), closed=shape.closed,
                     contours=tuple(counts) if shape.contours else None)
    return Shape(shape.points[spread_indices(shape, n)], ordered=False)


def resampled_counts(contours: list, n: int, closed: bool = True) -> list[int]:
    """``n`` nodes shared among contours (a list of (m_k, d) arrays) by length, as
    :func:`share` does, but each may get more nodes than it has (resampled)."""
    if len(contours) == 1:
        return [n]
    dense = [resample(c, n, closed=closed) for c in contours]
    return share(Shape(np.vstack(dense), closed=closed, contours=(n,) * len(dense)), n)


def share(shape: Shape, n: int) -> list[int]:
    """``n`` nodes shared among the contours of an ordered shape in proportion to their
    lengths (largest remainders), each keeping at least 3 (2 when open) and at most its
    own node count; one contour gets ``min(n, m)``."""
    sizes = np.asarray(shape.sizes)
    if len(sizes) == 1:
        return [min(n, shape.m)]
    least = 3 if shape.closed else 2
    length = np.array([_length(shape.points[r], shape.closed) for r in shape.slices])
    free = max(n - least * len(sizes), 0)
    want = least + free * length / length.sum()
    counts = np.minimum(np.floor(want).astype(int), sizes)
    for k in np.argsort(counts - want):  # largest remainders first
        if counts.sum() >= min(n, shape.m):
            break
        if counts[k] < sizes[k]:
            counts[k] += 1
    return counts.tolist()


def _length(points: np.ndarray, closed: bool) -> float:
    path = np.vstack([points, points[:1]]) if closed else points
    return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())


def check_pairs(pairs, m: int, n: int) -> np.ndarray:
    """Node pairs (K, 2) ``(source index, target index)`` as intp, checked against ``m``
    source and ``n`` target nodes: integers, at least one pair, every index in range,
    each source node at most once. Raises :class:`ShapeError` naming what is wrong."""
    pairs = np.asarray(pairs)
    if pairs.ndim != 2 or pairs.shape[1] != 2 or not (
            pairs.size == 0 or np.issubdtype(pairs.dtype, np.integer)):
        raise ShapeError(f"matching must be a Matching or an integer array of shape (K, 2), "
                         f"got {pairs.dtype} {pairs.shape}")
    if len(pairs) == 0:
        raise ShapeError("no node is matched: morph needs at least one matched pair")
    if pairs[:, 0].min() < 0 or pairs[:, 0].max() >= m or pairs[:, 1].min() < 0 \
            or pairs[:, 1].max() >= n:
        raise ShapeError(f"matching indices out of range for {m} source and {n} target "
                         "nodes")
    if np.bincount(pairs[:, 0].astype(np.intp, copy=False)).max() > 1:  # np.unique: 4x
        raise ShapeError("matching pairs a source node more than once")
    return pairs.astype(np.intp)


def curve_dimension(points: np.ndarray) -> float:
    """The dimension a point set shows (1 along a curve, 2 on a surface): the median of
    ``log 4 / log(r12 / r3)`` over up to ``CURVE_SAMPLE`` points taken in order."""
    _, r = _sample_neighbours(points)
    return float(points.shape[1] - 1) if r is None else _dimension(r)


def traces_curve(points: np.ndarray) -> bool:
    """Whether 3D points lie along one curve (:func:`curve_dimension` under
    ``CURVE_DIMENSION``) and follow it in the order given: the median step to the next
    point within ``CURVE_STEP`` second-nearest distances, none over ``CURVE_JUMP`` times
    the median step (on up to ``CURVE_SAMPLE`` points taken in order)."""
    sample, r = _sample_neighbours(points)
    if r is None:
        return False
    steps = np.linalg.norm(np.diff(sample, axis=0), axis=1)
    median = np.median(steps)
    return bool(median <= CURVE_STEP * np.median(r[:, 2]) and steps.max() <= CURVE_JUMP
                * median and _dimension(r) < CURVE_DIMENSION)


def _sample_neighbours(points: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """Up to ``CURVE_SAMPLE`` of the points, in order, and the distances to their 12
    nearest (none under 13 points)."""
    sample = points[::-(-len(points) // CURVE_SAMPLE)]
    if len(sample) < 13:
        return sample, None
    return sample, cKDTree(sample).query(sample, k=13)[0]


def _dimension(r: np.ndarray) -> float:
    return float(np.median(np.log(4.0) / np.log(r[:, 12] / np.maximum(r[:, 3], 1e-300))))
