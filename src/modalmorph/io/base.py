"""What every reader returns (:class:`RawShape`) and how coordinates read from a file
become a :class:`~modalmorph.core.shape.Shape` (:func:`make_shape`)."""

from __future__ import annotations

import logging
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.quality import check_flat, crossed_contours
from ..core.shape import ImageFrame, Shape, resample, resampled_counts
from ..errors import InputFileError, ShapeError
from ..options import ReadOptions

__all__ = ["DEFAULT_NODES", "FLIPPED_FRAME", "OPEN_LOOKING", "RawShape", "Reader",
           "UNEVEN_SPACING", "extension", "looks_open", "make_shape", "uneven_nodes", "y_down"]

_log = logging.getLogger(__name__)

# Nodes sampled along an image contour or an SVG path when ``nodes`` is not given.
DEFAULT_NODES = 200
# A contour from a point file whose longest edge is more than this many times its median
# edge is resampled evenly by arc length when ``nodes`` is not given. The bundled contours
# have 1.4-3.0 (hand 3: 3.0); a glyph drawn with 4 vertices on a straight stem and many
# on its curves has 10 or more, and its stem then holds too few nodes for its loads.
UNEVEN_SPACING = 4.0
# A contour from a point file that does not say whether it closes, whose closing edge (last
# node back to the first) is its longest and more than this many times its median edge, is
# said to look open. Closed outlines: at most 14.3 (the vertices of 288 glyphs of DejaVu
# Sans and Serif, STIX and cmr10: cmr10 'E'), the shared hearts and hands 1.0-1.6; open
# strokes of 50-80 nodes (a half circle, a sine) 31-63.
OPEN_LOOKING = 20.0
# The frame of a point file read with ``flip_y``: its y mirrored into image coordinates.
FLIPPED_FRAME = ImageFrame(unit="input units (y mirrored)", y_down=True)


def extension(path) -> str:
    """A file's extension, lower case, the two of a compressed NIfTI file (``.nii.gz``)
    together."""
    name = Path(path).name.lower()
    return ".nii.gz" if name.endswith(".nii.gz") else Path(name).suffix


def y_down(shape) -> bool:
    """Whether a shape's y points down (images, SVG, ``flip_y``) rather than up."""
    frame = getattr(shape, "frame", None)
    return frame is not None and frame.y_down


def uneven_nodes(name: str, pts: np.ndarray, closed: bool, contours=None) -> int | None:
    """Nodes to resample an unevenly spaced 2D contour to (logged), or None to keep it.

    ``max(DEFAULT_NODES, m)`` when the longest edge exceeds :data:`UNEVEN_SPACING` times
    the median edge; the log line names ``nodes=``, which chooses the count.
    """
    if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 3 or not np.isfinite(pts).all():
        return None  # make_shape says what is wrong
    ends = np.cumsum(contours or (len(pts),))
    if ends[-1] != len(pts):
        return None  # make_shape says what is wrong
    with np.errstate(over="ignore", invalid="ignore"):  # absurd sizes: Shape refuses them
        edges = np.concatenate([_edge_lengths(p, closed) for p in np.split(pts, ends[:-1])])
    median = float(np.median(edges))
    if not np.isfinite(edges).all() or median <= 0 or edges.max() <= UNEVEN_SPACING * median:
        return None
    nodes = max(DEFAULT_NODES, len(pts))
    _log.info("%s: uneven spacing (longest edge %.3g times the median): resampled from %d "
              "to %d nodes equally spaced by arc length (nodes=N for another count)",
              name, edges.max() / median, len(pts), nodes)
    return nodes


def looks_open(name: str, pts: np.ndarray, contours=None) -> None:
    """Warn where a 2D contour closed by default looks like an open curve
    (:data:`OPEN_LOOKING`): its closing chord would cut across the shape."""
    if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 3 or not np.isfinite(pts).all():
        return
    sizes = contours or (len(pts),)
    for k, p in enumerate(np.split(pts, np.cumsum(sizes)[:-1])):
        edges = _edge_lengths(p, True)
        median = float(np.median(edges))
        if len(p) > 2 and edges[-1] >= edges.max() and edges[-1] > OPEN_LOOKING * median > 0:
            which = f"contour {k}" if len(sizes) > 1 else "the contour"
            warnings.warn(f"{name}: {which} is closed by an edge from its last node back to "
                          f"its first {edges[-1] / median:.0f} times its median edge: if it "
                          "is an open curve (a centreline, a stroke), say so (open_curves=True)",
                          UserWarning, stacklevel=3)


def _edge_lengths(pts: np.ndarray, closed: bool) -> np.ndarray:
    path = np.vstack([pts, pts[:1]]) if closed else pts
    return np.linalg.norm(np.diff(path, axis=0), axis=1)


@dataclass(frozen=True)
class RawShape:
    """What a reader found in a file, before :func:`modalmorph.io.read_shape` checks it.

    Attributes
    ----------
    points : ndarray, shape (m, d)
        The coordinates as read (checked later by :func:`make_shape`).
    faces : ndarray of int, shape (f, 3), optional
        Triangles, for surfaces.
    closed : bool, optional
        Whether the file says the contour closes; None: it does not say (closed).
    frame : ImageFrame, optional
        Pixel or SVG coordinates, y down (images and SVG).
    default_nodes : int, optional
        Nodes to resample to when ``nodes`` is not given: :data:`DEFAULT_NODES` for
        outlines sampled from an image or a drawing; None keeps the file's nodes.
    drop_closing_repeat : bool
        Whether a last node repeating the first (a contour written closed) is dropped;
        False for a mesh's points.
    contours : tuple of int, optional
        Node counts of several contours in row order (an object's outer boundary then its
        holes; the subpaths of an SVG path); None: one contour.
    """

    points: np.ndarray
    faces: np.ndarray | None = None
    closed: bool | None = None
    frame: ImageFrame | None = None
    default_nodes: int | None = None
    drop_closing_repeat: bool = True
    contours: tuple[int, ...] | None = None


# A reader: (the file, its name as given, the read options) -> what the file holds.
Reader = Callable[[Path, str, ReadOptions], RawShape]


def make_shape(name, pts, *, faces=None, nodes=None, closed=True, frame=None,
               contours=None) -> Shape:
    """Check an (m, d) array of coordinates from ``name``; resample (``nodes`` shared among
    ``contours`` by length, :func:`~modalmorph.core.shape.share`); build the Shape."""
    pts = np.asarray(pts, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] not in (2, 3):
        raise InputFileError(f"{name}: expected an (m, 2) or (m, 3) array of coordinates, "
                             f"got shape {pts.shape}")
    if len(pts) < 3:
        raise InputFileError(f"{name}: only {len(pts)} node{'s' if len(pts) != 1 else ''}; "
                             f"a shape needs at least 3")
    if faces is not None and pts.shape[1] != 3:
        raise InputFileError(f"{name}: has triangles but {pts.shape[1]}D points; triangles "
                             f"describe 3D surfaces (give a 2D contour without faces)")
    bad = np.flatnonzero(~np.isfinite(pts).all(axis=1))
    if len(bad):
        raise InputFileError(f"{name}: node {bad[0]} has non-finite coordinates "
                             f"{pts[bad[0]].tolist()} ({len(bad)} such node(s))")
    if nodes is not None and (pts.shape[1] != 2 or faces is not None):
        raise InputFileError(f"{name}: nodes= resamples 2D contours; this is a "
                             f"{pts.shape[1]}D "
                             f"{'surface' if faces is not None else 'point set'}")
    if nodes is not None and closed and sum(contours or (len(pts),)) == len(pts):
        try:  # resampled, a contour on one line would double back over itself
            for part in np.split(pts, np.cumsum(contours or (len(pts),))[:-1]):
                check_flat(part, name)
        except ShapeError as exc:
            raise InputFileError(str(exc)) from None
    try:
        if nodes is not None:
            pts, contours = _resampled(name, pts, int(nodes), bool(closed), contours)
        return Shape(pts, closed=bool(closed), faces=faces, frame=frame, contours=contours)
    except ValueError as exc:
        raise InputFileError(f"{name}: {exc}") from None


def _resampled(name: str, pts, nodes: int, closed: bool, contours
               ) -> tuple[np.ndarray, tuple | None]:
    """Every contour resampled by arc length, ``nodes`` shared among them by length. At
    a detail finer than the node spacing (logged): a contour that then crosses itself
    (a thin hole of 10 nodes) gets twice its nodes, up to its own count; of two that
    cross (a hole a pixel inside the outline), the shorter is dropped."""
    raw = np.split(pts, np.cumsum(contours or (len(pts),))[:-1])
    keep, grown, dropped = list(range(len(raw))), {}, []
    while True:
        counts = resampled_counts([raw[k] for k in keep], nodes, closed)
        counts = [max(c, grown.get(k, 0)) for k, c in zip(keep, counts, strict=True)]
        parts = [resample(raw[k], c, closed=closed) for k, c in zip(keep, counts, strict=True)]
        own, both = crossed_contours(Shape(np.vstack(parts), closed=closed,
                                           contours=tuple(counts)))
        own = [i for i in own if counts[i] < len(raw[keep[i]])]
        for i in own:
            grown[keep[i]] = min(2 * counts[i], len(raw[keep[i]]))
        worse = {min(pair, key=lambda i: counts[i]) for pair in both} if not own else ()
        if not own and not worse:
            break
        dropped += [keep[i] for i in worse]
        keep = [k for i, k in enumerate(keep) if i not in worse]
    if grown:
        _log.info("%s: resampled to %d nodes, contour(s) %s crossed themselves (a detail "
                  "finer than their node spacing): given more nodes, %d in all (nodes=N for "
                  "another count)", name, nodes, _listed(grown), sum(counts))
    if dropped:
        warnings.warn(f"{name}: resampled to {nodes} nodes, contour(s) {_listed(dropped)} "
                      "crossed another (closer to it than the node spacing) and were dropped; "
                      "more nodes (nodes=N) keep them", stacklevel=4)
    return np.vstack(parts), (tuple(counts) if len(counts) > 1 else None)


def _listed(numbers) -> str:
    return ", ".join(map(str, sorted(numbers)))


