"""Reading rings and label volumes: accuracy of the boundaries and time per frame.

    PYTHONPATH=src python benchmarks/read_masks.py

Prints (1) the radii of a pixelated ring's two contours against the truth (marching
squares at half level, then resampled by arc length), for LV-sized rings at clinical
resolution; (2) the time to read a 30-frame 2D+t NIfTI label volume of 128 x 128 voxels
(issue 23's sequence), per frame; (3) the noise holes of thresholded scikit-image samples
behind :data:`~modalmorph.io.images.MIN_HOLE_AREA`.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from modalmorph.io import read_frames
from modalmorph.io.images import MIN_HOLE_AREA, mask_shape


def ring(size, outer, inner, centre):
    rows, cols = np.indices((size, size))
    r = np.hypot(cols - centre[0], rows - centre[1])
    return (r <= outer) & (r > inner)


def radii_table():
    print("ring (px)          contour  nodes  mean radius  truth   max |error|")
    rng = np.random.default_rng(0)
    for outer, inner in ((35.0, 25.0), (30.0, 20.0), (25.0, 16.0)):
        centre = 64 + rng.uniform(-0.5, 0.5, 2)
        shape = mask_shape(ring(128, outer, inner, centre), "ring", nodes=120)
        for k, truth in enumerate((outer, inner)):
            r = np.hypot(*(shape.points[shape.slices[k]] - centre).T)
            print(f"{outer:4.0f} / {inner:4.0f}        {k:>7d}  {shape.sizes[k]:5d}  "
                  f"{r.mean():11.3f}  {truth:5.1f}   {np.abs(r - truth).max():.3f}")


def nifti_time(frames=30, size=128):
    import nibabel

    i, j = np.indices((size, size))
    r = np.hypot(i - 64.0, j - 60.0)
    volume = np.stack([np.where(r <= 28 - 4 * np.sin(np.pi * t / frames) ** 2,
                                np.where(r <= 18 - 5 * np.sin(np.pi * t / frames) ** 2, 3, 2),
                                0) for t in range(frames)], axis=-1).astype(np.uint8)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "cine.nii.gz"
        image = nibabel.Nifti1Image(volume[:, :, None, :], np.diag([1.4, 1.4, 8.0, 1.0]))
        nibabel.save(image, path)
        start = time.perf_counter()
        read = read_frames(path, label=2)
        took = time.perf_counter() - start
    sizes = {s.sizes for s in read.shapes}
    print(f"\nNIfTI {size} x {size} x {frames} frames (label 2, a ring): {took:.3f} s, "
          f"{1e3 * took / frames:.1f} ms per frame; contours per frame: "
          f"{sorted({len(s) for s in sizes})}")


def noise_holes():
    from skimage import color, data, filters, measure

    names = ["camera", "coins", "moon", "page", "text", "horse", "astronaut", "coffee",
             "chelsea", "rocket", "hubble_deep_field", "immunohistochemistry", "brick",
             "grass", "gravel", "clock", "checkerboard"]
    areas = []
    for name in names:
        im = getattr(data, name)()
        im = np.asarray(color.rgb2gray(im[..., :3]) if im.ndim == 3 else im, float)
        mask = im > (filters.threshold_otsu(im) if len(np.unique(im)) > 2 else im.mean())
        if np.mean(np.r_[mask[0], mask[-1], mask[:, 0], mask[:, -1]]) > 0.5:
            mask = ~mask
        labels = measure.label(mask, connectivity=1)
        obj = labels == np.argmax(np.bincount(labels.ravel())[1:]) + 1
        loops = measure.find_contours(np.pad(obj, 1).astype(float), 0.5)
        a = sorted(abs(0.5 * np.sum(c[:-1, 0] * c[1:, 1] - c[1:, 0] * c[:-1, 1]))
                   for c in loops)
        areas += a[:-1]  # the holes: all but the outer boundary
    areas = np.array(areas)
    print(f"\nholes of the largest object of {len(names)} thresholded skimage images: "
          f"{len(areas)}")
    for limit in (1.0, 4.0, MIN_HOLE_AREA, 16.0, 64.0):
        print(f"  area < {limit:5.1f} px^2: {np.mean(areas < limit):6.1%}")


if __name__ == "__main__":
    radii_table()
    nifti_time()
    noise_holes()
