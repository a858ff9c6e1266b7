"""The modes a simulation superposes and their values at every node (method.md §4, §7).

How many modes (:func:`mode_count`), the Rayleigh-Ritz augmentation of a truncated basis
with smooth motions (:func:`superposed_modes`), the similarity motions of the model's
nodes (:func:`similarity_fields`), and ``Phi`` at every node of the source, through the
element's field for a reduced model (:class:`Field`).
"""

from __future__ import annotations

import numpy as np
from scipy import sparse
from scipy.spatial import cKDTree

from ..core.affine import affine_fit_weights
from ..core.model import FEModel
from ..core.modes import Modes
from ..errors import OptionError

__all__ = ["AFFINE_NEIGHBOURS", "COARSE_MAX", "Field", "SPARSE_MODES",
           "affine_weights", "flat", "mode_count", "nodes", "similarity_fields",
           "smooth_fields", "superposed_modes"]

SPARSE_MODES = 100  # modes superposed by default with the sparse solvers (method.md §7)
COARSE_MAX = 400  # nodes of the coarse copy whose modes augment a truncated basis (§7)
# A reduced 3D model's nodal displacement at every node: the Gaussian-weighted least-squares
# affine fit of this many nearest model nodes (method.md §7). Measured on the bunny (1839
# nodes, 400 model nodes): a shift of one size and a 90 deg turn are reproduced to 1e-4
# and 6e-4 sizes at worst (the element's field: 0.17 and 0.31), a 25 % warp to 0.02 (12
# and 24 neighbours: the same to 0.003).
AFFINE_NEIGHBOURS = 16
AFFINE_BLOCK = 1 << 16  # points fitted at once: about 100 MB of work arrays a block


def flat(P: np.ndarray) -> np.ndarray:
    """(m, d) -> component-major (d*m,) (7)."""
    return P.T.reshape(-1)


def nodes(u: np.ndarray, d: int) -> np.ndarray:
    """(d*m,) -> (m, d)."""
    return u.reshape(d, -1).T


def mode_count(modes, total: int, *, sparse: bool) -> int:
    """``None``: all modes (the lowest SPARSE_MODES with the sparse solver); an int: a
    count, at most ``total``; a float: a fraction of all modes (MorphOptions checked the
    rest)."""
    if modes is None:
        return min(SPARSE_MODES, total - 2) if sparse else total
    if isinstance(modes, float):
        return max(1, int(round(modes * total)))
    if modes > total:
        raise OptionError(f"modes must be None, a count between 1 and {total} (d * m), "
                          f"or a fraction in (0, 1], got {modes!r}")
    return int(modes)


def superposed_modes(model: FEModel, n: int) -> Modes:
    """The model's lowest ``n`` modes; when that is not all of them, with the Rayleigh-Ritz
    modes of the smooth motions outside their span (:func:`smooth_fields`,
    :meth:`FEModel.augmented`, method.md §7)."""
    md = model.modes(n)
    if n < model.dim * model.m:  # truncated: add smooth motions (method.md §7)
        md = model.augmented(md, smooth_fields(model, n))
    return md


def similarity_fields(points: np.ndarray) -> np.ndarray:
    """Displacements of the nodes (m, d) under the infinitesimal similarity motions,
    component-major (d*m, s): translations, dilation and rotations. In 2D every finite
    similarity displacement ``(s R - I) X + t`` lies in their span; in 3D only small
    rotations do."""
    m, d = points.shape
    fields = [np.kron(np.eye(d)[a], np.ones(m)) for a in range(d)]  # translations
    fields.append(points.T.reshape(-1))  # dilation X
    for a, b in ((0, 1),) if d == 2 else ((0, 1), (0, 2), (1, 2)):  # rotations
        r = np.zeros((d, m))
        r[a], r[b] = -points[:, b], points[:, a]
        fields.append(r.reshape(-1))
    return np.column_stack(fields)


def smooth_fields(model: FEModel, n: int) -> np.ndarray:
    """Smooth displacements of the model's nodes (d*m, s) that its lowest ``n`` modes
    carry poorly (method.md §7): the affine motions (every finite similarity
    ``(s R - I) X + t`` lies in their span) and, for a truncated model (sparse or
    multilevel solver: a count asked of the dense solver is a choice of a coarser
    description), every mode of a copy of it on ``min(n, COARSE_MAX)`` nodes,
    evaluated through its field (1)-(4)."""
    X, d = model.points, model.dim
    affine = [np.kron(np.eye(d)[a], c) for a in range(d) for c in (np.ones(len(X)), *X.T)]
    if not model.truncated:
        return np.column_stack(affine)
    coarse = model.coarsened(min(n, COARSE_MAX))
    at_nodes = coarse.shape.to_normalized(model.shape.points)
    return np.column_stack([*affine, coarse.modes_at(coarse.modes(), at_nodes)])


def affine_weights(model_points: np.ndarray, points: np.ndarray, width: float):
    """The sparse (p, mc) weights ``W`` that take a reduced model's nodal displacements
    (mc, d) to ``points`` (p, d), ``u = W U``: at each point, the least-squares affine
    fit of its ``AFFINE_NEIGHBOURS`` nearest model nodes, weighted by a Gaussian of
    ``width``, evaluated there (moving least squares,
    :func:`~modalmorph.core.affine.affine_fit_weights`). Every affine motion, rigid ones
    included, is reproduced; unlike the element's field (1)-(4), which ripples between
    its nodes (method.md §7)."""
    p = len(points)
    k = min(AFFINE_NEIGHBOURS, len(model_points))
    idx = cKDTree(model_points).query(points, k=k)[1].reshape(p, k)
    rows = np.concatenate([affine_fit_weights(model_points[idx[b:b + AFFINE_BLOCK]],
                                              points[b:b + AFFINE_BLOCK], width)
                           for b in range(0, p, AFFINE_BLOCK)])
    return sparse.csr_array((rows.ravel(), (np.repeat(np.arange(p), k), idx.ravel())),
                            shape=(p, len(model_points)))


class Field:
    """The modes at every node, ``Phi = (I_d kron g) B``, applied without forming Phi.

    ``B`` (d*mc, n) is the modal basis at the model's nodes (``Phi`` itself, then ``g`` is
    None, or for a reduced 3D model ``g`` is the sparse (m, mc) :func:`affine_weights`) or
    in the Gaussian basis (``psi``, with ``g`` the sparse (m, mc) field matrix of a reduced
    2D model, :meth:`FEModel.field`). Memory stays that of ``g`` and ``B``.
    """

    def __init__(self, basis: np.ndarray, d: int, g=None):
        self.B = basis.reshape(d, -1, basis.shape[1])
        self.g = g

    def dot(self, x: np.ndarray) -> np.ndarray:
        """``Phi x``, (d*m,)."""
        parts = [b @ x for b in self.B]
        return np.concatenate(parts if self.g is None else [self.g @ p for p in parts])

    def tdot(self, v: np.ndarray) -> np.ndarray:
        """``Phi^T v`` for v (d*m,)."""
        v = v.reshape(len(self.B), -1)
        if self.g is not None:
            v = [self.g.T @ va for va in v]
        return sum(b.T @ va for b, va in zip(self.B, v, strict=True))

    def gram(self) -> np.ndarray:
        """``Phi^T Phi``, (n, n)."""
        if self.g is None:
            return sum(b.T @ b for b in self.B)
        gtg = (self.g.T @ self.g).tocsr()
        return sum(b.T @ (gtg @ b) for b in self.B)

    def sq_norm(self) -> float:
        """The sum of the squares of ``Phi``, the trace of ``Phi^T Phi`` (not formed: a
        reduced model's (n, n) product took 40 ms at 800 modes)."""
        parts = self.B if self.g is None else (self.g @ b for b in self.B)
        return float(sum(np.vdot(p, p) for p in parts))

    def dense(self) -> np.ndarray:
        """``Phi`` itself, (d*m, n)."""
        return np.concatenate([b if self.g is None else self.g @ b for b in self.B])
