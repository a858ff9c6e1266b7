"""The figures and animation of a tracked sequence (:func:`modalmorph.track`): the nodes'
trajectories, the strain and energy curves, every frame coloured by its local energy."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ._draw import (
    ENERGY_UNIT,
    SOURCE_COLOR,
    TARGET_COLOR,
    check_axes,
    check_every,
    describe,
    draw_image,
    edges_of,
    finish_axes,
    import_matplotlib,
    line_collection,
    new_axes,
    save_draws,
    view_of,
)
from .animation import animate
from .morph import plot_shapes


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
    check_every(every)
    points = np.asarray(track.points)
    n_frames, m, dim = points.shape
    ax = check_axes(ax, dim)
    import matplotlib as mpl

    view = view_of(track.frames[-1], track.frames[0], background=background)
    image = draw_image(ax, view)
    nodes = np.arange(0, m, every)
    segs = np.stack([points[:-1, nodes], points[1:, nodes]], axis=2).reshape(-1, 2, dim)
    frame = np.repeat(np.arange(1, n_frames), len(nodes))
    lines = line_collection(segs, ax, cmap="viridis", linewidths=0.9, zorder=2)
    lines.set_array(frame)
    lines.set_norm(mpl.colors.Normalize(0, n_frames - 1))
    ax.add_collection(lines)
    for f, color in ((0, SOURCE_COLOR), (n_frames - 1, TARGET_COLOR)):
        pts, closed, ordered, faces = describe(track.shape(f), "track")
        edges = edges_of(m, closed, ordered, faces)
        if len(edges) and faces is None:
            ax.add_collection(line_collection(pts[edges], ax, colors=color, linewidths=0.8,
                                              zorder=3))
        ax.scatter(*pts.T, s=6, c=color, linewidths=0, zorder=4, label=f"frame {f}")
    ax.legend(loc="best", fontsize="small")
    from matplotlib.ticker import MaxNLocator

    cbar = ax.figure.colorbar(lines, ax=ax, label="frame", shrink=0.8)
    cbar.locator = MaxNLocator(integer=True)
    cbar.update_ticks()
    finish_axes(ax, points.reshape(-1, dim), view, image=image)
    return ax


def plot_track_curves(track, *, ax=None):
    """Global strain (and each segment's) and cumulative strain energy over the frames:
    strain on ``ax`` (left axis, in %), energy on a twin axis on the right.

    Returns the Axes of the strain."""
    import_matplotlib()
    if ax is None:
        ax = new_axes(2, "chart")
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
    import_matplotlib()

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    dim = track.points.shape[2]
    draws = {"trajectories": lambda ax: plot_trajectories(track, ax=ax),
             "curves": lambda ax: plot_track_curves(track, ax=ax),
             "frames_energy": lambda ax: plot_shapes(_as_morph(track), color_by="energy",
                                                     ax=ax)}
    return save_draws(draws, out, dim, layouts=dict(curves="chart"), formats=formats,
                      dpi=dpi)


def animate_track(track, path, *, fps: int = 8, dpi: int = 100) -> Path:
    """An animation of the whole sequence, one frame per frame, each tracked shape
    coloured by its local strain energy (:func:`animate`)."""
    return animate(_as_morph(track), path, fps=fps, color_by="energy", dpi=dpi)
