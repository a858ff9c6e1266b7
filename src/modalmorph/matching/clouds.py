"""Fine correspondence between unordered 3D point sets (issue 16).

The modal matcher (:mod:`modalmorph.matching`) finds the pose and a smooth deformation
in the lowest modes, on at most ``COARSE_CLOUD`` nodes: where it takes the source is
right to about a coarse node spacing. :func:`refine` carries it the rest of the way,
coarse to fine: at each level both objects are summarised by the means of their nodes in
cubes of the level's width, weighted by the areas their nodes stand for (exact local
densities: random subsets of the nodes, used before, made the transport match their
chance clumps and drifted 2 target spacings away from the true correspondence at 100 000
nodes); the summaries are put in an entropic transport, each node weighing the area it
stands for (so that a surface sampled unevenly, as by a scanner, is covered by area, not
by count) and the marginals relaxed (unbalanced transport: a part that one object lacks,
a cap cut away, stays unpaired instead of pulling the rest over to cover it), and the
move it asks of the source is smoothed with Gaussians (the kernel of Sclaroff's element
(1)), each point weighing the share of its mass that found a partner, and applied to
every node. The last level uses the nodes
themselves, and its landings, noisy as the target is, are averaged over each node's
nearest neighbours (beyond the best similarity). Memory is linear in the node counts
(k-d trees, sparse transport plans).
"""

from __future__ import annotations

from itertools import count
from typing import NamedTuple

import numpy as np
from scipy.sparse import coo_matrix, csr_matrix
from scipy.spatial import cKDTree

from ..core.shape import even_subset
from ..threads import blas_threads

__all__ = ["Measures", "cube_levels", "finer", "measures", "refine", "stretch"]

_ROUNDS = 3  # transport and smoothing rounds of the last level, the nodes (not measured)
_FEW = 0.25  # a level with fewer cubes than this x the source nodes is cheap: more rounds
_COARSE_ROUNDS = (60, 10)  # rounds of a coarse level, cheap or not (100k blob: 3.67 -> 1.49)
_OVERRELAX = 2.0  # over-relaxation of every move (x3 diverged; x1: 1.71 against 1.52)
_NEIGHBOURS = 16  # nearest nodes: controls per node, and edges of the transport graph
_SINKHORN = 30  # scaling iterations of the transport
# Scaling iterations of a transport with more points than _MANY_POINTS on a side (blob,
# 100 000 points, 0/30/90 deg: median 1.19/0.96/1.33 -> 1.15/0.90/1.21 target spacings,
# p90 5.7/3.0/6.3 -> 6.1/1.8/4.9, 21 -> 19 CPU-s); smaller transports keep _SINKHORN.
_SINKHORN_MANY = 10
_MANY_POINTS = 10_000
# Such a transport's graph (k-d tree queries) found anew every this many rounds of a
# level, its weights every round (blob 100 000, 0/30/90 deg: 18.6 -> 11.6 CPU-s at 30;
# median 1.15/0.91/1.21 -> 1.16/0.92/1.26 spacings, p90 6.1/2.2/4.9 -> 5.5/2.3/6.0; every
# 8 rounds: 11.1 CPU-s, 0.92, p90 2.4 at 30 deg).
_REGRAPH = 4
_TEMPERATURE = 0.5  # width of the transport's Gaussian, x the level's cube width
# The transport's marginals relaxed (unbalanced): exponent of the scaling updates,
# rho / (rho + epsilon) for a mass penalty rho and the entropy epsilon (1: balanced).
# 1000 points, 20 % cut away as a cap, 30 deg: bunny 0.84 -> 0.14, blob 1.15 -> 0.33
# spacings after refine (0.7: 0.10, 0.23 but the uneven blob at 180 deg 1.61 -> 1.70).
# 0.95 rather than 0.9: an icosphere of 162 nodes onto an ellipsoid stretched x2 (642)
# converges (0.9: equilibrium at 1.02 x the tolerance, the stretched tips read as a part
# the sphere lacks); the 1000-point table of 7 shapes x cut/uneven/base x 30/90/180 deg
# within 0.02 spacings but the torus cut at 90 deg modulo its symmetry (1.29 -> 1.45),
# 100 000 points unchanged (blob 0.87, bunny 0.83), 1 000 000: blob 4.06 -> 4.27.
_RELAX = 0.955
# A source point whose nearest target point lies farther than this x the temperature goes
# nowhere (share 0) and is carried by its neighbours' moves, so a part that the target
# lacks is not dragged onto the nearest of what is there; target points keep pulling
# whatever is near them. benchmarks/match3d.py, median (p90) in target spacings, none ->
# 2: blob cut 10 000 at 30/180 deg 4.35/2.12 (16.7/6.7) -> 0.92/1.00 (5.7/6.2), bunny cut
# 10 000 0.88/0.91 (13.6/9.0) -> 0.61/0.67 (1.0/1.2), 1000-point cuts' p90 1.7-2.6 ->
# 0.5-1.5. Every edge beyond the reach dropped instead (targets too): blob cut 10 000 at
# 30 deg 0.80 (4.7), but an icosphere of 162 nodes onto an ellipsoid stretched x2 (642,
# benchmarks/morph3d.py --surfaces) no longer stretched to its tips (distance 37 x the
# tolerance; 4 temperatures: 12 x).
_REACH = 2.0
_WIDTH = 8.0  # smoothing width, x the level's cube width
_STEP = 2.0  # ratio of the cube widths of successive levels
_AVERAGE = 32  # last landings averaged over this many nearest nodes (100k blob 1.14 -> 0.88)
_AVERAGE_PASSES = 4  # passes of that average (measured together with _AVERAGE)
# Masses by the area a point stands for, from its 32nd nearest point: uneven sampling
# (density x20 across), 2000 points, 90 deg: bunny 2.37 -> 1.42, blob 5.83 -> 2.17
# spacings; even sampling as before (blob 10 000 at 180 deg 0.64, bunny 2000 0.37); from
# the 8th nearest: uneven 1.32 and 1.87 but the even blob 0.70, p90 1.12 -> 1.60.
_AREA_NEIGHBOURS = 32
# The affine start (:func:`stretch`): each object summarised in about this many points,
# whose dense entropic transport is annealed over _STRETCH_ROUNDS rounds from the first
# to the second of _STRETCH_HEAT (x the target's RMS radius), _STRETCH_SINKHORN scaling
# iterations a round. Icospheres of 162-2562 vertices onto ellipsoids of 162-2562 with
# radii (1.3, 1, 0.8) and (2, 1, 0.5): the ratios of the map's singular values within
# 0.071 of the radii's in 44 ms (30 rounds of 50: 0.051 in 191 ms; 10 of 10: 0.080 in
# 17 ms); 0.3 s at 100 000 points.
_STRETCH_CUBES = 300
_STRETCH_ROUNDS = 15
_STRETCH_HEAT = (0.5, 0.05)
_STRETCH_SINKHORN = 20


def _cells(p: np.ndarray, width: float) -> np.ndarray:
    """The label of the cube of a grid of side ``width`` holding each point, (k,): the
    cubes numbered in the lexicographic order of their integer coordinates."""
    index = np.floor(p / width).astype(np.int64)
    index -= index.min(axis=0)
    key = np.ravel_multi_index(index.T, index.max(axis=0) + 1)  # same order, one integer
    return np.unique(key, return_inverse=True)[1].ravel()


def _means(label: np.ndarray, p: np.ndarray, weight: np.ndarray | None = None
           ) -> tuple[np.ndarray, np.ndarray]:
    """Weighted mean point of each label, (c, 3), and the total weight of each, (c,)."""
    w = np.ones(len(p)) if weight is None else weight
    total = np.bincount(label, w)
    return np.stack([np.bincount(label, w * p[:, a]) for a in range(3)], axis=1) \
        / total[:, None], total


def _smoother(xc: np.ndarray, mass: np.ndarray, x: np.ndarray, width: float):
    """The linear map from residuals at the points ``xc`` (k, 3) of masses ``mass`` to a
    displacement field over every node ``x`` (m, 3), Gaussian-smoothed (width ``width``):
    the residuals are averaged onto control points ``width`` apart, and every node takes
    the Gaussian-weighted mean of its nearest controls (the kernel of Sclaroff's element
    (1)). Returned as a function of the residuals (k, 3) and of the share (k,) of each
    point's mass that found a partner: both means weigh it (normalised convolution), so
    points with nothing to go to are carried by their neighbours' moves."""
    c, _ = _means(_cells(xc, width), xc, mass)
    k = min(_NEIGHBOURS, len(c))
    tree = cKDTree(c)

    def weights(p, scale):
        dist, near = tree.query(p, k=k)
        dist, near = dist.reshape(len(p), k), near.reshape(len(p), k)
        w = np.exp(-0.5 * (dist / width) ** 2)
        w *= scale[:, None] / w.sum(axis=1, keepdims=True)
        return csr_matrix((w.ravel(), near.ravel(), np.arange(0, len(p) * k + 1, k)),
                          shape=(len(p), len(c)))

    gather = weights(xc, mass).T.tocsr()  # controls x points
    total = np.maximum(np.asarray(gather.sum(axis=1)).ravel(), 1e-12)
    spread = weights(x, np.ones(len(x)))

    def smooth(resid: np.ndarray, share: np.ndarray) -> np.ndarray:
        held = np.maximum(gather @ share, 1e-12 * total)  # per control
        move = (gather @ (share[:, None] * resid)) / held[:, None]
        held = held / total
        return (spread @ (held[:, None] * move)) / np.maximum(spread @ held, 1e-12)[:, None]

    return smooth


def _graph(z: np.ndarray, y: np.ndarray) -> csr_matrix:
    """The sparse graph of each side's ``_NEIGHBOURS`` nearest points on the other, (s, t)
    CSR with sorted indices: each edge's count (1, or 2 when it runs both ways)."""
    s, t = len(z), len(y)
    k = min(_NEIGHBOURS, s, t)
    workers = blas_threads(max(s, t))  # the cores the thread policy gives (same result)
    j1 = cKDTree(y).query(z, k=k, workers=workers)[1]
    i2 = cKDTree(z).query(y, k=k, workers=workers)[1]
    rows = np.r_[np.repeat(np.arange(s), k), i2.ravel()]
    cols = np.r_[j1.ravel(), np.repeat(np.arange(t), k)]
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(s, t)).tocsr()
    graph.sum_duplicates()
    return graph


def _transport(z: np.ndarray, mu: np.ndarray, y: np.ndarray, nu: np.ndarray,
               temperature: float, graph: csr_matrix | None = None
               ) -> tuple[np.ndarray, np.ndarray]:
    """Where each source point ``z`` (s, 3) of mass ``mu`` belongs on the target points
    ``y`` (t, 3) of masses ``nu``, and the share of its mass that goes anywhere (s,): the
    barycentre and the total of its row of an unbalanced entropic transport plan
    (Sinkhorn scaling with the marginals relaxed, ``_RELAX``) on the sparse graph of each
    side's nearest points on the other (or on ``graph``, :func:`_graph` of an earlier
    round), a source point with no target point within ``_REACH`` temperatures left
    unpaired. Matching the masses makes
    the source cover the target evenly, which slides it along the surface where nearest
    points alone would not; relaxing them, and the reach, let a part that one side lacks
    go unpaired, instead of pulling the rest of the other side over to cover it."""
    s, t = len(z), len(y)
    if graph is None:
        k = min(_NEIGHBOURS, s, t)
        workers = blas_threads(max(s, t))  # the cores the thread policy gives (same result)
        d1, j1 = cKDTree(y).query(z, k=k, workers=workers)
        d2, i2 = cKDTree(z).query(y, k=k, workers=workers)
        rows = np.r_[np.repeat(np.arange(s), k), i2.ravel()]
        cols = np.r_[j1.ravel(), np.repeat(np.arange(t), k)]
        dist = np.r_[d1.ravel(), d2.ravel()]
        P = coo_matrix((np.exp(-0.5 * (dist / temperature) ** 2), (rows, cols)),
                       shape=(s, t))
        P = P.tocsr()
        P.sum_duplicates()
        lone = d1[:, 0] > _REACH * temperature
    else:
        rows = np.repeat(np.arange(s), np.diff(graph.indptr))
        d = z[rows] - y[graph.indices]
        d2 = d[:, 0] ** 2 + d[:, 1] ** 2 + d[:, 2] ** 2  # np.sum's order, bit for bit, faster
        P = graph.copy()
        P.data = graph.data * np.exp(-0.5 * d2 / temperature**2)
        lone = np.minimum.reduceat(d2, graph.indptr[:-1]) > (_REACH * temperature) ** 2
    P.data = np.maximum(P.data, 1e-300)
    a, b = np.ones(s), np.ones(t)
    for _ in range(_SINKHORN if max(s, t) <= _MANY_POINTS else _SINKHORN_MANY):
        a = np.where(lone, 0.0, (mu / (P @ b)) ** _RELAX)
        b = (nu / np.maximum(P.T @ a, 1e-300)) ** _RELAX
    plan = P.copy()  # P scaled by a along its rows and b along its columns
    plan.data = P.data * np.repeat(a, np.diff(P.indptr)) * b[P.indices]
    row = np.asarray(plan.sum(axis=1)).ravel()
    return (plan @ y) / np.maximum(row, 1e-300)[:, None], np.minimum(row / mu, 1.0)


class Measures(NamedTuple):
    """What :func:`refine` measures of a source and a target before it moves anything
    (:func:`measures`), and how it builds their transports' graphs."""

    spacing: float  # the target's mean node spacing
    wx: np.ndarray  # the source's masses: the area each node stands for (_area)
    wy: np.ndarray  # the target's, scaled to the source's total
    near: np.ndarray  # each source node's _AVERAGE nearest nodes (_nearest)
    reuse: bool  # every level's graphs kept for _REGRAPH rounds, not only the largest


def measures(x: np.ndarray, y: np.ndarray, reuse: bool = False) -> Measures:
    """:class:`Measures` of the source ``x`` and the target ``y``, the same for every
    :func:`refine` of them, for a caller that refines one pair more than once; ``reuse``:
    keep every level's transport graph for ``_REGRAPH`` rounds (a large set: the caller's
    choice), not only the graphs of more than ``_MANY_POINTS`` points a side."""
    spacing = cKDTree(y).query(y, k=2, workers=blas_threads(len(y)))[0][:, 1].mean()
    wx, near = _nearest(x)
    return Measures(float(spacing), wx, _area(y) * (len(x) / len(y)), near, reuse)


def refine(x: np.ndarray, z: np.ndarray, y: np.ndarray, start: int, *,
           levels: int | None = None, smoothing: float = _WIDTH, decay: float = 0.0,
           known: Measures | None = None) -> np.ndarray:
    """Where the source lands on the target, refined coarse to fine.

    The first level summarises the target in cubes of about ``4 * start`` node counts'
    worth, each next level in cubes ``_STEP`` times smaller, the last in its nodes; at
    each level the source's nodes are summarised in the same cubes of their own frame
    ``x`` (so a cube's nodes stay together as they move), put in transport with the
    target's (:func:`_transport`), and the move of each summary towards its share is
    smoothed over the source (:func:`_smoother`) with a width of a few cubes and applied
    to every node, over-relaxed; many rounds on the coarse levels (cheap), few on the
    nodes themselves, whose landings are then averaged over their nearest neighbours
    beyond the best similarity (:func:`_average`).

    Parameters
    ----------
    x : ndarray, shape (m, 3)
        The source nodes (normalised frame: the displacement field is smooth over them).
    z : ndarray, shape (m, 3)
        Where the coarse match takes them, in the target's normalised frame.
    y : ndarray, shape (n, 3)
        The target nodes, normalised.
    start : int
        Source nodes of the coarse match (its resolution).
    levels : int, optional
        Stop after this many levels of cubes, coarsest first, and return the landings as
        they are then (no average); default: every level, the nodes last.
    smoothing : float, optional
        Width of the Gaussian smoothing of the moves, in the level's cube widths
        (``_WIDTH`` by default).
    decay : float, optional
        Fraction by which, every round of the first level, the landings' departure from
        their best affine map (:func:`_affine`) shrinks (0, the default: none): the
        affine map takes the pose instead of a smooth field that can hold a turn as
        well (:mod:`modalmorph.matching`, ``POSE_DECAY``).
    known : Measures, optional
        :func:`measures` of ``x`` and ``y`` (found here, ``reuse`` False, when not given).

    Returns
    -------
    ndarray, shape (m, 3)
        The refined positions of the source nodes.
    """
    m, n = len(x), len(y)
    spacing, wx, wy, near, reuse = measures(x, y) if known is None else known
    width = spacing * np.sqrt(n / max(start, 1))  # a source of under 4 nodes: start 0
    for level in count(1):
        width = max(width / _STEP, spacing)
        if width == spacing:
            label, xc, mu, yc, nu = np.arange(m), x, wx, y, wy
        else:
            label = _cells(x, width)
            xc, mu = _means(label, x, wx)
            yc, nu = _means(_cells(y, width), y, wy)
        smooth = _smoother(xc, mu, x, smoothing * width)
        rounds = _ROUNDS if width == spacing else _COARSE_ROUNDS[len(mu) >= _FEW * m]
        graph = None
        for i in range(rounds):
            zc = z if width == spacing else _means(label, z, wx)[0]
            if (reuse or max(len(mu), len(nu)) > _MANY_POINTS) and i % _REGRAPH == 0:
                graph = _graph(zc, yc)
            zt, share = _transport(zc, mu, yc, nu, _TEMPERATURE * width, graph)
            z = z + _OVERRELAX * smooth(zt - zc, share)
            if decay and level == 1 and width > spacing:
                pose = _affine(x, z)
                z = pose + (1.0 - decay) * (z - pose)
        if width == spacing:
            return _average(x, z, near)
        if level == levels:
            return z


def finer(start: int, levels: int) -> int:
    """The ``start`` from which :func:`refine` begins ``levels`` levels finer than from
    ``start``: its first cube width, ``sqrt(n / start) / _STEP`` target spacings, shrinks
    ``_STEP`` times a level."""
    return int(max(start, 1) * _STEP ** (2 * levels))


def cube_levels(n: int, start: int) -> int:
    """How many levels of cubes :func:`refine` runs on a target of ``n`` nodes from a
    coarse match of ``start`` nodes before the level of the nodes themselves."""
    width, levels = np.sqrt(n / max(start, 1)), 0  # in target spacings, as refine's
    while (width := max(width / _STEP, 1.0)) > 1.0:
        levels += 1
    return levels


def stretch(z: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The landings ``z`` (m, 3) of the source nodes moved by the affine map
    that best puts them in balanced transport with the target ``y`` (n, 3), each
    summarised by the means of its nodes nearest each of ``_STRETCH_CUBES`` of them
    spread evenly (:func:`even_subset`; their masses the node counts, so a flat or thin
    set has as few as a round one): a least-squares fit of the
    summaries' barycentres in the plan, annealed from a wide to a narrow transport, as
    CPD's affine registration with the transport's marginals balanced. What a similarity
    cannot do, a sphere stretched onto an ellipsoid, reaches the ellipsoid's tips; where
    the target lacks a part or is sampled unevenly it distorts the source, so the caller
    keeps it only where it brings the surfaces much closer (:mod:`modalmorph.matching`)."""
    def summary(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if len(p) <= _STRETCH_CUBES:
            return p, np.full(len(p), 1 / len(p))
        spread = p[even_subset(p, _STRETCH_CUBES)]
        c, mass = _means(cKDTree(spread).query(p)[1], p)
        return c, mass / mass.sum()

    def lse(a: np.ndarray, axis: int) -> np.ndarray:  # log-sum-exp (scipy's: 2 x slower)
        top = a.max(axis=axis, keepdims=True)
        return np.squeeze(top + np.log(np.exp(a - top).sum(axis=axis, keepdims=True)), axis)

    zc, mu = summary(z)
    yc, nu = summary(y)
    size = np.sqrt(np.mean(np.sum((yc - yc.mean(axis=0)) ** 2, axis=1)))
    lift = np.c_[zc, np.ones(len(zc))]
    affine = np.r_[np.eye(3), np.zeros((1, 3))]  # (4, 3): [A^T; t]
    hot, cold = _STRETCH_HEAT
    for r in range(_STRETCH_ROUNDS):
        heat = size * hot * (cold / hot) ** (r / (_STRETCH_ROUNDS - 1))
        q = lift @ affine
        cost = np.sum((q[:, None] - yc[None]) ** 2, axis=2) / (2 * heat**2)
        g = np.zeros(len(yc))
        for _ in range(_STRETCH_SINKHORN):  # log-domain balanced Sinkhorn
            f = np.log(mu) - lse(g[None] - cost, axis=1)
            g = np.log(nu) - lse(f[:, None] - cost, axis=0)
        plan = np.exp(f[:, None] + g[None] - cost)
        centre = (plan @ yc) / plan.sum(axis=1)[:, None]
        root = np.sqrt(mu)[:, None]
        affine = np.linalg.lstsq(lift * root, centre * root, rcond=None)[0]
    return np.c_[z, np.ones(len(z))] @ affine


def _nearest(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_area` of the points ``p`` (k, 3), and the indices of each one's ``_AVERAGE``
    nearest points (itself first) for :func:`_average`: one k-d tree query for both."""
    k = min(max(_AREA_NEIGHBOURS, _AVERAGE), len(p))
    dist, near = cKDTree(p).query(p, k=k, workers=blas_threads(len(p)))
    dist, near = dist.reshape(len(p), k), near.reshape(len(p), k)
    if len(p) <= _AREA_NEIGHBOURS:
        return np.ones(len(p)), near[:, :_AVERAGE]
    area = dist[:, _AREA_NEIGHBOURS - 1] ** 2
    return area / area.mean(), near[:, :_AVERAGE]


def _area(p: np.ndarray) -> np.ndarray:
    """The share of the surface each point stands for, mean 1, (k,): the squared distance
    to its ``_AREA_NEIGHBOURS``-th nearest point (1 for every point of a set too small)."""
    return _nearest(p)[0]


def _average(x: np.ndarray, z: np.ndarray, near: np.ndarray | None = None) -> np.ndarray:
    """The landings ``z`` (m, 3) of the nodes ``x`` (m, 3) with each node's move beyond
    the best affine map (least squares) replaced by its mean over the node's ``_AVERAGE``
    nearest nodes in ``x`` (``near``, :func:`_nearest`'s, found here when not given),
    ``_AVERAGE_PASSES`` times; an affine map is left exactly as
    it is (the mean of a stretch over a curved patch lies inside it: averaged beyond the
    best similarity, a sphere of 162 nodes stretched onto an ellipsoid (2, 1, 0.5)
    landed 1.5, not 2, along it, its tips unpaired)."""
    base = _affine(x, z)
    near = _nearest(x)[1] if near is None else near
    k = near.shape[1]
    mean = csr_matrix((np.full(near.size, 1.0 / k), near.ravel(),
                       np.arange(0, near.size + 1, k)), shape=(len(x), len(x)))
    move = z - base
    for _ in range(_AVERAGE_PASSES):
        move = mean @ move
    return base + move


def _affine(x: np.ndarray, z: np.ndarray) -> np.ndarray:
    """The best affine map (least squares) of the nodes ``x`` (m, 3) onto their landings
    ``z`` (m, 3), applied to ``x``."""
    lift = np.c_[x, np.ones(len(x))]
    return lift @ np.linalg.lstsq(lift, z, rcond=None)[0]
