"""
Images with several objects: which one is read
==============================================

An image may hold several objects. :func:`modalmorph.read_shape` outlines one of them:
``object="largest"`` (the default; ``--object`` on the command line), ``"center"`` (the
one nearest the image centre) or a label number (1 = the first object in reading order,
row by row). A grey image needs a ``threshold`` (``--threshold``; Otsu's by default),
and whichever side covers most of the image border is the background, so dark objects on
a light background work as well as light on dark.
"""

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from PIL import Image
from skimage import data, draw, transform

import modalmorph as mm

# a grey picture: a dark horse, a disc and a square on a light background
canvas = np.full((300, 420), 220, dtype=np.uint8)
horse = transform.resize(~data.horse(), (150, 190)) > 0.5
canvas[120:270, 200:390][horse] = 40
canvas[draw.disk((80, 90), 55)] = 60
canvas[140:200, 40:100] = 80
path = Path(tempfile.mkdtemp()) / "objects.png"
Image.fromarray(canvas).save(path)

choices = {"largest": "largest", "center": "center", "label 3": 3}
shapes = {name: mm.read_shape(path, object=obj, threshold=150, nodes=120)
          for name, obj in choices.items()}

fig, axes = plt.subplots(1, 3, figsize=(13, 3.6), layout="constrained")
for ax, (name, shape) in zip(axes, shapes.items(), strict=True):
    ax.imshow(canvas, cmap="gray", vmin=0, vmax=255)        # rows down, as the shape
    ax.plot(*np.vstack([shape.points, shape.points[:1]]).T, "-", color="tab:red")
    ax.set_title(f"object={choices[name]!r}: {shape.m} nodes")
    ax.axis("off")

summary = ", ".join(f"{name}: centroid {np.round(s.points.mean(0)).astype(int).tolist()}"
                    for name, s in shapes.items())
print(summary)
