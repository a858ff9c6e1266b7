"""Fine correspondence between unordered 3D point sets (issue 16).

The modal matcher (:mod:`modalmorph.matching`) finds the pose and a smooth deformation in
the lowest modes, on at most ``COARSE`` nodes: where it takes the source is right to
about a coarse node spacing. :func:`refine` carries it the rest of the way, coarse to
fine: the source is moved by a displacement field smoothed with Gaussians of decreasing
width (the kernel of Sclaroff's element (1), on control nodes spread over the source),
each time fitted to where the target lies near the moved source, in both directions
(nearest target of each source node, nearest moved source node of each target node), so
that the source neither collapses onto part of the target nor leaves part of it
uncovered. Each node is then paired with the target node nearest to where it lands
(k-d trees, memory linear in the node counts).
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.spatial import cKDTree

__all__ = ["refine"]

_ROUNDS = 3  # transport and smoothing rounds per level
_NEIGHBOURS = 16  # nearest nodes: controls per node, and edges of the transport graph
_SINKHORN = 30  # scaling iterations of the transport
_TEMPERATURE = 0.5  # width of the transport's Gaussian, x the level's node spacing
_WIDTH = 8.0  # smoothing width, x the level's node spacing


def _controls(x: np.ndarray, width: float) -> np.ndarray:
    """Control nodes about ``width`` apart: the mean of the nodes in each cube of a grid."""
    cell = np.floor(x / width).astype(np.int64)
    _, inverse = np.unique(cell, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    count = np.bincount(inverse)
    return np.stack([np.bincount(inverse, x[:, a]) for a in range(3)], axis=1) / count[:, None]


def _smooth(x: np.ndarray, rows: np.ndarray, resid: np.ndarray, width: float) -> np.ndarray:
    """A displacement field over every node ``x`` (m, 3), Gaussian-smoothed (width
    ``width``) from the residuals ``resid`` (k, 3) of the nodes ``rows``: the residuals are
    averaged onto control nodes ``width`` apart, and every node takes the Gaussian-weighted
    mean of its nearest controls (the kernel of Sclaroff's element (1))."""
    c = _controls(x[rows], width)
    k = min(_NEIGHBOURS, len(c))
    tree = cKDTree(c)

    def weights(p):
        dist, near = tree.query(p, k=k)
        dist, near = dist.reshape(len(p), k), near.reshape(len(p), k)
        w = np.exp(-0.5 * (dist / width) ** 2)
        return w / w.sum(axis=1, keepdims=True), near

    w, near = weights(x[rows])
    flat, wr = near.ravel(), w.ravel()
    tot = np.bincount(flat, wr, minlength=len(c))
    ctrl = np.stack([np.bincount(flat, wr * np.repeat(resid[:, a], k), minlength=len(c))
                     for a in range(3)], axis=1) / np.maximum(tot, 1e-12)[:, None]
    w, near = weights(x)
    return np.einsum("ik,ika->ia", w, ctrl[near])


def _transport(z: np.ndarray, y: np.ndarray, temperature: float) -> np.ndarray:
    """Where each moved source node ``z`` (s, 3) belongs on the target nodes ``y`` (t, 3):
    the barycentre of its row of an entropic transport plan (Sinkhorn scaling) between
    the two, each source node carrying mass 1 and each target node ``s / t``, on the
    sparse graph of each side's nearest nodes on the other. The equal masses make the
    source cover the target evenly, which slides it along the surface where nearest
    nodes alone would not."""
    s, t = len(z), len(y)
    k = min(_NEIGHBOURS, s, t)
    d1, j1 = cKDTree(y).query(z, k=k)
    d2, i2 = cKDTree(z).query(y, k=k)
    rows = np.r_[np.repeat(np.arange(s), k), i2.ravel()]
    cols = np.r_[j1.ravel(), np.repeat(np.arange(t), k)]
    dist = np.r_[d1.ravel(), d2.ravel()]
    P = coo_matrix((np.exp(-0.5 * (dist / temperature) ** 2), (rows, cols)), shape=(s, t))
    P = P.tocsr()
    P.sum_duplicates()
    P.data = np.maximum(P.data, 1e-300)
    a, b = np.ones(s), np.ones(t)
    for _ in range(_SINKHORN):
        a = 1.0 / (P @ b)
        b = (s / t) / (P.T @ a)
    plan = P.multiply(a[:, None]).multiply(b[None, :]).tocsr()
    return (plan @ y) / np.asarray(plan.sum(axis=1))


def refine(x: np.ndarray, z: np.ndarray, y: np.ndarray, start: int) -> np.ndarray:
    """Where the source lands on the target, refined coarse to fine.

    At each level a subset of the nodes, four times larger each time from ``start``
    source nodes, is put in transport with as large a share of the target
    (:func:`_transport`), and the move of each node of the subset towards its share is
    smoothed over the source (:func:`_smooth`) with a width of a few of the level's node
    spacings and applied to every node.

    Parameters
    ----------
    x : ndarray, shape (m, 3)
        The source nodes (normalised frame: the displacement field is smooth over them).
    z : ndarray, shape (m, 3)
        Where the coarse match takes them, in the target's normalised frame.
    y : ndarray, shape (n, 3)
        The target nodes, normalised.
    start : int
        Source nodes of the first level (the coarse match's resolution).

    Returns
    -------
    ndarray, shape (m, 3)
        The refined positions of the source nodes.
    """
    m, n = len(x), len(y)
    # nested random subsets, fixed seed: every level's nodes spread evenly in expectation
    ps, pt = np.random.default_rng(0).permutation(m), np.random.default_rng(1).permutation(n)
    z = z.copy()
    size = start
    while True:
        size = min(size * 4, m)
        rows, cols = ps[:size], pt[:max(int(round(size * n / m)), 1)]
        h = cKDTree(y[cols]).query(y[cols], k=2)[0][:, 1].mean()
        for _ in range(_ROUNDS):
            goal = _transport(z[rows], y[cols], _TEMPERATURE * h)
            z += _smooth(x, rows, goal - z[rows], _WIDTH * h)
        if size == m:
            return z
