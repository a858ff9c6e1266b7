"""
3D point cloud: matching an unordered, turned, warped copy
==========================================================

Unordered 3D points (no faces) are matched by the modal matcher and refined coarse to
fine. The source is 1500 points on a bumpy blob; the target is a smooth warp of it,
turned by 90 degrees, with 1 % noise, 80 % of its points kept, and shuffled. Since the
truth is known, each pair's error can be measured, here in % of the target's RMS radius
(its size), and against the node spacing: the side of the square each target node would
cover on a sphere of that radius, sqrt(4 pi R^2 / n).
"""

import matplotlib.pyplot as plt
import numpy as np

import modalmorph as mm

rng = np.random.default_rng(2005)
direction = rng.normal(size=(1500, 3))
direction /= np.linalg.norm(direction, axis=1)[:, None]
x, y, z = direction.T
radius = 1 + 0.15 * np.sin(3 * x) * np.cos(2 * y) + 0.1 * z**2
source = direction * radius[:, None] * [1.6, 1.0, 0.8]

warp = source + 0.1 * np.sin(source[:, [1, 2, 0]])
c, s = 0.0, 1.0                                           # 90 degrees about z
truth = warp @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T
keep = rng.permutation(len(truth))[: int(0.8 * len(truth))]
target = truth[keep] + 0.01 * np.ptp(truth, axis=0).max() * rng.normal(size=(len(keep), 3))

matching = mm.match(source, target)
pairs = matching.pairs
size = np.sqrt(np.mean(np.sum((target - target.mean(0)) ** 2, axis=1)))
where_kept = {int(j): i for i, j in enumerate(keep)}        # source row -> target row
known = np.array([p for p in pairs if int(p[0]) in where_kept])
error = 100 * np.linalg.norm(truth[keep[known[:, 1]]] - truth[known[:, 0]], axis=1) / size

fig = plt.figure(figsize=(12, 4.4), layout="constrained")
ax = fig.add_subplot(1, 2, 1, projection="3d")
ax.scatter(*source.T, s=2, color="0.3", label="source")
ax.scatter(*(target + [4, 0, 0]).T, s=2, color="tab:red", label="target (shifted)")
for i, j in pairs[::25]:
    ax.plot(*np.column_stack([source[i], target[j] + [4, 0, 0]]), color="tab:blue", lw=0.5)
ax.set_axis_off()
ax.legend(loc="upper left")
ax2 = fig.add_subplot(1, 2, 2)
ax2.hist(error, bins=40, color="tab:blue")
ax2.set_xlabel("pair error against the noise-free truth, % of the size")
ax2.set_ylabel("pairs")
spacing = 100 * np.sqrt(4 * np.pi / len(target))              # in % of the size
ax2.axvline(spacing, color="k", ls="--", label=f"one node spacing ({spacing:.1f} %)")
ax2.legend()
ax2.set_title(f"median {np.median(error):.1f} %, 90th percentile {np.percentile(error, 90):.1f} %")

summary = f"{len(pairs)} pairs; median error {np.median(error):.1f} % of the size"
print(summary)
