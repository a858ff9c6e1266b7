"""Each point's distance to its nearest other point, for node spacings.

Up to :data:`BRUTE_NEAREST` points from every pair's squared distance, summed a component
at a time (the k-d tree's numbers, bit for bit: 830 contours of ``benchmarks/speed.py``'s
corpus at 20-250 nodes and random 2D and 3D sets of 4-300 points), a k-d tree above.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["BRUTE_NEAREST", "nearest_distances"]

# Every pair up to this many points, a k-d tree above: one thread, 70 points 65 -> 17 us,
# 100 points 86 -> 37 us, 128 points 97 -> 63 us, 160 points 115 -> 93 us
BRUTE_NEAREST = 128


def nearest_distances(points: np.ndarray) -> np.ndarray:
    """The distance (m,) from each of ``points`` (m, d), m >= 2, to its nearest other
    point: ``cKDTree(points).query(points, k=2)``'s second column."""
    m = len(points)
    if m > BRUTE_NEAREST:
        return cKDTree(points).query(points, k=2)[0][:, 1]
    xt = points.T  # |x_j - x_i|^2, one component at a time
    diff = xt[0][None, :] - xt[0][:, None]
    d2 = diff * diff
    for xa in xt[1:]:
        np.subtract(xa[None, :], xa[:, None], out=diff)
        diff *= diff
        d2 += diff
    d2.flat[::m + 1] = np.inf  # not the point itself
    return np.sqrt(d2.min(axis=1))
