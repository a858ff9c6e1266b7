"""``morph()``: the whole method, end to end, returning one result object.

The source is modelled with Sclaroff's Gaussian element, matched nodes are pulled to their
partners by springs of stiffness ``k`` (19), unmatched nodes by the neighbourhood rule
(20), and Lagrange's dynamic equilibrium ``M U'' + C U' + K U = R`` (9) is integrated in
time by mode superposition (11)-(13) and Newmark's method (14)-(15)
(:class:`modalmorph.simulation.Simulation`).

What each option of :class:`modalmorph.options.MorphOptions` does is in its field's help;
why the defaults are what they are, with the measurements behind them, is in
docs/method.md:

- ``free_motion="similarity"``: a change of position, orientation or size costs no strain
  energy, so the springs reach a target of any size or pose (method.md §4, "Similarity-free
  stiffness"); ``"none"`` is the paper's ``U^T K U`` (22) for every motion.
- ``loads="consistent"``: every bit of the object is pulled in proportion to its mass, so
  no mode lags behind; ``"nodal"`` is the paper's force on every node (method.md §4,
  "Consistent loads").
- ``damping=1``: the ratio at the springs' frequency, growing with frequency, so every mode
  creeps to the target at nearly the same rate and nothing folds; a pair is the paper's
  Rayleigh damping by two ratios (method.md §4, "Damping (5)").
- ``unmatched="arclength"``: a run of unmatched nodes spreads evenly over the target stretch
  between its neighbours' partners; ``"mean"`` is the paper's rule (20), which folds long
  runs (method.md §4, "Springs (19) and unmatched nodes (20)").
- ``model_nodes=400``: larger sources are modelled on 400 nodes spread over them and move
  with the element's field (in 3D its moving affine fit, which does not ripple between the
  model's nodes; method.md §7, "Reduced models in the dynamics").
- pairs that turn the source by more than ``CO_ROTATE`` (30°): the turn is taken as a
  rigid motion along the steps (:attr:`Morph.co_rotation`), not along straight node paths
  that shrink a turning shape (method.md §4, "Large turns").
- ``scheme="implicit"``: the spring enters the effective stiffness, unconditionally stable;
  ``"explicit"`` is the paper's (stable for small ``k`` only).
- ``tol``: converged when :attr:`Morph.distance` (the stop test's measure, both ways for
  contours and surfaces) is below ``tol`` times the target's RMS radius (method.md §5).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from .core.align import Similarity, align
from .core.quality import check_contours, step_crossings
from .core.shape import Shape, as_shape
from .core.surfaces import intersection_sentence, step_self_intersections, unlike_sentence
from .errors import MorphDivergedError, OptionError, ShapeError
from .matching import Matching, match
from .matching.contours import unpaired_sentence
from .matching.mirror import mirror_said
from .options import MatchOptions, MorphOptions, split_overrides
from .simulation import SPARSE_MODES, Run, Simulation
from .simulation.driver import mean_pair_distance
from .simulation.result import stop_sentence
from .threads import limit

__all__ = ["COINCIDENT", "CO_ROTATE", "Morph", "MorphDivergedError", "co_rotated", "morph",
           "SPARSE_MODES"]

# Pairs that turn the source by more than this many degrees are taken as a rigid turn
# along the steps (Morph.co_rotation). Straight node paths shrink a turning shape: by
# 1 - cos(angle / 2) of its size halfway (3.4 % at 30 deg, 29 % at 90), and a half turn
# passes through a point (a hand: 0.98 of its size at 30 deg, 0.72 at 90, 0.04 at 180;
# method.md §4, "Large turns").
CO_ROTATE = 30.0
# Pair points spread over less than this fraction of their magnitude fix no similarity
# (every pair naming one target node): the tolerance of a Shape's "nearly one point".
COINCIDENT = 1e-10
# A source of fewer than half the target's nodes is said to be too coarse where the target
# drawn through as many nodes lies this many tolerances from itself (stop.resolution;
# a circle of radius 10, 200 nodes, at the default tolerance: drawn through 4 / 8 / 12 / 20
# nodes 39 / 10 / 4.6 / 1.6 tolerances; glyph outlines as TextPath gives them, sans ->
# serif: 'i' 4 -> 10 nodes 15, 'x' 12 -> 28 nodes 9).
COARSE_SOURCE = 2.0
# A source with at most this fraction of the target's nodes, whose run stops short or
# folds, is told that resampled it may follow closer: raw glyphs N T f r x Y, 8-22 nodes
# onto 16-33 (0.43-0.76), converge resampled to the target's count; at 199 onto 200 nodes
# the advice would be idle.
SHORT_SOURCE = 0.8

log = logging.getLogger(__name__)



@dataclass(frozen=True, eq=False, repr=False)
class Morph(Run):
    """The intermediate shapes between two objects, their strain energy, and how they were
    found: every attribute of :class:`~modalmorph.simulation.Run` (``shapes``, ``loads``,
    ``energy``, ``node_energy``, ``mean_distance``, ``distance``, ``tolerance``,
    ``stop_reason``, ``message``, ``resolved``, ``converged``, ``steps``) and:

    Attributes
    ----------
    matching : Matching
        The correspondences used (given pairs are a Matching of method ``"given"``).
    similarity : Similarity or None
        The similarity removed before morphing (``remove_rigid``), else None.
    source, target : Shape
        The objects as given (the source before any rigid alignment).
    options : MorphOptions
        The options of the physical model and the time integration.
    match_options : MatchOptions or None
        The matcher's options (None for given pairs).
    co_rotation : Similarity or None
        Where the pairs turn the source by more than ``CO_ROTATE`` degrees (and
        ``remove_rigid`` is off): their similarity, taken as a rigid motion along the steps
        (:func:`co_rotated`) rather than as straight node paths, which pass through a
        flattened shape; None otherwise.
    self_intersections : ndarray of int, shape (T+1,), or None
        For surfaces (a source with faces): the number of the surface's triangles that
        cut another of its triangles, at every step (:mod:`modalmorph.core.surfaces`;
        None when pymeshlab, which finds them, is not installed). For 2D contours: the
        folds at every step, pairs of segments that cross between two contours or, within
        one, close a loop larger than tracing noise
        (:func:`modalmorph.core.quality.step_crossings`). ``message`` says so when a step
        has more than the source. None for other objects.
    """

    matching: Matching
    similarity: Similarity | None
    source: Shape
    target: Shape
    options: MorphOptions
    match_options: MatchOptions | None = None
    self_intersections: np.ndarray | None = None
    co_rotation: Similarity | None = None

    def shape(self, step: int = -1) -> Shape:
        """The shape at ``step`` (the last by default): the source's topology (contours,
        faces) on the nodes of ``shapes[step]``."""
        return self.source.with_points(self.shapes[step])


def morph(source, target, *, matching=None, options: MorphOptions | None = None,
          progress: Callable[[int, float], None] | None = None, **overrides) -> Morph:
    """Estimate the intermediate shapes that take ``source`` into ``target``.

    Parameters
    ----------
    source, target : Shape or array_like, shape (m, d) and (n, d)
        The objects at times t and t+1, both 2D or both 3D. Shapes of several contours
        (``Shape(points, contours=...)``): every source contour is pulled onto its
        partner target contour alone and measured against it (method.md §2, "Objects of
        several contours"); contours without a partner are named in ``message``.
    matching : Matching, array_like of int (K, 2), MatchOptions or None, optional
        Correspondences: a Matching of these two objects, given ``(source index, target
        index)`` pairs (recorded as a Matching of method ``"given"``), or the options to
        compute them with :func:`modalmorph.match` (None: its defaults).
    options : MorphOptions, optional
        The rigid alignment first (``remove_rigid``: Horn's similarity from the matched
        pairs, section 5.2; the morph then holds only the non-rigid part), the physical
        model, loads, time integration and stop test (the module's docstring says why the
        defaults are what they are).
    progress : callable, optional
        Called after every step as ``progress(step, distance)``: the mean distance of the
        pulled nodes to their partners, in user units (with a co-rotation, that of the
        run on the turned source, which the shapes then turn with).
    **overrides
        :class:`MorphOptions` fields (``k=60``, ``max_steps=20``, ...) replacing those of
        ``options``; and the matcher's options MorphOptions does not have (``rotation``,
        ``method``, ``reject``, ``match_sigma``, ``match_modes``), used when the matching
        is computed here (ignored for a given Matching or pairs).

    Returns
    -------
    Morph

    Raises
    ------
    OptionError
        For an unknown or invalid option (a ValueError).
    ShapeError
        For invalid objects, pairs that do not belong to them, or no matched node (a
        ValueError).
    MorphDivergedError
        When the integration diverges (typically the explicit scheme with too large a k).
    """
    src = as_shape(source, "source")
    tgt = as_shape(target, "target")
    if src.dim != tgt.dim:
        raise ShapeError(f"source and target must have the same dimension, got "
                         f"{src.dim}D and {tgt.dim}D")
    options, match_options = _options(options, matching, overrides)
    given = not (matching is None or isinstance(matching, MatchOptions))
    if isinstance(matching, Matching):
        matching, match_options = matching.check(src.m, tgt.m), matching.options
    elif given:
        matching, match_options = Matching.given(matching, src.m, tgt.m), None
    if given:  # match() checks the contours of what it matches
        for name, shape in (("source", src), ("target", tgt)):
            if shape.dim == 2 and shape.ordered:
                check_contours(shape, name)
    with limit(max(src.m, tgt.m)):
        if not given:
            matching = match(src, tgt, options=match_options)
        pairs = matching.pairs
        similarity = turned = found = None
        work = src
        if options.remove_rigid:  # section 5.2: Horn's similarity from the matched pairs
            similarity = align(src.points[pairs[:, 0]], tgt.points[pairs[:, 1]], scale=True)
            work = src.with_points(similarity.apply(src.points))
        else:  # a large turn taken along the steps ("none": there turns strain)
            found = _pairs_similarity(src.points[pairs[:, 0]], tgt.points[pairs[:, 1]])
            if found is not None and found.angle > CO_ROTATE and options.free_motion != "none":
                turned = found
                work = src.with_points(turned.apply(src.points))
        sim = Simulation(work, tgt, pairs, options, matching.contours)
        run = sim.run(progress).result()
        if turned is not None:  # the turn taken along the steps, in the source's frame
            run = co_rotated(run, turned, src.points, tgt, sim.system.pairs)
    crossed = None
    if src.dim == 3 and src.has_faces:
        crossed = step_self_intersections(run.shapes, src.faces)
    elif src.dim == 2 and src.ordered:  # a contour folded through itself
        crossed = step_crossings(run.shapes[1:], src, (src, tgt))
        crossed = np.concatenate((np.zeros(1, crossed.dtype), crossed))  # np.r_[0, ...]
    turn = None  # the hint's turn, where folds come of a turn taken as straight paths
    if crossed is not None and np.any(crossed) and found is not None and turned is None:
        turn = found.angle
    said = intersection_sentence(crossed, model_nodes=run.resolved.model_nodes, nodes=src.m,
                                 turn=turn, contours=src.dim == 2)
    if sim.system.partners is not None:
        said += _unpaired(src, tgt, sim.system.partners)
    if src.dim == 3 and not src.ordered and not run.converged:
        said += unlike_sentence(pairs, src.m, tgt.m)
    folded = crossed is not None and bool(np.any(crossed[1:] > crossed[0]))
    said += _coarse_source(sim.stop, run, tgt, folded)
    said += _mirror_sentence(getattr(matching, "mirror", None))
    if turned is not None:
        said += (f"; the pairs' turn of {turned.angle:.0f} deg taken as a rigid motion along "
                 f"the steps (co_rotation)")
    fields = {**vars(run), "message": run.message + said}
    return Morph(**fields, matching=matching, similarity=similarity, source=src,
                 target=tgt, options=options, match_options=match_options,
                 self_intersections=crossed, co_rotation=turned)


def _coarse_source(stop, run, target: Shape, folded: bool) -> str:
    """What the message adds where the source may have too few nodes to follow the target
    (``stop.resolution``; for shapes of several contours, of the partner contours where
    the target drawn through the source's node count lies farthest from itself): where
    it has at most ``SHORT_SOURCE`` of the target's nodes and that allowance exceeds
    ``COARSE_SOURCE`` tolerances (a 4-node rectangle onto a circle; cmr10's 'I' of 28
    vertices onto its 'T' of 55 converged within 6 tolerances' allowance, the serifs
    cut), or fewer nodes than
    the target (at most ``SHORT_SOURCE`` of them) and the run stopped short or folded
    (raw glyph outlines of 8-22 vertices onto serif ones of 16-33: resampled to the
    target's count, 6 of 8 converge)."""
    floor, m, n, partners = stop.resolution
    coarse = m <= SHORT_SOURCE * n and floor > COARSE_SOURCE * stop.tolerance
    if not m or not (coarse or (m <= SHORT_SOURCE * n and (folded or not run.converged))):
        return ""
    src, tgt = ("the source", "the target's") if partners is None else \
        (f"source contour {partners[0]}", f"target contour {partners[1]}'s")
    if not coarse and target.dim == 3:  # a handful of vertices (stop.PLANE)
        return (f"; the source has {m} vertices for the target's {n}: its triangles are "
                "its shape; with more vertices (subdivided) it may follow the target closer")
    if not coarse:
        return (f"; {src} has {m} nodes for {tgt} {n}: resampled to more nodes (as many "
                "as the target's, evenly spaced) it may follow the target closer")
    unit = "input units" if target.frame is None else target.frame.unit
    floor *= run.tolerance / stop.tolerance
    return (f"; {src} has {m} nodes for {tgt} {n}: drawn through {m} nodes spread along "
            f"it, the target lies {floor:.3g} {unit} from itself on average, which the stop "
            "test allows; resample the source to more nodes to follow the target closer")


def _mirror_sentence(mirror: float | None) -> str:
    """What the message adds where the target looks like the source's mirror image
    (:attr:`Matching.mirror`)."""
    if not mirror:
        return ""
    return (f"; {mirror_said(mirror)}: no rotation takes a shape into its mirror image, so "
            "the pairs join unlike parts and the deformation is large; to compare the two "
            "shapes, mirror one input (flip it left to right)")


def _pairs_similarity(a: np.ndarray, b: np.ndarray) -> Similarity | None:
    """Horn's similarity of the pairs (``a`` onto ``b``), or None where they fix none (one
    pair in 2D, two in 3D; coincident points on either side)."""
    if len(a) < a.shape[1] or any(np.ptp(x, axis=0).max() <= COINCIDENT * max(
            1.0, np.abs(x).max()) for x in (a, b)):
        return None
    try:
        return align(a, b, scale=True)
    except ShapeError:
        return None


def co_rotated(run: Run, turn: Similarity, source: np.ndarray, target: Shape,
               pairs: np.ndarray) -> Run:
    """A run computed from the source turned by ``turn`` (its pairs' similarity) given in
    the source's frame: step k's shape is taken back by the inverse turn and forward by
    the part ``w_k`` of it (:meth:`Similarity.part`, about the source's centroid), ``w_k``
    the share of the run's whole displacement made by step k (its projection on the
    last step's, never decreasing: 0 at the source, 1 at the last step, whose shape stays
    as computed); loads turn with the shapes, mean distances are measured anew; the
    energies are the deformation's, which no similarity changes when similarities move
    freely (method.md §4, "Large turns"). A run that starts within the tolerance takes
    the turn in one step."""
    if run.steps == 0:
        unit = "input units" if target.frame is None else target.frame.unit
        run = replace(run, **{f: np.repeat(getattr(run, f), 2, axis=0) for f in (
            "shapes", "loads", "energy", "node_energy", "mean_distance")},
            message=stop_sentence(run.stop_reason, 1, run.distance, run.tolerance, unit))
    last = run.shapes[-1] - run.shapes[0]
    whole = float(np.vdot(last, last))  # a step at a time: no copy of every step's shape
    made = np.array([np.vdot(shape - run.shapes[0], last) for shape in run.shapes])
    w = np.maximum.accumulate(np.clip(made / whole, 0.0, 1.0)) if whole > 0 else \
        np.ones(len(made))
    w[0], w[-1] = 0.0, 1.0
    back, centre = turn.inverse(), source.mean(axis=0)
    shapes, loads = run.shapes.copy(), run.loads.copy()
    distance = run.mean_distance.copy()
    for k in range(len(shapes) - 1):
        part = turn.part(w[k], centre)
        shapes[k] = part.apply(back.apply(run.shapes[k]))
        loads[k] = run.loads[k] @ (part.rotation @ back.rotation).T
        distance[k] = mean_pair_distance(shapes[k], target.points, pairs)
    shapes[0] = source  # exactly, not through the turn and back
    return replace(run, shapes=shapes, loads=loads, mean_distance=distance)


def _unpaired(src: Shape, tgt: Shape, partners: np.ndarray) -> str:
    """The message's sentence on contours without a partner ('' when none), logged."""
    said = unpaired_sentence(src, tgt, partners, (
        "moved with its nearest pulled nodes, not measured by the stop test",
        "not measured by the stop test"))
    if said:
        log.info("morph: %s", said)
        return "; " + said
    return ""


def _options(options, matching, overrides: dict) -> tuple[MorphOptions, MatchOptions]:
    """The MorphOptions and MatchOptions of a call: ``overrides`` split by name."""
    if options is None:
        options = MorphOptions()
    elif not isinstance(options, MorphOptions):
        raise OptionError(f"options must be a MorphOptions, got {type(options).__name__}")
    morph_kw, match_kw = split_overrides(overrides, where="morph")
    base = matching if isinstance(matching, MatchOptions) else MatchOptions()
    return options.replace(**morph_kw), base.replace(**match_kw)
