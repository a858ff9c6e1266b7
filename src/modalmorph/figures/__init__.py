"""Figures and animations of a morph, a tracked sequence and a batch.

Where each lives:

- :mod:`~modalmorph.figures.morph`: one morph's figures, :func:`plot_matches`,
  :func:`plot_shapes` (the intermediate shapes, the paper's figure), :func:`plot_energy`,
  the steps they draw (:func:`frame_steps`), and :func:`save_figures` to write them all;
- :mod:`~modalmorph.figures.animation`: :func:`animate`, a GIF or MP4 of the deformation;
- :mod:`~modalmorph.figures.track`: a sequence's :func:`plot_trajectories`,
  :func:`plot_track_curves`, :func:`save_track_figures` and :func:`animate_track`;
- :mod:`~modalmorph.figures.batch`: :func:`plot_batch`, the summary of a batch;
- ``_draw``: what they share (axes and layouts, colours, colour maps and bars, the view
  of the coordinates, the edges drawn, saving a set of figures).

Every function here imports matplotlib when called, so the core of modalmorph stays
numpy + scipy. The plotting functions take ``ax=None`` and return the Axes they drew on;
they never call ``plt.show()``. When no Axes is given they make a pyplot figure, which
the caller owns (close it with ``plt.close(ax.figure)``). :func:`save_figures` and
:func:`animate` build their figures without pyplot, so they leave no open figures behind.

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

from ._draw import (
    COLOR_BY,
    DISTANCE_NAME,
    ENERGY_COLORS,
    ENERGY_UNIT,
    IMAGE_ALPHA,
    MATCH_COLOR,
    MEAN_DISTANCE_NAME,
    NO_DEFORMATION,
    SHAPE_COLOR,
    SOURCE_COLOR,
    TARGET_COLOR,
)
from .animation import GIF_DPI, MAX_ANIMATION_FRAMES, animate
from .batch import plot_batch
from .morph import (
    FIGURE_DPI,
    MAX_FIGURE_SHAPES,
    RASTER_SEGMENTS,
    frame_steps,
    plot_energy,
    plot_matches,
    plot_shapes,
    save_figures,
)
from .track import animate_track, plot_track_curves, plot_trajectories, save_track_figures

__all__ = [
    # figures and animations
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
    # limits, resolutions and the palette
    "COLOR_BY",
    "DISTANCE_NAME",
    "ENERGY_COLORS",
    "ENERGY_UNIT",
    "FIGURE_DPI",
    "GIF_DPI",
    "IMAGE_ALPHA",
    "MATCH_COLOR",
    "MAX_ANIMATION_FRAMES",
    "MAX_FIGURE_SHAPES",
    "MEAN_DISTANCE_NAME",
    "NO_DEFORMATION",
    "RASTER_SEGMENTS",
    "SHAPE_COLOR",
    "SOURCE_COLOR",
    "TARGET_COLOR",
]
