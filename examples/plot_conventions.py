"""
Input conventions: y up in coordinate files, y down in images and SVG
=====================================================================

The same numbers mean different pictures in different formats. Coordinates in CSV, TSV,
TXT, NPY, NPZ and JSON are plain coordinates, y pointing up. Images and SVG are drawn y
down: a shape read from them carries an :class:`~modalmorph.core.shape.ImageFrame` and the
figures draw it that way, so it looks as it does in the file. Here one polygon, an "L"
with its foot at small y, is written as a CSV file and as an SVG path; each is read with
:func:`modalmorph.read_shape` and morphed into a slanted copy of itself from the same
kind of file. SVG shapes are resampled by arc length (200 nodes unless ``nodes`` is
given, ``--nodes``); coordinate files keep their nodes unless asked.
"""

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import modalmorph as mm
from modalmorph import figures

ell = np.array([[0, 0], [60, 0], [60, 15], [15, 15], [15, 80], [0, 80]], dtype=float)
slanted = ell + np.column_stack([0.4 * ell[:, 1], np.zeros(len(ell))])
folder = Path(tempfile.mkdtemp())


def write_csv(points, name):
    np.savetxt(folder / name, points, delimiter=",", header="x,y", comments="")
    return mm.read_shape(folder / name, nodes=80)


def write_svg(points, name):
    d = "M " + " L ".join(f"{x:g},{y:g}" for x, y in points) + " Z"
    (folder / name).write_text(
        '<svg xmlns="http://www.w3.org/2000/svg" width="120" height="100">'
        f'<path d="{d}" fill="none" stroke="black"/></svg>')
    return mm.read_shape(folder / name, nodes=80)


results = {"CSV (y up)": mm.morph(write_csv(ell, "a.csv"), write_csv(slanted, "b.csv")),
           "SVG (y down)": mm.morph(write_svg(ell, "a.svg"), write_svg(slanted, "b.svg"))}

fig, axes = plt.subplots(1, 2, figsize=(11, 4.6), layout="constrained")
for ax, (name, result) in zip(axes, results.items(), strict=True):
    figures.plot_shapes(result, color_by=None, ax=ax)
    ax.set_title(name, pad=24)

summary = "; ".join(f"{name}: {r.source.m} nodes, {r.steps} steps"
                    for name, r in results.items())
print(summary)
