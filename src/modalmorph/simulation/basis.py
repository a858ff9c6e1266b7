"""The coordinates a simulation integrates in and their values at every node (method.md
§4, §7).

How many modes (:func:`mode_count`), the Rayleigh-Ritz augmentation of a truncated basis
with smooth motions (:func:`superposed_modes`), the similarity motions of the model's
nodes (:func:`similarity_fields`), the two bases of the equations (:class:`ModeBasis`, the
modes superposed; :class:`ElementBasis`, every mode's span without the eigenproblem), and
``Phi`` at every node of the source, through the element's field for a reduced model
(:class:`Field`, :class:`KronField`).
"""

from __future__ import annotations

from functools import cached_property

import numpy as np
from scipy import sparse
from scipy.linalg import blas
from scipy.spatial import cKDTree

from ..core.affine import affine_fit_weights
from ..core.model import FEModel
from ..core.modes import Modes
from ..core.solvers.dense import whitened
from ..errors import OptionError

__all__ = ["AFFINE_NEIGHBOURS", "COARSE_MAX", "ElementBasis", "Field", "KronField",
           "ModeBasis", "SPARSE_MODES", "affine_weights", "flat", "mode_count", "nodes",
           "similarity_fields", "smooth_fields", "superposed_modes"]

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
    if n < model.dim * model.m and not model.truncated:
        _ = model.stiffness_gaussian  # kept: both the solver and augmented read it (made once)
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
    turns = ((0, 1),) if d == 2 else ((0, 1), (0, 2), (1, 2))
    out = np.zeros((d * m, d + 1 + len(turns)))  # np.column_stack's array, filled in place
    for a in range(d):  # translations
        out[a * m:(a + 1) * m, a] = 1.0
    out[:, d] = points.T.reshape(-1)  # dilation X
    for k, (a, b) in enumerate(turns):  # rotations
        out[a * m:(a + 1) * m, d + 1 + k] = -points[:, b]
        out[b * m:(b + 1) * m, d + 1 + k] = points[:, a]
    return out


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

    @property
    def n(self) -> int:
        """The number of coordinates (columns of ``Phi``)."""
        return self.B.shape[2]

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


def _kron(f, v: np.ndarray, d: int) -> np.ndarray:
    """``(I_d kron F) v`` for ``v`` (d*m,) or (d*m, k), ``F`` (p, m) applied by ``f`` to
    the (m, d*k) array of every component's block side by side (one call)."""
    k = v.shape[1] if v.ndim == 2 else 1
    out = f(v.reshape(d, -1, k).transpose(1, 0, 2).reshape(-1, d * k))
    out = out.reshape(-1, d, k).transpose(1, 0, 2).reshape(-1, k)
    return out if v.ndim == 2 else out[:, 0]


class KronField:
    """The element basis at every node, ``Phi = s (I_d kron g C L^-T)``, applied without
    forming it: ``L^-T`` (the whitening of :class:`ElementBasis`) by triangular products,
    then ``C`` (``G``, to the model's nodes, or None) and ``g`` (a reduced model's field
    or affine weights, sparse (m, mc), or None). The interface of :class:`Field`."""

    def __init__(self, l_inv: np.ndarray, d: int, scale: float, *, g=None, inner=None):
        self.l_inv, self.d, self.scale, self.g, self.inner = l_inv, d, scale, g, inner

    @property
    def n(self) -> int:
        return self.d * len(self.l_inv)

    def _right(self, X: np.ndarray) -> np.ndarray:
        Y = blas.dtrmm(self.scale, self.l_inv, X, lower=1, trans_a=1)
        Y = Y if self.inner is None else self.inner @ Y
        return Y if self.g is None else self.g @ Y

    def _left(self, V: np.ndarray) -> np.ndarray:
        V = V if self.g is None else self.g.T @ V
        V = V if self.inner is None else self.inner.T @ V
        return blas.dtrmm(self.scale, self.l_inv, V, lower=1)

    def dot(self, x: np.ndarray) -> np.ndarray:
        """``Phi x``, (d*m,)."""
        return _kron(self._right, x, self.d)

    def tdot(self, v: np.ndarray) -> np.ndarray:
        """``Phi^T v`` for v (d*m,)."""
        return _kron(self._left, v, self.d)

    @cached_property
    def _p(self) -> np.ndarray:
        """``s C L^-T``, (m, mc): the whitened basis at the model's nodes (``C = G``)."""
        return self._whitened_nodes()

    def _whitened_nodes(self) -> np.ndarray:
        """:attr:`_p`, made (not kept)."""
        return blas.dtrmm(self.scale, self.l_inv, self.inner, side=1, lower=1, trans_a=1)

    @cached_property
    def _block(self) -> np.ndarray:
        """One component's ``Phi^T Phi``, (mc, mc), made once (the springs' scale and
        Gram both read it)."""
        if self.g is None:  # (G L^-T s)^T (G L^-T s)
            return self._p.T @ self._p
        gtg = (self.g.T @ self.g)
        gtg = gtg.toarray() if sparse.issparse(gtg) else gtg
        if self.inner is not None:  # P^T gtg P with P = s G L^-T, Phi's block at the nodes
            return self._p.T @ gtg @ self._p  # (G gtg G first lost 1e-9 of a 3D fit's solve)
        half = blas.dtrmm(self.scale, self.l_inv, gtg, lower=1)
        return blas.dtrmm(self.scale, self.l_inv, half, side=1, lower=1, trans_a=1)

    def gram(self) -> np.ndarray:
        """``Phi^T Phi``, (n, n)."""
        return np.kron(np.eye(self.d), self._block)

    def sq_norm(self) -> float:
        """The sum of the squares of ``Phi``, the trace of ``Phi^T Phi``."""
        if self.g is None:  # one C-ordered copy (vdot of the Fortran array made two);
            # the product kept only when the Gram's block made it (a morph's steps never
            # read it: 8 m^2 bytes fewer kept)
            p = self.__dict__.get("_p")
            p = (self._whitened_nodes() if p is None else p).ravel()
            return float(self.d * np.vdot(p, p))
        return float(self.d * np.trace(self._block))

    def dense(self) -> np.ndarray:
        """``Phi`` itself, (d*m, n)."""
        return np.kron(np.eye(self.d), self._right(np.eye(len(self.l_inv))))


class ModeBasis:
    """The modes superposed as the coordinates of the equations (11)-(13):
    ``Phi^T M Phi = I``, ``Phi^T K Phi = Omega^2`` (diagonal).

    Attributes
    ----------
    model : FEModel
    modes : Modes
        The modes (:func:`superposed_modes`).
    mass_modes : ndarray, shape (d*mc, n)
        ``M Phi`` at the model's nodes (method.md §1).
    """

    def __init__(self, model: FEModel, modes: Modes):
        self.model, self.modes = model, modes
        self.mass_modes = model.mass_times_modes(modes)  # M Phi = (I kron A) M_g psi

    @property
    def n(self) -> int:
        return self.modes.n

    @property
    def shapes(self) -> np.ndarray:
        """``Phi`` at the model's nodes, (d*mc, n)."""
        return self.modes.shapes

    def stiffness(self) -> np.ndarray:
        """``Phi^T K Phi``, (n, n): ``Omega^2`` (13)."""
        return np.diag(self.modes.eigenvalues)

    def at_nodes(self, x: np.ndarray) -> np.ndarray:
        """``Phi x`` at the model's nodes."""
        return self.modes.shapes @ x

    def mass(self, y: np.ndarray) -> np.ndarray:
        """``M Phi y`` at the model's nodes."""
        return self.mass_modes @ y

    def mass_t(self, u: np.ndarray) -> np.ndarray:
        """``Phi^T M u`` for ``u`` (d*mc,) or (d*mc, k) at the model's nodes."""
        return self.mass_modes.T @ u

    def field(self, *, nodes=None, gaussian=None) -> Field:
        """``Phi`` at other points: ``nodes`` (sparse (m, mc)) weights the model's nodal
        values, ``gaussian`` (m, mc) is the element's field (1)-(4); neither: the
        model's nodes."""
        if gaussian is not None:
            return Field(self.modes.gaussian, self.model.dim, gaussian)
        return Field(self.modes.shapes, self.model.dim, nodes)


class ElementBasis:
    """Every mode's span without the eigenproblem: the element's Gaussian basis
    whitened, ``psi = s (I kron L^-T)`` with ``Gamma = L L^T`` and ``s = rho^-1/2``, and
    ``Phi = (I kron G) psi`` (method.md §4, "Every mode").

    Orthonormal in the mass like the modes (``Phi^T M Phi = I``), so the springs, the
    loads, the damping and Newmark read it as they read the modes; but its stiffness
    ``Phi^T K Phi = s^2 (I kron L^-1) K_g (I kron L^-T)`` is a full matrix. With every mode
    superposed the two are the same equations in coordinates an orthogonal matrix apart
    (the eigenvectors ``Y`` of that stiffness: ``x_modes = Y^T x``), so the results are
    equal to rounding, and the (d*m)^3 eigenproblem is not solved; :attr:`modes` solves
    it when asked.
    """

    def __init__(self, model: FEModel):
        self.model = model
        self.L, self.l_inv, Kw = whitened(model)
        rho = model.material.rho
        self.scale, self.root = 1.0 / np.sqrt(rho), np.sqrt(rho)
        Kw /= rho  # whitened's own array: no second (n, n) one
        self._stiffness = Kw

    @property
    def n(self) -> int:
        return self.model.dim * self.model.m

    @cached_property
    def modes(self) -> Modes:
        """The model's modes, all of them (solved on first use: figures, tests)."""
        return self.model.modes()

    @cached_property
    def shapes(self) -> np.ndarray:
        """``Phi`` at the model's nodes, (d*mc, n)."""
        return self._at_model.dense()

    def stiffness(self) -> np.ndarray:
        """``Phi^T K Phi``, (n, n), full (made again, the same numbers, after
        :meth:`take_stiffness`)."""
        if self._stiffness is None:
            Kw = whitened(self.model)[2]
            Kw /= self.model.material.rho
            self._stiffness = Kw
        return self._stiffness

    def take_stiffness(self) -> np.ndarray:
        """:meth:`stiffness`, handed over: the basis no longer holds it (the caller may
        overwrite it, and a morph keeps one (n, n) array fewer)."""
        K, self._stiffness = self.stiffness(), None
        return K

    def at_nodes(self, x: np.ndarray) -> np.ndarray:
        """``Phi x`` at the model's nodes: ``s (I kron G L^-T) x``."""
        return self._at_model.dot(x)

    @cached_property
    def _at_model(self) -> KronField:
        return self.field()

    def mass(self, y: np.ndarray) -> np.ndarray:
        """``M Phi y = rho^1/2 (I kron A L) y`` at the model's nodes."""
        Ly = _kron(lambda X: blas.dtrmm(self.root, self.L, X, lower=1), y, self.model.dim)
        return self.model.solve_gram(Ly)

    def mass_t(self, u: np.ndarray) -> np.ndarray:
        """``Phi^T M u = rho^1/2 (I kron L^T A) u`` for ``u`` (d*mc,) or (d*mc, k)."""
        return _kron(lambda X: blas.dtrmm(self.root, self.L, X, lower=1, trans_a=1),
                     self.model.solve_gram(u), self.model.dim)

    def field(self, *, nodes=None, gaussian=None) -> KronField:
        """As :meth:`ModeBasis.field`."""
        G = self.model.gram[0] if gaussian is None else None
        return KronField(self.l_inv, self.model.dim, self.scale,
                         g=gaussian if gaussian is not None else nodes, inner=G)
