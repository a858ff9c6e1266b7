"""``morph()``: the whole method, end to end, returning one result object."""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy import linalg

from .dynamics import UNMATCHED_RULES, LoadTargets, Newmark, check_newmark
from .element import check_sigma
from .energy import node_energy
from .material import POLYETHYLENE, Material
from .model import FEModel
from .modes import rayleigh
from .quality import Polyline
from .shape import Shape, as_shape, coarsen, resample

__all__ = ["Morph", "MorphDivergedError", "morph"]

log = logging.getLogger(__name__)

# Modes superposed by default for large objects (sparse solver), where all modes would
# need a dense eigenproblem: the lowest ones carry the smooth part of the deformation.
SPARSE_MODES = 100
# Equilibrium also when the mean distance gained less than 0.1 % over this many steps.
_STALL = 5
# Similarity fields whose modal image is below this fraction of the largest are dependent.
_RANK_TOL = 1e-10
FREE_MOTIONS = ("similarity", "none")
# Option ranges beyond which the integration is meaningless or overflows (the fuzz suite
# found dt = 1e-300 dividing by zero in Newmark's coefficients and c_x = 1e300 overflowing):
# k and dt over 12 decades about their defaults; c_x, c_v are fractions of the way (17),
# (18), where 1 already starts at the target.
K_RANGE = (1e-6, 1e6)
DT_RANGE = (1e-6, 1e6)
C_MAX = 10.0
LOADS = ("consistent", "nodal")


class MorphDivergedError(ArithmeticError):
    """The time integration diverged; ``.steps`` says when, the message what to change."""

    def __init__(self, message: str, steps: int):
        super().__init__(message)
        self.steps = steps


@dataclass(frozen=True, eq=False)
class Morph:
    """The intermediate shapes between two objects and their strain energy.

    Attributes
    ----------
    shapes : ndarray, shape (T+1, m, d)
        The deforming source at every step, in the user's (target's) coordinates. Step 0
        is the source (after removing the rigid part, when ``remove_rigid``).
    loads : ndarray, shape (T+1, m, d)
        Load on every node, ``k (X_2 - X_j)`` (19)-(20), in the user's length units times
        the dimensionless ``k``.
    energy : ndarray, shape (T+1,)
        Global strain energy ``U^T K U`` (22), in units of ``k_ref L^2`` (``k_ref`` the
        stiffness of one node, ``L`` the source's RMS radius): independent of the units of
        the input and of the material's E.
    node_energy : ndarray, shape (T+1, m)
        Strain energy per node (25), same units; sums to ``energy``; may be negative.
    mean_distance : ndarray, shape (T+1,)
        Mean distance of the matched nodes to their partners, in the user's units.
    distance : float
        The stop test's measure at the last step, in the user's units (it is below the
        tolerance exactly when ``converged``): for contours the largest of the
        mean distance of the nodes pulled to partners (the matching's pairs less those
        freed to cover unpaired stretches of the target) and the distances both ways
        between the shape and the target curve, so that every stretch of the target
        counts, paired or not: the mean distance of the shape's nodes to the target
        polyline, and of the target's nodes to the shape's polyline less what a shape of
        the source's node count leaves there (the target resampled evenly by arc length
        at ``m`` nodes: a source no finer than the target cannot follow its every
        corner). For point sets: the mean distance of the nodes pulled to partners.
    matching : Matching
        The correspondences used.
    similarity : Similarity or None
        The similarity removed before morphing (``remove_rigid``), else None.
    converged : bool
        Whether ``distance`` reached the tolerance.
    stop_reason : str
        One sentence: converged, stopped at equilibrium (loads and elastic forces balance
        short of the tolerance) or at ``max_steps``, with the final distance.
    source, target : Shape
        The objects as given (the source before any rigid alignment).
    params : dict
        Every option used, for reports.
    """

    shapes: np.ndarray
    loads: np.ndarray
    energy: np.ndarray
    node_energy: np.ndarray
    mean_distance: np.ndarray
    matching: object
    similarity: object
    converged: bool
    stop_reason: str
    source: Shape
    target: Shape
    params: dict = field(default_factory=dict)
    distance: float | None = None

    @property
    def steps(self) -> int:
        """Number of time steps taken, T."""
        return self.shapes.shape[0] - 1


def morph(source, target, *, matching=None, remove_rigid: bool = False,
          rotation: str = "auto", free_motion: str = "similarity",
          loads: str = "consistent", k: float = 100.0,
          dt: float = 0.1, alpha: float = 0.25, delta: float = 0.5,
          damping: float | tuple[float, float] = 1.0, c_x: float = 0.0, c_v: float = 0.0,
          material: Material = POLYETHYLENE, sigma: float | None = None,
          modes: int | float | None = None, solver: str = "auto", model_nodes: int = 400,
          scheme: str = "implicit", tol: float = 0.005,
          tol_distance: float | None = None, max_steps: int = 100,
          equilibrium_tol: float = 1e-5, unmatched: str = "arclength", neighbours: int = 6,
          progress: Callable[[int, float], None] | None = None) -> Morph:
    """Estimate the intermediate shapes that take ``source`` into ``target``.

    The source is modelled with Sclaroff's Gaussian element, matched nodes are pulled to
    their partners by springs of stiffness ``k`` (19), unmatched nodes by the neighbourhood
    rule (20), and Lagrange's dynamic equilibrium ``M U'' + C U' + K U = R`` (9) is
    integrated in time by mode superposition (11)-(13) and Newmark's method (14)-(15).

    Parameters
    ----------
    source, target : Shape or array_like, shape (m, d) and (n, d)
        The objects at times t and t+1, both 2D or both 3D.
    matching : Matching or array_like of int (K, 2), optional
        Correspondences (source index, target index). Computed with
        :func:`modalmorph.match` when not given.
    remove_rigid : bool, optional
        Align the source onto the target first with Horn's similarity (rotation,
        translation, scale) from the matched pairs; the morph then holds only the
        non-rigid part and usually needs far fewer steps.
    rotation : {"auto", "free", "none"}, optional
        When ``matching`` is not given: how the matcher treats the relative orientation
        of the objects (see :func:`modalmorph.match`; ``"none"`` for objects drawn in one
        frame, such as the frames of a sequence).
    free_motion : {"similarity", "none"}, optional
        Motions the elastic model does not resist. ``"similarity"`` (default): a change of
        position, orientation or size of the whole object costs no strain energy (the
        energy of a displacement is that of its non-similar part,
        ``min_a (U - S a)^T K (U - S a)`` over the similarity fields ``S``; exact for 2D,
        small rotations in 3D): the springs then reach a target of any size or pose, and
        the energy measures the change of shape alone. The Gaussian element's own rigid
        modes are only nearly free (method.md §1). ``"none"``: the paper's ``U^T K U``
        (22) for every motion, so a size change is resisted like any strain (a heart
        morphed onto itself scaled 1000x then stops far from it).
    loads : {"consistent", "nodal"}, optional
        How the springs (19)-(20) load the model. ``"nodal"``: the paper's, a force
        ``k (X_2 - X)`` on every node; with the element's consistent mass the modes then
        feel different springs, so some race ahead of others (a heart shrunk 1000x passed
        through shapes 12x rougher than either end, and folded). ``"consistent"``
        (default): every bit of the object is pulled towards where the targets say, in
        proportion to its mass: in modal coordinates ``kappa (x_T - x)``, ``x_T`` the
        mass projection of the targets' displacement onto the modes and ``kappa`` the
        springs' mean modal stiffness, the same for every mode. A pure change of size or
        pose then morphs along that similarity, and no mode lags behind. A reduced model
        (a source of more than ``model_nodes`` nodes) is loaded node by node through its
        field either way.
    k : float, optional
        Stiffness of the springs that pull nodes to their targets (19), in units of the
        elastic stiffness of one node of the model. Larger ``k`` pulls harder: fewer steps
        and a closer final fit; with ``scheme="explicit"`` too large a ``k`` diverges.
    dt : float, optional
        Time step, in units of ``1/omega_ref`` (``omega_ref`` the natural frequency of one
        node on its own elastic stiffness). Larger steps move faster per step.
    alpha, delta : float, optional
        Newmark's parameters (14). ``delta=0.5`` has no numerical damping; ``delta > 0.5``
        damps (first-order accurate), best with ``alpha=(delta+0.5)**2/4`` (16). Must
        satisfy ``2 alpha >= delta >= 0.5``.
    damping : float or (float, float), optional
        Rayleigh damping ``C = a M + b K`` (5) of the loaded model (elastic stiffness plus
        springs). A pair: the damping ratios (fractions of critical) at its lowest and
        highest frequencies; the paper used 0.005-0.03, which leaves the shape oscillating
        about the target for many steps. A number (default 1): the ratio at the springs'
        frequency, growing in proportion to the frequency above it (stiffness-
        proportional), so that every mode creeps to the target at nearly the same rate
        and the shape moves along nearly straight paths. Measured on the shared hearts:
        with the former default (2, 2) the stiff modes raced ahead of the soft ones, and
        intermediate shapes were up to 1.9x rougher than either end and folded on 8 of 16
        pairs (and on a heart shrunk 1000x); with 1, none.
    c_x, c_v : float, optional
        Initial displacement as a fraction of the load (17), (21) and initial velocity
        ``c_v`` times it (18). Larger values start faster.
    material : Material, optional
        The material filling the source (default polyethylene, the paper's).
    sigma : float or None, optional
        Gaussian width of the physical model in units of its mean node spacing (see
        :class:`FEModel`); ``None`` (default): 1, or less where the model's Gram matrix
        would be ill-conditioned. The matcher's models have their own width (see
        :func:`modalmorph.match`).
    modes : int, float or None, optional
        Modes used in the superposition: all (``None``), a count, or a fraction in (0, 1]
        of all modes (the paper compares all with 2/3). Fewer modes: cheaper steps, a less
        exact final shape. With the sparse solver ``None`` means the lowest 100.
    model_nodes : int, optional
        Largest physical model built. A source with more nodes is modelled on this many
        nodes spread evenly over it (by arc length for contours), and every node moves with
        the element's displacement field ``u(x) = sum_k h_k(x) U_k`` (3)-(4); its load
        enters through the same field (consistent nodal loads), and the local energy is
        spread from the model nodes over the nodes around them. The default, 400, was
        measured: with 300, 4 of the 186 glyph outlines at 400 nodes folded for 1-4 steps
        beside a serif (the interpolated field lets neighbouring nodes overtake where the
        displacement turns sharply); with 400, none, at twice the cost of a 1000-node
        morph (0.16 -> 0.28 s, still 22x the dense transcription).
    solver : {"auto", "dense", "sparse", "multilevel"}, optional
        Eigensolver of the model (see :class:`FEModel`): ``"auto"`` uses the exact dense
        one for small objects and the truncated sparse one for large objects.
    scheme : {"implicit", "explicit"}, optional
        Where the loads are evaluated. ``"implicit"``: at the new shape (the spring enters
        the effective stiffness; unconditionally stable). ``"explicit"``: at the previous
        shape, as in the paper (stable only for small ``k``).
    tol : float, optional
        Stop (converged) when :attr:`Morph.distance` falls below this fraction of the
        target's RMS radius: for contours, when the shape is that close to the whole
        target curve both ways.
    tol_distance : float, optional
        The same tolerance in the user's units; overrides ``tol``.
    max_steps : int, optional
        Maximum number of time steps.
    equilibrium_tol : float, optional
        Stop when no node moves by more than this fraction of the target's size in a step,
        or when the distance has changed by less than 0.1 % over 5 steps: the loads
        and the elastic forces balance short of the tolerance. 0 disables both.
    unmatched : {"arclength", "mean"}, optional
        Where an unmatched node of a contour is pulled, between the partners of its
        matched neighbours along the contour. ``"arclength"`` (default): to the point of
        the target stretch between those partners at the node's fraction of the source
        stretch's arc length, so a run of unmatched nodes spreads evenly over it.
        ``"mean"``: the paper's neighbourhood rule (20), a weighted mean of the target
        nodes of that stretch (weights normalised to 1); it pulls every node of a long
        run to nearly one point, which folds the contour (measured: the 28 pairs of
        bundled hands at full resolution cross themselves). 3D point sets use the
        (20)-weighted displacements of their ``neighbours`` nearest matched nodes either
        way. See :class:`modalmorph.dynamics.LoadTargets`.
    neighbours : int, optional
        For unordered 3D objects: how many matched neighbours pull an unmatched node.
    progress : callable, optional
        Called after every step as ``progress(step, mean_distance)`` (user units), e.g.
        to drive a progress bar.

    Returns
    -------
    Morph

    Raises
    ------
    ValueError
        For invalid inputs or options, or when no node is matched.
    MorphDivergedError
        When the integration diverges (typically the explicit scheme with too large a k).
    """
    src = as_shape(source, "source")
    tgt = as_shape(target, "target")
    if src.dim != tgt.dim:
        raise ValueError(f"source and target must have the same dimension, got "
                         f"{src.dim}D and {tgt.dim}D")
    _check_options(k=k, dt=dt, damping=damping, scheme=scheme, tol=tol,
                   tol_distance=tol_distance, max_steps=max_steps, neighbours=neighbours,
                   model_nodes=model_nodes, unmatched=unmatched, free_motion=free_motion,
                   loads=loads, c_x=c_x, c_v=c_v, equilibrium_tol=equilibrium_tol)
    check_newmark(alpha, delta)
    check_sigma(sigma)
    if matching is None:
        from .matching import match

        matching = match(src, tgt, rotation=rotation)
    pairs = _pairs(matching, src.m, tgt.m)

    similarity = None
    work = src
    if remove_rigid:  # section 5.2: Horn's similarity from the matched pairs
        from .align import align

        similarity = align(src.points[pairs[:, 0]], tgt.points[pairs[:, 1]], scale=True)
        work = src.with_points(similarity.apply(src.points))

    # The physical model: the source itself, or a coarser copy when it has more nodes
    # than model_nodes; every node then moves with the element's displacement field.
    reduced = coarsen(work, model_nodes)
    model = FEModel(reduced, sigma=sigma, material=material, solver=solver)
    n_modes = _mode_count(modes, model.dim * model.m,
                          sparse=model.solver in ("sparse", "multilevel"))
    md = model.modes(n_modes)
    d, m = work.dim, work.m
    w2 = md.eigenvalues
    rho = material.rho
    MPhi = model.mass_times_modes(md)  # M Phi = (I kron A) M_g psi (method.md §1)

    # Reference scales: the stiffness and mass of one node in the Gaussian basis.
    lam, mu = model.lame
    V = (np.pi * model.sigma**2) ** (d / 2)
    k_ref = V / model.sigma**2 * ((lam + mu) / 2 + mu * d / 2)
    m_ref = rho * V
    w_ref = np.sqrt(k_ref / m_ref)
    # one spring per node; with a reduced model their total stiffness is kept the same
    k_abs, dt_abs = k * k_ref * model.m / m, dt / w_ref

    X1 = reduced.to_normalized(work.points)  # everything in the model's normalised frame
    Y = reduced.to_normalized(tgt.points)
    if reduced is work:
        Phi, spread = _Field(md.shapes, d), None
    else:  # modes at every node: u(x) = sum_k g_k(x) psi_k (1)-(4), truncated like G
        g_eval = model.field(X1)
        Phi = _Field(md.gaussian, d, g_eval)
        spread = g_eval / g_eval.sum(axis=0)  # each model node's energy over the nodes
    loads_rule = LoadTargets(X1, Y, pairs, ordered=bool(work.ordered), closed=work.closed,
                             target_closed=tgt.closed, neighbours=neighbours, rule=unmatched)

    # elastic stiffness in modal coordinates: Omega^2 (13), or with the similarity motions
    # of the model's nodes made free (free_motion="similarity")
    K_el = (np.diag(w2) if free_motion == "none" else
            _similarity_free(md.frequencies, MPhi.T @ _similarity_fields(model.points)))
    # the springs (19) in modal coordinates: Phi^T R = k Phi^T (T - X) ("nodal"), or
    # kappa x_T with x_T the modes' fit of T - X and kappa their mean ("consistent")
    PtP = Phi.gram()
    spring = k_abs * PtP
    if loads == "consistent" and spread is None:  # x_T = Phi^T M (T - X), M-projection
        kappa = k_abs * np.trace(PtP) / len(w2)
        spring = kappa * np.eye(len(w2))

        def modal(u):
            return kappa * (MPhi.T @ u)
    else:  # nodal, and every reduced model: each node's load through the field
        def modal(u):
            return k_abs * Phi.tdot(u)
    K_mod = K_el + (spring if scheme == "implicit" else 0.0)
    w_lo, w_hi = _frequency_range(K_mod, highest=np.ndim(damping) > 0)
    if np.ndim(damping) == 0:  # every mode approaches at nearly the springs' one rate
        a_r, b_r = _uniform_damping(float(damping), np.trace(spring) / len(w2), w_lo)
    else:  # (5) through two ratios, as the paper
        a_r, b_r = rayleigh(*damping, w_lo, w_hi)
    C_mod = a_r * np.eye(len(w2)) + b_r * K_mod  # (5) on the loaded model
    integrator = Newmark(K_mod, C_mod, dt_abs, alpha, delta)

    def flat(P):  # (m, d) -> component-major (d*m,) (7)
        return P.T.reshape(-1)

    def nodes(u):  # (d*m,) -> (m, d)
        return u.reshape(d, m).T

    size = reduced.size
    tol_n = (tol_distance / size) if tol_distance is not None else tol * tgt.size / size
    shapes, forces, energy, e_node, mean_dist, near = [], [], [], [], [], []
    two_way = bool(work.ordered and tgt.ordered)
    pulled = loads_rule.pairs  # the pairs the springs (19) pull together
    if two_way:  # what an m-node shape spread evenly along the target leaves off it
        floor = float(Polyline(resample(Y, m, closed=tgt.closed), tgt.closed).distance(Y)
                      .mean())
        to_target = Polyline(Y, tgt.closed)

    def distance(current, near, lazy=True):
        """The stop test's measure (normalised units). It is at least ``near``, so with
        ``lazy`` the curves are measured only once ``near`` is within the tolerance."""
        if not two_way or lazy and near > tol_n:
            return near
        d_ab = to_target.distance(current)
        d_ba = Polyline(current, work.closed).distance(Y)
        return max(near, float(d_ab.mean()), float(d_ba.mean()) - floor)

    def record(x, current, targets):
        shapes.append(reduced.to_user(current))
        forces.append(k * (targets - current) * size)  # (19)-(20), user length units x k
        energy.append(float(x @ K_el @ x) / k_ref)  # (22), U^T K U = x^T (Phi^T K Phi) x
        e = node_energy(md.shapes @ x, MPhi @ (K_el @ x), d) / k_ref  # (25), model nodes
        e_node.append(e if spread is None else spread @ e)
        mean_dist.append(_mean_distance(current, Y, pairs))
        near.append(_mean_distance(current, Y, pulled))

    # t = 0: the source, and the initial state (17), (18), (21)
    T0 = loads_rule.targets(X1)
    U0 = c_x * flat(T0 - X1)  # (21): U0 = (c_x / k) R0
    # X0 = Phi^T M U0; with a reduced model, the least-squares fit of the field to U0
    if c_x == 0:
        x = np.zeros(len(w2))
    else:
        x = MPhi.T @ U0 if spread is None else np.linalg.lstsq(Phi.dense(), U0, rcond=None)[0]
    v = c_v * x  # (18)
    # the loads rise from zero over the first step (a(0) without them): a sudden load
    # excites the stiffest modes, which Newmark's scheme damps slowly unless
    # alpha = delta / 2 (measured: alpha = delta = 0.5, k = 1000, dt = 1 on the bundled
    # heart swung 450 px at step 1 with the sudden load; ramped, it converges in 23 steps)
    a = -(C_mod @ v) - K_mod @ x
    record(np.zeros_like(x), X1, T0)
    dist = distance(X1, near[0])
    at_rest = equilibrium_tol * tgt.size / size  # a step this small moves nothing visible
    reason = "tolerance" if dist <= tol_n else None
    current = X1 + nodes(Phi.dot(x))
    T = loads_rule.targets(current)  # weights of (20) from the current shape
    step = 0
    while reason is None:
        step += 1
        # implicit: R = k (T - X1 - U_new), the U_new part is in K_mod; explicit: (19) at
        # the previous shape
        f = modal(flat(T - (X1 if scheme == "implicit" else current)))
        x_new, v, a = integrator.step(x, v, a, f)
        new = X1 + nodes(Phi.dot(x_new))
        moved = np.abs(new - current).max()
        x, current = x_new, new
        if not np.all(np.isfinite(x)) or _mean_distance(current, Y, pairs) > 10 * max(
                mean_dist[0], 1):
            raise MorphDivergedError(
                f"the morph diverged at step {step} ({scheme} loads, k={k:g}, dt={dt:g}): "
                + ("the explicit load is only conditionally stable; use scheme='implicit' "
                   "or a smaller k or dt" if scheme == "explicit"
                   else "try a smaller dt or k, or more damping"), step)
        T = loads_rule.targets(current)
        record(x, current, T)
        if progress is not None:
            progress(step, near[-1] * size)
        dist = distance(current, near[-1])
        if dist <= tol_n:
            reason = "tolerance"
        elif moved <= at_rest or (equilibrium_tol > 0 and step > _STALL and abs(
                near[-1 - _STALL] - near[-1]) <= 1e-3 * near[-1]):
            reason = "equilibrium"  # at rest, or the distance no longer decreases
        elif step == max_steps:
            reason = "max_steps"

    converged = reason == "tolerance"
    if two_way and reason != "tolerance":  # measured both ways at the end in any case
        dist = distance(current, near[-1], lazy=False)
    stop = _stop_sentence(reason, step, dist * size, tol_n * size, two_way)
    if not converged:
        log.info("morph stopped without reaching the tolerance: %s", stop)
    params = dict(remove_rigid=remove_rigid, rotation=rotation, free_motion=free_motion,
                  loads=loads,
                  k=k, dt=dt, alpha=alpha, delta=delta,
                  damping=np.asarray(damping).tolist(), c_x=c_x, c_v=c_v, material=material.name,
                  E=material.E, nu=material.nu, rho=material.rho, sigma=model.sigma_rel,
                  modes=n_modes, model_nodes=model.m, solver=model.solver, scheme=scheme,
                  tol=tol, tol_distance=tol_distance,
                  max_steps=max_steps, equilibrium_tol=equilibrium_tol,
                  unmatched=unmatched, neighbours=neighbours)
    return Morph(shapes=np.array(shapes), loads=np.array(forces), energy=np.array(energy),
                 node_energy=np.array(e_node), mean_distance=np.array(mean_dist) * size,
                 matching=matching, similarity=similarity, converged=converged,
                 stop_reason=stop, source=src, target=tgt, params=params,
                 distance=dist * size)


def _stop_sentence(reason: str, steps: int, final: float, tol: float, two_way: bool) -> str:
    """``stop_reason``: one short sentence with the distance and its tolerance."""
    what = ("mean distance of the matched nodes and both ways" if two_way else
            "mean distance of the matched nodes")
    where = f"{final:.3g} from the target ({what}; tolerance {tol:.3g}, input units)"
    if reason == "tolerance":
        return f"converged after {steps} steps: {where}"
    if reason == "equilibrium":
        return f"stopped at equilibrium after {steps} steps, {where}"
    return f"stopped at max_steps={steps}, {where}"


class _Field:
    """The modes at every node, ``Phi = (I_d kron g) B``, applied without forming Phi.

    ``B`` (d*mc, n) is the modal basis at the model's nodes (``Phi`` itself, then ``g`` is
    None) or in the Gaussian basis (``psi``, with ``g`` the sparse (m, mc) field matrix of a
    reduced model, :meth:`FEModel.field`). Memory stays that of ``g`` and ``B``.
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

    def dense(self) -> np.ndarray:
        """``Phi`` itself, (d*m, n)."""
        return np.concatenate([b if self.g is None else self.g @ b for b in self.B])


def _uniform_damping(xi: float, spring: float, w_lo: float) -> tuple[float, float]:
    """Rayleigh coefficients ``(a, b)`` (5) of the default damping: ``b = 2 xi / w_s``
    with ``w_s^2`` the springs' mean modal stiffness, so that a mode of loaded frequency
    ``w >= w_s`` has the ratio ``xi w / w_s``: overdamped modes then creep towards the
    target at nearly one rate (``~1 / b``), and the shape moves along nearly straight
    paths, with no mode racing ahead (ripples, folds); ``a`` lifts the softest loaded
    mode to ``xi`` when it lies below ``w_s``."""
    w_s = np.sqrt(spring)
    b = 2 * xi / w_s
    return max(0.0, 2 * w_lo * (xi - b * w_lo / 2)), b


def _similarity_fields(points: np.ndarray) -> np.ndarray:
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


def _similarity_free(frequencies: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Modal stiffness with the similarity motions free: ``min_a (U - S a)^T K (U - S a)``.

    ``B = Phi^T M S`` (n, s) are the modal coordinates of the similarity fields ``S``.
    The elastic energy of ``U = Phi x`` less that of its best-fitting similarity part is
    ``x^T Omega (I - P) Omega x`` with ``P`` the projector onto the columns of
    ``Omega B``: positive semi-definite, zero on similarity motions.
    """
    W = frequencies[:, None] * B
    U, sv, _ = np.linalg.svd(W, full_matrices=False)
    OmU = frequencies[:, None] * U[:, sv > _RANK_TOL * sv.max()]
    K = np.diag(frequencies**2) - OmU @ OmU.T
    return (K + K.T) / 2


def _frequency_range(K_mod, *, highest: bool = True):
    """The lowest and (when ``highest``) the highest frequency of the loaded model."""
    if not highest:  # only the lowest eigenvalue: 3x faster at 140 modes
        ev = linalg.eigh(K_mod, eigvals_only=True, subset_by_index=(0, 0), driver="evr")
        return np.sqrt(max(ev[0], 0.0)), None
    ev = np.linalg.eigvalsh(K_mod)
    hi = np.sqrt(ev[-1])
    lo = np.sqrt(max(ev[0], 0.0))
    return min(lo, hi * (1 - 1e-9)), hi


def _mean_distance(current, Y, pairs):
    return float(np.linalg.norm(current[pairs[:, 0]] - Y[pairs[:, 1]], axis=1).mean())


def _pairs(matching, m, n):
    pairs = getattr(matching, "pairs", matching)
    pairs = np.asarray(pairs)
    if pairs.ndim != 2 or pairs.shape[1] != 2 or not np.issubdtype(pairs.dtype, np.integer):
        raise ValueError(f"matching must be a Matching or an integer array of shape (K, 2), "
                         f"got {pairs.dtype} {pairs.shape}")
    if len(pairs) == 0:
        raise ValueError("no node is matched: morph needs at least one matched pair")
    if pairs[:, 0].min() < 0 or pairs[:, 0].max() >= m or pairs[:, 1].min() < 0 \
            or pairs[:, 1].max() >= n:
        raise ValueError(f"matching indices out of range for {m} source and {n} target nodes")
    if len(np.unique(pairs[:, 0])) != len(pairs):
        raise ValueError("matching pairs a source node more than once")
    return pairs.astype(np.intp)


def _mode_count(modes, total, *, sparse):
    """``None``: all modes (the lowest SPARSE_MODES with the sparse solver); an int: a
    count; a float: a fraction of all modes."""
    if modes is None:
        return min(SPARSE_MODES, total - 2) if sparse else total
    if isinstance(modes, float | np.floating):
        if not 0 < modes <= 1:
            raise ValueError(f"modes as a fraction must be in (0, 1], got {modes}")
        return max(1, int(round(modes * total)))
    if not isinstance(modes, int | np.integer) or not 1 <= modes <= total:
        raise ValueError(f"modes must be None, a count between 1 and {total} (d * m), "
                         f"or a fraction in (0, 1], got {modes!r}")
    return int(modes)


def _check_options(*, k, dt, damping, scheme, tol, tol_distance, max_steps, neighbours,
                   model_nodes, unmatched, free_motion, loads, c_x, c_v, equilibrium_tol):
    if not np.isfinite(k) or k <= 0:
        raise ValueError(f"k must be a positive number, got {k}")
    if not K_RANGE[0] <= k <= K_RANGE[1]:
        raise ValueError(f"k must lie in [{K_RANGE[0]:g}, {K_RANGE[1]:g}] (x one node's "
                         f"stiffness), got {k:g}")
    if not np.isfinite(dt) or dt <= 0:
        raise ValueError(f"dt must be a positive number, got {dt}")
    if not DT_RANGE[0] <= dt <= DT_RANGE[1]:
        raise ValueError(f"dt must lie in [{DT_RANGE[0]:g}, {DT_RANGE[1]:g}] (x 1/omega_ref), "
                         f"got {dt:g}")
    for name, value in (("c_x", c_x), ("c_v", c_v)):
        if not (np.isfinite(value) and 0 <= value <= C_MAX):
            raise ValueError(f"{name} must be a number in [0, {C_MAX:g}], got {value!r}")
    if not (np.isfinite(equilibrium_tol) and equilibrium_tol >= 0):
        raise ValueError(f"equilibrium_tol must be a number >= 0, got {equilibrium_tol!r}")
    if not (np.ndim(damping) == 0 and np.isfinite(damping) and damping > 0 or np.shape(
            damping) == (2,) and np.all(np.isfinite(damping)) and min(damping) >= 0):
        raise ValueError(f"damping must be a ratio > 0 or two ratios >= 0, got {damping!r}")
    if scheme not in ("implicit", "explicit"):
        raise ValueError(f"scheme must be 'implicit' or 'explicit', got {scheme!r}")
    if not tol > 0:
        raise ValueError(f"tol must be > 0, got {tol}")
    if tol_distance is not None and not tol_distance > 0:
        raise ValueError(f"tol_distance must be > 0, got {tol_distance}")
    if int(max_steps) != max_steps or max_steps < 1:
        raise ValueError(f"max_steps must be a positive integer, got {max_steps}")
    if int(neighbours) != neighbours or neighbours < 1:
        raise ValueError(f"neighbours must be a positive integer, got {neighbours}")
    if loads not in LOADS:
        raise ValueError(f"loads must be one of {LOADS}, got {loads!r}")
    if free_motion not in FREE_MOTIONS:
        raise ValueError(f"free_motion must be one of {FREE_MOTIONS}, got {free_motion!r}")
    if unmatched not in UNMATCHED_RULES:
        raise ValueError(f"unmatched must be one of {UNMATCHED_RULES}, got {unmatched!r}")
    if int(model_nodes) != model_nodes or model_nodes < 3:
        raise ValueError(f"model_nodes must be an integer >= 3, got {model_nodes}")
