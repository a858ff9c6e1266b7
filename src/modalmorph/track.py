"""``track()``: the nodes of the first frame followed through a whole sequence.

A sequence of observed objects (the left ventricle over the cardiac cycle, the sole of the
foot over a step) is followed by morphing the tracked shape onto each next frame's
observed contour (:func:`modalmorph.morph`, correspondence in the common frame of the
images), so every frame keeps the node identities of frame 0 and the track does not drift
away from the data. From the trajectories come the per-frame strain energy (22), (25) and
the contour strain: the relative change of length of each stretch between nodes against
frame 0 (for a closed left-ventricle contour, the circumferential strain).
"""

from __future__ import annotations

import inspect
import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, fields

import numpy as np
from scipy.spatial import cKDTree

from .matching import match
from .options import MatchOptions
from .pipeline import Morph, MorphDivergedError, morph
from .quality import curve_distances, self_crossings
from .shape import Shape, as_shape

__all__ = ["REFERENCES", "CORRESPONDENCES", "Track", "track", "curve_distance"]

log = logging.getLogger(__name__)

REFERENCES = ("previous", "first")
CORRESPONDENCES = ("nearest", "modal")
# morph() options that track() sets itself, per frame.
_OWN = ("source", "target", "matching", "progress")


@dataclass(frozen=True, eq=False)
class Track:
    """The nodes of frame 0 followed through every frame, with energy and strain.

    Attributes
    ----------
    points : ndarray, shape (F, m, d)
        Tracked nodes: row ``i`` of every frame is the same material node ``i`` of frame 0,
        in the user's units. ``points[0]`` is frame 0 itself.
    frames : tuple of Shape
        The observed objects (2D contours oriented like frame 0).
    names : tuple of str
        A name per frame (file name, or ``"frame <i>"``), used in messages.
    morphs : tuple of Morph
        ``F - 1`` morphs: ``morphs[f - 1]`` takes the tracked frame ``f - 1`` (or frame 0
        with ``reference="first"``) onto frame ``f``'s observed object.
    energy : ndarray, shape (F,)
        Strain energy ``U^T K U`` (22) at the end of each frame's morph (0 for frame 0),
        in the morph's units (:class:`Morph`): with ``reference="previous"`` the energy
        of the deformation from the previous frame, with ``"first"`` from frame 0.
    node_energy : ndarray, shape (F, m)
        The same per node (25).
    cumulative_energy : ndarray, shape (F,)
        ``cumsum(energy)``: the energy spent along the sequence up to each frame.
    edges : ndarray of int, shape (e, 2)
        The stretches between nodes whose strain is measured (contour edges, or the edges
        of a surface's triangles; none for point clouds).
    edge_strain : ndarray, shape (F, e)
        Relative change of length of every edge against frame 0, ``l_f / l_0 - 1``:
        negative when the stretch shortens.
    strain : ndarray, shape (F,)
        Global strain: relative change of the summed edge length (the perimeter of a
        closed contour: global circumferential strain of a left ventricle).
    segment_strain : ndarray, shape (F, S)
        Strain of ``S`` segments of equal arc length on frame 0, the first starting at
        ``start_node`` and following the node order (e.g. the 6 segments of a
        left-ventricle slice); ``(F, 0)`` for unordered objects.
    segment_of_edge : ndarray of int, shape (e,)
        The segment each edge belongs to (-1 for none).
    distance : ndarray, shape (F,)
        Two-way distance of the tracked shape to the observed object of its frame
        (:func:`curve_distance`), in the user's units.
    crossed : ndarray of bool, shape (F,)
        Whether a tracked 2D contour crosses itself at that frame.
    closure : Morph or None
        With ``cycle=True``: the morph of the last tracked frame back onto frame 0.
    closure_error : float or None
        Mean distance of the nodes brought back by ``closure`` to their own positions in
        frame 0 (user units): how far the track drifted over the cycle.
    params : dict
        The options used, for reports.
    """

    points: np.ndarray
    frames: tuple
    names: tuple
    morphs: tuple
    energy: np.ndarray
    node_energy: np.ndarray
    cumulative_energy: np.ndarray
    edges: np.ndarray
    edge_strain: np.ndarray
    strain: np.ndarray
    segment_strain: np.ndarray
    segment_of_edge: np.ndarray
    distance: np.ndarray
    crossed: np.ndarray
    closure: Morph | None
    closure_error: float | None
    params: dict = field(default_factory=dict)

    @property
    def n_frames(self) -> int:
        """Number of frames, F."""
        return self.points.shape[0]

    def shape(self, f: int) -> Shape:
        """The tracked shape of frame ``f`` (frame 0's topology on frame ``f``'s nodes)."""
        return self.frames[0].with_points(self.points[f])


def track(frames, *, reference: str = "previous", correspondence: str = "nearest",
          cycle: bool = False, segments: int = 6, start_node: int = 0,
          names: Sequence[str] | None = None, match_options: dict | None = None,
          morph_options: dict | None = None,
          progress: Callable[[int, int], None] | None = None) -> Track:
    """Follow the nodes of frame 0 through a sequence of observed objects.

    Each frame ``f`` is reached by morphing the tracked shape of frame ``f - 1`` onto the
    observed object of frame ``f`` (:func:`modalmorph.morph`), so node ``i`` keeps its
    identity through the whole sequence and every frame is fitted to its own data (no
    drift away from the contours).

    Parameters
    ----------
    frames : sequence of Shape or array_like (n_f, d)
        The observed objects in time order, at least 2, all 2D or all 3D, in one common
        frame of reference (the images' coordinates); node counts may differ. Frame 0's
        nodes are the ones tracked.
    reference : {"previous", "first"}, optional
        ``"previous"`` (default): morph the tracked frame ``f - 1`` onto frame ``f``
        (small steps). ``"first"``: morph frame 0 straight onto every frame.
    correspondence : {"nearest", "modal"}, optional
        How the morphed nodes are paired with the observed frame. ``"nearest"`` (default):
        in the common frame, each observed node is paired with at most one node, the
        nearest of those whose nearest observed node it is; the other nodes follow the
        morph's rule for unmatched nodes (spread by arc length along the contour), so the
        node spacing stays even. Suited to consecutive frames, where nodes move by less
        than the node spacing. ``"modal"``: :func:`modalmorph.match` (modal matching),
        for large motions between frames; ``match_options`` are passed to it.
    cycle : bool, optional
        The sequence is periodic (a cardiac cycle): also morph the last tracked frame back
        onto frame 0 and report how far the nodes land from where they started
        (``closure_error``).
    segments : int, optional
        Number of segments of equal arc length for ``segment_strain`` (default 6, the
        segments of a left-ventricle short-axis slice).
    start_node : int, optional
        Node of frame 0 where the first segment starts.
    names : sequence of str, optional
        A name per frame (e.g. file names) for messages; default ``"frame <i>"``.
    match_options : dict, optional
        Keyword arguments of :func:`modalmorph.match` (``correspondence="modal"``).
    morph_options : dict, optional
        Keyword arguments of :func:`modalmorph.morph` (``k``, ``dt``, ``model_nodes``,
        ...), the same for every frame.
    progress : callable, optional
        Called after each frame as ``progress(frame, n_frames)``.

    Returns
    -------
    Track

    Raises
    ------
    ValueError
        For invalid options, or a frame that cannot be tracked; the message names the
        frame (index and name).
    """
    if reference not in REFERENCES:
        raise ValueError(f"reference must be one of {REFERENCES}, got {reference!r}")
    if correspondence not in CORRESPONDENCES:
        raise ValueError(f"correspondence must be one of {CORRESPONDENCES}, "
                         f"got {correspondence!r}")
    if isinstance(segments, bool) or not isinstance(segments, int | np.integer) \
            or segments < 1:
        raise ValueError(f"segments must be a positive integer, got {segments!r}")
    match_kw = _options(match_options, match, (), "match_options")
    if match_kw and correspondence != "modal":
        raise ValueError("match_options apply to correspondence='modal' only")
    morph_kw = _options(morph_options, morph, _OWN, "morph_options")
    if len(frames) < 2:
        raise ValueError(f"frames must hold at least 2 objects, got {len(frames)}")
    names = tuple(f"frame {i}" for i in range(len(frames))) if names is None else \
        tuple(str(n) for n in names)
    if len(names) != len(frames):
        raise ValueError(f"names must have one entry per frame ({len(frames)}), "
                         f"got {len(names)}")
    shapes = [_frame(obj, f, names) for f, obj in enumerate(frames)]
    first = shapes[0]
    if isinstance(start_node, bool) or not isinstance(start_node, int | np.integer) \
            or not 0 <= start_node < first.m:
        raise ValueError(f"start_node must be a node of frame 0 (0..{first.m - 1}), "
                         f"got {start_node!r}")
    for f, shape in enumerate(shapes):
        if shape.dim != first.dim:
            raise ValueError(f"frame {f} ({names[f]}) is {shape.dim}D but frame 0 "
                             f"({names[0]}) is {first.dim}D: all frames must have the "
                             f"same dimension")
        shapes[f] = _oriented(shape, first)

    def step(source: Shape, f: int, target: Shape) -> Morph:
        try:
            pairs = (_nearest_pairs(source.normalized, target.normalized)
                     if correspondence == "nearest" else match(source, target, **match_kw))
            return morph(source, target, matching=pairs, **morph_kw)
        except (ValueError, MorphDivergedError) as exc:
            raise ValueError(f"frame {f} ({names[f]}): {exc}") from exc

    points, morphs = [first.points], []
    for f in range(1, len(shapes)):
        source = first if reference == "first" else first.with_points(points[-1])
        morphs.append(step(source, f, shapes[f]))
        points.append(morphs[-1].shapes[-1])
        if progress is not None:
            progress(f, len(shapes))
    points = np.array(points)

    closure = closure_error = None
    if cycle:
        closure = step(first.with_points(points[-1]), 0, first)
        closure_error = float(np.linalg.norm(closure.shapes[-1] - first.points, axis=1).mean())

    energy = np.r_[0.0, [r.energy[-1] for r in morphs]]
    node_energy = np.vstack([np.zeros(first.m), *[r.node_energy[-1] for r in morphs]])
    edges = _edges(first)
    lengths = np.linalg.norm(points[:, edges[:, 1]] - points[:, edges[:, 0]], axis=2)
    seg = _segment_of_edge(first, edges, segments, int(start_node))
    n_seg = segments if first.ordered else 0
    seg_len = np.stack([lengths[:, seg == s].sum(axis=1) for s in range(n_seg)], axis=1) \
        if n_seg else np.zeros((len(points), 0))
    params = dict(reference=reference, correspondence=correspondence, cycle=cycle,
                  segments=n_seg, start_node=int(start_node), match_options=match_kw,
                  morph=morphs[0].params)
    return Track(
        points=points, frames=tuple(shapes), names=names, morphs=tuple(morphs),
        energy=energy, node_energy=node_energy, cumulative_energy=np.cumsum(energy),
        edges=edges, edge_strain=lengths / lengths[0] - 1.0,
        strain=lengths.sum(axis=1) / lengths[0].sum() - 1.0 if len(edges) else
        np.zeros(len(points)),
        segment_strain=seg_len / seg_len[0] - 1.0 if n_seg else seg_len,
        segment_of_edge=seg,
        distance=np.array([curve_distance(first.with_points(p), s)
                           for p, s in zip(points, shapes, strict=True)]),
        crossed=np.array([_crosses_itself(p, first) for p in points]),
        closure=closure, closure_error=closure_error, params=params)


def _options(options: dict | None, func, own: tuple, name: str) -> dict:
    """Check a dict of keyword options against ``func``'s keyword-only parameters."""
    if options is None:
        return {}
    if not isinstance(options, dict):
        raise ValueError(f"{name} must be a dict, got {type(options).__name__}")
    known = [p.name for p in inspect.signature(func).parameters.values()
             if p.kind is inspect.Parameter.KEYWORD_ONLY and p.name not in own]
    if func is match:  # match takes MatchOptions' fields by name
        known = [f.name for f in fields(MatchOptions)]
    unknown = sorted(set(options) - set(known))
    if unknown:
        raise ValueError(f"{name}: unknown option(s) {unknown}; known: {', '.join(known)}")
    return dict(options)


def _frame(obj, f: int, names: tuple) -> Shape:
    try:
        return as_shape(obj, "frame")
    except ValueError as exc:
        raise ValueError(f"frame {f} ({names[f]}): {exc}") from None


def _oriented(shape: Shape, first: Shape) -> Shape:
    """A 2D contour turned to run the same way round as frame 0 (the sign of its area),
    so the morph's rule for unmatched nodes walks both in the same direction."""
    if shape.dim != 2 or not shape.ordered or not shape.closed or shape is first:
        return shape
    if np.sign(_area(shape.points)) == np.sign(_area(first.points)):
        return shape
    return shape.with_points(shape.points[::-1])


def _area(p: np.ndarray) -> float:
    return 0.5 * float(np.dot(p[:, 0], np.roll(p[:, 1], -1))
                       - np.dot(p[:, 1], np.roll(p[:, 0], -1)))


def _nearest_pairs(current: np.ndarray, observed: np.ndarray) -> np.ndarray:
    """Pairs (node, observed node) in the common frame: each observed node is paired with
    the closest of the nodes whose nearest observed node it is, so no two nodes are
    pulled to one point (which would bunch them and make the next model singular)."""
    dist, j = cKDTree(observed).query(current)
    order = np.lexsort((dist, j))
    first = np.r_[True, j[order][1:] != j[order][:-1]]
    keep = np.sort(order[first])
    return np.c_[keep, j[keep]]


def _edges(shape: Shape) -> np.ndarray:
    """Stretches whose strain is measured: contour edges, or the triangles' edges."""
    m = shape.m
    if shape.faces is not None:
        e = np.sort(shape.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
        return np.unique(e, axis=0)
    if not shape.ordered:
        return np.zeros((0, 2), dtype=np.intp)
    i = np.arange(m if shape.closed else m - 1)
    return np.c_[i, (i + 1) % m]


def _segment_of_edge(shape: Shape, edges: np.ndarray, segments: int,
                     start: int) -> np.ndarray:
    """Segment index of every contour edge: ``segments`` stretches of equal arc length of
    frame 0, the first starting at node ``start`` and following the node order."""
    if not shape.ordered or shape.faces is not None:
        return np.full(len(edges), -1, dtype=np.intp)
    p = shape.points
    length = np.linalg.norm(p[edges[:, 1]] - p[edges[:, 0]], axis=1)
    rolled = np.roll(np.arange(len(edges)), -start) if shape.closed else np.arange(len(edges))
    mid = np.cumsum(length[rolled]) - length[rolled] / 2  # arc length at each edge's middle
    seg = np.empty(len(edges), dtype=np.intp)
    seg[rolled] = np.minimum((mid / length.sum() * segments).astype(np.intp), segments - 1)
    return seg


def curve_distance(a: Shape, b: Shape) -> float:
    """Two-way distance between two objects: the larger of the mean distance of ``a``'s
    nodes to ``b`` and of ``b``'s nodes to ``a`` (to the polyline of an ordered contour,
    to the nodes of anything else; :func:`modalmorph.quality.curve_distances`), in the
    user's units."""
    ordered = bool(a.ordered and b.ordered and a.faces is None and b.faces is None)
    d_ab, d_ba = curve_distances(a.points, b.points, closed_a=a.closed, closed_b=b.closed,
                                 ordered=ordered)
    return float(max(d_ab.mean(), d_ba.mean()))


def _crosses_itself(points: np.ndarray, first: Shape) -> bool:
    """Whether a 2D contour (frame 0's topology on ``points``) crosses itself."""
    if points.shape[1] != 2 or not first.ordered:
        return False
    return self_crossings(points, closed=first.closed) > 0
