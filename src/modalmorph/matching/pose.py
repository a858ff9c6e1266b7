"""The pose search of the default matcher (method.md §2).

Candidate rotations start at the rotation between the objects' principal axes (so they
turn with either input); with ``rotation="auto"`` the identity and small turns about it
join them (the common frame). Each is scored on a coarse subset of the nodes: for ordered
contours by the total of the order-preserving search with both directions of the target
(:func:`contour_pose`, branch and bound), for point sets by a few rigid rounds of
assignment and alignment (:func:`cloud_pose`). The outcome is a :class:`Pose`.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace
from functools import partial

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from ..core.align import Similarity, align
from ..core.shape import spread_indices
from .features import Problem
from .search import (
    REPEAT,
    SKIP,
    Costs,
    monotone_totals,
    ordered_pairs,
    trusted_pairs,
)

__all__ = ["Pose", "contour_pose", "cloud_pose", "surface_gap", "widened"]

_COARSE_NODES = 64  # nodes of each contour in the pose search (not measured)
_COARSE_NODES_CLOUD = 256  # the same for point sets, which have 4 poses only (not measured)
_ANGLES = 24  # rotations tried by the pose search in 2D (not measured)
_POSE_BATCH = 4  # rotations searched at once by the branch and bound (speed; not measured)
_POSE_ROUNDS = 2  # rigid rounds per point-set pose: after one a wrong pose can cost less
COMMON_ANGLE = 20.0  # degrees: poses this near the identity are the common frame (not measured)
_SMALL_TURNS = (-10.0, 10.0)  # degrees, 2D common-frame poses besides the identity (not measured)
_TURN_EVIDENCE = 7.5  # degrees: a turn below it is no turn (candidates 10 degrees apart)
_COMMON_MARGIN = 2.0  # common frame / best total: shared hearts <= 1.51, turned hands >= 1.65
# Or unless the common frame's pose places the source as near the target as the best pose
# within _COMMON_GAP (RMS of both ways' nearest-node distances, 2D): common / best is
# 0-1.00 for symmetric outlines in one frame (a circle, an ellipse, a square, a hexagon, a
# ring onto themselves or x1.02: their totals differ by rounding, -6e-14 against 1e-15, or
# 2.5x, and the pairs turned 120-180 deg), and where the totals chose a turn on 60 heart,
# 146 hand and 248 glyph pairs turned 25-180 deg, at least 1.10 (glyph 'm' at 180 deg;
# hands 1.42). In 3D the common frame's pose is the trimmed ICP from the identity without
# a turn, and its score (squared distances) within _COMMON_GAP_3D of the best: symmetric
# bodies stretched in one frame (trimesh's torus, cylinder, capsule, box, icosphere, cone
# x [0.8, 1, 1.5] and 4 other stretches) at most 1.44 (the box; pairs turned 180 deg
# before: torus, capsule, box); benchmarks/match3d.py's 6 shapes turned 30-180 deg
# (base, cut, uneven, warp25; 1000 points) at least 1.78 (sampled unevenly), else 1.96.
# A mean hides a small feature (a cylinder's knob, a torus's bump: turned 45-180 deg,
# 1.03-1.56): the farthest of both ways' nearest distances must also lie within
# _COMMON_FARTHEST of the turned pose's (the knob 1.59-3.89; the stretched bodies 0.48-1.00).
_COMMON_GAP = 1.05
_COMMON_GAP_3D = 1.6
_COMMON_FARTHEST = 1.25
_FRAME_ROUNDS = 3  # Procrustes rounds turning the common frame's pose for _as_near (not measured)
# 3D point sets: trimmed nearest-point rounds (ICP) from many starts on few nodes, the
# best few again on more nodes; the trimming distance shrinks from the size (normalised:
# 1) to _TRIM coarse spacings. Measured on benchmarks/match3d.py, 1000 points, medians in
# target spacings (see docs/issue25): before, blob uneven 180 deg 30.3, bunny cut 90 deg
# 21.0; with 25 starts (principal axes x 24 turns) the bunny cut 90 deg still 11.3.
_STARTS = 120  # turns spread evenly over all rotations, besides the principal axes' 24
_SCOUT_NODES = 64  # nodes of each object in the first stage (not measured otherwise)
_SCOUT_ROUNDS = 10  # rounds of the first stage (not measured otherwise)
_FINALISTS = 16  # starts carried to the second stage (8: blob uneven 180 deg lost), ended
_DISTINCT = 20.0  # degrees apart at least (else the bone at 30 deg: 16 of one wrong pose)
# Second-stage scores within _CLOSE x the best: the modal total decides. A near-symmetric
# body's flips score within 2 %: by the score alone (_CLOSE 1) the twisted ellipsoid at
# 90 deg 21.1 spacings (1.37 with 1.05) and the bone sampled unevenly at 30 deg 46.3
# (1.18). The total counts what one object lacks too (the blob cut at 20 000 points
# 111.6; with the cheapest 60 % of the pairs 6.7, but the uneven bone 43.4).
_CLOSE = 1.05
_ICP_ROUNDS = 30  # rounds of the second stage, on _ICP_NODES nodes
# Nodes of each object in the second stage, whose close poses (_CLOSE) are then settled
# by _POSE_ROUNDS rigid rounds of assignment each (as the modal pose is) before the
# modal totals decide. benchmarks/match3d.py, median in target spacings, main (256, not
# settled) / 1024 not settled / 512 settled / 1024 settled: blob 100 000 at 30 deg
# 1.46 / 0.86 / 0.89 / 0.87 (with 256 the ICP pose won, 4.4 deg from the truth's best
# rotation; the modal pose, 2.3 deg, scored 7 % worse). 1000 points, 7 shapes x 4
# variants x 30/90/180 deg (docs/issue25/README.md): blob cut 180 deg 0.99 / 0.31 /
# 0.30 / 0.30, blob uneven 30 deg 2.52 / 1.65 / 2.25 / 1.59, torus warp25 30 deg 20.4 /
# 0.31 / 0.31 / 0.31, twisted 30 deg 2.17 / 2.00 / 1.32 / 1.32, but bone uneven 180 deg
# 1.41 / 13.0 / 1.41 / 1.36, twisted cut 30 and uneven 90 deg 1.76, 2.48 / 1.77, 2.32 /
# 21.4, 30.2 / 1.81, 2.28; kept worse: twisted 180 deg 1.46 -> 2.11, twisted uneven
# 180 deg 3.14 -> 4.60, bone uneven 90 deg 14.5 -> 48.4 (wrong either way); the rest
# in docs/issue25/scale.md. 1000 points: 0.66 -> about 1.0 s a case.
_ICP_NODES = 1024
_TRIM = 2.0  # coarse target spacings (3: the bone cut, 180 deg, 12.0; 2: 0.41; 1.5: same)

@dataclass(frozen=True, eq=False)
class Pose:
    """The outcome of the pose search: the similarity to start from, the same pose with a
    turn allowed, whether the target is searched reversed, whether the alternation may
    rotate and whether a turned start is to be tried too (``common``)."""

    sim: Similarity
    turned: Similarity
    reverse: bool = False
    rotate: bool = True
    common: bool = False


def _axes(x: np.ndarray) -> np.ndarray:
    """Principal axes of centred points as the columns of a proper rotation, each axis
    signed by the third moment along it: they turn with the points (rotation covariant)."""
    _, e = np.linalg.eigh(x.T @ x)
    e = e * np.where(np.sum((x @ e) ** 3, axis=0) < 0, -1.0, 1.0)
    # the determinant of orthonormal axes is +-1: its sign by the 2 x 2 formula in 2D
    det = e[0, 0] * e[1, 1] - e[0, 1] * e[1, 0] if len(e) == 2 else np.linalg.det(e)
    if det < 0:
        e[:, 0] = -e[:, 0]
    return e


def _turns(t: np.ndarray) -> np.ndarray:
    """2D rotations (r, 2, 2) by the angles ``t`` (radians): ``[[c, -s], [s, c]]`` (the
    array np.stack made, filled in place)."""
    c, s = np.cos(t), np.sin(t)
    out = np.empty((len(t), 2, 2))
    out[:, 0, 0], out[:, 0, 1], out[:, 1, 0], out[:, 1, 1] = c, -s, s, c
    return out


def _rotations(d: int, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Candidate rotations (r, d, d) taking x towards y for the pose search: in 2D a circle
    of angles starting at the rotation between the principal axes (so the search turns
    with either input); in 3D the proper rotations between the principal axes, with every
    choice of axis signs."""
    ex, ey = _axes(x), _axes(y)
    if d == 2:
        R0 = ey @ ex.T
        return _CIRCLE @ R0
    out = []
    for signs in itertools.product([1.0, -1.0], repeat=3):
        R = ey @ np.diag(signs) @ ex.T
        if np.linalg.det(R) > 0:
            out.append(R)
    return np.array(out)


# the fixed 2D turns of the pose search (made once: 25 us a match)
_CIRCLE = _turns(2 * np.pi * np.arange(_ANGLES) / _ANGLES)
_SMALL = _turns(np.radians(_SMALL_TURNS))
_COMMON_COS = np.cos(np.radians(COMMON_ANGLE))
_CIRCLE.setflags(write=False)
_SMALL.setflags(write=False)


def _pose_candidates(d: int, x: np.ndarray, y: np.ndarray, rotation: str
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rotations (r, d, d) tried by the pose search, a mask of those that keep the common
    frame (within ``COMMON_ANGLE`` of the identity) and the cosines of their angles.
    ``rotation="none"``: the identity alone; ``"free"``: :func:`_rotations`; ``"auto"``:
    both, with small turns about the identity in 2D."""
    eye = np.eye(d)[None]
    if rotation == "none":
        return eye, np.ones(1, bool), np.ones(1)
    rots = _rotations(d, x, y)
    if rotation == "auto" and d == 2:  # the identity first, then small turns about it
        rots = np.concatenate([eye, _SMALL, rots])
    elif rotation == "auto":
        rots = np.concatenate([eye, rots])
    cos = (np.trace(rots, axis1=1, axis2=2) - (d - 2)) / 2  # cos of the rotation angle
    return rots, cos >= _COMMON_COS - 1e-12, cos


def _pose_search(C: np.ndarray, low: np.ndarray, candidates: np.ndarray, closed: bool,
                 skip: float, repeat: float) -> tuple[float, np.ndarray, bool, int]:
    """The cheapest pose of an ordered contour among ``candidates`` (indices into the
    rotations of ``C`` (r, m, n), whose rows' least costs are ``low`` (r, m)), each with
    both directions of the target.

    Branch and bound: an order-preserving total is at least the sum of each row's cheapest
    choice, so rotations are searched best bound first and the search stops once no bound
    left can beat the best total found. Returns the total, the cost matrix of the best
    pose (target reversed when it won reversed), whether it is reversed and its index.
    """
    bound = np.minimum(low[candidates], skip).sum(axis=1)
    ranked = candidates[np.argsort(bound)]
    bound = np.sort(bound)
    best_total, best = np.inf, None
    for start in range(0, len(ranked), _POSE_BATCH):
        if bound[start] >= best_total:
            break
        r = ranked[start:start + _POSE_BATCH]
        Cr = C[r]
        Cb = np.concatenate([Cr, Cr[:, :, ::-1]])  # forward, reversed target order
        total = monotone_totals(Cb, skip, repeat, closed)
        k = int(np.argmin(total))
        if total[k] < best_total:
            best_total, best = float(total[k]), (Cb[k], k >= len(r), r[k % len(r)])
    return best_total, *best


def _coarse_costs(p: Problem):
    """The pose search's cost (r, mc, nc) of every candidate rotation on evenly spread
    subsets ``ci``, ``cj`` of the nodes and its rows' least (r, mc) (the search's bound,
    made with the costs in 2D: 0.1 ms less at 70 nodes); also the mask of the
    common-frame rotations and of those turned enough to show a turn
    (:func:`_pose_candidates`)."""
    x, y = p.src.normalized, p.tgt.normalized
    coarse = _COARSE_NODES if p.ordered else _COARSE_NODES_CLOUD
    ci, cj = spread_indices(p.src, coarse), spread_indices(p.tgt, coarse)
    hc2 = p.tgt.spacing**2 * (p.tgt.m / len(cj)) ** 2
    rots, near, cos = _pose_candidates(p.src.dim, x, y, p.rotation)
    xc, yc = x[ci], y[cj]
    evidence = cos < np.cos(np.radians(_TURN_EVIDENCE))
    if p.src.dim == 2:  # compiled, einsum's products added in its order: bitwise equal
        from ._dp import pose_costs
        D, low = pose_costs(rots, xc, yc, float(hc2), p.F[np.ix_(ci, cj)])
        return D, low, ci, cj, near, evidence, rots
    z = np.einsum("rab,ib->ria", rots, xc)
    zy = np.einsum("ria,ja->rij", z, yc)
    D = (np.sum(z**2, -1)[:, :, None] + np.sum(yc**2, -1)[None, None, :] - 2 * zy) / hc2
    D += p.F[np.ix_(ci, cj)]
    return D, D.min(axis=2), ci, cj, near, evidence, rots


def _as_near(z_common: np.ndarray, z_best: np.ndarray, y: np.ndarray) -> bool:
    """Whether the source nodes placed by the common frame's pose, ``z_common``, lie as
    near the target nodes ``y`` as placed by the best pose, ``z_best``, within
    ``_COMMON_GAP``: the RMS of both ways' nearest-node distances, whatever the pairs (a
    symmetric outline fits alike in its symmetric poses, and only the signatures'
    rounding tells them apart)."""
    tree = cKDTree(y)
    gap = partial(surface_gap, y=y, trim=np.inf, tree=tree)
    common = min(gap(z_common), gap(_turned_in_frame(z_common, y, tree)))
    return bool(common <= _COMMON_GAP**2 * gap(z_best))


def _turned_in_frame(z: np.ndarray, y: np.ndarray, tree) -> np.ndarray:
    """``z`` turned about the origin (the normalised frames' centroid) by a few rounds of
    nearest-node Procrustes, as far as the common frame allows (``COMMON_ANGLE``): a
    symmetric outline turned by a few degrees fits its turned copy there as well as in a
    symmetric pose (a 5-fold star sampled 5-fold, turned 3 degrees, was paired 72 degrees
    off: its candidates lie 10 degrees apart, the symmetric one nearest the turn)."""
    rot = np.eye(z.shape[1])
    for _ in range(_FRAME_ROUNDS):
        zr = z @ rot
        u, _, vt = np.linalg.svd(zr.T @ y[tree.query(zr)[1]])
        turn = rot @ u @ vt  # zr @ (u vt) nearest the partners (orthogonal Procrustes)
        angle = Similarity(turn, 1.0, np.zeros(len(turn))).angle
        if np.linalg.det(turn) < 0 or angle > COMMON_ANGLE:
            break
        rot = turn
    return z @ rot


def contour_pose(p: Problem) -> Pose:
    """Pose of an ordered contour: the cheapest rotation and target direction of the
    order-preserving search on the coarse nodes; with ``rotation="auto"`` the best
    common-frame pose unless another is cheaper by more than ``_COMMON_MARGIN``."""
    C, low, ci, cj, near, evidence, rots = _coarse_costs(p)
    repeat = REPEAT if len(ci) > len(cj) else np.inf
    total, Cb, reverse, r = _pose_search(C, low, np.arange(len(C)), p.closed, SKIP, repeat)
    rotate, common = p.rotation != "none", False
    if p.rotation == "auto":
        total_near, Cn, rev_near, rn = (total, Cb, reverse, r) if near[r] else _pose_search(
            C, low, np.flatnonzero(near), p.closed, SKIP, repeat)
        if total_near <= _COMMON_MARGIN * total or _as_near(  # x[ci] only where needed
                *(p.src.normalized[ci] @ rots[k].T for k in (rn, r)), p.tgt.normalized[cj]):
            Cb, reverse, common, rotate = Cn, rev_near, evidence[r], False
    jj, _ = ordered_pairs(Cb, p.closed, SKIP, repeat)
    if np.count_nonzero(jj >= 0) <= p.src.dim:  # none near (a circle onto a needle): all
        jj, _ = ordered_pairs(Cb, p.closed, np.inf, repeat)  # in order, none left out
    keep = jj >= 0
    if reverse:
        jj = len(cj) - 1 - jj
    xs, ys = p.src.normalized[ci[keep]], p.tgt.normalized[cj[jj[keep]]]
    turned = align(xs, ys)  # the same fit twice where the pose may rotate (immutable)
    return Pose(turned if rotate else align(xs, ys, rotate=False), turned, reverse, rotate,
                common)


def _trimmed_icp(x: np.ndarray, y: np.ndarray, sim: Similarity, trim: float,
                 rotate: bool, rounds: int = _ICP_ROUNDS) -> tuple[float, Similarity]:
    """Nearest-point rounds (ICP) from ``sim``, both ways (each placed source node to its
    nearest target node and each target node to its nearest placed source node), pairs
    farther than a distance that shrinks from the size (1) to ``trim`` left out: a part
    missing on either side pulls nothing. Returns the score, the mean of both ways'
    squared nearest distances capped at ``trim`` (independent of the sampling density and
    of what the other side lacks), and the similarity."""
    ty = cKDTree(y)
    shrink = trim ** (2.0 / rounds)  # reaches trim halfway
    cut = 1.0
    for _ in range(rounds + 1):
        z = sim.apply(x)
        ds, js = ty.query(z)
        dt, it = cKDTree(z).query(y)
        near_s, near_t = ds <= cut, dt <= cut
        rows = np.r_[np.flatnonzero(near_s), it[near_t]]
        if len(rows) < 4 or np.all(rows == rows[0]):  # one source node near: no fit
            break
        sim = align(x[rows], np.r_[y[js[near_s]], y[near_t]], rotate=rotate)
        cut = max(cut * shrink, trim)
    return surface_gap(sim.apply(x), y, trim, tree=ty), sim


def _score(x: np.ndarray, y: np.ndarray, sim: Similarity, trim: float) -> float:
    """:func:`surface_gap` of the source nodes ``x`` placed by ``sim``."""
    return surface_gap(sim.apply(x), y, trim)


def surface_gap(z: np.ndarray, y: np.ndarray, trim: float, *, tree=None) -> float:
    """The mean of both ways' squared nearest distances capped at ``trim`` between the
    placed source nodes ``z`` (m, 3) and the target nodes ``y`` (n, 3): how far apart
    the surfaces lie, whatever the density of their sampling and what one of them lacks.
    ``tree``: ``y``'s k-d tree, where the caller has it."""
    ds = (cKDTree(y) if tree is None else tree).query(z)[0]
    dt = cKDTree(z).query(y)[0]
    return float(np.mean(np.minimum(ds, trim) ** 2) + np.mean(np.minimum(dt, trim) ** 2))


def widened(costs: Costs, sim: Similarity) -> Costs:
    """``costs`` with distances in units of the source's misfit placed by ``sim`` (the
    root mean square of both ways' nearest-node distances) where that exceeds the
    target's spacing: for shapes so unlike (a circle onto a needle) that no pair lies
    within ``SKIP`` of the target's."""
    return replace(costs, h2=max(costs.h2, surface_gap(sim.apply(costs.x), costs.y, np.inf) / 2))


def _even_turns(n: int) -> np.ndarray:
    """``n`` rotations spread evenly over all rotations (super-Fibonacci spirals, Alexa
    2022), (n, 3, 3)."""
    s = np.arange(n) + 0.5
    r, big = np.sqrt(s / n), np.sqrt(1 - s / n)
    a, b = 2 * np.pi * s / np.sqrt(2), 2 * np.pi * s / 1.533751168755204288118041
    return Rotation.from_quat(np.c_[r * np.sin(a), r * np.cos(a), big * np.sin(b),
                                    big * np.cos(b)]).as_matrix()


def _spread(shape, k: int) -> tuple[np.ndarray, float]:
    """``k`` nodes spread over a shape (normalised) and ``_TRIM`` times their spacing."""
    p = shape.normalized[spread_indices(shape, k)]
    return p, _TRIM * cKDTree(p).query(p, k=2)[0][:, 1].mean()


def _distinct(sims: list) -> list:
    """The first ``_FINALISTS`` similarities of ``sims`` whose rotations differ from
    every earlier one kept by more than ``_DISTINCT`` degrees."""
    kept, cos = [], np.cos(np.radians(_DISTINCT))
    for sim in sims:
        if all((np.trace(sim.rotation.T @ k.rotation) - 1) / 2 < cos for k in kept):
            kept.append(sim)
        if len(kept) == _FINALISTS:
            break
    return kept


def _surface_pose(p: Problem, costs: Costs, sub: np.ndarray, modal: Similarity) -> Pose:
    """Pose of a 3D point set: trimmed ICP (:func:`_trimmed_icp`) from many starts (the
    identity with ``rotation="auto"``, the principal axes' rotation with each of the 24
    turns that permute and sign them, ``_STARTS`` turns spread over all rotations), first
    briefly on ``_SCOUT_NODES`` nodes, then the ``_FINALISTS`` best fully on
    ``_ICP_NODES``. The score counts where the surfaces lie, not how densely
    they are sampled nor what one of them lacks, so that uneven sampling and partial
    overlap cannot make a wrong pose cheaper; but it hardly tells the poses of a
    near-symmetric body apart, so of the poses scoring within ``_CLOSE`` of the best
    (the pose of :func:`_assignment_pose`, ``modal``, among them), each settled by the
    same rigid rounds of assignment as ``modal`` (:func:`_rigid_rounds`), the one of
    least modal total (the search on ``sub``, modal signatures included) wins, polished
    by the trimmed ICP again (the assignments of those rounds shift and shrink a pose
    when the target is sampled unevenly or lacks a part: cow, 500 points sampled
    unevenly, 0.35 -> 4.96 target spacings from the truth); with
    ``rotation="auto"`` one within ``COMMON_ANGLE`` of the identity wins instead unless
    its total exceeds ``_COMMON_MARGIN`` x the least (the common frame, as in 2D), the
    identity's start always among the second stage's (a sphere scores alike in every pose:
    it had lost there, and the pairs turned the sphere 169-171 degrees)."""
    src, tgt = p.src, p.tgt
    rotate = p.rotation != "none"
    rots = np.eye(3)[None]
    if rotate:
        ex, ey = _axes(src.normalized), _axes(tgt.normalized)
        turns = Rotation.create_group("O").as_matrix()  # the 24 that permute and sign axes
        rots = np.concatenate([ey @ turns @ ex.T, _even_turns(_STARTS)])
        rots = np.concatenate([np.eye(3)[None], rots]) if p.rotation == "auto" else rots
    zero = np.zeros(3)
    (xs, ys, trim) = (*_spread(src, _SCOUT_NODES)[:1], *_spread(tgt, _SCOUT_NODES))
    scouts = [_trimmed_icp(xs, ys, Similarity(r, 1.0, zero), trim, rotate, _SCOUT_ROUNDS)
              for r in rots]
    order = sorted(range(len(rots)), key=lambda r: scouts[r][0])
    if p.rotation == "auto":  # the identity's always goes on: a featureless body (a sphere)
        order.remove(0)       # scores alike in every pose, and the common frame must compete
        order.insert(0, 0)
    best = _distinct([scouts[r][1] for r in order])
    (x, y, trim) = (*_spread(src, _ICP_NODES)[:1], *_spread(tgt, _ICP_NODES))
    tried = [_trimmed_icp(x, y, sim, trim, rotate) for sim in best]
    tried.append((_score(x, y, modal, trim), modal))
    low = min(score for score, _ in tried)
    close = [_rigid_rounds(costs, sub, sim, rotate)[1] for score, sim in tried
             if score <= _CLOSE * low]
    totals = [trusted_pairs(costs, sim.apply(costs.x), sub)[1] for sim in close]
    best = int(np.argmin(totals))
    turned = p.rotation == "auto" and close[best].angle > COMMON_ANGLE
    if p.rotation == "auto":  # the common frame, as in 2D: kept unless far costlier
        near = [k for k, s in enumerate(close) if s.angle <= COMMON_ANGLE]
        if near and min(totals[k] for k in near) <= _COMMON_MARGIN * totals[best]:
            best, turned = min(near, key=totals.__getitem__), False
    sim = _trimmed_icp(x, y, close[best], trim, rotate)[1]
    if turned:  # unless the common frame lies as near, its farthest node too
        still = _trimmed_icp(x, y, Similarity(np.eye(3), 1.0, np.zeros(3)), trim, False)
        if still[0] <= _COMMON_GAP_3D * low and \
                _farthest(still[1], x, y) <= _COMMON_FARTHEST * _farthest(sim, x, y):
            sim = _trimmed_icp(x, y, still[1], trim, rotate)[1]
    return Pose(sim, sim, False, rotate, False)


def _farthest(sim: Similarity, x: np.ndarray, y: np.ndarray) -> float:
    """The largest of both ways' nearest-node distances between the source nodes ``x``
    placed by ``sim`` and the target nodes ``y``: what a small feature left unmatched
    shows, which a mean hides."""
    z = sim.apply(x)
    return float(max(cKDTree(y).query(z)[0].max(), cKDTree(z).query(y)[0].max()))


def _rigid_rounds(costs: Costs, sub: np.ndarray, sim: Similarity, rotate: bool
                  ) -> tuple[float, Similarity]:
    """``_POSE_ROUNDS`` rounds of assignment on ``sub`` and alignment to its pairs from
    ``sim``: the total of the last assignment and the similarity after it."""
    x, y = costs.x, costs.y
    for _ in range(_POSE_ROUNDS):
        good, total = trusted_pairs(costs, sim.apply(x), sub)
        sim = align(x[good[:, 0]], y[good[:, 1]], rotate=rotate)
    return total, sim


def cloud_pose(p: Problem, costs: Costs, sub: np.ndarray) -> Pose:
    """Pose of a point set: in 3D :func:`_surface_pose`. In 2D each candidate's coarse
    assignment, then ``_POSE_ROUNDS``
    rigid rounds of search and alignment on ``sub`` from each (the coarse costs of poses
    180 degrees apart can be close); the cheapest, or with ``rotation="auto"`` the best
    common-frame pose unless another is cheaper by more than ``_COMMON_MARGIN``."""
    if p.src.dim == 3:
        return _surface_pose(p, costs, sub, _assignment_pose(p, costs, sub).sim)
    return _assignment_pose(p, costs, sub)


def _assignment_pose(p: Problem, costs: Costs, sub: np.ndarray) -> Pose:
    """The pose of :func:`cloud_pose` in 2D: by coarse assignments and rigid rounds."""
    C, _, ci, cj, near, evidence, _ = _coarse_costs(p)
    x, y = costs.x, costs.y
    rotate, common = p.rotation != "none", False
    tried = []
    for r, c in map(linear_sum_assignment, C):
        tried.append(_rigid_rounds(costs, sub, align(x[ci[r]], y[cj[c]], rotate=rotate),
                                   rotate))
    best = min(range(len(tried)), key=lambda r: tried[r][0])
    if p.rotation == "auto":
        near_best = min(np.flatnonzero(near), key=lambda r: tried[r][0])
        x = costs.x[sub]
        if tried[near_best][0] <= _COMMON_MARGIN * tried[best][0] or _as_near(
                tried[near_best][1].apply(x), tried[best][1].apply(x), costs.y):
            common, rotate, best = evidence[best], False, near_best
    return Pose(tried[best][1], tried[best][1], False, rotate, common)
