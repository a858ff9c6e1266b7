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
    and alternated with Horn's alignment (:func:`modalmorph.align.align`) and a smooth
    deformation in the lowest modes. Ordered contours are matched by an order-preserving
    (cyclic for closed ones) search; point clouds by assignment. See :func:`match`.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree

from .align import Similarity, align
from .element import check_sigma
from .match3d import refine
from .model import FEModel
from .shape import Shape, as_shape, resample, spread_indices

__all__ = ["Matching", "match", "modal_features", "affinity", "METHODS", "ROTATIONS"]

METHODS = ("auto", "local", "global")
ROTATIONS = ("auto", "free", "none")

# Defaults chosen by measurement on the families of benchmarks/matching.py (3 pairs each,
# auto method, precision/recall overall): sigma 1 -> 0.90/0.75, sigma 2 -> 0.95/0.95,
# sigma 3 -> Gram matrix singular on a 160-node model; 48 modes -> 0.92/0.90 vs 24.
DEFAULT_MODES = 24  # modes describing each node
# Nominal Gaussian width of the matching models, x mean node spacing; sigma=None uses it
# where the Gram matrix stays well conditioned, else the largest width that does
# (element.auto_sigma: about 1.55 for an evenly sampled circle or letter).
DEFAULT_SIGMA = 2.0
MAX_MODEL_NODES = 160
# Objects with more nodes are matched on COARSE nodes, then refined (linear memory).
LARGE = 2000
COARSE = 1000
# The matcher's alternation of search and fits runs on at most this many source nodes.
ALTERNATION_NODES = 400
# Largest m x n affinity matrix the paper's local/global searches may build.
MAX_AFFINITY = 4e7  # larger objects are modelled on an evenly spread subset of nodes
_COARSE_NODES = 64  # resolution of the pose search of the default method
_COARSE_NODES_CLOUD = 256  # the same for point sets, which have only 4 candidate poses
_ANGLES = 24  # rotations tried by the pose search in 2D
_POSE_BATCH = 4  # rotations searched at once by the branch and bound of the pose search
# Point sets: rigid rounds from each of the 4 poses before one is chosen. Measured on the
# scale benchmark's blob (1000-3000 nodes): after one round a wrong pose can still cost
# less (2000 nodes: 2.23 against 2.29), after two the right one is clearly cheapest.
_POSE_ROUNDS = 2
# rotation="auto": poses within this angle of the identity keep the common frame ...
_COMMON_ANGLE = 20.0  # degrees
_SMALL_TURNS = (-10.0, 10.0)  # degrees, 2D common-frame poses beside the identity
# A best pose turned by less than this is no evidence of a turn (the finest candidates are
# 10 degrees apart): the turned alternation is then not tried (it cost 6 of the 23 ms of
# matching hands 0 -> 3 at 70 nodes, one frame).
_TURN_EVIDENCE = 7.5
# ... and win unless the best pose's search total is below theirs by more than this factor.
# Measured (total of the best common-frame pose / best total): the 16 shared heart pairs
# (ED -> ES, one image frame) 1.00-1.51, seven of them above 1.0 (their best pose turned
# 60-165 degrees); four hand pairs turned by 25 / 45 / 60 / 90 / 180 degrees 1.65-3.7 /
# 2.1-7.4 / 3.1-12.7 / 5.2-17.6 / 6.2-22.1. Below 45 degrees the common-frame start still
# finds the turn: the alignment in the alternation is free.
_COMMON_MARGIN = 2.0
# rotation="auto" in the common frame: the alternation is run without a turn and with one;
# the turn wins when it lowers the search's objective below this fraction. Measured
# (turned / unturned): the 16 shared heart pairs 0.67-1.00 (unturned they match radially;
# turned, near-circular ones drift by up to 15 degrees and fold), hand pairs turned by 25
# and 30 degrees whose pose search chose the common frame: 0.37.
_TURN_GAIN = 0.5


@dataclass(frozen=True, eq=False)
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
    shape : tuple of int
        ``(m, n)``, the node counts of source and target.
    """

    pairs: np.ndarray
    cost: np.ndarray
    method: str
    modes: int
    sigma: float | None
    similarity: Similarity | None
    shape: tuple

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


# --------------------------------------------------------------------------- modal model


def modal_features(shape, n_modes: int, *, sigma: float | None = None,
                   max_nodes: int = MAX_MODEL_NODES) -> tuple[np.ndarray, np.ndarray]:
    """The lowest modes of an object, one row per node, made comparable between objects.

    The object is modelled in its normalised frame (6). When it has more than
    ``max_nodes`` nodes, the model is built on an evenly spread subset and the modes are
    evaluated at every node through the element's own interpolation,
    ``u(x) = sum_k g_k(x) psi_k`` (1)-(3) with ``Phi = (I kron G) psi``; at the model's
    nodes this is exactly ``Phi``. Each mode is scaled to unit RMS displacement per node,
    so objects with different node counts are comparable (method.md §2).

    Parameters
    ----------
    shape : Shape or array_like, shape (m, d)
    n_modes : int
        Number of modes, lowest first.
    sigma : float or None, optional
        Gaussian width as a multiple of the model's mean node spacing; ``None``:
        ``DEFAULT_SIGMA`` or less, as :func:`modalmorph.element.auto_sigma` chooses.
    max_nodes : int, optional
        Largest model built (the eigenproblem is dense: cost grows as nodes cubed).

    Returns
    -------
    phi : ndarray, shape (m, d, n_modes)
        Displacement of node ``i`` along axis ``a`` in mode ``k``, in the normalised frame.
    frequencies : ndarray, shape (n_modes,)
    """
    shape = as_shape(shape)
    if shape.ordered:
        # contours: model an arc-length-uniform resampling, so that sigma (a multiple of the
        # mean spacing) is well conditioned whatever the input's sampling, and the modes
        # do not depend on how densely either contour was traced
        model_shape = Shape(resample(shape.points, min(shape.m, max_nodes),
                                     closed=shape.closed), closed=shape.closed)
    else:
        subset = spread_indices(shape, max_nodes)
        model_shape = shape if len(subset) == shape.m else Shape(
            shape.points[subset], closed=shape.closed, ordered=shape.ordered)
    model = FEModel(model_shape, sigma=sigma, nominal_sigma=DEFAULT_SIGMA)
    n_modes = min(int(n_modes), model.dim * model.m)
    modes = model.modes(n_modes)
    if model_shape is shape:
        phi = modes.node_shapes()
    else:  # u(x_i) = sum_k g_k(x_i) psi_k (1)-(4), at every node
        at = model.modes_at(modes, model_shape.to_normalized(shape.points))
        phi = at.reshape(shape.dim, shape.m, n_modes).transpose(1, 0, 2)
    rms = np.sqrt(np.mean(np.sum(phi**2, axis=1), axis=0))
    return phi / rms, modes.frequencies


def _fix_signs(phi1: np.ndarray, phi2: np.ndarray) -> np.ndarray:
    """Flip each target mode to the sign under which its per-node displacement vectors lie
    closest (symmetric Chamfer distance) to the source's: the sign is arbitrary (§2)."""
    out = phi2.copy()
    for k in range(phi1.shape[2]):
        a = phi1[:, :, k]
        tree_a = cKDTree(a)
        costs = []
        for s in (1.0, -1.0):
            b = s * phi2[:, :, k]
            costs.append(cKDTree(b).query(a)[0].mean() + tree_a.query(b)[0].mean())
        if costs[1] < costs[0]:
            out[:, :, k] *= -1
    return out


def affinity(phi1: np.ndarray, phi2: np.ndarray) -> np.ndarray:
    """Modal affinity (8): ``Z_ij = sum_a sum_k (phi1[i, a, k] - phi2[j, a, k])^2``.

    Parameters
    ----------
    phi1 : ndarray, shape (m, d, k)
    phi2 : ndarray, shape (n, d, k)

    Returns
    -------
    ndarray, shape (m, n)
    """
    a = phi1.reshape(phi1.shape[0], -1)
    b = phi2.reshape(phi2.shape[0], -1)
    Z = np.sum(a**2, axis=1)[:, None] + np.sum(b**2, axis=1)[None, :] - 2 * a @ b.T
    return np.maximum(Z, 0.0)


# --------------------------------------------------------------------------- searches


def _mutual_best(Z: np.ndarray) -> np.ndarray:
    """Pairs ``(i, j)`` with ``j`` best in row ``i`` and ``i`` best in column ``j``."""
    j = np.argmin(Z, axis=1)
    i = np.arange(Z.shape[0])
    keep = np.argmin(Z, axis=0)[j] == i
    return np.c_[i[keep], j[keep]]


def _reject(cost: np.ndarray, factor: float) -> np.ndarray:
    """Mask of the pairs whose cost is not implausibly high: at most ``factor`` times the
    median cost (and at least the median, so that a clean matching loses nothing)."""
    if cost.size == 0:
        return np.ones(0, bool)
    return cost <= factor * max(float(np.median(cost)), 1e-12)


def _forward(C: np.ndarray, skip: float, repeat: float, keep: bool):
    """The dynamic programme of :func:`_monotone` over the rows of ``C`` (..., m, n).

    Returns ``(F, T)``: ``F[i, ..., 1 + j]`` is the best cost of rows < i whose last
    target is <= j (``F[i, ..., 0]``: every one of them skipped) and ``T[i, ..., j]`` the
    best cost of rows <= i with row i matched to j. Within a row the best predecessor is a
    running minimum (``np.minimum.accumulate``): a few vectorised O(n) operations per row.
    With ``keep=False`` only two rows of ``F`` are kept (the last is ``F[m % 2]``) and
    ``T`` is None.
    """
    *batch, m, n = C.shape
    F = np.empty((m + 1 if keep else 2, *batch, n + 1))
    T = np.empty((m if keep else 1, *batch, n))
    F[0] = 0.0
    repeats = np.isfinite(repeat)
    prev = np.empty((*batch, n))
    for i in range(m):
        Fi, Fn = (F[i], F[i + 1]) if keep else (F[i % 2], F[1 - i % 2])
        Ti = T[i] if keep else T[0]
        if repeats and i > 0:  # previous target < j, or == j at a price
            np.add(Fi[..., 1:], repeat, out=prev)
            np.minimum(prev, Fi[..., :-1], out=prev)
            np.add(C[..., i, :], prev, out=Ti)
        else:  # previous target < j
            np.add(C[..., i, :], Fi[..., :-1], out=Ti)
        np.minimum.accumulate(Ti, axis=-1, out=Fn[..., 1:])
        np.add(Fi[..., 1:], skip, out=prev)  # or row i skipped
        np.minimum(Fn[..., 1:], prev, out=Fn[..., 1:])
        Fn[..., 0] = skip * (i + 1)
    return F, (T if keep else None)


def _monotone(C: np.ndarray, skip: float, repeat: float = np.inf
              ) -> tuple[np.ndarray, float]:
    """Order-preserving matching: ``j(i)`` non-decreasing in ``i``, each source node matched
    (cost ``C[i, j]``) or skipped (cost ``skip``), a target reused by consecutive source
    nodes at the extra cost ``repeat`` (``inf``: one-to-one); minimal total cost.

    ``C`` has shape (m, n). Returns ``j`` (m,), -1 where the source node is unmatched, and
    the total cost. The backtrack recomputes each decision on the one column it visits.
    """
    m, n = C.shape
    F, T = _forward(C, skip, repeat, keep=True)
    j = np.full(m, -1, np.intp)
    repeats = np.isfinite(repeat)
    cur = n - 1
    for i in range(m - 1, -1, -1):
        if cur < 0:
            break
        Ti, Fi = T[i], F[i]
        a = cur - int(Ti[cur::-1].argmin())  # last position of the minimum so far
        if Ti[a] < Fi[cur + 1] + skip:  # row i matched (else skipped)
            j[i] = a
            again = repeats and i > 0 and Fi[a + 1] + repeat < Fi[a]
            cur = a if again else a - 1
    return j, float(F[m, -1])


def _monotone_totals(C: np.ndarray, skip: float, repeat: float = np.inf) -> np.ndarray:
    """The least total cost of :func:`_monotone` for a batch of problems ``C`` (..., m, n),
    shape (...,), in memory of two rows."""
    F, _ = _forward(C, skip, repeat, keep=False)
    return F[C.shape[-2] % 2, ..., -1]


def _signature(phi: np.ndarray, width: int) -> np.ndarray:
    """Pose-, sign- and eigenspace-invariant description of each node from its modes.

    ``|phi_k(i)|^2`` does not change with a rotation of the object or the sign of mode
    ``k``; summed over a window of ``width`` consecutive modes it does not change either
    with a rotation inside a (near-)degenerate eigenspace or a swap of close modes.
    Returns (m, ceil(k / width)), each column with unit mean.
    """
    energy = np.sum(phi**2, axis=1)  # (m, k)
    k = energy.shape[1]
    starts = np.arange(0, k, width)
    sig = np.add.reduceat(energy, starts, axis=1)
    return sig / sig.mean(axis=0)


def _sq_dist(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.maximum(np.sum(a**2, axis=1)[:, None] + np.sum(b**2, axis=1)[None, :]
                      - 2 * a @ b.T, 0.0)


def _axes(x: np.ndarray) -> np.ndarray:
    """Principal axes of centred points as the columns of a proper rotation, each axis
    signed by the third moment along it: they turn with the points (rotation covariant)."""
    _, e = np.linalg.eigh(x.T @ x)
    e = e * np.where(np.sum((x @ e) ** 3, axis=0) < 0, -1.0, 1.0)
    if np.linalg.det(e) < 0:
        e[:, 0] = -e[:, 0]
    return e


def _rotations(d: int, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Candidate rotations (r, d, d) taking x towards y for the pose search: in 2D a circle
    of angles starting at the rotation between the principal axes (so the search turns
    with either input); in 3D the proper rotations between the principal axes, with every
    choice of axis signs."""
    ex, ey = _axes(x), _axes(y)
    if d == 2:
        R0 = ey @ ex.T
        t = 2 * np.pi * np.arange(_ANGLES) / _ANGLES
        c, s = np.cos(t), np.sin(t)
        return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2) @ R0
    out = []
    for signs in itertools.product([1.0, -1.0], repeat=3):
        R = ey @ np.diag(signs) @ ex.T
        if np.linalg.det(R) > 0:
            out.append(R)
    return np.array(out)


def _modal_deformation(phi: np.ndarray, freq: np.ndarray, rotation: np.ndarray,
                       rows: np.ndarray, resid: np.ndarray, stiff: float,
                       weight: np.ndarray | None = None) -> np.ndarray:
    """Smooth deformation of the aligned source, in its own lowest modes, towards the pairs.

    Mode superposition ``U = Phi X`` (11), rotated into the target's frame, fitted to the
    residuals ``resid`` (k, d) of the matched source nodes ``rows`` by least squares plus
    ``stiff`` times the modal strain energy ``X^T Omega^2 X`` (22), frequencies measured
    relative to the lowest. ``weight`` (k, d, d), optional, is the square root of a
    per-pair metric applied to the residuals (identity when omitted). Returns the
    displacement of every source node, (m, d).
    """
    B = np.einsum("ab,ibk->iak", rotation, phi)  # (m, d, k)
    Bm = B[rows]
    if weight is not None:
        Bm = np.einsum("iab,ibk->iak", weight, Bm)
        resid = np.einsum("iab,ib->ia", weight, resid)
    Bm = Bm.reshape(-1, B.shape[2])
    w = (freq / freq[0]) ** 2
    X = np.linalg.solve(Bm.T @ Bm + stiff * len(rows) * np.diag(w), Bm.T @ resid.ravel())
    return B @ X


def _tangents(y: np.ndarray, closed: bool, k: int = 2) -> np.ndarray:
    """Unit tangents (n, d) of an ordered contour: central differences over ``k`` nodes on
    each side (one-sided at the ends of an open one), robust to noise on single nodes."""
    n = len(y)
    k = max(1, min(k, (n - 1) // 2))
    t = np.roll(y, -k, axis=0) - np.roll(y, k, axis=0)
    if not closed:
        idx = np.arange(n)
        t = y[np.minimum(idx + k, n - 1)] - y[np.maximum(idx - k, 0)]
    return t / np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-300)


def _cyclic(C: np.ndarray, closed: bool) -> np.ndarray:
    """A closed target doubled, so that an order-preserving search may start anywhere."""
    return np.concatenate([C, C], axis=-1) if closed else C


def _ordered_pairs(C: np.ndarray, closed: bool, skip: float, repeat: float):
    """Order-preserving pairs over a cost (m, n), cyclic for a closed target. Returns j
    (m,) and the total cost."""
    j, total = _monotone(_cyclic(C, closed), skip, repeat)
    return np.where(j >= 0, j % C.shape[-1], -1), total


def _untangle(t: np.ndarray, cost: np.ndarray, n: int, skip: float, strict: bool
              ) -> np.ndarray:
    """Pairs of a cyclic order-preserving search that go round the target once.

    ``t`` (K,) are the partners, in source order, on a closed target of ``n`` nodes, and
    ``cost`` their costs. On the doubled target the search may step forward by nearly a
    whole turn, which is a step backwards on the closed target: there, and at the
    source's own cut, partners can overlap and cross. Each extra turn is removed at the
    largest step: unrolled from just after it, the pairs at the end that reach past where
    the first ones started are dropped, or the first ones they overlap, whichever keeps
    the search's objective (pair costs plus ``skip`` per unmatched node) lower. Returns a
    mask of the pairs kept.
    """
    keep = np.ones(len(t), bool)
    while True:
        idx = np.flatnonzero(keep)
        steps = np.diff(np.r_[t[idx], t[idx[:1]]]) % n  # to the next partner, cyclically
        if idx.size < 2 or steps.sum() <= n:  # round once (or all on one target)
            return keep
        k = int(np.argmax(steps))  # the step back, seen as nearly a whole turn
        r = np.roll(idx, -(k + 1))
        u = t[r[0]] + np.r_[0, np.cumsum(np.roll(steps, -(k + 1))[:-1])]
        first, last = u[0] + n, u[-1] - n  # how far each end may reach
        end = r[u >= first] if strict else r[u > first]
        start = r[u <= last] if strict else r[u < last]
        loss_end = skip * len(end) - cost[end].sum()  # change of the objective
        loss_start = skip * len(start) - cost[start].sum()
        keep[end if loss_end <= loss_start else start] = False


def _pairs_from_j(j: np.ndarray, cost: np.ndarray, one_to_one: bool) -> np.ndarray:
    i = np.flatnonzero(j >= 0)
    pairs = np.c_[i, j[i]]
    if one_to_one and len(pairs):  # a cyclic search may reuse a target once across the cut
        order = np.argsort(cost[pairs[:, 0], pairs[:, 1]], kind="stable")
        _, first = np.unique(pairs[order, 1], return_index=True)
        pairs = pairs[np.sort(order[first])]
    return pairs


_SKIP = 16.0  # cost of leaving a source node unmatched (squared target spacings)
_SIG_WEIGHT = 1.0  # weight of the modal signature against position
_SIG_WIDTH = 2  # modes summed per signature entry
_RIGID = 3  # first alternations: Horn alignment only (the deformation waits for the pose)
_ITERATIONS = 12  # most alternations of matching, Horn alignment and modal deformation
_STIFF = 1e-3  # modal strain-energy penalty of the deformation step
_TANGENTIAL = 0.3  # weight of the along-contour part of a residual in the deformation fit
_REPEAT = 4.0  # extra cost of one target for consecutive source nodes (squared spacings)
_TRUST = 4.0  # pairs trusted for the alignment and deformation fits (squared spacings)
_REJECT = 16.0  # pairs costing more than this (squared target spacings) are dropped

# Measured on benchmarks/matching.py, 4 pairs per family and seeds 2005 and 7 (precision /
# recall overall; drop10; combined): 4 alternations all with deformation, signature weight
# 4, isotropic fit: 0.931/0.919; 0.908/0.896; 0.723/0.720. Why: the first pairs come from
# a rigid pose, and near a missing stretch or a strong warp whole runs of them sit one or
# two nodes along the contour from the truth; a deformation fitted to them at once slides
# the source along with them and locks the error in (deformation off: drop10 1.000). Three
# rigid alternations first, then up to 12 with the deformation fitted mostly to the
# across-contour part of each residual (the along-contour part of a pair is what is in
# doubt): 0.967/0.960; 1.000/0.994; 0.876/0.892. A signature weight of 1 instead of 4
# helps two different hands (0.74 -> 0.80 precision) and costs nothing elsewhere.
_AUTO = dict(skip=_SKIP, sig_weight=_SIG_WEIGHT, width=_SIG_WIDTH, rigid=_RIGID,
             iterations=_ITERATIONS, stiff=_STIFF, tangential=_TANGENTIAL, trust=_TRUST,
             dense=0.95, repeat=_REPEAT)


def _pose_candidates(d: int, x: np.ndarray, y: np.ndarray, rotation: str
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rotations (r, d, d) tried by the pose search, a mask of those that keep the common
    frame (within ``_COMMON_ANGLE`` of the identity) and the cosines of their angles.
    ``rotation="none"``: the identity alone; ``"free"``: :func:`_rotations`; ``"auto"``:
    both, with small turns about the identity in 2D."""
    eye = np.eye(d)[None]
    if rotation == "none":
        return eye, np.ones(1, bool), np.ones(1)
    rots = _rotations(d, x, y)
    if rotation == "auto" and d == 2:  # the identity first, then small turns about it
        c, s = np.cos(np.radians(_SMALL_TURNS)), np.sin(np.radians(_SMALL_TURNS))
        small = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)
        rots = np.concatenate([eye, small, rots])
    elif rotation == "auto":
        rots = np.concatenate([eye, rots])
    cos = (np.trace(rots, axis1=1, axis2=2) - (d - 2)) / 2  # cos of the rotation angle
    return rots, cos >= np.cos(np.radians(_COMMON_ANGLE)) - 1e-12, cos


def _pose_search(C: np.ndarray, candidates: np.ndarray, closed: bool, skip: float,
                 repeat: float) -> tuple[float, np.ndarray, bool, int]:
    """The cheapest pose of an ordered contour among ``candidates`` (indices into the
    rotations of ``C`` (r, m, n)), each with both directions of the target.

    Branch and bound: an order-preserving total is at least the sum of each row's cheapest
    choice, so rotations are searched best bound first and the search stops once no bound
    left can beat the best total found. Returns the total, the cost matrix of the best
    pose (target reversed when it won reversed), whether it is reversed and its index.
    """
    bound = np.minimum(C[candidates].min(axis=2), skip).sum(axis=1)
    ranked = candidates[np.argsort(bound)]
    bound = np.sort(bound)
    best_total, best = np.inf, None
    for start in range(0, len(ranked), _POSE_BATCH):
        if bound[start] >= best_total:
            break
        r = ranked[start:start + _POSE_BATCH]
        Cb = np.concatenate([C[r], C[r][:, :, ::-1]])  # forward, reversed target order
        total = _monotone_totals(_cyclic(Cb, closed), skip, repeat)
        k = int(np.argmin(total))
        if total[k] < best_total:
            best_total, best = float(total[k]), (Cb[k], k >= len(r), r[k % len(r)])
    return best_total, *best


def _search(z, yo, Fo, h2, rows, ordered, closed, skip, repeat, many_to_one):
    """Pairs (row index, target index) for the source nodes ``rows`` placed at ``z``, and
    the cost matrix: order-preserving for contours, an assignment for point sets."""
    C = _sq_dist(z[rows], yo) / h2 + Fo[rows]
    if ordered:
        j, _ = _ordered_pairs(C, closed, skip, repeat)
        return _pairs_from_j(j, C, one_to_one=not many_to_one), C
    r, c = linear_sum_assignment(C)
    return np.c_[r, c], C


def _trusted(pairs: np.ndarray, cost: np.ndarray, trust: float, d: int) -> np.ndarray:
    """The pairs trusted for the alignment and deformation fits: those costing at most
    ``trust``, or all of them when too few are."""
    good = pairs[cost <= trust]
    return pairs if len(good) < max(d + 1, len(pairs) // 4) else good


def _objective(z, rows, fit, repeat, many) -> float:
    """The search's objective for the source placed at ``z``: pair costs plus ``skip``
    for every source node of ``rows`` left unmatched."""
    pairs, C = _search(z, fit["yo"], fit["Fo"], fit["h2"], rows, fit["ordered"],
                       fit["closed"], fit["opt"]["skip"], repeat, many)
    return float(C[pairs[:, 0], pairs[:, 1]].sum() + fit["opt"]["skip"]
                 * (len(rows) - len(pairs)))


def _alternate(sim, rotate: bool, *, x, yo, Fo, h2, sub, ordered, closed, phi, freq,
               metric, opt, repeat, many) -> np.ndarray:
    """Alternate the search on the source nodes ``sub`` with Horn's alignment (rotation
    only when ``rotate``) and, after ``opt["rigid"]`` rounds, a smooth deformation in the
    source's lowest modes fitted to the trusted pairs. Returns where the fitted
    similarity and deformation take every source node, (m, d), target frame."""
    d = x.shape[1]
    shift = np.zeros_like(x)
    previous = None
    it = -1
    while (it := it + 1) < opt["iterations"] - 1:
        pairs, C = _search(sim.apply(x) + shift, yo, Fo, h2, sub, ordered, closed,
                           opt["skip"], repeat, many)
        cost = C[pairs[:, 0], pairs[:, 1]]
        good = _trusted(np.c_[sub[pairs[:, 0]], pairs[:, 1]], cost, opt["trust"], d)
        # the fits depend on the trusted pairs alone: the same ones twice running, fitted
        # the same way, are a fixed point
        if previous is not None and np.array_equal(good, previous):
            if it > opt["rigid"]:
                break
            # a fixed point of the rigid fit: the rigid alternations left would repeat this
            # one exactly, so go on with the deformation at once
            it = max(it, opt["rigid"])
        previous = good
        sim = align(x[good[:, 0]], yo[good[:, 1]], rotate=rotate)
        if it >= opt["rigid"]:
            rows = good[:, 0]
            resid = yo[good[:, 1]] - sim.apply(x[rows])
            shift = _modal_deformation(phi, freq, sim.rotation, rows, resid, opt["stiff"],
                                       None if metric is None else metric[good[:, 1]])
    return sim.apply(x) + shift


def _match_auto(src: Shape, tgt: Shape, n_modes: int, sigma: float, reject: float,
                options: dict | None = None, *, rotation: str = "auto"
                ) -> tuple[np.ndarray, np.ndarray, Similarity, np.ndarray]:
    """The default matcher; also returns where the fitted similarity and deformation take
    every source node (the target's user coordinates), shape (m, d)."""
    opt = dict(_AUTO, **(options or {}))
    x, y = src.normalized, tgt.normalized
    n, d = tgt.m, src.dim
    ordered = bool(src.ordered and tgt.ordered)
    closed = ordered and src.closed and tgt.closed
    phi1, w1 = modal_features(src, n_modes, sigma=sigma)
    phi2, _ = modal_features(tgt, n_modes, sigma=sigma)
    sig1, sig2 = _signature(phi1, opt["width"]), _signature(phi2, opt["width"])
    F = opt["sig_weight"] * _sq_dist(sig1, sig2) / sig1.shape[1]
    h2 = tgt.spacing**2

    # pose search on a coarse subset: every candidate rotation, both target directions
    coarse = _COARSE_NODES if ordered else _COARSE_NODES_CLOUD
    ci, cj = spread_indices(src, coarse), spread_indices(tgt, coarse)
    hc2 = h2 * (n / len(cj)) ** 2
    rots, near, cos = _pose_candidates(d, x, y, rotation)
    evidence = cos < np.cos(np.radians(_TURN_EVIDENCE))  # poses that show a turn
    # common: the common frame won the pose search, but its cheapest pose was turned by
    # more than _TURN_EVIDENCE: both the turned and the unturned alternation are tried
    rotate, common = rotation != "none", False
    z = np.einsum("rab,ib->ria", rots, x[ci])
    yc = y[cj]
    D = (np.sum(z**2, -1)[:, :, None] + np.sum(yc**2, -1)[None, None, :]
         - 2 * np.einsum("ria,ja->rij", z, yc)) / hc2
    C = D + F[np.ix_(ci, cj)]
    if ordered:
        repeat = opt["repeat"] if len(ci) > len(cj) else np.inf
        total, Cb, reverse, r = _pose_search(C, np.arange(len(rots)), closed, opt["skip"],
                                             repeat)
        if rotation == "auto":  # the common frame unless another pose is clearly better
            total_near, Cn, rev_near = (total, Cb, reverse) if near[r] else _pose_search(
                C, np.flatnonzero(near), closed, opt["skip"], repeat)[:3]
            if total_near <= _COMMON_MARGIN * total:
                Cb, reverse, common, rotate = Cn, rev_near, evidence[r], False
        jj, _ = _ordered_pairs(Cb, closed, opt["skip"], repeat)
        keep = jj >= 0
        if reverse:
            jj = len(cj) - 1 - jj
        pi, pj = ci[keep], cj[jj[keep]]
    else:
        reverse = False
        starts = [(ci[r], cj[c]) for r, c in map(linear_sum_assignment, C)]
    sim = align(x[pi], y[pj], rotate=rotate) if ordered else None
    turned = align(x[pi], y[pj]) if ordered else None  # the same pose, turn allowed

    order = np.arange(n)[::-1] if reverse else np.arange(n)
    Fo = F[:, order]
    yo = y[order]
    # the alternation runs on at most ALTERNATION_NODES source nodes; the final search,
    # with the fitted similarity and deformation, on all of them
    sub = spread_indices(src, ALTERNATION_NODES)
    if not ordered:
        # point sets: the coarse costs of the 4 poses can be close (one 180 degrees off won
        # on a 2000-node benchmark blob); a few rigid rounds of search and alignment on
        # the subset from each pose tell them apart, and the best one goes on
        def rounds(s):
            for _ in range(_POSE_ROUNDS):
                pairs, C = _search(s.apply(x), yo, Fo, h2, sub, False, False, opt["skip"],
                                   np.inf, False)
                good = _trusted(pairs, C[pairs[:, 0], pairs[:, 1]], opt["trust"], d)
                s = align(x[sub[good[:, 0]]], yo[good[:, 1]], rotate=rotate)
            return C[pairs[:, 0], pairs[:, 1]].sum(), s  # of the last search

        tried = [rounds(align(x[i], y[j], rotate=rotate)) for i, j in starts]
        best = min(range(len(tried)), key=lambda r: tried[r][0])
        if rotation == "auto":  # the common frame unless another pose is clearly better
            near_best = min(np.flatnonzero(near), key=lambda r: tried[r][0])
            if tried[near_best][0] <= _COMMON_MARGIN * tried[best][0]:
                common, rotate, best = evidence[best], False, near_best
        sim = turned = tried[best][1]

    # one target per source node, unless the source is denser than the target
    denser = src.spacing * sim.scale < opt["dense"] * tgt.spacing
    repeat = opt["repeat"] if denser else np.inf
    metric = None
    if ordered:  # metric of the deformation fit: across-contour 1, along-contour smaller
        t = _tangents(yo, closed)
        metric = np.eye(d) - (1 - np.sqrt(opt["tangential"])) * t[:, :, None] * t[:, None, :]
    sub_denser = src.spacing * src.m / len(sub) * sim.scale < opt["dense"] * tgt.spacing
    fit = dict(x=x, yo=yo, Fo=Fo, h2=h2, sub=sub, ordered=ordered, closed=closed,
               phi=phi1, freq=w1, metric=metric, opt=opt,
               repeat=repeat if sub_denser else np.inf, many=sub_denser)
    z = _alternate(sim, rotate, **fit)
    if rotation == "auto" and common:
        # the common frame won, but a turned pose had cost less: kept without a turn
        # unless turning fits far better in the end (a shape turned by 5-45 degrees)
        free = _alternate(turned, True, **fit)
        totals = [_objective(zz, np.arange(src.m), fit, repeat, denser) for zz in (z, free)]
        if totals[1] < _TURN_GAIN * totals[0]:
            z = free
    pairs, C = _search(z, yo, Fo, h2, np.arange(src.m), ordered, closed, opt["skip"],
                       repeat, denser)
    cost = C[pairs[:, 0], pairs[:, 1]]
    keep = cost <= reject
    if closed:  # partners round the target once: none crossing at the cut or a step back
        keep &= _untangle(pairs[:, 1], cost, n, opt["skip"], strict=not denser)
    pairs, cost = pairs[keep], cost[keep]
    pairs = np.c_[pairs[:, 0], order[pairs[:, 1]]]
    landed = tgt.to_user(z)  # where the fitted similarity and deformation take the source
    return pairs, cost, align(src.points[pairs[:, 0]], tgt.points[pairs[:, 1]]), landed


def _match_large(src: Shape, tgt: Shape, n_modes: int, sigma: float, reject: float,
                 coarse: int, *, rotation: str = "auto"
                 ) -> tuple[np.ndarray, np.ndarray, Similarity, np.ndarray]:
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
    *_, landed_c = _match_auto(sub_s, sub_t, n_modes, sigma, reject, rotation=rotation)
    dist, near = cKDTree(sub_s.points).query(src.points, k=4)
    w = 1.0 / np.maximum(dist, 1e-12 * src.size)
    w /= w.sum(axis=1, keepdims=True)
    landed = src.points + np.einsum("ik,ikd->id", w, (landed_c - sub_s.points)[near])
    j = cKDTree(tgt.points).query(landed)[1]
    gap = np.linalg.norm(tgt.points[j] - landed, axis=1)
    h = tgt.spacing * tgt.size * tgt.m / len(cj)  # the coarse target's node spacing
    cost = (gap / h) ** 2  # in squared coarse target spacings, as on the coarse level
    keep = cost <= reject
    pairs = np.c_[np.flatnonzero(keep), j[keep]]
    return pairs, cost[keep], align(src.points[pairs[:, 0]], tgt.points[pairs[:, 1]]), landed


def _match_cloud(src: Shape, tgt: Shape, n_modes: int, sigma: float | None, reject: float,
                 rotation: str) -> tuple[np.ndarray, np.ndarray, Similarity]:
    """The default matcher for unordered 3D point sets: the modal matcher (on ``COARSE``
    nodes for large objects), then :func:`modalmorph.match3d.refine`, then each source
    node paired with the target node nearest to where it lands; pairs farther than
    ``sqrt(reject)`` target spacings are dropped. Cost in squared target spacings."""
    if max(src.m, tgt.m) > LARGE:
        *_, landed = _match_large(src, tgt, n_modes, sigma, reject, COARSE, rotation=rotation)
    else:
        *_, landed = _match_auto(src, tgt, n_modes, sigma, reject, rotation=rotation)
    y = tgt.normalized
    z = refine(src.normalized, tgt.to_normalized(landed), y, min(src.m, COARSE) // 4)
    gap, j = cKDTree(y).query(z)
    cost = (gap / tgt.spacing) ** 2
    keep = cost <= reject
    pairs = np.c_[np.flatnonzero(keep), j[keep]]
    return pairs, cost[keep], align(src.points[pairs[:, 0]], tgt.points[pairs[:, 1]])


def match(source, target, *, method: str = "auto", rotation: str = "auto",
          modes: int | None = None, sigma: float | None = None,
          reject: float | None = None) -> Matching:
    """Correspondences between the nodes of two objects by modal matching (6)-(8).

    Parameters
    ----------
    source, target : Shape or array_like, shape (m, d) and (n, d)
        The two objects, of the same dimension ``d`` in {2, 3}; ``m`` and ``n`` may differ.
        Arrays become :class:`Shape` with its defaults (2D: closed ordered contour; 3D:
        unordered point cloud); pass a ``Shape`` for an open contour (``closed=False``)
        or an unordered 2D set (``ordered=False``).
    method : {"auto", "local", "global"}, optional
        ``"local"``: mutual best in the affinity ``Z`` (8), the paper's search.
        ``"global"``: assignment over ``Z`` with rejection of implausible pairs.
        ``"auto"`` (default): pose-invariant modal signatures plus position, alternated
        with Horn's alignment and a deformation in the lowest modes; order-preserving
        (cyclic) search for contours, assignment for point clouds. Invariant to
        translation, rotation, scale, start node and direction of a contour.
    rotation : {"auto", "free", "none"}, optional
        How the ``"auto"`` search treats the objects' relative orientation.
        ``"none"``: the objects share one frame (frames of a sequence, end-diastole and
        end-systole of one image slice): the correspondence is not rotated at all, only
        translated and scaled. ``"free"``: any rotation, the pose chosen by cost alone
        (objects drawn in unrelated poses). ``"auto"`` (default): any rotation is tried,
        but poses within 20 degrees of the given frame are kept unless another pose costs
        clearly less: near-symmetric shapes (a left ventricle, a circle) keep their common
        frame, a shape turned by a large angle is still found.
    modes : int, optional
        Number of lowest modes describing each node (default 24).
    sigma : float or None, optional
        Gaussian width of the matching models, x mean node spacing. ``None`` (default):
        2, or less where the Gram matrix of a model would be ill-conditioned
        (:func:`modalmorph.element.auto_sigma`, per model).
    reject : float, optional
        Pairs costing more than this are dropped. ``"global"``: a multiple of the median
        pair cost (default 3). ``"auto"``: squared distance after the final alignment in
        units of the target's squared node spacing (default 16, i.e. 4 spacings).
        ``"local"`` rejects nothing.

    Returns
    -------
    Matching

    Raises
    ------
    ValueError
        If an object is invalid (see :class:`Shape`), the dimensions differ, or an option
        is out of range.
    """
    src, tgt = as_shape(source, "source"), as_shape(target, "target")
    for name, shape in (("source", src), ("target", tgt)):
        if shape.dim == 2 and shape.ordered and shape.closed:
            x, y = shape.normalized.T  # shoelace area, relative to the unit RMS radius
            if abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))) < 1e-9:
                raise ValueError(f"{name} is a closed contour with no area (its nodes lie on "
                                 f"one line): pass it as Shape(points, closed=False)")
    if src.dim != tgt.dim:
        raise ValueError(f"source and target must have the same dimension, got "
                         f"{src.dim}D and {tgt.dim}D")
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    if modes is not None and (not isinstance(modes, int | np.integer) or modes < 1):
        raise ValueError(f"modes must be a positive integer, got {modes!r}")
    n_modes = DEFAULT_MODES if modes is None else int(modes)
    n_modes = min(n_modes, src.dim * min(src.m, tgt.m, MAX_MODEL_NODES))
    check_sigma(sigma)
    if rotation not in ROTATIONS:
        raise ValueError(f"rotation must be one of {ROTATIONS}, got {rotation!r}")
    if reject is not None and not reject > 0:
        raise ValueError(f"reject must be > 0, got {reject}")
    sim = None
    reject_auto = _REJECT if reject is None else reject
    if method == "auto" and src.dim == 3 and not (src.ordered or tgt.ordered):
        pairs, cost, sim = _match_cloud(src, tgt, n_modes, sigma, reject_auto, rotation)
    elif method == "auto" and max(src.m, tgt.m) > LARGE:
        pairs, cost, sim, _ = _match_large(src, tgt, n_modes, sigma, reject_auto, COARSE,
                                           rotation=rotation)
    elif method == "auto":
        pairs, cost, sim, _ = _match_auto(src, tgt, n_modes, sigma, reject_auto,
                                          rotation=rotation)
    else:
        if src.m * tgt.m > MAX_AFFINITY:
            raise ValueError(f"method={method!r} builds the full {src.m} x {tgt.m} affinity "
                             f"matrix (8), too large here; use method='auto', which "
                             f"matches large objects in linear memory")
        phi1, _ = modal_features(src, n_modes, sigma=sigma)
        phi2, _ = modal_features(tgt, n_modes, sigma=sigma)
        Z = affinity(phi1, _fix_signs(phi1, phi2))  # (8)
        if method == "local":
            pairs = _mutual_best(Z)
        else:
            r, c = linear_sum_assignment(Z)
            pairs = np.c_[r, c]
            keep = _reject(Z[r, c], 3.0 if reject is None else reject)
            pairs = pairs[keep]
        cost = Z[pairs[:, 0], pairs[:, 1]]
    order = np.argsort(pairs[:, 0], kind="stable")
    return Matching(pairs=pairs[order].astype(np.intp), cost=cost[order], method=method,
                    modes=n_modes, sigma=sigma, similarity=sim, shape=(src.m, tgt.m))
