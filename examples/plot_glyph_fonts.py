"""
Glyphs: strain energy as a distance between fonts
=================================================

Strain energy (22) measures how much an object had to deform to become another, with
changes of position, orientation and size free (``free_motion="similarity"``, the
default). Here the letter "g" of DejaVu Sans is morphed into the same letter of five
fonts that ship with matplotlib; the energy ranks the fonts by how far their "g" is from
the sans-serif one.
"""

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.font_manager import FontProperties
from matplotlib.textpath import TextPath

import modalmorph as mm


def outline(letter, family, nodes=100):
    """The largest closed polygon of a glyph, resampled to ``nodes`` nodes."""
    path = TextPath((0, 0), letter, size=100, prop=FontProperties(family=family))
    polygons = path.to_polygons(closed_only=True)
    largest = max(polygons, key=lambda p: abs(np.sum(p[:-1, 0] * p[1:, 1]
                                                     - p[1:, 0] * p[:-1, 1])))
    return mm.resample(largest[:-1], nodes)


fonts = ["DejaVu Sans", "DejaVu Sans Mono", "DejaVu Serif", "STIXGeneral", "cmr10"]
source = outline("g", fonts[0])
targets = {font: outline("g", font) for font in fonts[1:]}
energy = {font: mm.morph(source, t).energy[-1] for font, t in targets.items()}

fig, axes = plt.subplots(1, 2, figsize=(12, 4), layout="constrained",
                         gridspec_kw={"width_ratios": [2, 1]})
for i, (font, t) in enumerate(targets.items()):
    axes[0].fill(*(t - t.mean(0) + [130 * i, 0]).T, alpha=0.6, label=font)
axes[0].plot(*(source - source.mean(0) - [130, 0]).T, "k-", label="DejaVu Sans (source)")
axes[0].set_aspect("equal")
axes[0].axis("off")
axes[0].legend(loc="lower center", ncols=3, fontsize=8, bbox_to_anchor=(0.5, -0.3))
axes[1].barh(list(energy), list(energy.values()), color="tab:orange")
axes[1].set_xlabel("strain energy of the morph from DejaVu Sans")

summary = ", ".join(f"{font} {e:.3g}" for font, e in sorted(energy.items(),
                                                          key=lambda kv: kv[1]))
print(summary)
