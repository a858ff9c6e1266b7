"""
A sequence: following the heart's nodes through a cycle with ``track``
======================================================================

A synthetic cardiac cycle of 12 frames made from the bundled end-diastole contour: each
frame contracts the ventricle smoothly (more at the apex side than at the base) and back,
and is resampled on its own, with a different node count and start, so that node ``i``
of one frame is not node ``i`` of the next. :func:`modalmorph.track` follows the nodes of
frame 0 through the sequence by morphing frame 0 onto each frame; its result gives the
trajectories, the strain energy of each frame's morph from frame 0 and the relative change
of the contour's length (global and per segment), as ``modalmorph track frames/ --out DIR
--cycle`` writes them.
"""

import matplotlib.pyplot as plt
import numpy as np

import modalmorph as mm
from modalmorph import figures
from modalmorph.datasets import load_heart

heart = mm.resample(load_heart("diastole"), 90)
centre = heart.mean(0)
frames = []
for f in range(12):
    squeeze = 0.25 * np.sin(np.pi * f / 11) ** 2               # 0 -> 0.25 -> 0
    along = (heart[:, 1] - heart[:, 1].min()) / np.ptp(heart[:, 1])
    points = centre + (heart - centre) * (1 - squeeze * (0.6 + 0.4 * along))[:, None]
    frames.append(np.roll(mm.resample(points, 80 + f % 3 * 5), 7 * f, axis=0))

tr = mm.track(frames, cycle=True)

fig, axes = plt.subplots(1, 2, figsize=(12, 4.8), layout="constrained")
figures.plot_trajectories(tr, ax=axes[0])
figures.plot_track_curves(tr, ax=axes[1])

# %%
# ``tr.points`` is (F, m, d): the nodes of frame 0 in every frame, same identities.
summary = (f"{tr.n_frames} frames of {tr.points.shape[1]} nodes; strain "
           f"{tr.strain.min():+.1%} at most; closure error {tr.closure_error:.3g}")
print(summary)
