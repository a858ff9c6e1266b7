"""Matching objects of several contours (a myocardium ring, a footprint), method.md §2.

One contour is matched by the ordered (cyclic) search of the default matcher. An object of
several contours (:attr:`Shape.contours`) is matched in three stages:

1. the pose of the whole object: the default (ordered) matcher on the largest contour of
   each object (the epicardium of a ring, the forefoot of a footprint), with the
   caller's ``rotation``; Horn's similarity of its pairs (translation and scale only
   with ``rotation="none"``) places the whole source. (All the nodes as one unordered
   2D set kept the common frame of a lobed ring turned by 40 or 160 degrees with
   ``rotation="auto"``; the largest contours find the turn: benchmarks/contours.py);
   The same stages match 3D polylines of several contours;
2. partner contours: an assignment (:func:`scipy.optimize.linear_sum_assignment`) over
   the two-way mean distance of each placed source contour to each target contour
   (:func:`pair_contours`); with unequal contour counts the extra contours stay
   unpaired;
3. each pair of partners matched by the ordered matcher in that pose
   (``rotation="none"``), so that a near-circular contour (an endocardium) is not
   turned on its own; the pairs are offset back to the rows of the whole objects.

The paper's searches (``"local"``, ``"global"``) run over all the nodes; their partner
contours are those that share the most pairs
(:func:`~modalmorph.core.dynamics.contour_partners`), and pairs
joining other contours are dropped.
"""

from __future__ import annotations

import logging
from collections.abc import Callable

import numpy as np
from scipy.optimize import linear_sum_assignment

from ..core.align import Similarity, align
from ..core.quality import area, curve_distances
from ..core.shape import Shape

__all__ = ["AREA_TIE", "keep_partners", "match_contours", "pair_contours",
           "unpaired_sentence"]

log = logging.getLogger(__name__)

# Weight of the relative area difference in the pairing cost, a tie-breaker only: wrong
# partners of the ring and footprint of tests/test_contours.py cost 0.30-2.1 target RMS
# radii (right ones 0.10-0.21, before the pose), this term at most AREA_TIE.
AREA_TIE = 1e-3


def pair_contours(a: Shape, b: Shape, placed: np.ndarray | None = None) -> np.ndarray:
    """Partner contours of two ordered shapes, (P, 2) of ``(contour of a, contour of b)``,
    sorted by ``a``'s contour: the assignment of least summed cost, the cost of a pair
    the larger of the mean distances both ways between the contour of ``a`` (its nodes
    at ``placed`` (m, d), the same rows as ``a``, when given) and the contour of ``b``,
    in units of ``b``'s RMS radius, plus ``AREA_TIE`` times their relative difference of
    area (2D). ``min(P_a, P_b)`` pairs."""
    pts = a.points if placed is None else np.asarray(placed, dtype=np.float64)
    cost = np.empty((len(a.sizes), len(b.sizes)))
    for k, rk in enumerate(a.slices):
        for j, rj in enumerate(b.slices):
            d_ab, d_ba = curve_distances(pts[rk], b.points[rj], closed_a=a.closed,
                                         closed_b=b.closed)
            cost[k, j] = max(d_ab.mean(), d_ba.mean()) / b.size
            if a.dim == 2 and a.closed and b.closed:
                s, t = abs(area(pts[rk])), abs(area(b.points[rj]))
                cost[k, j] += AREA_TIE * abs(s - t) / max(s, t, np.finfo(float).tiny)
    r, c = linear_sum_assignment(cost)
    return np.c_[r, c].astype(np.intp)


def keep_partners(a: Shape, b: Shape, pairs: np.ndarray, partners: np.ndarray
                  ) -> np.ndarray:
    """The mask (K,) of the pairs whose contours are partners."""
    partner = np.full(len(a.sizes), -1)
    partner[partners[:, 0]] = partners[:, 1]
    return partner[a.contour_of[pairs[:, 0]]] == b.contour_of[pairs[:, 1]]


def largest(shape: Shape) -> int:
    """The contour enclosing the largest area (closed 2D contours), else the longest."""
    if shape.dim == 2 and shape.closed:
        return int(np.argmax([abs(area(shape.points[r])) for r in shape.slices]))
    return int(np.argmax([np.linalg.norm(np.diff(shape.points[r], axis=0), axis=1).sum()
                          for r in shape.slices]))


def object_pose(src: Shape, tgt: Shape, rotation: str, match_one: Callable
                ) -> tuple[Similarity, float | None]:
    """The pose of the whole source: Horn's similarity of the pairs the ordered matcher
    finds between the largest contour of each object (``match_one(a, b)`` returns a
    Matching), with the caller's ``rotation``; no rotation with ``rotation="none"``.
    Also that match's ``mirror`` (the largest contours' mirror images)."""
    a, b = src.contour(largest(src)), tgt.contour(largest(tgt))
    found = match_one(a, b)
    return (align(a.points[found.pairs[:, 0]], b.points[found.pairs[:, 1]],
                  rotate=rotation != "none"), found.mirror)


def match_contours(src: Shape, tgt: Shape, rotation: str, match_one: Callable):
    """The default matcher on shapes of several contours (the module's three stages).

    ``match_one(a, b, **options)`` is :func:`modalmorph.match` (passed in: this module
    sits below it). Returns the pairs (K, 2) in the rows of the whole objects, their
    costs (K,), the similarity placing the source (Horn on all the pairs), the partner
    contours (P, 2) and the largest contours' ``Matching.mirror``.
    """
    pose, mirror = object_pose(src, tgt, rotation, match_one)
    placed = pose.apply(src.points)
    partners = pair_contours(src, tgt, placed)
    pairs, cost = [], []
    for k, j in partners:
        rk, rj = src.slices[k], tgt.slices[j]
        a = Shape(placed[rk], closed=src.closed)
        found = match_one(a, tgt.contour(j), rotation="none")
        pairs.append(found.pairs + [rk.start, rj.start])
        cost.append(found.cost)
    pairs, cost = np.vstack(pairs), np.concatenate(cost)
    said = unpaired_sentence(src, tgt, partners)
    if said:
        log.info("match: %s", said)
    sim = align(src.points[pairs[:, 0]], tgt.points[pairs[:, 1]])
    return pairs, cost, sim, partners, mirror


def unpaired_sentence(src: Shape, tgt: Shape, partners: np.ndarray,
                      outcome: tuple[str, str] = ("left unmatched", "left unmatched")) -> str:
    """A sentence naming the contours without a partner, each side with its ``outcome``
    (source, target); '' when every contour has one."""
    said = []
    for name, shape, col in (("source", src, 0), ("target", tgt, 1)):
        left = sorted(set(range(len(shape.sizes))) - set(partners[:, col].tolist()))
        if left:
            nodes = ", ".join(str(shape.sizes[k]) for k in left)
            which = ", ".join(str(k) for k in left)
            said.append(f"{name} contour{'s' if len(left) > 1 else ''} {which} ({nodes} "
                        f"nodes) without a partner contour: {outcome[col]}")
    return "; ".join(said)
