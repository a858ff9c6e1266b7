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
``target``, ``converged`` and ``stop_reason``.
"""

from __future__ import annotations

import os
import secrets
from pathlib import Path

import numpy as np

__all__ = [
    "animate",
    "animate_track",
    "plot_batch",
    "plot_energy",
    "plot_matches",
    "plot_shapes",
    "plot_track_curves",
    "plot_trajectories",
    "save_figures",
    "save_track_figures",
    "write_vtk_series",
]

COLOR_BY = ("load", "energy", None)

# Source and target keep these colours in every figure; the colour maps below avoid them.
SOURCE_COLOR = "black"
TARGET_COLOR = "#d81b60"  # a strong magenta-red, absent from viridis, coolwarm and greys
MATCH_COLOR = "0.55"
_LABELS = {
    "load": "load magnitude $\\|R_i\\|$",
    "energy": "strain energy per node $e_i$",
    None: "step",
}


def _matplotlib():
    try:
        import matplotlib
    except ImportError as exc:  # pragma: no cover - exercised on a bare install
        raise ImportError("plotting needs matplotlib (a dependency of modalmorph): "
                          "pip install matplotlib") from exc
    return matplotlib


def _new_axes(dim: int, figsize=(6.4, 5.2)):
    """A fresh pyplot Axes (3D when ``dim == 3``); the caller owns its figure."""
    _matplotlib()
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=figsize, layout="constrained")
    return fig.add_subplot(projection="3d" if dim == 3 else None)


def _axes_for(fig, dim: int):
    return fig.add_subplot(projection="3d" if dim == 3 else None)


def _legend_above(ax, handles, labels, **kw):
    """A frameless one-row legend just above the axes, where it hides no data."""
    return ax.legend(handles, labels, loc="lower center", bbox_to_anchor=(0.5, 1.0),
                     ncols=len(handles), frameon=False, fontsize="small",
                     handlelength=1.6, columnspacing=1.2, **kw)


def _is_3d(ax) -> bool:
    return getattr(ax, "name", "") == "3d"


def _check_axes(ax, dim: int):
    """``ax``, or a new one, after checking that it is 3D exactly when the data are."""
    if ax is None:
        return _new_axes(dim)
    if _is_3d(ax) != (dim == 3):
        want = "a 3D Axes (projection='3d')" if dim == 3 else "a 2D Axes"
        raise ValueError(f"{dim}D shapes need {want}, got a {ax.name!r} Axes")
    return ax


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


def _finish(ax, points: np.ndarray):
    """Equal aspect, x/y(/z) labels, limits fitted to ``points`` (any (N, d))."""
    if _is_3d(ax):
        lo, hi = points.min(axis=0), points.max(axis=0)
        pad = 0.04 * max(float(np.max(hi - lo)), 1e-12)
        ax.set(xlim=(lo[0] - pad, hi[0] + pad), ylim=(lo[1] - pad, hi[1] + pad),
               zlim=(lo[2] - pad, hi[2] + pad), xlabel="x", ylabel="y", zlabel="z")
        ax.set_box_aspect(np.maximum(hi - lo + 2 * pad, 1e-12))
    else:
        ax.update_datalim(points)
        ax.autoscale_view()
        ax.set_aspect("equal", adjustable="datalim")
        ax.set(xlabel="x", ylabel="y")


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
    """(cmap, norm) for the values shown; zero is light grey or dark, never white.

    Loads are magnitudes (>= 0): viridis from 0, cut before its pale yellow end. Local
    strain energy can be negative: coolwarm centred on 0 (grey at 0, blue < 0, red > 0),
    only its upper half when no value is negative. Steps: greys from light to dark.
    """
    import matplotlib as mpl
    from matplotlib.colors import CenteredNorm, ListedColormap, Normalize

    def part(name, lo, hi):
        return ListedColormap(mpl.colormaps[name](np.linspace(lo, hi, 256)), name=name)

    finite = values[np.isfinite(values)]
    top = float(np.max(np.abs(finite))) if finite.size else 1.0
    top = top if top > 0 else 1.0
    if color_by == "load":
        return part("viridis", 0.0, 0.92), Normalize(0.0, top)
    if color_by == "energy":
        if finite.size and finite.min() < 0:
            return mpl.colormaps["coolwarm"], CenteredNorm(0.0, halfrange=top)
        return part("coolwarm", 0.5, 1.0), Normalize(0.0, top)
    return part("Greys", 0.25, 0.85), Normalize(0.0, max(float(values.max()), 1.0))


def _colorbar(ax, mappable, color_by, *, n_steps: int | None = None):
    fig = ax.figure
    kw = {"shrink": 0.75, "pad": 0.08} if _is_3d(ax) else {}
    cbar = fig.colorbar(mappable, ax=ax, label=_LABELS[color_by], **kw)
    if color_by is None:
        from matplotlib.ticker import MaxNLocator

        cbar.locator = MaxNLocator(integer=True, nbins=min(n_steps or 10, 10))
        cbar.update_ticks()
    elif color_by == "energy":
        cbar.formatter.set_powerlimits((-3, 4))
    return cbar


# ------------------------------------------------------------------------- figures


def plot_matches(source, target, pairs, *, ax=None):
    """Draw the source and target nodes and the matches between them.

    Parameters
    ----------
    source, target : Shape or array_like, shape (m, d) and (n, d)
        The two objects; a :class:`~modalmorph.Shape` (or anything with ``points``,
        ``closed``, ``faces``) is drawn as its contour or mesh, a bare 2D array as a
        closed contour, a bare 3D array as a point cloud.
    pairs : array_like of int, shape (K, 2)
        Matches as (source index, target index), e.g. ``morph.matching.pairs``.
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
    pairs = np.asarray(pairs)
    if pairs.size == 0:
        pairs = np.empty((0, 2), dtype=int)
    if pairs.ndim != 2 or pairs.shape[1] != 2 or not np.issubdtype(pairs.dtype, np.integer):
        raise ValueError(f"pairs must be an integer array of shape (K, 2), got "
                         f"{pairs.dtype} {pairs.shape}")
    if len(pairs) and (pairs.min() < 0 or pairs[:, 0].max() >= len(src)
                       or pairs[:, 1].max() >= len(tgt)):
        raise ValueError(f"pairs index nodes outside the source (0..{len(src) - 1}) or "
                         f"the target (0..{len(tgt) - 1})")
    dim = src.shape[1]
    ax = _check_axes(ax, dim)
    from matplotlib.lines import Line2D

    segs = np.stack([src[pairs[:, 0]], tgt[pairs[:, 1]]], axis=1)
    ax.add_collection(_line_collection(segs, ax, colors=MATCH_COLOR, linewidths=0.6,
                                       zorder=1))
    size = 14 if dim == 2 else 8
    for pts, closed, ordered, color, marker, who in (
        (src, s_closed, s_ordered, SOURCE_COLOR, "o", "source"),
        (tgt, t_closed, t_ordered, TARGET_COLOR, "s", "target"),
    ):
        edges = _edges(len(pts), closed, ordered, None)  # contours only: meshes clutter
        if len(edges):
            ax.add_collection(_line_collection(pts[edges], ax, colors=color, linewidths=0.8,
                                               alpha=0.6, zorder=2))
        ax.scatter(*pts.T, s=size, c=color, marker=marker, linewidths=0, zorder=3,
                   label=f"{who} ({len(pts)} nodes)")
    handles, labels = ax.get_legend_handles_labels()
    handles.append(Line2D([], [], color=MATCH_COLOR, lw=0.8))
    labels.append(f"matches ({len(pairs)})")
    _legend_above(ax, handles, labels)
    _finish(ax, np.vstack([src, tgt]))
    return ax


def plot_shapes(morph, *, color_by="energy", every: int = 1, ax=None):
    """Draw the intermediate shapes of a morph in order (the paper's figure).

    Contours (and 3D polylines) are drawn as one polyline per step, coloured per node by
    the load magnitude or the local strain energy at that step, or in grey levels from
    light (early) to dark (late) when ``color_by`` is None; a colour bar gives the scale.
    3D surfaces and point clouds are drawn as the path of every node over the steps
    (coloured the same way) and the final shape's nodes. The source (step 0) and the
    target nodes are drawn on top in fixed colours.

    Parameters
    ----------
    morph : Morph
        A morph result (see the module docstring for the fields used).
    color_by : {"energy", "load", None}, optional
        Per-node quantity to colour by: ``"energy"``, the local strain energy
        e_i (25), which can be negative (diverging map centred on 0); ``"load"``, the
        magnitude of the load R_i (19)-(20); None, the step number in grey levels.
    every : int, optional
        Draw every ``every``-th step (the last step is always drawn).
    ax : matplotlib Axes, optional
        Where to draw (a 3D Axes for 3D shapes). A new figure is made if omitted.

    Returns
    -------
    matplotlib.axes.Axes
    """
    _check_color_by(color_by)
    if isinstance(every, bool) or not isinstance(every, (int, np.integer)) or every < 1:
        raise ValueError(f"every must be a positive integer, got {every!r}")
    shapes = np.asarray(morph.shapes, dtype=np.float64)
    n_steps, m, dim = shapes.shape
    _, closed, ordered, faces = _describe(morph.source, "morph.source")
    tgt, t_closed, t_ordered, t_faces = _describe(morph.target, "morph.target")
    ax = _check_axes(ax, dim)
    from matplotlib.lines import Line2D

    values = _node_values(morph, color_by)
    cmap, norm = _colormap(color_by, values)
    drawn = np.unique(np.r_[np.arange(0, n_steps, every), n_steps - 1])
    edges = _edges(m, closed, ordered, faces)
    contour = faces is None and len(edges) > 0
    if contour:  # one polyline per step, each half-edge coloured by its node
        parts = [_half_segments(shapes[j], edges, values[j]) for j in drawn]
        segs = np.concatenate([p[0] for p in parts])
        vals = np.concatenate([p[1] for p in parts])
    else:  # surfaces and clouds: each node's path, segment j-1 -> j coloured by step j
        segs = np.stack([shapes[drawn[:-1]], shapes[drawn[1:]]], axis=2).reshape(-1, 2, dim)
        vals = values[drawn[1:]].reshape(-1)
    lines = _line_collection(segs, ax, cmap=cmap, norm=norm, zorder=2, capstyle="round",
                             linewidths=1.2 if contour else 0.6)
    lines.set_array(vals)
    ax.add_collection(lines)
    if faces is not None and len(faces):  # the final surface
        from mpl_toolkits.mplot3d.art3d import Poly3DCollection

        tri = shapes[-1][faces]
        surf = Poly3DCollection(tri, alpha=0.9, edgecolors="0.3", linewidths=0.15, zorder=3)
        if color_by is None:  # light grey, shaded (either orientation of the faces)
            normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
            normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
            light = np.abs(normal @ np.array([-0.4, -0.5, 0.77]))
            surf.set_facecolor(np.c_[np.repeat(0.55 + 0.4 * light[:, None], 3, axis=1),
                                     np.full(len(tri), 0.9)])
        else:  # each face coloured by the mean value of its nodes
            surf.set_cmap(cmap)
            surf.set_norm(norm)
            surf.set_array(values[-1][faces].mean(axis=1))
        ax.add_collection3d(surf)
    elif not contour:  # the final cloud's nodes, coloured by their value
        ax.scatter(*shapes[-1].T, c=values[-1], cmap=cmap, norm=norm, s=14, zorder=3,
                   linewidths=0)

    src_label = "source" if getattr(morph, "similarity", None) is None else "source (aligned)"
    size = 9 if dim == 2 else 5
    ax.scatter(*shapes[0].T, s=size, c=SOURCE_COLOR, marker="o", linewidths=0, zorder=4)
    t_edges = _edges(len(tgt), t_closed, t_ordered, t_faces)
    if len(t_edges) and t_faces is None:
        ax.add_collection(_line_collection(tgt[t_edges], ax, colors=TARGET_COLOR,
                                           linewidths=1.0, linestyles="--", zorder=4))
    ax.scatter(*tgt.T, s=size + 3, c=TARGET_COLOR, marker="s", linewidths=0, zorder=5,
               alpha=1.0 if dim == 2 else 0.6)

    mid = cmap(0.75)  # a representative colour of the intermediate shapes
    t_style = {"ls": "--"} if len(t_edges) and t_faces is None else {"ls": "none"}
    last = n_steps - 1
    handles = [Line2D([], [], color=SOURCE_COLOR, marker="o", ms=4, ls="none"),
               Line2D([], [], color=mid, lw=1.5 if contour else 1.0)]
    labels = [f"{src_label} (step 0)",
              f"intermediate shapes (steps 1-{last})" if contour else "node paths"]
    if faces is not None and len(faces):
        from matplotlib.patches import Patch

        handles.append(Patch(facecolor="0.8" if color_by is None else mid, edgecolor="0.35"))
        labels.append(f"final surface (step {last})")
    elif not contour:
        handles.append(Line2D([], [], color=mid, marker="o", ms=4, ls="none"))
        labels.append(f"final nodes (step {last})")
    handles.append(Line2D([], [], color=TARGET_COLOR, marker="s", ms=4, **t_style))
    labels.append("target")
    _legend_above(ax, handles, labels)
    _colorbar(ax, lines, color_by, n_steps=n_steps)
    _finish(ax, np.vstack([shapes.reshape(-1, dim), tgt]))
    return ax


def plot_energy(morph, *, ax=None):
    """Global strain energy per step, with the mean distance to the target on a twin axis.

    Parameters
    ----------
    morph : Morph
        A morph result: uses ``energy``, ``mean_distance`` and ``stop_reason``.
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
        ax = _new_axes(2, figsize=(6.4, 4.0))
    from matplotlib.ticker import MaxNLocator

    steps = np.arange(len(energy))
    marker = "o" if len(steps) <= 40 else None
    (e_line,) = ax.plot(steps, energy, color="#1f4e99", marker=marker, ms=4,
                        label="global strain energy $E$ (22)")
    ax.set(xlabel="step", ylabel="global strain energy $E$", xlim=(0, max(len(steps) - 1, 1)))
    ax.set_ylim(bottom=min(0.0, float(np.nanmin(energy))))
    ax.yaxis.get_major_formatter().set_powerlimits((-3, 4))
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.grid(True, alpha=0.3)
    twin = ax.twinx()
    (d_line,) = twin.plot(steps, distance, color="#d95f02", ls="--", marker=marker, ms=4,
                          mfc="white", label="mean distance to target")
    twin.set_ylabel("mean distance to target")
    twin.set_ylim(bottom=0.0)
    import textwrap

    status = "converged" if getattr(morph, "converged", False) else "not converged"
    reason = textwrap.fill(getattr(morph, "stop_reason", "") or status, 70)
    _legend_above(ax, [e_line, d_line], [e_line.get_label(), d_line.get_label()],
                  title=reason, title_fontsize="small")
    return ax


def plot_batch(results, *, ax=None):
    """One point per completed item of a batch: final distance against strain energy.

    Parameters
    ----------
    results : sequence of ItemResult
        The rows of :func:`modalmorph.batch.run` (``Batch.results``); items without
        numbers (failed, interrupted) are counted in the title.
    ax : matplotlib Axes, optional

    Returns
    -------
    matplotlib.axes.Axes
    """
    if ax is None:
        ax = _new_axes(2, figsize=(6.4, 4.4))
    done = [r for r in results if r.distance is not None and r.energy is not None]
    for kind, color in (("pair", "#1f4e99"), ("sequence", "#d95f02")):
        for converged, marker in ((True, "o"), (False, "x")):
            rows = [r for r in done if r.kind == kind and bool(r.converged) == converged]
            if rows:
                ax.scatter([r.distance for r in rows], [r.energy for r in rows], s=18,
                           color=color, marker=marker, label=f"{kind}s, " + (
                               "converged" if converged else "not converged"))
    ax.set(xlabel="final distance to target", ylabel="strain energy",
           title=f"{len(done)} of {len(results)} items done"
                 + (f", {len(results) - len(done)} failed or not run"
                    if len(done) < len(results) else ""))
    ax.grid(True, alpha=0.3)
    if done:
        ax.legend(fontsize="small")
    return ax


# ------------------------------------------------------------------ animation, files


def animate(morph, path, *, fps: int = 10, color_by="energy", dpi: int = 100) -> Path:
    """Write an animation of the deformation, one frame per step.

    Each frame shows the shape at that step coloured per node (as :func:`plot_shapes`,
    with one colour scale for all frames), the source and the target drawn faintly.

    Parameters
    ----------
    morph : Morph
        A morph result.
    path : str or Path
        Output file: ``.gif`` (Pillow) or ``.mp4`` (needs ffmpeg on the PATH).
    fps : int, optional
        Frames per second.
    color_by : {"energy", "load", None}, optional
        As in :func:`plot_shapes`; None draws every frame in one colour.
    dpi : int, optional
        Resolution of the frames.

    Returns
    -------
    Path
        ``path``, written atomically (a temporary file renamed at the end, so a failure
        leaves no partial file).

    Raises
    ------
    ValueError
        If the suffix is neither ``.gif`` nor ``.mp4``, or ``.mp4`` is asked for and no
        ffmpeg is available.
    """
    _check_color_by(color_by)
    if fps <= 0:
        raise ValueError(f"fps must be positive, got {fps!r}")
    path = Path(path)
    suffix = path.suffix.lower()
    _matplotlib()
    from matplotlib import animation
    from matplotlib.figure import Figure

    if suffix == ".gif":
        writer = animation.PillowWriter(fps=fps)
    elif suffix == ".mp4":
        if not animation.writers.is_available("ffmpeg"):
            raise ValueError(f"writing {path.name} needs ffmpeg on the PATH; install it "
                             f"or ask for a .gif")
        writer = animation.FFMpegWriter(fps=fps)
    else:
        raise ValueError(f"path must end in .gif or .mp4, got {path.name!r}")

    shapes = np.asarray(morph.shapes, dtype=np.float64)
    n_steps, m, dim = shapes.shape
    _, closed, ordered, faces = _describe(morph.source, "morph.source")
    tgt, t_closed, t_ordered, _ = _describe(morph.target, "morph.target")
    faces = faces if faces is not None and len(faces) else None
    if color_by is None:
        values, cmap, norm = np.zeros((n_steps, m)), None, None
    else:
        values = _node_values(morph, color_by)
        cmap, norm = _colormap(color_by, values)

    from matplotlib.lines import Line2D

    fig = Figure(figsize=(6.4, 5.2), dpi=dpi, layout="constrained")
    ax = _axes_for(fig, dim)
    handles = []
    for pts, (c, o), color, marker, label in (
        (shapes[0], (closed, ordered), SOURCE_COLOR, "o", "source"),
        (tgt, (t_closed, t_ordered), TARGET_COLOR, "s", "target"),
    ):  # the fixed background, faint: contours as lines, surfaces and clouds as nodes
        e = _edges(len(pts), c, o, None)
        if len(e):
            ax.add_collection(_line_collection(pts[e], ax, colors=color, linewidths=0.9,
                                               alpha=0.35, zorder=1))
        ax.scatter(*pts.T, s=5, c=color, marker=marker, alpha=0.35, linewidths=0, zorder=1)
        handles.append(Line2D([], [], color=color, alpha=0.5, marker=marker, ms=3,
                              ls="-" if len(e) else "none", label=label))
    _finish(ax, np.vstack([shapes.reshape(-1, dim), tgt]))
    if color_by is not None:
        from matplotlib.cm import ScalarMappable

        _colorbar(ax, ScalarMappable(norm=norm, cmap=cmap), color_by)
    one = "#1f4e99" if cmap is None else cmap(0.75)
    if faces is not None:
        from matplotlib.patches import Patch

        current = Patch(facecolor=one, edgecolor="0.3", label="shape at the step")
    else:
        current = Line2D([], [], color=one, lw=2.0, marker="o", ms=3, mec="0.15",
                         ls="-" if len(_edges(m, closed, ordered, None)) else "none",
                         label="shape at the step")
    handles.insert(0, current)
    ax.legend(handles=handles, loc="lower right", bbox_to_anchor=(1.0, 1.0), ncols=3,
              frameon=False, fontsize="small")  # the step number goes on the left
    edges = _edges(m, closed, ordered, None)
    # lay the figure out once, with a title, then freeze it: frames neither jitter nor
    # pay for the layout again
    ax.set_title(f"step {n_steps - 1} / {n_steps - 1}", loc="left", fontsize="medium")
    fig.draw_without_rendering()
    fig.set_layout_engine("none")

    # a unique name beside the target, same suffix (ffmpeg picks its format from it)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}-{secrets.token_hex(4)}.tmp{suffix}")
    try:
        with writer.saving(fig, tmp, dpi=dpi):
            artists = []
            for j in range(n_steps):
                for artist in artists:
                    artist.remove()
                artists = _draw_frame(ax, shapes[j], edges, faces, values[j], cmap, norm)
                ax.set_title(f"step {j} / {n_steps - 1}", loc="left", fontsize="medium")
                writer.grab_frame()
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def _draw_frame(ax, points, edges, faces, values, cmap, norm):
    """The artists of one animation frame: the shape at one step, coloured per node."""
    one = "#1f4e99"  # the shape's colour when not coloured by a quantity (as in animate)
    if faces is not None:
        from mpl_toolkits.mplot3d.art3d import Poly3DCollection

        kw = {"facecolors": one} if cmap is None else {"cmap": cmap, "norm": norm}
        surf = Poly3DCollection(points[faces], edgecolors="0.3", linewidths=0.15,
                                alpha=0.9, zorder=3, **kw)
        if cmap is not None:
            surf.set_array(values[faces].mean(axis=1))
        ax.add_collection3d(surf)
        return [surf]
    artists = []
    if len(edges):
        kw = {"colors": one} if cmap is None else {"cmap": cmap, "norm": norm}
        # a dark casing under the coloured line: the moving shape stands out from the
        # faint source and target even where its colour is pale (values near zero)
        casing = _line_collection(points[edges], ax, colors="0.15", linewidths=3.0,
                                  zorder=3, capstyle="round")
        ax.add_collection(casing)
        artists.append(casing)
        segs, vals = _half_segments(points, edges, values)
        lines = _line_collection(segs, ax, linewidths=1.8, zorder=3, capstyle="round", **kw)
        if cmap is not None:
            lines.set_array(vals)
        ax.add_collection(lines)
        artists.append(lines)
    kw = {"c": one} if cmap is None else {"c": values, "cmap": cmap, "norm": norm}
    artists.append(ax.scatter(*points.T, s=10 if len(edges) else 16, zorder=4,
                              edgecolors="0.15", linewidths=0.5, **kw))
    return artists


def write_vtk_series(morph, out_dir, *, name: str = "morph") -> Path:
    """Write one VTU file per step and a ParaView ``.pvd`` collection of them.

    Each ``{name}_{step:04d}.vtu`` holds the shape at that step (2D padded with z = 0)
    with line cells for contours, triangles for surfaces or vertices for point clouds,
    and point data ``load`` (vectors), ``energy`` (local strain energy) and
    ``displacement`` (from the source). Open ``{name}.pvd`` in ParaView to play it.

    Parameters
    ----------
    morph : Morph
        A morph result.
    out_dir : str or Path
        Directory to write into (created if missing).
    name : str, optional
        Stem of the file names.

    Returns
    -------
    Path
        The ``.pvd`` file.
    """
    try:
        import meshio
    except ImportError as exc:  # pragma: no cover - exercised on a bare install
        raise ImportError("writing VTK needs meshio (a dependency of modalmorph): "
                          "pip install meshio") from exc
    from xml.sax.saxutils import quoteattr

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    shapes = np.asarray(morph.shapes, dtype=np.float64)
    n_steps, m, dim = shapes.shape
    _, closed, ordered, faces = _describe(morph.source, "morph.source")

    def pad(a):
        return np.pad(a, ((0, 0), (0, 3 - dim))) if dim == 2 else a

    if faces is not None and len(faces):
        cells = [("triangle", np.asarray(faces, dtype=np.int64))]
    elif ordered:
        cells = [("line", _edges(m, closed, ordered, None).astype(np.int64))]
    else:
        cells = [("vertex", np.arange(m, dtype=np.int64)[:, None])]
    loads = np.asarray(morph.loads, dtype=np.float64)
    energy = np.asarray(morph.node_energy, dtype=np.float64)
    entries = []
    for j in range(n_steps):
        fname = f"{name}_{j:04d}.vtu"
        mesh = meshio.Mesh(pad(shapes[j]), cells, point_data={
            "load": pad(loads[j]),
            "energy": energy[j],
            "displacement": pad(shapes[j] - shapes[0]),
        })
        mesh.write(out / fname)
        entries.append(f'    <DataSet timestep="{j}" group="" part="0" '
                       f"file={quoteattr(fname)}/>")
    pvd = out / f"{name}.pvd"
    pvd.write_text('<?xml version="1.0"?>\n'
                   '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">\n'
                   "  <Collection>\n" + "\n".join(entries) + "\n  </Collection>\n"
                   "</VTKFile>\n")
    return pvd


def save_figures(morph, out_dir, *, formats=("png", "svg"), dpi: int = 200) -> list[Path]:
    """Write the standard figures of a morph, in every format asked for.

    The figures are ``matches`` (:func:`plot_matches` on the aligned source),
    ``shapes_plain``, ``shapes_load``, ``shapes_energy`` (:func:`plot_shapes` with
    ``color_by`` None, "load", "energy") and ``energy`` (:func:`plot_energy`).

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

    Returns
    -------
    list of Path
        The files written, figure by figure, format by format.
    """
    if isinstance(formats, str):
        formats = (formats,)
    _matplotlib()

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    shapes = np.asarray(morph.shapes)
    dim = shapes.shape[2]
    source = morph.source
    if hasattr(source, "points"):  # the matches are drawn on the shape that was morphed
        from types import SimpleNamespace

        source = SimpleNamespace(points=shapes[0], closed=getattr(source, "closed", True),
                                 ordered=getattr(source, "ordered", None),
                                 faces=getattr(source, "faces", None))
    else:
        source = shapes[0]
    draws = {
        "matches": lambda ax: plot_matches(source, morph.target, morph.matching.pairs, ax=ax),
        "shapes_plain": lambda ax: plot_shapes(morph, color_by=None, ax=ax),
        "shapes_load": lambda ax: plot_shapes(morph, color_by="load", ax=ax),
        "shapes_energy": lambda ax: plot_shapes(morph, color_by="energy", ax=ax),
        "energy": lambda ax: plot_energy(morph, ax=ax),
    }
    return _save_draws(draws, out, dim, flat=("energy", (6.4, 4.0)), formats=formats, dpi=dpi)


def _save_draws(draws: dict, out: Path, dim: int, *, flat: tuple, formats, dpi) -> list[Path]:
    """Draw each figure of ``draws`` (stem -> function of an Axes) on its own Figure and
    save it in every format; ``flat = (stem, figsize)`` names the one 2D chart."""
    from matplotlib.figure import Figure

    paths = []
    for stem, draw in draws.items():
        chart = stem == flat[0]
        fig = Figure(figsize=flat[1] if chart else (6.4, 5.2), layout="constrained")
        draw(_axes_for(fig, 2 if chart else dim))
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


def plot_trajectories(track, *, every: int = 1, ax=None):
    """Draw the path of every ``every``-th tracked node over the frames, coloured by
    frame, over frame 0's shape (black) and the last frame's (magenta).

    Returns the Axes."""
    if isinstance(every, bool) or not isinstance(every, (int, np.integer)) or every < 1:
        raise ValueError(f"every must be a positive integer, got {every!r}")
    points = np.asarray(track.points)
    n_frames, m, dim = points.shape
    ax = _check_axes(ax, dim)
    import matplotlib as mpl

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
    ax.figure.colorbar(lines, ax=ax, label="frame", shrink=0.8)
    _finish(ax, points.reshape(-1, dim))
    return ax


def plot_track_curves(track, *, ax=None):
    """Global strain (and each segment's) and cumulative strain energy over the frames:
    strain on ``ax`` (left axis, in %), energy on a twin axis on the right.

    Returns the Axes of the strain."""
    _matplotlib()
    if ax is None:
        ax = _new_axes(2, figsize=(6.4, 4.0))
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
    right.set_ylabel("cumulative strain energy (22)", color=TARGET_COLOR)
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
    return _save_draws(draws, out, dim, flat=("curves", (7.0, 4.0)), formats=formats, dpi=dpi)


def animate_track(track, path, *, fps: int = 8, dpi: int = 100) -> Path:
    """An animation of the whole sequence, one frame per frame, each tracked shape
    coloured by its local strain energy (:func:`animate`)."""
    return animate(_as_morph(track), path, fps=fps, color_by="energy", dpi=dpi)
