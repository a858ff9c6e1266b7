"""The driver of one morph's time integration: a state, a history and a stop test.

:class:`Simulation` builds the :class:`~modalmorph.simulation.system.ModalSystem` once,
chooses the stop test once (:func:`~modalmorph.simulation.stop.choose_stop_test`), and
records step 0; :meth:`Simulation.step` advances the :class:`State` one Newmark step and
records it in the :class:`History`, :meth:`Simulation.stop_test` says whether to stop
and why, :meth:`Simulation.run` alternates the two, and :meth:`Simulation.result` gives
the frozen :class:`~modalmorph.simulation.result.Run`.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ..core.model import FEModel
from ..core.modes import Modes
from ..core.shape import Shape
from ..errors import MorphDivergedError
from ..options import MorphOptions
from .basis import flat
from .result import Run, stop_sentence
from .stop import Limits, choose_stop_test
from .system import ModalSystem

__all__ = ["DIVERGED", "History", "Simulation", "State", "mean_pair_distance"]

log = logging.getLogger(__name__)

DIVERGED = 10  # diverged past this many initial pair distances (or sizes) (method.md §4)


def mean_pair_distance(current: np.ndarray, target: np.ndarray, pairs: np.ndarray) -> float:
    """Mean distance of the (source, target) ``pairs`` of nodes ``current`` and
    ``target``."""
    r = current[pairs[:, 0]] - target[pairs[:, 1]]  # np.linalg.norm(axis=1).mean()'s
    return float(np.add.reduce(np.sqrt(np.add.reduce(r * r, axis=1)))) / len(r)  # numbers


@dataclass(frozen=True, eq=False)
class State:
    """Newmark's state in modal coordinates and the shape it gives (normalised frame).

    Attributes
    ----------
    x, v, a : ndarray, shape (n,)
        Modal coordinates, velocities and accelerations.
    shape : ndarray, shape (m, d)
        The nodes, ``X_1 + Phi x``.
    targets : ndarray, shape (m, d)
        Where the springs pull the nodes (19)-(20), from ``shape``.
    moved : float
        The largest displacement of a node in the last step (inf before the first).
    """

    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    shape: np.ndarray
    targets: np.ndarray
    moved: float


class History:
    """Every step recorded: the shapes and loads (user units), the strain energies
    (``k_ref L^2``), and the mean distances of the matched and of the pulled pairs
    (normalised units), one entry per step in each list."""

    def __init__(self):
        self.shapes, self.loads, self.energy, self.node_energy = [], [], [], []
        self.mean_distance, self.near = [], []

    def record(self, system: ModalSystem, x: np.ndarray, shape: np.ndarray,
               targets: np.ndarray, mean_distance: float | None = None) -> None:
        """The step at modal coordinates ``x``, nodes ``shape`` pulled to ``targets``
        (``mean_distance``: that of the matched pairs, when already measured)."""
        size = system.size
        self.shapes.append(system.reduced.to_user(shape))
        self.loads.append(system.options.k * (targets - shape) * size)  # (19)-(20) x k
        energy, e_node = system.energies(x)
        self.energy.append(energy)
        self.node_energy.append(e_node)
        self.mean_distance.append(mean_pair_distance(shape, system.target_n, system.pairs)
                                  if mean_distance is None else mean_distance)
        self.near.append(mean_pair_distance(shape, system.target_n, system.pulled))


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
    partners : array_like of int, shape (P, 2), optional
        Objects of several contours: the partner contours ``(source contour, target
        contour)`` (None: those sharing the most pairs).

    Attributes
    ----------
    system : ModalSystem
        The equations, built once: the model, its modes, stiffness, springs, damping,
        the Newmark integrator and the load targets.
    stop : StopTest
        The stop test chosen for these objects (contour, surface or pairs).
    state : State
        Modal coordinates, velocities, accelerations and the current shape.
    history : History
        Every step's shape, loads, energies and distances.
    steps : int
        Time steps taken.
    reason : str or None
        Why the stop test stopped (``"tolerance"``, ``"equilibrium"``, ``"max_steps"``);
        None while running.
    """

    def __init__(self, source: Shape, target: Shape, pairs, options: MorphOptions | None = None,
                 partners: np.ndarray | None = None):
        self.system = s = ModalSystem.build(source, target, pairs, options, partners)
        self.stop = choose_stop_test(s.source, s.target, s.target_n,
                                     Limits.from_options(s.options, s.target.size, s.size),
                                     s.partners)
        self.history = History()
        self.steps = 0
        self.reason: str | None = None
        self._distance = np.inf  # the stop test's latest measure (normalised)
        self._start()

    def _start(self) -> None:
        """The initial state (17), (18), (21), step 0 recorded and tested."""
        s = self.system
        X1 = s.source_n
        T0 = s.loads.targets(X1)
        x = s.initial_coordinates(T0)
        v = s.options.c_v * x  # (18)
        # the loads rise from zero over the first step: a(0) without them (method.md §4)
        a = -(s.newmark.C @ v) - s.newmark.stiffness_dot(x)
        self.state = State(x, v, a, X1, T0, np.inf)
        self.history.record(s, np.zeros_like(x), X1, T0)
        self.stop_test()
        shape = s.shape(x)
        self.state = replace(self.state, shape=shape, targets=s.loads.targets(shape))

    # ------------------------------------------------------------------------- loop

    def step(self) -> None:
        """One time step: Newmark (14)-(15) under the loads (19)-(20), the loads updated
        to the new shape, the new shape recorded.

        Raises
        ------
        MorphDivergedError
            When the state is no longer finite or runs away from the target.
        """
        s, st = self.system, self.state
        self.steps += 1
        # implicit: R = k (T - X1 - U_new), the U_new part is in K_mod; explicit: (19) at
        # the previous shape
        f = s.modal_load(flat(st.targets - (s.source_n if s.options.scheme == "implicit"
                                            else st.shape)))
        x, v, a = s.newmark.step(st.x, st.v, st.a, f)
        new = s.shape(x)
        moved = np.abs(new - st.shape).max()
        self.state = State(x, v, a, new, st.targets, moved)
        dist = mean_pair_distance(new, s.target_n, s.pairs)  # recorded below
        if not np.all(np.isfinite(x)) or dist > DIVERGED * max(self.history.mean_distance[0], 1):
            raise MorphDivergedError(_diverged(s.options, self.steps), self.steps)
        self.state = State(x, v, a, new, s.loads.targets(new), moved)  # not replace(): 8 us
        self.history.record(s, x, new, self.state.targets, dist)

    def stop_test(self) -> str | None:
        """Whether to stop after the latest step, and why: ``"tolerance"`` (converged),
        ``"equilibrium"`` (no node moved visibly, or the distance gained less than 0.1 %
        over 5 steps) or ``"max_steps"``; None to go on (method.md §5). Sets
        :attr:`reason`."""
        near = self.history.near
        self._distance = self.stop.distance(self.state.shape, near[-1])
        self.reason = self.stop.reason(self._distance, self.steps, self.state.moved, near)
        return self.reason

    def run(self, progress: Callable[[int, float], None] | None = None) -> Simulation:
        """Step until the stop test stops; ``progress(step, mean distance of the pulled
        nodes in user units)`` after every step. Returns ``self``."""
        while self.reason is None:
            self.step()
            if progress is not None:
                progress(self.steps, self.history.near[-1] * self.system.size)
            self.stop_test()
        return self

    # ------------------------------------------------------------------- read-outs

    @property
    def shapes(self) -> np.ndarray:
        """The shapes so far, (steps + 1, m, d), user units."""
        return np.array(self.history.shapes)

    @property
    def mean_distance(self) -> np.ndarray:
        """Mean distance of the matched nodes to their partners so far, user units."""
        return np.array(self.history.mean_distance) * self.system.size

    @property
    def model(self) -> FEModel:
        """The physical model, of the source or of a coarser copy of it."""
        return self.system.model

    @property
    def modes(self) -> Modes:
        """The modes superposed: all of the model's (then solved on first use: the
        integration runs in the element's basis, method.md §4), or its lowest ``n_modes``
        and the Rayleigh-Ritz modes of smooth motions outside their span (§7)."""
        return self.system.modes

    @property
    def k_ref(self) -> float:
        """The stiffness of one node, the unit of ``k`` and of the energies."""
        return self.system.k_ref

    def result(self) -> Run:
        """The frozen :class:`Run` of a stopped simulation."""
        if self.reason is None:
            raise RuntimeError("the simulation has not stopped: call run(), or step() until "
                               "stop_test() gives a reason")
        s, h = self.system, self.history
        size, converged = s.size, self.reason == "tolerance"
        dist = self._distance
        if self.stop.lazy and not converged:  # the full measure at the end
            dist = self.stop.distance(self.state.shape, h.near[-1], lazy=False)
        unit = "input units" if s.target.frame is None else s.target.frame.unit
        message = stop_sentence(self.reason, self.steps, dist * size,
                                self.stop.tolerance * size, unit)
        if not converged:
            log.info("morph stopped without reaching the tolerance: %s", message)
        return Run(shapes=np.array(h.shapes), loads=np.array(h.loads),
                   energy=np.array(h.energy), node_energy=np.array(h.node_energy),
                   mean_distance=np.array(h.mean_distance) * size, distance=dist * size,
                   tolerance=self.stop.tolerance * size, stop_reason=self.reason,
                   message=message, resolved=s.resolved())


def _diverged(options: MorphOptions, steps: int) -> str:
    """The message of :class:`MorphDivergedError` at step ``steps``."""
    o = options
    return (f"the morph diverged at step {steps} ({o.scheme} loads, k={o.k:g}, "
            f"dt={o.dt:g}): " + ("the explicit load is only conditionally stable; use "
                                 "scheme='implicit' or a smaller k or dt"
                                 if o.scheme == "explicit"
                                 else "try a smaller dt or k, or more damping"))
