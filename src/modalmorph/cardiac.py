"""``strain()``: radial and circumferential strain of the myocardium from segmented frames.

A short-axis slice of the left-ventricle wall is a ring: the endocardium (the hole) inside
the epicardium (the outer boundary). Both are tracked through the frames (:func:`track`;
``correspondence``, ``smooth_frames``: :data:`DEFINITIONS`), so every node is a material
point of the wall, and the strains are Lagrangian, against the reference frame ``r``
(end-diastole, frame 0 by default), in percent:

- **radial**, wall thickening along the endocardium's normals at the reference frame;
- **circumferential**, the length change of the midwall (of the endocardium, the
  epicardium: ``circumferential_endo``, ``circumferential_epi``);
- by **segments**, equal sectors around the reference endocardium's centroid that the
  material points keep; their **strain rate** and **peaks** (:data:`DEFINITIONS`, also
  written into ``strain.json``).

With ``endo_only=True`` (the blood pool, or endocardial contours) only the endocardial
circumferential strain is measured; the other columns are NaN. (The module is ``cardiac``:
a submodule named ``strain`` would replace the function ``modalmorph.strain``.)
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .core.shape import Shape, resample
from .errors import OptionError, ShapeError
from .io.images import MIN_OBJECT_PIXELS, choose_objects
from .options import MatchOptions, MorphOptions, StrainOptions, TrackOptions
from .tracking import track

__all__ = ["Strain", "KINDS", "strain", "wall_strain", "mask_ring", "rounding_stretch",
           "DEFINITIONS"]

KINDS = ("radial", "circumferential", "circumferential_endo", "circumferential_epi")
DEFINITIONS = {
    "radial": "wall thickness along the endocardium's normal at the reference frame, from "
              "the endocardial material point to the epicardial material point the normal "
              "ray meets: sum(T_f) / sum(T_ref) - 1 over the segment's chords",
    "circumferential": "length of the midwall (midpoints of those chords): L_f / L_ref - 1 "
                       "over the segment's stretches",
    "circumferential_endo": "the same of the endocardium",
    "circumferential_epi": "the same of the epicardium",
    "segments": "N equal sectors by angle around the endocardial centroid of the reference "
                "frame, segment 1 from the reference angle, counterclockwise as the image "
                "is shown (x right, y down); material points keep their segment; segment "
                "0 = the whole wall",
    "strain_rate": "central differences of the strain over frames (per frame, or per "
                   "second given frame_interval)",
    "peak": "the value of largest magnitude over the frames, and its frame",
    "tracking": "every frame reached from the first frame by a morph; by default "
                "(correspondence normal) each node paired with the point where the "
                "contour's normal meets the frame's contour, as a contour shows no motion "
                "along itself (made round first: on an elliptical wall, its rays from the "
                "centre); the node paths smoothed over time (smooth_frames, cines of 24 "
                "frames or more)",
}
CONTOUR_FILES = (".csv", ".tsv", ".txt", ".json", ".svg")  # read as contours, not masks
# A hole smaller than a 3 x 3 block is a speck, not a ventricle: io's measured
# MIN_HOLE_AREA (8.5 px^2 by marching squares), counted in pixels.
MIN_HOLE_PIXELS = MIN_OBJECT_PIXELS
# Gaussian blur (px) of a mask before its 0.5 level is taken: sub-pixel boundaries. On the
# 30-frame ring phantoms (128 x 128, LV 60 px, no noise) the largest error of the global
# radial strain falls from 1.54 to 0.86 points (benchmarks/strain.py).
SMOOTH = 1.0
# Observed contours are this many times denser than the tracked ones (correspondence
# "nearest"; "normal" meets their polyline between nodes): the nearest-node
# pairs then no longer snap nodes along the curve (endocardial nodes drifted 2.2 degrees
# rms at 1x); on the same phantoms the worst segment's circumferential error 12.8 -> 3.9.
DENSE = 4
# Frames are reached from the reference shape straight (track's reference="first"): no
# drift accumulating along the sequence; worst segment circumferential error 3.9 -> 1.6
# points on the noiseless phantom (2.5 with 0.2 px boundary noise, 4.8 frame to frame).
TRACK_REFERENCE = "first"
# The correspondence (StrainOptions.correspondence, default "normal"): every reference node
# goes to where the reference contour's normal meets the frame's contour. A contour shows
# no motion along itself, and "nearest" pairs slide towards a sector that moves less (up
# to 10.5 degrees in the akinetic phantom): worst segment circumferential error on the
# noiseless phantoms 1.6/8.3/4.0 -> 0.5/1.2/0.5 points (contract/akinetic/hypokinetic;
# 0.2 px boundary noise, smoothed: 1.3/1.7/0.9, nearest pairs 2.5/8.9/4.2). But a shrinking
# ellipse moves its points along its rays, and plain normals slid them to its long axis
# (review17: segments 2 and 5 of aspect 1.3 at -12 % against -17 %, -7 against -18 with
# 1.5 x 0.8 mm pixels): the walls are tracked made round (rounding_stretch), where those
# rays are the normals; worst segment error on the ellipses 1.15/1.3/1.5 x 0.8 mm pixels
# 3.6/6.4/12.9 -> 0.4/0.4/0.7, circular phantoms unchanged (benchmarks/strain.py --modes;
# False: plain normals, for that comparison).
ROUNDING = True
# The morph's stop tolerance (MorphOptions.tol, a fraction of the RMS radius) for the
# strain: the default 0.005 leaves the nodes up to 0.09 px short of their partners, 0.9
# points of radial strain on a 10 px wall (global radial error 1.42 -> 0.71 on the
# contracting phantom with 0.001; same time, 0.6 s for 30 frames).
MORPH_TOL = 0.001
# StrainOptions.smooth_frames (a Gaussian over time, sigma in frames, on every frame and
# the reference too) applies to cines of at least this many frames. Sigma 1 frame takes
# the phantoms' worst segment radial error 2.0/1.8/2.6 -> 1.2/1.0/1.6 points, with 0.2 px
# boundary noise 8.6/8.7/7.7 -> 4.2/6.0/4.1 (sigma 0.7: 5.0/6.5/4.8), but flattens the
# peaks of a short cine: global peak radial / circumferential error -2.5/+1.9 points at
# 12 frames (review17), -0.7/+0.7 at 20, -0.4/+0.4 at 24, -0.1/+0.2 at 30 (unsmoothed
# +0.3/0.0; benchmarks/strain.py --frames, docs/guide/strain.md).
SMOOTH_MIN_FRAMES = 24
# An RV insertion point nearer the ventricle's centre than this fraction of the reference
# endocardium's mean radius gives no direction (a click on the centre): refused. The
# insertion points lie on the epicardium, beyond 1.
RV_MIN_DISTANCE = 0.5


@dataclass(frozen=True, eq=False, repr=False)
class Strain:
    """Strains of a myocardium sequence (module docstring for the definitions).

    Attributes
    ----------
    radial, circumferential, circumferential_endo, circumferential_epi : ndarray (F, N+1)
        Percent, column 0 the whole wall, column ``s`` segment ``s``; NaN where not
        measured (``endo_only``).
    endo, epi : ndarray, shape (F, m, 2) and (F, n, 2)
        Tracked endocardial and epicardial nodes ((F, 0, 2) for ``epi`` with
        ``endo_only``), in the input's units, smoothed over time (``smooth_frames``;
        ``tracks`` hold them as tracked).
    outer : ndarray, shape (F, m, 2)
        The epicardial material point of each endocardial node's chord.
    segment_of_chord : ndarray of int, shape (m,)
        Segment (1..N) of each chord (and of the midwall node on it).
    centre : ndarray, shape (2,)
        The reference centre.
    reference, reference_angle : int, float
        Reference frame; start of segment 1 (degrees).
    names : tuple of str
    tracks : tuple of Track
        The tracking of the endocardium and of the epicardium; with ``correspondence=
        "normal"`` of the walls made round: their points times
        ``params["rounding"]`` (transposed) are the walls' (:func:`rounding_stretch`).
    masks : ndarray or None, shape (F, H, W)
        The masks the contours came from (None for contour inputs).
    spacing : tuple of float
        Pixel size (x, y) of the masks, in the input's units.
    params : dict
    """

    radial: np.ndarray
    circumferential: np.ndarray
    circumferential_endo: np.ndarray
    circumferential_epi: np.ndarray
    endo: np.ndarray
    epi: np.ndarray
    outer: np.ndarray
    segment_of_chord: np.ndarray
    centre: np.ndarray
    reference: int
    reference_angle: float
    names: tuple
    tracks: tuple
    masks: np.ndarray | None = None
    spacing: tuple = (1.0, 1.0)
    params: dict = field(default_factory=dict)

    def __repr__(self) -> str:
        kind = "circumferential_endo" if self.params.get("endo_only") else "radial"
        value, frame = self.peak(kind)
        return (f"Strain({self.n_frames} frames, {self.segments} segments, peak global "
                f"{kind} {value[0]:+.1f} % at frame {frame[0]})")

    @property
    def n_frames(self) -> int:
        return self.endo.shape[0]

    @property
    def segments(self) -> int:
        return self.radial.shape[1] - 1

    @property
    def endo_only(self) -> bool:
        return bool(self.params.get("endo_only"))

    def rate(self, kind: str) -> np.ndarray:
        """Strain rate (F, N+1) of a kind: percent per frame, or per second given
        ``frame_interval``."""
        values = self._kind(kind)
        dt = self.params.get("frame_interval") or 1.0
        return np.gradient(values, dt, axis=0) if self.n_frames > 1 else values * 0.0

    def peak(self, kind: str) -> tuple[np.ndarray, np.ndarray]:
        """``(value, frame)``, each (N+1,): the strain of largest magnitude and its frame."""
        values = self._kind(kind)
        if np.isnan(values).all():
            nan = np.full(values.shape[1], np.nan)
            return nan, np.full(values.shape[1], -1)
        frame = np.nanargmax(np.abs(np.nan_to_num(values, nan=0.0)), axis=0)
        return values[frame, np.arange(values.shape[1])], frame

    def _kind(self, kind: str) -> np.ndarray:
        if kind not in KINDS:
            raise OptionError(f"kind must be one of {', '.join(KINDS)}, got {kind!r}")
        return getattr(self, kind)


def strain(frames, *, options: StrainOptions | None = None,
           names: Sequence[str] | None = None, track_options: TrackOptions | None = None,
           match_options: MatchOptions | dict | None = None,
           morph_options: MorphOptions | dict | None = None, **overrides) -> Strain:
    """Radial and circumferential strain of the myocardium through a sequence.

    Parameters
    ----------
    frames : array_like (F, H, W), sequence of masks or of Shapes, path or paths
        Myocardium masks (non-zero, or ``label``, is the wall), ring Shapes (the
        epicardium first, then the endocardium: ``Shape(np.vstack([epi, endo]),
        contours=(n_epi, n_endo))``), or files: a folder or list of PNG/TIFF images, a
        multi-page TIFF or animated GIF, an NPY/NPZ (F, H, W) stack, a NIfTI 2D+t image.
    options : StrainOptions, optional
    names : sequence of str, optional
        A name per frame for messages (default: file names or ``"frame <i>"``).
    track_options, match_options, morph_options : optional
        Passed to :func:`modalmorph.track` for each contour (default: every frame
        reached from frame 0 straight, ``reference="first"``, see :data:`TRACK_REFERENCE`;
        the morph's ``tol`` :data:`MORPH_TOL`; a dict of morph fields changes those
        defaults, a :class:`MorphOptions` replaces them).
    **overrides
        :class:`StrainOptions` fields.

    Returns
    -------
    Strain

    Raises
    ------
    ValueError
        A frame without a hole (not a ring; the message names it; ``endo_only=True``
        measures the endocardium alone), masks of different sizes or pixel spacings,
        invalid options.
    """
    opts = (options or StrainOptions()).replace(**overrides)
    masks, spacing, unit, names, shapes = _masks_of(frames, names)
    if masks is not None:
        said: list[str] = []
        rings = [mask_ring(m, names[f], opts, spacing=spacing, say=said.append)
                 for f, m in enumerate(masks)]
        if said:  # the choice of object once, not once per frame
            more = f" (and in {len(said) - 1} more frames)" if len(said) > 1 else ""
            warnings.warn(f"{said[0]}{more}", stacklevel=2)
    else:
        rings = [_shape_ring(s, names[f], opts) for f, s in enumerate(shapes)]
    if opts.reference_frame >= len(rings):
        raise OptionError(f"reference_frame={opts.reference_frame} is not a frame: the "
                          f"frames are 0..{len(rings) - 1}")
    topts = (track_options or TrackOptions(reference=TRACK_REFERENCE)).replace(
        correspondence=opts.correspondence)
    kw = dict(options=topts, names=names, match_options=match_options,
              morph_options=_morph_options(morph_options))
    rounding = rounding_stretch(rings[0][0]) if opts.correspondence == "normal" and \
        ROUNDING else np.eye(2)  # tracked made round, measured as they are
    tracks = [track(_observed([r[k] @ np.linalg.inv(rounding).T for r in rings], opts.nodes),
                    **kw) for k in range(1 if opts.endo_only else 2)]
    endo = _smoothed(tracks[0].points @ rounding.T, opts)
    epi = _smoothed(tracks[1].points @ rounding.T, opts) if len(tracks) > 1 else \
        np.zeros((len(endo), 0, 2))
    angle = _reference_angle(opts, endo[opts.reference_frame], masks, spacing)
    values = wall_strain(endo, epi, reference=opts.reference_frame, segments=opts.segments,
                         angle=angle)
    params = dict(opts.record(), reference_angle=angle, spacing=list(spacing), unit=unit,
                  rounding=rounding.tolist(), track=topts.record(),
                  morph=kw["morph_options"].record())
    return Strain(**values, endo=endo, epi=epi, reference=opts.reference_frame,
                  reference_angle=angle, names=names, tracks=tuple(tracks),
                  masks=masks, spacing=spacing, params=params)


def rounding_stretch(endo: np.ndarray) -> np.ndarray:
    """The area-keeping linear map (2, 2) that takes a circle to the ellipse of the same
    second moments as the area inside ``endo`` (m, 2): symmetric, determinant 1; the
    identity for a circle. ``correspondence="normal"`` tracks the walls mapped by its
    inverse (frame 0's endocardium, where the tracks start, made round), where the
    normals of an elliptical wall are its rays from the centre (:data:`ROUNDING`)."""
    x, y = (endo - polygon_centroid(endo)).T
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    moments = np.array([[(x * x + x * xn + xn * xn) @ cross * 2,
                         (x * yn + 2 * x * y + 2 * xn * yn + xn * y) @ cross],
                        [0.0, (y * y + y * yn + yn * yn) @ cross * 2]])
    moments[1, 0] = moments[0, 1]  # 24 x the second moments (Green's theorem), any sign
    values, vectors = np.linalg.eigh(moments * np.sign(cross.sum()))
    if values.min() <= 0:
        return np.eye(2)
    axes = np.sqrt(values / np.sqrt(values.prod()))
    return (vectors * axes) @ vectors.T


def _smoothed(points: np.ndarray, opts: StrainOptions) -> np.ndarray:
    """Nodes (F, m, 2) smoothed over time (cines of :data:`SMOOTH_MIN_FRAMES` frames+)."""
    if not opts.smooth_frames or len(points) < SMOOTH_MIN_FRAMES:
        return points
    from scipy.ndimage import gaussian_filter1d

    return gaussian_filter1d(points, opts.smooth_frames, axis=0, mode="nearest")


def _morph_options(value) -> MorphOptions:
    """The strain's morph options: the defaults with ``tol`` :data:`MORPH_TOL`, changed by
    the fields of a dict (the command line's flags), or the object given as it is."""
    if isinstance(value, MorphOptions):
        return value
    return MorphOptions(tol=MORPH_TOL).replace(**(value or {}))


def _observed(contours, nodes: int) -> list:
    """The contours to track: frame 0 with ``nodes`` nodes (the material points), the
    others ``DENSE`` times denser (a node pulled to its nearest one does not snap)."""
    return [resample(c, nodes if f == 0 else DENSE * nodes) for f, c in enumerate(contours)]


# ------------------------------------------------------------------------------ measure


def wall_strain(endo, epi, *, reference: int = 0, segments: int = 6,
                angle: float = 0.0) -> dict:
    """The strains of tracked walls (module docstring), without any tracking.

    Parameters
    ----------
    endo, epi : array_like, shape (F, m, 2) and (F, n, 2)
        Material nodes of the endocardium and epicardium (closed contours, node ``i`` the
        same material point in every frame); ``n = 0`` for the endocardium alone.
    reference : int
        Reference frame.
    segments : int
        Number of sectors N.
    angle : float
        Start of segment 1, degrees counterclockwise from +x as the image is shown.

    Returns
    -------
    dict
        ``radial``, ``circumferential``, ``circumferential_endo``, ``circumferential_epi``
        (F, N+1) in percent; ``outer`` (F, m, 2); ``segment_of_chord`` (m,); ``centre``.
    """
    endo = np.asarray(endo, dtype=float)
    epi = np.asarray(epi, dtype=float)
    ref = endo[reference]
    centre = polygon_centroid(ref)
    sector = _sectors(centre, angle, segments)
    nan = np.full((len(endo), segments + 1), np.nan)
    out = dict(circumferential_endo=_stretch(endo, sector(_midpoints(ref)), segments,
                                             reference),
               radial=nan, circumferential=nan.copy(), circumferential_epi=nan.copy(),
               outer=np.full_like(endo, np.nan), centre=centre,
               segment_of_chord=sector(ref))
    if epi.shape[1] == 0:
        return out
    j, t = _normal_hits(ref, epi[reference], centre)
    outer = (1 - t)[None, :, None] * epi[:, j] + t[None, :, None] * epi[:, (j + 1) %
                                                                         epi.shape[1]]
    mid = (endo + outer) / 2
    seg = sector(mid[reference])
    thick = np.linalg.norm(outer - endo, axis=2)
    out.update(radial=_ratio(thick, seg, segments, reference), outer=outer,
               circumferential=_stretch(mid, sector(_midpoints(mid[reference])), segments,
                                        reference),
               circumferential_epi=_stretch(epi, sector(_midpoints(epi[reference])),
                                            segments, reference),
               segment_of_chord=seg)
    return out


def polygon_centroid(p: np.ndarray) -> np.ndarray:
    """Centroid of the area inside a closed polygon (m, 2)."""
    q = np.roll(p, -1, axis=0)
    cross = p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]
    a = cross.sum() / 2
    return ((p + q) * cross[:, None]).sum(axis=0) / (6 * a)


def _sectors(centre: np.ndarray, angle: float, segments: int):
    """A function: points (k, 2) -> their segment 1..N by angle around ``centre``."""
    def sector(points):
        d = points - centre
        theta = np.degrees(np.arctan2(-d[:, 1], d[:, 0]))  # counterclockwise as shown
        return 1 + (np.mod(theta - angle, 360.0) // (360.0 / segments)).astype(np.intp) \
            % segments
    return sector


def _midpoints(p: np.ndarray) -> np.ndarray:
    return (p + np.roll(p, -1, axis=0)) / 2


def _ratio(values: np.ndarray, seg: np.ndarray, segments: int, reference: int):
    """Percent change of the sum of ``values`` (F, k) over each segment (and all)."""
    sums = np.stack([values.sum(axis=1)] + [values[:, seg == s].sum(axis=1)
                                            for s in range(1, segments + 1)], axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return 100.0 * (sums / sums[reference] - 1.0)


def _stretch(p: np.ndarray, seg: np.ndarray, segments: int, reference: int):
    """Percent change of the closed polyline's length per segment of its stretches."""
    lengths = np.linalg.norm(np.roll(p, -1, axis=1) - p, axis=2)
    return _ratio(lengths, seg, segments, reference)


def _normal_hits(endo: np.ndarray, epi: np.ndarray, centre: np.ndarray):
    """For every endocardial node, where its outward normal ray first meets the
    epicardium: the epicardial stretch ``j`` (nodes j, j+1) and the fraction ``t``."""
    tangent = np.roll(endo, -1, axis=0) - np.roll(endo, 1, axis=0)
    normal = np.c_[tangent[:, 1], -tangent[:, 0]]
    normal *= np.sign(np.einsum("ij,ij->i", normal, endo - centre))[:, None]
    a, b = epi, np.roll(epi, -1, axis=0)
    e = b - a
    # endo_i + s n_i = a_j + t e_j, solved for every (i, j) pair by Cramer's rule
    w = a[None, :, :] - endo[:, None, :]
    det = normal[:, None, 0] * (-e[None, :, 1]) + e[None, :, 0] * normal[:, None, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (w[..., 0] * (-e[None, :, 1]) + e[None, :, 0] * w[..., 1]) / det
        t = (normal[:, None, 0] * w[..., 1] - normal[:, None, 1] * w[..., 0]) / det
    ok = (s > 0) & (t >= 0) & (t <= 1) & np.isfinite(s)
    s = np.where(ok, s, np.inf)
    j = np.argmin(s, axis=1)
    rows = np.arange(len(endo))
    miss = ~np.isfinite(s[rows, j])
    if miss.any():  # a ray leaving through a gap: the nearest epicardial node instead
        j[miss] = np.argmin(np.linalg.norm(epi[None] - endo[miss, None], axis=2), axis=1)
        t[rows[miss], j[miss]] = 0.0
    return j, np.clip(t[rows, j], 0.0, 1.0)


def _reference_angle(opts: StrainOptions, ref_endo, masks, spacing) -> float:
    """Start of segment 1 (degrees): from the RV insertion point, the RV label or the
    option (see :class:`StrainOptions`)."""
    width = 360.0 / opts.segments
    centre = polygon_centroid(ref_endo)
    if opts.rv_point is not None:
        d = np.asarray(opts.rv_point, dtype=float) - centre
        _check_rv_point(opts.rv_point, d, ref_endo, masks, spacing)
        return float(np.mod(np.degrees(np.arctan2(-d[1], d[0])) - width, 360.0))
    if opts.rv_label is not None:
        if masks is None:
            raise OptionError("rv_label needs label images; give rv_point or "
                              "reference_angle with contours")
        rows, cols = np.nonzero(masks[opts.reference_frame] == opts.rv_label)
        if not len(rows):
            raise OptionError(f"rv_label: no pixel of label {opts.rv_label} in the "
                              f"reference frame {opts.reference_frame}")
        d = np.array([cols.mean() * spacing[0], rows.mean() * spacing[1]]) - centre
        return float(np.mod(np.degrees(np.arctan2(-d[1], d[0])) - 2 * width, 360.0))
    return float(opts.reference_angle)


def _check_rv_point(point, d: np.ndarray, ref_endo: np.ndarray, masks, spacing) -> None:
    """Refuse an RV point off the image (masks) or nearer the centre than
    :data:`RV_MIN_DISTANCE` (its direction means nothing)."""
    where, spacing = f"rv_point ({point[0]:g}, {point[1]:g})", np.asarray(spacing, float)
    if masks is not None:
        low, high = -0.5 * spacing, (np.array(masks.shape[:0:-1]) - 0.5) * spacing
        if np.any(np.asarray(point) < low) or np.any(np.asarray(point) > high):
            raise OptionError(f"{where} lies outside the image: x {low[0]:g}..{high[0]:g}, "
                              f"y {low[1]:g}..{high[1]:g} (image units, y down)")
    radius = np.linalg.norm(ref_endo - (point - d), axis=1).mean()
    if np.hypot(*d) < RV_MIN_DISTANCE * radius:
        raise OptionError(f"{where} lies {np.hypot(*d):.3g} from the ventricle's centre, "
                          f"under {RV_MIN_DISTANCE:g} x the endocardium's mean radius "
                          f"{radius:.3g}: it gives no direction for the segments; give the "
                          f"RV insertion point on the wall")


# ------------------------------------------------------------------------------ inputs


def _masks_of(frames, names):
    """``(masks (F, H, W) or None, spacing (x, y), unit, names, frames)`` of the inputs:
    masks, or (``masks`` None) the frames as contours (contour files read as Shapes)."""
    spacing, masks, unit = (1.0, 1.0), None, "px"
    paths = [frames] if isinstance(frames, str | Path) else list(frames) if (
        isinstance(frames, Sequence) and len(frames) and
        all(isinstance(f, str | Path) for f in frames)) else None
    if paths and all(Path(p).suffix.lower() in CONTOUR_FILES for p in paths):
        from .io import read_shape

        frames = [read_shape(p) for p in paths]
        names = tuple(Path(p).name for p in paths) if names is None else names
        unit = "input units" if frames[0].frame is None else frames[0].frame.unit
    elif paths:
        from .io.masks import read_masks

        read = read_masks(paths)
        masks, spacing, unit = read.frames, read.spacing, read.unit
        names = read.names if names is None else names
    elif isinstance(frames, np.ndarray) and frames.ndim == 3 or (
            isinstance(frames, Sequence) and len(frames) and
            all(isinstance(f, np.ndarray) and f.ndim == 2 and f.shape[1] != 2
                for f in frames)):
        shapes = {np.shape(f) for f in frames}
        if len(shapes) > 1:
            raise ShapeError(f"masks of different sizes: {sorted(shapes)}; all frames "
                             f"must have one size")
        masks = np.asarray(frames)
    n = len(masks) if masks is not None else len(frames)
    if n < 2:
        raise ShapeError(f"frames must hold at least 2 frames, got {n}")
    names = tuple(f"frame {i}" for i in range(n)) if names is None else tuple(map(str, names))
    if len(names) != n:
        raise ValueError(f"names must have one entry per frame ({n}), got {len(names)}")
    return masks, spacing, unit, names, frames


def mask_ring(mask, name: str, options: StrainOptions | None = None, *,
              spacing=(1.0, 1.0), say=None) -> tuple[np.ndarray, np.ndarray | None]:
    """``(endocardium (m, 2), epicardium (m, 2) or None)`` of a myocardium mask.

    The wall is the ``label`` pixels (or every non-zero pixel); of several 8-connected
    objects the chosen one (``object``, by io's rule, except that ``"largest"`` takes the
    largest object with a hole when the largest has none; said in a warning, or to ``say``
    when given); its largest hole is the endocardium, its outer boundary the epicardium,
    each resampled to ``nodes`` nodes, in ``(x, y) = (column, row) * spacing``.
    ``endo_only``: the hole, or without one the object's own boundary (a blood-pool
    mask).

    Raises
    ------
    ShapeError
        No object, or (not ``endo_only``) no hole: the message names the frame.
    """
    from scipy import ndimage

    opts = options or StrainOptions()
    mask = np.asarray(mask)
    wall = mask == opts.label if opts.label is not None else mask != 0
    if not wall.any():
        raise ShapeError(f"{name}: the mask is empty (no wall pixel)")
    say = say or (lambda text: warnings.warn(text, stacklevel=3))
    ring = _ring_object(wall, opts, name, say)
    hole = _largest_hole(ring)
    if not hole.any():
        if opts.endo_only:
            return _outline(ring, spacing), None
        several = "" if np.array_equal(ring, wall) else (
            "; none of the mask's objects has one" if opts.object == "largest" else
            f"; object={opts.object!r} chose it, object= chooses another")
        raise ShapeError(f"{name}: the wall has no hole (not a ring: no endocardium inside "
                         f"an epicardium{several}); check the label, or pass endo_only "
                         f"(--endo-only) for endocardial strain only")
    endo = _outline(hole, spacing)
    if opts.endo_only:
        return endo, None
    return endo, _outline(ndimage.binary_fill_holes(ring), spacing)


def _ring_object(wall: np.ndarray, opts: StrainOptions, name: str, say) -> np.ndarray:
    """The wall's object: io's choice, but for ``object="largest"`` (not ``endo_only``)
    the largest object with a hole, a wall, when the largest has none (said)."""
    from skimage.measure import label

    labels, count = label(wall, connectivity=2, return_num=True)  # io's numbering
    area = np.bincount(labels.ravel(), minlength=count + 1)[1:]
    ringed = (k for k in np.argsort(-area) if _largest_hole(labels == k + 1).any()) \
        if opts.object == "largest" and not opts.endo_only and count > 1 else iter(())
    pick, largest = int(next(ringed, -1)), int(np.argmax(area))  # the first hit only
    if pick < 0 or pick == largest:
        return choose_objects(wall, opts.object, name, connectivity=2, say=say)[0]
    say(f"{name}: object {pick + 1} of {count} (the largest with a hole, a wall; object "
        f"{largest + 1}, {area[largest]} px, has none): {area[pick]} px; object= chooses "
        f"another")
    return labels == pick + 1


def _largest_hole(region: np.ndarray) -> np.ndarray:
    """The largest hole of a region (bool), empty if none has :data:`MIN_HOLE_PIXELS`."""
    from scipy import ndimage

    holes, count = ndimage.label(ndimage.binary_fill_holes(region) & ~region)
    sizes = np.bincount(holes.ravel())[1:]
    return holes == 1 + np.argmax(sizes) if count and sizes.max() >= MIN_HOLE_PIXELS \
        else np.zeros_like(region)


def _outline(region: np.ndarray, spacing) -> np.ndarray:
    """The boundary of a region as a closed contour of ``nodes`` nodes (x, y)."""
    from scipy.ndimage import gaussian_filter
    from skimage.measure import find_contours

    pad = int(np.ceil(3 * SMOOTH)) + 1  # the blur spreads 3 sigma: closed contours
    blurred = gaussian_filter(np.pad(region.astype(float), pad), SMOOTH)
    contour = max(find_contours(blurred, 0.5), key=len)[:-1] - pad  # (row, col), open
    return contour[:, ::-1] * np.asarray(spacing, float)


def _shape_ring(shape, name: str, opts: StrainOptions):
    """``(endo, epi or None)`` of a ring Shape (epicardium first) or an endocardium."""
    if not isinstance(shape, Shape):
        shape = Shape(np.asarray(shape, dtype=float))
    sizes = shape.sizes
    if len(sizes) >= 2:
        epi, endo = shape.contour(0).points, shape.contour(1).points
        return endo, None if opts.endo_only else epi
    if opts.endo_only:
        return shape.points, None
    raise ShapeError(f"{name}: one contour, not a ring (an epicardium then an "
                     f"endocardium); pass endo_only for endocardial strain only")
