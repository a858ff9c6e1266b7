"""
Vibration modes of the heart's Gaussian finite element model
============================================================

:class:`modalmorph.FEModel` builds Sclaroff's Gaussian element over the nodes of an
object (mass, stiffness: closed forms, ``docs/method.md`` section 1) in the object's
normalised frame (centroid at the origin, unit RMS radius). Its modes, ``K Phi = M Phi
Omega^2``, are what modal matching compares and what the dynamics superpose. The lowest
ones are drawn here, each added to the contour (grey) with an exaggerated amplitude;
the contour is resampled to 80 nodes evenly spaced by arc length first (the traced
contour's pixel staircase has nodes at uneven spacings, whose lowest modes are local).
"""

import matplotlib.pyplot as plt
import numpy as np

import modalmorph as mm
from modalmorph.datasets import load_heart

heart = mm.Shape(mm.resample(load_heart("diastole"), 80))   # even spacing; drawn y up
model = mm.FEModel(heart)
modes = model.modes(8)
X = heart.normalized

fig, axes = plt.subplots(2, 4, figsize=(13, 6.4), layout="constrained")
for ax, i in zip(axes.flat, range(8), strict=True):
    phi = modes.shapes[:, i].reshape(2, -1).T          # component-major (7): x, then y
    moved = X + 0.3 * phi / np.abs(phi).max()
    ax.plot(*np.vstack([X, X[:1]]).T, color="0.7")
    ax.plot(*np.vstack([moved, moved[:1]]).T, color="tab:blue")
    ax.set_title(f"mode {i + 1}: omega = {modes.frequencies[i]:.3g}", fontsize=9)
    ax.set_aspect("equal")
    ax.axis("off")

summary = (f"{heart.m} nodes, sigma {model.sigma:.3g} spacings; lowest frequencies "
           + ", ".join(f"{w:.2g}" for w in modes.frequencies[:6]))
print(summary)
