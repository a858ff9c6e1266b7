"""Correspondence along the normals: each node of a contour goes to where the contour's
normal line at the node meets another contour (``track``'s ``correspondence="normal"``).

A contour shows no motion along itself: pairing a node with its nearest point of the
next contour lets it slide along the wall, towards a part that moves less (method.md's
trap of nearest pairs in a normalised frame). Along the normals a wall that moves
inward or outward keeps its material points where they were along it.
"""

from __future__ import annotations

from bisect import bisect_left

import numpy as np
from scipy.ndimage import gaussian_filter1d

from ..core.shape import Shape

__all__ = ["along_normals", "NORMAL_REACH", "NORMAL_SCALE", "FOLD_STARTS"]

# A node's normal line is followed to the other contour only up to this many times the
# distance to the contour's closest point (or the node spacing): lines more oblique than
# 60 degrees to the contour, or ones that meet a far part of it, take the closest point.
NORMAL_REACH = 2.0
# The normals are those of the contour smoothed over this fraction of its nodes (a
# Gaussian, at least 1 node): the wall's direction, not the jitter of drawn nodes or of a
# segmentation. 20-frame synthetic heart (tests/test_track.py, reference="first"), median
# error / node spacing at 70/250/1000 nodes: unsmoothed 0.36/1.23/3.29 (795 node-frames at
# 250 nodes with normals crossing before the contour), 0.02: 0.30/1.05/4.08 (none),
# 0.08: 0.24/0.82/3.26, 0.16: 0.23/0.80/3.17 (track's default, nearest pairs from the
# previous frame: 0.39/0.94/3.39). Ring phantoms with 0.2 px boundary noise, worst
# segment circumferential error (contract/akinetic/hypokinetic): 0.02: 1.95/2.05/1.55,
# 0.08: 1.27/1.72/0.94 points; noiseless unchanged within 0.1 point. Larger scales turn
# the normals towards the directions from the contour's middle (a circle's normals).
NORMAL_SCALE = 0.08
# Where normal lines cross before the contour (a concave stretch, large motions) the
# nodes' order is repaired from the longest run in order; so many starting nodes are
# tried round the contour for that run.
FOLD_STARTS = 8


def along_normals(source: Shape, target: Shape) -> np.ndarray:
    """Where the normal line of each node of ``source`` (2D contours) meets the partner
    contour of ``target`` (its polyline; ``target``'s contours in the order of their
    partners in ``source``): the crossing nearest the node, either side;
    a node whose line misses it, or meets it more than :data:`NORMAL_REACH` times
    farther than the polyline's closest point (or node spacing), goes to that closest
    point."""
    out = np.empty_like(source.points)
    for a, b in zip(source.slices, target.slices, strict=True):
        out[a] = _cast(source.points[a], target.points[b], source.closed, target.closed)
    return out


def _cast(p: np.ndarray, q: np.ndarray, closed: bool, closed_q: bool) -> np.ndarray:
    """:func:`_along_normals` of one contour ``p`` (m, 2) onto a polyline ``q``; closed
    contours keep their order round the polyline (:func:`_in_order`)."""
    tangent = gaussian_filter1d(p, max(NORMAL_SCALE * len(p), 1.0), axis=0, order=1,
                                mode="wrap" if closed else "nearest")
    n = np.c_[tangent[:, 1], -tangent[:, 0]]
    n /= np.maximum(np.linalg.norm(n, axis=1), np.finfo(float).tiny)[:, None]
    path = np.vstack([q, q[:1]]) if closed_q else q
    start, e = path[:-1], np.diff(path, axis=0)
    arc = np.r_[0.0, np.cumsum(np.linalg.norm(e, axis=1))]
    w = start[None] - p[:, None]  # p_i + s n_i = start_j + t e_j by Cramer's rule
    det = e[None, :, 0] * n[:, None, 1] - n[:, None, 0] * e[None, :, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (e[None, :, 0] * w[..., 1] - w[..., 0] * e[None, :, 1]) / det
        t = (n[:, None, 0] * w[..., 1] - n[:, None, 1] * w[..., 0]) / det
    s = np.where((t >= 0) & (t < 1) & np.isfinite(s), s, np.inf)
    rows = np.arange(len(p))
    cast = np.argmin(np.abs(s), axis=1)
    foot = np.clip(np.einsum("ijk,jk->ij", -w, e) / np.einsum("jk,jk->j", e, e), 0, 1)
    gap = np.linalg.norm(start[None] + foot[..., None] * e - p[:, None], axis=2)
    near = np.argmin(gap, axis=1)
    spacing = np.linalg.norm(np.diff(p, axis=0), axis=1).mean()
    ok = np.abs(s[rows, cast]) <= NORMAL_REACH * np.maximum(gap[rows, near], spacing)
    seg = np.where(ok, cast, near)
    u = arc[seg] + np.where(ok, t[rows, cast], foot[rows, near]) * (arc[seg + 1] - arc[seg])
    if closed and closed_q:
        u = _in_order(u, arc[-1], p)
    return np.column_stack([np.interp(u, arc, path[:, a]) for a in range(2)])


def _in_order(u: np.ndarray, total: float, p: np.ndarray) -> np.ndarray:
    """Arc-length places ``u`` (m,) on a closed polyline of length ``total`` for the
    nodes ``p`` of a closed contour, in the nodes' order round it: where normal lines
    cross before they reach the polyline (nodes folding back), the longest run of
    places in order is kept and the others spread between them by ``p``'s arc length."""
    step = np.mod(np.roll(u, -1) - u, total)
    if np.all((step < total / 2) & (step > 1e-9 * total)) and \
            abs(step.sum() - total) < 1e-6 * total:  # in order, none on another
        return u
    arc = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))]
    length = arc[-1] + np.linalg.norm(p[0] - p[-1])
    best = None
    for first in np.unique(np.linspace(0, len(u), FOLD_STARTS, endpoint=False).astype(int)):
        order = np.roll(np.arange(len(u)), -first)
        signed = np.where(step[order] < total / 2, step[order], step[order] - total)
        place = u[first] + np.r_[0.0, np.cumsum(signed[:-1])]
        keep = _increasing(place, place[0] + total)
        if best is None or len(keep) > len(best[2]):
            best = order, place, keep
    order, place, keep = best
    c = np.mod(arc[order] - arc[order[0]], length)
    xs = np.r_[c[keep[-1]] - length, c[keep], c[keep[0]] + length]
    ys = np.r_[place[keep[-1]] - total, place[keep], place[keep[0]] + total]
    out = np.empty_like(u)
    out[order] = np.mod(np.interp(c, xs, ys), total)
    return out


def _increasing(values: np.ndarray, below: float) -> np.ndarray:
    """Indices of the longest strictly increasing run of ``values`` under ``below``
    (a subsequence, patience sorting)."""
    tails, tail_at, before = [], [], np.full(len(values), -1)
    for i, v in enumerate(values):
        if v >= below:
            continue
        k = bisect_left(tails, v)
        before[i] = tail_at[k - 1] if k else -1
        if k == len(tails):
            tails.append(v)
            tail_at.append(i)
        else:
            tails[k], tail_at[k] = v, i
    out, i = [], tail_at[-1] if tail_at else -1
    while i >= 0:
        out.append(i)
        i = before[i]
    return np.array(out[::-1], dtype=np.intp)
