"""``track()``: the nodes of the first frame followed through a whole sequence.

A sequence of observed objects (the left ventricle over the cardiac cycle, the sole of the
foot over a step) is followed by morphing frame 0 (or the tracked previous frame) onto
each frame's observed contour (:func:`modalmorph.morph`, correspondence in the common
frame of the images), so every frame keeps the node identities of frame 0 and the track
does not drift away from the data. From the trajectories come the per-frame strain
energy (22), (25) and the contour strain: the relative change of length of each stretch
between nodes against frame 0 (for a closed left-ventricle contour, the circumferential
strain).
"""

from __future__ import annotations

import logging
import warnings
from collections.abc import Callable, Sequence
from contextlib import nullcontext
from dataclasses import asdict, dataclass, field
from functools import partial

import numpy as np
from scipy.spatial import cKDTree

from .core.quality import area, curve_distances, step_crossings
from .core.shape import Shape, as_shape
from .errors import MorphDivergedError, OptionError, ShapeError
from .matching import match
from .matching.contours import pair_contours
from .matching.normals import along_normals
from .options import (
    CORRESPONDENCES,
    REFERENCES,
    MatchOptions,
    MorphOptions,
    TrackOptions,
    parameters,
)
from .pipeline import Morph, morph
from .simulation import reuse_systems
from .slide import outline_slides
from .threads import limit

__all__ = ["REFERENCES", "CORRESPONDENCES", "Track", "track", "curve_distance"]

log = logging.getLogger(__name__)

# A frame reached from frame 0 (reference="first") is redone from the tracked previous
# frame when its morph did not converge, its contour crosses itself, or it lies farther
# than this many of frame 0's node spacings from the observed contour (curve_distance).
# Sound tracks of the corpus of benchmarks/track.py (hearts, pressure parts, warped
# glyphs and horse) lie within 0.25 mean edge lengths (0.78 on a pressure part whose
# morphs did not converge); wrong correspondences (nearest pairs on frames turned by
# 90-180 degrees) 2-35.
FIT_SPACINGS = 1.0


@dataclass(frozen=True, eq=False, repr=False)
class Track:
    """The nodes of frame 0 followed through every frame, with energy and strain.

    Attributes
    ----------
    points : ndarray, shape (F, m, d)
        Tracked nodes: row ``i`` of every frame is the same material node ``i`` of frame 0,
        in the user's units. ``points[0]`` is frame 0 itself.
    frames : tuple of Shape
        The observed objects (2D contours oriented like frame 0; the contours of each
        frame of several contours in the order of their partners in frame 0).
    names : tuple of str
        A name per frame (file name, or ``"frame <i>"``), used in messages.
    morphs : tuple of Morph
        ``F - 1`` morphs: ``morphs[f - 1]`` takes the tracked frame ``source_frame[f]``
        onto frame ``f``'s observed object.
    source_frame : ndarray of int, shape (F,)
        The frame each frame's morph started from: 0 with ``reference="first"`` (or
        ``f - 1`` where the morph from frame 0 failed and the one from the tracked
        previous frame was kept, see :func:`track`), ``f - 1`` with ``"previous"``; 0
        for frame 0.
    energy : ndarray, shape (F,)
        Strain energy ``U^T K U`` (22) at the end of frame ``f``'s morph, in the morph's
        units (:class:`Morph`): the energy of the deformation from the tracked frame
        ``source_frame[f]`` to frame ``f`` (from frame 0 with ``"first"``, from frame
        ``f - 1`` with ``"previous"``); 0 for frame 0.
    node_energy : ndarray, shape (F, m)
        The same per node (25).
    cumulative_energy : ndarray, shape (F,)
        Strain energy summed over the morphs that lead from frame 0 to frame ``f``
        (``energy[f] + cumulative_energy[source_frame[f]]``): with ``"first"`` the one
        morph from frame 0, so ``energy`` itself; with ``"previous"`` every step,
        ``cumsum(energy)``. Defined the same way for both; the values differ (over a
        cycle the steps add up while the morph from frame 0 returns to 0).
    edges : ndarray of int, shape (e, 2)
        The stretches between nodes whose strain is measured (:attr:`Shape.edges` of
        frame 0: the edges of each contour, or of a surface's triangles; none for point
        clouds).
    edge_strain : ndarray, shape (F, e)
        Relative change of length of every edge against frame 0, ``l_f / l_0 - 1``:
        negative when the stretch shortens.
    strain : ndarray, shape (F,)
        Global strain: relative change of the summed edge length (the perimeter of a
        closed contour: global circumferential strain of a left ventricle).
    segment_strain : ndarray, shape (F, S) or (F, P * S)
        Strain of ``S`` segments of equal arc length on frame 0, the first starting at
        ``start_node`` and following the node order (e.g. the 6 segments of a
        left-ventricle slice); ``(F, 0)`` for unordered objects. Objects of ``P``
        contours (a myocardium ring): ``S`` segments per contour, columns
        ``k S .. k S + S - 1`` for contour ``k``; the contour of ``start_node`` starts
        there, every other contour at its node nearest in angle about frame 0's
        centroid, numbered the way the first runs round, so that segment ``s`` of the
        endocardium and of the epicardium cover about the same sector.
    segment_of_edge : ndarray of int, shape (e,)
        The segment each edge belongs to (-1 for none).
    distance : ndarray, shape (F,)
        Two-way distance of the tracked shape to the observed object of its frame
        (:func:`curve_distance`, contour by contour for several contours), in the user's
        units.
    crossed : ndarray of bool, shape (F,)
        Whether a tracked 2D contour folds at that frame: crosses itself beyond tracing
        noise's tiny loops (or, for several contours, one crosses another), as
        ``Morph.self_intersections`` counts.
    closure : Morph or None
        With ``cycle=True``: the morph of the last tracked frame back onto frame 0.
    closure_error : float or None
        Mean distance of the nodes brought back by ``closure`` to their own positions in
        frame 0 (user units): how far the track drifted over the cycle.
    slide : ndarray, shape (F,)
        How far the tracked nodes lie shifted along the outline from frame 0's, fraction
        of the outline (signed, + in the node order; the largest of several contours;
        NaN where not measured: open contours, surfaces, point sets).
    slid : ndarray of bool, shape (F,)
        Frames whose nodes slid along the outline, an object turning or sliding farther
        than the correspondence follows (:func:`modalmorph.slide.outline_slides`).
    params : dict
        The options used, for reports.
    """

    points: np.ndarray
    frames: tuple
    names: tuple
    morphs: tuple
    source_frame: np.ndarray
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
    slide: np.ndarray
    slid: np.ndarray
    params: dict = field(default_factory=dict)

    def __repr__(self) -> str:
        n_frames, m, d = self.points.shape
        return (f"Track({n_frames} frames of {m} nodes in {d}D, strain "
                f"{float(self.strain[-1]):+.3%} and strain energy from frame 0 "
                f"{float(self.cumulative_energy[-1]):.4g} at the last frame)")

    @property
    def n_frames(self) -> int:
        """Number of frames, F."""
        return self.points.shape[0]

    def shape(self, f: int) -> Shape:
        """The tracked shape of frame ``f`` (frame 0's topology on frame ``f``'s nodes)."""
        return self.frames[0].with_points(self.points[f])


def track(frames, *, options: TrackOptions | None = None,
          names: Sequence[str] | None = None, match_options: MatchOptions | dict | None = None,
          morph_options: MorphOptions | dict | None = None,
          progress: Callable[[int, int], None] | None = None, **overrides) -> Track:
    """Follow the nodes of frame 0 through a sequence of observed objects.

    Frame ``f`` is reached by morphing frame 0 (``reference="first"``, the default) or
    the tracked frame ``f - 1`` (``"previous"``) onto the observed frame ``f``
    (:func:`modalmorph.morph`): node ``i`` keeps its identity and every frame is fitted
    to its own data (no drift away from the contours). With ``"first"`` frame 0's model,
    modes and integrator are built once for every frame
    (:func:`modalmorph.simulation.reuse_systems`), and a frame whose morph from frame 0
    fails its own test (raises, does not converge, crosses itself, or, for contours,
    ends farther than :data:`FIT_SPACINGS` node spacings from the observed contour) is
    morphed from the tracked previous frame instead, kept when that one passes
    (``source_frame`` says which; a warning says when neither passes). ``"nearest"``
    pairs the objects centred and scaled to one size: it follows changes of size and
    position, not a turn by more than about a node spacing from the frame a morph starts
    from (``Track.slid`` and a warning say when the nodes slid along the outline); for
    objects that turn, use ``correspondence="modal"`` (benchmarks/track.py).

    Parameters
    ----------
    frames : sequence of Shape or array_like (n_f, d)
        At least 2 objects in time order, all 2D or all 3D, in one common frame of
        reference (the images' coordinates); node counts may differ. Shapes of several
        contours (a myocardium ring) need as many contours in every frame; each frame's
        contours are paired with frame 0's by distance in that common frame, and every
        node stays on its partner contour (``correspondence="nearest"`` pairs within
        partners; ``"modal"`` matches partners, :func:`modalmorph.match`).
    options : TrackOptions, optional
        How the sequence is followed (reference, correspondence, cycle, segments).
    names : sequence of str, optional
        A name per frame for messages (default ``"frame <i>"``).
    match_options, morph_options : MatchOptions, MorphOptions or dict, optional
        The matcher's (``correspondence="modal"`` only) and the morph's options; dicts of
        their fields are converted (``remove_rigid=True`` in the morph's options removes
        the similarity between consecutive frames first).
    progress : callable, optional
        Called after each frame as ``progress(frame, n_frames)``.
    **overrides
        :class:`TrackOptions` fields (``reference="first"``, ``cycle=True``, ...).

    Returns
    -------
    Track

    Raises
    ------
    ValueError
        Invalid options (an :class:`~modalmorph.errors.OptionError` naming ``segments``
        when frame 0 has too few edges for them: a segment without an edge has no
        strain), or a frame that cannot be tracked (the message names it).
    """
    opts = _track_options(options, overrides)
    match_opts = _match_options(match_options, opts.correspondence)
    morph_opts = _as_options(morph_options, MorphOptions, "morph_options")
    shapes, names = _frames(frames, names, opts.start_node)
    _check_segments(shapes[0], names[0], opts)
    _check_normal(shapes[0], opts.correspondence)
    step = partial(_morph_frame, names=names, match_options=match_opts,
                   morph_options=morph_opts, normal=opts.correspondence == "normal")
    first = shapes[0]
    # reference "first": every frame's morph starts from frame 0's model and integrator
    reuse = reuse_systems() if opts.reference == "first" else nullcontext()
    with limit(max(shape.m for shape in shapes)), reuse:
        morphs, sources = _follow(shapes, names, opts.reference, step, progress)
        points = np.array([first.points, *[r.shapes[-1] for r in morphs]])
        closure = step(first.with_points(points[-1]), first, 0) if opts.cycle else None
    params = dict(asdict(opts), segments=opts.segments if first.ordered else 0,
                  start_node=int(opts.start_node),
                  match_options={} if match_opts is None else match_opts.record(),
                  morph=parameters(morphs[0]))
    result = _result(shapes, names, points, (morphs, sources), closure, params)
    _say_slid(result, opts.correspondence)
    return result


def _track_options(options, overrides: dict) -> TrackOptions:
    if options is None:
        options = TrackOptions()
    elif not isinstance(options, TrackOptions):
        raise OptionError(f"options must be a TrackOptions, got {type(options).__name__}")
    return options.replace(**overrides)


def _follow(shapes, names, reference: str, step, progress) -> tuple[list, np.ndarray]:
    """The morphs onto frames 1, 2, ... (``step(source, target, f)``) and the frame each
    started from: the tracked previous frame, or with ``reference="first"`` frame 0,
    unless that morph raised (then the one from the tracked previous frame, as with
    "previous") or fails its own test (:func:`_sound`) and the one from the tracked
    previous frame passes it (else it is kept, with a warning)."""
    first, morphs, sources = shapes[0], [], [0]
    for f in range(1, len(shapes)):
        previous = first if f == 1 else first.with_points(morphs[-1].shapes[-1])
        result, source = None, f - 1
        if reference == "first" and f > 1:
            result, source = _attempt(step, first, shapes[f], f), 0
        if result is None:
            result, source = step(previous, shapes[f], f), f - 1
        elif not _sound(result, first, shapes[f]):
            again = _attempt(step, previous, shapes[f], f)
            if again is not None and _sound(again, first, shapes[f]):
                result, source = again, f - 1
            else:
                warnings.warn(f"frame {f} ({names[f]}): neither its morph from frame 0 nor "
                              f"the one from frame {f - 1} converged, uncrossed, within "
                              f"{FIT_SPACINGS:g} node spacing of it (kept the first; see "
                              "Track.crossed and Track.distance): objects that turn need "
                              "correspondence='modal'", stacklevel=3)
        morphs.append(result)
        sources.append(source)
        if progress is not None:
            progress(f, len(shapes))
    return morphs, np.array(sources)


def _attempt(step, source: Shape, target: Shape, f: int) -> Morph | None:
    """``step(source, target, f)``, or None (logged) when it raises."""
    try:
        return step(source, target, f)
    except ValueError as exc:
        log.info("%s", exc)
        return None


def _sound(result: Morph, first: Shape, observed: Shape) -> bool:
    """A frame's morph that converged to a tracked shape that does not cross itself and,
    for contours, lies within :data:`FIT_SPACINGS` of frame 0's node spacing of the
    observed contour (surfaces and point sets: node to node distances depend on how
    densely each frame is sampled, so no such test)."""
    end = result.shapes[-1]
    if not result.converged or _crosses_itself(end, first, (first, observed)):
        return False
    return not (first.ordered and first.faces is None) or curve_distance(
        first.with_points(end), observed) <= FIT_SPACINGS * first.spacing * first.size


def _morph_frame(source: Shape, target: Shape, f: int, *, names: tuple,
                 match_options: MatchOptions | None, morph_options: MorphOptions,
                 normal: bool = False) -> Morph:
    """One frame's morph: pairs (nearest, along the normals onto the observed contour,
    or modal with ``match_options``), then :func:`modalmorph.morph`; errors name the
    frame."""
    try:
        cast = along_normals(source, target) if normal else None
        if cast is not None and len(np.unique(cast, axis=0)) == len(cast) and \
                not _crosses_itself(cast, source, (target,)):
            target = source.with_points(cast)  # node i to its own point on the polyline
            pairs = np.repeat(np.arange(source.m)[:, None], 2, axis=1)
        else:  # (normal targets that cross or coincide, open contours: nearest pairs)
            pairs = (_nearest_pairs_per_contour(source, target) if match_options is None
                     else match(source, target, options=match_options))
        return morph(source, target, matching=pairs, options=morph_options)
    except (ValueError, MorphDivergedError) as exc:
        raise ValueError(f"frame {f} ({names[f]}): {exc}") from exc


def _match_options(value, correspondence: str) -> MatchOptions | None:
    """The matcher's options for ``correspondence="modal"``, None for ``"nearest"``."""
    if value is None or isinstance(value, dict) and not value:
        return MatchOptions() if correspondence == "modal" else None
    if correspondence != "modal":
        raise OptionError("match_options apply to correspondence='modal' only")
    return _as_options(value, MatchOptions, "match_options")


def _as_options(value, cls, name: str):
    """An option object of class ``cls`` from one, a dict of its fields, or None."""
    if value is None:
        return cls()
    if isinstance(value, cls):
        return value
    if not isinstance(value, dict):
        raise OptionError(f"{name} must be a {cls.__name__} or a dict, "
                          f"got {type(value).__name__}")
    try:
        return cls().replace(**value)
    except OptionError as exc:
        raise OptionError(f"{name}: {exc}") from None


def _frames(frames, names, start_node) -> tuple[list, tuple]:
    """The frames as shapes (2D contours running the way frame 0 does) and their names."""
    if len(frames) < 2:
        raise ValueError(f"frames must hold at least 2 objects, got {len(frames)}")
    names = tuple(f"frame {i}" for i in range(len(frames))) if names is None else \
        tuple(str(n) for n in names)
    if len(names) != len(frames):
        raise ValueError(f"names must have one entry per frame ({len(frames)}), "
                         f"got {len(names)}")
    shapes = [_frame(obj, f, names) for f, obj in enumerate(frames)]
    first = shapes[0]
    if start_node >= first.m:
        raise OptionError(f"start_node must be a node of frame 0 (0..{first.m - 1}), "
                          f"got {start_node!r}")
    for f, shape in enumerate(shapes):
        if shape.dim != first.dim:
            raise ShapeError(f"frame {f} ({names[f]}) is {shape.dim}D but frame 0 "
                             f"({names[0]}) is {first.dim}D: all frames must have the "
                             f"same dimension")
        try:
            shapes[f] = _oriented(shape, first)
        except ShapeError as exc:
            raise ShapeError(f"frame {f} ({names[f]}): {exc}") from None
    return shapes, names


def _result(shapes, names, points, runs, closure, params) -> Track:
    """The Track: energies of the morphs (``runs``: the morphs and the frame each started
    from), strains of the tracked edges, distances."""
    first, (morphs, sources) = shapes[0], runs
    energy = np.r_[0.0, [r.energy[-1] for r in morphs]]
    cumulative = np.zeros(len(energy))
    for f in range(1, len(energy)):  # along the morphs that lead from frame 0 to frame f
        cumulative[f] = energy[f] + cumulative[sources[f]]
    node_energy = np.vstack([np.zeros(first.m), *[r.node_energy[-1] for r in morphs]])
    edges = first.edges
    lengths = np.linalg.norm(points[:, edges[:, 1]] - points[:, edges[:, 0]], axis=2)
    n_seg = params["segments"] * len(first.sizes)  # per contour
    seg = _segment_of_edge(first, edges, max(params["segments"], 1), params["start_node"])
    seg_len = np.stack([lengths[:, seg == s].sum(axis=1) for s in range(n_seg)], axis=1) \
        if n_seg else np.zeros((len(points), 0))
    closure_error = None if closure is None else float(
        np.linalg.norm(closure.shapes[-1] - first.points, axis=1).mean())
    return Track(
        points=points, frames=tuple(shapes), names=names, morphs=tuple(morphs),
        source_frame=sources, energy=energy, node_energy=node_energy,
        cumulative_energy=cumulative,
        edges=edges, edge_strain=lengths / lengths[0] - 1.0,
        strain=lengths.sum(axis=1) / lengths[0].sum() - 1.0 if len(edges) else
        np.zeros(len(points)),
        segment_strain=seg_len / seg_len[0] - 1.0 if n_seg else seg_len,
        segment_of_edge=seg,
        distance=np.array([curve_distance(first.with_points(p), s)
                           for p, s in zip(points, shapes, strict=True)]),
        crossed=np.array([_crosses_itself(p, first, (first, s))
                          for p, s in zip(points, shapes, strict=True)]),
        closure=closure, closure_error=closure_error,
        **dict(zip(("slide", "slid"), outline_slides(first, points), strict=True)), params=params)


def _say_slid(result: Track, correspondence: str) -> None:
    """A warning naming the frames whose nodes slid along the outline (``Track.slid``)."""
    frames = np.flatnonzero(result.slid)
    if len(frames):
        worst = int(frames[np.argmax(np.abs(result.slide[frames]))])
        warnings.warn(
            f"the tracked nodes slid along the outline at {len(frames)} of "
            f"{result.n_frames - 1} frames (most at frame {worst}, {result.names[worst]}: "
            f"{abs(result.slide[worst]):.1%} of the outline; Track.slide): the object "
            f"turns or slides farther than correspondence='{correspondence}' follows"
            + ("; use correspondence='modal'" if correspondence != "modal" else ""), stacklevel=3)


def _frame(obj, f: int, names: tuple) -> Shape:
    try:
        return as_shape(obj, "frame")
    except ValueError as exc:
        raise ValueError(f"frame {f} ({names[f]}): {exc}") from None


def _oriented(shape: Shape, first: Shape) -> Shape:
    """A 2D contour turned to run the same way round as frame 0 (the sign of its area),
    so the morph's rule for unmatched nodes walks both in the same direction; several
    contours: each ordered and turned like its partner of frame 0 (:func:`_like_first`)."""
    if shape is not first and (shape.contours or first.contours):
        return _like_first(shape, first)
    if shape.dim != 2 or not shape.ordered or not shape.closed or shape is first:
        return shape
    if np.sign(_area(shape.points)) == np.sign(_area(first.points)):
        return shape
    return shape.with_points(shape.points[::-1])


def _like_first(shape: Shape, first: Shape) -> Shape:
    """A frame of several contours with its contours in the order of their partners in
    frame 0 (:func:`~modalmorph.matching.contours.pair_contours` in the frames' common
    frame) and, closed 2D ones, running the same way round as them."""
    if len(shape.sizes) != len(first.sizes) or not shape.ordered:
        count = len(shape.sizes)
        raise ShapeError(f"it has {count or 'no'} contour{'' if count == 1 else 's'} but "
                         f"frame 0 has {len(first.sizes)}: the frames of a sequence of "
                         "several contours must have as many contours")
    partner = pair_contours(first, shape)[:, 1]
    pieces = []
    for k, j in enumerate(partner):
        p = shape.points[shape.slices[j]]
        turn = shape.dim == 2 and shape.closed and (
            np.sign(area(p)) != np.sign(area(first.points[first.slices[k]])))
        pieces.append(p[::-1] if turn else p)
    return Shape(np.vstack(pieces), closed=shape.closed, frame=shape.frame,
                 contours=tuple(len(p) for p in pieces))


def _area(p: np.ndarray) -> float:
    return 0.5 * float(np.dot(p[:, 0], np.roll(p[:, 1], -1))
                       - np.dot(p[:, 1], np.roll(p[:, 0], -1)))


def _nearest_pairs_per_contour(source: Shape, target: Shape) -> np.ndarray:
    """:func:`_nearest_pairs` of the normalised objects; for objects of several contours
    (the frames' contours in frame 0's order), within each contour and its partner."""
    x, y = source.normalized, target.normalized
    if not source.contours:
        return _nearest_pairs(x, y)
    return np.vstack([_nearest_pairs(x[a], y[b]) + [a.start, b.start]
                      for a, b in zip(source.slices, target.slices, strict=True)])


def _nearest_pairs(current: np.ndarray, observed: np.ndarray) -> np.ndarray:
    """Pairs (node, observed node) in the common frame: each observed node is paired with
    the closest of the nodes whose nearest observed node it is, so no two nodes are
    pulled to one point (which would bunch them and make the next model singular)."""
    dist, j = cKDTree(observed).query(current)
    order = np.lexsort((dist, j))
    first = np.r_[True, j[order][1:] != j[order][:-1]]
    keep = np.sort(order[first])
    return np.c_[keep, j[keep]]


def _check_normal(first: Shape, correspondence: str) -> None:
    if correspondence == "normal" and not (first.dim == 2 and first.ordered
                                           and first.faces is None):
        raise OptionError("correspondence='normal' needs 2D contours (ordered nodes): "
                          "use 'nearest' or 'modal' for point sets and surfaces")


def _check_segments(first: Shape, name: str, opts: TrackOptions) -> None:
    """An :class:`OptionError` naming ``segments`` when a segment of frame 0 would hold
    no edge (its strain would be 0/0), before any morph is computed."""
    if not first.ordered or first.faces is not None:
        return  # no segments: the strain table is empty
    edges = first.edges

    def fits(n: int) -> bool:
        seg = _segment_of_edge(first, edges, n, opts.start_node)
        return len(np.unique(seg)) == n * len(first.sizes)

    if fits(opts.segments):
        return
    most = next(n for n in range(min(opts.segments, len(edges)), 0, -1) if fits(n))
    raise OptionError(f"segments: frame 0 ({name}) has {len(edges)} edges, too few for "
                      f"{opts.segments} segments of equal arc length (a segment would hold "
                      f"no edge and its strain would be undefined): pass segments={most} or "
                      f"fewer, or resample the frames to more nodes")


def _segment_of_edge(shape: Shape, edges: np.ndarray, segments: int,
                     start: int) -> np.ndarray:
    """Segment index of every contour edge: ``segments`` stretches of equal arc length of
    frame 0, the first starting at node ``start`` and following the node order; for
    several contours, per contour (:func:`_contour_segments`)."""
    if not shape.ordered or shape.faces is not None:
        return np.full(len(edges), -1, dtype=np.intp)
    if shape.contours:
        return _contour_segments(shape, segments, start)
    p = shape.points
    length = np.linalg.norm(p[edges[:, 1]] - p[edges[:, 0]], axis=1)
    rolled = np.roll(np.arange(len(edges)), -start) if shape.closed else np.arange(len(edges))
    mid = np.cumsum(length[rolled]) - length[rolled] / 2  # arc length at each edge's middle
    seg = np.empty(len(edges), dtype=np.intp)
    seg[rolled] = np.minimum((mid / length.sum() * segments).astype(np.intp), segments - 1)
    return seg


def _contour_segments(shape: Shape, segments: int, start: int) -> np.ndarray:
    """Segments of a frame 0 of several contours, ``segments`` per contour, contour ``k``
    holding segments ``k * segments`` to ``(k + 1) * segments - 1`` (edges in the order
    of :attr:`Shape.edges`). The contour of node ``start`` starts there; every other one
    at its node nearest in angle about frame 0's centroid, and is numbered the way the
    first contour runs round (the sign of their areas), so that segment ``s`` of every
    contour covers about the same sector (an endocardium and its epicardium)."""
    p, own = shape.points, int(shape.contour_of[start])
    angle = np.arctan2(*(p - shape.centroid).T[::-1])
    way = np.sign(area(p[shape.slices[own]])) if shape.closed and shape.dim == 2 else 1.0
    out = []
    for k, rows in enumerate(shape.slices):
        part = Shape(p[rows], closed=shape.closed)
        first = start - rows.start if k == own else int(np.argmin(
            np.abs(np.angle(np.exp(1j * (angle[rows] - angle[start]))))))
        seg = _segment_of_edge(part, part.edges, segments, first)
        if shape.closed and shape.dim == 2 and np.sign(area(p[rows])) != way:
            seg = segments - 1 - seg  # numbered the other way round from the start
        out.append(k * segments + seg)
    return np.concatenate(out)


def curve_distance(a: Shape, b: Shape) -> float:
    """Two-way distance between two objects: the larger of the mean distance of ``a``'s
    nodes to ``b`` and of ``b``'s nodes to ``a`` (to the polyline of an ordered contour,
    to the nodes of anything else; :func:`modalmorph.core.quality.curve_distances`), in the
    user's units."""
    ordered = bool(a.ordered and b.ordered and a.faces is None and b.faces is None)
    if ordered and (a.contours or b.contours):
        return _contours_distance(a, b)
    d_ab, d_ba = curve_distances(a.points, b.points, closed_a=a.closed, closed_b=b.closed,
                                 ordered=ordered)
    return float(max(d_ab.mean(), d_ba.mean()))


def _contours_distance(a: Shape, b: Shape) -> float:
    """:func:`curve_distance` of objects of several contours, contour by contour: each
    contour of ``a`` against its partner in ``b`` (the same index when both have as
    many contours, else :func:`~modalmorph.matching.contours.pair_contours`); contours
    without a partner are left out."""
    partners = np.c_[np.arange(len(a.sizes)), np.arange(len(a.sizes))] \
        if len(a.sizes) == len(b.sizes) else pair_contours(a, b)
    d_ab, d_ba = [], []
    for k, j in partners:
        one, two = curve_distances(a.points[a.slices[k]], b.points[b.slices[j]],
                                   closed_a=a.closed, closed_b=b.closed)
        d_ab.append(one)
        d_ba.append(two)
    return float(max(np.concatenate(d_ab).mean(), np.concatenate(d_ba).mean()))


def _crosses_itself(points: np.ndarray, first: Shape, inputs: tuple = ()) -> bool:
    """Whether a 2D contour (frame 0's topology on ``points``) folds: crosses itself
    beyond tracing noise, one contour crosses another, or it has more loops of noise's
    size than the frames ``inputs`` carry as given
    (:func:`~modalmorph.core.quality.step_crossings`, as ``Morph.self_intersections``
    counts them)."""
    if points.shape[1] != 2 or not first.ordered:
        return False
    return bool(step_crossings([points], first, inputs)[0])
