"""
A stance phase on a pressure plate: every loaded part with ``stance``
=====================================================================

Dynamic pedobarography, the paper's home field: the loaded region of a foot on a
pressure plate changes through the stance phase. The heel touches down, the forefoot and
the toes follow, parts merge and leave. :func:`modalmorph.stance` finds each frame's
loaded parts with sub-sensor boundaries (marching squares on the lightly smoothed
pressure), follows every part from when it appears to when it leaves with its own nodes,
and gives the strain energy of every frame's deformation per part and in all, as
``modalmorph stance stack.npy --out DIR`` writes them.

With the optional package jiku-data (GPL-3, ``pip install jiku-data``) this runs on a
real stance phase of Pataky et al. (2008) at 25 Hz; without it, on a synthetic one.
"""

import numpy as np

import modalmorph as mm
from modalmorph.figures.stance import plot_part_energy, plot_stance_frames

try:
    from modalmorph.io.pressure import jiku_trial

    pressure = jiku_trial(3, 0, every=20)  # subject 3, trial 0: 500 Hz taken at 25 Hz
    source = "jiku-data: subject 3, trial 0"
except ImportError:  # a heel, then a forefoot, joined by the midfoot for a while
    print("jiku-data is not installed: a synthetic stance phase instead")
    rows, cols = np.indices((40, 20), dtype=float)
    pressure = np.array([
        100 * (t < 10) * np.exp(-0.5 * (((rows - 8) / (2 + t / 4)) ** 2 + ((cols - 10) / 4) ** 2))
        + 80 * (t > 3) * np.exp(-0.5 * (((rows - 30) / 3.5) ** 2 + ((cols - 10) / 4) ** 2))
        + 40 * (6 < t < 9) * np.exp(-0.5 * (((rows - 19) / 7) ** 2 + ((cols - 10) / 2) ** 2))
        for t in range(14)])
    pressure[pressure < 10] = 0  # the plate reads nothing below 10 kPa
    source = "synthetic"

result = mm.stance(pressure)
fig = plot_stance_frames(result)
ax = plot_part_energy(result)

# %%
# ``result.parts`` holds each part's tracked nodes (F_p, m, 2), its energy per frame and
# how it began and ended; ``result.events`` says when parts appear, merge and leave.
for event in result.events[:6]:
    print(event)
summary = (f"{source}: {result.n_frames} frames, {len(result.parts)} parts, total strain "
           f"energy {result.energy.sum():.3g}; largest node-to-boundary distance "
           f"{max(p.node_distance.max() for p in result.parts):.2f} sensors")
print(summary)
