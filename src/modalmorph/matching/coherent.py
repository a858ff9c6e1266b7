"""The coherent passes of the default matcher: on contours (method.md §2), and the
rigid one that poses a 3D point set (:func:`rigid_pose`).

Geometry alone leaves the position along a near-circular stretch open. After the
alternation, :func:`drift` moves the source by coherent point drift (Myronenko & Song
2010), restricted to a band of target nodes about each node's partner, with a smooth
Gaussian field in Nystrom features; :func:`settle` keeps its result, each node's move cut
to a few target spacings, only where it does not raise the search's objective.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.distance import cdist

from ..core.align import Similarity
from ..core.shape import even_subset
from .alternation import Fit, Placement
from .features import sq_dist
from .search import Costs, pairs_at, total

__all__ = ["drift", "rigid_pose", "settle"]

_COHERENT_WIDTH = 1.0  # kernel width x target RMS radius (hand precision 1.5: 0.835, 1: 0.866)
_COHERENT_LAMBDA = 2.0  # smoothness weight, CPD's default (8: warp-strong 0.958 vs 0.985)
_COHERENT_BAND = 8  # target nodes either side of a partner (4: combined 0.918 vs 0.944)
_COHERENT_ROUNDS = 50  # EM rounds (25: common-heart 0.990 / 0.879 vs 0.996 / 0.933)
_COHERENT_FLOOR = 1.0  # sigma >= this x target spacing (none: start recall 0.987 vs 0.997)
_COHERENT_LANDMARKS = 64  # Nystrom landmarks: the table to 3 decimals as the full kernel
_COHERENT_REACH = 3.0  # largest move x target spacing (unclamped: the F glyph folded)
_COHERENT_NODES = 100  # fewer nodes, no pass (29-node glyph Q folded; 70-node hand +5 ms)
_EIG_FLOOR = 1e-10  # kernel eigenvalues below this x the largest are rounding (not measured)


def _band(fit: Fit, pairs: np.ndarray) -> np.ndarray:
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


def _nystrom(z0: np.ndarray, landmarks: np.ndarray) -> np.ndarray:
    """Nystrom features (m, r) of the Gaussian kernel of width ``_COHERENT_WIDTH`` on the
    points ``z0``: ``k(a, b) ~ f(a) . f(b)``, from the kernel on the ``landmarks`` rows,
    its eigenvalues below ``_EIG_FLOOR`` of the largest dropped."""
    def kernel(a, b):
        return np.exp(-sq_dist(a, b) / (2 * _COHERENT_WIDTH**2))

    s, V = np.linalg.eigh(kernel(z0[landmarks], z0[landmarks]))
    keep = s > _EIG_FLOOR * s[-1]
    return kernel(z0, z0[landmarks]) @ (V[:, keep] / np.sqrt(s[keep]))


def _band_sq_dist(z: np.ndarray, yb: np.ndarray) -> np.ndarray:
    """``np.sum((z[:, None, :] - yb) ** 2, axis=2)`` (k, b), bit for bit; 2D compiled."""
    if z.shape[1] != 2:
        return np.sum((z[:, None, :] - yb) ** 2, axis=2)
    from ._dp import band_sq_dist
    return band_sq_dist(np.ascontiguousarray(z), yb)


def drift(fit: Fit, placed: Placement, pairs: np.ndarray) -> np.ndarray:
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
    f_all = _nystrom(z0, landmarks)
    f, zs, yb = f_all[sub], z0[sub], y[band]
    d = x.shape[1]
    floor = _COHERENT_FLOOR**2 * fit.costs.h2
    # CPD's start: the mean squared distance between every source and target node
    sigma2 = (np.sum(zs**2) / len(zs) + np.sum(y**2) / len(y) - 2 * zs.mean(0) @ y.mean(0)) / d
    a = np.zeros((f.shape[1], d))
    D = _band_sq_dist(zs, yb)
    eye = np.eye(f.shape[1])
    from ._dp import shared_weights  # compiled, numpy's operations in its order
    for _ in range(_COHERENT_ROUNDS):
        # E-step: each target node shares one unit of weight among the bands that hold it
        P = shared_weights(np.exp(-D / (2 * sigma2)), valid, band, len(y))
        p1 = P.sum(axis=1)
        if not p1.any():  # every band out of reach (shapes far apart): no field to fit
            break
        # M-step: the field's coefficients (CPD's W, in the Nystrom features)
        target = np.einsum("kb,kbd->kd", P, yb) - p1[:, None] * zs
        a = np.linalg.solve(f.T @ (p1[:, None] * f) + _COHERENT_LAMBDA * sigma2 * eye,
                            f.T @ target)
        D = _band_sq_dist(zs + f @ a, yb)
        sigma2 = max(float(np.sum(P * D) / (p1.sum() * d)), floor)
    return z0 + f_all @ a


def settle(fit: Fit, final: Costs, placed: Placement, ordered: bool):
    """Where the source ends (m, d) and the final search there: for contours of at least
    ``_COHERENT_NODES`` nodes the coherent pass (:func:`drift`), each node's move from
    the alternation's placement cut to ``_COHERENT_REACH`` target spacings, unless the
    search's objective is higher there than at the alternation's placement (a smooth
    field that fits the pair worse: serifs, fingers spread differently; the limit's
    measurement is in method.md §2)."""
    everyone = np.arange(len(placed.z))
    found = pairs_at(final, placed.z, everyone) if placed.found is None else placed.found
    if not ordered or min(len(final.x), len(final.y)) < _COHERENT_NODES:
        return placed.z, found
    step = drift(fit, placed, found[0]) - placed.z
    reach = _COHERENT_REACH * np.sqrt(final.h2)
    length = np.linalg.norm(step, axis=1, keepdims=True)
    z = placed.z + step * np.minimum(1.0, reach / np.maximum(length, np.finfo(float).tiny))
    there = pairs_at(final, z, everyone)
    if total(there, len(z)) <= total(found, len(z)):
        return z, there
    return placed.z, found


# rigid_pose: nodes of the source's even subset (the target's: as many times fewer as it
# has fewer nodes), EM rounds at most, and the stop (relative change of sigma^2). On the
# test's blob (two samplings of 4000 points, 8 deg apart): 1000 / 2000 / 4000 nodes end
# 0.78 / 1.17 / 1.33 deg off (the samplings' chance clumps, not the count); without the
# stop, 100 / 200 rounds 0.72 deg. In the route it costs 0.3-0.5 CPU-s at 2000-10 000 points.
_RIGID_NODES = 1000
_RIGID_ROUNDS = 100
_RIGID_TOL = 1e-4
_RIGID_SPREAD = 4  # at most this x _RIGID_NODES target nodes (memory: 4e6 distances)


def rigid_pose(p: np.ndarray, y: np.ndarray) -> Similarity:
    """The similarity that best lays the posed source ``p`` (m, 3) on the target ``y``
    (n, 3) as a Gaussian mixture: rigid coherent point drift (Myronenko & Song 2010,
    with scale; no outlier term), on even subsets of ``_RIGID_NODES`` source nodes,
    started at the identity with CPD's wide sigma, which narrows as it fits. The pose a
    3D point set's refinement starts from: the modal match's own similarity holds a
    part of its deformation."""
    a = p[even_subset(p, min(_RIGID_NODES, len(p)))]
    b = y[even_subset(y, min(max(_RIGID_NODES * len(y) // len(p), 1), len(y),
                             _RIGID_SPREAD * _RIGID_NODES))]
    d = a.shape[1]
    sim = Similarity(np.eye(d), 1.0, np.zeros(d))
    dist = cdist(a, b, "sqeuclidean")
    sigma2 = dist.mean() / d
    for _ in range(_RIGID_ROUNDS):
        w = np.exp(-(dist - dist.min(axis=0)) / (2 * sigma2))  # each target node's shares
        w /= w.sum(axis=0)
        mass = w.sum()
        mu_a, mu_b = w.sum(axis=1) @ a / mass, w.sum(axis=0) @ b / mass
        ac, bc = a - mu_a, b - mu_b
        u, sv, vt = np.linalg.svd(bc.T @ w.T @ ac)  # sum of w b a^T: Kabsch
        flip = np.ones(d)
        flip[-1] = np.sign(np.linalg.det(u @ vt))
        rot = u @ np.diag(flip) @ vt
        scale = float(sv @ flip / (w.sum(axis=1) @ np.sum(ac**2, axis=1)))
        sim = Similarity(rot, scale, mu_b - scale * rot @ mu_a)
        dist = cdist(sim.apply(a), b, "sqeuclidean")
        last, sigma2 = sigma2, max(float(np.sum(w * dist) / (mass * d)), 1e-12 * sigma2)
        if abs(last - sigma2) <= _RIGID_TOL * last:
            break
    return sim
