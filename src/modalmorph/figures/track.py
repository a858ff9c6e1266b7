"""The figures and animation of a tracked sequence (:func:`modalmorph.track`): the nodes'
trajectories, the strain and energy curves, every frame coloured by its local energy."""

from __future__ import annotations

import os
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
    legend_above,
    line_collection,
    new_axes,
    save_draws,
    short_names,
    view_of,
)
from .animation import animate
from .morph import plot_shapes

MAX_NAMED_FRAMES = 12  # frames named one by one on an axis at most (longer names overlap)
SLANT = 30  # degrees of the frame names under a chart's axis when they are long
# Width of a tick label's character and the height of the axis label below the names, in
# points, at matplotlib's default 10 pt sans-serif (DejaVu Sans averages 6.1 pt a
# character over file names such as "SC-HF-NI-03-0009.csv", 20 characters, 122 pt).
CHAR_PT, LABEL_PT = 6.2, 30.0


def _as_morph(track):
    """A Track seen as a morph whose steps are the frames (for plot_shapes, animate)."""
    from types import SimpleNamespace

    return SimpleNamespace(shapes=track.points, node_energy=track.node_energy,
                           loads=np.zeros_like(track.points), source=track.frames[0],
                           target=track.frames[-1], similarity=None,
                           names=short_names(track.names))


def _name_frames(axis, names, *, at_most: int = MAX_NAMED_FRAMES) -> None:
    """Label a frame axis (or colour bar axis) 0..F-1 with the frames' names: each
    frame when there are few, else a few of them."""
    from matplotlib.ticker import FixedLocator, FuncFormatter, MaxNLocator

    if len(names) <= at_most:
        axis.set_major_locator(FixedLocator(range(len(names))))
    else:
        axis.set_major_locator(MaxNLocator(integer=True, nbins=at_most))
    axis.set_major_formatter(FuncFormatter(
        lambda v, _: names[int(round(v))] if 0 <= round(v) < len(names) else ""))


def _slant_names(ax, longest: int) -> None:
    """Frame names slanted under the axis, ending at their ticks, with the room they
    take below it (the Axes shortened from below when its margin is too small)."""
    ax.tick_params(axis="x", labelrotation=SLANT)
    for label in ax.xaxis.get_ticklabels():
        label.set_horizontalalignment("right")
    fig = ax.figure
    size = CHAR_PT * longest / 72  # inches
    below = (size * np.sin(np.radians(SLANT)) + LABEL_PT / 72) / fig.get_figheight()
    left = size * np.cos(np.radians(SLANT)) / fig.get_figwidth()  # the first name's reach
    x0, y0, width, height = ax.get_position().bounds
    x1, y1 = x0 + width, y0 + height
    ax.set_position([max(x0, left), max(y0, below), x1 - max(x0, left), y1 - max(y0, below)])


def differing_parts(names) -> tuple[tuple[str, ...], str]:
    """The part of each name that differs from the others, and the pattern they share
    (``f-0009.csv``, ``f-0020.csv`` -> ``("0009", "0020")``, ``"f-*.csv"``), cut at
    non-alphanumeric characters; the names and ``""`` when nothing is shared."""
    names = tuple(names)
    if len(names) < 2:
        return names, ""
    head = os.path.commonprefix(names)
    tail = os.path.commonprefix([n[::-1] for n in names])[::-1]
    head = head[:max((k + 1 for k, c in enumerate(head) if not c.isalnum()), default=0)]
    tail = tail[min((k for k, c in enumerate(tail) if not c.isalnum()), default=len(tail)):]
    parts = tuple(n[len(head):len(n) - len(tail)] for n in names)
    if not (head or tail) or not all(parts):
        return names, ""
    return parts, f"{head}*{tail}"


def plot_trajectories(track, *, every: int = 1, background: bool = True, ax=None):
    """Draw the path of every ``every``-th tracked node over the frames, coloured by
    frame, over the first frame's shape (black) and the last frame's (magenta), each
    named, and over the last frame's image when it was read from one (``background``).

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
        pts, closed, ordered, faces, sizes = describe(track.shape(f), "track")
        edges = edges_of(m, closed, ordered, faces, sizes)
        if len(edges) and faces is None:
            ax.add_collection(line_collection(pts[edges], ax, colors=color, linewidths=0.8,
                                              zorder=3))
        ax.scatter(*pts.T, s=6, c=color, linewidths=0, zorder=4,
                   label=short_names(track.names)[f])
    handles, labels = ax.get_legend_handles_labels()
    legend_above(ax, handles, labels)
    ticks, pattern = differing_parts(short_names(track.names))
    cbar = ax.figure.colorbar(lines, ax=ax, shrink=0.8,
                              label=f"frame ({pattern})" if pattern else "frame")
    _name_frames(cbar.ax.yaxis, ticks)
    finish_axes(ax, points.reshape(-1, dim), view, image=image)
    return ax


def energy_labels(track) -> tuple[str, str]:
    """(legend, axis label) of ``track.cumulative_energy``, the strain energy summed over
    the morphs that lead from frame 0 to each frame, in the words of how the frames were
    reached (``track.source_frame``): one morph from frame 0 each, a chain of
    frame-to-frame morphs, or some of each."""
    source = np.asarray(track.source_frame)[1:]
    if not source.any():
        return "energy from frame 0", "strain energy (22) of the morph from frame 0"
    if np.array_equal(source, np.arange(len(source))):
        return "energy summed frame to frame", "strain energy (22) summed frame to frame"
    return ("energy from frame 0", "strain energy (22) from frame 0 (summed where a "
            "frame came from the previous one)")


def plot_track_curves(track, *, ax=None):
    """Global strain (and each segment's) and the strain energy of reaching each frame
    from frame 0 (``track.cumulative_energy``, named by :func:`energy_labels`) over the
    frames: strain on ``ax`` (left axis, in %), energy on a twin axis on the right.

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
    names = short_names(track.names)
    ticks, pattern = differing_parts(names)
    if pattern:
        ax.set_xlabel(f"frame ({pattern})")
    _name_frames(ax.xaxis, ticks)
    if track.n_frames <= MAX_NAMED_FRAMES and max(map(len, ticks)) > 6:
        _slant_names(ax, max(map(len, ticks)))
    ax.set_ylabel(f"strain against {names[0]} (%)")
    right = ax.twinx()
    legend, label = energy_labels(track)
    right.plot(frames, track.cumulative_energy, color=TARGET_COLOR, ls="--", lw=1.5,
               label=legend)
    right.set_ylabel(f"{label} ({ENERGY_UNIT})", color=TARGET_COLOR)
    handles = ax.get_legend_handles_labels()
    more = right.get_legend_handles_labels()
    legend_above(ax, handles[0] + more[0], handles[1] + more[1])  # hides no curve
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
