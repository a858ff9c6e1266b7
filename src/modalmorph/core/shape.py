"""Shapes: ordered node sets in 2D or 3D, validated once at the boundary."""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from scipy.spatial import cKDTree

from ..errors import ShapeError

__all__ = ["ImageFrame", "Shape", "as_shape", "check_pairs", "coarsen", "even_subset",
           "resample", "spread_indices", "GRID_ROUNDS", "HUGE", "FPS_POOL"]

# Two nodes closer than this fraction of the object's RMS radius are "the same node".
_REPEAT_TOL = 1e-9
# Coordinates beyond this magnitude are refused: sums of squared distances between such
# nodes (up to 1e6 of them) would overflow float64 (1.8e308): (2e150)^2 * 1e6 = 4e306.
MAX_COORDINATE = 1e150
# An object whose RMS radius is below this fraction of its coordinates' magnitude is a point.
_POINT_TOL = 1e-10
GRID_ROUNDS = 6  # cell sizes even_subset tries: within 10 % of m on icospheres (method.md §5)
HUGE = 200_000  # unordered sets above this: farthest points among an even_subset (§7)
FPS_POOL = 20  # its candidates per point chosen (§7)


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
        Defaults to ``True`` in 2D and to ``False`` in 3D.
    faces : array_like of int, shape (f, 3), optional
        Triangles of a 3D surface (indices into ``points``).
    frame : ImageFrame, optional
        For shapes in image coordinates (read from an image or SVG): their unit,
        orientation (y down) and source image, used by the figures. None: plain
        coordinates in the input's units, y up.

    Raises
    ------
    ShapeError
        If the points are not finite, not of shape (m, 2) or (m, 3), fewer than 3, contain
        repeated nodes, or all lie (nearly) at one point; or if ``closed`` or ``ordered``
        is not a boolean.
    """

    points: np.ndarray
    closed: bool = True
    ordered: bool | None = None
    faces: np.ndarray | None = field(default=None)
    frame: ImageFrame | None = None

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
            object.__setattr__(self, "ordered", pts.shape[1] == 2)
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
            object.__setattr__(self, "faces", faces)
        if self.frame is not None and not isinstance(self.frame, ImageFrame):
            raise ShapeError(f"frame must be an ImageFrame or None, got {self.frame!r}")

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
        dist, _ = cKDTree(self.normalized).query(self.normalized, k=2)
        return float(dist[:, 1].mean())

    def to_user(self, normalized_points: np.ndarray) -> np.ndarray:
        """Map points from this shape's normalised frame back to the user's coordinates."""
        return np.asarray(normalized_points) * self.size + self.centroid

    def to_normalized(self, points: np.ndarray) -> np.ndarray:
        """Map points in the user's coordinates into this shape's normalised frame."""
        return (np.asarray(points, dtype=np.float64) - self.centroid) / self.size

    def __repr__(self) -> str:
        kind = ("surface" if self.faces is not None else "closed contour" if self.ordered
                and self.closed else "open curve" if self.ordered else "point set")
        frame = "" if self.frame is None else f", in {self.frame.unit}"
        return f"Shape({self.m} nodes, {self.dim}D {kind}{frame})"

    def with_points(self, points: np.ndarray) -> Shape:
        """The same topology (closed, ordered, faces) and frame on other node coordinates."""
        return Shape(points, closed=self.closed, ordered=self.ordered, faces=self.faces,
                     frame=self.frame)


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
    return pts


def as_shape(obj, name: str = "shape") -> Shape:
    """Return ``obj`` if it is a :class:`Shape`, else build one from an (m, d) array."""
    if isinstance(obj, Shape):
        return obj
    try:
        return Shape(obj)
    except ValueError as exc:
        msg = str(exc)
        raise ShapeError(msg.replace("points", name, 1) if msg.startswith("points") else
                         f"{name}: {msg}") from None


def resample(points, n: int, *, closed: bool = True) -> np.ndarray:
    """Resample a polyline to ``n`` nodes equally spaced by arc length.

    Parameters
    ----------
    points : array_like, shape (m, d)
        Ordered nodes.
    n : int
        Number of nodes wanted, >= 3.
    closed : bool, optional
        Whether the polyline closes on itself (then the first node is kept and the last
        segment is included).

    Returns
    -------
    ndarray, shape (n, d)
    """
    pts = np.asarray(points, dtype=np.float64)
    if n < 3:
        raise ShapeError(f"n must be >= 3, got {n}")
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
        return np.unique(np.linspace(0, m, n, endpoint=not shape.closed).astype(np.intp) % m)
    x = shape.normalized
    pool = None
    if m > HUGE and m > FPS_POOL * n:  # linear cost, not m n: among an even subset
        pool = even_subset(x, FPS_POOL * n)
        x = x[pool]
    chosen = np.empty(n, dtype=np.intp)
    chosen[0] = np.argmin(np.sum(x**2, axis=1))
    dist = np.sum((x - x[chosen[0]]) ** 2, axis=1)
    for i in range(1, n):
        chosen[i] = np.argmax(dist)
        dist = np.minimum(dist, np.sum((x - x[chosen[i]]) ** 2, axis=1))
    return np.sort(chosen if pool is None else pool[chosen])


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
        return Shape(resample(shape.points, n, closed=shape.closed), closed=shape.closed)
    return Shape(shape.points[spread_indices(shape, n)], ordered=False)


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
    if len(np.unique(pairs[:, 0])) != len(pairs):
        raise ShapeError("matching pairs a source node more than once")
    return pairs.astype(np.intp)
