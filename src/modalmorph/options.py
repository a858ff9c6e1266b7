"""Options as data: the one schema of the library, the recorded parameters, the TOML
config, the command-line flags and the web form.

Every option is a field of a frozen dataclass that validates itself on construction:

- :class:`MatchOptions`: how :func:`modalmorph.match` finds correspondences;
- :class:`MorphOptions`: the physical model, the loads, the time integration and the stop
  test of :func:`modalmorph.morph`;
- :class:`ReadOptions`: how shape files become shapes (:func:`modalmorph.io.read_shape`);
- :class:`OutputOptions`: what the command line writes besides the results.

A field's ``metadata`` holds what the command line and the form need: ``help`` (one or
two sentences), ``group`` and, where the values are a closed set, ``choices``. Its type
is ``kind`` (see :func:`parse_value`). Add an option by adding a field: the flag, the
config key, the form entry and the record in ``result.json`` follow.

Flat names: one namespace (the config file, the flags, the form) holds the fields of
every class; a :class:`MatchOptions` field whose name a :class:`MorphOptions` field also
has is prefixed ``match_`` there (``match_sigma``, ``match_modes``). See
:func:`flat_fields` and :func:`split`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields, replace
from numbers import Integral, Real

from .core.dynamics import UNMATCHED_RULES, check_newmark
from .core.element import MAX_SIGMA, MIN_SIGMA
from .core.material import MATERIALS, POLYETHYLENE, Material
from .core.solvers import SOLVERS
from .errors import OptionError

__all__ = [
    "MatchOptions", "MorphOptions", "ReadOptions", "OutputOptions", "TrackOptions",
    "StrainOptions",
    "StanceOptions",
    "OPTION_CLASSES", "REFERENCES", "CORRESPONDENCES", "flat_fields", "parameters", "split",
    "split_overrides", "parse_value", "METHODS", "ROTATIONS", "FREE_MOTIONS", "LOADS",
    "SCHEMES", "OBJECTS", "FRAME_SPACINGS", "STEP_MESHES", "K_RANGE", "DT_RANGE", "C_MAX",
]

METHODS = ("auto", "local", "global")
ROTATIONS = ("auto", "free", "none")
FREE_MOTIONS = ("similarity", "none")
LOADS = ("consistent", "nodal")
SCHEMES = ("implicit", "explicit")
OBJECTS = ("largest", "center", "all")  # or a number of the image's objects
FRAME_SPACINGS = ("time", "path")
STEP_MESHES = ("none", "ply", "obj")  # OutputOptions.meshes
REFERENCES = ("previous", "first")
CORRESPONDENCES = ("nearest", "modal")
# Ranges beyond which the integration is meaningless or overflows (fuzz suite; method.md §4).
K_RANGE = (1e-6, 1e6)
DT_RANGE = (1e-6, 1e6)
C_MAX = 10.0


def _opt(default, help: str, *, group: str, kind: str, choices=None, flag: str | None = None):
    """A field with the metadata of the command line and the form."""
    return field(default=default, metadata=dict(help=help, group=group, kind=kind,
                                                choices=choices, flag=flag))


class _Options:
    """Shared behaviour: validation on construction, ``replace``, the record."""

    def __post_init__(self):
        for f in fields(self):
            value = getattr(self, f.name)
            choices = f.metadata.get("choices")
            if choices and value not in choices and not (
                    f.metadata["kind"] == "object" and _is_label(value)):
                label = " or a label number >= 1" if f.metadata["kind"] == "object" else ""
                raise OptionError(f"{f.name} must be one of {', '.join(map(str, choices))}"
                                  f"{label}, got {value!r}")
        self._check()

    def _check(self):
        pass

    def replace(self, **changes):
        """A copy with some options changed (validated); unknown names are refused."""
        known = {f.name for f in fields(self)}
        unknown = sorted(set(changes) - known)
        if unknown:
            raise OptionError(f"unknown {type(self).__name__} option {unknown[0]!r}; "
                              f"known: {', '.join(sorted(known))}")
        return replace(self, **changes)

    def record(self) -> dict:
        """Every option as plain JSON values (the material as its four properties)."""
        out = asdict(self)
        for name, value in out.items():
            if isinstance(value, tuple):
                out[name] = list(value)
        if isinstance(getattr(self, "material", None), Material):
            mat = self.material
            out["material"] = dict(name=mat.name, E=mat.E, nu=mat.nu, rho=mat.rho)
        return out


@dataclass(frozen=True)
class MatchOptions(_Options):
    """How :func:`modalmorph.match` finds the correspondences (method.md §2)."""

    method: str = _opt(
        "auto", "auto: the most accurate, order-preserving for contours; local: the "
        "paper's mutual best (8); global: an assignment over all nodes with implausible "
        "pairs rejected", group="matching", kind="str", choices=METHODS)
    rotation: str = _opt(
        "auto", "auto: keep the common frame of the two inputs unless another pose fits "
        "clearly better (shapes turned by more than ~20 degrees are found); none: the "
        "inputs share one frame (frames of a sequence, ED/ES of one slice), never turn; "
        "free: any pose, by cost alone", group="matching", kind="str", choices=ROTATIONS)
    modes: int | None = _opt(
        None, "lowest modes describing each node (default 24)", group="matching",
        kind="int")
    sigma: float | None = _opt(
        None, "Gaussian width of the matching models, x mean node spacing (default: 2, "
        "or less where a model's Gram matrix would be ill-conditioned)", group="matching",
        kind="float")
    reject: float | None = _opt(
        None, "drop pairs costing more than this: global, a multiple of the median pair "
        "cost (default 3); auto, the squared distance after alignment in squared target "
        "node spacings (default 16)", group="matching", kind="float")

    def _check(self):
        if self.modes is not None and not (_is_int(self.modes) and self.modes >= 1):
            raise OptionError(f"modes must be a positive integer, got {self.modes!r}")
        _check_sigma(self.sigma)
        if self.reject is not None and not (_is_number(self.reject) and self.reject > 0):
            raise OptionError(f"reject must be a number > 0, got {self.reject!r}")


@dataclass(frozen=True)
class MorphOptions(_Options):
    """The physical model, the loads, the time integration and the stop test of
    :func:`modalmorph.morph`; each field's ``help`` says what it does, and the docstring
    of :mod:`modalmorph.pipeline` (and docs/method.md §4, §5) why the defaults are what
    they are, with the measurements."""

    remove_rigid: bool = _opt(
        False, "remove rotation, translation and scale first (Horn): morph only the "
        "non-rigid part, in fewer steps", group="alignment", kind="bool")
    # physics
    material: Material = _opt(
        POLYETHYLENE, "material filling the objects: polyethylene (the paper's), rubber, "
        "unit, or three numbers 'E nu rho'", group="physics", kind="material",
        choices=None)
    sigma: float | None = _opt(
        None, "how far nodes interact in the physical model: Gaussian width, x mean node "
        "spacing (default: 1, or less where the Gram matrix would be ill-conditioned)",
        group="physics", kind="float")
    modes: int | float | None = _opt(
        None, "modes superposed: all (default; the lowest 100 for large objects), a count "
        "(40) or a fraction (2/3); fewer are cheaper and less exact", group="physics",
        kind="modes")
    solver: str = _opt(
        "auto", "eigensolver: auto (dense for small objects, truncated sparse or "
        "multilevel for large ones), dense, sparse or multilevel", group="physics",
        kind="str", choices=SOLVERS)
    model_nodes: int = _opt(
        400, "largest physical model: a source with more nodes is modelled on this many, "
        "spread evenly, and every node moves with the element's field", group="physics",
        kind="int")
    free_motion: str = _opt(
        "similarity", "similarity: changes of position, orientation and size cost no "
        "strain energy, so any size ratio is reached; none: the paper's U^T K U (22) for "
        "every motion", group="physics", kind="str", choices=FREE_MOTIONS)
    damping: float | tuple[float, float] = _opt(
        1.0, "one ratio (default 1): stiffness-proportional damping, every mode creeps to "
        "the target at nearly one rate (no ripples or folds); or two: Rayleigh ratios at "
        "the lowest and highest frequency (the paper's 0.005 0.03 oscillates)",
        group="physics", kind="damping")
    # loads and time integration
    loads: str = _opt(
        "consistent", "consistent: the springs pull every bit of the object in proportion "
        "to its mass, so all modes move together; nodal: the paper's force k (X2 - X) on "
        "every node (19)", group="loads and time integration", kind="str", choices=LOADS)
    k: float = _opt(
        100.0, "spring stiffness pulling nodes to their targets (19), x one node's own "
        "stiffness: larger pulls harder, needs fewer steps and fits closer",
        group="loads and time integration", kind="float")
    scheme: str = _opt(
        "implicit", "implicit: loads at the new shape, always stable; explicit: the "
        "paper's, loads at the previous shape, diverges for large k",
        group="loads and time integration", kind="str", choices=SCHEMES)
    dt: float = _opt(
        0.1, "time step, x 1/omega_ref (one node's natural period / 2 pi): larger moves "
        "further per step", group="loads and time integration", kind="float")
    alpha: float = _opt(
        0.25, "Newmark alpha (14); need 2 alpha >= delta >= 0.5",
        group="loads and time integration", kind="float")
    delta: float = _opt(
        0.5, "Newmark delta (14): 0.5 has no numerical damping, > 0.5 damps",
        group="loads and time integration", kind="float")
    c_x: float = _opt(
        0.0, "initial displacement as a fraction of the way to the target (17), (21)",
        group="loads and time integration", kind="float", flag="--cx")
    c_v: float = _opt(
        0.0, "initial velocity as a multiple of the initial displacement (18)",
        group="loads and time integration", kind="float", flag="--cv")
    unmatched: str = _opt(
        "arclength", "contours: where unmatched nodes are pulled, between the partners of "
        "their matched neighbours; arclength: spread evenly along the target; mean: the "
        "paper's weighted mean (20), which folds long unmatched runs",
        group="loads and time integration", kind="str", choices=UNMATCHED_RULES)
    neighbours: int = _opt(
        6, "3D point sets: matched neighbours that pull an unmatched node",
        group="loads and time integration", kind="int")
    # stopping
    tol: float = _opt(
        0.005, "converged when the shape is this close to the target both ways, as a "
        "fraction of the target's RMS radius", group="stopping", kind="float")
    tol_distance: float | None = _opt(
        None, "the same tolerance in the input's units (overrides tol)", group="stopping",
        kind="float")
    max_steps: int = _opt(100, "maximum number of time steps", group="stopping", kind="int")
    equilibrium_tol: float = _opt(
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
        _check_sigma(self.sigma)
        _check_modes(self.modes)
        _check_range("k", self.k, *K_RANGE, "x one node's stiffness")
        _check_range("dt", self.dt, *DT_RANGE, "x 1/omega_ref")
        for name in ("c_x", "c_v"):
            _check_range(name, getattr(self, name), 0.0, C_MAX, "fraction of the way")
        try:
            check_newmark(self.alpha, self.delta)
        except ValueError as exc:
            raise OptionError(str(exc)) from None
        _check_damping(self.damping)
        if not (_is_number(self.tol) and self.tol > 0):
            raise OptionError(f"tol must be a number > 0, got {self.tol!r}")
        if self.tol_distance is not None and not (
                _is_number(self.tol_distance) and self.tol_distance > 0):
            raise OptionError(f"tol_distance must be a number > 0, got {self.tol_distance!r}")
        if not (_is_number(self.equilibrium_tol) and self.equilibrium_tol >= 0):
            raise OptionError(f"equilibrium_tol must be a number >= 0, got "
                              f"{self.equilibrium_tol!r}")
        for name, low in (("max_steps", 1), ("neighbours", 1), ("model_nodes", 3)):
            value = getattr(self, name)
            if not (_is_int(value) and value >= low):
                raise OptionError(f"{name} must be an integer >= {low}, got {value!r}")


@dataclass(frozen=True)
class ReadOptions(_Options):
    """How shape files become shapes (:func:`modalmorph.io.read_shape`)."""

    nodes: int | None = _opt(
        None, "resample 2D contours to this many nodes (default: as in the file; 200 for "
        "images and SVG)", group="input", kind="int")
    threshold: float | None = _opt(
        None, "grey images: level separating object from background; needed for grey "
        "images (two-level masks need none), whose refusal proposes Otsu's",
        group="input", kind="float")
    object: str | int = _opt(
        "largest", "images: which object to take: largest, center (the one nearest the "
        "image centre), all (every object, its contours one after another) or a number "
        "(1 = the first in reading order)", group="input", kind="object", choices=OBJECTS)
    label: int | None = _opt(
        None, "label images (segmentations, NIfTI): the value of the object's pixels",
        group="input", kind="int")

    flip_y: bool = _opt(
        False, "mirror the y of 2D point files (CSV, TSV, TXT, NPY, NPZ, JSON: y up) into "
        "image coordinates (y down, as images and SVG), for inputs mixing the two; the "
        "results are in the mirrored coordinates", group="input", kind="bool")

    def _check(self):
        if self.nodes is not None and not (_is_int(self.nodes) and self.nodes >= 3):
            raise OptionError(f"nodes must be an integer >= 3, got {self.nodes!r}")
        if self.threshold is not None and not _is_number(self.threshold):
            raise OptionError(f"threshold must be a number, got {self.threshold!r}")
        if self.label is not None and not _is_int(self.label):
            raise OptionError(f"label must be an integer, got {self.label!r}")


@dataclass(frozen=True)
class OutputOptions(_Options):
    """What the command line writes besides the results (``result.json``, the shapes)."""

    figures: bool = _opt(True, "the PNG figures", group="outputs", kind="bool")
    svg: bool = _opt(False, "the figures also as SVG (vector graphics; costs as much again "
                     "as the PNGs)", group="outputs", kind="bool")
    gif: bool = _opt(True, "the animation as a GIF", group="outputs", kind="bool")
    mp4: bool = _opt(False, "also the animation as an MP4 (needs ffmpeg)", group="outputs",
                     kind="bool")
    vtk: bool = _opt(False, "also a VTK time series (.vtu + .pvd) for ParaView",
                     group="outputs", kind="bool")
    gltf: bool = _opt(False, "also morph.glb: one animated glTF 2.0 file (a morph target per "
                      "step) for Blender, three.js and other 3D viewers", group="outputs",
                      kind="bool")
    meshes: str = _opt("none", "also the shape at every step as a mesh file in meshes/: "
                       "ply, obj or none", group="outputs", kind="str", choices=STEP_MESHES)
    html: bool = _opt(False, "also report.html: the interactive viewer in one "
                      "self-contained file", group="outputs", kind="bool")
    background: bool = _opt(True, "draw shapes read from an image over that image",
                            group="outputs", kind="bool")
    frames: str = _opt(
        "time", "frames of the animation and the figures: time (every time step) or path "
        "(evenly spaced along the path, as the damped motion bunches steps near the "
        "target)", group="outputs", kind="str", choices=FRAME_SPACINGS)


@dataclass(frozen=True)
class TrackOptions(_Options):
    """How :func:`modalmorph.track` follows a sequence."""

    reference: str = _opt(
        "previous", "previous: morph each tracked frame onto the next (small steps); "
        "first: morph frame 0 straight onto every frame", group="sequence", kind="str",
        choices=REFERENCES)
    correspondence: str = _opt(
        "nearest", "nearest: in the frames' common frame each observed node pulls at most "
        "one node, the nearest of those whose nearest it is (consecutive frames, motions "
        "under the node spacing); modal: modal matching (large motions between frames)",
        group="sequence", kind="str", choices=CORRESPONDENCES)
    cycle: bool = _opt(
        False, "periodic sequence (a cardiac cycle): also morph the last frame back onto "
        "the first and report the closure error", group="sequence", kind="bool")
    segments: int = _opt(
        6, "segments of equal arc length for the strain table (6: those of a left-"
        "ventricle short-axis slice)", group="sequence", kind="int")
    start_node: int = _opt(
        0, "node of the first frame where segment 1 starts", group="sequence", kind="int")

    def _check(self):
        if not isinstance(self.cycle, bool):
            raise OptionError(f"cycle must be true or false, got {self.cycle!r}")
        for name, low in (("segments", 1), ("start_node", 0)):
            value = getattr(self, name)
            if not (_is_int(value) and value >= low):
                raise OptionError(f"{name} must be an integer >= {low}, got {value!r}")


@dataclass(frozen=True)
class StrainOptions(_Options):
    """How :func:`modalmorph.strain` measures the wall of a myocardium sequence."""

    segments: int = _opt(
        6, "equal sectors by angle around the reference centre (6: the AHA mid-ventricular "
        "segments); segment 0 is the whole wall", group="strain", kind="int")
    reference_frame: int = _opt(
        0, "frame the strains are measured against (end-diastole)", group="strain",
        kind="int", flag="--reference")
    reference_angle: float = _opt(
        0.0, "where segment 1 starts, degrees counterclockwise from the image's +x axis as "
        "the image is shown (y down); segments follow counterclockwise", group="strain",
        kind="float")
    rv_point: tuple | None = _opt(
        None, "an RV insertion point x,y (image units) at the reference frame: segment 1 "
        "starts one segment clockwise of it (the AHA anterior segment, from the anterior "
        "insertion); overrides reference_angle", group="strain", kind="point")
    rv_label: int | None = _opt(
        None, "label images: the RV's label; segment 1 starts two segments clockwise of the "
        "direction of the RV's centre at the reference frame (the septum, segments 2-3, "
        "faces the RV); overrides reference_angle", group="strain", kind="int")
    label: int | None = _opt(
        None, "label images: the myocardium's label (default: every non-zero pixel)",
        group="strain", kind="int")
    object: str | int = _opt(
        "largest", "several objects in a mask: largest, center (nearest the image centre) or "
        "a label number (1 = the first in reading order)", group="strain", kind="object",
        choices=OBJECTS)
    endo_only: bool = _opt(
        False, "masks of the blood pool or contours without an epicardium: endocardial "
        "circumferential strain only", group="strain", kind="bool")
    nodes: int = _opt(
        64, "nodes per contour (endocardium, epicardium)", group="strain", kind="int")
    frame_interval: float | None = _opt(
        None, "seconds between frames: strain rates per second (default: per frame)",
        group="strain", kind="float")
    correspondence: str = _opt(
        "nearest", "how the tracking pairs nodes between frames (as track's)",
        group="strain", kind="str", choices=CORRESPONDENCES)

    def _check(self):
        for name, low in (("segments", 1), ("reference_frame", 0), ("nodes", 8)):
            value = getattr(self, name)
            if not (_is_int(value) and value >= low):
                raise OptionError(f"{name} must be an integer >= {low}, got {value!r}")
        if not _is_number(self.reference_angle):
            raise OptionError(f"reference_angle must be a number (degrees), got "
                              f"{self.reference_angle!r}")
        for name in ("rv_label", "label"):
            value = getattr(self, name)
            if value is not None and not (_is_int(value) and value >= 0):
                raise OptionError(f"{name} must be a label value >= 0, got {value!r}")
        if self.frame_interval is not None and not (_is_number(self.frame_interval)
                                                    and self.frame_interval > 0):
            raise OptionError(f"frame_interval must be a number of seconds > 0, got "
                              f"{self.frame_interval!r}")
        if self.rv_point is not None and not (
                isinstance(self.rv_point, tuple) and len(self.rv_point) == 2
                and all(map(_is_number, self.rv_point))):
            raise OptionError(f"rv_point must be two numbers (x, y), got {self.rv_point!r}")
        if not isinstance(self.endo_only, bool):
            raise OptionError(f"endo_only must be true or false, got {self.endo_only!r}")


@dataclass(frozen=True)
class StanceOptions(_Options):
    """How :func:`modalmorph.stance` reads a pressure stack and follows its loaded parts
    (:mod:`modalmorph.io.pressure` says how the parts and their boundaries are found)."""

    threshold: float | None = _opt(
        None, "pressure above which a sensor is loaded, in the array's units (default: "
        "fraction x the peak)", group="pressure", kind="float")
    fraction: float = _opt(
        0.02, "without threshold: the loaded level as a fraction of the stack's peak",
        group="pressure", kind="float")
    pixel_size: float = _opt(
        1.0, "sensor pitch in mm: contours, areas and figures in mm (1: in sensors)",
        group="pressure", kind="float")
    smooth: float = _opt(
        0.5, "Gaussian width (sensors) of the smoothing before the boundary is drawn "
        "through the sensors (0: none)", group="pressure", kind="float")
    min_sensors: int = _opt(
        2, "smaller contacts (a single loaded sensor) are skipped, and said",
        group="pressure", kind="int")
    spacing: float = _opt(
        0.5, "node spacing along a part's boundary at its largest, in sensors",
        group="pressure", kind="float")
    every: int = _opt(
        1, "take every N-th frame (20: a 500 Hz plate at 25 Hz)", group="pressure",
        kind="int")

    def _check(self):
        if self.threshold is not None and not _is_number(self.threshold):
            raise OptionError(f"threshold must be a number, got {self.threshold!r}")
        _check_range("fraction", self.fraction, 0.0, 1.0, "of the peak")
        for name in ("pixel_size", "spacing"):
            value = getattr(self, name)
            if not (_is_number(value) and value > 0):
                raise OptionError(f"{name} must be a number > 0, got {value!r}")
        if not (_is_number(self.smooth) and self.smooth >= 0):
            raise OptionError(f"smooth must be a number >= 0, got {self.smooth!r}")
        for name in ("min_sensors", "every"):
            value = getattr(self, name)
            if not (_is_int(value) and value >= 1):
                raise OptionError(f"{name} must be an integer >= 1, got {value!r}")


OPTION_CLASSES = (ReadOptions, MatchOptions, MorphOptions, OutputOptions)


def flat_fields(classes=OPTION_CLASSES):
    """``[(flat name, class, field)]`` of the given option classes, in order: the one
    namespace of the config file, the flags and the form (see the module's docstring)."""
    names = {f.name for cls in classes if cls is not MatchOptions for f in fields(cls)}
    return [((f"match_{f.name}" if cls is MatchOptions and f.name in names else f.name),
             cls, f) for cls in classes for f in fields(cls)]


def split_overrides(overrides: dict, *, where: str) -> tuple[dict, dict]:
    """Keyword overrides of :func:`modalmorph.morph` as ``(MorphOptions fields,
    MatchOptions fields)``: the matcher's options under their flat names (``rotation``,
    ``method``, ``reject``, ``match_sigma``, ``match_modes``); unknown names refused."""
    morph_names = {f.name for f in fields(MorphOptions)}
    match_names = {flat: f.name for flat, cls, f in flat_fields() if cls is MatchOptions}
    unknown = sorted(set(overrides) - morph_names - set(match_names))
    if unknown:
        raise OptionError(f"unknown {where} option {unknown[0]!r}; known: "
                          f"{', '.join(sorted(morph_names | set(match_names)))}")
    return ({k: v for k, v in overrides.items() if k in morph_names},
            {match_names[k]: v for k, v in overrides.items() if k in match_names})


def parameters(morph) -> dict:
    """What a morph used, by flat name (``result.json``'s ``parameters``): its
    :meth:`MorphOptions.record` with the values resolved for its object (``sigma``,
    ``modes`` as a count, ``model_nodes`` as the model's node count, ``solver``) and the
    matcher's options when known."""
    flat = {f.name: name for name, cls, f in flat_fields() if cls is MatchOptions}
    from_match = {} if morph.match_options is None else {
        flat[name]: value for name, value in morph.match_options.record().items()}
    resolved = morph.resolved
    return {**morph.options.record(),
            "sigma": resolved.sigma, "modes": resolved.modes,
            "model_nodes": resolved.model_nodes, "solver": resolved.solver, **from_match}


def split(values: dict, classes=OPTION_CLASSES, *, where: str = "options") -> dict:
    """``{class: instance}`` from flat values (parsed or text); unknown names refused."""
    table = {flat: (cls, f) for flat, cls, f in flat_fields(classes)}
    unknown = sorted(set(values) - set(table))
    if unknown:
        raise OptionError(f"{where}: unknown option {unknown[0]!r}; known: "
                          f"{', '.join(table)}")
    kwargs = {cls: {} for cls in classes}
    for flat, value in values.items():
        cls, f = table[flat]
        kwargs[cls][f.name] = parse_value(flat, f.metadata["kind"], value)
    try:
        return {cls: cls(**kw) for cls, kw in kwargs.items()}
    except OptionError as exc:
        raise OptionError(f"{where}: {exc}") from None


def parse_value(name: str, kind: str, value):
    """A value of the given kind from text (the flags, the form) or from TOML.

    Kinds: ``bool``, ``int``, ``float``, ``str``; ``modes`` ("all", a count or a fraction
    such as "2/3" or 0.66); ``damping`` (one or two numbers); ``point`` (two numbers x,y);
    ``material`` (a name or three numbers E, nu, rho); ``object`` (largest, center or a
    label number). ``None`` and empty text give ``None`` (the default).
    """
    if value is None or isinstance(value, str) and not value.strip():
        return None
    if not isinstance(value, str):
        return _typed(name, kind, value)
    text = value.strip()
    if kind == "bool":
        if text.lower() not in ("true", "false", "1", "0", "yes", "no"):
            raise OptionError(f"{name} must be true or false, got {text!r}")
        return text.lower() in ("true", "1", "yes")
    if kind == "str":
        return text
    if kind == "object":
        return int(text) if text.isdigit() else text
    if kind == "modes" and text.lower() == "all":
        return None
    if kind == "material" and text in MATERIALS:
        return MATERIALS[text]
    numbers = [_number(name, token) for token in text.replace(",", " ").split()]
    return _typed(name, kind, numbers[0] if len(numbers) == 1 else numbers)


def _typed(name, kind, value):
    """Check a non-text value's type for its kind; lists become tuples."""
    if kind == "material":
        if isinstance(value, Material):
            return value
        if isinstance(value, str) and value in MATERIALS:
            return MATERIALS[value]
        if isinstance(value, list | tuple) and len(value) == 3 and all(map(_is_number, value)):
            return Material(*map(float, value), name="custom")
        raise OptionError(f"{name} must be one of {', '.join(MATERIALS)} or three numbers "
                          f"E nu rho, got {value!r}")
    if kind == "point":
        if not (isinstance(value, list | tuple) and len(value) == 2
                and all(map(_is_number, value))):
            raise OptionError(f"{name} must be two numbers x,y, got {value!r}")
        return tuple(map(float, value))
    if kind == "damping" and isinstance(value, list | tuple):
        if len(value) not in (1, 2) or not all(map(_is_number, value)):
            raise OptionError(f"{name} takes one or two ratios, got {value!r}")
        return float(value[0]) if len(value) == 1 else tuple(map(float, value))
    expected = {"bool": bool, "int": Integral, "float": Real, "str": str, "modes": Real,
                "damping": Real, "object": (str, Integral)}[kind]
    if not isinstance(value, expected) or isinstance(value, bool) and kind != "bool":
        raise OptionError(f"{name} has the wrong type ({type(value).__name__}) for "
                          f"{kind}")
    return float(value) if kind == "float" else value


def _number(name, token):
    try:
        if "/" in token:
            num, den = token.split("/")
            return float(num) / float(den)
        return int(token) if token.lstrip("+-").isdigit() else float(token)
    except (ValueError, ZeroDivisionError):
        raise OptionError(f"{name} must be a number, got {token!r}") from None


def _is_number(value) -> bool:
    return isinstance(value, Real) and not isinstance(value, bool) and math.isfinite(value)


def _is_int(value) -> bool:
    return isinstance(value, Integral) and not isinstance(value, bool)


def _is_label(value) -> bool:
    return _is_int(value) and value >= 1


def _check_range(name, value, low, high, unit):
    if not (_is_number(value) and low <= value <= high):
        raise OptionError(f"{name} must be a number in [{low:g}, {high:g}] ({unit}), "
                          f"got {value!r}")


def _check_sigma(sigma):
    if sigma is not None and not (_is_number(sigma) and MIN_SIGMA <= sigma <= MAX_SIGMA):
        raise OptionError(f"sigma must be None (chosen per shape) or a number between "
                          f"{MIN_SIGMA:g} and {MAX_SIGMA:g} (x mean node spacing), "
                          f"got {sigma!r}")


def _check_modes(modes):
    if modes is None or _is_int(modes) and modes >= 1:
        return
    if _is_number(modes) and isinstance(modes, float) and 0 < modes <= 1:
        return
    raise OptionError(f"modes must be None (all), a count >= 1 or a fraction in (0, 1], "
                      f"got {modes!r}")


def _check_damping(damping):
    if _is_number(damping) and damping > 0:
        return
    if isinstance(damping, tuple) and len(damping) == 2 and all(
            _is_number(x) and x >= 0 for x in damping):
        return
    raise OptionError(f"damping must be a ratio > 0 or two ratios >= 0, got {damping!r}")
