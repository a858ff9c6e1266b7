"""
Horse: a shape read from an image
=================================

scikit-image's horse silhouette (:func:`skimage.data.horse`, a binary image) is saved as
a PNG and read back with :func:`modalmorph.read_shape`, as ``modalmorph morph horse.png
...`` would: the outline of the largest object, in pixel coordinates ``(x, y) = (column,
row)`` with y pointing down, resampled to 160 nodes by arc length. The target is the same
outline with its legs bent and its body stretched, a smooth warp in pixels. Figures draw
a shape read from an image over that image, y down.
"""

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from PIL import Image
from skimage import data

import modalmorph as mm
from modalmorph import figures

folder = Path(tempfile.mkdtemp())
mask = ~data.horse()                        # True on the horse
Image.fromarray(mask).save(folder / "horse.png")
horse = mm.read_shape(folder / "horse.png", nodes=160)

x, y = horse.points.T
height = (y - y.min()) / np.ptp(y)          # 0 at the top (y down), 1 at the hooves
warped = np.column_stack([x + 40 * height**3 + 0.1 * (x - x.mean()),
                          y - 15 * np.sin(np.pi * (x - x.min()) / np.ptp(x))])
target = mm.Shape(warped, frame=horse.frame)
result = mm.morph(horse, target)

fig, axes = plt.subplots(1, 2, figsize=(12, 4.8), layout="constrained")
figures.plot_shapes(result, color_by="energy", ax=axes[0])
figures.plot_energy(result, ax=axes[1])

summary = f"{horse.m} nodes from a {mask.shape[1]} x {mask.shape[0]} px image: {result.message}"
print(summary)
