"""What a simulation gives: the frozen :class:`Run`, the values it resolved
(:class:`Resolved`) and its reasons for stopping (:data:`STOP_REASONS`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Resolved", "Run", "STOP_REASONS", "stop_sentence"]

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
        corner); for objects of several contours, the largest of that measure over the
        pairs of partner contours, each source contour against its partner alone
        (contours without a partner left out). For 3D point sets (unordered): the larger
        of the mean distances both ways between the shape's nodes and the target's
        surface, less the target's own
        roughness (each point's distance to the plane of its 8 nearest points of the
        other set, and of the target's points to the plane of their 8 nearest other
        target points: what a sample of the target surface leaves; 0 when below), so that
        pairs right only to about a node spacing do not keep a shape lying on the target
        from converging; measured once the pulled pairs are within the tolerance plus 4
        target spacings; a source coarser than the target is allowed, the second way,
        what as many target points spread evenly leave. Other point sets (2D, or of at
        most 8 points): the mean distance of the nodes pulled to partners.
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


def stop_sentence(reason: str, steps: int, final: float, tol: float, unit: str) -> str:
    """:attr:`Run.message`: one short sentence with the distance (:attr:`Run.distance`)
    and its tolerance, in the target's unit."""
    where = f"{final:.3g} {unit} from the target (tolerance {tol:.3g} {unit})"
    if reason == "tolerance":
        return f"converged after {steps} steps, {where}"
    if reason == "equilibrium":
        return f"stopped at equilibrium after {steps} steps, {where}"
    return f"stopped at max_steps={steps}, {where}"

