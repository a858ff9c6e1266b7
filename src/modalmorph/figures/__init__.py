"""Figures, animations and ParaView series of a morph (method §6: what the user sees).

Every function here imports matplotlib (or meshio) when called, so the core of
modalmorph stays numpy + scipy. The plotting functions take ``ax=None`` and return the
Axes they drew on; they never call ``plt.show()``. When no Axes is given they make a
pyplot figure, which the caller owns (close it with ``plt.close(ax.figure)``).
:func:`save_figures` and :func:`animate` build their figures without pyplot, so they
leave no open figures behind.

A *morph* here is the result of :func:`modalmorph.morph` (or anything with the same
fields): ``shapes`` (T+1, m, d) in the user's coordinates with step 0 the (aligned)
source, ``loads`` (T+1, m, d), ``energy`` (T+1,), ``node_energy`` (T+1, m),
``mean_distance`` (T+1,), ``matching.pairs`` (K, 2), ``similarity``, ``source``,
``target``, ``converged`` and ``message``.

Shapes in image coordinates (a :class:`~modalmorph.core.shape.ImageFrame` on the target, as
read from an image or SVG) are drawn with y pointing down, their axes in pixels, over
the image they were read from unless ``background=False``. Others are drawn with y up,
in the input's units.
"""

from __future__ import annotations

import math
import os
import secrets
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..options import FRAME_SPACINGS

__all__ = [
    "MAX_ANIMATION_FRAMES",
    "MAX_FIGURE_SHAPES",
    "animate",
    "animate_track",
    "frame_steps",
    "plot_batch",
    "plot_energy",
    "plot_matches",
    "plot_shapes",
    "plot_trajectories",
    "plot_track_curves",
    "save_figures",
    "save_track_figures",
]

COLOR_BY = ("load", "energy", None)

# Source and target keep these colours in every figure; the colour maps below avoid them.
SOURCE_COLOR = "black"
TARGET_COLOR = "#d81b60"  # a strong magenta-red, absent from the colour maps below
MATCH_COLOR = "0.55"
SHAPE_COLOR = "#1f4e99"  # the moving shape when not coloured by a quantity
# Units of the energy (pipeline.Morph.energy): one node's stiffness x the source's RMS
# radius squared, whatever the input's units.
ENERGY_UNIT = "$k_{ref} L^2$"
_LABELS = {  # colour bars; {unit}: the coordinates' unit
    "load": "load magnitude $\\|R_i\\|$ (k x {unit})",
    "energy": f"strain energy per node $e_i$ ({ENERGY_UNIT})",
    None: "step",
}
# Intermediate shapes drawn in the figures and frames of the animation, at most: evenly
# spaced (in time or along the path), as more add clutter and rendering time, not
# information. Measured on the heart run for 100 steps (247 nodes; best of 3 on the loaded
# 2-core machine): the GIF of 40 frames took 1.16 s, of all 101 frames 2.83 s; the energy
# figure (PNG) of 34 shapes 0.56 s, of all 101 shapes 1.14 s.
MAX_FIGURE_SHAPES = 30
MAX_ANIMATION_FRAMES = 40
# Figure sizes (inches) and fixed margins (with matplotlib's constrained layout the energy
# figure above took 0.79 s instead of 0.56 s): shapes with a colour bar on the right (room
# for its label), shapes without one, and charts (a twin axis on the right); legends above.
_LAYOUTS = {
    "bar": ((6.4, 5.4), dict(left=0.11, right=0.86, bottom=0.09, top=0.86)),
    "wide": ((6.4, 5.4), dict(left=0.11, right=0.97, bottom=0.09, top=0.86)),
    "chart": ((6.4, 4.2), dict(left=0.12, right=0.87, bottom=0.12, top=0.80)),
}
# Vector files (SVG, PDF) hold the intermediate shapes as an image (at the file's dpi) when
# they have more segments than this; axes, text, source and target stay vectors. Writing
# the five SVG figures of the heart (247 nodes, 7 steps, 11,652 segments drawn) took 1.4 s,
# about 0.12 ms per segment; rasterized, the four largest took 0.43 s.
RASTER_SEGMENTS = 1000
# Opacity of the grey source image under the shapes: a black background shows as 75 %
# grey, light enough for every colour map (0.4 hid the light early steps of the horse).
IMAGE_ALPHA = 0.25
# The local energy's colours (< 0, 0, > 0): coolwarm's ends around a mid grey, as its own
# 87 % grey centre made the many values near 0 vanish on white and over an image.
ENERGY_COLORS = ("#3b4cc0", "0.6", "#b40426")


def _matplotlib():
    try:
        import matplotlib
    except ImportError as exc:  # pragma: no cover - exercised on a bare install
        raise ImportError("plotting needs matplotlib (a dependency of modalmorph): "
                          "pip install matplotlib") from exc
    return matplotlib


def _new_axes(dim: int, layout: str = "bar"):
    """A fresh pyplot Axes (3D when ``dim == 3``) in one of the :data:`_LAYOUTS`; the
    caller owns its figure."""
    _matplotlib()
    import matplotlib.pyplot as plt

    figsize, margins = _LAYOUTS[layout]
    fig = plt.figure(figsize=figsize)
    fig.subplots_adjust(**margins)
    return fig.add_subplot(projection="3d" if dim == 3 else None)


def _new_figure(dim: int, layout: str = "bar"):
    """A Figure without pyplot (no layout engine: fixed margins) and its Axes."""
    from matplotlib.figure import Figure

    figsize, margins = _LAYOUTS[layout]
    fig = Figure(figsize=figsize)
    fig.subplots_adjust(**margins)
    return fig, fig.add_subplot(projection="3d" if dim == 3 else None)


def _legend_above(ax, handles, labels, **kw):
    """A frameless legend just above the axes, where it hides no data."""
    return ax.legend(handles, labels, loc="lower center", bbox_to_anchor=(0.5, 1.0),
                     ncols=min(len(handles), 3), frameon=False, fontsize="small",
                     handlelength=1.6, columnspacing=1.2, **kw)


def _is_3d(ax) -> bool:
    return getattr(ax, "name", "") == "3d"


def _check_axes(ax, dim: int, layout: str = "bar"):
    """``ax``, or a new one, after checking that it is 3D exactly when the data are."""
    if ax is None:
        return _new_axes(dim, layout)
    if _is_3d(ax) != (dim == 3):
        want = "a 3D Axes (projection='3d')" if dim == 3 else "a 2D Axes"
        raise ValueError(f"{dim}D shapes need {want}, got a {ax.name!r} Axes")
    return ax


def _check_every(every):
    if isinstance(every, bool) or not isinstance(every, int | np.integer) or every < 1:
        raise ValueError(f"every must be a positive integer, got {every!r}")


def _check_frames(frames):
    if frames not in FRAME_SPACINGS:
        raise ValueError(f"frames must be one of {', '.join(FRAME_SPACINGS)}, got {frames!r}")


# --------------------------------------------------------------------------- topology


def _describe(shape, name: str):
    """(points (m, d), closed, ordered, faces) of a Shape-like object or a bare array."""
    if hasattr(shape, "points"):
        pts = np.asarray(shape.points, dtype=np.float64)
        faces = getattr(shape, "faces", None)
        closed = bool(getattr(shape, "closed", True))
        ordered = getattr(shape, "ordered", None)
    else:
        pts = np.asarray(shape, dtype=np.float64)
        faces, closed, ordered = None, True, None
    if pts.ndim != 2 or pts.shape[1] not in (2, 3):
        raise ValueError(f"{name} must have shape (m, 2) or (m, 3), got {pts.shape}")
    if ordered is None:
        ordered = pts.shape[1] == 2
    return pts, closed, bool(ordered), None if faces is None else np.asarray(faces)


def _edges(m: int, closed: bool, ordered: bool, faces) -> np.ndarray:
    """Node pairs (e, 2) to draw: the contour, the mesh edges, or none for a point cloud."""
    if faces is not None and len(faces):
        e = np.vstack([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
        return np.unique(np.sort(e, axis=1), axis=0)
    if ordered:
        i = np.arange(m if closed else m - 1)
        return np.column_stack([i, (i + 1) % m])
    return np.empty((0, 2), dtype=int)


def _half_segments(points: np.ndarray, edges: np.ndarray, values: np.ndarray):
    """Split each edge at its midpoint so each half carries its own node's value.

    Returns segments (2e, 2, d) and values (2e,): the polyline is coloured per node.
    """
    a, b = points[edges[:, 0]], points[edges[:, 1]]
    mid = 0.5 * (a + b)
    segs = np.concatenate([np.stack([a, mid], axis=1), np.stack([mid, b], axis=1)])
    return segs, np.concatenate([values[edges[:, 0]], values[edges[:, 1]]])


def _line_collection(segments, ax, **kw):
    if _is_3d(ax):
        from mpl_toolkits.mplot3d.art3d import Line3DCollection

        return Line3DCollection(segments, **kw)
    from matplotlib.collections import LineCollection

    return LineCollection(segments, **kw)


# ------------------------------------------------------------------------------ view


@dataclass(frozen=True)
class _View:
    """How coordinates are drawn: their unit, whether y points down, the image under them
    (a file and its (height, width)) or None."""

    unit: str = "input units"
    y_down: bool = False
    image: str | None = None
    size: tuple | None = None


def _view(target, source=None, *, background: bool = True) -> _View:
    """The view of the target's ImageFrame, else of the source's; the image drawn is the
    target's only (the shapes are drawn in the target's coordinates)."""
    frame = getattr(target, "frame", None)
    own = frame is not None
    frame = frame if own else getattr(source, "frame", None)
    if frame is None:
        return _View()
    image = frame.image if background and own and frame.size is not None else None
    return _View(unit=frame.unit, y_down=frame.y_down, image=image, size=frame.size)


def _draw_image(ax, view: _View) -> bool:
    """Draw the view's image in grey under everything (pixel centres at integer x, y);
    whether it was drawn (a file that cannot be read any more is skipped, logged)."""
    if view.image is None or _is_3d(ax):
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


def _finish(ax, points: np.ndarray, view: _View = _View(), *, image: bool = False):
    """Equal aspect, axis labels with units, limits fitted to ``points`` (any (N, d)) or
    to the image when drawn; y pointing down for image coordinates."""
    names = ("x", "y", "z")[: points.shape[1]]
    labels = {f"{a}label": f"{a} ({view.unit})" for a in names}
    if _is_3d(ax):
        lo, hi = points.min(axis=0), points.max(axis=0)
        pad = 0.04 * max(float(np.max(hi - lo)), 1e-12)
        ax.set(xlim=(lo[0] - pad, hi[0] + pad), ylim=(lo[1] - pad, hi[1] + pad),
               zlim=(lo[2] - pad, hi[2] + pad), **labels)
        ax.set_box_aspect(np.maximum(hi - lo + 2 * pad, 1e-12))
        return
    if image:
        h, w = view.size
        points = np.vstack([points, [[-0.5, -0.5], [w - 0.5, h - 0.5]]])
    ax.update_datalim(points)
    ax.autoscale_view()
    ax.set_aspect("equal", adjustable="datalim")
    ax.set(**labels)
    if view.y_down:
        ax.yaxis.set_inverted(True)  # (keeps autoscaling: the aspect may widen the limits)


# ------------------------------------------------------------------------ colouring


def _check_color_by(color_by):
    if color_by not in COLOR_BY:
        raise ValueError(f"color_by must be one of 'load', 'energy' or None, got {color_by!r}")


def _node_values(morph, color_by) -> np.ndarray:
    """(T+1, m) value of every node at every step for the chosen colouring."""
    shapes = np.asarray(morph.shapes)
    if color_by == "load":
        return np.linalg.norm(np.asarray(morph.loads, dtype=np.float64), axis=2)
    if color_by == "energy":
        return np.asarray(morph.node_energy, dtype=np.float64)
    steps = np.arange(shapes.shape[0], dtype=np.float64)
    return np.broadcast_to(steps[:, None], shapes.shape[:2])


def _colormap(color_by, values: np.ndarray):
    """(cmap, norm) for the values shown; zero is grey or dark, never white.

    Loads are magnitudes (>= 0): viridis from 0, cut before its pale yellow end. The local
    strain energy (25) has both signs (on the bundled heart and hands, its minimum is -5
    to -63 % of its maximum, with either ``free_motion``): blue (< 0), grey (0), red
    (> 0) on one scale both sides of 0 (:data:`ENERGY_COLORS`); from grey to red when no
    value is negative. Steps: blues from light (early) to dark (late).
    """
    import matplotlib as mpl
    from matplotlib.colors import CenteredNorm, LinearSegmentedColormap, ListedColormap, Normalize

    def part(name, lo, hi):
        return ListedColormap(mpl.colormaps[name](np.linspace(lo, hi, 256)), name=name)

    finite = values[np.isfinite(values)]
    top = float(np.max(np.abs(finite))) if finite.size else 1.0
    top = top if top > 0 else 1.0
    if color_by == "load":
        return part("viridis", 0.0, 0.92), Normalize(0.0, top)
    if color_by == "energy":
        if finite.size and finite.min() < 0:
            return (LinearSegmentedColormap.from_list("energy", ENERGY_COLORS),
                    CenteredNorm(0.0, halfrange=top))
        return (LinearSegmentedColormap.from_list("energy", ENERGY_COLORS[1:]),
                Normalize(0.0, top))
    return part("Blues", 0.35, 1.0), Normalize(0.0, max(float(values.max()), 1.0))


def _colorbar(ax, mappable, color_by, *, unit: str, values=None):
    """A colour bar labelled with the quantity and its unit, spanning the values shown
    (a signed quantity's bar from its minimum to its maximum, 0 at the map's middle)."""
    kw = {"shrink": 0.75, "pad": 0.08} if _is_3d(ax) else {"pad": 0.03, "fraction": 0.06}
    cbar = ax.figure.colorbar(mappable, ax=ax, label=_LABELS[color_by].replace("{unit}", unit),
                              **kw)
    if color_by is None:
        from matplotlib.ticker import MaxNLocator

        n_steps = int(mappable.norm.vmax) + 1
        cbar.locator = MaxNLocator(integer=True, nbins=min(n_steps, 10))
        cbar.update_ticks()
    elif color_by == "energy":
        cbar.formatter.set_powerlimits((-3, 4))
        finite = values[np.isfinite(values)] if values is not None else np.empty(0)
        if finite.size and finite.min() < 0 < finite.max():
            cbar.ax.set_ylim(float(finite.min()), float(finite.max()))
    return cbar


# -------------------------------------------------------------------------- steps


def frame_steps(morph, frames: str = "time", count: int | None = None) -> np.ndarray:
    """Steps of a morph to draw: all of them, or ``count`` evenly spaced in time or along
    the path; ascending, always with the first and the last.

    Parameters
    ----------
    morph : Morph
        A morph result (uses ``shapes``).
    frames : {"time", "path"}
        ``"time"``: evenly spaced steps. ``"path"``: steps evenly spaced along the path,
        the cumulative mean node displacement: the damped dynamics make most of the way
        in the first steps, which evenly spaced steps show as a jump then a crawl.
    count : int, optional
        Steps wanted, at most (along the path, fewer where several fall on one step).
        Default, or ``count`` >= the steps: all of them.

    Returns
    -------
    ndarray of int
    """
    _check_frames(frames)
    shapes = np.asarray(morph.shapes, dtype=np.float64)
    n = shapes.shape[0]
    count = n if count is None else max(2, min(int(count), n))
    if count == n:
        return np.arange(n)
    if frames == "time":
        return np.unique(np.rint(np.linspace(0, n - 1, count)).astype(np.intp))
    moved = np.linalg.norm(np.diff(shapes, axis=0), axis=2).mean(axis=1)
    path = np.r_[0.0, np.cumsum(moved)]
    if path[-1] <= 0:
        return frame_steps(morph, "time", count)
    wanted = np.linspace(0.0, path[-1], count)
    after = np.clip(np.searchsorted(path, wanted), 1, n - 1)
    nearer = np.where(wanted - path[after - 1] < path[after] - wanted, after - 1, after)
    return np.unique(np.r_[0, nearer, n - 1])


def _drawn_steps(n_steps: int, every: int, frames: str, morph) -> np.ndarray:
    """Every ``every``-th step and the last, or as many spaced along the path."""
    timed = np.unique(np.r_[np.arange(0, n_steps, every), n_steps - 1])
    return timed if frames == "time" else frame_steps(morph, "path", len(timed))


# ------------------------------------------------------------------------- figures


def _check_pairs(pairs, n_source: int, n_target: int) -> np.ndarray:
    pairs = np.asarray(pairs)
    if pairs.size == 0:
        pairs = np.empty((0, 2), dtype=int)
    if pairs.ndim != 2 or pairs.shape[1] != 2 or not np.issubdtype(pairs.dtype, np.integer):
        raise ValueError(f"pairs must be an integer array of shape (K, 2), got "
                         f"{pairs.dtype} {pairs.shape}")
    if len(pairs) and (pairs.min() < 0 or pairs[:, 0].max() >= n_source
                       or pairs[:, 1].max() >= n_target):
        raise ValueError(f"pairs index nodes outside the source (0..{n_source - 1}) or "
                         f"the target (0..{n_target - 1})")
    return pairs


def plot_matches(source, target, pairs, *, background: bool = True, ax=None):
    """Draw the source and target nodes and the matches between them.

    Parameters
    ----------
    source, target : Shape or array_like, shape (m, d) and (n, d)
        The two objects; a :class:`~modalmorph.Shape` (or anything with ``points``,
        ``closed``, ``faces``) is drawn as its contour or mesh, a bare 2D array as a
        closed contour, a bare 3D array as a point cloud.
    pairs : array_like of int, shape (K, 2)
        Matches as (source index, target index), e.g. ``morph.matching.pairs``.
    background : bool, optional
        Draw the target's source image under the shapes (shapes read from an image).
    ax : matplotlib Axes, optional
        Where to draw (a 3D Axes for 3D objects). A new figure is made if omitted.

    Returns
    -------
    matplotlib.axes.Axes
    """
    src, s_closed, s_ordered, _ = _describe(source, "source")
    tgt, t_closed, t_ordered, _ = _describe(target, "target")
    if src.shape[1] != tgt.shape[1]:
        raise ValueError(f"source and target must have the same dimension, got "
                         f"{src.shape[1]} and {tgt.shape[1]}")
    pairs = _check_pairs(pairs, len(src), len(tgt))
    dim = src.shape[1]
    ax = _check_axes(ax, dim, "wide")
    from matplotlib.lines import Line2D

    view = _view(target, source, background=background)
    image = _draw_image(ax, view)
    segs = np.stack([src[pairs[:, 0]], tgt[pairs[:, 1]]], axis=1)
    ax.add_collection(_line_collection(segs, ax, colors=MATCH_COLOR, linewidths=0.6,
                                       zorder=1))
    for pts, closed, ordered, color, marker, who in (
        (src, s_closed, s_ordered, SOURCE_COLOR, "o", "source"),
        (tgt, t_closed, t_ordered, TARGET_COLOR, "s", "target"),
    ):
        edges = _edges(len(pts), closed, ordered, None)  # contours only: meshes clutter
        if len(edges):
            ax.add_collection(_line_collection(pts[edges], ax, colors=color, linewidths=0.8,
                                               alpha=0.6, zorder=2))
        ax.scatter(*pts.T, s=14 if dim == 2 else 8, c=color, marker=marker, linewidths=0,
                   zorder=3, label=f"{who} ({len(pts)} nodes)")
    handles, labels = ax.get_legend_handles_labels()
    handles.append(Line2D([], [], color=MATCH_COLOR, lw=0.8))
    labels.append(f"matches ({len(pairs)})")
    _legend_above(ax, handles, labels)
    _finish(ax, np.vstack([src, tgt]), view, image=image)
    return ax


def plot_shapes(morph, *, color_by="energy", every: int = 1, frames: str = "time",
                background: bool = True, ax=None):
    """Draw the intermediate shapes of a morph in order (the paper's figure).

    Contours (and 3D polylines) are drawn as one polyline per step, coloured per node by
    the load magnitude or the local strain energy at that step, or in grey levels from
    light (early) to dark (late) when ``color_by`` is None; a colour bar gives the scale.
    3D surfaces and point clouds are drawn as the path of every node over the steps
    (coloured the same way) and the final shape. The source (step 0) and the target are
    drawn on top in fixed colours.

    Parameters
    ----------
    morph : Morph
        A morph result (see the module docstring for the fields used).
    color_by : {"energy", "load", None}, optional
        ``"energy"``: the local strain energy e_i (25), signed (diverging map, one scale
        both sides of 0); ``"load"``: the magnitude of the load R_i (19)-(20), from 0;
        None: the step number in grey levels.
    every : int, optional
        Draw every ``every``-th step (the last step is always drawn).
    frames : {"time", "path"}, optional
        ``"path"``: draw as many steps, evenly spaced along the path (:func:`frame_steps`).
    background : bool, optional
        Draw the target's source image under the shapes (shapes read from an image).
    ax : matplotlib Axes, optional
        Where to draw (a 3D Axes for 3D shapes). A new figure is made if omitted.

    Returns
    -------
    matplotlib.axes.Axes
    """
    _check_color_by(color_by)
    _check_every(every)
    _check_frames(frames)
    shapes = np.asarray(morph.shapes, dtype=np.float64)
    _, closed, ordered, faces = _describe(morph.source, "morph.source")
    tgt, *_ = _describe(morph.target, "morph.target")
    ax = _check_axes(ax, shapes.shape[2])
    view = _view(morph.target, morph.source, background=background)
    image = _draw_image(ax, view)
    values = _node_values(morph, color_by)
    cmap, norm = _colormap(color_by, values)
    drawn = _drawn_steps(len(shapes), every, frames, morph)
    edges = _edges(shapes.shape[1], closed, ordered, faces)
    contour = faces is None and len(edges) > 0
    lines = _step_lines(ax, shapes, values, drawn, edges if contour else None)
    lines.set(cmap=cmap, norm=norm)
    ax.add_collection(lines)
    if faces is not None and len(faces):
        _draw_surface(ax, shapes[-1], faces, values[-1] if color_by else None, cmap, norm)
    elif not contour:  # the final cloud's nodes, coloured by their value
        ax.scatter(*shapes[-1].T, c=values[-1], cmap=cmap, norm=norm, s=14, zorder=3,
                   linewidths=0)
    t_line = _draw_ends(ax, morph.target, shapes[0], tgt)
    kind = "contour" if contour else "surface" if faces is not None and len(faces) else "cloud"
    _shapes_legend(ax, morph, cmap(0.75), kind, color_by, t_line)
    _colorbar(ax, lines, color_by, unit=view.unit, values=values[drawn])
    _finish(ax, np.vstack([shapes.reshape(-1, shapes.shape[2]), tgt]), view, image=image)
    return ax


def _step_lines(ax, shapes, values, drawn, edges):
    """One LineCollection of the drawn steps: each step's contour (``edges``), each
    half-edge coloured by its node; or, for surfaces and clouds (``edges`` None), each
    node's path, segment j-1 -> j coloured by step j."""
    if edges is not None:
        parts = [_half_segments(shapes[j], edges, values[j]) for j in drawn]
        segs = np.concatenate([p[0] for p in parts])
        vals = np.concatenate([p[1] for p in parts])
        width = 1.2
    else:
        segs = np.stack([shapes[drawn[:-1]], shapes[drawn[1:]]], axis=2)
        segs = segs.reshape(-1, 2, shapes.shape[2])
        vals = values[drawn[1:]].reshape(-1)
        width = 0.6
    lines = _line_collection(segs, ax, zorder=2, capstyle="round", linewidths=width,
                             rasterized=len(segs) > RASTER_SEGMENTS)
    lines.set_array(vals)
    return lines


def _draw_surface(ax, points, faces, values, cmap, norm):
    """The final surface: faces coloured by the mean value of their nodes, or (values
    None) light grey shaded by the faces' normals (either orientation)."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    tri = points[faces]
    surf = Poly3DCollection(tri, alpha=0.9, edgecolors="0.3", linewidths=0.15, zorder=3)
    if values is None:
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
        light = np.abs(normal @ np.array([-0.4, -0.5, 0.77]))
        surf.set_facecolor(np.c_[np.repeat(0.55 + 0.4 * light[:, None], 3, axis=1),
                                 np.full(len(tri), 0.9)])
    else:
        surf.set(cmap=cmap, norm=norm, array=values[faces].mean(axis=1))
    ax.add_collection3d(surf)


def _draw_ends(ax, target, start, tgt) -> bool:
    """The source's nodes (step 0) and the target (dashed contour and nodes) on top;
    whether the target was drawn as a line."""
    _, t_closed, t_ordered, t_faces = _describe(target, "morph.target")
    dim = start.shape[1]
    size = 9 if dim == 2 else 5
    ax.scatter(*start.T, s=size, c=SOURCE_COLOR, marker="o", linewidths=0, zorder=4)
    t_edges = _edges(len(tgt), t_closed, t_ordered, t_faces)
    if len(t_edges) and t_faces is None:
        ax.add_collection(_line_collection(tgt[t_edges], ax, colors=TARGET_COLOR,
                                           linewidths=1.0, linestyles="--", zorder=4))
    ax.scatter(*tgt.T, s=size + 3, c=TARGET_COLOR, marker="s", linewidths=0, zorder=5,
               alpha=1.0 if dim == 2 else 0.6)
    return bool(len(t_edges)) and t_faces is None


def _shapes_legend(ax, morph, mid, kind: str, color_by, t_line: bool):
    """The legend of :func:`plot_shapes`: source, intermediate shapes (or node paths and
    the final surface or nodes), target; ``mid`` a representative colour."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    last = len(morph.shapes) - 1
    aligned = getattr(morph, "similarity", None) is not None
    handles = [Line2D([], [], color=SOURCE_COLOR, marker="o", ms=4, ls="none"),
               Line2D([], [], color=mid, lw=1.5 if kind == "contour" else 1.0)]
    labels = [f"source{' (aligned)' if aligned else ''} (step 0)",
              f"intermediate shapes (steps 1-{last})" if kind == "contour" else "node paths"]
    if kind == "surface":
        handles.append(Patch(facecolor="0.8" if color_by is None else mid, edgecolor="0.35"))
        labels.append(f"final surface (step {last})")
    elif kind == "cloud":
        handles.append(Line2D([], [], color=mid, marker="o", ms=4, ls="none"))
        labels.append(f"final nodes (step {last})")
    handles.append(Line2D([], [], color=TARGET_COLOR, marker="s", ms=4,
                          ls="--" if t_line else "none"))
    labels.append("target")
    _legend_above(ax, handles, labels)


def plot_energy(morph, *, ax=None):
    """Global strain energy per step, with the mean distance to the target on a twin axis.

    Parameters
    ----------
    morph : Morph
        A morph result: uses ``energy``, ``mean_distance`` and ``message``.
    ax : matplotlib Axes, optional
        Where to draw the energy; the distance goes on ``ax.twinx()``.

    Returns
    -------
    matplotlib.axes.Axes
        The energy axes; the distance axes is its twin (the figure's last Axes).
    """
    energy = np.asarray(morph.energy, dtype=np.float64)
    distance = np.asarray(morph.mean_distance, dtype=np.float64)
    if ax is None:
        ax = _new_axes(2, "chart")
    from matplotlib.ticker import MaxNLocator

    steps = np.arange(len(energy))
    marker = "o" if len(steps) <= 40 else None
    (e_line,) = ax.plot(steps, energy, color=SHAPE_COLOR, marker=marker, ms=4,
                        label="global strain energy $E$ (22)")
    ax.set(xlabel="step", ylabel=f"global strain energy $E$ ({ENERGY_UNIT})",
           xlim=(0, max(len(steps) - 1, 1)))
    ax.set_ylim(bottom=min(0.0, float(np.nanmin(energy))))
    ax.yaxis.get_major_formatter().set_powerlimits((-3, 4))
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.grid(True, alpha=0.3)
    twin = ax.twinx()
    (d_line,) = twin.plot(steps, distance, color="#d95f02", ls="--", marker=marker, ms=4,
                          mfc="white", label="mean distance to target")
    twin.set_ylabel(f"mean distance to target ({_view(morph.target, morph.source).unit})")
    twin.set_ylim(bottom=0.0)
    import textwrap

    status = "converged" if getattr(morph, "converged", False) else "not converged"
    reason = textwrap.fill(getattr(morph, "message", "") or status, 70)
    _legend_above(ax, [e_line, d_line], [e_line.get_label(), d_line.get_label()],
                  title=reason, title_fontsize="small")
    return ax


def plot_batch(results, *, ax=None):
    """One point per completed item of a batch: final distance against strain energy.

    Parameters
    ----------
    results : sequence of ItemResult
        The rows of :func:`modalmorph.apps.batch.run` (``Batch.results``); items without
        numbers (failed, interrupted) are counted in the title.
    ax : matplotlib Axes, optional

    Returns
    -------
    matplotlib.axes.Axes
    """
    if ax is None:
        ax = _new_axes(2, "chart")
    done = [r for r in results if r.distance is not None and r.energy is not None]
    for kind, color in (("pair", SHAPE_COLOR), ("sequence", "#d95f02")):
        for converged, marker in ((True, "o"), (False, "x")):
            rows = [r for r in done if r.kind == kind and bool(r.converged) == converged]
            if rows:
                ax.scatter([r.distance for r in rows], [r.energy for r in rows], s=18,
                           color=color, marker=marker, label=f"{kind}s, " + (
                               "converged" if converged else "not converged"))
    ax.set(xlabel="final distance to target (input units)",
           ylabel=f"strain energy ({ENERGY_UNIT})",
           title=f"{len(done)} of {len(results)} items done"
                 + (f", {len(results) - len(done)} failed or not run"
                    if len(done) < len(results) else ""))
    ax.grid(True, alpha=0.3)
    if done:
        ax.legend(fontsize="small")
    return ax


# ------------------------------------------------------------------ animation, files

# Resolution of the animation's frames: 6.4 x 5.4 in at 80 dpi is 512 x 432 px, text
# still legible; the 40 frames above took 1.16 s at 80 dpi, 1.67 s at 100 dpi.
GIF_DPI = 80
# Resolution of the raster figures (PNG): 960 x 810 px; the energy figure above took
# 0.56 s at 150 dpi, 0.71 s at 200 dpi.
FIGURE_DPI = 150


def animate(morph, path, *, fps: int = 10, color_by="energy", dpi: int = GIF_DPI,
            frames: str = "time", background: bool = True,
            max_frames: int = MAX_ANIMATION_FRAMES) -> Path:
    """Write an animation of the deformation.

    Each frame shows the shape at one step coloured per node (as :func:`plot_shapes`,
    one colour scale for all frames), the source and the target drawn faintly; the fixed
    parts are drawn once, each frame only the moving shape over them.

    Parameters
    ----------
    morph : Morph
        A morph result.
    path : str or Path
        Output file: ``.gif`` (Pillow) or ``.mp4`` (needs ffmpeg on the PATH).
    fps, dpi : int, optional
        Frames per second; resolution of the frames.
    color_by : {"energy", "load", None}, optional
        As in :func:`plot_shapes`; None draws every frame in one colour.
    frames : {"time", "path"}, optional
        Steps shown (:func:`frame_steps`), at most ``max_frames``: evenly spaced in time,
        or along the path (the damped motion makes most of its way in the first steps).
    background : bool, optional
        Draw the target's source image under the shapes (shapes read from an image).

    Returns
    -------
    Path
        ``path``, written atomically (a temporary file renamed at the end, so a failure
        leaves no partial file). A ValueError for a suffix other than ``.gif`` or
        ``.mp4``, or ``.mp4`` without ffmpeg.
    """
    _check_color_by(color_by)
    _check_frames(frames)
    if fps <= 0:
        raise ValueError(f"fps must be positive, got {fps!r}")
    path = Path(path)
    suffix = path.suffix.lower()
    _matplotlib()
    from matplotlib import animation

    if suffix not in (".gif", ".mp4"):
        raise ValueError(f"path must end in .gif or .mp4, got {path.name!r}")
    if suffix == ".mp4" and not animation.writers.is_available("ffmpeg"):
        raise ValueError(f"writing {path.name} needs ffmpeg on the PATH; install it or ask "
                         f"for a .gif")
    scene = _Scene(morph, color_by, background=background, dpi=dpi)
    steps = frame_steps(morph, frames, max_frames)
    # a unique name beside the target, same suffix (ffmpeg picks its format from it)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}-{secrets.token_hex(4)}.tmp{suffix}")
    try:
        _write_animation(scene, steps, tmp, fps=fps, dpi=dpi)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def _write_animation(scene, steps, path: Path, *, fps: int, dpi: int) -> None:
    """Write the frames of ``steps``: a GIF with Pillow, an MP4 with ffmpeg."""
    if path.suffix.lower() == ".gif":
        images = _gif_frames(scene, steps)
        images[0].save(path, format="GIF", save_all=True, append_images=images[1:],
                       duration=round(1000 / fps), loop=0)
        return
    from matplotlib import animation

    writer = animation.FFMpegWriter(fps=fps)
    with writer.saving(scene.fig, path, dpi=dpi):
        for j in steps:
            scene.show(j)
            writer.grab_frame()


def _gif_frames(scene, steps) -> list:
    """The frames as palette images: the fixed parts rendered once (Agg), then for each
    step that background restored and only the moving shape and the title drawn."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from PIL import Image

    canvas = FigureCanvasAgg(scene.fig)
    scene.ax.title.set_animated(True)
    canvas.draw()
    clean = canvas.copy_from_bbox(scene.fig.bbox)
    images = []
    for j in steps:
        canvas.restore_region(clean)
        for artist in scene.show(j, animated=True):
            if hasattr(artist, "do_3d_projection"):
                artist.do_3d_projection()  # (what Axes3D.draw does before drawing)
            scene.ax.draw_artist(artist)
        scene.ax.draw_artist(scene.ax.title)
        rgb = Image.fromarray(np.asarray(canvas.buffer_rgba())[..., :3])
        images.append(rgb.quantize(colors=255, method=Image.Quantize.FASTOCTREE))
    return images


class _Scene:
    """An animation's figure: the fixed parts (image, faint source and target, colour
    bar, legend) laid out once; :meth:`show` draws the shape at one step over them."""

    def __init__(self, morph, color_by, *, background: bool, dpi: int):
        shapes = np.asarray(morph.shapes, dtype=np.float64)
        _, closed, ordered, faces = _describe(morph.source, "morph.source")
        self.shapes, self.last = shapes, len(shapes) - 1
        self.faces = faces if faces is not None and len(faces) else None
        self.edges = _edges(shapes.shape[1], closed, ordered, None)
        if color_by is None:
            self.values, self.cmap, self.norm = np.zeros(shapes.shape[:2]), None, None
        else:
            self.values = _node_values(morph, color_by)
            self.cmap, self.norm = _colormap(color_by, self.values)
        self.fig, self.ax = _new_figure(shapes.shape[2])
        self.fig.set_dpi(dpi)
        view = _view(morph.target, morph.source, background=background)
        image = _draw_image(self.ax, view)
        handles = _faint_ends(self.ax, shapes[0], morph.source, morph.target)
        tgt = _describe(morph.target, "morph.target")[0]
        _finish(self.ax, np.vstack([shapes.reshape(-1, shapes.shape[2]), tgt]), view,
                image=image)
        if color_by is not None:
            from matplotlib.cm import ScalarMappable

            _colorbar(self.ax, ScalarMappable(norm=self.norm, cmap=self.cmap), color_by,
                      unit=view.unit, values=self.values)
        handles.insert(0, _current_handle(self.cmap, self.faces is not None,
                                          bool(len(self.edges))))
        self.ax.legend(handles=handles, loc="lower right", bbox_to_anchor=(1.0, 1.0),
                       ncols=3, frameon=False, fontsize="small")  # step number: left
        self.artists = []

    def show(self, j: int, *, animated: bool = False) -> list:
        """Replace the moving shape by the one at step ``j``; the new artists."""
        for artist in self.artists:
            artist.remove()
        self.artists = _draw_frame(self.ax, self.shapes[j], self.edges, self.faces,
                                   self.values[j], self.cmap, self.norm)
        for artist in self.artists:
            artist.set_animated(animated)
        self.ax.set_title(f"step {j} / {self.last}", loc="left", fontsize="medium")
        return self.artists


def _faint_ends(ax, start, source, target) -> list:
    """The fixed background of the animation, faint: the source at step 0 (``start``) and
    the target, contours as lines, surfaces and clouds as nodes; their legend handles."""
    from matplotlib.lines import Line2D

    _, s_closed, s_ordered, _ = _describe(source, "morph.source")
    tgt, t_closed, t_ordered, _ = _describe(target, "morph.target")
    handles = []
    for pts, closed, ordered, color, marker, label in (
        (start, s_closed, s_ordered, SOURCE_COLOR, "o", "source"),
        (tgt, t_closed, t_ordered, TARGET_COLOR, "s", "target"),
    ):
        e = _edges(len(pts), closed, ordered, None)
        if len(e):
            ax.add_collection(_line_collection(pts[e], ax, colors=color, linewidths=0.9,
                                               alpha=0.35, zorder=1))
        ax.scatter(*pts.T, s=5, c=color, marker=marker, alpha=0.35, linewidths=0, zorder=1)
        handles.append(Line2D([], [], color=color, alpha=0.5, marker=marker, ms=3,
                              ls="-" if len(e) else "none", label=label))
    return handles


def _current_handle(cmap, surface: bool, lines: bool):
    """The legend handle of the moving shape."""
    one = SHAPE_COLOR if cmap is None else cmap(0.75)
    if surface:
        from matplotlib.patches import Patch

        return Patch(facecolor=one, edgecolor="0.3", label="shape at the step")
    from matplotlib.lines import Line2D

    return Line2D([], [], color=one, lw=2.0, marker="o", ms=3, mec="0.15",
                  ls="-" if lines else "none", label="shape at the step")


def _draw_frame(ax, points, edges, faces, values, cmap, norm):
    """The artists of one animation frame: the shape at one step, coloured per node."""
    if faces is not None:
        from mpl_toolkits.mplot3d.art3d import Poly3DCollection

        kw = {"facecolors": SHAPE_COLOR} if cmap is None else {"cmap": cmap, "norm": norm}
        surf = Poly3DCollection(points[faces], edgecolors="0.3", linewidths=0.15,
                                alpha=0.9, zorder=3, **kw)
        if cmap is not None:
            surf.set_array(values[faces].mean(axis=1))
        ax.add_collection3d(surf)
        return [surf]
    artists = []
    if len(edges):
        kw = {"colors": SHAPE_COLOR} if cmap is None else {"cmap": cmap, "norm": norm}
        # a dark casing under the coloured line: the moving shape stands out from the
        # faint source and target even where its colour is pale (values near zero)
        casing = _line_collection(points[edges], ax, colors="0.15", linewidths=3.0,
                                  zorder=3, capstyle="round")
        segs, vals = _half_segments(points, edges, values)
        lines = _line_collection(segs, ax, linewidths=1.8, zorder=3, capstyle="round", **kw)
        if cmap is not None:
            lines.set_array(vals)
        for artist in (casing, lines):
            ax.add_collection(artist, autolim=False)
            artists.append(artist)
    kw = {"c": SHAPE_COLOR} if cmap is None else {"c": values, "cmap": cmap, "norm": norm}
    artists.append(ax.scatter(*points.T, s=10 if len(edges) else 16, zorder=4,
                              edgecolors="0.15", linewidths=0.5, **kw))
    return artists


def save_figures(morph, out_dir, *, formats=("png", "svg"), dpi: int = FIGURE_DPI,
                 background: bool = True, frames: str = "time") -> list[Path]:
    """Write the standard figures of a morph, in every format asked for.

    The figures are ``matches`` (:func:`plot_matches` on the aligned source),
    ``shapes_plain``, ``shapes_load``, ``shapes_energy`` (:func:`plot_shapes` with
    ``color_by`` None, "load", "energy"; at most :data:`MAX_FIGURE_SHAPES` steps) and
    ``energy`` (:func:`plot_energy`).

    Parameters
    ----------
    morph : Morph
        A morph result.
    out_dir : str or Path
        Directory to write into (created if missing).
    formats : sequence of str, optional
        File formats matplotlib can write (``"png"``, ``"svg"``, ``"pdf"``, ...).
    dpi : int, optional
        Resolution of raster formats.
    background : bool, optional
        Draw the source image under shapes read from an image.
    frames : {"time", "path"}, optional
        The steps drawn, evenly spaced in time or along the path (:func:`frame_steps`).

    Returns
    -------
    list of Path
        The files written, figure by figure, format by format.
    """
    formats = (formats,) if isinstance(formats, str) else tuple(formats)
    _check_frames(frames)
    _matplotlib()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    shapes = np.asarray(morph.shapes)
    source = morph.source
    if hasattr(source, "with_points"):  # the matches are drawn on the shape that was morphed
        source = source.with_points(shapes[0])
    elif not hasattr(source, "points"):
        source = shapes[0]
    every = math.ceil(len(shapes) / MAX_FIGURE_SHAPES)
    kw = dict(every=every, frames=frames, background=background)
    draws = {
        "matches": lambda ax: plot_matches(source, morph.target, morph.matching.pairs,
                                           background=background, ax=ax),
        "shapes_plain": lambda ax: plot_shapes(morph, color_by=None, ax=ax, **kw),
        "shapes_load": lambda ax: plot_shapes(morph, color_by="load", ax=ax, **kw),
        "shapes_energy": lambda ax: plot_shapes(morph, color_by="energy", ax=ax, **kw),
        "energy": lambda ax: plot_energy(morph, ax=ax),
    }
    return _save_draws(draws, out, shapes.shape[2], layouts=dict(matches="wide",
                                                                 energy="chart"),
                       formats=formats, dpi=dpi)


def _save_draws(draws: dict, out: Path, dim: int, *, layouts: dict, formats,
                dpi) -> list[Path]:
    """Draw each figure of ``draws`` (stem -> function of an Axes) on its own Figure and
    save it in every format; ``layouts``: stem -> layout other than "bar" ("chart": a 2D
    chart)."""
    paths = []
    for stem, draw in draws.items():
        layout = layouts.get(stem, "bar")
        fig, ax = _new_figure(2 if layout == "chart" else dim, layout)
        draw(ax)
        for fmt in formats:
            p = out / f"{stem}.{fmt}"
            fig.savefig(p, dpi=dpi)
            paths.append(p)
    return paths


# --------------------------------------------------------------------------------------
# sequences (modalmorph.track)


def _as_morph(track):
    """A Track seen as a morph whose steps are the frames (for plot_shapes, animate)."""
    from types import SimpleNamespace

    return SimpleNamespace(shapes=track.points, node_energy=track.node_energy,
                           loads=np.zeros_like(track.points), source=track.frames[0],
                           target=track.frames[-1], similarity=None)


def plot_trajectories(track, *, every: int = 1, background: bool = True, ax=None):
    """Draw the path of every ``every``-th tracked node over the frames, coloured by
    frame, over frame 0's shape (black) and the last frame's (magenta), and over the last
    frame's image when it was read from one (``background``).

    Returns the Axes."""
    _check_every(every)
    points = np.asarray(track.points)
    n_frames, m, dim = points.shape
    ax = _check_axes(ax, dim)
    import matplotlib as mpl

    view = _view(track.frames[-1], track.frames[0], background=background)
    image = _draw_image(ax, view)
    nodes = np.arange(0, m, every)
    segs = np.stack([points[:-1, nodes], points[1:, nodes]], axis=2).reshape(-1, 2, dim)
    frame = np.repeat(np.arange(1, n_frames), len(nodes))
    lines = _line_collection(segs, ax, cmap="viridis", linewidths=0.9, zorder=2)
    lines.set_array(frame)
    lines.set_norm(mpl.colors.Normalize(0, n_frames - 1))
    ax.add_collection(lines)
    for f, color in ((0, SOURCE_COLOR), (n_frames - 1, TARGET_COLOR)):
        pts, closed, ordered, faces = _describe(track.shape(f), "track")
        edges = _edges(m, closed, ordered, faces)
        if len(edges) and faces is None:
            ax.add_collection(_line_collection(pts[edges], ax, colors=color, linewidths=0.8,
                                               zorder=3))
        ax.scatter(*pts.T, s=6, c=color, linewidths=0, zorder=4, label=f"frame {f}")
    ax.legend(loc="best", fontsize="small")
    from matplotlib.ticker import MaxNLocator

    cbar = ax.figure.colorbar(lines, ax=ax, label="frame", shrink=0.8)
    cbar.locator = MaxNLocator(integer=True)
    cbar.update_ticks()
    _finish(ax, points.reshape(-1, dim), view, image=image)
    return ax


def plot_track_curves(track, *, ax=None):
    """Global strain (and each segment's) and cumulative strain energy over the frames:
    strain on ``ax`` (left axis, in %), energy on a twin axis on the right.

    Returns the Axes of the strain."""
    _matplotlib()
    if ax is None:
        ax = _new_axes(2, "chart")
    frames = np.arange(track.n_frames)
    for s in range(track.segment_strain.shape[1]):
        ax.plot(frames, 100 * track.segment_strain[:, s], lw=0.9, alpha=0.7,
                label=f"segment {s + 1}")
    ax.plot(frames, 100 * track.strain, color="black", lw=2.2, label="global")
    ax.axhline(0, color="0.7", lw=0.8)
    ax.set_xlabel("frame")
    ax.xaxis.get_major_locator().set_params(integer=True)
    ax.set_ylabel("strain against frame 0 (%)")
    right = ax.twinx()
    right.plot(frames, track.cumulative_energy, color=TARGET_COLOR, ls="--", lw=1.5,
               label="cumulative energy")
    right.set_ylabel(f"cumulative strain energy (22) ({ENERGY_UNIT})", color=TARGET_COLOR)
    handles = ax.get_legend_handles_labels()
    more = right.get_legend_handles_labels()
    ax.legend(handles[0] + more[0], handles[1] + more[1], fontsize="small", ncols=3,
              loc="lower left")
    return ax


def save_track_figures(track, out_dir, *, formats=("png",), dpi: int = 150) -> list[Path]:
    """Write the figures of a track: ``trajectories`` (:func:`plot_trajectories`),
    ``curves`` (:func:`plot_track_curves`) and ``frames_energy`` (every frame's tracked
    shape coloured by its local strain energy, :func:`plot_shapes`). Returns the files."""
    if isinstance(formats, str):
        formats = (formats,)
    _matplotlib()

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    dim = track.points.shape[2]
    draws = {"trajectories": lambda ax: plot_trajectories(track, ax=ax),
             "curves": lambda ax: plot_track_curves(track, ax=ax),
             "frames_energy": lambda ax: plot_shapes(_as_morph(track), color_by="energy",
                                                     ax=ax)}
    return _save_draws(draws, out, dim, layouts=dict(curves="chart"), formats=formats,
                       dpi=dpi)


def animate_track(track, path, *, fps: int = 8, dpi: int = 100) -> Path:
    """An animation of the whole sequence, one frame per frame, each tracked shape
    coloured by its local strain energy (:func:`animate`)."""
    return animate(_as_morph(track), path, fps=fps, color_by="energy", dpi=dpi)
