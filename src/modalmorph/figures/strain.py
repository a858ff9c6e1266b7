"""Figures of myocardial strain (:func:`modalmorph.strain`): curves per segment with their
peaks, a polar bullseye of the peak strain by segment, the tracked wall over the masks."""

from __future__ import annotations

import numpy as np

from ._draw import short_names

__all__ = ["plot_strain_curves", "plot_bullseye", "plot_wall", "SEGMENT_COLORS"]

SEGMENT_COLORS = "tab10"  # segment s is colour s - 1 of this map (global: black)
DARK = 0.3  # RdBu_r beyond 0.5 +- this is dark enough for white text (looked at)


def _plt():
    import matplotlib.pyplot as plt

    return plt


# The walls in colours no segment has (segments: the first colours of SEGMENT_COLORS).
ENDO_COLOR, EPI_COLOR = "magenta", "cyan"


def _kinds(result) -> tuple:
    return (("circumferential_endo",) if result.endo_only else
            ("radial", "circumferential", "circumferential_endo", "circumferential_epi"))


def _color(s: int):
    from matplotlib import colormaps

    return "black" if s == 0 else colormaps[SEGMENT_COLORS](s - 1)


def plot_strain_curves(result, *, kinds=None, fig=None):
    """Strain against frame, one panel per kind, a line per segment (global in black,
    thick), each peak marked by a dot. Returns the Figure."""
    plt = _plt()
    from matplotlib.ticker import MaxNLocator

    kinds = _kinds(result) if kinds is None else tuple(kinds)
    if fig is None:
        fig = plt.figure(figsize=(5.2 * min(len(kinds), 2), 3.6 * ((len(kinds) + 1) // 2)),
                         layout="constrained")
    axes = fig.subplots((len(kinds) + 1) // 2, min(len(kinds), 2), squeeze=False).ravel()
    dt = result.params.get("frame_interval")
    x = np.arange(result.n_frames) * (dt or 1.0)
    for ax, kind in zip(axes, kinds, strict=False):
        values = getattr(result, kind)
        peak, frame = result.peak(kind)
        for s in range(values.shape[1]):
            label = "global" if s == 0 else f"segment {s}"
            ax.plot(x, values[:, s], color=_color(s), lw=2.4 if s == 0 else 1.2, label=label)
            ax.plot(x[frame[s]], peak[s], "o", color=_color(s), ms=5)
        ax.axhline(0, color="0.6", lw=0.6)
        ax.axvline(x[result.reference], color="0.6", lw=0.6, ls=":")
        ax.set_title(kind.replace("_", " "))
        ax.set_xlabel("time (s)" if dt else "frame")
        if not dt:
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_ylabel("strain (%)")
    for ax in axes[len(kinds):]:
        ax.set_visible(False)
    axes[0].legend(fontsize=7, ncol=2)
    return fig


def plot_bullseye(result, kind: str | None = None, *, ax=None):
    """The peak strain of each segment as a polar ring of sectors, drawn as on the image
    (counterclockwise, segment 1 from the reference angle), the value and number written
    in each and the global peak in the middle. Returns the Axes."""
    plt = _plt()
    from matplotlib import colormaps
    from matplotlib.colors import TwoSlopeNorm

    kind = kind or ("circumferential_endo" if result.endo_only else "circumferential")
    peak, _ = result.peak(kind)
    if ax is None:
        ax = plt.figure(figsize=(4.4, 4.4), layout="constrained").add_subplot(
            projection="polar")
    n = result.segments
    width = 2 * np.pi / n
    start = np.radians(result.reference_angle)
    limit = max(float(np.nanmax(np.abs(peak))), 1e-9)
    norm = TwoSlopeNorm(0.0, -limit, limit)
    cmap = colormaps["RdBu_r"]
    for s in range(1, n + 1):
        theta = start + (s - 0.5) * width
        ax.bar(theta, 1.0, width=width, bottom=0.5, color=cmap(norm(peak[s])),
               edgecolor="white", lw=1.5)
        dark = abs(norm(peak[s]) - 0.5) > DARK  # white text on the dark ends of the map
        ax.text(theta, 1.0, f"{s}\n{peak[s]:+.1f}", ha="center", va="center", fontsize=9,
                color="white" if dark else "black")
    ax.text(0, 0, f"global\n{peak[0]:+.1f} %", ha="center", va="center", fontsize=10)
    ax.set_ylim(0, 1.5)
    ax.set_axis_off()
    ax.set_title(f"peak {kind.replace('_', ' ')} strain (%)", fontsize=10)
    return ax


def plot_wall(result, frames=None, *, fig=None):
    """The tracked endocardium, epicardium and chords (coloured by segment) over the
    masks, at the reference frame and at the global peak (or ``frames``). Returns the
    Figure."""
    plt = _plt()
    kind = "circumferential_endo" if result.endo_only else "radial"
    if frames is None:
        frames = (result.reference, int(result.peak(kind)[1][0]))
    if fig is None:
        fig = plt.figure(figsize=(4.2 * len(frames), 4.9), layout="constrained")
    axes = fig.subplots(1, len(frames), squeeze=False).ravel()
    box = _box(result)
    for ax, f in zip(axes, frames, strict=True):
        if result.masks is not None:
            sx, sy = result.spacing
            h, w = result.masks.shape[1:]
            ax.imshow(result.masks[f] != 0, cmap="gray", vmin=0, vmax=2.5,
                      extent=(-0.5 * sx, (w - 0.5) * sx, (h - 0.5) * sy, -0.5 * sy))
        for p, color in ((result.endo[f], ENDO_COLOR), (result.epi[f], EPI_COLOR)):
            if len(p):
                ax.plot(*np.vstack([p, p[:1]]).T, color=color, lw=1.2)
        if not result.endo_only:
            for i, s in enumerate(result.segment_of_chord):
                ax.plot(*np.c_[result.endo[f, i], result.outer[f, i]], color=_color(s),
                        lw=0.9)
        ax.plot(*result.centre, "+", color="yellow")
        ax.set_xlim(box[0], box[2])
        ax.set_ylim(box[3], box[1])
        ax.set_aspect("equal")
        ax.set_title(f"frame {f} ({short_names(result.names)[f]})", fontsize=9)
        unit = result.params.get("unit", "px")
        ax.set_xlabel(f"x ({unit})")
        ax.set_ylabel(f"y ({unit})")
    fig.legend(handles=_wall_legend(result), fontsize=8, loc="outside lower center",
               ncol=4, frameon=False)
    return fig


def _wall_legend(result) -> list:
    """What the wall figure's lines are."""
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], color=ENDO_COLOR, label="endocardium")]
    if not result.endo_only:
        handles += [Line2D([], [], color=EPI_COLOR, label="epicardium"),
                    Line2D([], [], color=_color(1), label="chords (colour: segment)")]
    return handles + [Line2D([], [], ls="", marker="+", color="yellow",
                             label="reference centre")]


def _box(result) -> tuple:
    """x0, y0, x1, y1 around every tracked node with a margin."""
    pts = np.concatenate([result.endo.reshape(-1, 2), result.epi.reshape(-1, 2)])
    low, high = pts.min(axis=0), pts.max(axis=0)
    pad = 0.15 * float((high - low).max())
    return (*(low - pad), *(high + pad))
