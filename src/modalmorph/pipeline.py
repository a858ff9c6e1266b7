"""``morph()``: the whole method, end to end, returning one result object.

The source is modelled with Sclaroff's Gaussian element, matched nodes are pulled to their
partners by springs of stiffness ``k`` (19), unmatched nodes by the neighbourhood rule
(20), and Lagrange's dynamic equilibrium ``M U'' + C U' + K U = R`` (9) is integrated in
time by mode superposition (11)-(13) and Newmark's method (14)-(15)
(:class:`modalmorph.simulation.Simulation`).

The options (:class:`modalmorph.options.MorphOptions`) and why their defaults are what
they are:

free_motion
    ``"similarity"`` (default): a change of position, orientation or size of the whole
    object costs no strain energy (the energy of a displacement is that of its non-similar
    part, ``min_a (U - S a)^T K (U - S a)`` over the similarity fields ``S``; exact for 2D,
    small rotations in 3D): the springs then reach a target of any size or pose, and the
    energy measures the change of shape alone. The Gaussian element's own rigid modes are
    only nearly free (method.md §1). ``"none"``: the paper's ``U^T K U`` (22) for every
    motion, so a size change is resisted like any strain (a heart morphed onto itself
    scaled 1000x then stops far from it).
loads
    ``"nodal"``: the paper's, a force ``k (X_2 - X)`` on every node; with the element's
    consistent mass the modes then feel different springs, so some race ahead of others (a
    heart shrunk 1000x passed through shapes 12x rougher than either end, and folded).
    ``"consistent"`` (default): every bit of the object is pulled towards where the targets
    say, in proportion to its mass: in modal coordinates ``kappa (x_T - x)``, ``x_T`` the
    mass projection of the targets' displacement onto the modes and ``kappa`` the springs'
    mean modal stiffness, the same for every mode. A pure change of size or pose then
    morphs along that similarity, and no mode lags behind. A reduced model (a source of
    more than ``model_nodes`` nodes) is loaded node by node through its field either way.
k, dt
    ``k``: stiffness of the springs (19), in units of the elastic stiffness of one node of
    the model; larger pulls harder (fewer steps, a closer fit; with
    ``scheme="explicit"`` too large a ``k`` diverges). ``dt``: time step in units of
    ``1/omega_ref`` (``omega_ref`` the natural frequency of one node on its own stiffness).
alpha, delta
    Newmark's parameters (14). ``delta=0.5`` has no numerical damping; ``delta > 0.5``
    damps (first-order accurate), best with ``alpha=(delta+0.5)**2/4`` (16).
damping
    Rayleigh damping ``C = a M + b K`` (5) of the loaded model (elastic stiffness plus
    springs). A pair: the damping ratios at its lowest and highest frequencies; the paper
    used 0.005-0.03, which leaves the shape oscillating about the target for many steps. A
    number (default 1): the ratio at the springs' frequency, growing in proportion to the
    frequency above it (stiffness-proportional), so that every mode creeps to the target
    at nearly the same rate and the shape moves along nearly straight paths. Measured on
    the shared hearts: with the former default (2, 2) the stiff modes raced ahead of the
    soft ones, and intermediate shapes were up to 1.9x rougher than either end and folded
    on 8 of 16 pairs (and on a heart shrunk 1000x); with 1, none.
c_x, c_v
    Initial displacement as a fraction of the load (17), (21) and initial velocity ``c_v``
    times it (18). Larger values start faster.
sigma, modes, solver
    Gaussian width of the physical model in units of its mean node spacing (``None``: 1,
    or less where the Gram matrix would be ill-conditioned; the matcher's models have
    their own width, ``match_sigma``). Modes superposed: all (``None``; with the sparse
    solver the lowest 100), a count, or a fraction of all (the paper compares all with
    2/3). ``solver="auto"`` uses the exact dense eigensolver for small objects and the
    truncated sparse one for large objects.
model_nodes
    A source with more nodes is modelled on this many nodes spread evenly over it (by arc
    length for contours), and every node moves with the element's displacement field
    ``u(x) = sum_k h_k(x) U_k`` (3)-(4); its load enters through the same field, and the
    local energy is spread from the model nodes over the nodes around them. The default,
    400, was measured: with 300, 4 of the 186 glyph outlines at 400 nodes folded for 1-4
    steps beside a serif (the interpolated field lets neighbouring nodes overtake where the
    displacement turns sharply); with 400, none, at twice the cost of a 1000-node morph
    (0.16 -> 0.28 s, still 22x the dense transcription).
scheme
    ``"implicit"``: loads at the new shape (the spring enters the effective stiffness;
    unconditionally stable). ``"explicit"``: at the previous shape, as in the paper
    (stable only for small ``k``).
tol, tol_distance, max_steps, equilibrium_tol
    Converged when :attr:`Morph.distance` falls below ``tol`` times the target's RMS
    radius (``tol_distance``: in the user's units): for contours, when the shape is that
    close to the whole target curve both ways. At equilibrium when no node moves by more
    than ``equilibrium_tol`` times the target's size in a step, or the distance changed by
    less than 0.1 % over 5 steps (0 disables both).
unmatched, neighbours
    Where an unmatched node of a contour is pulled, between the partners of its matched
    neighbours. ``"arclength"`` (default): to the point of the target stretch between
    those partners at the node's fraction of the source stretch's arc length, so a run of
    unmatched nodes spreads evenly over it. ``"mean"``: the paper's rule (20), a weighted
    mean of the target nodes of that stretch; it pulls every node of a long run to nearly
    one point, which folds the contour (measured: the 28 pairs of bundled hands at full
    resolution cross themselves). 3D point sets use the (20)-weighted displacements of
    their ``neighbours`` nearest matched nodes (:class:`modalmorph.core.dynamics.LoadTargets`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from .core.align import Similarity, align
from .core.shape import Shape, as_shape
from .errors import MorphDivergedError, OptionError, ShapeError
from .matching import Matching, match
from .options import MatchOptions, MorphOptions, split_overrides
from .simulation import SPARSE_MODES, Run, Simulation

__all__ = ["Morph", "MorphDivergedError", "morph", "SPARSE_MODES"]



@dataclass(frozen=True, eq=False, repr=False)
class Morph(Run):
    """The intermediate shapes between two objects, their strain energy, and how they were
    found: every attribute of :class:`~modalmorph.simulation.Run` (``shapes``, ``loads``,
    ``energy``, ``node_energy``, ``mean_distance``, ``distance``, ``tolerance``,
    ``stop_reason``, ``message``, ``resolved``, ``converged``, ``steps``) and:

    Attributes
    ----------
    matching : Matching
        The correspondences used (given pairs are a Matching of method ``"given"``).
    similarity : Similarity or None
        The similarity removed before morphing (``remove_rigid``), else None.
    source, target : Shape
        The objects as given (the source before any rigid alignment).
    options : MorphOptions
        The options of the physical model and the time integration.
    match_options : MatchOptions or None
        The matcher's options (None for given pairs).
    """

    matching: Matching
    similarity: Similarity | None
    source: Shape
    target: Shape
    options: MorphOptions
    match_options: MatchOptions | None = None


def morph(source, target, *, matching=None, options: MorphOptions | None = None,
          progress: Callable[[int, float], None] | None = None, **overrides) -> Morph:
    """Estimate the intermediate shapes that take ``source`` into ``target``.

    Parameters
    ----------
    source, target : Shape or array_like, shape (m, d) and (n, d)
        The objects at times t and t+1, both 2D or both 3D.
    matching : Matching, array_like of int (K, 2), MatchOptions or None, optional
        Correspondences: a Matching of these two objects, given ``(source index, target
        index)`` pairs (recorded as a Matching of method ``"given"``), or the options to
        compute them with :func:`modalmorph.match` (None: its defaults).
    options : MorphOptions, optional
        The rigid alignment first (``remove_rigid``: Horn's similarity from the matched
        pairs, section 5.2; the morph then holds only the non-rigid part), the physical
        model, loads, time integration and stop test (the module's docstring says why the
        defaults are what they are).
    progress : callable, optional
        Called after every step as ``progress(step, mean_distance)`` (user units).
    **overrides
        :class:`MorphOptions` fields (``k=60``, ``max_steps=20``, ...) replacing those of
        ``options``; and the matcher's options MorphOptions does not have (``rotation``,
        ``method``, ``reject``, ``match_sigma``, ``match_modes``), used when the matching
        is computed here (ignored for a given Matching or pairs).

    Returns
    -------
    Morph

    Raises
    ------
    OptionError
        For an unknown or invalid option (a ValueError).
    ShapeError
        For invalid objects, pairs that do not belong to them, or no matched node (a
        ValueError).
    MorphDivergedError
        When the integration diverges (typically the explicit scheme with too large a k).
    """
    src = as_shape(source, "source")
    tgt = as_shape(target, "target")
    if src.dim != tgt.dim:
        raise ShapeError(f"source and target must have the same dimension, got "
                         f"{src.dim}D and {tgt.dim}D")
    options, match_options = _options(options, matching, overrides)
    if matching is None or isinstance(matching, MatchOptions):
        matching = match(src, tgt, options=match_options)
    elif isinstance(matching, Matching):
        matching, match_options = matching.check(src.m, tgt.m), matching.options
    else:
        matching, match_options = Matching.given(matching, src.m, tgt.m), None
    pairs = matching.pairs
    similarity, work = None, src
    if options.remove_rigid:  # section 5.2: Horn's similarity from the matched pairs
        similarity = align(src.points[pairs[:, 0]], tgt.points[pairs[:, 1]], scale=True)
        work = src.with_points(similarity.apply(src.points))
    run = Simulation(work, tgt, pairs, options).run(progress).result()
    return Morph(**vars(run), matching=matching, similarity=similarity, source=src,
                 target=tgt, options=options, match_options=match_options)


def _options(options, matching, overrides: dict) -> tuple[MorphOptions, MatchOptions]:
    """The MorphOptions and MatchOptions of a call: ``overrides`` split by name."""
    if options is None:
        options = MorphOptions()
    elif not isinstance(options, MorphOptions):
        raise OptionError(f"options must be a MorphOptions, got {type(options).__name__}")
    morph_kw, match_kw = split_overrides(overrides, where="morph")
    base = matching if isinstance(matching, MatchOptions) else MatchOptions()
    return options.replace(**morph_kw), base.replace(**match_kw)
