"""Shapes of several contours from files and masks: rings, holes, labels, glyphs, NIfTI."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.path import Path as MplPath

from modalmorph.core.quality import area
from modalmorph.errors import InputFileError
from modalmorph.io.images import MIN_HOLE_AREA, mask_shape


def ring(size=100, outer=30.0, inner=15.0, centre=(50.0, 45.0)):
    """A ring mask (H, W) bool: a disc of radius ``outer`` with a hole of ``inner``."""
    rows, cols = np.indices((size, size))
    r = np.hypot(cols - centre[0], rows - centre[1])
    return (r <= outer) & (r > inner)


def test_mask_shape_ring_outer_then_hole():
    shape = mask_shape(ring(), "ring", nodes=120)
    assert len(shape.sizes) == 2 and sum(shape.sizes) == 120
    outer, hole = (shape.points[s] for s in shape.slices)
    assert area(outer) > 0 > area(hole)  # outer counter-clockwise, hole clockwise in (x, y)
    # nodes shared by length (3 each, the rest in proportion): within one node of rounding
    length = np.array([np.linalg.norm(p - np.roll(p, 1, axis=0), axis=1).sum()
                       for p in (outer, hole)])
    assert np.all(np.abs(np.subtract(shape.sizes, 3) - 114 * length / length.sum()) <= 1)
    # sub-pixel boundaries at half level: radii within a pixel of the truth
    r_out = np.hypot(*(outer - [50.0, 45.0]).T)
    r_in = np.hypot(*(hole - [50.0, 45.0]).T)
    assert np.all(np.abs(r_out - 30.0) < 1.0) and np.all(np.abs(r_in - 15.0) < 1.0)
    inside = MplPath(outer).contains_points(hole)
    assert inside.all()  # the hole lies inside the outer boundary
    assert shape.frame.size == (100, 100) and shape.frame.y_down


def test_mask_shape_without_hole_is_one_contour():
    disc = ring(inner=-1.0)
    shape = mask_shape(disc, "disc")
    assert shape.contours is None and shape.m == 200


def test_mask_shape_noise_holes_ignored():
    mask = ring(inner=-1.0)
    mask[50, 50] = mask[40, 40:42] = False  # holes of 1 and 2 px: specks of noise
    assert mask_shape(mask, "specks").contours is None
    mask[55:58, 45:48] = False  # a 3 x 3 hole: area MIN_HOLE_AREA
    shape = mask_shape(mask, "hole")
    assert len(shape.sizes) == 2
    assert abs(area(shape.points[shape.slices[1]])) == pytest.approx(MIN_HOLE_AREA, rel=0.2)


def test_mask_shape_label_image_picks_the_label():
    labels = np.zeros((90, 120), dtype=np.uint8)
    labels[10:40, 10:40] = 1
    labels[50:80, 60:110] = 2
    labels[20:30, 70:100] = 3
    shape = mask_shape(labels, "labels", label=2)
    x, y = shape.points.T
    assert x.min() == pytest.approx(59.5) and x.max() == pytest.approx(109.5)
    assert y.min() == pytest.approx(49.5) and y.max() == pytest.approx(79.5)
    with pytest.raises(InputFileError, match="labels: a label image .*label"):
        mask_shape(labels, "labels")
    with pytest.raises(InputFileError, match="no pixel has label 7"):
        mask_shape(labels, "labels", label=7)


def test_mask_shape_all_objects():
    labels = np.zeros((60, 100), dtype=bool)
    labels[10:30, 10:30] = labels[35:55, 50:90] = True
    labels[2, 95] = True  # a speck: not an object of "all"
    shape = mask_shape(labels, "two", choice="all")
    assert len(shape.sizes) == 2
    first, second = (shape.points[s] for s in shape.slices)
    assert first[:, 0].max() < 31 and second[:, 0].min() > 49  # reading order


@pytest.mark.parametrize("bad, match", [
    (np.zeros((4, 4, 2)), "2D"), (np.zeros((5, 5)), "no object"),
    (np.full((5, 5), np.nan), "non-finite")])
def test_mask_shape_bad_input(bad, match):
    with pytest.raises(InputFileError, match=f"frame 3: .*{match}"):
        mask_shape(bad, "frame 3")


# ------------------------------------------------------------------------------ NIfTI


def _ring_labels(t: int, size=64):
    """A label slice (X, Y): 1 = right ventricle blob, 2 = a myocardium ring contracting
    with ``t``, 3 = its blood pool."""
    i, j = np.indices((size, size))  # voxel indices (first axis i = x)
    r = np.hypot(i - 32.0, j - 30.0)
    outer, inner = 20.0 - 0.5 * t, 12.0 - 0.8 * t
    out = np.zeros((size, size), dtype=np.int16)
    out[r <= outer] = 2
    out[r <= inner] = 3
    out[(i < 8) & (j > 20) & (j < 40)] = 1
    return out


def _save_nifti(path, data, spacing):
    nib = pytest.importorskip("nibabel")
    spacing = (*spacing, 1.0)[:3] if len(spacing) < 3 else spacing
    image = nib.Nifti1Image(data, np.diag([*spacing, 1.0]))
    image.header.set_zooms(spacing[: data.ndim] + (1.0,) * (data.ndim - len(spacing)))
    image.header.set_xyzt_units("mm", "msec")
    nib.save(image, path)
    return path


def test_nifti_2d_t_frames_in_mm(tmp_path):
    from modalmorph.io import read_frames, read_shape

    volume = np.stack([_ring_labels(t) for t in range(4)], axis=-1)[:, :, None, :]
    path = _save_nifti(tmp_path / "cine.nii.gz", volume, (1.5, 1.5, 8.0))
    frames = read_frames(path, label=2)
    assert len(frames.shapes) == 4 and frames.names[1] == f"{path}[frame 1]"
    for t, shape in enumerate(frames.shapes):
        assert len(shape.sizes) == 2 and shape.frame.unit == "mm"
        outer, hole = (shape.points[s] for s in shape.slices)
        # voxel (i, j) -> (1.5 i, 1.5 j) mm; ring radii within a voxel (1.5 mm) of the truth
        assert_radii(outer, (48.0, 45.0), 1.5 * (20.0 - 0.5 * t), 1.5)
        assert_radii(hole, (48.0, 45.0), 1.5 * (12.0 - 0.8 * t), 1.5)
    with pytest.raises(InputFileError, match="2D\\+t volume of 4 frames"):
        read_shape(path, label=2)
    two_d = _save_nifti(tmp_path / "ed.nii", _ring_labels(0), (1.5, 1.5))
    shape = read_shape(two_d, label=3)  # the blood pool: one contour
    assert shape.contours is None
    assert_radii(shape.points, (48.0, 45.0), 18.0, 1.5)
    with pytest.raises(InputFileError, match="label image, label= the object"):
        read_shape(two_d)


def assert_radii(points, centre, radius, tol):
    r = np.hypot(*(points - centre).T)
    assert np.all(np.abs(r - radius) < tol), (r.min(), r.max(), radius)


def test_nifti_frames_of_different_grids_are_refused(tmp_path):
    from modalmorph.io import read_frames

    a = _save_nifti(tmp_path / "f0.nii", _ring_labels(0), (1.5, 1.5))
    b = _save_nifti(tmp_path / "f1.nii", _ring_labels(1), (1.2, 1.2))
    c = _save_nifti(tmp_path / "f2.nii", _ring_labels(1, size=70), (1.5, 1.5))
    with pytest.raises(InputFileError, match=f"{b}: pixel spacing .*first frame"):
        read_frames([a, b], label=2)
    with pytest.raises(InputFileError, match=f"{c}: the image is 70 x 70 px"):
        read_frames([a, c], label=2)
    volume = np.zeros((8, 8, 3, 2), dtype=np.uint8)
    bad = _save_nifti(tmp_path / "vol.nii", volume, (1.0, 1.0, 1.0))
    with pytest.raises(InputFileError, match="vol.nii: expected a 2D slice"):
        read_frames(bad)


def test_nifti_without_nibabel_says_how_to_install(tmp_path, monkeypatch):
    import sys

    from modalmorph.io import read_shape

    path = tmp_path / "a.nii"
    path.write_bytes(b"\0" * 400)
    monkeypatch.setitem(sys.modules, "nibabel", None)
    with pytest.raises(InputFileError, match=r"a.nii: reading NIfTI .*modalmorph\[nifti\]"):
        read_shape(path)
