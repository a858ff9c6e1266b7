"""The modal system of one morph, built once: ``x'' + C_mod x' + K_mod x = Phi^T R``.

:class:`ModalSystem` holds what the time integration reads and never changes: the
physical model and the basis of its coordinates (the modes superposed, or with every
mode the element's whitened basis, the same equations without the eigenproblem), the
reference scales, the stiffness in that basis (with the similarity motions free), the
springs, the damping, the Newmark integrator and the load targets (method.md §4).
Everything runs in the model's normalised frame (the centroid and RMS radius of the
shape it is built on).
"""

from __future__ import annotations

from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass

import numpy as np
from scipy import linalg

from ..core.dynamics import ContourLoads, LoadTargets, Newmark, contour_partners, lifted
from ..core.element import self_entries
from ..core.energy import node_energy
from ..core.model import FEModel
from ..core.modes import Modes, rayleigh
from ..core.shape import Shape, as_shape, check_pairs, coarsen
from ..options import MorphOptions
from .basis import (
    ElementBasis,
    ModeBasis,
    affine_weights,
    flat,
    mode_count,
    nodes,
    similarity_fields,
    superposed_modes,
)
from .result import Resolved

__all__ = ["FIT_JITTER", "ModalSystem", "RANK_TOL", "reuse_systems", "several", "damping_matrix",
           "elastic_stiffness", "frequency_range", "similarity_free", "similarity_free_full",
           "springs"]

RANK_TOL = 1e-10  # similarity fields whose modal image is below this fraction are dependent
FIT_JITTER = 1e-12  # relative lift of Phi^T Phi's diagonal (rounding: 1e-16 x its mean)


@dataclass(frozen=True, eq=False, repr=False)
class ModalSystem:
    """The equations of one morph in modal coordinates, built once by :meth:`build`.

    Attributes
    ----------
    source, target : Shape
        The object that deforms and the target.
    pairs : ndarray of int, shape (K, 2)
        Matched (source, target) pairs.
    options : MorphOptions
        The physical model, loads, time integration and stop test.
    reduced : Shape
        The shape the model is built on: the source, or a coarser copy of it (its
        normalised frame is the frame of every array below).
    model : FEModel
        The physical model.
    n_modes : int
        The modes asked of the model (before the Rayleigh-Ritz additions).
    basis : ModeBasis or ElementBasis
        The coordinates of the equations: the modes superposed
        (:func:`~modalmorph.simulation.basis.superposed_modes`), or, when that is every
        mode of the exact model, the element's whitened basis, the same equations
        without the eigenproblem (:class:`~modalmorph.simulation.basis.ElementBasis`);
        ``M Phi`` and ``Phi^T M`` at the model's nodes (method.md §1).
    field : Field or KronField
        ``Phi`` at every node of the source.
    spread : sparse array (m, mc) or None
        A reduced model's node energy spread over the source's nodes (None: not reduced).
    k_ref : float
        The stiffness of one node, the unit of ``k`` and of the energies.
    k_abs : float
        The springs' stiffness ``k`` in the model's units, per source node.
    source_n, target_n : ndarray, shape (m, d) and (n, d)
        Source and target nodes, normalised.
    loads : LoadTargets
        Where every node is pulled (19)-(20).
    pulled : ndarray of int, shape (K', 2)
        The pairs the springs (19) pull together (:attr:`LoadTargets.pairs`).
    stiffness : ndarray, shape (n, n)
        The elastic stiffness ``K_el`` (13), the similarity motions free or not.
    similar : tuple of ndarray or None
        ``(C, Y)``, (n, r) and (r, n): the similarity part of coordinates ``x`` is
        ``C (Y x)``, the one ``K_el`` leaves out (None: none left out, ``free_motion``
        "none"); the node energies (25) are those of ``x`` less it.
    kappa : float or None
        The consistent loads' modal spring (None: loads through the field, node by node).
    fit : tuple or None
        A reduced 3D model's consistent loads: the Cholesky factor of ``Phi^T Phi``, whose
        solve gives the modes' least-squares fit ``x_T`` of ``T - X`` (None otherwise).
    newmark : Newmark
        The integrator of the loaded model: ``K_mod``, ``C_mod`` and the time step.
    partners : ndarray of int, shape (P, 2), or None
        Objects of several contours: the partner contours that pull each other
        (:class:`~modalmorph.core.dynamics.ContourLoads`); None for one contour.
    """

    source: Shape
    target: Shape
    pairs: np.ndarray
    options: MorphOptions
    reduced: Shape
    model: FEModel
    n_modes: int
    basis: ModeBasis | ElementBasis
    field: object  # Field or KronField
    spread: object  # sparse array (m, mc) or None
    k_ref: float
    k_abs: float
    source_n: np.ndarray
    target_n: np.ndarray
    loads: LoadTargets
    pulled: np.ndarray
    stiffness: np.ndarray
    similar: tuple | None
    kappa: float | None
    newmark: Newmark
    partners: np.ndarray | None = None
    fit: tuple | None = None

    @classmethod
    def build(cls, source, target, pairs, options: MorphOptions | None = None,
              partners: np.ndarray | None = None) -> ModalSystem:
        """The system of ``source`` (Shape or (m, d)) pulled onto ``target`` by ``pairs``;
        for objects of several contours, ``partners`` (P, 2) are the partner contours
        (None: derived from the pairs,
        :func:`~modalmorph.core.dynamics.contour_partners`)."""
        source, target = as_shape(source, "source"), as_shape(target, "target")
        pairs = check_pairs(pairs, source.m, target.m)
        o = MorphOptions() if options is None else options
        part = _cached(source, o)
        if part is None:
            part = _source_part(source, o)
            _remember(source, o, part)
        reduced = part["reduced"]
        Y = reduced.to_normalized(target.points)  # the model's normalised frame
        loads = _loads(source, target, part["source_n"], Y, pairs, o, partners)
        return cls(source=source, target=target, pairs=pairs, options=o, target_n=Y,
                   loads=loads, pulled=loads.pairs,
                   partners=getattr(loads, "partners", None), **part)

    @property
    def modes(self) -> Modes:
        """The modes superposed (with an :class:`ElementBasis`, all of the model's,
        solved on first use)."""
        return self.basis.modes

    @property
    def size(self) -> float:
        """The model's length unit in the user's units (its shape's RMS radius)."""
        return self.reduced.size

    def shape(self, x: np.ndarray) -> np.ndarray:
        """The nodes (m, d), normalised, at modal coordinates ``x``: ``X_1 + Phi x``."""
        return self.source_n + nodes(self.field.dot(x), self.source.dim)

    def modal_load(self, u: np.ndarray) -> np.ndarray:
        """The springs' load (19) in modal coordinates, ``Phi^T R``, for the stretch
        ``u = T - X`` (d*m,)."""
        if self.fit is not None:  # consistent, reduced: kappa (Phi^T Phi)^-1 Phi^T (T - X)
            return self.kappa * linalg.cho_solve(self.fit, self.field.tdot(u))
        if self.kappa is not None:  # consistent: kappa Phi^T M (T - X)
            return self.kappa * self.basis.mass_t(u)
        return self.k_abs * self.field.tdot(u)

    def initial_coordinates(self, targets: np.ndarray) -> np.ndarray:
        """``x^0`` (17), (21): ``U^0 = c_x (T^0 - X_1)`` in modal coordinates,
        ``Phi^T M U^0``, or with a reduced model the least-squares fit of the field."""
        c_x = self.options.c_x
        U0 = c_x * flat(targets - self.source_n)  # (21): U0 = (c_x / k) R0
        if c_x == 0:
            return np.zeros(self.basis.n)
        if self.spread is None:
            return self.basis.mass_t(U0)
        return np.linalg.lstsq(self.field.dense(), U0, rcond=None)[0]

    def energies(self, x: np.ndarray) -> tuple[float, np.ndarray]:
        """The strain energy (22) at ``x`` and its share at every node (25), in units of
        ``k_ref L^2``: ``x^T K_el x`` and ``u . (K U)`` with ``K U = M Phi K_el x`` and
        ``u`` the displacement less its similarity part (:attr:`similar`), which strains
        nothing in all but shares out +- terms node by node (method.md §6)."""
        k_ref, K_el = self.k_ref, self.stiffness
        energy = float(x @ K_el @ x) / k_ref  # (22), x^T (Phi^T K Phi) x
        own = x if self.similar is None else x - self.similar[0] @ (self.similar[1] @ x)
        e = node_energy(self.basis.at_nodes(own), self.basis.mass(K_el @ x),
                        self.source.dim) / k_ref  # (25), model nodes
        return energy, (e if self.spread is None else self.spread @ e)

    def resolved(self) -> Resolved:
        """The values resolved from the options (sigma, modes, model nodes, solver)."""
        return Resolved(sigma=self.model.sigma, modes=self.n_modes,
                        model_nodes=self.model.m, solver=self.model.solver)


def _source_part(source: Shape, o: MorphOptions) -> dict:
    """The fields of a :class:`ModalSystem` that depend on the source and the options
    alone (not on the target or the pairs): the model, its modes, the reference scales,
    the stiffness, the springs, the damping and the integrator."""
    # The physical model: the source itself, or a coarser copy when it has more nodes
    # than model_nodes; every node then moves with the element's displacement field.
    reduced = coarsen(source, o.model_nodes)
    model = FEModel(reduced, sigma=o.sigma, material=o.material, solver=o.solver)
    n_modes = mode_count(o.modes, model.dim * model.m, sparse=model.truncated)
    if n_modes == model.dim * model.m and not model.truncated:  # every mode: no eigh
        basis = ElementBasis(model)
    else:
        basis = ModeBasis(model, superposed_modes(model, n_modes))
    # Reference scales: the stiffness and mass of one node in the Gaussian basis.
    k_ref, V = self_entries(model.width, source.dim, *model.lame)
    w_ref = np.sqrt(k_ref / (o.material.rho * V))
    # one spring per node; with a reduced model their total stiffness is kept the same
    k_abs = o.k * k_ref * model.m / source.m
    X1 = reduced.to_normalized(source.points)  # all in the model's normalised frame
    field, spread = _nodal_field(model, basis, X1, reduced is not source)
    # a reduced 3D model pulls consistently too, by the modes' fit of the stretch (§7)
    fitted = o.loads == "consistent" and spread is not None and model.dim == 3
    kappa, spring = springs(field, k_abs, consistent=o.loads == "consistent"
                            and (spread is None or fitted))
    fit = _gram_factor(field) if fitted else None
    # after the springs (their arrays kept): the whitened stiffness it frees leaves a
    # hole the damping matrix fits in, not fresh pages at the heap's top (issue 22)
    stiffness, similar = elastic_stiffness(basis, model.points, o.free_motion)
    uniform = kappa is not None and o.scheme == "implicit"  # K_mod = K_el + kappa I
    # K_mod = K_el + kappa I is K_el read with its diagonal lifted (no (n, n) copy)
    # where only its diagonal and products with it are needed (one damping ratio)
    lift = kappa if uniform and np.ndim(o.damping) == 0 else 0.0
    K_mod = (stiffness if lift or o.scheme != "implicit"
             else _loaded(stiffness, kappa, spring))
    newmark = Newmark(K_mod, damping_matrix(o.damping, K_mod, _mean(kappa, spring, field.n),
                                            uniform=uniform, lift=lift),
                      o.dt / w_ref, o.alpha, o.delta, lift=lift)
    return dict(reduced=reduced, model=model, n_modes=n_modes, basis=basis,
                field=field, spread=spread, k_ref=k_ref,
                k_abs=k_abs, source_n=X1, stiffness=stiffness, similar=similar, kappa=kappa,
                newmark=newmark, fit=fit)


# reuse_systems(): the source parts built in it, [(source, options, part)]; None outside
_REUSED: ContextVar[list | None] = ContextVar("reused_systems", default=None)


@contextmanager
def reuse_systems():
    """Within it, :meth:`ModalSystem.build` reuses the model, modes and integrator of the
    first system built in it, for the same :class:`Shape` object with equal options (a
    sequence morphed from one frame: ``track(..., reference="first")``; the frames redone
    from another source are built afresh and not kept, so memory stays one system); the
    results are those of a fresh build, bit for bit. What it holds is released on
    leaving."""
    token = _REUSED.set([])
    try:
        yield
    finally:
        _REUSED.reset(token)


def _cached(source: Shape, o: MorphOptions) -> dict | None:
    for shape, options, part in _REUSED.get() or ():
        if shape is source and options == o:
            return part
    return None


def _remember(source: Shape, o: MorphOptions, part: dict) -> None:
    reused = _REUSED.get()
    if reused is not None and not reused:  # the first system only: bounded memory
        reused.append((source, o, part))


def several(source: Shape, target: Shape) -> bool:
    """Whether the objects are contours and one of them has several."""
    return bool(source.ordered and target.ordered and (source.contours or target.contours))


def _loads(source: Shape, target: Shape, X1, Y, pairs, o: MorphOptions, partners):
    """Where every node is pulled (19)-(20): :class:`LoadTargets`, or per pair of partner
    contours (:class:`ContourLoads`)."""
    if not several(source, target):
        onto = target.dim == 3 and not source.ordered and target.has_faces
        return LoadTargets(X1, Y, pairs, ordered=bool(source.ordered),
                           closed=(source.closed, target.closed), neighbours=o.neighbours,
                           rule=o.unmatched, faces=target.faces if onto else None)
    if partners is None:
        partners = contour_partners(source.contour_of, target.contour_of, pairs)
    return ContourLoads(X1, Y, pairs, slices=(source.slices, target.slices),
                        partners=np.asarray(partners, dtype=np.intp),
                        closed=(source.closed, target.closed), rule=o.unmatched)


def _nodal_field(model: FEModel, basis, points: np.ndarray, reduced: bool):
    """``Phi`` at the source's nodes ``points`` and, for a reduced model, the spread of
    each model node's energy over them (its field ``g_k`` at them, normalised). A
    reduced 2D model moves every node with the element's field; a 3D one with the
    moving affine fit of the model's nodal motion (:func:`affine_weights`): the field
    ripples between the model's nodes, by up to 0.17 sizes under a shift of one size,
    and thin parts (the bunny's ears) cut through each other (method.md §7)."""
    if not reduced:
        return basis.field(), None
    g_eval = model.field(points)  # u(x) = sum_k g_k(x) psi_k (1)-(4), truncated like G
    spread = g_eval / g_eval.sum(axis=0)
    if model.dim == 3:
        return basis.field(nodes=affine_weights(model.points, points, model.width)), spread
    return basis.field(gaussian=g_eval), spread


def _gram_factor(field) -> tuple:
    """The Cholesky factor of ``Phi^T Phi``, its diagonal lifted by ``FIT_JITTER`` of its
    mean (a mode nearly invisible at the nodes would make it singular)."""
    gram = field.gram()
    gram.flat[::len(gram) + 1] += FIT_JITTER * np.trace(gram) / len(gram)
    return linalg.cho_factor(gram)


def elastic_stiffness(basis, points: np.ndarray, free_motion: str) -> tuple:
    """The elastic stiffness in the coordinates of ``basis``: ``Phi^T K Phi`` (13), or
    with the similarity motions of the model's nodes ``points`` free
    (``"similarity"``; an :class:`ElementBasis` then hands its own over,
    :meth:`~ElementBasis.take_stiffness`); and the factors ``(C, Y)`` of the similarity
    part ``C (Y x)`` it leaves out (None for ``"none"``)."""
    if free_motion == "none":
        return basis.stiffness(), None
    B = basis.mass_t(similarity_fields(points))
    if isinstance(basis, ModeBasis):
        return similarity_free(basis.modes.frequencies, B)
    return similarity_free_full(basis.take_stiffness(), B)  # K_w freed once it is used


def similarity_free(frequencies: np.ndarray, B: np.ndarray) -> tuple:
    """Modal stiffness with the similarity motions free: ``min_a (U - S a)^T K (U - S a)``,
    and the factors ``(C, Y)`` of the best-fitting similarity part ``C (Y x)``.

    ``B = Phi^T M S`` (n, s) are the modal coordinates of the similarity fields ``S``.
    The elastic energy of ``U = Phi x`` less that of its best-fitting similarity part is
    ``x^T Omega (I - P) Omega x`` with ``P`` the projector onto the columns of
    ``Omega B``: positive semi-definite, zero on similarity motions.
    """
    W = frequencies[:, None] * B
    U, sv, _ = np.linalg.svd(W, full_matrices=False)
    U = U[:, sv > RANK_TOL * sv.max()]
    OmU = frequencies[:, None] * U
    K = np.diag(frequencies**2) - OmU @ OmU.T
    # the similarity part: Omega^-1 P Omega x, P = U U^T (its energy is what K drops)
    return (K + K.T) / 2, (U / frequencies[:, None], OmU.T)


def similarity_free_full(K: np.ndarray, B: np.ndarray) -> tuple:
    """:func:`similarity_free` for a full stiffness ``K`` (n, n) (not diagonal):
    ``K - K B (B^T K B)^+ B^T K``, the same rank rule on the singular values of the
    similarity fields' image (the square roots of the eigenvalues of ``B^T K B``), at
    least ``sqrt(s eps)`` of the largest: below that the square's eigenvalues are its
    rounding."""
    KB = K @ B
    lam, V = np.linalg.eigh(B.T @ KB)
    root = np.sqrt(np.clip(lam, 0.0, None))
    keep = root > max(RANK_TOL, np.sqrt(len(lam) * np.finfo(float).eps)) * root.max()
    Z = KB @ (V[:, keep] / root[keep])
    out = Z @ Z.T  # one syrk: exactly symmetric, as K is
    # the similarity part: B (B^T K B)^+ B^T K x = (B V / root) (Z^T x)
    return np.subtract(K, out, out=out), (B @ (V[:, keep] / root[keep]), Z.T)


def springs(field, k_abs: float, *, consistent: bool):
    """The springs (19) in modal coordinates, ``(kappa, spring matrix)``: nodal,
    ``Phi^T R = k Phi^T (T - X)`` (kappa None); consistent, ``kappa x_T`` with ``x_T``
    the modes' fit of ``T - X`` and ``kappa`` their mean stiffness (the trace of
    ``Phi^T Phi`` is the sum of the squares of ``Phi``: the product itself is not formed),
    the matrix ``kappa I`` then not formed either (None)."""
    if consistent:  # x_T = Phi^T M (T - X)
        return k_abs * field.sq_norm() / field.n, None
    return None, k_abs * field.gram()


def _loaded(stiffness: np.ndarray, kappa: float | None, spring) -> np.ndarray:
    """The loaded stiffness ``K_el + spring``, or ``K_el + kappa I`` (its diagonal lifted:
    the same numbers without the identity)."""
    return stiffness + spring if kappa is None else lifted(stiffness, kappa)


def _mean(kappa: float | None, spring, n: int) -> float:
    """The springs' mean modal stiffness, the trace of the spring matrix over ``n``
    (``kappa I``'s summed as ``np.trace`` sums it: bitwise the same)."""
    return float((np.trace(spring) if kappa is None else np.full(n, kappa).sum()) / n)


def damping_matrix(damping, K_mod: np.ndarray, spring_mean: float, *,
                   uniform: bool = False, lift: float = 0.0) -> np.ndarray:
    """``C_mod = a I + b K_mod`` (5) on the loaded model, by one of the two rules.

    ``damping=(xi_1, xi_2)``: the paper's, the ratios at the loaded model's lowest and
    highest frequencies (:func:`~modalmorph.rayleigh`). ``damping=xi``: ``b = 2 xi / w_s``
    with ``w_s^2`` the springs' mean modal stiffness (``spring_mean``), so that a mode of
    loaded frequency ``w >= w_s`` has the ratio ``xi w / w_s``: overdamped modes then creep
    towards the target at nearly one rate (``~1 / b``), and the shape moves along nearly
    straight paths, with no mode racing ahead (ripples, folds); ``a`` lifts the softest loaded
    mode to ``xi`` when it lies below ``w_s`` (method.md §4). ``uniform``: ``K_mod`` is a
    positive semi-definite elastic stiffness plus ``spring = w_s^2 I`` (consistent springs
    in the effective stiffness), so no loaded mode lies below ``w_s``, ``a`` is 0 and the
    lowest frequency is not computed (it gave ``a`` of the order of its rounding).
    ``lift`` (one ratio, ``uniform``): the loaded stiffness is ``K_mod + lift I``, its
    diagonal lifted here (the same numbers as ``b`` times the lifted matrix).
    """
    n = len(K_mod)
    if lift and not (uniform and np.ndim(damping) == 0):
        raise ValueError("damping_matrix: a lifted stiffness takes one damping ratio")
    if np.ndim(damping) == 0:  # every mode approaches at nearly the springs' one rate
        xi, w_s = float(damping), np.sqrt(float(spring_mean))  # a number, not K_s
        b = 2 * xi / w_s
        if uniform:  # K_mod = K_el + w_s^2 I, K_el >= 0: w_lo >= w_s, so a = 0
            if not lift:
                return b * K_mod
            C = np.multiply(b, K_mod, order="C")  # in the order of a lifted copy's
            C.flat[::n + 1] = b * (np.diagonal(K_mod) + lift)
            return C
        w_lo, _ = frequency_range(K_mod, highest=False)
        a = max(0.0, 2 * w_lo * (xi - b * w_lo / 2))
    else:
        w_lo, w_hi = frequency_range(K_mod)  # (5) through two ratios, as the paper
        a, b = rayleigh(*damping, w_lo, w_hi)
    C = b * K_mod  # a I + b K_mod
    C.flat[::n + 1] += a
    return C


def frequency_range(K_mod: np.ndarray, *, highest: bool = True):
    """The lowest and (when ``highest``) the highest frequency of the loaded model. A
    lowest eigenvalue within rounding of zero (below ``n eps`` times the largest row sum:
    the similarity motions of an explicit scheme's free stiffness) is zero: its square
    root was rounding noise of either sign, 1e-4 of the frequencies."""
    floor = len(K_mod) * np.finfo(float).eps * np.abs(K_mod).sum(axis=1).max()
    if not highest:  # only the lowest eigenvalue: 3x faster at 140 modes
        ev = linalg.eigh(K_mod, eigvals_only=True, subset_by_index=(0, 0), driver="evr")
        return np.sqrt(ev[0] if ev[0] > floor else 0.0), None
    ev = np.linalg.eigvalsh(K_mod)
    hi = np.sqrt(ev[-1])
    lo = np.sqrt(ev[0] if ev[0] > floor else 0.0)
    return min(lo, hi * (1 - 1e-9)), hi
