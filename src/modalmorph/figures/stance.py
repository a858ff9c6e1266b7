"""Figures of a stance phase (:func:`modalmorph.stance`): the tracked contours of every
part over the pressure image through stance, and the strain energy per part.

The plate is drawn as it is read: rows down (the walking direction), columns across, in
mm (the sensor pitch), the pressure in the array's units.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ._draw import import_matplotlib

__all__ = ["MAX_PANELS", "plot_stance_frames", "plot_part_energy", "save_stance_figures"]

MAX_PANELS = 8  # frames drawn side by side at most (8 footprints of 33 x 63 sensors fit A4)
_CYCLE = "tab10"


def _colour(part: int):
    import matplotlib

    return matplotlib.colormaps[_CYCLE](part % 10)


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
        ax.set_xlabel("mm" if px != 1 else "sensors", fontsize=8)
        ax.tick_params(labelsize=7)
    axes[0].set_ylabel("mm" if px != 1 else "sensors", fontsize=8)
    fig.colorbar(image, ax=list(axes), shrink=0.8, label="pressure")
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
    ax.set_xlabel("frame")
    ax.set_ylabel("strain energy per frame (22)")
    ax.set_yscale("symlog", linthresh=max(1e-3, float(np.nanmax(stance.energy)) * 1e-3))
    ax.legend(fontsize=7, ncols=4, loc="upper left")
    return ax


def save_stance_figures(stance, out_dir, *, dpi: int = 150) -> list[Path]:
    """``stance.png`` (:func:`plot_stance_frames`) and ``stance_energy.png``
    (:func:`plot_part_energy`) in ``out_dir``; returns their paths."""
    import_matplotlib()
    from matplotlib.figure import Figure

    out = Path(out_dir)
    fig = plot_stance_frames(stance)
    fig.savefig(out / "stance.png", dpi=dpi)
    energy = Figure(figsize=(6.4, 3.6), layout="constrained")
    plot_part_energy(stance, ax=energy.add_subplot())
    energy.savefig(out / "stance_energy.png", dpi=dpi)
    return [out / "stance.png", out / "stance_energy.png"]
