"""
3D surface: a mesh written and read with meshio
===============================================

A triangulated surface made procedurally (an ellipsoid's surface, by scikit-image's
marching cubes) is written as a PLY file with meshio and read back with
:func:`modalmorph.read_shape`, as ``modalmorph morph a.ply b.ply`` would: nodes and
faces. The target is the same surface bent and turned by 30 degrees. In 3D the morph
stops on the two-way distance between the surfaces.
"""

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import meshio
import numpy as np
from skimage import measure

import modalmorph as mm

# an ellipsoid's surface by marching cubes over its implicit function (scikit-image)
grid = np.linspace(-1.2, 1.2, 18)
X, Y, Z = np.meshgrid(grid, grid, grid, indexing="ij")
volume = (X / 1.0) ** 2 + (Y / 0.6) ** 2 + (Z / 0.45) ** 2
verts, faces, _, _ = measure.marching_cubes(volume, level=1.0, spacing=(grid[1] - grid[0],) * 3)
source_points = verts - verts.mean(0)
c, s = np.cos(np.pi / 6), np.sin(np.pi / 6)
bent = source_points + np.column_stack([np.zeros(len(verts)),
                                        0.3 * source_points[:, 0] ** 2, np.zeros(len(verts))])
target_points = bent @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T

folder = Path(tempfile.mkdtemp())
for name, p in (("source.ply", source_points), ("target.ply", target_points)):
    meshio.write(folder / name, meshio.Mesh(p, [("triangle", faces)]))
source, target = mm.read_shape(folder / "source.ply"), mm.read_shape(folder / "target.ply")
result = mm.morph(source, target)

fig = plt.figure(figsize=(12, 4.2), layout="constrained")
for i, (title, p) in enumerate([("source", result.shapes[0]),
                                (f"step {result.steps // 2}", result.shapes[result.steps // 2]),
                                (f"end, step {result.steps}", result.shapes[-1])]):
    ax = fig.add_subplot(1, 3, i + 1, projection="3d")
    ax.plot_trisurf(*p.T, triangles=result.source.faces, color="tab:blue", alpha=0.5,
                    linewidth=0.2, edgecolor="k")
    ax.scatter(*target.points.T, s=2, color="tab:red")
    ax.set_title(title)
    ax.set_box_aspect(np.ptp(target.points, axis=0))
    ax.set_axis_off()

summary = f"{source.m} nodes, {len(faces)} faces: {result.message}"
print(summary)
