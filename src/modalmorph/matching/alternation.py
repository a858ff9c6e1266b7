"""The alternation of the default matcher: search, fit, deform (method.md §2).

From the pose, the search on a subset of the source nodes alternates with Horn's alignment
on its trusted pairs (:func:`modalmorph.core.align.align`): a few rigid rounds, then rounds
with a smooth deformation in the source's lowest modes fitted to the same pairs
(:func:`alternate`), until the trusted pairs repeat. :func:`fits` sets it up (:class:`Fit`:
the subset's search, the source modes and, for contours, a metric that weights the
along-contour part of a residual less); :func:`keep_or_turn` tries a turned start when the
common frame won the pose search. The result is a :class:`Placement`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..core.align import Similarity, align
from .features import Problem
from .pose import Pose
from .search import REPEAT, Costs, pairs_at, total, trusted_pairs

__all__ = ["Fit", "Placement", "fits", "alternate", "keep_or_turn"]

_DENSE = 0.95  # source spacing below this x the target's may repeat targets (not measured)
_RIGID = 3  # rigid rounds first; with the next and _TANGENTIAL: precision 0.931 -> 0.967
_DEFORM_ROUNDS = 8  # rounds with the deformation (measured together with _RIGID)
_STIFF = 1e-3  # weight of the modal strain energy in the deformation fit (not measured)
_TANGENTIAL = 0.3  # weight of the along-contour residual (measured together with _RIGID)
# A contour's node lies up to half its own spacing off a finer target's curve after a
# smooth fit (a chord's sagitta is less): a coarser source contour's distances are measured
# in this share of its spacing. 20-, 30- and 60-node circles onto a 400-node ellipse kept
# 4, 4 and 8 pairs in target spacings (20 raised), all with 0.5 or 0.75; 0.35 keeps 28 of
# 30 at 30 -> 200 and 34 of 40 at 40 -> 200, 0.25 16 and 32; no pair of realdata.py or the
# regression changes.
# 3D point sets keep the target's spacing (review18: a 162-vertex sphere onto a 2562-vertex
# ellipsoid paired 0.229 -> 0.252 spacings off with it).
_COARSE_REACH = 0.5
_TURN_GAIN = 0.5  # a turn must lower the objective below this: hearts >= 0.67, hands 0.37
# Or lower it at all, turned by more than this (degrees): the shared hearts' turned
# alternatives lie at most 21.4 degrees off where they lower it (685 runs: 16 pairs both
# ways, 40-300 nodes and as given; at 20, 17 of them turned); glyphs and hands turned
# 25-35 degrees are found (benchmarks/turns.py; method.md §2)
_TURN_BEYOND = 25.0


@dataclass(frozen=True, eq=False)
class Fit:
    """The alternation's setting: its search on the source nodes ``sub``, the source
    modes for the deformation and, for contours, the metric (n, d, d) that weights the
    along-contour part of a residual by ``_TANGENTIAL``."""

    costs: Costs
    sub: np.ndarray
    phi: np.ndarray
    freq: np.ndarray
    metric: np.ndarray | None


@dataclass(frozen=True, eq=False)
class Placement:
    """A similarity and where it, with a deformation, takes every source node (m, d);
    ``found``, when already run, the final search there (pairs and their costs,
    :func:`~modalmorph.matching.search.pairs_at` on every node)."""

    sim: Similarity
    z: np.ndarray
    found: tuple | None = None


def _tangents(y: np.ndarray, closed: bool, k: int = 2) -> np.ndarray:
    """Unit tangents (n, d) of an ordered contour: central differences over ``k`` nodes on
    each side (one-sided at the ends of an open one), robust to noise on single nodes."""
    n = len(y)
    k = max(1, min(k, (n - 1) // 2))
    if closed:  # np.roll(y, -k) - np.roll(y, k), 0 < k < n
        t = np.concatenate((y[k:], y[:k])) - np.concatenate((y[n - k:], y[:n - k]))
    else:
        idx = np.arange(n)
        t = y[np.minimum(idx + k, n - 1)] - y[np.maximum(idx - k, 0)]
    norm = np.sqrt(np.add.reduce(t * t, axis=1, keepdims=True))  # np.linalg.norm's numbers
    return t / np.maximum(norm, 1e-300)


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


def fits(p: Problem, pose: Pose, costs: Costs, sub: np.ndarray) -> tuple[Fit, Costs]:
    """The alternation's setting and the final search's costs. One target per source node,
    unless the source (or the alternation's subset ``sub``) is denser than the target."""
    s, h = pose.sim.scale, _DENSE * p.tgt.spacing
    denser = p.src.spacing * s < h
    if costs.ordered:  # distances in half a coarser source contour's spacing
        costs = replace(costs, h2=max(costs.h2, (_COARSE_REACH * p.src.spacing * s) ** 2))
    final = replace(costs, repeat=REPEAT if denser else np.inf, many=denser)
    sub_denser = p.src.spacing * p.src.m / len(sub) * s < h
    metric = None
    if costs.ordered:  # across-contour 1, along-contour _TANGENTIAL (squared)
        t = _tangents(costs.y, costs.closed)
        d = t.shape[1]
        metric = np.eye(d) - (1 - np.sqrt(_TANGENTIAL)) * t[:, :, None] * t[:, None, :]
    sub_costs = replace(costs, repeat=final.repeat if sub_denser else np.inf, many=sub_denser)
    return Fit(sub_costs, sub, p.phi, p.freq, metric), final


def _deformation(fit: Fit, sim: Similarity, good: np.ndarray) -> np.ndarray:
    """The smooth deformation (m, d) fitted to the residuals of the trusted pairs."""
    rows, x, y = good[:, 0], fit.costs.x, fit.costs.y
    resid = y[good[:, 1]] - sim.apply(x[rows])
    return _modal_deformation(fit.phi, fit.freq, sim.rotation, rows, resid, _STIFF,
                              None if fit.metric is None else fit.metric[good[:, 1]])


def alternate(fit: Fit, sim: Similarity, rotate: bool) -> Placement:
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
        good, _ = trusted_pairs(fit.costs, sim.apply(x), fit.sub)
        if previous is not None and np.array_equal(good, previous) or len(good) <= x.shape[1]:
            break
        previous, good = good, None
        sim = align(x[previous[:, 0]], y[previous[:, 1]], rotate=rotate)
    shift = np.zeros_like(x)
    for r in range(_DEFORM_ROUNDS):
        if good is None:
            good, _ = trusted_pairs(fit.costs, sim.apply(x) + shift, fit.sub)
        if r and np.array_equal(good, previous) or len(good) <= x.shape[1]:
            break  # a fixed point, or too few pairs near to fit (a pose off the target)
        previous, good = good, None
        sim = align(x[previous[:, 0]], y[previous[:, 1]], rotate=rotate)
        shift = _deformation(fit, sim, previous)
    return Placement(sim, sim.apply(x) + shift)


def keep_or_turn(fit: Fit, final: Costs, placed: Placement, turned: Similarity
                 ) -> Placement:
    """The common frame won the pose search although a turned pose cost less: the
    alternation from the turned pose replaces ``placed`` if it lowers the objective below
    ``_TURN_GAIN`` of its own (a shape turned by 5-45 degrees), or lowers it at all with a
    turn of more than ``_TURN_BEYOND``."""
    free = alternate(fit, turned, True)
    everyone = np.arange(len(placed.z))
    free = replace(free, found=pairs_at(final, free.z, everyone))
    placed = replace(placed, found=pairs_at(final, placed.z, everyone))
    turned, kept = total(free.found, len(free.z)), total(placed.found, len(placed.z))
    gain = turned < _TURN_GAIN * kept or (turned < kept and free.sim.angle > _TURN_BEYOND)
    return free if gain else placed  # with its final search, which settle() reuses
