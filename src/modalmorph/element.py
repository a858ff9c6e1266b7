"""Sclaroff's isoparametric Gaussian element: Gram integrals, mass and stiffness (1)-(4).

Every integral is over all of R^d and has a closed form (method.md §1). With
``r = X_j - X_i``, ``e_ij = exp(-|r|^2 / (4 sigma^2))`` and ``V = (pi sigma^2)^(d/2)``:

- ``Gamma_ij = V e_ij``                           (integral of g_i g_j)
- ``D^ab_ij = V e_ij / sigma^4 (delta_ab sigma^2 / 2 - r_a r_b / 4)``  (of dg_i/dx_a dg_j/dx_b)

The physical matrices use ``A = G^-1``: ``M = rho (I_d kron A Gamma A)`` and
``K_ab = A [(lambda + mu) D^ab + mu delta_ab sum_c D^cc] A``. ``A`` is never formed: the
eigenproblem is solved in the Gaussian basis (see :mod:`modalmorph.modes`), and the dense
``mass``/``stiffness`` properties use triangular solves with ``G``'s Cholesky factor.

Large objects: every entry above decays like ``exp(-|r|^2 / (4 sigma^2))`` and sigma is a
multiple of the node spacing, so each node interacts with a bounded number of others. The
sparse solver keeps only pairs closer than a cutoff radius (:attr:`FEModel.cutoff_radius`,
set by ``cutoff``) and works with sparse ``G``, ``Gamma`` and ``K_g``; no m x m matrix is
formed. For 3D point sets (some 200-300 neighbours per node) the sparse factor of the
shift-invert solver does not fit beyond a few thousand nodes; the multilevel solver
(:mod:`modalmorph.multilevel`) only multiplies by ``K_g`` and ``Gamma``, which it
assembles from :attr:`FEModel.pairs` itself (six scalar components of ``K_g`` over one
index structure, products over 2 threads). :attr:`FEModel.stiffness_gaussian_blocks` (the
same ``K_g`` as d x d blocks) serves ``apply_stiffness`` on such models and is large (about
1.4 GB at 100k 3D nodes).
"""

from __future__ import annotations

from functools import cached_property

import numpy as np
from scipy import linalg, sparse
from scipy.sparse import linalg as splinalg
from scipy.spatial import cKDTree

from .material import POLYETHYLENE, Material
from .shape import Shape, as_shape

__all__ = ["FEModel", "DEFAULT_SIGMA", "AUTO_CONDITION", "MIN_SIGMA", "MAX_SIGMA", "auto_sigma",
           "check_sigma", "DEFAULT_CUTOFF", "MULTILEVEL_CUTOFF",
           "AUTO_DENSE_MAX_DOF", "AUTO_MULTILEVEL_MIN_NODES", "DENSE_MAX_DOF", "SOLVERS",
           "cutoff_radius", "gram_entries", "stiffness_entries"]

# sigma in units of the mean nearest-neighbour spacing; chosen by measurement, see README.
DEFAULT_SIGMA = 1.0
# sigma=None: the largest width up to the nominal one whose Gamma has a condition number of
# at most AUTO_CONDITION, two decades inside the refusal limit MAX_CONDITION (modes.py).
# Measured (log10 cond(Gamma) at sigma 1 / 1.5 / 2): evenly sampled circle of 160 nodes
# 4.0 / 9.1 / 15.8, letter R 3.9 / 8.8 / 14.7, hand 3.6 / 6.5 / 9.1: a nominal 2 is fine for
# hands and singular for circles and glyphs, so the width must follow the shape.
AUTO_CONDITION = 1e10
# Below this sigma neighbouring nodes overlap by less than exp(-1 / (4 * 0.05^2)) = e^-100:
# they do not interact and the model degenerates (all-NaN modes at 1e-100).
MIN_SIGMA = 0.05
# Above this sigma the Gram matrix of any shape of more than a few nodes is numerically
# singular (condition numbers 1e9-1e17 already at sigma 3, measured as above).
MAX_SIGMA = 10.0
# The sparse solver drops every interaction smaller than this fraction of the diagonal.
DEFAULT_CUTOFF = 1e-10
# The multilevel solver's default: a radius of 8.1 sigma instead of 10.3, 190 neighbours
# per node of a 3D surface instead of 294; the lowest 60 frequencies of the 2000-node
# benchmark ellipsoid move by 3e-6 relative (benchmarks/scale.py). 1e-4 leaves Gamma
# indefinite there.
MULTILEVEL_CUTOFF = 1e-6
# solver="auto" uses the dense solver up to this many degrees of freedom (d * m): there all
# modes take about a second (benchmarks/model.py); above it, the sparse one.
AUTO_DENSE_MAX_DOF = 3000
# ... and, for 3D shapes, the multilevel solver from this many nodes on: the sparse
# factor of a 3D point set (some 300 neighbours per node) needs about 1 GB at 2000 nodes
# and runs out of 8 GB at 3000.
AUTO_MULTILEVEL_MIN_NODES = 2500
# Dense (d*m)^2 matrices are refused beyond this size (an 8 * 12000^2 = 1.2 GB array).
DENSE_MAX_DOF = 12000
SOLVERS = ("auto", "dense", "sparse", "multilevel")
# modes_at evaluates the field densely (one (p, m) array, 8 MB) up to this many entries:
# at 70 x 70 that takes 0.1 ms against 0.6 ms through k-d trees.
_DENSE_FIELD_MAX = 10**6


def gram_entries(r: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """Entries of ``G`` (1)-(2) and ``Gamma`` for node offsets ``r`` (..., d).

    Returns ``(g, gamma)``, each of shape ``r.shape[:-1]``.
    """
    d = r.shape[-1]
    r2 = np.einsum("...a,...a->...", r, r)
    g = np.exp(-r2 / (2 * sigma**2))  # (2) g_j(X_i)
    gamma = (np.pi * sigma**2) ** (d / 2) * np.exp(-r2 / (4 * sigma**2))
    return g, gamma


def stiffness_entries(r: np.ndarray, sigma: float, lam: float, mu: float) -> np.ndarray:
    """Blocks of the stiffness in the Gaussian basis, ``K_g[..., a, b]``, for offsets ``r``.

    ``K_g^ab = (lambda + mu) D^ab + mu delta_ab sum_c D^cc``, shape ``r.shape + (d,)``.
    """
    d = r.shape[-1]
    r2 = np.einsum("...a,...a->...", r, r)
    scale = (np.pi * sigma**2) ** (d / 2) * np.exp(-r2 / (4 * sigma**2)) / sigma**4
    out = (-(lam + mu) / 4) * r[..., :, None] * r[..., None, :]
    diag = (lam + mu) * sigma**2 / 2 + mu * (d * sigma**2 / 2 - r2 / 4)
    idx = np.arange(d)
    out[..., idx, idx] += diag[..., None]
    out *= scale[..., None, None]
    return out


def cutoff_radius(sigma: float, cutoff: float = DEFAULT_CUTOFF) -> float:
    """Distance beyond which the sparse model drops the interaction of two nodes.

    The radius ``2 sigma sqrt(x)`` where ``2 x exp(-x) = cutoff`` (``x >= 1``): beyond it,
    every entry of ``G`` (decaying like ``exp(-2x)``), ``Gamma`` (``exp(-x)``) and ``K_g``
    (at most ``2 x exp(-x)`` of its diagonal) is below ``cutoff`` times the diagonal.
    ``cutoff = 1e-10`` gives ``x = 26.3``, a radius of 10.3 sigma.
    """
    if not 0 < cutoff < 1:
        raise ValueError(f"cutoff must be in (0, 1), got {cutoff}")
    target = np.log(1 / cutoff)
    x = max(target, 1.0)
    for _ in range(100):  # fixed point of x = log(1/cutoff) + log(2x), a contraction
        x_new = target + np.log(2 * x)
        if abs(x_new - x) < 1e-12 * x:
            break
        x = x_new
    return float(2 * sigma * np.sqrt(x_new))


def _log_condition(r2: np.ndarray, sigma: float) -> float:
    """log10 of the condition number of ``Gamma`` for squared distances ``r2`` (m, m) and
    an absolute sigma (the factor V of :func:`gram_entries` cancels); capped at 17, where
    the smallest eigenvalue is lost in double-precision round-off."""
    ev = np.linalg.eigvalsh(np.exp(-r2 / (4 * sigma**2)))
    return float(min(np.log10(ev[-1] / ev[0]), 17.0)) if ev[0] > 0 else 17.0


def auto_sigma(shape, nominal: float = DEFAULT_SIGMA) -> float:
    """The Gaussian width (x mean node spacing) used when ``sigma=None``.

    ``nominal`` if the Gram matrix ``Gamma`` is well conditioned there (condition number at
    most ``AUTO_CONDITION``), else the largest width below it that is, within a factor
    10^0.5 of the limit: log10 of the condition number is close to linear in sigma^2
    (measured on circles, glyphs and hands), so a few steps of regula falsi in sigma^2
    find it. Objects too large for a dense Gram matrix (more than ``AUTO_DENSE_MAX_DOF``
    degrees of freedom) get ``nominal``: their solvers check the conditioning themselves.
    """
    return _auto_sigma(shape, nominal)[0]


def _auto_sigma(shape, nominal: float) -> tuple[float, float | None]:
    """:func:`auto_sigma` and log10 of Gamma's condition number there (None when not
    computed: objects too large for a dense Gram matrix)."""
    shape = as_shape(shape)
    if shape.dim * shape.m > AUTO_DENSE_MAX_DOF:
        return float(nominal), None
    x = shape.normalized
    r2 = np.maximum(np.sum(x**2, 1)[:, None] + np.sum(x**2, 1)[None, :] - 2 * x @ x.T, 0.0)
    h, target = shape.spacing, np.log10(AUTO_CONDITION)
    hi, c_hi = float(nominal), _log_condition(r2, nominal * h)
    if c_hi <= target:
        return hi, c_hi
    lo, c_lo = hi, c_hi
    while c_lo > target and lo > MIN_SIGMA:  # halve until well conditioned
        hi, c_hi = lo, c_lo
        lo = max(lo / 2, MIN_SIGMA)
        c_lo = _log_condition(r2, lo * h)
    for _ in range(_AUTO_STEPS):
        if target - c_lo <= _AUTO_SLACK:
            break
        q = lo**2 + (target - _AUTO_SLACK / 2 - c_lo) * (hi**2 - lo**2) / (c_hi - c_lo)
        s, c = float(np.sqrt(q)), _log_condition(r2, np.sqrt(q) * h)
        if c <= target:
            lo, c_lo = s, c
        else:
            hi, c_hi = s, c
    return lo, c_lo


def check_sigma(sigma) -> None:
    """Refuse a sigma that is not None or a number in [MIN_SIGMA, MAX_SIGMA]."""
    if sigma is None:
        return
    if not isinstance(sigma, int | float | np.integer | np.floating) or not (
            MIN_SIGMA <= sigma <= MAX_SIGMA):
        raise ValueError(f"sigma must be None (chosen per shape) or a number between "
                         f"{MIN_SIGMA:g} and {MAX_SIGMA:g} (x mean node spacing), got {sigma!r}")


# auto_sigma stops within this many decades below AUTO_CONDITION, or after _AUTO_STEPS.
_AUTO_SLACK, _AUTO_STEPS = 0.5, 8


class FEModel:
    """The physical model of one object with Sclaroff's Gaussian element.

    Parameters
    ----------
    shape : Shape or array_like, shape (m, d)
        The object. It is modelled in its normalised frame (centroid at the origin, unit
        RMS radius), so the model does not depend on position, orientation or units.
    sigma : float or None, optional
        Width of the Gaussians as a multiple of the mean nearest-neighbour spacing of the
        nodes (scale-free), between ``MIN_SIGMA`` and ``MAX_SIGMA``. Larger values couple
        nodes further apart (smoother low modes) but make the Gram matrices
        ill-conditioned. ``None`` (default): ``DEFAULT_SIGMA`` (1) unless that makes
        ``Gamma`` ill-conditioned for this node set, then the largest width that does not
        (:func:`auto_sigma`). A given value is used as it is, and refused with a
        ``ValueError`` (naming the largest width that works) when the Gram matrix is
        numerically singular. The width used is :attr:`sigma_rel`.
    nominal_sigma : float, optional
        The width ``sigma=None`` starts from (default ``DEFAULT_SIGMA``; the matcher's
        models use 2).
    material : Material, optional
        The material filling the object (default: polyethylene, the paper's choice).
    plane : {"stress", "strain"}, optional
        2D idealisation: plane stress (thin sheet, the default) or plane strain.
    solver : {"auto", "dense", "sparse", "multilevel"}, optional
        How :meth:`modes` solves the eigenproblem. ``"dense"``: all interactions, dense
        matrices, LAPACK; exact, but O(m^2) memory and O(m^3) time. ``"sparse"``:
        interactions beyond :attr:`cutoff_radius` are dropped, the lowest ``n`` modes
        come from a shift-invert Lanczos solver (ARPACK) on sparse matrices; about linear
        memory in the number of pairs, plus the fill of a sparse factor, which is large
        for 3D point sets. ``"multilevel"``: the same truncated matrices, no
        factorisation; the lowest ``n`` modes of a coarse model give the starting
        subspace of a preconditioned LOBPCG iteration on the full model, stopped when
        every residual is below a tolerance (:mod:`modalmorph.multilevel`; iterative, so
        less accurate than the others: see there). ``"auto"`` (default) picks dense up to
        ``AUTO_DENSE_MAX_DOF`` degrees of freedom (``d * m``), multilevel for 3D shapes
        of ``AUTO_MULTILEVEL_MIN_NODES`` nodes or more, and sparse otherwise.
        The resolved choice is :attr:`solver`.
    cutoff : float, optional
        Sparse and multilevel solvers: the relative size below which interactions are
        dropped (see :func:`cutoff_radius`; default 1e-10, a radius of 10.3 sigma, and
        ``MULTILEVEL_CUTOFF`` = 1e-6, 8.1 sigma, for the multilevel solver). This
        truncation is the sparse model's only approximation: with 1e-10, its lowest
        frequencies agree with the dense ones to about 1e-9 relative
        (``tests/test_scale.py``, ``benchmarks/scale.py``). A larger cutoff saves time and
        memory and costs accuracy; since the truncated Gram matrices are no longer exactly
        positive definite, a cutoff near the inverse condition number of ``Gamma`` fails.

    Raises
    ------
    ValueError
        For an invalid shape, a non-positive sigma, an unknown solver, or (when the modes
        are computed) a sigma so large that the Gram matrix is numerically singular for
        this node set.
    """

    def __init__(self, shape, *, sigma: float | None = None,
                 material: Material = POLYETHYLENE, plane: str = "stress",
                 solver: str = "auto", cutoff: float | None = None,
                 nominal_sigma: float = DEFAULT_SIGMA):
        self.shape: Shape = as_shape(shape)
        check_sigma(sigma)
        if not isinstance(material, Material):
            raise ValueError(f"material must be a Material, got {type(material).__name__}")
        if solver not in SOLVERS:
            raise ValueError(f"solver must be one of {SOLVERS}, got {solver!r}")
        if cutoff is not None and not (isinstance(cutoff, int | float) and 0 < cutoff < 1):
            raise ValueError(f"cutoff must be a number in (0, 1), got {cutoff!r}")
        if solver == "auto":
            d, m = self.shape.dim, self.shape.m
            solver = ("dense" if d * m <= AUTO_DENSE_MAX_DOF else
                      "multilevel" if d == 3 and m >= AUTO_MULTILEVEL_MIN_NODES else "sparse")
        self.solver = solver
        if cutoff is None:
            cutoff = MULTILEVEL_CUTOFF if solver == "multilevel" else DEFAULT_CUTOFF
        self.cutoff = float(cutoff)
        if sigma is None:
            self.sigma_rel, log_cond = _auto_sigma(self.shape, nominal_sigma)
            if log_cond is not None:  # measured on the way: no second eigensolve
                self.__dict__["gamma_condition"] = 10.0**log_cond
        else:
            self.sigma_rel = float(sigma)
        self.material = material
        self.plane = plane
        if self.dim == 2:
            self.lame = material.lame_2d(plane)
        else:
            if plane not in ("stress", "strain"):
                raise ValueError(f"plane must be 'stress' or 'strain', got {plane!r}")
            self.lame = material.lame
        self._modes = {}

    @property
    def dim(self) -> int:
        return self.shape.dim

    @property
    def m(self) -> int:
        return self.shape.m

    @property
    def points(self) -> np.ndarray:
        """Nodes in the normalised frame, shape (m, d)."""
        return self.shape.normalized

    @cached_property
    def sigma(self) -> float:
        """Absolute Gaussian width in the normalised frame."""
        return self.sigma_rel * self.shape.spacing

    @cached_property
    def gamma_condition(self) -> float:
        """Condition number of the dense Gram matrix ``Gamma`` (inf when singular)."""
        ev = np.linalg.eigvalsh(self.gram[1])
        return float(ev[-1] / ev[0]) if ev[0] > 0 else np.inf

    @property
    def cutoff_radius(self) -> float:
        """Sparse solver: pairs of nodes farther apart than this (normalised frame) do not
        interact. See :func:`cutoff_radius`."""
        return cutoff_radius(self.sigma, self.cutoff)

    def field(self, points: np.ndarray) -> sparse.csr_array:
        """``g_k(x_p)`` (2) at points ``x_p`` (normalised frame) for every node ``k``.

        A sparse (p, m) matrix; entries beyond :attr:`cutoff_radius` are dropped as in the
        sparse Gram matrices. The element's displacement field at the points is then
        ``u(x_p) = sum_k g_k(x_p) psi_k`` (1)-(4): see :meth:`modes_at`.

        Raises
        ------
        ValueError
            When a point lies beyond the cutoff radius of every node.
        """
        points = np.asarray(points, dtype=np.float64)
        dist = cKDTree(points).sparse_distance_matrix(cKDTree(self.points), self.cutoff_radius,
                                                      output_type="coo_matrix")
        g = sparse.csr_array((np.exp(-dist.data**2 / (2 * self.sigma**2)),
                              (dist.row, dist.col)), shape=(len(points), self.m))
        _check_reached(g.sum(axis=1) > 0)
        return g

    def _field_small(self, points: np.ndarray) -> np.ndarray:
        """:meth:`field` as a dense (p, m) array, for few points and nodes (no k-d trees)."""
        x = np.asarray(points, dtype=np.float64)
        r2 = (np.sum(x**2, axis=1)[:, None] + np.sum(self.points**2, axis=1)[None, :]
              - 2 * x @ self.points.T)
        inside = r2 <= self.cutoff_radius**2
        _check_reached(inside.any(axis=1))
        return np.where(inside, np.exp(-np.maximum(r2, 0.0) / (2 * self.sigma**2)), 0.0)

    def modes_at(self, modes, points: np.ndarray) -> np.ndarray:
        """Mode shapes evaluated at arbitrary points (normalised frame), shape (d*p, n).

        Uses the element's own interpolation ``u(x) = sum_k g_k(x) psi_k`` with
        ``Phi = (I kron G) psi`` (1)-(4): at the model's nodes this is exactly ``Phi``. It
        lets a coarse model describe a dense point set (a reduced model).
        """
        d, m = self.dim, self.m
        small = len(points) * m <= _DENSE_FIELD_MAX
        g = self._field_small(points) if small else self.field(points)
        psi = modes.gaussian.reshape(d, m, -1)
        return np.concatenate([g @ psi[a] for a in range(d)], axis=0)

    def _check_dense(self, what: str) -> None:
        dof = self.dim * self.m
        if dof > DENSE_MAX_DOF:
            raise ValueError(
                f"{what} is a dense ({dof}, {dof}) matrix, too large for this "
                f"{self.m}-node shape (limit {DENSE_MAX_DOF} degrees of freedom); use "
                f"modes(n), apply_mass, apply_stiffness or the sparse gram_sparse instead")

    @cached_property
    def _offsets(self) -> np.ndarray:
        self._check_dense("the offset table")
        x = self.points
        return x[None, :, :] - x[:, None, :]  # r_ij = X_j - X_i

    @cached_property
    def gram(self) -> tuple[np.ndarray, np.ndarray]:
        """Dense ``(G, Gamma)``, each (m, m)."""
        return gram_entries(self._offsets, self.sigma)

    @cached_property
    def stiffness_gaussian(self) -> np.ndarray:
        """Dense stiffness in the Gaussian basis, ``K_g`` (dm, dm), component-major (7)."""
        self._check_dense("K_g")
        lam, mu = self.lame
        blocks = stiffness_entries(self._offsets, self.sigma, lam, mu)  # (m, m, d, d)
        dm = self.dim * self.m
        return np.ascontiguousarray(blocks.transpose(2, 0, 3, 1).reshape(dm, dm))

    # -- sparse model: pairs within the cutoff radius ----------------------------------

    @cached_property
    def pairs(self) -> np.ndarray:
        """Pairs ``(i, j)``, ``i < j``, of nodes closer than :attr:`cutoff_radius`,
        shape (p, 2). The sparse model's interactions (besides each node with itself)."""
        found = cKDTree(self.points).query_pairs(self.cutoff_radius, output_type="ndarray")
        return found.astype(_index_dtype(self.dim * self.m), copy=False)

    @cached_property
    def gram_sparse(self) -> tuple[sparse.csr_array, sparse.csr_array]:
        """Sparse ``(G, Gamma)``, each (m, m) CSR, truncated at :attr:`cutoff_radius`."""
        m, (i, j) = self.m, self.pairs.T
        g, gamma = gram_entries(self.points[j] - self.points[i], self.sigma)
        g0, gamma0 = gram_entries(np.zeros((1, self.dim)), self.sigma)
        diag = np.arange(m, dtype=i.dtype)
        rows, cols = np.r_[i, j, diag], np.r_[j, i, diag]

        def build(off, on):
            data = np.r_[off, off, np.full(m, on[0])]
            return sparse.csr_array((data, (rows, cols)), shape=(m, m))

        return build(g, g0), build(gamma, gamma0)

    @cached_property
    def stiffness_gaussian_sparse(self) -> sparse.csr_array:
        """Sparse ``K_g`` (dm, dm) CSR, component-major (7), truncated at
        :attr:`cutoff_radius`; assembled from the pair list in chunks."""
        d, m = self.dim, self.m
        lam, mu = self.lame
        pairs, x = self.pairs, self.points
        p = len(pairs)
        itype = pairs.dtype
        nnz_block = 2 * p + m
        data = np.empty((d, d, nnz_block))
        rows = np.empty(nnz_block, dtype=itype)
        cols = np.empty(nnz_block, dtype=itype)
        data[:, :, 2 * p:] = stiffness_entries(np.zeros((1, d)), self.sigma, lam, mu)[0][
            :, :, None]
        rows[2 * p:] = cols[2 * p:] = np.arange(m, dtype=itype)
        chunk = 1 << 20
        for start in range(0, p, chunk):
            i, j = pairs[start:start + chunk].T
            blocks = stiffness_entries(x[j] - x[i], self.sigma, lam, mu)  # (c, d, d)
            stop = start + len(i)
            # K_g^ab_ij = K_g^ab_ji: the blocks are even in r and symmetric in (a, b)
            data[:, :, start:stop] = data[:, :, p + start:p + stop] = blocks.transpose(1, 2, 0)
            rows[start:stop], cols[start:stop] = i, j
            rows[p + start:p + stop], cols[p + start:p + stop] = j, i
        offsets = (np.arange(d, dtype=itype) * itype.type(m))
        all_rows = (offsets[:, None, None] + rows).repeat(d, axis=1).reshape(-1)
        all_cols = np.broadcast_to(offsets[None, :, None] + cols, (d, d, nnz_block)).reshape(-1)
        return sparse.csr_array((data.reshape(-1), (all_rows, all_cols)), shape=(d * m, d * m))

    @cached_property
    def stiffness_gaussian_blocks(self) -> sparse.bsr_array:
        """Sparse ``K_g`` node-major: a (dm, dm) BSR matrix of d x d blocks, block
        ``(i, j)`` holding ``K_g^ab_ij`` for all ``a, b``, truncated at
        :attr:`cutoff_radius`.

        The same entries as :attr:`stiffness_gaussian_sparse` with the degrees of freedom
        ordered node-major (x, y, z of node 0, then of node 1, ...): one column index per
        block instead of one per entry, and block products (used by
        :mod:`modalmorph.multilevel`).
        """
        d, m = self.dim, self.m
        lam, mu = self.lame
        i, j = self.pairs.T
        itype = i.dtype
        diag = np.arange(m, dtype=itype)
        rows = np.r_[i, j, diag]
        order = np.argsort(rows, kind="stable")
        rows = rows[order]
        cols = np.r_[j, i, diag][order]
        del order
        data = np.empty((len(rows), d, d))
        chunk = 1 << 20
        for start in range(0, len(rows), chunk):
            r = self.points[cols[start:start + chunk]] - self.points[rows[start:start + chunk]]
            data[start:start + chunk] = stiffness_entries(r, self.sigma, lam, mu)
        indptr = np.zeros(m + 1, dtype=itype)
        np.cumsum(np.bincount(rows, minlength=m), out=indptr[1:])
        return sparse.bsr_array((data, cols, indptr), shape=(d * m, d * m))

    # -- products with M, K and A = G^-1 -----------------------------------------------

    @cached_property
    def _g_factor(self):
        if self._truncated:
            try:
                return splinalg.splu(self.gram_sparse[0].tocsc(), permc_spec="MMD_AT_PLUS_A",
                                     diag_pivot_thresh=0.0,
                                     options={"SymmetricMode": True})
            except RuntimeError:  # "Factor is exactly singular"
                raise ValueError(_breakdown_message(self)) from None
        G = self.gram[0]
        try:
            return linalg.cho_factor(G, lower=True, check_finite=False)
        except linalg.LinAlgError:
            raise ValueError(_breakdown_message(self)) from None

    def solve_gram(self, B: np.ndarray) -> np.ndarray:
        """``(I_d kron A) B`` for B of shape (dm, k) or (dm,), by solves with G's factor
        (Cholesky for the dense solver, sparse LU of the truncated ``G`` for the sparse one).
        """
        d, m = self.dim, self.m
        flat = np.asarray(B, dtype=np.float64).reshape(d, m, -1).transpose(1, 0, 2)
        flat = flat.reshape(m, -1)
        if self._truncated:
            X = self._g_factor.solve(np.asfortranarray(flat))
        else:
            X = linalg.cho_solve(self._g_factor, flat, check_finite=False)
        return X.reshape(m, d, -1).transpose(1, 0, 2).reshape(np.shape(B))

    def _apply_gaussian(self, which: str, B: np.ndarray) -> np.ndarray:
        """``M_g B`` (without rho) or ``K_g B`` for B (dm, k) or (dm,)."""
        d, m = self.dim, self.m
        B = np.asarray(B, dtype=np.float64)
        if which == "mass":
            Gamma = self.gram_sparse[1] if self._truncated else self.gram[1]
            out = np.stack([Gamma @ b for b in B.reshape(d, m, -1)])
            return out.reshape(B.shape)
        if self.solver == "multilevel":  # its node-major blocks, not a second copy
            from .multilevel import _component_major, _node_major

            flat = _node_major(B.reshape(d * m, -1), d, m)
            return _component_major(self.stiffness_gaussian_blocks @ flat, d,
                                    m).reshape(B.shape)
        Kg = self.stiffness_gaussian_sparse if self.solver == "sparse" else \
            self.stiffness_gaussian
        return Kg @ B

    def apply_mass(self, U: np.ndarray) -> np.ndarray:
        """``M U`` for U (dm,) or (dm, k), without forming M: ``(I kron A) M_g (I kron A) U``.

        With the sparse solver, this is the truncated model's mass (the one its modes are
        orthonormal in). For mode shapes, ``M Phi = (I kron A) M_g psi`` needs one solve:
        ``model.solve_gram(rho * Gamma psi)``, see :meth:`mass_times_modes`.
        """
        return self.material.rho * self.solve_gram(self._apply_gaussian("mass",
                                                                         self.solve_gram(U)))

    def apply_stiffness(self, U: np.ndarray) -> np.ndarray:
        """``K U`` for U (dm,) or (dm, k), without forming K: ``(I kron A) K_g (I kron A) U``."""
        return self.solve_gram(self._apply_gaussian("stiffness", self.solve_gram(U)))

    def mass_times_modes(self, modes) -> np.ndarray:
        """``M Phi`` (dm, n) for modes of this model, by one solve with G (method.md §1
        "cheap products"): ``M Phi = (I kron A) rho (I kron Gamma) psi``. Then
        ``K Phi = M Phi diag(omega^2)``. Dense solver: ``A Gamma`` is formed once (m
        right-hand sides) and applied by GEMM, 3.6x faster at 300 nodes and all modes than
        solving for every mode."""
        if self.solver != "dense":
            return self.solve_gram(self.material.rho * self._apply_gaussian("mass",
                                                                             modes.gaussian))
        d, m = self.dim, self.m
        a_gamma = linalg.cho_solve(self._g_factor, self.gram[1], check_finite=False)
        psi = modes.gaussian.reshape(d, m, -1)
        return self.material.rho * np.matmul(a_gamma, psi).reshape(d * m, -1)

    @property
    def mass(self) -> np.ndarray:
        """Dense mass matrix ``M = rho (I_d kron A Gamma A)``, (dm, dm), component-major."""
        self._check_dense("M")
        G_fac, Gamma = self._dense_g_factor, self.gram[1]
        AGA = linalg.cho_solve(G_fac, linalg.cho_solve(G_fac, Gamma, check_finite=False).T,
                               check_finite=False)
        AGA = (AGA + AGA.T) * (self.material.rho / 2)
        return np.kron(np.eye(self.dim), AGA)

    @property
    def stiffness(self) -> np.ndarray:
        """Dense stiffness matrix ``K = (I kron A) K_g (I kron A)``, (dm, dm)."""
        self._check_dense("K")
        d, m = self.dim, self.m
        G_fac = self._dense_g_factor
        # each block K_ab = A K_g^ab A: solve on the rows, then on the columns
        Kg = self.stiffness_gaussian.reshape(d, m, d * m).transpose(1, 0, 2).reshape(m, -1)
        X = linalg.cho_solve(G_fac, Kg, check_finite=False).reshape(m, d, d, m)
        X = X.transpose(3, 0, 1, 2).reshape(m, -1)  # columns of each block to the front
        Y = linalg.cho_solve(G_fac, X, check_finite=False).reshape(m, m, d, d)
        K = Y.transpose(2, 1, 3, 0).reshape(d * m, d * m)
        return (K + K.T) / 2

    @property
    def _truncated(self) -> bool:
        """Whether this model drops the pairs beyond :attr:`cutoff_radius`."""
        return self.solver in ("sparse", "multilevel")

    @cached_property
    def _dense_g_factor(self):
        if self.solver == "dense":
            return self._g_factor
        try:
            return linalg.cho_factor(self.gram[0], lower=True, check_finite=False)
        except linalg.LinAlgError:
            raise ValueError(_breakdown_message(self)) from None

    def modes(self, n: int | None = None):
        """The lowest ``n`` modes (all when ``None``) of ``K Phi = M Phi Omega^2`` (6).

        With the sparse and multilevel solvers ``n`` is required and must be below
        ``d * m - 1``. The multilevel solver raises a ValueError when it does not
        converge (see :mod:`modalmorph.multilevel`).

        Returns
        -------
        Modes
            Frequencies ascending and mass-normalised mode shapes.
        """
        from .modes import solve_modes, solve_modes_sparse
        from .multilevel import solve_modes_multilevel

        total = self.dim * self.m
        if n is None and self._truncated:
            raise ValueError(
                f"the {self.solver} solver computes the lowest n modes: pass n (e.g. "
                f"modes(50)), or use FEModel(..., solver='dense') for all {total} modes of "
                f"this {self.m}-node shape")
        n = total if n is None else int(n)
        if not 1 <= n <= total:
            raise ValueError(f"n must be between 1 and {total} (d * m), got {n}")
        if self._truncated and n >= total - 1:
            raise ValueError(f"the {self.solver} solver computes at most {total - 2} modes "
                             f"of this {self.m}-node shape, got n={n}; use solver='dense'")
        if n not in self._modes:
            solve = {"sparse": solve_modes_sparse, "multilevel": solve_modes_multilevel,
                     "dense": solve_modes}[self.solver]
            self._modes[n] = solve(self, n)
        return self._modes[n]

    def __repr__(self) -> str:
        return (f"FEModel(m={self.m}, d={self.dim}, sigma={self.sigma_rel:g}, "
                f"material={self.material.name}, solver={self.solver!r})")


def _check_reached(reached: np.ndarray) -> None:
    far = np.flatnonzero(~reached)
    if far.size:
        raise ValueError(f"point {far[0]} lies beyond the cutoff radius of every node of the "
                         f"model: use more model nodes or a larger sigma")


def _index_dtype(size: int):
    return np.dtype(np.int32) if size < np.iinfo(np.int32).max else np.dtype(np.intp)


def _breakdown_message(model: FEModel, cond: float | None = None) -> str:
    what = f" (condition number {cond:.1e})" if cond is not None else ""
    works = auto_sigma(model.shape, model.sigma_rel)
    hint = (f"the largest sigma that keeps it well conditioned here is about {works:.2g}; "
            if works < model.sigma_rel else "")
    return (f"sigma={model.sigma_rel:g} (x mean node spacing) is too large for this "
            f"{model.m}-node shape: its Gaussian Gram matrix is numerically singular{what}. "
            f"Use a smaller sigma ({hint}sigma=None chooses one per shape).")
