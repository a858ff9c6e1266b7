"""The summary figure of a batch (:func:`modalmorph.apps.batch.run`)."""

from __future__ import annotations

from ._draw import ENERGY_UNIT, SHAPE_COLOR, new_axes


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
        ax = new_axes(2, "chart")
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
