"""The figures of one morph: the matches, the intermediate shapes (the paper's figure),
the energy curve, and the steps drawn; :func:`save_figures` writes them all to files.
"""

from __future__ import annotations

import math
import re
import textwrap
from pathlib import Path

import numpy as np

from ._draw import (
    DISTANCE_NAME,
    ENERGY_UNIT,
    MATCH_COLOR,
    MEAN_DISTANCE_COLOR,
    MEAN_DISTANCE_NAME,
    NO_DEFORMATION,
    SHAPE_COLOR,
    SOURCE_COLOR,
    TARGET_COLOR,
    check_axes,
    check_color_by,
    check_every,
    check_frames,
    colorbar,
    colormap,
    describe,
    draw_image,
    edges_of,
    finish_axes,
    half_segments,
    import_matplotlib,
    legend_above,
    line_collection,
    new_axes,
    node_values,
    save_draws,
    view_of,
)

MAX_FIGURE_SHAPES = 30  # steps drawn at most (heart PNG: 0.56 s with 34 shapes, 1.14 s with 101)
FIGURE_DPI = 150  # PNGs of 960 x 810 px (heart energy figure: 0.56 s at 150 dpi, 0.71 s at 200)
RASTER_SEGMENTS = 1000  # more go into SVG/PDF as an image (a vector segment costs 0.12 ms)
# Characters a line of the energy figure's title holds (small font over its 960 px: the
# co-rotation's clause of 84 was cut at both ends; 70 keeps "0.548 input units from the
# target (tolerance 0.614 input units)" whole).
TITLE_WIDTH = 70
# 3D node markers shrink in area beyond this many nodes, their ink as this many's: the
# target's 4278 squares of a voxel surface hid the final surface and its energy colours;
# the bunny's 1839 half hid them (shapes_energy.png, looked at).
MARKED_NODES = 1000


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
    check_frames(frames)
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
    src, s_closed, s_ordered, _, s_sizes = describe(source, "source")
    tgt, t_closed, t_ordered, _, t_sizes = describe(target, "target")
    if src.shape[1] != tgt.shape[1]:
        raise ValueError(f"source and target must have the same dimension, got "
                         f"{src.shape[1]} and {tgt.shape[1]}")
    pairs = _check_pairs(pairs, len(src), len(tgt))
    dim = src.shape[1]
    ax = check_axes(ax, dim, "wide")
    from matplotlib.lines import Line2D

    view = view_of(target, source, background=background)
    image = draw_image(ax, view)
    segs = np.stack([src[pairs[:, 0]], tgt[pairs[:, 1]]], axis=1)
    ax.add_collection(line_collection(segs, ax, colors=MATCH_COLOR, linewidths=0.6,
                                      zorder=1))
    for pts, closed, ordered, sizes, color, marker, who in (
        (src, s_closed, s_ordered, s_sizes, SOURCE_COLOR, "o", "source"),
        (tgt, t_closed, t_ordered, t_sizes, TARGET_COLOR, "s", "target"),
    ):
        edges = edges_of(len(pts), closed, ordered, None, sizes)  # contours: meshes clutter
        if len(edges):
            ax.add_collection(line_collection(pts[edges], ax, colors=color, linewidths=0.8,
                                              alpha=0.6, zorder=2))
        ax.scatter(*pts.T, s=14 if dim == 2 else 8, c=color, marker=marker, linewidths=0,
                   zorder=3, label=f"{who} ({len(pts)} nodes)")
    handles, labels = ax.get_legend_handles_labels()
    handles.append(Line2D([], [], color=MATCH_COLOR, lw=0.8))
    labels.append(f"matches ({len(pairs)})")
    legend_above(ax, handles, labels)
    finish_axes(ax, np.vstack([src, tgt]), view, image=image)
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
    check_color_by(color_by)
    check_every(every)
    check_frames(frames)
    shapes = np.asarray(morph.shapes, dtype=np.float64)
    _, closed, ordered, faces, sizes = describe(morph.source, "morph.source")
    tgt, *_ = describe(morph.target, "morph.target")
    ax = check_axes(ax, shapes.shape[2])
    view = view_of(morph.target, morph.source, background=background)
    image = draw_image(ax, view)
    values = node_values(morph, color_by)
    scale = colormap(color_by, values)
    cmap, norm = scale.cmap, scale.norm
    drawn = _drawn_steps(len(shapes), every, frames, morph)
    edges = edges_of(shapes.shape[1], closed, ordered, faces, sizes)
    contour = faces is None and len(edges) > 0
    lines = _step_lines(ax, shapes, values, drawn, edges if contour else None)
    lines.set(cmap=cmap, norm=norm)
    ax.add_collection(lines)
    if faces is not None:
        _draw_surface(ax, shapes[-1], faces, values[-1] if color_by else None, cmap, norm)
    elif not contour:  # the final cloud's nodes, coloured by their value
        ax.scatter(*shapes[-1].T, c=values[-1], cmap=cmap, norm=norm, s=14, zorder=3,
                   linewidths=0)
    t_line = _draw_ends(ax, morph.target, shapes[0], tgt)
    kind = "contour" if contour else "cloud" if faces is None else "surface"
    _shapes_legend(ax, morph, cmap(0.75), kind, color_by, t_line)
    colorbar(ax, lines, color_by, unit=view.unit, scale=scale)
    finish_axes(ax, np.vstack([shapes.reshape(-1, shapes.shape[2]), tgt]), view, image=image)
    return ax


def _step_lines(ax, shapes, values, drawn, edges):
    """One LineCollection of the drawn steps: each step's contour (``edges``), each
    half-edge coloured by its node; or, for surfaces and clouds (``edges`` None), each
    node's path, segment j-1 -> j coloured by step j."""
    if edges is not None:
        parts = [half_segments(shapes[j], edges, values[j]) for j in drawn]
        segs = np.concatenate([p[0] for p in parts])
        vals = np.concatenate([p[1] for p in parts])
        width = 1.2
    else:
        segs = np.stack([shapes[drawn[:-1]], shapes[drawn[1:]]], axis=2)
        segs = segs.reshape(-1, 2, shapes.shape[2])
        vals = values[drawn[1:]].reshape(-1)
        width = 0.6
    lines = line_collection(segs, ax, zorder=2, capstyle="round", linewidths=width,
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
    _, t_closed, t_ordered, t_faces, t_sizes = describe(target, "morph.target")
    dim = start.shape[1]
    size = 9 if dim == 2 else 5
    shrink = 1.0 if dim == 2 else min(1.0, MARKED_NODES / max(len(start), len(tgt)))
    ax.scatter(*start.T, s=size * shrink, c=SOURCE_COLOR, marker="o", linewidths=0, zorder=4)
    t_edges = edges_of(len(tgt), t_closed, t_ordered, t_faces, t_sizes)
    if len(t_edges) and t_faces is None:
        ax.add_collection(line_collection(tgt[t_edges], ax, colors=TARGET_COLOR,
                                          linewidths=1.0, linestyles="--", zorder=4))
    ax.scatter(*tgt.T, s=(size + 3) * shrink, c=TARGET_COLOR, marker="s", linewidths=0,
               zorder=5, alpha=1.0 if dim == 2 else 0.6)
    return bool(len(t_edges)) and t_faces is None


def _shapes_legend(ax, morph, mid, kind: str, color_by, t_line: bool):
    """The legend of :func:`plot_shapes`: source, intermediate shapes (or node paths and
    the final surface or nodes), target; ``mid`` a representative colour."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    last = len(morph.shapes) - 1
    aligned = getattr(morph, "similarity", None) is not None
    names = getattr(morph, "names", None)  # a tracked sequence: its frames' names
    end = f"step {last}" if names is None else names[-1]
    handles = [Line2D([], [], color=SOURCE_COLOR, marker="o", ms=4, ls="none"),
               Line2D([], [], color=mid, lw=1.5 if kind == "contour" else 1.0)]
    if names is None:
        labels = [f"source{' (aligned)' if aligned else ''} (step 0)",
                  f"intermediate shapes (steps 1-{last})"]
    else:
        labels = [f"{names[0]} (first frame)", "tracked shape, frame by frame"]
    if kind != "contour":
        labels[1] = "node paths"
    if kind == "surface":
        handles.append(Patch(facecolor="0.8" if color_by is None else mid, edgecolor="0.35"))
        labels.append(f"final surface ({end})")
    elif kind == "cloud":
        handles.append(Line2D([], [], color=mid, marker="o", ms=4, ls="none"))
        labels.append(f"final nodes ({end})")
    handles.append(Line2D([], [], color=TARGET_COLOR, marker="s", ms=4,
                          ls="--" if t_line else "none"))
    labels.append("target" if names is None else f"{names[-1]} (observed)")
    legend_above(ax, handles, labels)


def plot_energy(morph, *, ax=None):
    """Global strain energy per step; on a twin axis the mean distance of the matched
    pairs per step and, at the last step, the stop test's distance and its tolerance.

    The stop test's distance (:attr:`Morph.distance`, the one ``converged`` compares with
    ``tolerance``) is measured at the end only; the matched pairs' mean distance per step
    is a different measure, named as such.

    Parameters
    ----------
    morph : Morph
        A morph result: uses ``energy``, ``mean_distance``, ``message`` and, when there,
        ``distance`` and ``tolerance``.
    ax : matplotlib Axes, optional
        Where to draw the energy; the distances go on ``ax.twinx()``.

    Returns
    -------
    matplotlib.axes.Axes
        The energy axes; the distance axes is its twin (the figure's last Axes).
    """
    energy = np.asarray(morph.energy, dtype=np.float64)
    if ax is None:
        ax = new_axes(2, "chart")
    from matplotlib.ticker import MaxNLocator

    steps = np.arange(len(energy))
    marker = "o" if len(steps) <= 40 else None
    flat = not np.nanmax(np.abs(energy), initial=0.0) >= NO_DEFORMATION  # round-off only
    (e_line,) = ax.plot(steps, energy, color=SHAPE_COLOR, marker=marker, ms=4,
                        label="global strain energy $E$ (22)"
                        + (f": none (< {NO_DEFORMATION:.0e})" if flat else ""))
    ax.set(xlabel="step", ylabel=f"global strain energy $E$ ({ENERGY_UNIT})",
           xlim=(0, max(len(steps) - 1, 1)))
    if flat:  # zero drawn as zero, not round-off magnified into a curve
        ax.set_ylim(-1.0, 1.0)
    else:
        ax.set_ylim(bottom=min(0.0, float(np.nanmin(energy))))
    ax.yaxis.get_major_formatter().set_powerlimits((-3, 4))
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.grid(True, alpha=0.3)
    handles = [e_line, *_distance_lines(ax.twinx(), morph, steps, marker)]
    status = "converged" if getattr(morph, "converged", False) else "not converged"
    # one clause a line: a sentence wrapped at a width broke "0.135 input | units"; a
    # clause longer than a line (the co-rotation's) wrapped alone
    clauses = re.split(r"(?<=[,;]) ", getattr(morph, "message", "") or status)
    reason = "\n".join(textwrap.fill(c, TITLE_WIDTH) for c in clauses)
    legend_above(ax, handles, [h.get_label() for h in handles], title=reason,
                 title_fontsize="small")
    return ax


def _distance_lines(twin, morph, steps, marker) -> list:
    """On ``twin``: the matched pairs' mean distance per step, and the stop test's
    distance (a point at the last step) and tolerance (a line) when the morph has them."""
    unit = view_of(morph.target, morph.source).unit
    distance = np.asarray(morph.mean_distance, dtype=np.float64)
    (pairs,) = twin.plot(steps, distance, color=MEAN_DISTANCE_COLOR, ls="--", marker=marker,
                         ms=4, mfc="white", label=MEAN_DISTANCE_NAME)
    twin.set_ylabel(f"distance ({unit})")
    twin.set_ylim(bottom=0.0)
    lines = [pairs]
    stop, tol = getattr(morph, "distance", None), getattr(morph, "tolerance", None)
    if tol is not None and np.isfinite(tol):
        lines.append(twin.axhline(tol, color=TARGET_COLOR, ls=":", lw=1.4,
                                  label=f"tolerance {tol:.3g}"))
    if stop is not None and np.isfinite(stop):
        (point,) = twin.plot([steps[-1]], [stop], color=TARGET_COLOR, marker="*", ms=11,
                             ls="none", clip_on=False, zorder=5,
                             label=f"{DISTANCE_NAME}: {stop:.3g}")
        lines.append(point)
    return lines


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
    check_frames(frames)
    import_matplotlib()
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
    return save_draws(draws, out, shapes.shape[2], layouts=dict(matches="wide",
                                                                energy="chart"),
                      formats=formats, dpi=dpi)
