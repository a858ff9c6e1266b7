"""Figures of a stance phase (:func:`modalmorph.stance`): the tracked contours of every
part over the pressure image through stance, and the strain energy per part.

The plate is drawn as it is read: rows down (the walking direction), columns across, in
mm (the sensor pitch), the pressure in the array's units (``pressure_unit`` names them).
A sensor's square is centred on its (column, row) x pitch, where the contours put it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ._draw import ENERGY_RANGE, import_matplotlib

__all__ = ["MAX_PANELS", "length_unit", "plot_footprints", "plot_part_energy",
           "plot_stance_frames", "pressure_label", "save_stance_figures"]

MAX_PANELS = 8  # frames drawn side by side at most (8 footprints of 33 x 63 sensors fit A4)
# Part colours: 20 distinct ones (a real stance phase has up to 18 parts; tab10 gave
# parts 0 and 10 one colour).
_CYCLE, _COLOURS = "tab20", 20


def _colour(part: int):
    import matplotlib

    return matplotlib.colormaps[_CYCLE](part % _COLOURS)


def length_unit(pixel_size: float) -> str:
    """The unit of lengths at this sensor pitch: mm, or sensors at pitch 1."""
    return "mm" if pixel_size != 1 else "sensors"


def pressure_label(params: dict) -> str:
    """The colour bar's name: pressure and its unit (``pressure_unit``), else said to
    be the input's."""
    unit = (params or {}).get("pressure_unit") or "the input's units"
    return f"pressure ({unit})"


def plot_stance_frames(stance, *, frames=None, fig=None):
    """The pressure image of several frames with every part's tracked nodes (coloured by
    part) on its boundary (white).

    Parameters
    ----------
    stance : Stance
    frames : sequence of int, optional
        Stance frames to draw (default: up to :data:`MAX_PANELS` spread over the stance).
    fig : matplotlib Figure, optional

    Returns
    -------
    matplotlib Figure
    """
    import_matplotlib()
    from matplotlib.figure import Figure

    n = stance.n_frames
    frames = np.unique(np.linspace(0, n - 1, min(n, MAX_PANELS)).round().astype(int)) \
        if frames is None else np.asarray(frames, dtype=int)
    fig = fig or Figure(figsize=(1.4 * len(frames) + 1.0, 3.6), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, len(frames), sharey=True))
    h, w = stance.pressure.shape[1:]
    px = stance.pixel_size
    extent = (-0.5 * px, (w - 0.5) * px, (h - 0.5) * px, -0.5 * px)
    top = float(stance.pressure.max())
    for ax, f in zip(axes, frames, strict=True):
        image = ax.imshow(stance.pressure[f], cmap="magma", vmin=0, vmax=top, extent=extent,
                          interpolation="nearest")
        for b in stance.observed[f].contours:
            ax.plot(*np.vstack([b, b[:1]]).T, color="white", lw=0.8)
        for part in stance.parts:
            k = np.flatnonzero(part.frames == f)
            if len(k):
                p = part.points[k[0]]
                ax.plot(*np.vstack([p, p[:1]]).T, ".-", color=_colour(part.part), ms=2,
                        lw=0.6)
        ax.set_title(f"frame {stance.frames[f]}", fontsize=8)
        ax.set_xlabel(f"x ({length_unit(px)})", fontsize=8)
        ax.tick_params(labelsize=7)
    axes[0].set_ylabel(f"y ({length_unit(px)}), walking direction", fontsize=8)
    fig.colorbar(image, ax=list(axes), shrink=0.8, label=pressure_label(stance.params))
    return fig


def plot_part_energy(stance, *, ax=None):
    """Strain energy of every frame's deformation per part (a line each from its second
    frame: the first has none) and in all (black), against the input's frame."""
    import_matplotlib()
    if ax is None:
        import matplotlib.pyplot as plt

        ax = plt.figure(figsize=(6.4, 3.6), layout="constrained").add_subplot()
    frames = stance.frames
    for part in stance.parts:
        if len(part.frames) > 1:
            ax.plot(frames[part.frames[1:]], part.energy[1:], ".-", color=_colour(part.part),
                    lw=1, label=f"part {part.part}")
    ax.plot(frames, stance.energy, "k-", lw=2, label="all parts")
    ax.set_xlabel("frame of the input")
    ax.set_ylabel("strain energy per frame, eq. (22)")
    ax.set_yscale("symlog", linthresh=max(1e-3, float(np.nanmax(stance.energy)) * 1e-3))
    # beside the axes (the layout makes room for it): inside, it hid the curves' peaks
    ax.figure.legend(*ax.get_legend_handles_labels(), fontsize=7,
                     ncols=1 + len(stance.parts) // 12, loc="outside right upper")
    return ax


def save_stance_figures(stance, out_dir, *, dpi: int = 150) -> list[Path]:
    """``stance.png`` (:func:`plot_stance_frames`) and ``stance_energy.png``
    (:func:`plot_part_energy`) in ``out_dir``; returns their paths."""
    import_matplotlib()
    from matplotlib.figure import Figure

    out = Path(out_dir)
    fig = plot_stance_frames(stance)
    fig.savefig(out / "stance.png", dpi=dpi)
    energy = Figure(figsize=(7.4, 3.6), layout="constrained")
    plot_part_energy(stance, ax=energy.add_subplot())
    energy.savefig(out / "stance_energy.png", dpi=dpi)
    return [out / "stance.png", out / "stance_energy.png"]


def plot_footprints(registrations, *, titles=None, ncols: int = 10, fig=None,
                    unit: str = "mm"):
    """A grid of registered footprints (:func:`modalmorph.register_footprints`):
    each template part moved onto the image's part, coloured by the strain energy of
    its nodes (25) on one scale for all (up to the 98th percentile: a few folded
    registrations would grey out the rest), the node where it peaks marked (red +), the
    template's parts left unpaired in grey; a scale bar in ``unit`` (the footprints'
    coordinates: mm with a sensor pitch, else sensors) on the first, and a line saying
    what the marks are.

    Returns
    -------
    matplotlib Figure
    """
    import_matplotlib()
    from matplotlib.collections import LineCollection
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure

    n = len(registrations)
    rows = -(-n // ncols)
    fig = fig or Figure(figsize=(0.9 * min(n, ncols) + 1, 2.2 * rows), layout="constrained")
    axes = np.atleast_1d(fig.subplots(rows, min(n, ncols), sharex=True, sharey=True)).ravel()
    values = np.concatenate([e for r in registrations for e in r.node_energy])
    finite = values[np.isfinite(values)]
    norm = Normalize(0.0, float(np.percentile(finite, ENERGY_RANGE[1])) if len(finite)
                     else 1.0)
    for i, (ax, reg) in enumerate(zip(axes, registrations, strict=False)):
        for k, shape in enumerate(reg.shapes):
            if shape is None:
                t = reg.template[k]
                ax.plot(*np.vstack([t, t[:1]]).T, color="0.7", lw=0.6)
                continue
            closed = np.vstack([shape, shape[:1]])
            e = reg.node_energy[k]
            segs = np.stack([closed[:-1], closed[1:]], axis=1)
            ax.add_collection(LineCollection(segs, array=0.5 * (e + np.roll(e, -1)),
                                             cmap="viridis", norm=norm, lw=1.5))
        if reg.shapes[reg.peak_part] is not None:
            ax.plot(*reg.shapes[reg.peak_part][reg.peak_node], "r+", ms=5)
        ax.set_title(titles[i] if titles else f"{i}", fontsize=6)
        ax.set_aspect("equal")
        ax.axis("off")
    for ax in axes[n:]:
        ax.axis("off")
    axes[0].invert_yaxis()  # rows of the plate down, as the pressure images
    axes[0].autoscale()
    _scale_bar(axes[0], unit)
    mappable = axes[0].collections[0] if axes[0].collections else None
    if mappable is not None:
        fig.colorbar(mappable, ax=list(axes), shrink=0.6, extend="max",
                     label="node strain energy, eq. (25)")
    fig.suptitle("template parts registered onto each image, coloured by node strain "
                 "energy; +: its peak; grey: a template part with no partner", fontsize=8)
    return fig


def _scale_bar(ax, unit: str) -> None:
    """A vertical bar of a round length (1, 2 or 5 x 10^k, at most 40 % of the shown
    height) at the left of ``ax``, its length written beside it."""
    (x0, _), (y0, y1) = ax.get_xlim(), sorted(ax.get_ylim())
    most = 0.4 * (y1 - y0)
    power = 10.0 ** np.floor(np.log10(most))
    length = max(v * power for v in (1, 2, 5) if v * power <= most)
    ax.plot([x0, x0], [y1, y1 - length], color="k", lw=2, clip_on=False)
    ax.text(x0, y1 - length / 2, f"{length:g} {unit} ", ha="right", va="center",
            rotation=90, fontsize=6)
