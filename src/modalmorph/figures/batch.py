"""The summary figure of a batch (:func:`modalmorph.apps.batch.run`)."""

from __future__ import annotations

from ._draw import DISTANCE_NAME, ENERGY_UNIT, SHAPE_COLOR, TARGET_COLOR, new_axes

MAX_LABELLED = 30  # items named beside their dot at most (more would hide the dots)


def plot_batch(results, *, ax=None):
    """One point per completed pair of a batch: its stop test's distance, as a multiple
    of its tolerance (unit-free, so items in pixels and in other units share the axis;
    converged items lie left of the line at 1), against its strain energy.

    Parameters
    ----------
    results : sequence of ItemResult
        The rows of :func:`modalmorph.apps.batch.run` (``Batch.results``); items without
        those numbers (failed, interrupted, sequences) are counted in the title. Each
        point is named with its item's id when there are at most :data:`MAX_LABELLED`.
    ax : matplotlib Axes, optional

    Returns
    -------
    matplotlib.axes.Axes
    """
    if ax is None:
        ax = new_axes(2, "chart")
    done = [r for r in results if r.distance is not None and r.energy is not None
            and r.tolerance]
    for converged, marker, color in ((True, "o", SHAPE_COLOR), (False, "x", "#d95f02")):
        rows = [r for r in done if bool(r.converged) == converged]
        if rows:
            ax.scatter([r.distance / r.tolerance for r in rows], [r.energy for r in rows],
                       s=18, color=color, marker=marker, zorder=3,
                       label="converged" if converged else "not converged")
    if len(done) <= MAX_LABELLED:
        for r in done:
            ax.annotate(r.id, (r.distance / r.tolerance, r.energy), xytext=(3, 3),
                        textcoords="offset points", fontsize="x-small")
    ax.axvline(1.0, color=TARGET_COLOR, ls=":", lw=1.2, label="tolerance")
    skipped = len(results) - len(done)
    ax.set(xlabel=f"{DISTANCE_NAME} / tolerance", ylabel=f"strain energy ({ENERGY_UNIT})",
           title=f"{len(done)} of {len(results)} items drawn"
                 + (f"; {skipped} not (failed, not run, or sequences)" if skipped else ""))
    ax.set_xlim(left=0.0)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize="small")
    return ax
