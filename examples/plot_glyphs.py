"""
Glyphs: letters of one font into another
========================================

The outer outline of a letter drawn by matplotlib's :class:`~matplotlib.textpath.TextPath`
in DejaVu Sans is morphed into the same letter in DejaVu Serif (both fonts ship with
matplotlib). The outlines are polygons with few vertices; :func:`modalmorph.resample`
spreads 120 nodes evenly along each by arc length. Font coordinates point y up, so the
shapes are plain arrays and drawn y up.
"""

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.font_manager import FontProperties
from matplotlib.textpath import TextPath

import modalmorph as mm
from modalmorph import figures


def outline(letter, family, nodes=120):
    """The largest closed polygon of a glyph, resampled to ``nodes`` nodes."""
    path = TextPath((0, 0), letter, size=100, prop=FontProperties(family=family))
    polygons = path.to_polygons(closed_only=True)
    largest = max(polygons, key=lambda p: abs(np.sum(p[:-1, 0] * p[1:, 1]
                                                     - p[1:, 0] * p[:-1, 1])))
    return mm.resample(largest[:-1], nodes)


letters = "aRS5"
fig, axes = plt.subplots(2, 2, figsize=(11, 10), layout="constrained")
results = {}
for ax, letter in zip(axes.flat, letters, strict=True):
    source, target = outline(letter, "DejaVu Sans"), outline(letter, "DejaVu Serif")
    results[letter] = mm.morph(source, target)
    figures.plot_shapes(results[letter], color_by="energy", ax=ax)
    ax.set_title(f"{letter!r}: {results[letter].steps} steps", pad=24)

summary = "; ".join(f"{k}: energy {r.energy[-1]:.3g}, {r.stop_reason}"
                    for k, r in results.items())
print(summary)
