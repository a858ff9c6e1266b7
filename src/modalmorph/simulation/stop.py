"""The stop test (method.md §5): how far the shape is from the target, and why to stop.

One class per kind of object, chosen once by :func:`choose_stop_test`, all with the
interface of :class:`StopTest`: :class:`CurveStop` for contours (the two-way distance
between the curves; :class:`ContourStop` per pair of partner contours),
:class:`SurfaceStop` for 3D point sets and surfaces (the two-way distance to the other's
surface less the target's roughness), :class:`PairStop` for the others (the mean distance
of the pulled pairs), a 3D point set along a curve given unordered among them: the
quadrics of a curve's neighbours lie flat in any plane through it, and would call a curve
beside it reached. Distances are in the model's normalised units.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..core.quality import Polyline
from ..core.shape import CURVE_DIMENSION, Shape, curve_dimension, even_subset, resample
from ..core.surfaces import closest_on_band, face_distances, face_tree
from ..options import MorphOptions

__all__ = ["COARSE_FLOOR", "COVER_NEIGHBOUR", "ContourStop", "CurveStop", "LAZY_SPACINGS",
           "Limits", "PLANE", "PairStop", "QUADRIC_RIDGE", "STALL", "STALL_GAIN",
           "SURFACE_BLOCK", "StopTest", "SurfaceStop", "choose_stop_test", "to_surface"]

STALL = 5  # steps over which a stalled distance means equilibrium (method.md §5)
STALL_GAIN = 1e-3  # the least relative gain of the pulled pairs' distance over STALL steps
PLANE = 12  # nearest points whose least-squares quadric is the surface (method.md §5)
# A target whose own roughness (floor) exceeds this many tolerances is too coarse for its
# surface to be measured alone: floors at the default tolerance 0.005, the bunny of 1839
# and 900 vertices 1.3 and 2.6, an ellipsoid (2, 1, 0.5) of 162 vertices 3.0, one of 42
# 14 and 61, tori of 72 and 128 points 57 and 29 (method.md §5).
COARSE_FLOOR = 5
SURFACE_BLOCK = 1 << 16  # points measured at once: about 100 MB of work arrays a block
QUADRIC_RIDGE = 1e-3  # the quadric's curvature damped by this, per point (method.md §5)
# A coarse shape's node reaches as far as its COVER_NEIGHBOUR-th nearest node (SurfaceStop's
# cover). 300 / 1000 / 2000 nodes, all on a sphere of 4000 points, 10 times as dense on
# one half as on the other: 0.68 / 0.34 / 0.09 tolerances (with cover alone 3.0-7.2);
# 30 times: 5.4 / 1.5 / 0.24 (the quadrics alone 3.1 / 0.31 / 0.01); 162 nodes crowded
# into the middle three quarters of an ellipsoid (2, 1, 0.5): 1.7 (cover alone 2.1).
COVER_NEIGHBOUR = 3
LAZY_SPACINGS = 4  # surfaces measured within the tolerance plus this many spacings (§5)


@dataclass(frozen=True)
class Limits:
    """When to stop, normalised units: ``tolerance`` (converged), ``at_rest`` (the
    largest step that moves nothing), ``stall`` (whether a stalled distance is
    equilibrium), ``max_steps``."""

    tolerance: float
    at_rest: float
    stall: bool
    max_steps: int

    @classmethod
    def from_options(cls, options: MorphOptions, target_size: float, size: float) -> Limits:
        """The options' limits for a target of RMS radius ``target_size`` measured in
        units of ``size`` (user units)."""
        o = options
        tol = (o.tol_distance / size) if o.tol_distance is not None \
            else o.tol * target_size / size
        return cls(tolerance=tol, at_rest=o.equilibrium_tol * target_size / size,
                   stall=o.equilibrium_tol > 0, max_steps=o.max_steps)

    def reason(self, distance: float, steps: int, moved: float,
               near: Sequence[float]) -> str | None:
        """Why to stop after ``steps`` steps, the last of which moved no node more than
        ``moved``: ``"tolerance"`` (``distance`` within it), ``"equilibrium"`` (no node
        moved visibly, or the pulled pairs' distances ``near``, one per step, gained less
        than ``STALL_GAIN`` over ``STALL`` steps) or ``"max_steps"``; None to go on."""
        if distance <= self.tolerance:
            return "tolerance"
        if steps == 0:
            return None
        if moved <= self.at_rest or (self.stall and steps > STALL
                                     and abs(near[-1 - STALL] - near[-1])
                                     <= STALL_GAIN * near[-1]):
            return "equilibrium"  # at rest, or the distance no longer decreases
        if steps >= self.max_steps:
            return "max_steps"
        return None


class StopTest:
    """The interface of the stop tests: :meth:`distance` and :meth:`reason`.

    ``lazy`` says whether ``distance(..., lazy=True)`` may give the lower bound ``near``
    instead of the full measure: the driver then measures in full at the end.
    """

    lazy = False

    def __init__(self, limits: Limits):
        self.limits = limits

    @property
    def tolerance(self) -> float:
        """The tolerance on :meth:`distance` (normalised units)."""
        return self.limits.tolerance

    @property
    def resolution(self) -> tuple[float, int, int, tuple | None]:
        """How close, at best, a shape of the source's node count follows the target:
        ``(floor, m, n, partners)``, for contours the mean distance (normalised units)
        from the target (``n`` nodes) to itself drawn through the source's ``m`` nodes
        spread evenly along it, for shapes of several contours the pair of partner
        contours ``(k, j)`` where that is largest; ``(0.0, 0, 0, None)`` where not
        measured."""
        return 0.0, 0, 0, None

    def distance(self, current: np.ndarray, near: float, lazy: bool = True) -> float:
        """The measure of :attr:`Run.distance` for the shape ``current`` (m, d), given
        ``near``, the mean distance of its pulled pairs (a lower bound of the measure)."""
        raise NotImplementedError

    def reason(self, distance: float, steps: int, moved: float,
               near: Sequence[float]) -> str | None:
        """:meth:`Limits.reason`."""
        return self.limits.reason(distance, steps, moved, near)


class PairStop(StopTest):
    """2D point sets, and 3D targets of at most ``PLANE`` points: the mean distance of the
    nodes pulled to partners."""

    def distance(self, current: np.ndarray, near: float, lazy: bool = True) -> float:
        return near


class CurveStop(StopTest):
    """Contours: the largest of ``near`` and the mean distances both ways between the
    shape's and the target's polylines, less, the second way, what a shape of the
    source's node count spread evenly along the target leaves (``floor``). With ``lazy``
    the curves are measured only once ``near`` is within the tolerance."""

    lazy = True

    def __init__(self, limits: Limits, target: np.ndarray, *, closed: bool,
                 target_closed: bool, m: int):
        super().__init__(limits)
        self.closed, self.m = closed, m
        self.target = target
        self.to_target = Polyline(target, target_closed)
        self.floor = float(Polyline(resample(target, m, closed=target_closed), target_closed)
                           .distance(target).mean())

    def distance(self, current: np.ndarray, near: float, lazy: bool = True) -> float:
        if lazy and near > self.limits.tolerance:
            return near
        d_ab = self.to_target.distance(current)
        d_ba = Polyline(current, self.closed).distance(self.target)
        return max(near, float(d_ab.mean()), float(d_ba.mean()) - self.floor)

    @property
    def resolution(self) -> tuple[float, int, int, tuple | None]:
        return self.floor, self.m, len(self.target), None


class ContourStop(StopTest):
    """Objects of several contours: the largest, over the pairs of partner contours, of
    :class:`CurveStop`'s measure of the source contour against its partner target contour
    alone (each with its own ``floor``, the source contour's node count spread along
    the target contour); contours without a partner are not measured. With ``lazy`` the
    curves are measured only once ``near`` is within the tolerance."""

    lazy = True

    def __init__(self, limits: Limits, target: np.ndarray, *, source: Shape,
                 target_shape: Shape, partners: np.ndarray):
        super().__init__(limits)
        self.partners = partners
        self.rows = [source.slices[k] for k in partners[:, 0]]
        self.tests = [CurveStop(limits, target[target_shape.slices[j]], closed=source.closed,
                                target_closed=target_shape.closed, m=source.sizes[k])
                      for k, j in partners]

    def distance(self, current: np.ndarray, near: float, lazy: bool = True) -> float:
        if lazy and near > self.limits.tolerance:
            return near
        return max(test.distance(current[rows], near, lazy=False)
                   for rows, test in zip(self.rows, self.tests, strict=True))

    @property
    def resolution(self) -> tuple[float, int, int, tuple | None]:
        i = int(np.argmax([test.floor if test.m < len(test.target) else -np.inf
                           for test in self.tests]))  # of the coarser sources
        floor, m, n, _ = self.tests[i].resolution
        return floor, m, n, tuple(int(k) for k in self.partners[i])


class SurfaceStop(StopTest):
    """3D point sets and surfaces: the larger of the mean distances both ways between the
    shape's nodes and the other's surface (:func:`to_surface`), less the target's own
    roughness ``floor`` (0 at least). A source of ``m`` nodes, fewer than the target's,
    cannot follow the target more closely than ``m`` points spread over it do: the
    target's distance to the shape's surface is measured less ``coarse``, what such a
    sample (:func:`even_subset`) leaves beyond ``floor``; and since a surface through
    its nodes passes over a part of the target they do not reach, the target's distance
    to the shape's nodes is measured too: the mean, over the target's points, of how
    much farther each lies from its nearest node than ``cover`` (the farthest any
    target point lies from that sample) or that node's distance to its
    ``COVER_NEIGHBOUR``-th nearest node, whichever is larger (a shape sampled sparsely
    there reaches as far), and the larger of that and the quadrics' measure counts (a
    sphere of 162 vertices onto an ellipsoid (2, 1, 0.5) of 642 by pairs that left its
    tips unreached was said converged: its quadrics bridged the tips; the true pairs
    leave no point beyond, method.md §5). A target so coarse that its
    ``floor`` exceeds ``COARSE_FLOOR`` tolerances hides any distance below it: the mean
    distance of the pulled pairs, ``near``, then counts too (``pairs``). Surfaces with
    faces are their triangles: the shape's distance to a target with ``faces`` is to
    them, exact, with no floor (the quadrics of a coarse target's vertices pass off its
    faces: a sphere of 642 vertices said converged on an ellipsoid of 162 lay 2
    tolerances off its faces, method.md §5), and for a target of fewer vertices than the
    source (``band``) to the band between its faces and the smooth surface through its
    vertices (:func:`~modalmorph.core.surfaces.closest_on_band`: that sphere mapped
    exactly onto the ellipsoid stands 1.6 tolerances off its faces); the target's
    vertices' to the shape, when the source has ``source_faces`` and is not coarser
    than the target, is to the shape's faces less ``floor`` (a smooth shape may round a
    coarse target's corners by as much as they stand off a smooth surface through their
    neighbours). With ``lazy``
    the surfaces are measured only once ``near`` is within ``gate``, the tolerance plus
    ``LAZY_SPACINGS`` target spacings."""

    lazy = True

    def __init__(self, limits: Limits, target: np.ndarray, *, m: int | None = None,
                 faces: np.ndarray | None = None, source_faces: np.ndarray | None = None):
        super().__init__(limits)
        self.target = target
        self.faces = faces
        self.tree = cKDTree(target)
        self.face_tree = None if faces is None else face_tree(target, faces)
        self.floor = float(to_surface(target, target, self.tree, skip=1).mean())
        spacing = self.tree.query(target, k=2)[0][:, 1].mean()
        self.gate = limits.tolerance + LAZY_SPACINGS * spacing
        self.coarse = self.cover = 0.0
        if m is not None and m < len(target):  # a source coarser than the target
            sample = target[even_subset(target, m)]
            tree = cKDTree(sample)
            self.cover = float(tree.query(target)[0].max())
            if m > PLANE:  # enough nodes for their quadrics
                left = float(to_surface(target, sample, tree).mean())
                self.coarse = max(left - self.floor, 0.0)
        # the source's own triangles where it is as fine as the target, or has too few
        # vertices for quadrics (a box of 8 onto a sphere: its faces are the shape)
        self.source_faces = source_faces if m is not None and (
            m >= len(target) or m <= PLANE) else None
        self.few = (0.0, m, len(target), None) if source_faces is not None and \
            m is not None and m <= PLANE < len(target) else None
        self.band = faces is not None and m is not None and m > len(target)
        quadrics = faces is None or self.source_faces is None  # whose floor hides
        self.pairs = quadrics and self.floor > COARSE_FLOOR * limits.tolerance

    @property
    def resolution(self) -> tuple[float, int, int, tuple | None]:
        """For a surface of at most ``PLANE`` vertices onto a finer target, its and the
        target's counts (no allowance: its triangles are the shape); else not
        measured."""
        return self.few or super().resolution

    def distance(self, current: np.ndarray, near: float, lazy: bool = True) -> float:
        if lazy and near > self.gate:
            return near
        Y = self.target
        if self.faces is None:
            d_ab = float(to_surface(current, Y, self.tree).mean()) - self.floor
        elif self.band:
            d_ab = float(np.linalg.norm(current - closest_on_band(
                current, Y, self.faces, self.face_tree), axis=1).mean())
        else:
            d_ab = float(face_distances(current, Y, self.faces, self.face_tree).mean())
        if self.source_faces is None:
            tree = cKDTree(current)
            d_ba = max(float(to_surface(Y, current, tree).mean()) - self.coarse,
                       self.floor) - self.floor if len(current) > PLANE else 0.0
            if self.cover:
                gap, node = tree.query(Y)
                reach = np.maximum(tree.query(current, k=COVER_NEIGHBOUR + 1)[0][:, -1],
                                   self.cover)  # a node's own spacing, where sparser
                d_ba = max(d_ba, float(np.maximum(gap - reach[node], 0.0).mean()))
        else:
            d_ba = float(face_distances(Y, current, self.source_faces).mean()) - self.floor
        surface = max(d_ab, d_ba, 0.0)
        return max(surface, near) if self.pairs else surface


def choose_stop_test(source: Shape, target: Shape, target_n: np.ndarray,
                     limits: Limits, partners: np.ndarray | None = None) -> StopTest:
    """The stop test for these objects (``target_n``: the target's nodes, normalised;
    ``partners``: the partner contours (P, 2) of objects of several contours)."""
    if partners is not None:
        return ContourStop(limits, target_n, source=source, target_shape=target,
                           partners=partners)
    if source.ordered and target.ordered:
        return CurveStop(limits, target_n, closed=source.closed,
                         target_closed=target.closed, m=source.m)
    if source.dim == 3 and target.m > PLANE and (
            target.faces is not None or curve_dimension(target_n) >= CURVE_DIMENSION):
        return SurfaceStop(limits, target_n, m=source.m, faces=target.faces,
                           source_faces=source.faces)
    return PairStop(limits)


def to_surface(points: np.ndarray, cloud: np.ndarray, tree: cKDTree,
               skip: int = 0) -> np.ndarray:
    """Distance of every point to the surface of a point cloud (normalised units): to the
    least-squares quadric height field over the principal plane of its ``PLANE`` nearest
    cloud points (the ``skip`` nearest left out, e.g. the point itself), evaluated within
    their extent (a point beyond it adds its distance to the patch's rim). Linear in
    memory; unlike the distance to the nearest cloud point, nearly zero for a point on a
    smooth surface between samples, and unlike a plane's, at any resolution: the planes
    of a coarse cloud cut the chords of a curved surface (method.md §5). In blocks of
    ``SURFACE_BLOCK`` points."""
    if len(points) > SURFACE_BLOCK:
        return np.concatenate([to_surface(points[b:b + SURFACE_BLOCK], cloud, tree, skip)
                               for b in range(0, len(points), SURFACE_BLOCK)])
    near = cloud[tree.query(points, k=PLANE + skip)[1][:, skip:]]  # (p, k, d)
    centre = near.mean(axis=1)
    spread = near - centre[:, None]
    axes = np.linalg.eigh(np.einsum("pki,pkj->pij", spread, spread))[1]  # normal first
    scale = np.sqrt(np.einsum("pki,pki->p", spread, spread) / PLANE)[:, None]
    local = np.einsum("pki,pij->pkj", spread, axes) / scale[:, :, None]  # (w, v, u)
    at = np.einsum("pi,pij->pj", points - centre, axes) / scale
    rim = np.sqrt(np.max(local[:, :, 1] ** 2 + local[:, :, 2] ** 2, axis=1))
    tangent = np.hypot(at[:, 1], at[:, 2])
    clip = np.minimum(1.0, rim / np.maximum(tangent, 1e-300))[:, None]
    u, v = local[:, :, 2], local[:, :, 1]
    basis = np.stack([np.ones_like(u), u, v, u * u, u * v, v * v], axis=-1)
    gram = np.einsum("pki,pkj->pij", basis, basis)
    gram[:, 3:, 3:] += QUADRIC_RIDGE * PLANE * np.eye(3)
    c = np.linalg.solve(gram, np.einsum("pki,pk->pi", basis, local[:, :, 0])[..., None])[..., 0]
    u0, v0 = at[:, 2] * clip[:, 0], at[:, 1] * clip[:, 0]
    height = (c[:, 0] + c[:, 1] * u0 + c[:, 2] * v0 + c[:, 3] * u0 * u0 + c[:, 4] * u0 * v0
              + c[:, 5] * v0 * v0)
    slope = np.hypot(c[:, 1] + 2 * c[:, 3] * u0 + c[:, 4] * v0,
                     c[:, 2] + c[:, 4] * u0 + 2 * c[:, 5] * v0)
    normal = np.abs(at[:, 0] - height) / np.sqrt(1 + slope**2)
    return np.hypot(normal, tangent * (1 - clip[:, 0])) * scale[:, 0]
