"""The time integration of a morph in named stages: build, step, stop test, result.

:class:`Simulation` holds one morph's physical model and state. Building it makes the
model and its modes, the reference scales, the modal stiffness (with the similarity
motions free), the springs, the damping, the Newmark integrator and the load targets, and
records step 0; :meth:`Simulation.step` advances one time step, :meth:`Simulation.stop_test`
says whether to stop and why, :meth:`Simulation.run` alternates the two, and
:meth:`Simulation.result` gives the frozen :class:`Run`. :func:`modalmorph.morph` is
matching, optional alignment and this.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import linalg
from scipy.spatial import cKDTree

from .core.dynamics import LoadTargets, Newmark
from .core.element import self_entries
from .core.energy import node_energy
from .core.model import FEModel
from .core.modes import rayleigh
from .core.quality import Polyline
from .core.shape import Shape, as_shape, check_pairs, coarsen, resample
from .errors import MorphDivergedError, OptionError
from .options import MorphOptions

__all__ = ["Resolved", "Run", "STOP_REASONS", "Simulation", "SPARSE_MODES"]

log = logging.getLogger(__name__)

# Modes superposed by default for large objects (sparse solver), where all modes would
# need a dense eigenproblem: the lowest ones, with smooth motions added (method.md §7),
# carry the smooth part of the deformation.
SPARSE_MODES = 100
# A truncated basis of n modes is augmented with every mode of a copy of min(n,
# _COARSE_MAX) nodes (3000-node hand 0 -> 3 and heart outlines, sparse, 100 modes, pairs
# by arc length: copies of 50/100/200 nodes leave the hand at 0.77/0.50/0.33 % of the
# size from the target, converged from 100 on, the heart converged with each; the affine
# motions alone: 4.4 % and 1.6 %); 400 nodes keep the copy's modes a dense eigenproblem
# of at most 1200 unknowns.
_COARSE_MAX = 400
# Equilibrium also when the mean distance gained less than _STALL_GAIN (0.1 %) over
# _STALL steps.
_STALL = 5
_STALL_GAIN = 1e-3
# Diverged when the matched nodes are further from their partners than this many times
# their distance at the start (or than this many model sizes).
_DIVERGED = 10
# Similarity fields whose modal image is below this fraction of the largest are dependent.
_RANK_TOL = 1e-10
# Point sets: each point's distance to a cloud's surface is taken to the plane of its
# _PLANE nearest points (blob of 600-20 000 points, noise 0 and 1 %: the target's own
# roughness, its points to the planes of their neighbours, is above what its true shape
# leaves both ways, 0.05-1.8 % of the size, against 1.3-7.9 % for the distance to the
# nearest point). The surfaces are measured once the pulled pairs are within the
# tolerance plus _LAZY_SPACINGS target spacings (matcher pairs err by about one spacing).
_PLANE = 8
_LAZY_SPACINGS = 4


STOP_REASONS = ("tolerance", "equilibrium", "max_steps")  # Run.stop_reason, in that order


@dataclass(frozen=True)
class Resolved:
    """The values a morph resolved from its options for its objects.

    Attributes
    ----------
    sigma : float
        Gaussian width of the physical model, in units of its mean node spacing.
    modes : int
        Number of modes superposed (the Rayleigh-Ritz additions included).
    model_nodes : int
        Nodes of the physical model (fewer than the source's for a reduced model).
    solver : str
        The eigensolver used (``"dense"``, ``"sparse"`` or ``"multilevel"``).
    """

    sigma: float
    modes: int
    model_nodes: int
    solver: str


@dataclass(frozen=True, eq=False, repr=False)
class Run:
    """What one :class:`Simulation` computed: the shapes in time, their loads, strain
    energies and distances, and why it stopped.

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
        corner). For 3D point sets (unordered): the larger of the mean distances both ways
        between the shape's nodes and the target's surface, less the target's own
        roughness (each point's distance to the plane of its 8 nearest points of the
        other set, and of the target's points to the plane of their 8 nearest other
        target points: what a sample of the target surface leaves; 0 when below), so that
        pairs right only to about a node spacing do not keep a shape lying on the target
        from converging; measured once the pulled pairs are within the tolerance plus 4
        target spacings. Other point sets (2D, or of at most 8 points): the mean distance
        of the nodes pulled to partners.
    tolerance : float
        The stop test's tolerance, in the user's units (``tol`` times the target's RMS
        radius, or ``tol_distance``).
    stop_reason : str
        Why the integration stopped, one of :data:`STOP_REASONS`: ``"tolerance"`` (the
        distance reached the tolerance), ``"equilibrium"`` (loads and elastic forces
        balance short of it) or ``"max_steps"``. A diverging integration raises
        :class:`~modalmorph.errors.MorphDivergedError` instead.
    message : str
        The same in one sentence, with the final distance and the tolerance in the
        target's unit.
    resolved : Resolved
        The values resolved from the options for this object (sigma, modes, model nodes,
        solver).
    """

    shapes: np.ndarray
    loads: np.ndarray
    energy: np.ndarray
    node_energy: np.ndarray
    mean_distance: np.ndarray
    distance: float
    tolerance: float
    stop_reason: str
    message: str
    resolved: Resolved

    @property
    def converged(self) -> bool:
        """Whether the distance reached the tolerance."""
        return self.stop_reason == "tolerance"

    @property
    def steps(self) -> int:
        """Number of time steps taken, T."""
        return self.shapes.shape[0] - 1

    def __repr__(self) -> str:
        m, d = self.shapes.shape[1:]
        return f"{type(self).__name__}({m} nodes in {d}D: {self.message})"


class Simulation:
    """One morph's time integration, in stages that run, test and profile on their own.

    Lagrange's dynamic equilibrium ``M U'' + C U' + K U = R`` (9) of the source's model,
    loaded by springs towards the target (19)-(20), integrated by mode superposition
    (11)-(13) and Newmark's method (14)-(15) (method.md §4). Everything below runs in the
    model's normalised frame (the source's centroid and RMS radius).

    Parameters
    ----------
    source, target : Shape or array_like (m, d) and (n, d)
        The object that deforms (already aligned, when the rigid part is removed) and the
        target, of one dimension.
    pairs : array_like of int, shape (K, 2)
        Matched (source index, target index) pairs, at least one.
    options : MorphOptions, optional
        The physical model, loads, time integration and stop test.

    Attributes
    ----------
    steps : int
        Time steps taken.
    reason : str or None
        Why the stop test stopped (``"tolerance"``, ``"equilibrium"``, ``"max_steps"``);
        None while running.
    model : FEModel
        The physical model, of ``reduced``: the source, or a coarser copy of it.
    modes : Modes
        The modes superposed: all of the model's, or its lowest ``n_modes`` and the
        Rayleigh-Ritz modes of smooth motions outside their span (the affine motions
        and, for truncated models, a coarse copy's modes: :meth:`FEModel.augmented`,
        method.md §7).
    k_ref : float
        The stiffness of one node, the unit of ``k`` and of the energies.
    """

    def __init__(self, source: Shape, target: Shape, pairs, options: MorphOptions | None = None):
        self.source, self.target = as_shape(source, "source"), as_shape(target, "target")
        self.pairs = check_pairs(pairs, self.source.m, self.target.m)
        self.options = MorphOptions() if options is None else options
        self.steps = 0
        self.reason: str | None = None
        self._build_model()
        self._build_loads()
        self._build_equations()
        self._build_stop_test()
        self._start()

    # ------------------------------------------------------------------------ build

    def _build_model(self) -> None:
        """The physical model, its modes and the reference scales."""
        o, work = self.options, self.source
        # The physical model: the source itself, or a coarser copy when it has more nodes
        # than model_nodes; every node then moves with the element's displacement field.
        self.reduced = reduced = coarsen(work, o.model_nodes)
        self.model = model = FEModel(reduced, sigma=o.sigma, material=o.material,
                                     solver=o.solver)
        self.n_modes = _mode_count(o.modes, model.dim * model.m,
                                   sparse=model.truncated)
        md = model.modes(self.n_modes)
        if self.n_modes < model.dim * model.m:  # truncated: add smooth motions (method.md §7)
            md = model.augmented(md, _smooth_fields(model, self.n_modes))
        self.modes = md
        self._MPhi = model.mass_times_modes(md)  # M Phi = (I kron A) M_g psi (method.md §1)
        # Reference scales: the stiffness and mass of one node in the Gaussian basis.
        d = work.dim
        self.k_ref, V = self_entries(model.width, d, *model.lame)
        m_ref = o.material.rho * V
        w_ref = np.sqrt(self.k_ref / m_ref)
        # one spring per node; with a reduced model their total stiffness is kept the same
        self._k_abs, self._dt_abs = o.k * self.k_ref * model.m / work.m, o.dt / w_ref
        self._size = reduced.size
        self._X1 = reduced.to_normalized(work.points)  # all in the model's normalised frame
        self._Y = reduced.to_normalized(self.target.points)
        if reduced is work:
            self._Phi, self._spread = _Field(md.shapes, d), None
        else:  # modes at every node: u(x) = sum_k g_k(x) psi_k (1)-(4), truncated like G
            g_eval = model.field(self._X1)
            self._Phi = _Field(md.gaussian, d, g_eval)
            self._spread = g_eval / g_eval.sum(axis=0)  # each model node's energy over nodes

    def _build_loads(self) -> None:
        """Where every node is pulled to: its partner (19), or the rule for the others
        (20) (:class:`modalmorph.core.dynamics.LoadTargets`)."""
        o, work, tgt = self.options, self.source, self.target
        self._loads = LoadTargets(self._X1, self._Y, self.pairs, ordered=bool(work.ordered),
                                  closed=work.closed, target_closed=tgt.closed,
                                  neighbours=o.neighbours, rule=o.unmatched)
        self._pulled = self._loads.pairs  # the pairs the springs (19) pull together

    def _build_equations(self) -> None:
        """The modal stiffness, springs and damping, and the Newmark integrator."""
        o, md = self.options, self.modes
        n = len(md.eigenvalues)
        # elastic stiffness in modal coordinates: Omega^2 (13), or with the similarity
        # motions of the model's nodes made free (free_motion="similarity")
        self._K_el = (np.diag(md.eigenvalues) if o.free_motion == "none" else _similarity_free(
            md.frequencies, self._MPhi.T @ _similarity_fields(self.model.points)))
        # the springs (19) in modal coordinates: Phi^T R = k Phi^T (T - X) ("nodal"), or
        # kappa x_T with x_T the modes' fit of T - X and kappa their mean ("consistent")
        PtP = self._Phi.gram()
        if o.loads == "consistent" and self._spread is None:  # x_T = Phi^T M (T - X)
            self._kappa = self._k_abs * np.trace(PtP) / n
            spring = self._kappa * np.eye(n)
        else:  # nodal, and every reduced model: each node's load through the field
            self._kappa = None
            spring = self._k_abs * PtP
        K_mod = self._K_el + (spring if o.scheme == "implicit" else 0.0)
        w_lo, w_hi = _frequency_range(K_mod, highest=np.ndim(o.damping) > 0)
        if np.ndim(o.damping) == 0:  # every mode approaches at nearly the springs' one rate
            a_r, b_r = _uniform_damping(float(o.damping), np.trace(spring) / n, w_lo)
        else:  # (5) through two ratios, as the paper
            a_r, b_r = rayleigh(*o.damping, w_lo, w_hi)
        self._C = a_r * np.eye(n) + b_r * K_mod  # (5) on the loaded model
        self._integrator = Newmark(K_mod, self._C, self._dt_abs, o.alpha, o.delta)

    def _build_stop_test(self) -> None:
        """The tolerance and rest thresholds (normalised units) and, for contours, the
        target curve the shape is measured against both ways."""
        o, work, tgt = self.options, self.source, self.target
        size = self._size
        self._tol_n = (o.tol_distance / size) if o.tol_distance is not None \
            else o.tol * tgt.size / size
        self._at_rest = o.equilibrium_tol * tgt.size / size  # a step that moves nothing
        self._two_way = bool(work.ordered and tgt.ordered)
        if self._two_way:  # what an m-node shape spread evenly along the target leaves off
            Y = self._Y
            self._floor = float(Polyline(resample(Y, work.m, closed=tgt.closed), tgt.closed)
                                .distance(Y).mean())
            self._to_target = Polyline(Y, tgt.closed)
        self._surface = not self._two_way and work.dim == 3 and min(work.m, tgt.m) > _PLANE
        if self._surface:  # the target's own roughness: what a sample of it leaves
            self._tree = cKDTree(self._Y)
            self._floor = float(_to_surface(self._Y, self._Y, self._tree, skip=1).mean())
            spacing = self._tree.query(self._Y, k=2)[0][:, 1].mean()
            self._gate = self._tol_n + _LAZY_SPACINGS * spacing

    def _start(self) -> None:
        """The initial state (17), (18), (21), step 0 recorded and tested."""
        o, X1 = self.options, self._X1
        self._shapes, self._forces, self._energy, self._e_node = [], [], [], []
        self._mean_dist, self._near = [], []
        T0 = self._loads.targets(X1)
        U0 = o.c_x * _flat(T0 - X1)  # (21): U0 = (c_x / k) R0
        # X0 = Phi^T M U0; with a reduced model, the least-squares fit of the field to U0
        if o.c_x == 0:
            x = np.zeros(len(self.modes.eigenvalues))
        elif self._spread is None:
            x = self._MPhi.T @ U0
        else:
            x = np.linalg.lstsq(self._Phi.dense(), U0, rcond=None)[0]
        self._x, self._v = x, o.c_v * x  # (18)
        # the loads rise from zero over the first step (a(0) without them): a sudden load
        # excites the stiffest modes, which Newmark's scheme damps slowly unless
        # alpha = delta / 2 (measured: alpha = delta = 0.5, k = 1000, dt = 1 on the bundled
        # heart swung 450 px at step 1 with the sudden load; ramped, at most 10 px: method.md §4)
        self._a = -(self._C @ self._v) - self._integrator.K @ x
        self._current = X1
        self._record(np.zeros_like(x), T0)
        self.stop_test()
        self._current = X1 + _nodes(self._Phi.dot(x), self.source.dim)
        self._T = self._loads.targets(self._current)  # weights of (20) from the current shape

    # ------------------------------------------------------------------------- loop

    def step(self) -> None:
        """One time step: Newmark (14)-(15) under the loads (19)-(20), the loads updated
        to the new shape, the new shape recorded.

        Raises
        ------
        MorphDivergedError
            When the state is no longer finite or runs away from the target.
        """
        o = self.options
        self.steps += 1
        # implicit: R = k (T - X1 - U_new), the U_new part is in K_mod; explicit: (19) at
        # the previous shape
        f = self._modal(_flat(self._T - (self._X1 if o.scheme == "implicit" else
                                         self._current)))
        x_new, self._v, self._a = self._integrator.step(self._x, self._v, self._a, f)
        new = self._X1 + _nodes(self._Phi.dot(x_new), self.source.dim)
        self._moved = np.abs(new - self._current).max()
        self._x, self._current = x_new, new
        if not np.all(np.isfinite(x_new)) or _mean_distance(new, self._Y, self.pairs) > \
                _DIVERGED * max(self._mean_dist[0], 1):
            raise MorphDivergedError(
                f"the morph diverged at step {self.steps} ({o.scheme} loads, k={o.k:g}, "
                f"dt={o.dt:g}): " + ("the explicit load is only conditionally stable; use "
                                     "scheme='implicit' or a smaller k or dt"
                                     if o.scheme == "explicit"
                                     else "try a smaller dt or k, or more damping"),
                self.steps)
        self._T = self._loads.targets(new)
        self._record(x_new, self._T)

    def stop_test(self) -> str | None:
        """Whether to stop after the latest step, and why: ``"tolerance"`` (converged),
        ``"equilibrium"`` (no node moved visibly, or the distance gained less than 0.1 %
        over 5 steps) or ``"max_steps"``; None to go on (method.md §5). Sets
        :attr:`reason`."""
        o, near = self.options, self._near
        self._dist = self._distance(near[-1])
        if self._dist <= self._tol_n:
            self.reason = "tolerance"
        elif self.steps == 0:
            self.reason = None
        elif self._moved <= self._at_rest or (o.equilibrium_tol > 0 and self.steps > _STALL
                                              and abs(near[-1 - _STALL] - near[-1])
                                              <= _STALL_GAIN * near[-1]):
            self.reason = "equilibrium"  # at rest, or the distance no longer decreases
        elif self.steps >= o.max_steps:
            self.reason = "max_steps"
        else:
            self.reason = None
        return self.reason

    def run(self, progress: Callable[[int, float], None] | None = None) -> Simulation:
        """Step until the stop test stops; ``progress(step, mean distance of the pulled
        nodes in user units)`` after every step. Returns ``self``."""
        while self.reason is None:
            self.step()
            if progress is not None:
                progress(self.steps, self._near[-1] * self._size)
            self.stop_test()
        return self

    @property
    def shapes(self) -> np.ndarray:
        """The shapes so far, (steps + 1, m, d), user units."""
        return np.array(self._shapes)

    @property
    def mean_distance(self) -> np.ndarray:
        """Mean distance of the matched nodes to their partners so far, user units."""
        return np.array(self._mean_dist) * self._size

    # ----------------------------------------------------------------------- result

    def result(self) -> Run:
        """The frozen :class:`Run` of a stopped simulation."""
        if self.reason is None:
            raise RuntimeError("the simulation has not stopped: call run(), or step() until "
                               "stop_test() gives a reason")
        size, converged = self._size, self.reason == "tolerance"
        dist = self._dist
        if (self._two_way or self._surface) and not converged:  # both ways at the end
            dist = self._distance(self._near[-1], lazy=False)
        frame = self.target.frame
        message = _stop_sentence(self.reason, self.steps, dist * size, self._tol_n * size,
                                 "input units" if frame is None else frame.unit)
        if not converged:
            log.info("morph stopped without reaching the tolerance: %s", message)
        resolved = Resolved(sigma=self.model.sigma, modes=self.n_modes,
                            model_nodes=self.model.m, solver=self.model.solver)
        return Run(shapes=np.array(self._shapes), loads=np.array(self._forces),
                   energy=np.array(self._energy), node_energy=np.array(self._e_node),
                   mean_distance=np.array(self._mean_dist) * size, distance=dist * size,
                   tolerance=self._tol_n * size, stop_reason=self.reason, message=message,
                   resolved=resolved)

    # ---------------------------------------------------------------------- helpers

    def _modal(self, u: np.ndarray) -> np.ndarray:
        """The springs' load (19) in modal coordinates, ``Phi^T R``."""
        if self._kappa is not None:  # consistent: kappa Phi^T M (T - X)
            return self._kappa * (self._MPhi.T @ u)
        return self._k_abs * self._Phi.tdot(u)

    def _distance(self, near: float, lazy: bool = True) -> float:
        """The stop test's measure (normalised units, :attr:`Run.distance`). With
        ``lazy``, a contour's curves are measured only once ``near`` (a lower bound) is
        within the tolerance, a point set's surfaces once it is within ``_gate``."""
        if self._surface:
            if lazy and near > self._gate:
                return near
            current, Y = self._current, self._Y
            d_ab = _to_surface(current, Y, self._tree).mean()
            d_ba = _to_surface(Y, current, cKDTree(current)).mean()
            return max(float(d_ab), float(d_ba), self._floor) - self._floor
        if not self._two_way or lazy and near > self._tol_n:
            return near
        current = self._current
        d_ab = self._to_target.distance(current)
        d_ba = Polyline(current, self.source.closed).distance(self._Y)
        return max(near, float(d_ab.mean()), float(d_ba.mean()) - self._floor)

    def _record(self, x: np.ndarray, targets: np.ndarray) -> None:
        """Step's shape, loads, energies and distances (user units for the shapes and
        loads, ``k_ref L^2`` for the energies)."""
        current, size, k_ref = self._current, self._size, self.k_ref
        self._shapes.append(self.reduced.to_user(current))
        self._forces.append(self.options.k * (targets - current) * size)  # (19)-(20) x k
        self._energy.append(float(x @ self._K_el @ x) / k_ref)  # (22), x^T (Phi^T K Phi) x
        e = node_energy(self.modes.shapes @ x, self._MPhi @ (self._K_el @ x),
                        self.source.dim) / k_ref  # (25), model nodes
        self._e_node.append(e if self._spread is None else self._spread @ e)
        self._mean_dist.append(_mean_distance(current, self._Y, self.pairs))
        self._near.append(_mean_distance(current, self._Y, self._pulled))


def _flat(P: np.ndarray) -> np.ndarray:
    """(m, d) -> component-major (d*m,) (7)."""
    return P.T.reshape(-1)


def _nodes(u: np.ndarray, d: int) -> np.ndarray:
    """(d*m,) -> (m, d)."""
    return u.reshape(d, -1).T


def _stop_sentence(reason: str, steps: int, final: float, tol: float, unit: str) -> str:
    """:attr:`Run.message`: one short sentence with the distance (:attr:`Run.distance`)
    and its tolerance, in the target's unit."""
    where = f"{final:.3g} {unit} from the target (tolerance {tol:.3g} {unit})"
    if reason == "tolerance":
        return f"converged after {steps} steps, {where}"
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


def _smooth_fields(model: FEModel, n: int) -> np.ndarray:
    """Smooth displacements of the model's nodes (d*m, s) that its lowest ``n`` modes
    carry poorly (method.md §7): the affine motions (every finite similarity
    ``(s R - I) X + t`` lies in their span) and, for a truncated model (sparse or
    multilevel solver: a count asked of the dense solver is a choice of a coarser
    description), every mode of a copy of it on ``min(n, _COARSE_MAX)`` nodes,
    evaluated through its field (1)-(4)."""
    X, d = model.points, model.dim
    affine = [np.kron(np.eye(d)[a], c) for a in range(d) for c in (np.ones(len(X)), *X.T)]
    if not model.truncated:
        return np.column_stack(affine)
    coarse = model.coarsened(min(n, _COARSE_MAX))
    at_nodes = coarse.shape.to_normalized(model.shape.points)
    return np.column_stack([*affine, coarse.modes_at(coarse.modes(), at_nodes)])


def _to_surface(points: np.ndarray, cloud: np.ndarray, tree: cKDTree,
                skip: int = 0) -> np.ndarray:
    """Distance of every point to the surface of a point cloud (normalised units): to the
    least-squares plane of its ``_PLANE`` nearest cloud points (the ``skip`` nearest left
    out, e.g. the point itself). Linear in memory; unlike the distance to the nearest
    cloud point, nearly zero for a point on a smooth surface between samples."""
    near = cloud[tree.query(points, k=_PLANE + skip)[1][:, skip:]]  # (p, k, d)
    centre = near.mean(axis=1)
    spread = near - centre[:, None]
    normal = np.linalg.eigh(np.einsum("pki,pkj->pij", spread, spread))[1][:, :, 0]
    return np.abs(np.einsum("pi,pi->p", normal, points - centre))


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


def _mode_count(modes, total: int, *, sparse: bool) -> int:
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
