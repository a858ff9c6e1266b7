"""``morph()``: the whole method, end to end, returning one result object."""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .dynamics import UNMATCHED_RULES, LoadTargets, Newmark, check_newmark
from .element import DEFAULT_SIGMA, FEModel
from .energy import node_energy, strain_energy
from .material import POLYETHYLENE, Material
from .modes import rayleigh
from .shape import Shape, as_shape, coarsen

__all__ = ["Morph", "MorphDivergedError", "morph"]

log = logging.getLogger(__name__)

# Modes superposed by default for large objects (sparse solver), where all modes would
# need a dense eigenproblem: the lowest ones carry the smooth part of the deformation.
SPARSE_MODES = 100
# Equilibrium also when the mean distance gained less than 0.1 % over this many steps.
_STALL = 5


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
    matching : Matching
        The correspondences used.
    similarity : Similarity or None
        The similarity removed before morphing (``remove_rigid``), else None.
    converged : bool
        Whether the mean distance reached the tolerance.
    stop_reason : str
        ``"tolerance"``, ``"equilibrium"`` or ``"max_steps"``, with the final distance.
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

    @property
    def steps(self) -> int:
        """Number of time steps taken, T."""
        return self.shapes.shape[0] - 1


def morph(source, target, *, matching=None, remove_rigid: bool = False, k: float = 100.0,
          dt: float = 0.1, alpha: float = 0.25, delta: float = 0.5,
          damping: tuple[float, float] = (2.0, 2.0), c_x: float = 0.0, c_v: float = 0.0,
          material: Material = POLYETHYLENE, sigma: float = DEFAULT_SIGMA,
          modes: int | float | None = None, solver: str = "auto", model_nodes: int = 300,
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
    damping : (float, float), optional
        Damping ratios (fractions of critical) at the lowest and highest frequencies of the
        loaded model (elastic stiffness plus springs), giving Rayleigh's
        ``C = a M + b K`` (5). The paper used 0.005-0.03, which leaves the shape
        oscillating about the target for many steps; the default (2, 2), twice critical,
        makes the shape approach the target without overshoot (measured on the hands).
    c_x, c_v : float, optional
        Initial displacement as a fraction of the load (17), (21) and initial velocity
        ``c_v`` times it (18). Larger values start faster.
    material : Material, optional
        The material filling the source (default polyethylene, the paper's).
    sigma : float, optional
        Gaussian width in units of the mean node spacing (see :class:`FEModel`).
    modes : int, float or None, optional
        Modes used in the superposition: all (``None``), a count, or a fraction in (0, 1]
        of all modes (the paper compares all with 2/3). Fewer modes: cheaper steps, a less
        exact final shape. With the sparse solver ``None`` means the lowest 100.
    model_nodes : int, optional
        Largest physical model built. A source with more nodes is modelled on this many
        nodes spread evenly over it (by arc length for contours), and every node moves with
        the element's displacement field ``u(x) = sum_k h_k(x) U_k`` (3)-(4); its load
        enters through the same field (consistent nodal loads), and the local energy is
        spread from the model nodes over the nodes around them.
    solver : {"auto", "dense", "sparse"}, optional
        Eigensolver of the model (see :class:`FEModel`): ``"auto"`` uses the exact dense
        one for small objects and the truncated sparse one for large objects.
    scheme : {"implicit", "explicit"}, optional
        Where the loads are evaluated. ``"implicit"``: at the new shape (the spring enters
        the effective stiffness; unconditionally stable). ``"explicit"``: at the previous
        shape, as in the paper (stable only for small ``k``).
    tol : float, optional
        Stop when the mean distance of matched nodes to their partners falls below this
        fraction of the target's RMS radius.
    tol_distance : float, optional
        The same tolerance in the user's units; overrides ``tol``.
    max_steps : int, optional
        Maximum number of time steps.
    equilibrium_tol : float, optional
        Stop when no node moves by more than this fraction of the source's size in a step,
        or when the mean distance has changed by less than 0.1 % over 5 steps: the loads
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
                   model_nodes=model_nodes, unmatched=unmatched)
    check_newmark(alpha, delta)
    if matching is None:
        from .matching import match

        matching = match(src, tgt)
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

    PtP = Phi.gram()
    K_mod = np.diag(w2) + (k_abs * PtP if scheme == "implicit" else 0.0)
    w_lo, w_hi = _frequency_range(K_mod)
    a_r, b_r = rayleigh(*damping, w_lo, w_hi)
    C_mod = a_r * np.eye(len(w2)) + b_r * K_mod  # (5) on the loaded model
    integrator = Newmark(K_mod, C_mod, dt_abs, alpha, delta)

    def flat(P):  # (m, d) -> component-major (d*m,) (7)
        return P.T.reshape(-1)

    def nodes(u):  # (d*m,) -> (m, d)
        return u.reshape(d, m).T

    size = reduced.size
    tol_n = (tol_distance / size) if tol_distance is not None else tol * tgt.size / size
    shapes, loads, energy, e_node, dist = [], [], [], [], []

    def record(x, current, targets):
        shapes.append(reduced.to_user(current))
        loads.append(k * (targets - current) * size)  # (19)-(20), user length units x k
        energy.append(strain_energy(x, w2) / k_ref)  # (22)
        e = node_energy(md.shapes @ x, MPhi @ (w2 * x), d) / k_ref  # (25), model nodes
        e_node.append(e if spread is None else spread @ e)
        dist.append(_mean_distance(current, Y, pairs))

    # t = 0: the source, and the initial state (17), (18), (21)
    T0 = loads_rule.targets(X1)
    U0 = c_x * flat(T0 - X1)  # (21): U0 = (c_x / k) R0
    # X0 = Phi^T M U0; with a reduced model, the least-squares fit of the field to U0
    if c_x == 0:
        x = np.zeros(len(w2))
    else:
        x = MPhi.T @ U0 if spread is None else np.linalg.lstsq(Phi.dense(), U0, rcond=None)[0]
    v = c_v * x  # (18)
    f = k_abs * Phi.tdot(flat(T0 - X1) - (0.0 if scheme == "implicit" else U0))
    a = f - C_mod @ v - K_mod @ x
    record(np.zeros_like(x), X1, T0)
    d0 = dist[0]
    reason = "tolerance" if d0 <= tol_n else None
    current = X1 + nodes(Phi.dot(x))
    T = loads_rule.targets(current)  # weights of (20) from the current shape
    step = 0
    while reason is None:
        step += 1
        if scheme == "implicit":  # R = k (T - X1 - U_new): the U_new part is in K_mod
            f = k_abs * Phi.tdot(flat(T - X1))
        else:  # (19) evaluated at the previous shape
            f = k_abs * Phi.tdot(flat(T - current))
        x_new, v, a = integrator.step(x, v, a, f)
        new = X1 + nodes(Phi.dot(x_new))
        moved = np.abs(new - current).max()
        x, current = x_new, new
        if not np.all(np.isfinite(x)) or _mean_distance(current, Y, pairs) > 10 * max(d0, 1):
            raise MorphDivergedError(
                f"the morph diverged at step {step} ({scheme} loads, k={k:g}, dt={dt:g}): "
                + ("the explicit load is only conditionally stable; use scheme='implicit' "
                   "or a smaller k or dt" if scheme == "explicit"
                   else "try a smaller dt or k, or more damping"), step)
        T = loads_rule.targets(current)
        record(x, current, T)
        if progress is not None:
            progress(step, dist[-1] * size)
        if dist[-1] <= tol_n:
            reason = "tolerance"
        elif moved <= equilibrium_tol or (equilibrium_tol > 0 and step > _STALL and abs(
                dist[-1 - _STALL] - dist[-1]) <= 1e-3 * dist[-1]):
            reason = "equilibrium"  # at rest, or the distance no longer decreases
        elif step == max_steps:
            reason = "max_steps"

    converged = reason == "tolerance"
    final = dist[-1] * size
    stop = (f"{reason}: mean distance {final:.4g} after {len(dist) - 1} steps "
            f"(tolerance {tol_n * size:.4g})")
    if not converged:
        log.info("morph stopped without reaching the tolerance: %s", stop)
    params = dict(remove_rigid=remove_rigid, k=k, dt=dt, alpha=alpha, delta=delta,
                  damping=list(damping), c_x=c_x, c_v=c_v, material=material.name,
                  E=material.E, nu=material.nu, rho=material.rho, sigma=sigma,
                  modes=n_modes, model_nodes=model.m, solver=model.solver, scheme=scheme,
                  tol=tol, tol_distance=tol_distance,
                  max_steps=max_steps, equilibrium_tol=equilibrium_tol,
                  unmatched=unmatched, neighbours=neighbours)
    return Morph(shapes=np.array(shapes), loads=np.array(loads), energy=np.array(energy),
                 node_energy=np.array(e_node), mean_distance=np.array(dist) * size,
                 matching=matching, similarity=similarity, converged=converged,
                 stop_reason=stop, source=src, target=tgt, params=params)


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


def _frequency_range(K_mod):
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
                   model_nodes, unmatched):
    if not np.isfinite(k) or k <= 0:
        raise ValueError(f"k must be a positive number, got {k}")
    if not np.isfinite(dt) or dt <= 0:
        raise ValueError(f"dt must be a positive number, got {dt}")
    if len(damping) != 2 or min(damping) < 0:
        raise ValueError(f"damping must be two ratios >= 0, got {damping}")
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
    if unmatched not in UNMATCHED_RULES:
        raise ValueError(f"unmatched must be one of {UNMATCHED_RULES}, got {unmatched!r}")
    if int(model_nodes) != model_nodes or model_nodes < 3:
        raise ValueError(f"model_nodes must be an integer >= 3, got {model_nodes}")
