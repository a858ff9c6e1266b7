"""The options of the method: matching, the physical model and the dynamics, reading
files, the outputs and sequences."""

from __future__ import annotations

from dataclasses import dataclass

from ..core.dynamics import UNMATCHED_RULES, check_newmark
from ..core.material import MATERIALS, POLYETHYLENE, Material
from ..core.solvers import SOLVERS
from ..errors import OptionError
from .base import (
    C_MAX,
    CORRESPONDENCES,
    DT_RANGE,
    FRAME_SPACINGS,
    FREE_MOTIONS,
    K_RANGE,
    LOADS,
    METHODS,
    OBJECTS,
    REFERENCES,
    ROTATIONS,
    SCHEMES,
    STEP_MESHES,
    Options,
    check_damping,
    check_modes,
    check_range,
    check_sigma,
    is_int,
    is_number,
    option,
    parse_value,
)

__all__ = ['MatchOptions', 'MorphOptions', 'ReadOptions', 'OutputOptions', 'TrackOptions']


@dataclass(frozen=True)
class MatchOptions(Options):
    """How :func:`modalmorph.match` finds the correspondences (method.md §2)."""

    method: str = option(
        "auto", "auto: the most accurate, order-preserving for contours; local: the "
        "paper's mutual best (8); global: an assignment over all nodes with implausible "
        "pairs rejected", group="matching", kind="str", choices=METHODS)
    rotation: str = option(
        "auto", "auto: keep the common frame of the two inputs unless another pose fits "
        "clearly better, or better at all with a turn of more than 25 degrees (a turn "
        "of 10-25 degrees between two different shapes is partly taken for deformation: "
        "pass free); none: the "
        "inputs share one frame (frames of a sequence, ED/ES of one slice), never turn; "
        "free: any pose, by cost alone", group="matching", kind="str", choices=ROTATIONS)
    modes: int | None = option(
        None, "lowest modes describing each node (default 24)", group="matching",
        kind="int")
    sigma: float | None = option(
        None, "Gaussian width of the matching models, x mean node spacing (default: 2, "
        "or less where a model's Gram matrix would be ill-conditioned)", group="matching",
        kind="float")
    reject: float | None = option(
        None, "drop pairs costing more than this: global, a multiple of the median pair "
        "cost (default 3); auto, the squared distance after alignment in squared target "
        "node spacings (default 16)", group="matching", kind="float")

    def _check(self):
        if self.modes is not None and not (is_int(self.modes) and self.modes >= 1):
            raise OptionError(f"modes must be a positive integer, got {self.modes!r}")
        check_sigma(self.sigma)
        if self.reject is not None and not (is_number(self.reject) and self.reject > 0):
            raise OptionError(f"reject must be a number > 0, got {self.reject!r}")


@dataclass(frozen=True)
class MorphOptions(Options):
    """The physical model, the loads, the time integration and the stop test of
    :func:`modalmorph.morph`; each field's ``help`` says what it does, and the docstring
    of :mod:`modalmorph.pipeline` (and docs/method.md §4, §5) why the defaults are what
    they are, with the measurements."""

    remove_rigid: bool = option(
        False, "remove rotation, translation and scale first (Horn): morph only the "
        "non-rigid part, in fewer steps", group="alignment", kind="bool")
    # physics
    material: Material = option(
        POLYETHYLENE, "material filling the objects: polyethylene (the paper's), rubber, "
        "unit, or three numbers 'E nu rho'", group="physics", kind="material",
        choices=None)
    sigma: float | None = option(
        None, "how far nodes interact in the physical model: Gaussian width, x mean node "
        "spacing (default: 1, or less where the Gram matrix would be ill-conditioned)",
        group="physics", kind="float")
    modes: int | float | None = option(
        None, "modes superposed: all (default; the lowest 100 for large objects), a count "
        "(40) or a fraction (2/3); fewer are cheaper and less exact", group="physics",
        kind="modes")
    solver: str = option(
        "auto", "eigensolver: auto (dense for small objects, truncated sparse or "
        "multilevel for large ones), dense, sparse or multilevel", group="physics",
        kind="str", choices=SOLVERS)
    model_nodes: int = option(
        400, "largest physical model: a source with more nodes is modelled on this many, "
        "spread evenly, and every node moves with the element's field", group="physics",
        kind="int")
    free_motion: str = option(
        "similarity", "similarity: changes of position, orientation and size cost no "
        "strain energy, so any size ratio is reached; none: the paper's U^T K U (22) for "
        "every motion", group="physics", kind="str", choices=FREE_MOTIONS)
    damping: float | tuple[float, float] = option(
        1.0, "one ratio (default 1): stiffness-proportional damping, every mode creeps to "
        "the target at nearly one rate (no ripples or folds); or two: Rayleigh ratios at "
        "the lowest and highest frequency (the paper's 0.005 0.03 oscillates)",
        group="physics", kind="damping")
    # loads and time integration
    loads: str = option(
        "consistent", "consistent: the springs pull every bit of the object in proportion "
        "to its mass, so all modes move together; nodal: the paper's force k (X2 - X) on "
        "every node (19)", group="loads and time integration", kind="str", choices=LOADS)
    k: float = option(
        100.0, "spring stiffness pulling nodes to their targets (19), x one node's own "
        "stiffness: larger pulls harder, needs fewer steps and fits closer",
        group="loads and time integration", kind="float")
    scheme: str = option(
        "implicit", "implicit: loads at the new shape, always stable; explicit: the "
        "paper's, loads at the previous shape, diverges for large k",
        group="loads and time integration", kind="str", choices=SCHEMES)
    dt: float = option(
        0.1, "time step, x 1/omega_ref (one node's natural period / 2 pi): larger moves "
        "further per step", group="loads and time integration", kind="float")
    alpha: float = option(
        0.25, "Newmark alpha (14); need 2 alpha >= delta >= 0.5",
        group="loads and time integration", kind="float")
    delta: float = option(
        0.5, "Newmark delta (14): 0.5 has no numerical damping, > 0.5 damps",
        group="loads and time integration", kind="float")
    c_x: float = option(
        0.0, "initial displacement as a fraction of the way to the target (17), (21)",
        group="loads and time integration", kind="float", flag="--cx")
    c_v: float = option(
        0.0, "initial velocity as a multiple of the initial displacement (18)",
        group="loads and time integration", kind="float", flag="--cv")
    unmatched: str = option(
        "arclength", "contours: where unmatched nodes are pulled, between the partners of "
        "their matched neighbours; arclength: spread evenly along the target; mean: the "
        "paper's weighted mean (20), which folds long unmatched runs",
        group="loads and time integration", kind="str", choices=UNMATCHED_RULES)
    neighbours: int = option(
        6, "3D point sets: matched neighbours that pull an unmatched node",
        group="loads and time integration", kind="int")
    # stopping
    tol: float = option(
        0.005, "converged when the shape is this close to the target both ways, as a "
        "fraction of the target's RMS radius", group="stopping", kind="float")
    tol_distance: float | None = option(
        None, "the same tolerance in the input's units (overrides tol)", group="stopping",
        kind="float")
    max_steps: int = option(100, "maximum number of time steps", group="stopping", kind="int")
    equilibrium_tol: float = option(
        1e-5, "stop at equilibrium when no node moves more than this fraction of the "
        "target's size in a step, or the distance gained < 0.1 % over 5 steps; 0 disables",
        group="stopping", kind="float")

    def __post_init__(self):
        if isinstance(self.material, str | list | tuple):
            object.__setattr__(self, "material", parse_value("material", "material",
                                                             self.material))
        if isinstance(self.damping, list | tuple):
            object.__setattr__(self, "damping", tuple(float(x) for x in self.damping))
        super().__post_init__()

    def _check(self):
        if not isinstance(self.remove_rigid, bool):
            raise OptionError(f"remove_rigid must be true or false, got {self.remove_rigid!r}")
        if not isinstance(self.material, Material):
            raise OptionError(f"material must be a Material or one of "
                              f"{', '.join(MATERIALS)}, got {self.material!r}")
        check_sigma(self.sigma)
        check_modes(self.modes)
        check_range("k", self.k, *K_RANGE, "x one node's stiffness")
        check_range("dt", self.dt, *DT_RANGE, "x 1/omega_ref")
        for name in ("c_x", "c_v"):
            check_range(name, getattr(self, name), 0.0, C_MAX, "fraction of the way")
        try:
            check_newmark(self.alpha, self.delta)
        except ValueError as exc:
            raise OptionError(str(exc)) from None
        check_damping(self.damping)
        if not (is_number(self.tol) and self.tol > 0):
            raise OptionError(f"tol must be a number > 0, got {self.tol!r}")
        if self.tol_distance is not None and not (
                is_number(self.tol_distance) and self.tol_distance > 0):
            raise OptionError(f"tol_distance must be a number > 0, got {self.tol_distance!r}")
        if not (is_number(self.equilibrium_tol) and self.equilibrium_tol >= 0):
            raise OptionError(f"equilibrium_tol must be a number >= 0, got "
                              f"{self.equilibrium_tol!r}")
        for name, low in (("max_steps", 1), ("neighbours", 1), ("model_nodes", 3)):
            value = getattr(self, name)
            if not (is_int(value) and value >= low):
                raise OptionError(f"{name} must be an integer >= {low}, got {value!r}")


@dataclass(frozen=True)
class ReadOptions(Options):
    """How shape files become shapes (:func:`modalmorph.io.read_shape`)."""

    nodes: int | None = option(
        None, "resample 2D contours to this many nodes (default: as in the file; 200 for "
        "images and SVG)", group="input", kind="int")
    threshold: float | None = option(
        None, "grey images: level separating object from background; needed for grey "
        "images (two-level masks need none), whose refusal proposes Otsu's",
        group="input", kind="float")
    object: str | int = option(
        "largest", "images and SVG: which object (outline) to take: largest, center (the "
        "one nearest the image's or page's centre), all (every one, its contours one after "
        "another) or a number (1 = the first in reading order; in SVG, drawn)",
        group="input", kind="object", choices=OBJECTS)
    label: int | None = option(
        None, "label images (segmentations, NIfTI): the value of the object's pixels",
        group="input", kind="int")

    open_curves: bool = option(
        False, "the contours of point files (CSV, TSV, TXT, NPY; JSON and NPZ without "
        "'closed') are open curves (a centreline, a pen stroke), not closed outlines (the "
        "default); images, SVG and files that say are read as they say", group="input",
        kind="bool")
    flip_y: bool = option(
        False, "mirror the y of 2D point files (CSV, TSV, TXT, NPY, NPZ, JSON: y up) into "
        "image coordinates (y down, as images and SVG), for inputs mixing the two; the "
        "results are in the mirrored coordinates", group="input", kind="bool")

    def _check(self):
        if self.nodes is not None and not (is_int(self.nodes) and self.nodes >= 3):
            raise OptionError(f"nodes must be an integer >= 3, got {self.nodes!r}")
        if self.threshold is not None and not is_number(self.threshold):
            raise OptionError(f"threshold must be a number, got {self.threshold!r}")
        if self.label is not None and not is_int(self.label):
            raise OptionError(f"label must be an integer, got {self.label!r}")


@dataclass(frozen=True)
class OutputOptions(Options):
    """What the command line writes besides the results (``result.json``, the shapes)."""

    figures: bool = option(True, "the PNG figures", group="outputs", kind="bool")
    svg: bool = option(False, "the figures also as SVG (vector graphics; costs as much again "
                     "as the PNGs)", group="outputs", kind="bool")
    gif: bool = option(True, "the animation as a GIF", group="outputs", kind="bool")
    mp4: bool = option(False, "also the animation as an MP4 (needs ffmpeg)", group="outputs",
                     kind="bool")
    vtk: bool = option(False, "also a VTK time series (.vtu + .pvd) for ParaView",
                     group="outputs", kind="bool")
    gltf: bool = option(False, "also morph.glb: one animated glTF 2.0 file (a morph target per "
                      "step) for Blender, three.js and other 3D viewers", group="outputs",
                      kind="bool")
    meshes: str = option("none", "also the shape at every step as a mesh file in meshes/: "
                       "ply, obj or none", group="outputs", kind="str", choices=STEP_MESHES)
    html: bool = option(False, "also report.html: the interactive viewer in one "
                      "self-contained file", group="outputs", kind="bool")
    background: bool = option(True, "draw shapes read from an image over that image",
                            group="outputs", kind="bool")
    frames: str = option(
        "time", "frames of the animation and the figures: time (every time step) or path "
        "(evenly spaced along the path, as the damped motion bunches steps near the "
        "target)", group="outputs", kind="str", choices=FRAME_SPACINGS)


@dataclass(frozen=True)
class TrackOptions(Options):
    """How :func:`modalmorph.track` follows a sequence."""

    reference: str = option(
        "first", "first: morph frame 0 straight onto every frame (its model built once), "
        "a frame whose morph fails (not converged, crossed, off the contour) from the "
        "tracked previous frame; previous: morph each tracked frame onto the next",
        group="sequence", kind="str", choices=REFERENCES)
    correspondence: str = option(
        "nearest", "nearest: in the frames' common frame each observed node pulls at most "
        "one node, the nearest of those whose nearest it is (both centred and scaled: "
        "turns under the node spacing); normal: each node to where the normal of its contour "
        "meets the observed contour (2D contours; no sliding along the wall); modal: "
        "modal matching (large motions, objects that turn)",
        group="sequence", kind="str", choices=CORRESPONDENCES)
    cycle: bool = option(
        False, "periodic sequence (a cardiac cycle): also morph the last frame back onto "
        "the first and report the closure error", group="sequence", kind="bool")
    segments: int = option(
        6, "segments of equal arc length for the strain table (6: those of a left-"
        "ventricle short-axis slice)", group="sequence", kind="int")
    start_node: int = option(
        0, "node of the first frame where segment 1 starts", group="sequence", kind="int")

    def _check(self):
        if not isinstance(self.cycle, bool):
            raise OptionError(f"cycle must be true or false, got {self.cycle!r}")
        for name, low in (("segments", 1), ("start_node", 0)):
            value = getattr(self, name)
            if not (is_int(value) and value >= low):
                raise OptionError(f"{name} must be an integer >= {low}, got {value!r}")

