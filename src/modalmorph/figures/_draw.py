"""What the figures share: axes and layouts, colours, colour maps and bars, the view
(units, y down, the image under the shapes), the edges drawn, and saving figures.

A private module: its names are public so that the figure modules beside it can import
them; users import from :mod:`modalmorph.figures`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..options import FRAME_SPACINGS

COLOR_BY = ("load", "energy", None)  # what the moving shape is coloured by (None: the step)

# Source and target keep these colours in every figure; the colour maps below avoid them.
SOURCE_COLOR = "black"
TARGET_COLOR = "#d81b60"  # a strong magenta-red, absent from the colour maps below
MATCH_COLOR = "0.55"  # mid grey: the matches stay behind the two objects
SHAPE_COLOR = "#1f4e99"  # the moving shape when not coloured by a quantity
# The two distances a morph reports, each under its own name everywhere it is shown:
DISTANCE_NAME = "distance (stop test)"  # Morph.distance, compared with Morph.tolerance
MEAN_DISTANCE_NAME = "mean distance of matched pairs"  # Morph.mean_distance, per step
MEAN_DISTANCE_COLOR = "#d95f02"
ENERGY_UNIT = "$k_{ref} L^2$"  # energy unit: one node's stiffness x the source's RMS radius^2
_LABELS = {  # colour bars; {unit}: the coordinates' unit
    "load": "load magnitude $\\|R_i\\|$ (k x {unit})",
    "energy": f"strain energy per node $e_i$, signed ({ENERGY_UNIT})",
    None: "step",
}
# Figure sizes (inches) and fixed margins (constrained layout took 0.79 s, not 0.56 s):
# shapes with a colour bar on the right (room for its label), shapes without one, and
# charts (a twin axis on the right); legends above (the energy's: four lines and a title).
_LAYOUTS = {
    "bar": ((6.4, 5.4), dict(left=0.11, right=0.86, bottom=0.09, top=0.86)),
    "wide": ((6.4, 5.4), dict(left=0.11, right=0.97, bottom=0.09, top=0.86)),
    "chart": ((6.4, 4.4), dict(left=0.12, right=0.87, bottom=0.11, top=0.74)),
}
MARGIN = 0.04  # around what is drawn, on every side: a fraction of its larger side (as 3D had)
IMAGE_ALPHA = 0.25  # black shows as 75 % grey; 0.4 hid the horse's light early steps
ENERGY_COLORS = ("#3b4cc0", "0.6", "#b40426")  # coolwarm's ends; its 87 % grey hid e_i ~ 0
# Percentiles of the local energy spanned by its colours (issue 21): on a CSV glyph, SVG,
# horse mask and OFF egg the largest |e_i| was 1.1-5.9x this range; scaled to it, most grey.
ENERGY_RANGE = (2.0, 98.0)
NO_DEFORMATION = 1e-12  # |e_i| below this (k_ref L^2) is round-off: a translation gave 2e-14


# A legend entry's width in points: a character of its label at "small" (8.3 pt; DejaVu
# Sans averages 5.1 pt a character over frame names), plus the handle and the spacings.
LEGEND_CHAR_PT, LEGEND_HANDLE_PT = 5.2, 32.0


def short_names(names) -> tuple[str, ...]:
    """Frame names as a figure shows them: file paths without the folder they all share
    (``/data/lv/f01.csv`` -> ``f01.csv``), other names as they are."""
    names = tuple(map(str, names))
    folders = [os.path.dirname(n) for n in names]
    if not names or not all(folders):
        return names
    try:
        common = os.path.commonpath(folders)
    except ValueError:  # absolute and relative paths mixed
        return names
    return tuple(os.path.relpath(n, common) for n in names)


def import_matplotlib():
    """matplotlib, or an ImportError that says how to install it."""
    try:
        import matplotlib
    except ImportError as exc:  # pragma: no cover - exercised on a bare install
        raise ImportError("plotting needs matplotlib (a dependency of modalmorph): "
                          "pip install matplotlib") from exc
    return matplotlib


def new_axes(dim: int, layout: str = "bar"):
    """A fresh pyplot Axes (3D when ``dim == 3``) in one of the :data:`_LAYOUTS`; the
    caller owns its figure."""
    import_matplotlib()
    import matplotlib.pyplot as plt

    figsize, margins = _LAYOUTS[layout]
    fig = plt.figure(figsize=figsize)
    fig.subplots_adjust(**margins)
    return fig.add_subplot(projection="3d" if dim == 3 else None)


def new_figure(dim: int, layout: str = "bar"):
    """A Figure without pyplot (no layout engine: fixed margins) and its Axes."""
    from matplotlib.figure import Figure

    figsize, margins = _LAYOUTS[layout]
    fig = Figure(figsize=figsize)
    fig.subplots_adjust(**margins)
    return fig, fig.add_subplot(projection="3d" if dim == 3 else None)


def legend_above(ax, handles, labels, **kw):
    """A frameless legend just above the axes, where it hides no data: up to 3 columns,
    as many as the figure's width holds for its longest label."""
    entry = LEGEND_CHAR_PT * max(map(len, labels), default=0) + LEGEND_HANDLE_PT
    fits = int(ax.figure.get_figwidth() * 72 // max(entry, 1.0))
    return ax.legend(handles, labels, loc="lower center", bbox_to_anchor=(0.5, 1.0),
                     ncols=max(1, min(len(handles), 3, fits)), frameon=False,
                     fontsize="small", handlelength=1.6, columnspacing=1.2, **kw)


def is_3d(ax) -> bool:
    return getattr(ax, "name", "") == "3d"


def check_axes(ax, dim: int, layout: str = "bar"):
    """``ax``, or a new one, after checking that it is 3D exactly when the data are."""
    if ax is None:
        return new_axes(dim, layout)
    if is_3d(ax) != (dim == 3):
        want = "a 3D Axes (projection='3d')" if dim == 3 else "a 2D Axes"
        raise ValueError(f"{dim}D shapes need {want}, got a {ax.name!r} Axes")
    return ax


def check_every(every):
    if isinstance(every, bool) or not isinstance(every, int | np.integer) or every < 1:
        raise ValueError(f"every must be a positive integer, got {every!r}")


def check_frames(frames):
    if frames not in FRAME_SPACINGS:
        raise ValueError(f"frames must be one of {', '.join(FRAME_SPACINGS)}, got {frames!r}")


# --------------------------------------------------------------------------- topology


def describe(shape, name: str):
    """(points (m, d), closed, ordered, faces, sizes) of a Shape-like object or a bare
    array; ``faces`` None unless it is a triangle surface; ``sizes`` are the node counts
    of its contours (``None``: one contour)."""
    if hasattr(shape, "points"):
        pts = np.asarray(shape.points, dtype=np.float64)
        faces = getattr(shape, "faces", None)
        closed = bool(getattr(shape, "closed", True))
        ordered = getattr(shape, "ordered", None)
        sizes = getattr(shape, "contours", None)
    else:
        pts = np.asarray(shape, dtype=np.float64)
        faces, closed, ordered, sizes = None, True, None, None
    if pts.ndim != 2 or pts.shape[1] not in (2, 3):
        raise ValueError(f"{name} must have shape (m, 2) or (m, 3), got {pts.shape}")
    if ordered is None:
        ordered = pts.shape[1] == 2
    faces = np.asarray(faces) if faces is not None and len(faces) else None
    return pts, closed, bool(ordered), faces, sizes


def edges_of(m: int, closed: bool, ordered: bool, faces, sizes=None) -> np.ndarray:
    """Node pairs (e, 2) to draw: each contour (of ``sizes`` nodes, in row order; none
    joining one contour to the next), the mesh edges, or none for a point cloud."""
    if faces is not None:
        e = np.vstack([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
        return np.unique(np.sort(e, axis=1), axis=0)
    if ordered:
        parts = []
        for start, k in zip(np.cumsum([0, *(sizes or (m,))[:-1]]), sizes or (m,),
                            strict=True):
            i = np.arange(k if closed else k - 1)
            parts.append(start + np.column_stack([i, (i + 1) % k]))
        return np.vstack(parts)
    return np.empty((0, 2), dtype=int)


def half_segments(points: np.ndarray, edges: np.ndarray, values: np.ndarray):
    """Split each edge at its midpoint so each half carries its own node's value.

    Returns segments (2e, 2, d) and values (2e,): the polyline is coloured per node.
    """
    a, b = points[edges[:, 0]], points[edges[:, 1]]
    mid = 0.5 * (a + b)
    segs = np.concatenate([np.stack([a, mid], axis=1), np.stack([mid, b], axis=1)])
    return segs, np.concatenate([values[edges[:, 0]], values[edges[:, 1]]])


def line_collection(segments, ax, **kw):
    if is_3d(ax):
        from mpl_toolkits.mplot3d.art3d import Line3DCollection

        return Line3DCollection(segments, **kw)
    from matplotlib.collections import LineCollection

    return LineCollection(segments, **kw)


# ------------------------------------------------------------------------------ view


@dataclass(frozen=True)
class View:
    """How coordinates are drawn: their unit, whether y points down, the image under them
    (a file and its (height, width)) or None."""

    unit: str = "input units"
    y_down: bool = False
    image: str | None = None
    size: tuple | None = None


def view_of(target, source=None, *, background: bool = True) -> View:
    """The view of the target's ImageFrame, else of the source's; the image drawn is the
    target's only (the shapes are drawn in the target's coordinates)."""
    frame = getattr(target, "frame", None)
    own = frame is not None
    frame = frame if own else getattr(source, "frame", None)
    if frame is None:
        return View()
    image = frame.image if background and own and frame.size is not None else None
    return View(unit=frame.unit, y_down=frame.y_down, image=image, size=frame.size)


def draw_image(ax, view: View) -> bool:
    """Draw the view's image in grey under everything (pixel centres at integer x, y);
    whether it was drawn (a file that cannot be read any more is skipped, logged)."""
    if view.image is None or is_3d(ax):
        return False
    from PIL import Image

    try:
        with Image.open(view.image) as image:
            grey = np.asarray(image.convert("L"))
    except OSError as exc:
        import logging

        logging.getLogger(__name__).warning("cannot draw the image under the shapes: %s", exc)
        return False
    h, w = grey.shape
    ax.imshow(grey, cmap="gray", vmin=0, vmax=255, alpha=IMAGE_ALPHA, zorder=0,
              extent=(-0.5, w - 0.5, h - 0.5, -0.5), interpolation="nearest")
    return True


def finish_axes(ax, points: np.ndarray, view: View = View(), *, image: bool = False):
    """Equal aspect, axis labels with units, limits fixed to ``points`` (any (N, d)) and
    to the image when drawn; y pointing down for image coordinates.

    The limits are set once, explicitly: the box of ``points`` grown by :data:`MARGIN` of
    its larger side on every side (and to the whole image when drawn), then widened about
    its centre to the axes' aspect (2D); autoscaling is off. What is drawn later, the
    frames of an animation above all, lands where it was computed instead of rescaling
    the axes (the GIF drew a shape up to 2.2x its size when the first frame rescaled
    them). Lay out what takes room from the axes (a colour bar) before this.
    """
    names = ("x", "y", "z")[: points.shape[1]]
    labels = {f"{a}label": f"{a} ({view.unit})" for a in names}
    lo, hi = points.min(axis=0), points.max(axis=0)
    pad = MARGIN * max(float(np.max(hi - lo)), 1e-12)
    lo, hi = lo - pad, hi + pad
    if image:  # the whole image, no margin beyond it
        h, w = view.size
        lo, hi = np.minimum(lo, [-0.5, -0.5]), np.maximum(hi, [w - 0.5, h - 0.5])
    if is_3d(ax):
        ax.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), zlim=(lo[2], hi[2]), **labels)
        ax.set_box_aspect(np.maximum(hi - lo, 1e-12))
        return
    ax.set_aspect("equal", adjustable="box")  # a layout engine resizes the box, not the limits
    # the box the aspect is applied to (an image's own aspect may have shrunk the active one)
    box = ax.get_position(original=True).transformed(ax.figure.transFigure)
    lo, hi = fit_aspect(lo, hi, box.height / box.width)
    ax.set(xlim=(lo[0], hi[0]), ylim=(hi[1], lo[1]) if view.y_down else (lo[1], hi[1]),
           **labels)


def fit_aspect(lo: np.ndarray, hi: np.ndarray, ratio: float) -> tuple:
    """The 2D box (lo, hi) widened about its centre to height / width = ``ratio``."""
    centre, span = 0.5 * (lo + hi), hi - lo
    if span[1] < ratio * span[0]:
        span = np.array([span[0], ratio * span[0]])
    else:
        span = np.array([span[1] / ratio, span[1]])
    return centre - 0.5 * span, centre + 0.5 * span


# ------------------------------------------------------------------------ colouring


def check_color_by(color_by):
    if color_by not in COLOR_BY:
        raise ValueError(f"color_by must be one of 'load', 'energy' or None, got {color_by!r}")


def node_values(morph, color_by) -> np.ndarray:
    """(T+1, m) value of every node at every step for the chosen colouring."""
    shapes = np.asarray(morph.shapes)
    if color_by == "load":
        return np.linalg.norm(np.asarray(morph.loads, dtype=np.float64), axis=2)
    if color_by == "energy":
        return np.asarray(morph.node_energy, dtype=np.float64)
    steps = np.arange(shapes.shape[0], dtype=np.float64)
    return np.broadcast_to(steps[:, None], shapes.shape[:2])


@dataclass(frozen=True)
class Scale:
    """A colour scale: the map, its norm, which ends of the bar are clipped (``extend``:
    "neither", "min", "max" or "both", drawn as arrows) and ``flat``: every value is zero
    to round-off (one colour, labelled "no deformation")."""

    cmap: object
    norm: object
    extend: str = "neither"
    flat: bool = False


def colormap(color_by, values: np.ndarray) -> Scale:
    """The colour scale of the values shown; zero is grey or dark, never white.

    Loads are magnitudes (>= 0): viridis from 0, cut before its pale yellow end. Steps:
    blues from light (early) to dark (late). The local strain energy (25) is signed (on
    the bundled heart and hands its minimum is -5 to -63 % of its maximum) and a few
    nodes can hold most of it: its colours span the :data:`ENERGY_RANGE` percentiles of
    the values, symmetric about 0 (blue < 0, grey 0, red > 0, :data:`ENERGY_COLORS`;
    grey to red when none is negative), the values beyond drawn in the end colours. All
    values below :data:`NO_DEFORMATION` (a rigid motion's round-off): one grey, ``flat``.
    """
    import matplotlib as mpl
    from matplotlib.colors import ListedColormap, Normalize

    def part(name, lo, hi):
        return ListedColormap(mpl.colormaps[name](np.linspace(lo, hi, 256)), name=name)

    finite = values[np.isfinite(values)]
    top = float(np.max(np.abs(finite))) if finite.size else 1.0
    top = top if top > 0 else 1.0
    if color_by == "load":
        return Scale(part("viridis", 0.0, 0.92), Normalize(0.0, top))
    if color_by == "energy":
        return _energy_scale(finite)
    return Scale(part("Blues", 0.35, 1.0), Normalize(0.0, max(float(values.max()), 1.0)))


def _energy_scale(finite: np.ndarray) -> Scale:
    """:func:`colormap` of the local strain energy (finite values)."""
    from matplotlib.colors import CenteredNorm, LinearSegmentedColormap, ListedColormap, Normalize

    if not finite.size or np.max(np.abs(finite)) < NO_DEFORMATION:
        return Scale(ListedColormap([ENERGY_COLORS[1]], name="flat"),
                     CenteredNorm(0.0, halfrange=1.0), flat=True)
    lo, hi = np.percentile(finite, ENERGY_RANGE)
    signed = finite.min() < 0
    half = max(-float(lo), float(hi)) if signed else float(hi)
    if half < NO_DEFORMATION:  # nearly all zero, a few nodes strained: span those
        half = float(np.max(np.abs(finite)))
    below, above = signed and finite.min() < -half, finite.max() > half
    extend = {(False, False): "neither", (True, False): "min", (False, True): "max",
              (True, True): "both"}[(bool(below), bool(above))]
    if signed:
        return Scale(LinearSegmentedColormap.from_list("energy", ENERGY_COLORS),
                     CenteredNorm(0.0, halfrange=half), extend)
    return Scale(LinearSegmentedColormap.from_list("energy", ENERGY_COLORS[1:]),
                 Normalize(0.0, half), extend)


def colorbar(ax, mappable, color_by, *, unit: str, scale: Scale | None = None,
             label: str | None = None):
    """A colour bar labelled with the quantity and its unit (``label`` replaces the
    quantity's name); clipped ends as arrows; a flat energy as one colour, "no
    deformation"."""
    # 3D: the z label sits right of the box, beyond the tick labels; a pad of 0.08 put the
    # bar over it (shapes_*.png of a 3D morph), 0.2 clears it at the "bar" layout's size
    kw = {"shrink": 0.7, "pad": 0.2} if is_3d(ax) else {"pad": 0.03, "fraction": 0.06}
    text = _LABELS[color_by] if label is None else label
    if scale is not None and scale.flat:
        text = f"no deformation: $|e_i|$ < {NO_DEFORMATION:.0e} {ENERGY_UNIT}"
    cbar = ax.figure.colorbar(mappable, ax=ax, label=text.replace("{unit}", unit),
                              extend="neither" if scale is None else scale.extend, **kw)
    if color_by is None:
        from matplotlib.ticker import MaxNLocator

        n_steps = int(mappable.norm.vmax) + 1
        cbar.locator = MaxNLocator(integer=True, nbins=min(n_steps, 10))
        cbar.update_ticks()
    elif scale is not None and scale.flat:
        cbar.set_ticks([0.0], labels=["0"])
    elif color_by == "energy":
        cbar.formatter.set_powerlimits((-3, 4))
    return cbar


# ----------------------------------------------------------------------------- files


def save_draws(draws: dict, out: Path, dim: int, *, layouts: dict, formats,
               dpi) -> list[Path]:
    """Draw each figure of ``draws`` (stem -> function of an Axes) on its own Figure and
    save it in every format; ``layouts``: stem -> layout other than "bar" ("chart": a 2D
    chart)."""
    paths = []
    for stem, draw in draws.items():
        layout = layouts.get(stem, "bar")
        fig, ax = new_figure(2 if layout == "chart" else dim, layout)
        draw(ax)
        for fmt in formats:
            p = out / f"{stem}.{fmt}"
            fig.savefig(p, dpi=dpi)
            paths.append(p)
    return paths
