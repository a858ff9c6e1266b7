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
    (cyclic for closed ones) search; point clouds by assignment. Its stages, in order:
    :func:`_prepare` (modes and signatures), :func:`_contour_pose` or :func:`_cloud_pose`
    (the pose search and the common-frame decision), :func:`_alternate` (search, alignment
    and deformation), :func:`_keep_or_turn`, :func:`_settle` (for contours the coherent
    pass :func:`_coherent`, which settles the along-contour position) and
    :func:`_final_pairs` (the last search and the rejection). See :func:`match`.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree

from ..core.align import Similarity, align
from ..core.model import FEModel
from ..core.quality import area
from ..core.shape import Shape, as_shape, check_pairs, resample, spread_indices
from ..errors import OptionError, ShapeError
from ..options import METHODS, ROTATIONS, MatchOptions
from .clouds import refine

__all__ = ["Matching", "match", "modal_features", "affinity", "METHODS", "ROTATIONS"]

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
# Unordered 3D point sets above LARGE nodes are matched on one coarse node per
# NODES_PER_COARSE_CLOUD of the larger object, at least COARSE and at most COARSE_CLOUD,
# then refined. Measured on benchmarks/match3d.py after the refinement (median pair error,
# target spacings; time on the loaded 2-core machine): 100 000 points (blob turned 90 deg /
# bunny 180), 1000 coarse nodes 1.02 / 1.33 (17-18 s), 2000 0.92 / 1.03, 3000 0.88 / 0.95
# (28 s), 4000 (blob, before match3d's final averaging) 1.14 -> 1.11 in 44 s, 5000 2.80;
# 50 000 points (90 and 180 deg, both shapes), 1515 0.85-0.93 (8 s), 2500 0.80-0.85
# (10 s), 3000 0.80-0.83 (11 s); 10 000 points, 1000 0.61-0.64 (1.5 s), 3000 0.61-0.63
# (2.9 s). On benchmarks/scale.py's twisted ellipsoid (no noise) more coarse nodes cost:
# 10 000 points 5.8 spacings with 1000, 6.6 with 3000; 100 000 points 17.0 and 19.8.
NODES_PER_COARSE_CLOUD = 20
COARSE_CLOUD = 3000
# The matcher's alternation of search and fits runs on at most this many source nodes.
ALTERNATION_NODES = 400
# Largest m x n affinity matrix the paper's local/global searches may build.
MAX_AFFINITY = 4e7  # larger objects are modelled on an evenly spread subset of nodes
# A closed contour whose shoelace area, relative to its unit RMS radius, is below this has
# its nodes on one line: rounding leaves ~1e-16 per node there, a circle has pi.
FLAT_AREA = 5e-10
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
# 2.1-7.4 / 3.1-12.7 / 5.2-17.6 / 6.2-22.1.
_COMMON_MARGIN = 2.0
# rotation="auto" in the common frame: the alternation is run without a turn and with one;
# the turn wins when it lowers the search's objective below this fraction. Measured
# (turned / unturned): the 16 shared heart pairs 0.67-1.00 (unturned they match radially;
# turned, near-circular ones drift by up to 15 degrees and fold), hand pairs turned by 25
# and 30 degrees whose pose search chose the common frame: 0.37.
_TURN_GAIN = 0.5

# The default search's costs, in squared target node spacings.
_SKIP = 16.0  # leaving a source node unmatched
_REPEAT = 4.0  # one target for two consecutive source nodes (a denser source)
_TRUST = 4.0  # pairs costing at most this are trusted for the alignment and deformation
_REJECT = 16.0  # pairs costing more than this are dropped (4 spacings)
# A source whose spacing (after the similarity) is below this fraction of the target's may
# put consecutive nodes on one target (at the cost _REPEAT).
_DENSE = 0.95
_SIG_WIDTH = 2  # modes summed per signature entry
# Weight of the modal signature against position. Measured (benchmarks/matching.py, 4 pairs
# a family, seeds 2005 and 7): 1 instead of 4 lifts the precision on two different hands
# from 0.74 to 0.80 and changes no other family.
_SIG_WEIGHT = 1.0
# The alternation: _RIGID rounds of search and Horn alignment, then up to _DEFORM_ROUNDS
# with the deformation too, fitted with _STIFF times the modal strain energy and with the
# along-contour part of each residual weighted by _TANGENTIAL. Measured (the same runs;
# overall precision/recall; drop10; combined): 4 rounds all with deformation and an
# isotropic fit 0.931/0.919; 0.908/0.896; 0.723/0.720, these values 0.967/0.960;
# 1.000/0.994; 0.876/0.892. The first pairs come from a rigid pose and near a missing
# stretch or a strong warp whole runs of them sit a node or two along the contour from the
# truth: a deformation fitted to them at once locks that slip in.
_RIGID = 3
_DEFORM_ROUNDS = 8
# The coherent pass of contours (_coherent). Measured on benchmarks/matching.py, 4 pairs a
# family, seeds 2005 / 11 (overall precision/recall; common-heart precision): without it
# 0.950/0.940, 0.917; 0.944/0.934, 0.808; with these values 0.969/0.963, 0.996;
# 0.970/0.966, 0.933 (CPD on 12 common-heart pairs: 0.906 / 0.970, this matcher 0.933 /
# 0.991). Beside each value what the others gave.
# Kernel width, x the target's RMS radius. 12 hand pairs (seeds 2005 / 11): 1.5 -> 0.835 /
# 0.747, 1.0 -> 0.866 / 0.794, without the pass 0.843 / 0.791; 0.5 and 0.75 lower
# common-heart (seed 11: 0.901, 0.921 against 0.933).
_COHERENT_WIDTH = 1.0
_COHERENT_LAMBDA = 2.0  # smoothness weight, CPD's default (8: warp-strong 0.958 vs 0.985)
_COHERENT_BAND = 8  # target nodes either side of a partner (4: combined 0.918 vs 0.944)
_COHERENT_ROUNDS = 50  # EM rounds (25: common-heart 0.990 / 0.879 vs 0.996 / 0.933)
# sigma >= this x the target's node spacing: below it source nodes snap onto target nodes
# and two take one (start family recall 0.987 without the floor and at 0.5, 0.997 at 1;
# 2: warp-strong 0.956 vs 0.985).
_COHERENT_FLOOR = 1.0
# Nystrom landmarks of the kernel: the table to 3 decimals as with the full kernel.
_COHERENT_LANDMARKS = 64
# No node moves further than this x the target's node spacing from the alternation's
# placement: a smooth field cannot turn a corner, and unclamped it dragged the stem of F
# (DejaVu Sans -> Serif, 400 nodes, benchmarks/realdata.py) across the serif into a fold.
# 3: F folds no more, combined 0.893 (unclamped 0.928, main 0.762), hands 0.807 (0.835);
# 2 (F unfolded too): combined 0.887, hands 0.819 (seed 2005, 3 pairs a family).
_COHERENT_REACH = 3.0
# Fewer source or target nodes than this: no pass. The accuracy families have 100-400
# nodes; below, glyphs-raw Q (29 nodes, uneven spacing) folded with the pass, and the
# 70-node hand match took 17 ms instead of 12.
_COHERENT_NODES = 100
_EIG_FLOOR = 1e-10  # kernel eigenvalues below this x the largest are rounding

_STIFF = 1e-3
_TANGENTIAL = 0.3


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
    shape : tuple of int
        ``(m, n)``, the node counts of source and target.
    options : MatchOptions or None
        The options of the call that found them (recorded with a morph's parameters).
    """

    pairs: np.ndarray
    cost: np.ndarray
    method: str
    modes: int
    sigma: float | None
    similarity: Similarity | None
    shape: tuple
    options: MatchOptions | None = None

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
        m, n = self.shape
        how = self.method if not self.modes else f"{self.method}, {self.modes} modes"
        turned = "" if self.similarity is None else ", with a similarity"
        return f"Matching({len(self)} pairs of {m} -> {n} nodes, {how}{turned})"

    @classmethod
    def given(cls, pairs, m: int, n: int) -> Matching:
        """Given ``(source index, target index)`` pairs (K, 2) of objects of ``m`` source
        and ``n`` target nodes as a Matching of method ``"given"`` (sorted by source index,
        zero costs); :class:`ShapeError` when they are not such pairs."""
        pairs = check_pairs(pairs, m, n)
        pairs = pairs[np.argsort(pairs[:, 0], kind="stable")]
        return cls(pairs=pairs, cost=np.zeros(len(pairs)), method="given", modes=0,
                   sigma=None, similarity=None, shape=(int(m), int(n)))

    def check(self, m: int, n: int) -> Matching:
        """This matching, if it belongs to objects of ``m`` source and ``n`` target nodes;
        else :class:`ShapeError` naming both node counts."""
        if tuple(self.shape) != (m, n):
            raise ShapeError(f"the matching was found for {self.shape[0]} source and "
                             f"{self.shape[1]} target nodes, not for the {m} and {n} "
                             "given")
        check_pairs(self.pairs, m, n)
        return self


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
        ``DEFAULT_SIGMA`` or less, as :func:`modalmorph.core.element.auto_sigma` chooses.
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


# --------------------------------------------------------------------------- the default


@dataclass(frozen=True, eq=False)
class _Problem:
    """Source and target as the default matcher sees them (:func:`_prepare`)."""

    src: Shape
    tgt: Shape
    phi: np.ndarray  # source modes (m, d, k), normalised frame
    freq: np.ndarray  # their frequencies (k,)
    F: np.ndarray  # signature cost (m, n), squared target spacings
    rotation: str

    @property
    def ordered(self) -> bool:
        return bool(self.src.ordered and self.tgt.ordered)

    @property
    def closed(self) -> bool:
        return self.ordered and self.src.closed and self.tgt.closed


@dataclass(frozen=True, eq=False)
class _Costs:
    """What one search compares: the source nodes ``x`` (m, d) placed somewhere, against
    the target ``y`` (n, d) in search order (reversed when the pose search reversed it)
    with the signature cost ``F`` (m, n) in the same order; ``h2`` the target's squared
    node spacing; ``repeat`` and ``many`` as in :func:`_monotone` and
    :func:`_pairs_from_j`."""

    x: np.ndarray
    y: np.ndarray
    F: np.ndarray
    h2: float
    ordered: bool
    closed: bool
    repeat: float = np.inf
    many: bool = False


@dataclass(frozen=True, eq=False)
class _Fit:
    """The alternation's setting: its search on the source nodes ``sub``, the source
    modes for the deformation and, for contours, the metric (n, d, d) that weights the
    along-contour part of a residual by ``_TANGENTIAL``."""

    costs: _Costs
    sub: np.ndarray
    phi: np.ndarray
    freq: np.ndarray
    metric: np.ndarray | None


@dataclass(frozen=True, eq=False)
class _Pose:
    """The outcome of the pose search: the similarity to start from, the same pose with a
    turn allowed, whether the target is searched reversed, whether the alternation may
    rotate and whether a turned start is to be tried too (``common``)."""

    sim: Similarity
    turned: Similarity
    reverse: bool = False
    rotate: bool = True
    common: bool = False


@dataclass(frozen=True, eq=False)
class _Placement:
    """A similarity and where it, with a deformation, takes every source node (m, d)."""

    sim: Similarity
    z: np.ndarray


def _search(costs: _Costs, z: np.ndarray, rows: np.ndarray):
    """Pairs (row index, target index) for the source nodes ``rows`` placed at ``z``, and
    the cost matrix: order-preserving for contours, an assignment for point sets."""
    C = _sq_dist(z[rows], costs.y) / costs.h2 + costs.F[rows]
    if costs.ordered:
        j, _ = _ordered_pairs(C, costs.closed, _SKIP, costs.repeat)
        return _pairs_from_j(j, C, one_to_one=not costs.many), C
    r, c = linear_sum_assignment(C)
    return np.c_[r, c], C


def _trusted(pairs: np.ndarray, cost: np.ndarray, d: int) -> np.ndarray:
    """The pairs trusted for the alignment and deformation fits: those costing at most
    ``_TRUST``, or all of them when too few are."""
    good = pairs[cost <= _TRUST]
    return pairs if len(good) < max(d + 1, len(pairs) // 4) else good


def _trusted_pairs(costs: _Costs, z: np.ndarray, sub: np.ndarray):
    """Search the source nodes ``sub`` placed at ``z``: the trusted pairs (source index,
    target index) and the total cost of all pairs."""
    pairs, C = _search(costs, z, sub)
    cost = C[pairs[:, 0], pairs[:, 1]]
    return _trusted(np.c_[sub[pairs[:, 0]], pairs[:, 1]], cost, z.shape[1]), cost.sum()


def _total(found: tuple, m: int) -> float:
    """The search's objective from its pairs and cost matrix ``found``: pair costs plus
    ``_SKIP`` for every one of the ``m`` source nodes left unmatched."""
    pairs, C = found
    return float(C[pairs[:, 0], pairs[:, 1]].sum() + _SKIP * (m - len(pairs)))


def _objective(costs: _Costs, z: np.ndarray) -> float:
    """The search's objective for every source node placed at ``z``."""
    return _total(_search(costs, z, np.arange(len(z))), len(z))


def _prepare(src: Shape, tgt: Shape, n_modes: int, sigma: float | None,
             rotation: str) -> _Problem:
    """The source's modes and the signature cost between every source and target node."""
    phi1, w1 = modal_features(src, n_modes, sigma=sigma)
    phi2, _ = modal_features(tgt, n_modes, sigma=sigma)
    sig1, sig2 = _signature(phi1, _SIG_WIDTH), _signature(phi2, _SIG_WIDTH)
    F = _SIG_WEIGHT * _sq_dist(sig1, sig2) / sig1.shape[1]
    return _Problem(src, tgt, phi1, w1, F, rotation)


def _coarse_costs(p: _Problem):
    """The pose search's cost (r, mc, nc) of every candidate rotation on evenly spread
    subsets ``ci``, ``cj`` of the nodes; also the mask of the common-frame rotations and of
    those turned enough to show a turn (:func:`_pose_candidates`)."""
    x, y = p.src.normalized, p.tgt.normalized
    coarse = _COARSE_NODES if p.ordered else _COARSE_NODES_CLOUD
    ci, cj = spread_indices(p.src, coarse), spread_indices(p.tgt, coarse)
    hc2 = p.tgt.spacing**2 * (p.tgt.m / len(cj)) ** 2
    rots, near, cos = _pose_candidates(p.src.dim, x, y, p.rotation)
    z = np.einsum("rab,ib->ria", rots, x[ci])
    yc = y[cj]
    D = (np.sum(z**2, -1)[:, :, None] + np.sum(yc**2, -1)[None, None, :]
         - 2 * np.einsum("ria,ja->rij", z, yc)) / hc2
    evidence = cos < np.cos(np.radians(_TURN_EVIDENCE))
    return D + p.F[np.ix_(ci, cj)], ci, cj, near, evidence


def _contour_pose(p: _Problem) -> _Pose:
    """Pose of an ordered contour: the cheapest rotation and target direction of the
    order-preserving search on the coarse nodes; with ``rotation="auto"`` the best
    common-frame pose unless another is cheaper by more than ``_COMMON_MARGIN``."""
    C, ci, cj, near, evidence = _coarse_costs(p)
    repeat = _REPEAT if len(ci) > len(cj) else np.inf
    total, Cb, reverse, r = _pose_search(C, np.arange(len(C)), p.closed, _SKIP, repeat)
    rotate, common = p.rotation != "none", False
    if p.rotation == "auto":
        total_near, Cn, rev_near = (total, Cb, reverse) if near[r] else _pose_search(
            C, np.flatnonzero(near), p.closed, _SKIP, repeat)[:3]
        if total_near <= _COMMON_MARGIN * total:
            Cb, reverse, common, rotate = Cn, rev_near, evidence[r], False
    jj, _ = _ordered_pairs(Cb, p.closed, _SKIP, repeat)
    keep = jj >= 0
    if reverse:
        jj = len(cj) - 1 - jj
    xs, ys = p.src.normalized[ci[keep]], p.tgt.normalized[cj[jj[keep]]]
    return _Pose(align(xs, ys, rotate=rotate), align(xs, ys), reverse, rotate, common)


def _cloud_pose(p: _Problem, costs: _Costs, sub: np.ndarray) -> _Pose:
    """Pose of a point set: each candidate's coarse assignment, then ``_POSE_ROUNDS``
    rigid rounds of search and alignment on ``sub`` from each (the coarse costs of poses
    180 degrees apart can be close); the cheapest, or with ``rotation="auto"`` the best
    common-frame pose unless another is cheaper by more than ``_COMMON_MARGIN``."""
    C, ci, cj, near, evidence = _coarse_costs(p)
    x, y = costs.x, costs.y
    rotate, common = p.rotation != "none", False
    tried = []
    for r, c in map(linear_sum_assignment, C):
        sim = align(x[ci[r]], y[cj[c]], rotate=rotate)
        for _ in range(_POSE_ROUNDS):
            good, total = _trusted_pairs(costs, sim.apply(x), sub)
            sim = align(x[good[:, 0]], y[good[:, 1]], rotate=rotate)
        tried.append((total, sim))
    best = min(range(len(tried)), key=lambda r: tried[r][0])
    if p.rotation == "auto":
        near_best = min(np.flatnonzero(near), key=lambda r: tried[r][0])
        if tried[near_best][0] <= _COMMON_MARGIN * tried[best][0]:
            common, rotate, best = evidence[best], False, near_best
    return _Pose(tried[best][1], tried[best][1], False, rotate, common)


def _fits(p: _Problem, pose: _Pose, costs: _Costs, sub: np.ndarray) -> tuple[_Fit, _Costs]:
    """The alternation's setting and the final search's costs. One target per source node,
    unless the source (or the alternation's subset ``sub``) is denser than the target."""
    s, h = pose.sim.scale, _DENSE * p.tgt.spacing
    denser = p.src.spacing * s < h
    final = replace(costs, repeat=_REPEAT if denser else np.inf, many=denser)
    sub_denser = p.src.spacing * p.src.m / len(sub) * s < h
    metric = None
    if costs.ordered:  # across-contour 1, along-contour _TANGENTIAL (squared)
        t = _tangents(costs.y, costs.closed)
        d = t.shape[1]
        metric = np.eye(d) - (1 - np.sqrt(_TANGENTIAL)) * t[:, :, None] * t[:, None, :]
    sub_costs = replace(costs, repeat=final.repeat if sub_denser else np.inf, many=sub_denser)
    return _Fit(sub_costs, sub, p.phi, p.freq, metric), final


def _deformation(fit: _Fit, sim: Similarity, good: np.ndarray) -> np.ndarray:
    """The smooth deformation (m, d) fitted to the residuals of the trusted pairs."""
    rows, x, y = good[:, 0], fit.costs.x, fit.costs.y
    resid = y[good[:, 1]] - sim.apply(x[rows])
    return _modal_deformation(fit.phi, fit.freq, sim.rotation, rows, resid, _STIFF,
                              None if fit.metric is None else fit.metric[good[:, 1]])


def _alternate(fit: _Fit, sim: Similarity, rotate: bool) -> _Placement:
    """Alternate the search on the source nodes ``fit.sub`` with Horn's alignment
    (rotation only when ``rotate``): ``_RIGID`` rounds, then up to ``_DEFORM_ROUNDS`` with
    a smooth deformation in the source's lowest modes fitted to the trusted pairs too.
    The fits depend on the trusted pairs alone, so the same pairs twice running are a
    fixed point: it ends the rigid rounds (the deformation starts from it) and the
    deformation rounds after their first. Returns the last similarity and where it and
    the deformation take every source node."""
    x, y = fit.costs.x, fit.costs.y
    good = previous = None
    for _ in range(_RIGID):
        good, _ = _trusted_pairs(fit.costs, sim.apply(x), fit.sub)
        if previous is not None and np.array_equal(good, previous):
            break
        previous, good = good, None
        sim = align(x[previous[:, 0]], y[previous[:, 1]], rotate=rotate)
    shift = np.zeros_like(x)
    for r in range(_DEFORM_ROUNDS):
        if good is None:
            good, _ = _trusted_pairs(fit.costs, sim.apply(x) + shift, fit.sub)
        if r and np.array_equal(good, previous):
            break
        previous, good = good, None
        sim = align(x[previous[:, 0]], y[previous[:, 1]], rotate=rotate)
        shift = _deformation(fit, sim, previous)
    return _Placement(sim, sim.apply(x) + shift)


def _keep_or_turn(fit: _Fit, final: _Costs, placed: _Placement, turned: Similarity
                  ) -> _Placement:
    """The common frame won the pose search although a turned pose cost less: the
    alternation from the turned pose replaces ``placed`` only if it lowers the objective
    below ``_TURN_GAIN`` of its own (a shape turned by 5-45 degrees)."""
    free = _alternate(fit, turned, True)
    gain = _objective(final, free.z) < _TURN_GAIN * _objective(final, placed.z)
    return free if gain else placed


def _band(fit: _Fit, pairs: np.ndarray) -> np.ndarray:
    """Target nodes (k, 2 _COHERENT_BAND + 1) within ``_COHERENT_BAND`` of the partner of
    each source node of ``fit.sub`` in ``pairs`` (source index, target index); -1 for the
    unmatched nodes and past the ends of an open target."""
    n = len(fit.costs.y)
    partner = np.full(len(fit.costs.x), -1)
    partner[pairs[:, 0]] = pairs[:, 1]
    rows = np.flatnonzero(partner[fit.sub] >= 0)
    band = np.full((len(fit.sub), 2 * _COHERENT_BAND + 1), -1)
    near = partner[fit.sub[rows], None] + np.arange(-_COHERENT_BAND, _COHERENT_BAND + 1)
    if fit.costs.closed:
        band[rows] = near % n
    else:
        band[rows] = np.where((near >= 0) & (near < n), near, -1)
    return band


def _features(z0: np.ndarray, landmarks: np.ndarray) -> np.ndarray:
    """Nystrom features (m, r) of the Gaussian kernel of width ``_COHERENT_WIDTH`` on the
    points ``z0``: ``k(a, b) ~ f(a) . f(b)``, from the kernel on the ``landmarks`` rows,
    its eigenvalues below ``_EIG_FLOOR`` of the largest dropped."""
    def kernel(a, b):
        return np.exp(-_sq_dist(a, b) / (2 * _COHERENT_WIDTH**2))

    s, V = np.linalg.eigh(kernel(z0[landmarks], z0[landmarks]))
    keep = s > _EIG_FLOOR * s[-1]
    return kernel(z0, z0[landmarks]) @ (V[:, keep] / np.sqrt(s[keep]))


def _coherent(fit: _Fit, placed: _Placement, pairs: np.ndarray) -> np.ndarray:
    """Coherent point drift (Myronenko & Song 2010) restricted to the band of each node's
    partner in ``pairs`` (the final search at ``placed.z``): the source nodes ``fit.sub``
    at their similarity ``placed.sim`` move by a smooth field (Gaussian kernel,
    ``_COHERENT_WIDTH``, weight ``_COHERENT_LAMBDA``) towards a soft assignment in which
    every target node shares one unit of weight among the source nodes whose band holds
    it (method.md §2). Returns where the similarity and the field take every source node,
    (m, d)."""
    x, y, sub = fit.costs.x, fit.costs.y, fit.sub
    z0 = placed.sim.apply(x)
    band = _band(fit, pairs)
    valid = band >= 0
    landmarks = sub[np.linspace(0, len(sub), min(len(sub), _COHERENT_LANDMARKS),
                                endpoint=False).astype(np.intp)]
    f_all = _features(z0, landmarks)
    f, zs, yb = f_all[sub], z0[sub], y[band]
    d = x.shape[1]
    floor = _COHERENT_FLOOR**2 * fit.costs.h2
    # CPD's start: the mean squared distance between every source and target node
    sigma2 = (np.sum(zs**2) / len(zs) + np.sum(y**2) / len(y) - 2 * zs.mean(0) @ y.mean(0)) / d
    a = np.zeros((f.shape[1], d))
    D = np.sum((zs[:, None, :] - yb) ** 2, axis=2)
    for _ in range(_COHERENT_ROUNDS):
        # E-step: each target node shares one unit of weight among the bands that hold it
        K = np.where(valid, np.exp(-D / (2 * sigma2)), 0.0)
        share = np.bincount(band[valid], K[valid], minlength=len(y))
        P = K / np.maximum(share[band], np.finfo(float).tiny)
        p1 = P.sum(axis=1)
        # M-step: the field's coefficients (CPD's W, in the Nystrom features)
        target = np.einsum("kb,kbd->kd", P, yb) - p1[:, None] * zs
        a = np.linalg.solve(f.T @ (p1[:, None] * f) + _COHERENT_LAMBDA * sigma2
                            * np.eye(f.shape[1]), f.T @ target)
        D = np.sum((zs[:, None, :] + (f @ a)[:, None, :] - yb) ** 2, axis=2)
        sigma2 = max(float(np.sum(P * D) / (p1.sum() * d)), floor)
    return z0 + f_all @ a


def _final_pairs(final: _Costs, z: np.ndarray, found: tuple, reject: float):
    """The pairs ``found`` by the search on every source node placed at ``z`` (pairs
    and cost matrix), less those costing more than ``reject`` and, on a closed target,
    those that would go round it twice. Returns the pairs (target indices in search
    order) and their costs."""
    pairs, C = found
    cost = C[pairs[:, 0], pairs[:, 1]]
    keep = cost <= reject
    if final.closed:  # partners round the target once: none crossing at the cut or a step back
        keep &= _untangle(pairs[:, 1], cost, len(final.y), _SKIP, strict=not final.many)
    return pairs[keep], cost[keep]


def _settle(fit: _Fit, final: _Costs, placed: _Placement, ordered: bool):
    """Where the source ends (m, d) and the final search there: for contours of at least
    ``_COHERENT_NODES`` nodes the coherent pass (:func:`_coherent`), each node's move from
    the alternation's placement cut to ``_COHERENT_REACH`` target spacings, unless the
    search's objective is higher there than at the alternation's placement (a smooth
    field that fits the pair worse: serifs, fingers spread differently). Measured
    (objective there / at the alternation's, seeds 2005 and 11, 4 pairs a family): pairs
    the pass made better 0.36-1.45, worse 1.69-5.29; with a limit of 1.5 instead of 1, 7
    glyph pairs of benchmarks/realdata.py (1.19-1.34) end further than 1 % from the
    target."""
    everyone = np.arange(len(placed.z))
    found = _search(final, placed.z, everyone)
    if not ordered or min(len(final.x), len(final.y)) < _COHERENT_NODES:
        return placed.z, found
    step = _coherent(fit, placed, found[0]) - placed.z
    reach = _COHERENT_REACH * np.sqrt(final.h2)
    length = np.linalg.norm(step, axis=1, keepdims=True)
    z = placed.z + step * np.minimum(1.0, reach / np.maximum(length, np.finfo(float).tiny))
    there = _search(final, z, everyone)
    if _total(there, len(z)) <= _total(found, len(z)):
        return z, there
    return placed.z, found


def _match_auto(src: Shape, tgt: Shape, n_modes: int, opts: MatchOptions
                ) -> tuple[np.ndarray, np.ndarray, Similarity, np.ndarray]:
    """The default matcher; also returns where the fitted similarity and deformation take
    every source node (the target's user coordinates), shape (m, d)."""
    p = _prepare(src, tgt, n_modes, opts.sigma, opts.rotation)
    sub = spread_indices(src, ALTERNATION_NODES)
    costs = _Costs(src.normalized, tgt.normalized, p.F, tgt.spacing**2, p.ordered, p.closed)
    pose = _contour_pose(p) if p.ordered else _cloud_pose(p, costs, sub)
    order = np.arange(tgt.m)[::-1] if pose.reverse else np.arange(tgt.m)
    costs = replace(costs, y=costs.y[order], F=costs.F[:, order])
    fit, final = _fits(p, pose, costs, sub)
    placed = _alternate(fit, pose.sim, pose.rotate)
    if opts.rotation == "auto" and pose.common:
        placed = _keep_or_turn(fit, final, placed, pose.turned)
    z, found = _settle(fit, final, placed, p.ordered)
    pairs, cost = _final_pairs(final, z, found, _REJECT if opts.reject is None else opts.reject)
    pairs = np.c_[pairs[:, 0], order[pairs[:, 1]]]
    landed = tgt.to_user(z)
    return pairs, cost, align(src.points[pairs[:, 0]], tgt.points[pairs[:, 1]]), landed


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
    dist, near = cKDTree(sub_s.points).query(src.points, k=4)
    w = 1.0 / np.maximum(dist, 1e-12 * src.size)
    w /= w.sum(axis=1, keepdims=True)
    landed = src.points + np.einsum("ik,ikd->id", w, (landed_c - sub_s.points)[near])
    j = cKDTree(tgt.points).query(landed)[1]
    gap = np.linalg.norm(tgt.points[j] - landed, axis=1)
    h = tgt.spacing * tgt.size * tgt.m / len(cj)  # the coarse target's node spacing
    cost = (gap / h) ** 2  # in squared coarse target spacings, as on the coarse level
    keep = cost <= (_REJECT if opts.reject is None else opts.reject)
    pairs = np.c_[np.flatnonzero(keep), j[keep]]
    return pairs, cost[keep], align(src.points[pairs[:, 0]], tgt.points[pairs[:, 1]]), landed


def _match_cloud(src: Shape, tgt: Shape, n_modes: int, opts: MatchOptions
                 ) -> tuple[np.ndarray, np.ndarray, Similarity]:
    """The default matcher for unordered 3D point sets: the modal matcher (above ``LARGE``
    nodes on one coarse node per ``NODES_PER_COARSE_CLOUD``, from ``COARSE`` to
    ``COARSE_CLOUD``), then :func:`modalmorph.matching.clouds.refine`,
    then each source node paired with the target node nearest to where it lands; pairs
    farther than ``sqrt(reject)`` target spacings are dropped. Cost in squared target
    spacings."""
    m = max(src.m, tgt.m)
    coarse = min(max(m // NODES_PER_COARSE_CLOUD, COARSE), COARSE_CLOUD)
    if m > LARGE:
        *_, landed = _match_large(src, tgt, n_modes, opts, coarse)
    else:
        *_, landed = _match_auto(src, tgt, n_modes, opts)
    start = min(src.m, coarse) // 4
    y = tgt.normalized
    z = refine(src.normalized, tgt.to_normalized(landed), y, start)
    gap, j = cKDTree(y).query(z)
    cost = (gap / tgt.spacing) ** 2
    keep = cost <= (_REJECT if opts.reject is None else opts.reject)
    pairs = np.c_[np.flatnonzero(keep), j[keep]]
    return pairs, cost[keep], align(src.points[pairs[:, 0]], tgt.points[pairs[:, 1]])


def _match_paper(src: Shape, tgt: Shape, n_modes: int, opts: MatchOptions):
    """The paper's searches over the affinity (8): ``"local"`` or ``"global"``."""
    if src.m * tgt.m > MAX_AFFINITY:
        raise ShapeError(f"method={opts.method!r} builds the full {src.m} x {tgt.m} "
                         f"affinity matrix (8), too large here; use method='auto', which "
                         f"matches large objects in linear memory")
    phi1, _ = modal_features(src, n_modes, sigma=opts.sigma)
    phi2, _ = modal_features(tgt, n_modes, sigma=opts.sigma)
    Z = affinity(phi1, _fix_signs(phi1, phi2))  # (8)
    if opts.method == "local":
        pairs = _mutual_best(Z)
    else:
        r, c = linear_sum_assignment(Z)
        pairs = np.c_[r, c][_reject(Z[r, c], 3.0 if opts.reject is None else opts.reject)]
    return pairs, Z[pairs[:, 0], pairs[:, 1]], None


def _shapes(source, target) -> tuple[Shape, Shape]:
    """Both objects as shapes of one dimension; a closed contour must have an area."""
    src, tgt = as_shape(source, "source"), as_shape(target, "target")
    for name, shape in (("source", src), ("target", tgt)):
        if shape.dim == 2 and shape.ordered and shape.closed and (
                abs(area(shape.normalized)) < FLAT_AREA):
            raise ShapeError(f"{name} is a closed contour with no area (its nodes lie on "
                             f"one line): pass it as Shape(points, closed=False)")
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
        or an unordered 2D set (``ordered=False``).
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
    n_modes = DEFAULT_MODES if opts.modes is None else int(opts.modes)
    n_modes = min(n_modes, src.dim * min(src.m, tgt.m, MAX_MODEL_NODES))
    if opts.method != "auto":
        pairs, cost, sim = _match_paper(src, tgt, n_modes, opts)
    elif src.dim == 3 and not (src.ordered or tgt.ordered):
        pairs, cost, sim = _match_cloud(src, tgt, n_modes, opts)
    else:
        large = max(src.m, tgt.m) > LARGE
        pairs, cost, sim, _ = (_match_large if large else _match_auto)(src, tgt, n_modes,
                                                                       opts)
    order = np.argsort(pairs[:, 0], kind="stable")
    return Matching(pairs=pairs[order].astype(np.intp), cost=cost[order], method=opts.method,
                    modes=n_modes, sigma=opts.sigma, similarity=sim, shape=(src.m, tgt.m),
                    options=opts)
