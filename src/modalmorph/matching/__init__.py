"""Correspondence between two objects by modal matching (method.md §2).

Each object is modelled with Sclaroff's Gaussian element and its vibration modes are
computed (6); row ``i`` of ``Phi`` (one value per mode and axis) describes how node ``i``
moves in each mode, and nodes of the two objects that move alike are partners. Three
searches are offered:

``"local"``
    The paper's search: ``i <-> j`` when ``j`` is the best of row ``i`` and ``i`` the best
    of column ``j`` of the affinity matrix ``Z`` (8).
``"global"``
    An assignment over ``Z`` (:func:`scipy.optimize.linear_sum_assignment`), minus the
    pairs that cost far more than the typical pair (an assignment always returns
    ``min(m, n)`` pairs).
``"auto"`` (default)
    The modal description made invariant to what the paper leaves open (pose, eigenvector
    sign, rotations inside degenerate eigenspaces, mode order), combined with position,
    and alternated with Horn's alignment (:func:`modalmorph.core.align.align`) and a smooth
    deformation in the lowest modes. Ordered contours are matched by an order-preserving
    (cyclic for closed ones) search; point clouds by assignment. See :func:`match`.

This module holds :class:`Matching`, :func:`match` and the routes between the searches
(the paper's, the default one, large objects, 3D point sets); one module per stage holds
the rest, in the order of the default search:

:mod:`~modalmorph.matching.features`
    The modal model of each object, its features (:func:`modal_features`), the affinity
    (8) and the signatures with their cost (``prepare``).
:mod:`~modalmorph.matching.search`
    The searches: mutual best (the paper's), the order-preserving programme and the
    assignment over a placed source's cost, trusted pairs, the final pairs.
:mod:`~modalmorph.matching.pose`
    The pose search and the common-frame decision (``contour_pose``, ``cloud_pose``).
:mod:`~modalmorph.matching.alternation`
    Search, alignment and deformation in turn (``fits``, ``alternate``, ``keep_or_turn``).
:mod:`~modalmorph.matching.mirror`
    Whether a 2D target looks like the source's mirror image (``mirror_ratio``).
:mod:`~modalmorph.matching.coherent`
    The coherent pass of contours, which settles the along-contour position (``settle``).
:mod:`~modalmorph.matching.clouds`
    The coarse-to-fine refinement of 3D point sets (``refine``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import partial

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree

from ..core.align import Similarity, align
from ..core.dynamics import contour_partners
from ..core.quality import check_contours
from ..core.shape import Shape, as_shape, check_pairs, even_subset, spread_indices
from ..core.surfaces import facing_apart
from ..errors import OptionError, ShapeError
from ..options import METHODS, ROTATIONS, MatchOptions
from ..threads import blas_threads, limit
from .alternation import Placement, alternate, fits, keep_or_turn
from .clouds import cube_levels, finer, measures, refine, stretch
from .coherent import rigid_pose, settle
from .contours import keep_partners, match_contours
from .features import (
    FEATURE_SIGMA,
    MAX_MODEL_NODES,
    Problem,
    affinity,
    fix_signs,
    modal_features,
    prepare,
    reflected,
)
from .mirror import MIRROR, MIRROR_EXACT, MIRROR_SUSPECT, mirror_ratio
from .pose import cloud_pose, contour_pose, surface_gap, widened
from .search import Costs, final_pairs, mutual_best, plausible

__all__ = ["Matching", "match", "modal_features", "affinity", "DEFAULT_MODES",
           "FEATURE_SIGMA", "METHODS", "ROTATIONS", "MIRROR", "MIRROR_EXACT", "MIRROR_SUSPECT"]


DEFAULT_MODES = 24  # modes per node (48: precision/recall 0.92/0.90 against 0.95/0.95)
LARGE = 2000  # more nodes: matched on COARSE nodes, then refined (linear memory; not measured)
COARSE = 1000  # nodes of the coarse match of a large object (not measured)
NODES_PER_COARSE_CLOUD = 20  # 3D sets above LARGE: a coarse node per 20 (10 000 points: 2x faster)
COARSE_CLOUD = 3000  # at most (100 000 points: error 0.88-0.95 spacings, 1000 nodes 1.02-1.33)
# 3D sets above: matched on even subsets of this many nodes (blob, 1 000 000 points, 30 deg:
# subsets of 50 000 / 100 000 / 200 000: median 4.3 / 3.9 / 4.2 target spacings, 18 / 26 /
# 54 CPU-s; cell means instead of even subsets 6.2, random subsets 5.2; one more level of
# refine on all the nodes after the subsets', cubes a subset spacing wide: 4.0, 46 CPU-s).
FINE_CLOUD = 100_000
# Coarse or subset nodes whose moves carry a node (inverse-distance weights): the nodes so
# carried land as well as the subset's own (1M blob: 3.79 and 3.82 spacings).
CARRY = 4
# Passes of refine's first level, then FINE_PASSES of its second, each from the best similarity of
# the landings before it, on the subsets of a set above FINE_CLOUD (the pose the coarse match gives
# is 2-3 deg off, refine alone halves that, and the first level's passes stop at 0.7-0.9 deg from
# the truth's rotation whatever the start). 1 000 000 points, median pair error in target spacings
# (docs/issue25/scale.md): with first-level passes only (2, main): blob 0 / 30 / 90 / 180 deg 3.58
# / 2.70 / 3.77 / 5.24; 3 and the other levels smoothed 16 wide: 3.10 / 1.86 / 3.27 / 4.24; 1 + 3
# second-level passes: 2.03 / - / 3.06 / 3.92; 1 + 5: see the table there (90 deg 2.77, 180 deg
# 3.83; bunny 30 deg 2.10). On the landings of the blob's subset at 0 deg: the second level's
# passes take the turn from 0.92 deg to 0.54 / 0.34 / 0.32 deg, 3.10 -> 2.35 / 2.16 / 2.17.
POSE_PASSES = 1
FINE_PASSES = 5
# Smoothing width (refine's cube widths) of the second level's passes and of the levels after them
# (refine's own: 8): a finer transport under a stiffer field. After 2 passes of the first level,
# the levels from the second smoothed 4 / 8 / 16 / 24 wide, landings of the blob's subset at 0 deg
# 4.12 / 3.51 / 2.95 / -, 90 deg - / 3.65 / 3.27 / 3.75, 180 deg - / 4.70 / 4.19 / 4.53; the
# bunny's at 30 deg 1.87 / 1.39 / 2.09 / -. 16 at the first level: its field no longer turns (blob
# 0 deg: 2.2 deg off after 4 passes). Above CHOICE_NODES, _refined smooths refine's levels from the
# third as wide: on two independent samplings (benchmarks/match3d.py --variants resampled, 100 000
# points, 0 / 30 / 90 / 180 deg, with POSE_DECAY; median pair error in target spacings) blob 1.88 /
# 2.32 / 2.26 / 2.30 -> 1.77 / 2.12 / 1.85 / 2.06, bunny 1.20 / 1.07 / 1.14 / 1.11 -> 1.08 / 0.97 /
# 1.02 / 1.07 (the finer transports, 2.6-1 spacings wide, pulled by the samplings' chance clumps:
# blob 0 deg 1.98 -> 2.16 after the first level); base blob 0.96 / 0.84 / 0.94 / 0.91 -> 0.96 /
# 0.86 / 0.95 / 0.93, bunny 0.84 -> 0.85.
HUGE_SMOOTHING = 16.0
_SMOOTHING = {1: 8.0, 2: HUGE_SMOOTHING}  # per level of the passes
# refine() of a 3D point set up to FINE_CLOUD nodes starts this many times coarser than
# the start _coarse_landing gives (16 times coarser than the modal matcher's nodes instead
# of 4; benchmarks/match3d.py, median in target spacings, 1 -> 4: torus cut 1000 at 30
# deg modulo its symmetry 0.51 -> 0.31, blob cut 10 000 at 30/180 deg 0.76/1.18 ->
# 0.92/1.00, bone warp25 1000 at 90 deg 0.54 -> 0.61, bunny cut 10 000 within 0.01; with
# the reach of clouds.py dropping every long edge, 30 cases at 1000 and 12 at 10 000
# within 0.05 but those; blob 100 000 at 30 deg 0.89 -> 0.87, 14.0 -> 14.9 CPU-s).
REFINE_COARSER = 4
ALTERNATION_NODES = 400  # nodes in the alternation (at 1000: 0.52 -> 0.27 s, same precision)
MAX_AFFINITY = 4e7  # largest m x n affinity the paper's searches build (memory; not measured)
# Surface gaps compared up to this many target spacings (the pose search's _TRIM).
# 500 points, pose vs alternation (1000 twisted: the alternation kept): cow uneven and cut
# at 30 deg, after refine 4.38 -> 0.95, 1.74 -> 0.24 spacings; blob uneven 180 deg 3.06 -> 2.09.
_GAP_TRIM = 2.0
# The affine start of a 3D point set (clouds.stretch) is kept where it brings the surfaces
# closer than this x the pose's two-way gap (surface_gap, capped at _GAP_TRIM spacings).
# Icospheres of 162-2562 vertices onto ellipsoids (1.3-2 x as long as thick): 0.11-0.42;
# benchmarks/match3d.py at 1000 points (airplane, bone, cow cut; blob, torus, twisted
# uneven; bunny, twisted base): 0.95-4.1 (a part cut away pulls the balanced transport's
# affine map out of shape: airplane cut 30 deg 0.35 -> 5.19 spacings had it been kept).
_STRETCH_GAIN = 0.5
# Source nodes above which the two starts of refine (_refined) are tried on even subsets of
# about this many nodes, the first level's moves then carried to every node. Blob, 100 000
# points at 30/90/180 deg, gap after the first level from the similarity / from the
# landings: subsets of 1000-4000 nodes 0.98-1.02 (180 deg wrong), 10 000 0.99/0.97/0.96
# (median 0.84/0.93/0.87 spacings, main 0.85/1.11/1.22; 15.0-15.3 CPU-s, main 15.0-15.7).
CHOICE_NODES = 10_000
# Above CHOICE_NODES source nodes, refine's first level (of the subsets' starts and of the
# refinement after) shrinks the landings' departure from their best affine map by this fraction
# every round (clouds.refine's decay): a smooth field holds a turn as well as the pose does, and on
# two independent samplings nothing else pulls it back (blob, 100 000 points, benchmarks/match3d.py
# --variants resampled: the landings' best similarity 1.3 deg from the truth's at 0 deg). Median
# pair error in target spacings, 0 / 30 / 90 / 180 deg, none -> 0.02: blob resampled 2.83 / 2.39 /
# 2.23 / 2.45 -> 1.88 / 2.32 / 2.26 / 2.30; bunny resampled 1.22 / 1.09 / 1.15 / 1.12 -> 1.20 /
# 1.07 / 1.14 / 1.11; base (the target the source's points moved) blob 0.98 / 0.84 / 0.93 / 0.87 ->
# 0.96 / 0.84 / 0.94 / 0.91, bunny 0.83-0.84 unchanged; same CPU time. The similarity as its
# target, at 0 deg: 0.01 / 0.02 / 0.05: 2.03 / 1.88 / 2.41; at every level: 2.00; the subsets' or
# the refinement's first level alone: 2.00 / 2.14.
POSE_DECAY = 0.02
# refine (_refined) starts from the coarse landing only where, after its first level, that
# lies nearer the target's surface than this x the rigid pose's (coherent.rigid_pose: the
# modal match's similarity laid on the target by rigid CPD): on two samplings of one surface
# (match3d --variants resampled) they lie as near (0.985-1.14 at 2000 and 10 000 points) and
# the coarse deformation holds a turn (blob 2000 at 180 deg: 7 deg off the truth, rigid CPD
# 4.6); where the coarse deformation is real (twisted ellipsoid, warps of 25 %, a cap cut
# at 30 deg, on base) it lies nearer by 0.65-0.94. Above CHOICE_NODES the nearer is taken
# (100 000 points: the 0.95 rule took blob resampled 0 deg 1.77 -> 1.63 spacings, 180 deg
# 2.06 -> 2.81; the nearer 30 deg 2.12 -> 1.79, 90 deg 1.85 -> 1.88, 0 and 180 unchanged,
# 50 000 points at 180 deg 3.41 -> 3.15; base within 0.01).
_START_GAIN = 0.95
_REJECT = 16.0  # pairs costing more are dropped: 4 target spacings (not measured)


@dataclass(frozen=True, eq=False, repr=False)
class Matching:
    """Correspondences between the nodes of a source and a target object.

    Attributes
    ----------
    pairs : ndarray of intp, shape (K, 2)
        ``(source index, target index)`` per pair, sorted by source index.
    cost : ndarray, shape (K,)
        The cost of each pair: its entry in the affinity ``Z`` (8) for ``"local"`` and
        ``"global"``; for ``"auto"`` the combined modal and positional cost after the
        final alignment (squared distance in units of the target's node spacing).
    method : str
        The search used.
    modes : int
        Number of modes that described each node.
    sigma : float or None
        Gaussian width of the models, as a multiple of their mean node spacing, as given
        (``None``: chosen per model).
    similarity : Similarity or None
        For ``"auto"``: the similarity (in user coordinates) that maps the source onto the
        target, from Horn's method on the final pairs; ``None`` otherwise.
    nodes : tuple of int
        ``(m, n)``, the node counts of source and target.
    options : MatchOptions or None
        The options of the call that found them (recorded with a morph's parameters).
    contours : ndarray of intp, shape (P, 2), or None
        For objects of several contours: the partner contours, ``(source contour, target
        contour)`` per row (every pair joins partners; contours in no row are
        unmatched); None when both objects are one contour (or no contour).
    mirror : float or None
        For ``"auto"`` on 2D contours not held in one frame (``rotation`` not ``"none"``):
        where the target looks like the source's mirror image, how many times nearer
        the source reflected and matched again lies to it than the source placed by the
        pairs found (more than ``MIRROR``; at most ``1 / MIRROR_EXACT``, an exact mirror
        image); None otherwise. The pairs stay those of the source as given: no rotation
        takes a shape into its mirror image, so they join unlike parts.
    """

    pairs: np.ndarray
    cost: np.ndarray
    method: str
    modes: int
    sigma: float | None
    similarity: Similarity | None
    nodes: tuple
    options: MatchOptions | None = None
    contours: np.ndarray | None = None
    mirror: float | None = None

    @property
    def source(self) -> np.ndarray:
        """Source indices of the pairs, shape (K,)."""
        return self.pairs[:, 0]

    @property
    def target(self) -> np.ndarray:
        """Target indices of the pairs, shape (K,)."""
        return self.pairs[:, 1]

    def __len__(self) -> int:
        return self.pairs.shape[0]

    def __repr__(self) -> str:
        m, n = self.nodes
        how = self.method if not self.modes else f"{self.method}, {self.modes} modes"
        turned = "" if self.similarity is None else ", with a similarity"
        parts = "" if self.contours is None else f", {len(self.contours)} contour pair(s)"
        return f"Matching({len(self)} pairs of {m} -> {n} nodes, {how}{turned}{parts})"

    @classmethod
    def given(cls, pairs, m: int, n: int) -> Matching:
        """Given ``(source index, target index)`` pairs (K, 2) of objects of ``m`` source
        and ``n`` target nodes as a Matching of method ``"given"`` (sorted by source index,
        zero costs); :class:`ShapeError` when they are not such pairs."""
        pairs = check_pairs(pairs, m, n)
        pairs = pairs[np.argsort(pairs[:, 0], kind="stable")]
        return cls(pairs=pairs, cost=np.zeros(len(pairs)), method="given", modes=0,
                   sigma=None, similarity=None, nodes=(int(m), int(n)))

    def check(self, m: int, n: int) -> Matching:
        """This matching, if it belongs to objects of ``m`` source and ``n`` target nodes;
        else :class:`ShapeError` naming both node counts."""
        if tuple(self.nodes) != (m, n):
            raise ShapeError(f"the matching was found for {self.nodes[0]} source and "
                             f"{self.nodes[1]} target nodes, not for the {m} and {n} "
                             "given")
        check_pairs(self.pairs, m, n)
        return self


def _match_auto(src: Shape, tgt: Shape, n_modes: int, opts: MatchOptions,
                p: Problem | None = None) -> tuple[np.ndarray, np.ndarray, Similarity, np.ndarray]:
    """The default matcher (on ``p``, :func:`prepare`'s problem, when given); also where
    the fit takes every source node (m, d), in the target's user coordinates."""
    p = prepare(src, tgt, n_modes, opts.sigma, opts.rotation) if p is None else p
    sub = spread_indices(src, ALTERNATION_NODES)
    costs = Costs(src.normalized, tgt.normalized, p.F, tgt.spacing**2, p.ordered, p.closed)
    pose = contour_pose(p) if p.ordered else cloud_pose(p, costs, sub)
    order = np.arange(tgt.m)[::-1] if pose.reverse else np.arange(tgt.m)
    if pose.reverse:  # the target in search order (np.take: C order, rows read whole)
        costs = replace(costs, y=costs.y[order], F=np.take(costs.F, order, axis=1))
    for wide in (False, True):  # again, in units of the misfit, if none is near (a needle)
        costs = widened(costs, pose.sim) if wide else costs
        fit, final = fits(p, pose, costs, sub)
        placed = alternate(fit, pose.sim, pose.rotate)
        if p.rotation == "auto" and pose.common:
            placed = keep_or_turn(fit, final, placed, pose.turned)
        if src.dim == 3 and not p.ordered:
            placed = _nearer_surface(placed, pose.sim, costs, tgt.spacing)
        z, found = settle(fit, final, placed, p.ordered)
        pairs, cost = final_pairs(final, z, found, _REJECT if opts.reject is None else opts.reject)
        if len(pairs) > src.dim:
            break
    pairs[:, 1] = order[pairs[:, 1]]  # in the target's own order (np.c_'s 17 us spared)
    landed = tgt.to_user(z)
    return pairs, cost, align(src.points[pairs[:, 0]], tgt.points[pairs[:, 1]]), landed


def _match_one(src: Shape, tgt: Shape, n_modes: int, opts: MatchOptions
               ) -> tuple[np.ndarray, np.ndarray, Similarity, float | None]:
    """The default matcher, and :attr:`Matching.mirror` for 2D contours not held in one
    frame (up to ``LARGE`` nodes from the first match's modal features, reflected)."""
    large = max(src.m, tgt.m) > LARGE
    p = None if large else prepare(src, tgt, n_modes, opts.sigma, opts.rotation)
    pairs, cost, sim, _ = _match_large(src, tgt, n_modes, opts) if large else \
        _match_auto(src, tgt, n_modes, opts, p)
    if src.dim != 2 or not src.ordered or opts.rotation == "none":
        return pairs, cost, sim, None

    def again(reflect: bool) -> Similarity:  # the source, reflected or not, in any pose
        free, flip = opts.replace(rotation="free"), [-1.0 if reflect else 1.0, 1.0]
        if large:
            return _match_large(src.with_points(src.points * flip), tgt, n_modes, free)[2]
        q = reflected(p, "free") if reflect else replace(p, rotation="free")
        return _match_auto(q.src, tgt, n_modes, free, q)[2]
    return pairs, cost, sim, mirror_ratio(again, src, tgt, sim)


def _nearer_surface(placed: Placement, sim: Similarity, costs: Costs, spacing: float
                    ) -> Placement:
    """The alternation's placement of a 3D point set, or the pose ``sim`` alone where that
    lies nearer the target's surface (``surface_gap``, capped at ``_GAP_TRIM`` spacings):
    assignments drag the source to where a target is dense, or over a part it lacks."""
    posed = sim.apply(costs.x)
    gap = partial(surface_gap, y=costs.y, trim=_GAP_TRIM * spacing, tree=cKDTree(costs.y))
    return Placement(sim, posed) if gap(posed) < gap(placed.z) else placed


def _match_large(src: Shape, tgt: Shape, n_modes: int, opts: MatchOptions,
                 coarse: int = COARSE) -> tuple[np.ndarray, np.ndarray, Similarity, np.ndarray]:
    """The default matcher for large objects, in memory linear in the node counts.

    Both objects are matched on ``coarse`` nodes spread evenly over them; every source
    node is then carried by the fitted similarity and deformation of its nearest coarse
    nodes (inverse-distance weights) and paired with the target node nearest to where it
    lands (k-d trees); pairs farther than ``sqrt(reject)`` coarse target spacings are
    dropped.
    The correspondence is as good as the coarse one: within about one coarse spacing
    along a contour, not one node of the dense sampling. Also returns where every source
    node lands (the target's user coordinates), shape (m, d).
    """
    ci, cj = spread_indices(src, coarse), spread_indices(tgt, coarse)
    sub_s = Shape(src.points[ci], closed=src.closed, ordered=src.ordered)
    sub_t = Shape(tgt.points[cj], closed=tgt.closed, ordered=tgt.ordered)
    *_, landed_c = _match_auto(sub_s, sub_t, n_modes, opts)
    landed = src.points + _carried(sub_s.points, landed_c - sub_s.points, src.points,
                                   src.size)
    j = cKDTree(tgt.points).query(landed)[1]
    gap = np.linalg.norm(tgt.points[j] - landed, axis=1)
    h = tgt.spacing * tgt.size * tgt.m / len(cj)  # the coarse target's node spacing
    cost = (gap / h) ** 2  # in squared coarse target spacings, as on the coarse level
    keep = cost <= (_REJECT if opts.reject is None else opts.reject)
    pairs = np.c_[np.flatnonzero(keep), j[keep]]
    return pairs, cost[keep], align(src.points[pairs[:, 0]], tgt.points[pairs[:, 1]]), landed


def _match_cloud(src: Shape, tgt: Shape, n_modes: int, opts: MatchOptions
                 ) -> tuple[np.ndarray, np.ndarray, Similarity]:
    """The default matcher for unordered 3D point sets: where each source node lands
    (:func:`_cloud_landing`; above ``FINE_CLOUD`` nodes :func:`_huge_landing`, which has no affine
    stretch: a similarity and the refinement only), then each source node paired with the target
    node nearest to where it lands; pairs farther than ``sqrt(reject)`` target spacings are
    dropped. Cost in squared target spacings."""
    if max(src.m, tgt.m) > FINE_CLOUD:
        landed = _huge_landing(src, tgt, n_modes, opts)
    else:
        landed = _cloud_landing(src, tgt, n_modes, opts)
    y = tgt.normalized
    gap, j = cKDTree(y).query(landed, workers=blas_threads(len(y)))
    cost = (gap / tgt.spacing) ** 2
    reject = _REJECT if opts.reject is None else opts.reject
    keep = cost <= reject
    pairs = np.c_[np.flatnonzero(keep), j[keep]]
    if src.has_faces and tgt.has_faces and len(pairs) > 2:  # not inside out (FACING_SHARE)
        apart = facing_apart((src.points, src.faces), (tgt.points, tgt.faces), pairs)
        keep[pairs[apart, 0]], pairs = False, pairs[~apart]
    if len(pairs) < 2:  # nothing to align by
        raise ShapeError(
            f"only {len(pairs)} of the source's {src.m} nodes land within {np.sqrt(reject):.3g} "
            f"target spacings of a target node: too few to pair the objects (a source of "
            f"far fewer nodes than the target? resample them to comparable counts, or raise "
            f"reject)")
    return pairs, cost[keep], align(src.points[pairs[:, 0]], tgt.points[pairs[:, 1]])


def _cloud_landing(src: Shape, tgt: Shape, n_modes: int, opts: MatchOptions) -> np.ndarray:
    """Where each source node of a 3D point set lands on the target (the target's normalised
    frame), (m, 3): :func:`_coarse_landing`, stretched by
    :func:`~modalmorph.matching.clouds.stretch` where that brings the surfaces ``_STRETCH_GAIN``
    times closer, then :func:`modalmorph.matching.clouds.refine`, from ``REFINE_COARSER`` times
    coarser, from those landings or from their similarity alone (:func:`_refined`)."""
    landed, start = _coarse_landing(src, tgt, n_modes, opts)
    z, y = tgt.to_normalized(landed), tgt.normalized
    stretched, trim, tree = stretch(z, y), _GAP_TRIM * tgt.spacing, cKDTree(y)
    if surface_gap(stretched, y, trim, tree=tree) < _STRETCH_GAIN * surface_gap(
            z, y, trim, tree=tree):
        z = stretched
    return _refined(src.normalized, z, y, start // REFINE_COARSER)


def _refined(x: np.ndarray, z: np.ndarray, y: np.ndarray, start: int) -> np.ndarray:
    """:func:`~modalmorph.matching.clouds.refine` of the landings ``z`` (m, 3) of the
    source nodes ``x`` on the target ``y`` (normalised frames) from whichever of two starts
    lies nearer the target's surface after refine's first level
    (:func:`~modalmorph.matching.pose.surface_gap`, capped at ``_GAP_TRIM`` spacings): ``z``
    as it is, or its best similarity alone laid on the target by rigid CPD
    (:func:`~modalmorph.matching.coherent.rigid_pose`), without the deformation of the coarse
    match (carried from coarse nodes, it can hold the refinement away from the truth, or a
    turn, on two samplings of one surface). Up to ``CHOICE_NODES`` source nodes ``z`` is kept
    only where it lies ``_START_GAIN`` times nearer. Above, both are tried on even subsets,
    the first levels keep the deformation from taking the pose (``POSE_DECAY``), the levels
    keep their transports' graphs for a few rounds (``Measures.reuse``) and the levels from
    the third are smoothed ``HUGE_SMOOTHING`` cube widths wide."""
    i, j = np.arange(len(x)), np.arange(len(y))
    if len(x) > CHOICE_NODES:  # as wide cubes: an even subset's spacing grows as its count falls
        i = even_subset(x, CHOICE_NODES)
        j = even_subset(y, max(CHOICE_NODES * len(y) // len(x), 1))
    if start < 1 or cube_levels(len(j), start) == 0:  # a source of under 16 nodes, or no
        return refine(x, z, y, start)  # level before the nodes': nothing to compare
    large, posed = len(x) > CHOICE_NODES, align(x, z).apply(x)
    starts, yj = (z, rigid_pose(posed, y).apply(posed)), y[j]
    tree, known = cKDTree(yj), measures(x[i], yj, large)  # the subsets' spacing and masses
    trim, once = _GAP_TRIM * known.spacing, partial(refine, decay=POSE_DECAY * large)
    firsts = [once(x[i], s[i], yj, start, levels=1, known=known) for s in starts]
    gaps = [surface_gap(f, yj, trim, tree=tree) for f in firsts]
    best = int(gaps[1] < gaps[0]) if large else int(gaps[0] >= _START_GAIN * gaps[1])
    z, begun = firsts[best], starts[best]
    if len(i) < len(x):  # the subset's first level carried to every node, and all measured
        z, known = begun + _carried(x[i], z - begun[i], x, 1.0), measures(x, y, large)
    if not large or cube_levels(len(y), finer(start, 1)) < 2:
        return refine(x, z, y, finer(start, 1), known=known)  # from its second level on
    z = once(x, z, y, finer(start, 1), levels=1, known=known)  # its second level
    return once(x, z, y, finer(start, 2), smoothing=HUGE_SMOOTHING, known=known, decay=0.0)


def _coarse_landing(src: Shape, tgt: Shape, n_modes: int, opts: MatchOptions
                    ) -> tuple[np.ndarray, int]:
    """Where the modal matcher takes each source node of a 3D point set (the target's
    user coordinates), (m, 3), above ``LARGE`` nodes on one coarse node per
    ``NODES_PER_COARSE_CLOUD`` (from ``COARSE`` to ``COARSE_CLOUD``); and the ``start``
    of :func:`~modalmorph.matching.clouds.refine` for that resolution."""
    m = max(src.m, tgt.m)
    coarse = min(max(m // NODES_PER_COARSE_CLOUD, COARSE), COARSE_CLOUD)
    if m > LARGE:
        *_, landed = _match_large(src, tgt, n_modes, opts, coarse)
    else:
        *_, landed = _match_auto(src, tgt, n_modes, opts)
    return landed, min(src.m, coarse) // 4


def _huge_landing(src: Shape, tgt: Shape, n_modes: int, opts: MatchOptions) -> np.ndarray:
    """Where each source node lands (the target's normalised frame), (m, 3), for sets above
    ``FINE_CLOUD`` nodes, matched on even subsets of both (the same fraction of each, the larger
    ``FINE_CLOUD`` nodes): the subset's :func:`_coarse_landing`; ``POSE_PASSES`` times the first
    level of :func:`~modalmorph.matching.clouds.refine`, then ``FINE_PASSES`` times its second
    (smoothed ``HUGE_SMOOTHING`` cube widths wide), each from the best similarity of the landings
    so far (the pose, without the deformation that came with it); the levels of ``refine`` from its
    third, smoothed as wide; and every source node carried by the similarity of the subset's
    landings (Horn) plus the rest of the move of its ``CARRY`` nearest subset nodes
    (inverse-distance weights)."""
    keep = FINE_CLOUD / max(src.m, tgt.m)
    x = src.points[even_subset(src.normalized, int(keep * src.m))]
    sub_s = Shape(x, ordered=False)
    sub_t = Shape(tgt.points[even_subset(tgt.normalized, int(keep * tgt.m))], ordered=False)
    landed, start = _coarse_landing(sub_s, sub_t, n_modes, opts)
    landed, xs, ys = sub_t.to_normalized(landed), sub_s.normalized, sub_t.normalized
    once = partial(refine, x=xs, y=ys, known=measures(xs, ys))  # masses found once
    for level, passes in ((1, POSE_PASSES), (2, FINE_PASSES)):  # refine's first levels
        for _ in range(passes):
            posed = sub_t.to_normalized(align(x, sub_t.to_user(landed)).apply(x))
            landed = once(z=posed, start=finer(start, level - 1), levels=1,
                          smoothing=_SMOOTHING[level])
    landed = once(z=landed, start=finer(start, 2), smoothing=HUGE_SMOOTHING)  # its third
    landed = tgt.to_normalized(sub_t.to_user(landed))
    sim = align(x, landed)
    return sim.apply(src.points) + _carried(x, landed - sim.apply(x), src.points, src.size)


def _carried(nodes: np.ndarray, moves: np.ndarray, points: np.ndarray, size: float
             ) -> np.ndarray:
    """The moves of ``nodes`` carried to ``points``: the inverse-distance mean of the moves
    of each point's ``CARRY`` nearest nodes, (p, d)."""
    dist, near = cKDTree(nodes).query(points, k=CARRY, workers=blas_threads(len(points)))
    w = 1.0 / np.maximum(dist, 1e-12 * size)
    w /= w.sum(axis=1, keepdims=True)
    return np.einsum("ik,ikd->id", w, moves[near])


def _match_paper(src: Shape, tgt: Shape, n_modes: int, opts: MatchOptions):
    """The paper's searches over the affinity (8): ``"local"`` or ``"global"``."""
    if src.m * tgt.m > MAX_AFFINITY:
        raise ShapeError(f"method={opts.method!r} builds the full {src.m} x {tgt.m} "
                         f"affinity matrix (8), too large here; use method='auto', which "
                         f"matches large objects in linear memory")
    phi1, _ = modal_features(src, n_modes, sigma=opts.sigma)
    phi2, _ = modal_features(tgt, n_modes, sigma=opts.sigma)
    Z = affinity(phi1, fix_signs(phi1, phi2))  # (8)
    if opts.method == "local":
        pairs = mutual_best(Z)
    else:
        r, c = linear_sum_assignment(Z)
        pairs = np.c_[r, c][plausible(Z[r, c], 3.0 if opts.reject is None else opts.reject)]
    return pairs, Z[pairs[:, 0], pairs[:, 1]], None


def _match_several(src: Shape, tgt: Shape, opts: MatchOptions) -> Matching:
    """Objects of several contours (:mod:`~modalmorph.matching.contours`): the default
    matcher per pair of partner contours; the paper's searches over all the nodes, less
    the pairs joining contours that are not partners."""
    if not (src.ordered and tgt.ordered):
        raise ShapeError("an object of several contours is matched with another ordered "
                         "object (contours), not with a point set or a surface")
    mirror = None
    if opts.method == "auto":
        pairs, cost, sim, partners, mirror = match_contours(
            src, tgt, opts.rotation, partial(match, options=opts))
        n_modes = DEFAULT_MODES if opts.modes is None else int(opts.modes)
    else:
        n_modes = DEFAULT_MODES if opts.modes is None else int(opts.modes)
        n_modes = min(n_modes, src.dim * min(src.m, tgt.m, MAX_MODEL_NODES))
        with limit(max(src.m, tgt.m)):
            pairs, cost, sim = _match_paper(src, tgt, n_modes, opts)
        partners = contour_partners(src.contour_of, tgt.contour_of, pairs)
        keep = keep_partners(src, tgt, pairs, partners)
        pairs, cost = pairs[keep], cost[keep]
    order = np.argsort(pairs[:, 0], kind="stable")
    return Matching(pairs=pairs[order].astype(np.intp), cost=cost[order], method=opts.method,
                    modes=n_modes, sigma=opts.sigma, similarity=sim, nodes=(src.m, tgt.m),
                    options=opts, contours=partners, mirror=mirror)


def _shapes(source, target) -> tuple[Shape, Shape]:
    """Both objects as shapes of one dimension; a 2D contour must not cross itself, and a
    closed one must have an area."""
    src, tgt = as_shape(source, "source"), as_shape(target, "target")
    for name, shape in (("source", src), ("target", tgt)):
        if shape.dim == 2 and shape.ordered:
            check_contours(shape, name)  # simple, and closed ones with an area
    if src.dim != tgt.dim:
        raise ShapeError(f"source and target must have the same dimension, got "
                         f"{src.dim}D and {tgt.dim}D")
    return src, tgt


def match(source, target, *, options: MatchOptions | None = None, **overrides) -> Matching:
    """Correspondences between the nodes of two objects by modal matching (6)-(8).

    Parameters
    ----------
    source, target : Shape or array_like, shape (m, d) and (n, d)
        The two objects, of the same dimension ``d`` in {2, 3}; ``m`` and ``n`` may differ.
        Arrays become :class:`Shape` with its defaults (2D: closed ordered contour; 3D:
        unordered point cloud); pass a ``Shape`` for an open contour (``closed=False``)
        or an unordered 2D set (``ordered=False``). Shapes of several contours
        (``Shape(points, contours=...)``; 2D contours or 3D polylines): partner
        contours are found and matched pair by pair
        (:mod:`~modalmorph.matching.contours`, ``Matching.contours``).
    options : MatchOptions, optional
        ``method`` (``"auto"``: the default matcher, invariant to translation, rotation,
        scale, start node and direction of a contour; ``"local"``, ``"global"``: the
        paper's searches over the affinity (8)), ``rotation`` (for ``"auto"``: ``"none"``
        when the objects share one frame, ``"free"`` for unrelated poses, ``"auto"`` to
        keep the common frame unless another pose costs clearly less), ``modes``,
        ``sigma`` and ``reject``: see :class:`~modalmorph.options.MatchOptions`.
    **overrides
        Fields of ``options`` by name, e.g. ``match(a, b, rotation="none")``.

    Returns
    -------
    Matching

    Raises
    ------
    ShapeError
        If an object is invalid (see :class:`Shape`) or the dimensions differ.
    OptionError
        If an option is unknown or out of range.
    """
    if options is None:
        options = MatchOptions()
    elif not isinstance(options, MatchOptions):
        raise OptionError(f"options must be a MatchOptions, got {type(options).__name__}")
    opts = options.replace(**overrides) if overrides else options
    src, tgt = _shapes(source, target)
    if src.contours or tgt.contours:
        return _match_several(src, tgt, opts)
    n_modes = DEFAULT_MODES if opts.modes is None else int(opts.modes)
    n_modes = min(n_modes, src.dim * min(src.m, tgt.m, MAX_MODEL_NODES))
    mirror = None
    with limit(max(src.m, tgt.m)):
        if opts.method != "auto":
            pairs, cost, sim = _match_paper(src, tgt, n_modes, opts)
        elif src.dim == 3 and not (src.ordered or tgt.ordered):
            pairs, cost, sim = _match_cloud(src, tgt, n_modes, opts)
        else:
            pairs, cost, sim, mirror = _match_one(src, tgt, n_modes, opts)
    order = np.argsort(pairs[:, 0], kind="stable")
    return Matching(pairs=pairs[order].astype(np.intp), cost=cost[order], method=opts.method,
                    modes=n_modes, sigma=opts.sigma, similarity=sim, nodes=(src.m, tgt.m),
                    options=opts, mirror=mirror)
