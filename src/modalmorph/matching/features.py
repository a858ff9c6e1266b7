"""The modal model of each object and the features it gives its nodes (method.md §2).

:func:`modal_features` builds an object's Gaussian model and returns its lowest modes,
one row per node, scaled so that objects of different node counts compare. The paper's
searches compare them through the affinity (8) (:func:`affinity`, after :func:`fix_signs`);
the default search through :func:`signature`, which no rotation, mode sign or rotation
inside a degenerate eigenspace changes (:func:`prepare` builds the signature cost of every
pair of nodes, :class:`Problem`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..core.model import FEModel
from ..core.shape import Shape, as_shape, resample, share, spread_indices

__all__ = ["FEATURE_SIGMA", "MAX_MODEL_NODES", "modal_features", "fix_signs", "affinity",
           "signature", "sq_dist", "Problem", "prepare", "reflected"]

# Nominal Gaussian width of the matching models, x mean node spacing; sigma=None uses it
# where the Gram matrix stays well conditioned, else the largest width that does.
FEATURE_SIGMA = 2.0  # 1: precision/recall 0.90/0.75, 2: 0.95/0.95, 3: singular Gram
MAX_MODEL_NODES = 160  # largest model built: the eigenproblem is dense (not measured)
_SIG_WIDTH = 2  # modes summed per signature entry (not measured)
_SIG_WEIGHT = 1.0  # signature against position; 4 -> 1: two-hands precision 0.74 -> 0.80


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
        ``FEATURE_SIGMA`` or less, as :func:`modalmorph.core.element.auto_sigma` chooses.
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
                                     closed=shape.closed), closed=shape.closed) \
            if not shape.contours else _resampled(shape, max_nodes)
    else:
        subset = spread_indices(shape, max_nodes)
        model_shape = shape if len(subset) == shape.m else Shape(
            shape.points[subset], closed=shape.closed, ordered=shape.ordered)
    model = FEModel(model_shape, sigma=sigma, nominal_sigma=FEATURE_SIGMA)
    n_modes = min(int(n_modes), model.dim * model.m)
    modes = model.modes(n_modes)
    if model_shape is shape:
        phi = modes.node_shapes()
    else:  # u(x_i) = sum_k g_k(x_i) psi_k (1)-(4), at every node
        at = model.modes_at(modes, model_shape.to_normalized(shape.points))
        phi = at.reshape(shape.dim, shape.m, n_modes).transpose(1, 0, 2)
    rms = np.sqrt(np.mean(np.sum(phi**2, axis=1), axis=0))
    return phi / rms, modes.frequencies


def _resampled(shape: Shape, max_nodes: int) -> Shape:
    """An object of several contours, each resampled evenly by arc length, with at most
    ``max_nodes`` nodes shared among them by length (:func:`share`)."""
    counts = share(shape, min(shape.m, max_nodes))
    pts = [resample(shape.points[r], c, closed=shape.closed)
           for r, c in zip(shape.slices, counts, strict=True)]
    return Shape(np.vstack(pts), closed=shape.closed, contours=tuple(counts))


def fix_signs(phi1: np.ndarray, phi2: np.ndarray) -> np.ndarray:
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


def sq_dist(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Squared distances (m, n) between the rows of ``a`` (m, p) and ``b`` (n, p)."""
    out = np.sum(a**2, axis=1)[:, None] + np.sum(b**2, axis=1)[None, :]
    out -= 2 * a @ b.T  # in place: fewer fresh (m, n) arrays, the same operations
    return np.maximum(out, 0.0, out=out)


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
    return sq_dist(phi1.reshape(phi1.shape[0], -1), phi2.reshape(phi2.shape[0], -1))


def signature(phi: np.ndarray, width: int) -> np.ndarray:
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


@dataclass(frozen=True, eq=False)
class Problem:
    """Source and target as the default matcher sees them (:func:`prepare`)."""

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


def prepare(src: Shape, tgt: Shape, n_modes: int, sigma: float | None,
            rotation: str) -> Problem:
    """The source's modes and the signature cost between every source and target node."""
    phi1, w1 = modal_features(src, n_modes, sigma=sigma)
    phi2, _ = modal_features(tgt, n_modes, sigma=sigma)
    sig1, sig2 = signature(phi1, _SIG_WIDTH), signature(phi2, _SIG_WIDTH)
    F = sq_dist(sig1, sig2)
    F *= _SIG_WEIGHT  # _SIG_WEIGHT * sq_dist / width, in place
    F /= sig1.shape[1]
    return Problem(src, tgt, phi1, w1, F, rotation)


def reflected(p: Problem, rotation: str) -> Problem:
    """:func:`prepare`'s problem for the source reflected (x -> -x) onto the same target,
    from ``p``'s: the reflected model's matrices are the source's with the xy coupling
    blocks negated, so its modes are the source's with their x rows negated (the same
    frequencies) and its signatures, |phi|^2, and so ``F``, are the source's."""
    flip = np.array([-1.0, 1.0])
    return Problem(p.src.with_points(p.src.points * flip), p.tgt, p.phi * flip[:, None],
                   p.freq, p.F, rotation)
