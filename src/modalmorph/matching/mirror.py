"""Mirror images of 2D contours (method.md §2, "Mirror images"): whether the target looks
like the source reflected, which no rotation reaches (:attr:`Matching.mirror`)."""

from __future__ import annotations

import logging

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.distance import cdist

from ..core.align import Similarity
from ..core.shape import Shape

__all__ = ["MIRROR", "MIRROR_EXACT", "MIRROR_SUSPECT", "mirror_called", "mirror_gap",
           "mirror_ratio", "mirror_said"]

log = logging.getLogger(__name__)

# A 2D contour's target looks like its mirror image (a 'b', a 'd') where the source placed
# by the pairs' similarity lies farther than MIRROR_SUSPECT of the target's RMS radius from
# it (g0: mirror_gap, every node both ways), and the source reflected, matched again in any
# pose, lies MIRROR times nearer (g1) than the source as given does in the nearer of its
# first pose and any pose (the first pose of rotation="auto" can be a wrong turn: a 0 of
# DejaVu Sans Mono onto STIX turned 34 deg lay 0.163 away, 0.019 in any pose). Measured
# by benchmarks/mirror.py on 4602 targets: letters, digits and symbols of DejaVu Sans /
# Serif / Mono, STIXGeneral, cmr10, cmss10, cmtt10 (5 cross-font, 2 same-font pairs of
# fonts, the outer contour and every contour, 100 and 200 nodes), the shared hearts ED ->
# ES, hands, the horse; each target as given, turned 34 deg, mirrored about x or y, turned
# or not. Not mirrored (1534): min(g0, any pose's) / g1 at most 1.33 (a heart, g0 0.041),
# 1.115 where g0 > 0.10; none said (the former rule, g0 > 0.12 and g0 / g1 > 3 with the
# first pose alone, said 10, all turned glyphs). Mirrored, of a source whose own mirror
# image in its best pose lies over 0.05 away and over twice the pair's gap (1148 to call;
# none of a heart or an O): the ratio at least 1.54. The gate decides the cost: g0 > 0.12
# on 14 of the 159 pairs of benchmarks/speed.py, whose second match adds ~30-50 % to a
# match (0.031 -> 0.041 CPU s at 250 nodes; the third runs only on the few said after
# it), and 984 of the 1148 said (993 before session 16's turn rule; the reviewer's STIX
# -> cmr10 pairs at 200 nodes mirrored in x: 23 of 29, was 11); at 0.10, 38 of 159 pay
# for 1049 (25 of 29; the misses then all under the gate: same-font A K Q 3 8 e S G, of
# asymmetry 0.05-0.096).
MIRROR_SUSPECT = 0.12
MIRROR = 1.4
_BRUTE = 250_000  # node pairs measured all at once by mirror_gap (a 250 x 1000 pair: 2 MB)
MIRROR_EXACT = 1e-9  # gaps below this x the other's: an exact mirror image (ratio capped)


def mirror_gap(x: np.ndarray, y: np.ndarray, sim: Similarity) -> float:
    """How far the whole source ``x`` placed by ``sim`` lies from the target ``y``: the
    RMS of both ways' nearest-node distances over the target's RMS radius (every node,
    not the pairs alone: onto a mirror image the matcher keeps the few that fit); all
    distances up to ``_BRUTE`` of them (70 nodes: 0.03 ms, two k-d trees 0.1), else k-d
    trees."""
    z = sim.apply(x)
    if len(z) * len(y) <= _BRUTE:
        d = cdist(z, y, "sqeuclidean")
        d_xy, d_yx = d.min(axis=1), d.min(axis=0)
    else:
        d_xy, d_yx = cKDTree(y).query(z)[0] ** 2, cKDTree(z).query(y)[0] ** 2
    return float(np.sqrt((np.mean(d_xy) + np.mean(d_yx)) / 2
                         / np.mean(np.sum((y - y.mean(axis=0)) ** 2, axis=1))))


def mirror_ratio(again, src: Shape, tgt: Shape, sim: Similarity) -> float | None:
    """:attr:`Matching.mirror`: where the source placed by the pairs' similarity lies
    farther than ``MIRROR_SUSPECT`` from the target (:func:`mirror_gap`: ``g0``), the source
    reflected (x -> -x; any reflection is this one turned) is matched again in any pose
    (``again(True)``: its similarity onto the target, ``rotation="free"``: ``g1``); where
    :func:`mirror_called` says so, the source as given is matched again in any pose too
    (``again(False)``), ``g0`` is the nearer of its two poses', and the ratio ``g0 / g1`` is
    returned where :func:`mirror_called` still says so (at most ``1 / MIRROR_EXACT``: an
    exact mirror image); else None."""
    g0 = mirror_gap(src.points, tgt.points, sim)
    if not g0 > MIRROR_SUSPECT:
        return None
    g1 = mirror_gap(src.points * [-1.0, 1.0], tgt.points, again(True))
    if not mirror_called(g0, g1):
        return None
    # the first pose may be a wrong turn that the free search avoids
    g0 = min(g0, mirror_gap(src.points, tgt.points, again(False)))
    if not mirror_called(g0, g1):
        return None
    ratio = float(g0 / max(g1, MIRROR_EXACT * g0))
    log.debug("%s", mirror_said(ratio))
    return ratio


def mirror_called(g0: float, g1: float) -> bool:
    """Whether the gaps of the source as placed (``g0``) and reflected (``g1``) say that
    the target is a mirror image (:func:`mirror_gap`)."""
    return bool(g0 > MIRROR * g1)


def mirror_said(mirror: float) -> str:
    """The clause saying that the target looks like the source's mirror image, and how
    much nearer the source reflected fits it (:attr:`Matching.mirror`)."""
    how = "exactly" if mirror * MIRROR_EXACT > 0.5 else f"{mirror:.3g} times nearer"
    return f"the target looks like the source's mirror image (the source reflected fits it {how})"
