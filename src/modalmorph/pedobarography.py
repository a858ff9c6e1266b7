"""``stance()``: every loaded part of a foot on a pressure plate, followed through the
stance phase (dynamic pedobarography, the paper's home field).

Contact starts with the heel; the forefoot and the toes touch down, parts merge (the
midfoot joins heel and forefoot) and leave. Each frame's parts and their sub-sensor
boundaries come from :func:`modalmorph.io.pressure.frame_parts`. Parts are linked
between consecutive frames by overlap (shared loaded sensors): a part overlapping
exactly one part of the previous frame, which overlaps nothing else, continues it; a part
with no such link *appears*. Where parts merge or split, the parts before end and those
after start as new *transitional objects* (the paper's term), and the events say so.
Each part is followed from when it appears to when it leaves with its own nodes (as
many as its largest boundary needs at ``spacing``), as :func:`modalmorph.track` does:
the tracked shape of each frame is morphed (:func:`modalmorph.morph`) onto the next
frame's boundary, here with an order-preserving cyclic correspondence, so the strain
energy (22) of every frame's deformation is known per part and in all. Frames with
nothing loaded at the start and the end are skipped, and said.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial import cKDTree

from .core.quality import area, curve_distances, self_crossings, step_crossings
from .core.shape import Shape, resample
from .errors import InputFileError, MorphDivergedError, OptionError
from .io.pressure import check_pressure, frame_parts, pressure_level
from .options import MorphOptions, StanceOptions
from .pipeline import morph

__all__ = ["MIN_PART_NODES", "OTHER_FOOT", "PartTrack", "Registration", "Stance",
           "footprint_parts", "other_foot", "register_footprints", "stance"]

log = logging.getLogger(__name__)

# The template of register_footprints shows a foot's parts apart (a heel joined to the
# forefoot in the template would leave a separate heel unregistered; apart in the
# template, a joined one is cut where the regions meet): the most parts of >= LARGE_PART
# sensors (issue 24's large parts) shown by at least TEMPLATE_SHARE of the images. On
# jiku-data's subject 2, heel and forefoot are joined in 41 of 60 peak images: the most
# typical image joined them and left 18 heels unregistered.
LARGE_PART = 12
TEMPLATE_SHARE = 0.1
# Fewest nodes of a part's contour: a 2-sensor contact has a boundary of about 4 sensors,
# 8 nodes at the default spacing of 0.5 sensor.
MIN_PART_NODES = 8
# An image looks like the other foot of the template's (a left foot's template, a right
# foot's image, or one walking the other way) where the template reflected about either
# plate axis overlaps its loaded sensors OTHER_FOOT times better than as given
# (other_foot). jiku-data's peak images (10 subjects, one foot each), each subject's first
# image as the template of every 6th image of every subject (1000 pairs): as given, the
# reflected template fits at most 1.13 times better (rows reversed 1.11); the template
# mirrored left-right (the other foot's) fits over 1.2 times better reflected back in
# 96.7 % of them (1.1: 98.4 %, with one false call as given). Each subject's default
# (typical) or mean template onto its 60 images: at most 0.82 as given, 100 % mirrored.
OTHER_FOOT = 1.2


@dataclass(frozen=True, eq=False)
class PartTrack:
    """One loaded part followed from when it appears to when it leaves.

    Attributes
    ----------
    part : int
        Its number in the stance (0, 1, ... in order of appearance).
    frames : ndarray of int, shape (F_p,)
        The stance frames it is loaded in (consecutive).
    labels : ndarray of int, shape (F_p,)
        Its label in each frame's :class:`~modalmorph.io.pressure.FrameParts`.
    points : ndarray, shape (F_p, m, 2)
        Its tracked nodes (node ``i`` is the same material node in every frame), mm.
    energy : ndarray, shape (F_p,)
        Strain energy (22) of the deformation from its previous frame (0 at its first).
    sensors : ndarray of int, shape (F_p,)
        Loaded sensors.
    area : ndarray, shape (F_p,)
        Area inside its boundary, mm^2.
    node_distance : ndarray, shape (F_p,)
        Largest distance of a tracked node to the part's boundary, mm.
    boundary_gap : ndarray, shape (F_p,)
        Largest distance of a boundary point to the nearest tracked node, mm.
    crossed : ndarray of bool, shape (F_p,)
        Whether the tracked contour folds (crosses itself beyond tracing noise's tiny
        loops, as ``Morph.self_intersections`` counts).
    start, end : str
        How it began ("appears", "merge of parts 0, 1", "split of part 2", "first
        frame") and ended ("leaves", "merges into part 4", "splits into parts 5, 6",
        "last frame").
    """

    part: int
    frames: np.ndarray
    labels: np.ndarray
    points: np.ndarray
    energy: np.ndarray
    sensors: np.ndarray
    area: np.ndarray
    node_distance: np.ndarray
    boundary_gap: np.ndarray
    crossed: np.ndarray
    start: str = ""
    end: str = ""


@dataclass(frozen=True, eq=False)
class Stance:
    """Every loaded part of a stance phase, followed.

    Attributes
    ----------
    pressure : ndarray, shape (F, H, W)
        The frames kept (nothing-loaded frames at the ends skipped), array units.
    frames : ndarray of int, shape (F,)
        Their indices in the input stack.
    level : float
        Loaded above this, array units.
    pixel_size : float
        mm per sensor.
    observed : tuple of FrameParts
        Each frame's parts and boundaries.
    parts : tuple of PartTrack
        The parts, in order of appearance.
    energy : ndarray, shape (F,)
        Strain energy of every frame's deformation, summed over the parts.
    part_energy : ndarray, shape (F, P)
        The same per part (NaN where the part is not loaded).
    events : tuple of str
        What happened, in order ("frame 3: part 2 appears", ...: the input's frames).
    params : dict
        The options used.
    """

    pressure: np.ndarray
    frames: np.ndarray
    level: float
    pixel_size: float
    observed: tuple
    parts: tuple
    energy: np.ndarray
    part_energy: np.ndarray
    events: tuple
    params: dict = field(default_factory=dict)

    def __repr__(self) -> str:
        return (f"Stance({len(self.frames)} frames, {len(self.parts)} parts, total energy "
                f"{float(self.energy.sum()):.4g})")

    @property
    def n_frames(self) -> int:
        return len(self.frames)


def stance(pressure, *, options: StanceOptions | None = None, name: str = "pressure",
           morph_options: MorphOptions | None = None,
           progress: Callable[[int, int], None] | None = None, **overrides) -> Stance:
    """Follow every loaded part of a pressure stack through the stance phase.

    Parameters
    ----------
    pressure : array_like, shape (T, H, W) or (H, W)
        Pressure per sensor, in time order (rows and columns of the plate).
    options : StanceOptions, optional
        Level, sensor pitch, smoothing, node spacing, frame step.
    name : str, optional
        Names the input in messages.
    morph_options : MorphOptions, optional
        The morph of each frame (:func:`modalmorph.track`).
    progress : callable, optional
        Called as ``progress(done, total)`` after each part.
    **overrides
        :class:`StanceOptions` fields.

    Returns
    -------
    Stance

    Raises
    ------
    InputFileError
        NaN or infinite values (naming the frame), nothing loaded, a threshold above
        every value, or no part of ``min_sensors`` in any frame.
    """
    opts = _options(options, overrides)
    stack = check_pressure(pressure, name)[::opts.every]
    level = pressure_level(stack, threshold=opts.threshold, fraction=opts.fraction,
                           name=name)
    observed = [frame_parts(f, level, pixel_size=opts.pixel_size, smooth=opts.smooth,
                            min_sensors=opts.min_sensors) for f in stack]
    kept = _kept_frames(observed, name, opts)
    observed = observed[kept[0]:kept[-1] + 1]
    chains, events = _link(observed, kept * opts.every)
    parts = []
    for c, chain in enumerate(chains):
        parts.append(_follow(c, chain, observed, opts, morph_options))
        if progress is not None:
            progress(c + 1, len(chains))
    part_energy = np.full((len(observed), len(parts)), np.nan)
    for p in parts:
        part_energy[p.frames, p.part] = p.energy
    for e in events:
        log.info("%s: %s", name, e)
    return Stance(pressure=stack[kept[0]:kept[-1] + 1], frames=kept * opts.every,
                  level=level, pixel_size=float(opts.pixel_size), observed=tuple(observed),
                  parts=tuple(parts), energy=np.nansum(part_energy, axis=1),
                  part_energy=part_energy, events=tuple(events), params=opts.record())


def _options(options, overrides: dict) -> StanceOptions:
    if options is None:
        options = StanceOptions()
    elif not isinstance(options, StanceOptions):
        raise OptionError(f"options must be a StanceOptions, got {type(options).__name__}")
    return options.replace(**overrides)


def _kept_frames(observed: list, name: str, opts: StanceOptions) -> np.ndarray:
    """Stack indices from the first to the last frame with a part; the skipped ends and
    the left-out small contacts said."""
    loaded = np.flatnonzero([len(o.contours) for o in observed])
    if not len(loaded):
        raise InputFileError(f"{name}: no frame has a contact of {opts.min_sensors} "
                             f"sensors or more above the level")
    first, last = int(loaded[0]), int(loaded[-1])
    if first or last < len(observed) - 1:
        log.info("%s: frames with nothing loaded skipped: %d at the start, %d at the end",
                 name, first * opts.every, (len(observed) - 1 - last) * opts.every)
    dropped = sum(o.dropped for o in observed[first:last + 1])
    if dropped:
        log.info("%s: %d contact(s) smaller than %d sensors skipped", name, dropped,
                 opts.min_sensors)
    return np.arange(first, last + 1)


def _link(observed: list, numbers: np.ndarray) -> tuple[list, list]:
    """The parts' chains ``[(frame, label), ...]`` and the events (naming the input's
    frame ``numbers[f]``), by overlap."""
    chains, events = [], []
    open_chain = {}  # label in the previous frame -> chain index
    for f, parts in enumerate(observed):
        n_now = len(parts.contours)
        if f == 0:
            open_chain = {q: _start(chains, 0, q, "first frame") for q in range(1, n_now + 1)}
            continue
        prev = observed[f - 1]
        both = (prev.labels > 0) & (parts.labels > 0)
        links = set(zip(prev.labels[both].tolist(), parts.labels[both].tolist(),
                        strict=True))
        now = {}
        for group_prev, group_now in _groups(links, len(prev.contours), n_now):
            old = [open_chain[p] for p in sorted(group_prev)]
            if len(group_prev) == 1 and len(group_now) == 1:
                q = next(iter(group_now))
                chains[old[0]][0].append((f, q))
                now[q] = old[0]
                continue
            new = sorted(group_now)
            how = ("appears" if not old else f"merge of parts {_names(old)}"
                   if len(old) > 1 else f"split of part {old[0]}")
            for q in new:
                now[q] = _start(chains, f, q, how)
            ends = (f"merges into part {now[new[0]]}" if len(new) == 1 else
                    f"splits into parts {_names([now[q] for q in new])}" if new else
                    "leaves")
            for c in old:
                chains[c][2] = ends
            events.append(_event(int(numbers[f]), old, [now[q] for q in new]))
        open_chain = now
    for c in open_chain.values():
        chains[c][2] = "last frame"
    return chains, events


def _start(chains: list, f: int, q: int, how: str) -> int:
    chains.append([[(f, q)], how, ""])
    return len(chains) - 1


def _names(parts) -> str:
    return ", ".join(str(p) for p in parts)


def _event(f: int, old: list, new: list) -> str:
    if not old:
        return f"frame {f}: part {new[0]} appears"
    if not new:
        return f"frame {f}: part {old[0]} leaves"
    if len(new) == 1:
        return f"frame {f}: parts {_names(old)} merge into part {new[0]} (transitional)"
    if len(old) == 1:
        return f"frame {f}: part {old[0]} splits into parts {_names(new)} (transitional)"
    return f"frame {f}: parts {_names(old)} become parts {_names(new)} (transitional)"


def _groups(links: set, n_prev: int, n_now: int) -> list:
    """Connected groups (previous labels, current labels) of the overlap graph, every
    label in one group (a part without overlap alone)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n = n_prev + n_now
    i = np.array([p - 1 for p, _ in links], dtype=np.intp)
    j = np.array([n_prev + q - 1 for _, q in links], dtype=np.intp)
    graph = coo_matrix((np.ones(len(i)), (i, j)), shape=(n, n))
    _, comp = connected_components(graph, directed=False)
    groups = {}
    for k, c in enumerate(comp):
        side = 0 if k < n_prev else 1
        groups.setdefault(c, (set(), set()))[side].add(k + 1 if side == 0 else k - n_prev + 1)
    return list(groups.values())


def _follow(c: int, chain: list, observed: list, opts: StanceOptions,
            morph_options) -> PartTrack:
    """Track one part's chain of boundaries with its own nodes."""
    steps, start, end = chain
    frames = np.array([f for f, _ in steps])
    labels = np.array([q for _, q in steps])
    contours = [observed[f].contours[q - 1] for f, q in steps]
    spacing = opts.spacing * opts.pixel_size
    longest = max(_perimeter(b) for b in contours)
    shapes = _simple_samples(contours, max(MIN_PART_NODES, math.ceil(longest / spacing)))
    points, energy = _track_part(shapes, [f"part {c} in frame {f}" for f in frames],
                                 morph_options)
    crossed = step_crossings(points, shapes[0]) > 0  # folds, as morphs count them
    node_d, gap = zip(*(_fit(p, b) for p, b in zip(points, contours, strict=True)),
                      strict=True)
    return PartTrack(
        part=c, frames=frames, labels=labels, points=points, energy=energy,
        sensors=np.array([observed[f].sensors[q - 1] for f, q in steps]),
        area=np.array([abs(area(b)) for b in contours]), node_distance=np.array(node_d),
        boundary_gap=np.array(gap), crossed=crossed, start=start, end=end)


def _simple_samples(contours: list, m: int) -> list:
    """The boundaries resampled to ``m`` nodes evenly spaced, ``m`` raised by half
    until none crosses itself (a chord across a neck narrower than the spacing, where
    two parts nearly touch, would: 1 frame in 600 real stance phases)."""
    most = 4 * max(len(b) for b in contours)  # the chords then follow every vertex
    while True:
        samples = [resample(b, m) for b in contours]
        if m >= most or not any(self_crossings(p) for p in samples):
            return [Shape(p) for p in samples]
        m = math.ceil(1.5 * m)


def _track_part(shapes: list, names: list, morph_options) -> tuple:
    """(points (F_p, m, 2), energy (F_p,)): each frame reached by morphing the tracked
    previous frame onto it, node ``i`` pulled to the observed node of the cyclic shift
    nearest in the least-squares sense (order kept, every node matched, so the nodes stay
    evenly spread over the boundary as it grows, and no contour folds)."""
    points, energy = [shapes[0].points], [0.0]
    for f in range(1, len(shapes)):
        source, target = shapes[0].with_points(points[-1]), shapes[f]
        try:
            result = morph(source, target, matching=_cyclic_pairs(source.points,
                                                                  target.points),
                           options=morph_options)
        except (ValueError, MorphDivergedError) as exc:
            raise ValueError(f"{names[f]}: {exc}") from exc
        points.append(result.shapes[-1])
        energy.append(float(result.energy[-1]))
    return np.array(points), np.array(energy)


def _cyclic_pairs(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pairs (i, (i + s) mod m) for the shift ``s`` minimising the summed squared
    distances of two contours of ``m`` nodes running the same way round."""
    m = len(a)
    shifted = b[(np.arange(m)[:, None] + np.arange(m)[None, :]) % m]  # [s, i]
    s = int(np.argmin(((shifted - a[None]) ** 2).sum(axis=(1, 2))))
    return np.c_[np.arange(m), (np.arange(m) + s) % m]


def _perimeter(points: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(points, axis=0, append=points[:1]), axis=1).sum())


def _fit(nodes: np.ndarray, boundary: np.ndarray) -> tuple[float, float]:
    """(largest node-to-boundary distance, largest boundary-point-to-node distance)."""
    to_boundary, _ = curve_distances(nodes, boundary)
    return float(to_boundary.max()), float(cKDTree(nodes).query(boundary)[0].max())


@dataclass(frozen=True, eq=False)
class Registration:
    """A peak-pressure image registered to a template footprint, part by part.

    Attributes
    ----------
    template : tuple of ndarray (m_k, 2)
        The template's parts (mm), the same for every image registered to it.
    template_sensors : ndarray of int, shape (K,)
        Their loaded sensors.
    shapes : tuple of ndarray (m_k, 2) or None
        Each template part's nodes moved onto this image's part (None: no partner).
    node_energy : tuple of ndarray (m_k,)
        Strain energy (25) at each template node (NaN where no partner).
    part_energy : ndarray, shape (K,)
        Strain energy (22) of each template part's registration (NaN: no partner).
    energy : float
        Their sum over the registered parts.
    area : float
        Area of the image's registered parts, mm^2.
    peak : ndarray, shape (2,)
        Where on the template (mm) the node energy is largest.
    peak_part, peak_node : int
        The template part and node holding it.
    missing : tuple of int
        Template parts with no partner in the image (said in the log).
    other_foot : float
        How many times better the template reflected fits the image's loaded sensors than
        as given (:func:`other_foot`); above :data:`OTHER_FOOT` the image looks like the
        other foot (said in the log), and its energy measures that, not a deformation.
    """

    template: tuple
    template_sensors: np.ndarray
    shapes: tuple
    node_energy: tuple
    part_energy: np.ndarray
    energy: float
    area: float
    peak: np.ndarray
    peak_part: int
    peak_node: int
    missing: tuple
    other_foot: float = 1.0


def footprint_parts(image, level: float, opts: StanceOptions, regions=None):
    """The loaded parts (FrameParts) of a peak image, as :func:`stance` sees a frame,
    cut by ``regions`` (H, W) when given."""
    return frame_parts(check_pressure(image, "image")[0], level,
                       pixel_size=opts.pixel_size, smooth=opts.smooth,
                       min_sensors=opts.min_sensors, regions=regions)


def register_footprints(images, *, template: int | str | None = None,
                        options: StanceOptions | None = None,
                        morph_options: MorphOptions | None = None,
                        **overrides) -> list[Registration]:
    """Register peak-pressure images to a template footprint, part by part.

    The template is by default the most typical image (of those showing the most large
    parts that a tenth of the images show, :data:`TEMPLATE_SHARE`, the one whose loaded
    sensors overlap the others' most, by mean Jaccard index: its parts are a real
    foot's, where the mean image joins heel and forefoot through the averaged midfoot),
    ``"mean"`` (a
    subject's mean footprint: the images share the plate's frame), one of them
    (``template=i``) or an (H, W) image. Its parts
    (heel, forefoot, toes: the loaded parts of :func:`stance`, at the level of the
    images' peak) divide the plate into regions, every sensor to the template part
    nearest it (anatomical masks); each template part is morphed onto the largest loaded
    part of the image in its region (a heel joined to the forefoot through the midfoot
    is cut where the regions meet) (:func:`modalmorph.morph`, modal
    matching in the plate's frame); the strain energy says how much each part of the
    foot had to deform.

    Returns
    -------
    list of Registration, one per image.
    """
    opts = _options(options, overrides)
    stack = check_pressure(images, "images")
    level = pressure_level(stack, threshold=opts.threshold, fraction=opts.fraction,
                           name="images")
    if template is None:
        template = _typical(stack, level, opts)
        log.info("template: image %d, the most typical footprint", template)
    base = stack.mean(axis=0) if isinstance(template, str) and template == "mean" else \
        stack[template] if isinstance(template, int | np.integer) else \
        check_pressure(template, "template")[0]
    if base.shape != stack.shape[1:]:
        raise InputFileError(f"template: an image of {base.shape[0]} x {base.shape[1]} "
                             f"sensors, the images {stack.shape[1]} x {stack.shape[2]}: "
                             "a template shares the plate's sensors")
    ref = footprint_parts(base, level, opts)
    spacing = opts.spacing * opts.pixel_size
    shapes = [Shape(resample(b, max(MIN_PART_NODES, math.ceil(_perimeter(b) / spacing))))
              for b in ref.contours]
    from scipy import ndimage

    # every sensor of the plate in the region of the template part nearest it
    _, (ri, ci) = ndimage.distance_transform_edt(ref.labels == 0, return_indices=True)
    regions = ref.labels[ri, ci]
    regs = [_register(ref, shapes, footprint_parts(image, level, opts, regions), regions,
                      spacing, morph_options, f"image {i}") for i, image in enumerate(stack)]
    fits = [other_foot(base > level, image > level) for image in stack]
    flagged = [i for i, f in enumerate(fits) if f > OTHER_FOOT]
    if flagged:
        log.warning("%d of %d images look like the other foot of the template's (image(s) "
                    "%s: the template reflected overlaps their loaded sensors up to %.2f "
                    "times better than as given); their energy measures that, not a "
                    "deformation: register each foot to a template of its own side",
                    len(flagged), len(stack), _listed(flagged), max(fits))
    return [replace(r, other_foot=f) for r, f in zip(regs, fits, strict=True)]


def other_foot(template: np.ndarray, image: np.ndarray) -> float:
    """How many times better the template's loaded sensors reflected (rows or columns
    reversed: a left foot's for a right foot's, either way along the plate) overlap an
    image's than as given: the largest Jaccard index over every shift of each, reflected
    over as given (1 where either is empty). Two boolean (H, W) masks."""
    from scipy.signal import correlate

    def fit(a):
        both = np.rint(correlate(image.astype(float), a.astype(float)))  # every shift
        return float((both / (a.sum() + image.sum() - both)).max())

    if not template.any() or not image.any():
        return 1.0
    return max(fit(template[::-1]), fit(template[:, ::-1])) / fit(template)


def _listed(numbers: list, most: int = 10) -> str:
    """``numbers`` joined by commas, the first ``most`` and how many more."""
    more = f" and {len(numbers) - most} more" if len(numbers) > most else ""
    return ", ".join(map(str, numbers[:most])) + more


def _typical(stack: np.ndarray, level: float, opts: StanceOptions) -> int:
    """Among the images with the most large parts that :data:`TEMPLATE_SHARE` of them
    show, the one whose loaded sensors overlap the others' most (mean Jaccard index)."""
    counts = np.array([np.count_nonzero(footprint_parts(image, level, opts).sensors
                                        >= LARGE_PART) for image in stack])
    most = max(c for c in np.unique(counts) if np.mean(counts >= c) >= TEMPLATE_SHARE)
    masks = (stack > level).reshape(len(stack), -1).astype(np.float64)
    both = masks @ masks.T
    either = masks.sum(axis=1)[:, None] + masks.sum(axis=1)[None, :] - both
    score = (both / np.maximum(either, 1)).mean(axis=1)
    return int(np.argmax(np.where(counts == most, score, -1.0)))


def _register(ref, shapes: list, parts, regions: np.ndarray, spacing: float,
              morph_options, name: str):
    """One image's Registration (see :func:`register_footprints`)."""
    first = [int(np.flatnonzero(parts.labels.ravel() == q)[0])
             for q in range(1, len(parts.contours) + 1)]
    region = regions.ravel()[first] if first else np.zeros(0, dtype=np.intp)
    moved, node_e, part_e, area_sum = [], [], np.full(len(shapes), np.nan), 0.0
    for k, shape in enumerate(shapes):
        mine = np.flatnonzero(region == k + 1)
        if not len(mine):
            moved.append(None)
            node_e.append(np.full(shape.m, np.nan))
            continue
        b = parts.contours[int(mine[np.argmax(parts.sensors[mine])])]  # its largest part
        target = Shape(resample(b, max(MIN_PART_NODES, math.ceil(_perimeter(b) / spacing))))
        result = morph(shape, target, options=morph_options, rotation="none")
        moved.append(result.shapes[-1])
        node_e.append(result.node_energy[-1])
        part_e[k] = result.energy[-1]
        area_sum += abs(area(b))
    missing = tuple(k for k, s in enumerate(moved) if s is None)
    if missing:
        log.info("%s: template part(s) %s have no partner", name, _names(missing))
    flat = np.concatenate(node_e)
    best = int(np.nanargmax(flat)) if np.isfinite(flat).any() else 0
    owner = int(np.searchsorted(np.cumsum([s.m for s in shapes]), best, side="right"))
    return Registration(
        template=tuple(s.points for s in shapes), template_sensors=ref.sensors,
        shapes=tuple(moved),
        node_energy=tuple(node_e), part_energy=part_e, energy=float(np.nansum(part_e)),
        area=area_sum, peak=np.concatenate([s.points for s in shapes])[best],
        peak_part=owner, peak_node=best - sum(s.m for s in shapes[:owner]),
        missing=missing)
