"""Myocardial strain (issue 23): definitions, phantoms with analytic motion, files, CLI."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from numpy.testing import assert_allclose

import modalmorph as mm
from modalmorph.apps.cli import main
from modalmorph.apps.strain import write_strain
from modalmorph.cardiac import (
    KINDS,
    SMOOTH_MIN_FRAMES,
    mask_ring,
    rounding_stretch,
    wall_strain,
)
from modalmorph.errors import OptionError, ShapeError
from modalmorph.phantoms import ring_phantom

FRAMES = 7  # end-systole at frame 3


def _circle(centre, radius, n, phase=0.0):
    th = phase + np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.asarray(centre) + radius * np.c_[np.cos(th), -np.sin(th)]


def _truth(ph) -> dict:
    """The definitions applied to the exact material motion (dense nodes)."""
    endo, epi = _circle(ph.centre, ph.inner, 720), _circle(ph.centre, ph.outer, 4000)
    f = range(len(ph.masks))
    return wall_strain(np.array([ph.move(endo, i) for i in f]),
                       np.array([ph.move(epi, i) for i in f]))


@pytest.fixture(scope="module")
def phantom():
    return ring_phantom(FRAMES)


@pytest.fixture(scope="module")
def result(phantom):
    return mm.strain(phantom.masks)


def test_zero_at_the_reference(result, phantom):
    for kind in KINDS:
        assert_allclose(getattr(result, kind)[0], 0.0, atol=1e-9)  # l / l - 1
    other = mm.strain(phantom.masks, reference_frame=3)
    for kind in KINDS:
        assert_allclose(getattr(other, kind)[3], 0.0, atol=1e-9)
    assert (other.circumferential[0] > 0).all()  # end-diastole is longer than systole


def test_phantom_global_strain_within_tolerance(result, phantom):
    truth = _truth(phantom)
    # benchmarks/strain.py, noiseless 30-frame phantoms: global errors <= 1.0 point
    for kind in ("radial", "circumferential", "circumferential_endo"):
        assert_allclose(getattr(result, kind)[:, 0], truth[kind][:, 0], atol=1.5)
    assert truth["radial"][3, 0] > 15 and truth["circumferential"][3, 0] < -10
    assert repr(result).startswith(f"Strain({FRAMES} frames, 6 segments")


def test_exact_motion_is_incompressible_and_rotation_free():
    """Truth of a twisted ring: thickening and shortening do not see the rotation, and
    thickness x midwall length (the wall's area) is kept to first order."""
    plain, twisted = ring_phantom(5), ring_phantom(5, twist=20.0)
    a, b = _truth(plain), _truth(twisted)
    for kind in KINDS:
        assert_allclose(a[kind], b[kind], atol=1e-6)  # strain is frame-indifferent
    area = (1 + a["radial"][:, 0] / 100) * (1 + a["circumferential"][:, 0] / 100)
    assert_allclose(area, 1.0, atol=0.02)  # incompressible wall (curvature: 2nd order)


def test_segments_by_angle_counterclockwise_as_shown():
    centre = np.array([50.0, 50.0])
    angles = np.radians(np.arange(6) * 60 + 30)  # the middle of each 60-degree sector
    endo = centre + 10 * np.c_[np.cos(angles), -np.sin(angles)]  # y down: -sin
    endo = np.repeat(endo[None], 2, axis=0)
    epi = np.repeat(_circle(centre, 20, 400)[None], 2, axis=0)
    assert wall_strain(endo, epi)["segment_of_chord"].tolist() == [1, 2, 3, 4, 5, 6]
    assert wall_strain(endo, epi, angle=60.0)["segment_of_chord"].tolist() == \
        [6, 1, 2, 3, 4, 5]
    # the point above the centre on the image (smaller y) is at 90 degrees
    assert wall_strain(endo, epi, segments=4)["segment_of_chord"][1] == 2


def test_segments_are_lagrangian_and_find_an_akinetic_sector():
    ph = ring_phantom(FRAMES, sector=(60.0, 120.0, 0.0), twist=15.0)
    truth = _truth(ph)
    got = mm.strain(ph.masks)
    weakest = 1 + np.argmin(np.abs(got.peak("circumferential")[0][1:]))
    assert weakest == 2 == 1 + np.argmin(np.abs(truth["circumferential"][3, 1:]))
    assert np.abs(truth["circumferential"][3, 2]) < 5  # the sector barely shortens


def test_akinetic_sector_segments_within_the_goal():
    # the pairs follow the reference wall's normals: no sliding towards the sector that
    # does not contract (nearest pairs: 7.8 points off in segment 2, 4.4 in segment 1)
    ph = ring_phantom(FRAMES, sector=(60.0, 120.0, 0.0))
    truth, got = _truth(ph), mm.strain(ph.masks)
    for kind in ("radial", "circumferential"):  # measured: 1.44, 1.07 points
        assert np.abs(getattr(got, kind) - truth[kind]).max() < 2.0


def test_smoothing_over_time():
    ph = ring_phantom(SMOOTH_MIN_FRAMES)
    raw, smooth = (mm.strain(ph.masks, smooth_frames=s) for s in (0.0, 1.0))
    rounding = np.array(raw.params["rounding"])  # the tracks are of the rounded walls
    assert_allclose(raw.endo, raw.tracks[0].points @ rounding.T, atol=1e-9)
    assert np.abs(smooth.endo - raw.endo).max() > 1e-3  # smoothed, the reference too
    for kind in KINDS:  # ... and the strain is still 0 there
        assert_allclose(getattr(smooth, kind)[0], 0.0, atol=1e-9)
    short = mm.strain(ph.masks[:5])  # under SMOOTH_MIN_FRAMES: as tracked
    assert_allclose(short.endo, short.tracks[0].points @ np.array(short.params["rounding"]).T,
                    atol=1e-9)
    with pytest.raises(OptionError, match="smooth_frames"):
        mm.StrainOptions(smooth_frames=-1.0)


def test_rv_point_and_rv_label_set_segment_one(phantom):
    c = phantom.centre
    got = mm.strain(phantom.masks[:2], rv_point=(c[0] - 30, c[1]))  # RV at 180 degrees
    assert got.reference_angle == pytest.approx(120.0, abs=1.0)  # one segment before
    labels = phantom.masks[:2].astype(np.uint8)
    labels[:, 54:75, 5:15] = 3  # an "RV" left of the ventricle
    got = mm.strain(labels, label=1, rv_label=3)
    assert got.reference_angle == pytest.approx(60.0, abs=3.0)  # septum = segments 2-3


def test_rates_and_peaks(result):
    rate = result.rate("radial")
    assert_allclose(rate[1:-1], (result.radial[2:] - result.radial[:-2]) / 2, atol=1e-12)
    value, frame = result.peak("circumferential")
    assert frame[0] == 3 and value[0] == result.circumferential[3, 0]
    per_second = mm.strain(ring_phantom(3).masks, frame_interval=0.05)
    assert_allclose(per_second.rate("radial"), np.gradient(per_second.radial, 0.05, axis=0))


def test_endo_only_and_no_hole():
    ph = ring_phantom(3)
    disks = np.array([ph.masks[f] | _filled(ph.masks[f]) for f in range(3)])
    with pytest.raises(ShapeError, match="frame 1: the wall has no hole"):
        mm.strain(np.r_[ph.masks[:1], disks[1:]])
    got = mm.strain(disks, endo_only=True)  # the outline of a filled mask
    assert np.isnan(got.radial).all() and got.circumferential_endo[1, 0] < -5
    with pytest.raises(ShapeError, match="not a ring"):
        mm.strain([mm.Shape(_circle((0, 0), 5, 30))] * 2)


def _filled(mask):
    from scipy import ndimage

    return ndimage.binary_fill_holes(mask)


def test_ring_shapes_as_input(phantom):
    rings = [mask_ring(m, "f") for m in phantom.masks[:4]]
    shapes = [mm.Shape(np.vstack([epi, endo]), contours=(len(epi), len(endo)))
              for endo, epi in rings]
    from_shapes = mm.strain(shapes)
    from_masks = mm.strain(phantom.masks[:4])
    assert_allclose(from_shapes.radial[:, 0], from_masks.radial[:, 0], atol=1e-9)


def test_several_objects_are_said(phantom):
    masks = phantom.masks[:2].copy()
    masks[:, 2:6, 2:6] = True  # a speck in a corner
    with pytest.warns(UserWarning, match=r"object 2 of 2 \(the largest\).*1 more frames"):
        mm.strain(masks)


def test_options_are_checked():
    with pytest.raises(OptionError, match="segments"):
        mm.StrainOptions(segments=0)
    with pytest.raises(OptionError, match="rv_point"):
        mm.StrainOptions(rv_point=(1.0,))
    with pytest.raises(OptionError, match="reference_frame"):
        mm.strain(ring_phantom(2).masks, reference_frame=5)


def test_files_columns(result, tmp_path):
    files = write_strain(result, tmp_path / "out", report=True)
    names = {p.name for p in files}
    assert {"strain.csv", "strain.json", "report.html", "bullseye.png", "wall.png",
            "strain_curves.png"} <= names
    with open(tmp_path / "out" / "strain.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0])[:6] == ["frame", "segment", *KINDS]
    assert len(rows) == FRAMES * 7
    row = rows[3 * 7]  # frame 3, global
    assert float(row["radial"]) == pytest.approx(result.radial[3, 0], rel=1e-5)
    record = json.loads((tmp_path / "out" / "strain.json").read_text())
    assert record["reference_frame"] == 0 and record["units"]["strain"] == "percent"
    assert set(record["definitions"]) >= set(KINDS)
    assert record["peaks"]["radial"]["frame"][0] == 3


def _save_pngs(folder, masks):
    from PIL import Image

    folder.mkdir()
    for i, m in enumerate(masks):
        Image.fromarray((m * 255).astype(np.uint8)).save(folder / f"f{i}.png")


def test_cli_writes_and_refuses(tmp_path, capsys):
    ph = ring_phantom(3)
    np.save(tmp_path / "ring.npy", ph.masks.astype(np.uint8))
    out = tmp_path / "out"
    assert main(["strain", str(tmp_path / "ring.npy"), "--out", str(out), "-q",
                 "--segments", "4", "--reference-angle", "45"]) == 0
    record = json.loads((out / "strain.json").read_text())
    assert record["segments"] == 4 and record["reference_angle"] == 45.0
    assert record["inputs"][0]["sha256"]
    disks = np.array([_filled(m) for m in ph.masks]).astype(np.uint8)
    np.save(tmp_path / "disk.npy", disks)
    assert main(["strain", str(tmp_path / "disk.npy"), "--out", str(tmp_path / "o2")]) == 2
    assert "disk.npy[0]: the wall has no hole" in capsys.readouterr().err
    assert main(["strain", str(tmp_path / "disk.npy"), "--out", str(tmp_path / "o3"), "-q",
                 "--endo-only", "--no-figures"]) == 0
    assert not (tmp_path / "o3" / "wall.png").exists()
    _save_pngs(tmp_path / "sizes", [ph.masks[0], ph.masks[1][:-2]])
    assert main(["strain", str(tmp_path / "sizes"), "--out", str(tmp_path / "o4")]) == 2
    err = capsys.readouterr().err
    assert "f1.png: the mask is 128 x 126 px" in err and "share one grid" in err


def test_nifti_input(tmp_path, phantom):
    nibabel = pytest.importorskip("nibabel")
    data = np.moveaxis(phantom.masks[:3].astype(np.uint8), 0, -1).transpose(1, 0, 2)
    image = nibabel.Nifti1Image(data, np.diag([0.5, 0.5, 1.0, 1.0]))  # (X, Y, T)
    nibabel.save(image, tmp_path / "ring.nii.gz")
    got = mm.strain(tmp_path / "ring.nii.gz")
    ref = mm.strain(phantom.masks[:3])
    assert got.spacing == (0.5, 0.5)
    assert_allclose(got.endo[0], ref.endo[0] * 0.5, atol=1e-9)  # mm, not pixels
    assert_allclose(got.radial, ref.radial, atol=1e-9)  # strain has no unit


def test_nifti_spacings_must_agree(tmp_path, phantom):
    nibabel = pytest.importorskip("nibabel")
    for name, dx in (("a.nii", 0.5), ("b.nii", 0.7)):
        data = phantom.masks[0].astype(np.uint8).T  # (X, Y)
        nibabel.save(nibabel.Nifti1Image(data, np.diag([dx, dx, 1.0, 1.0])), tmp_path / name)
    assert main(["strain", str(tmp_path / "a.nii"), str(tmp_path / "b.nii"), "--out",
                 str(tmp_path / "o")]) == 2


def test_cli_rv_point(tmp_path, phantom):
    np.save(tmp_path / "ring.npy", phantom.masks[:2].astype(np.uint8))
    c = phantom.centre
    assert main(["strain", str(tmp_path / "ring.npy"), "--out", str(tmp_path / "o"), "-q",
                 "--no-figures", "--rv-point", f"{c[0] - 30},{c[1]}"]) == 0
    record = json.loads((tmp_path / "o" / "strain.json").read_text())
    assert record["reference_angle"] == pytest.approx(120.0, abs=1.0)


def test_phantom_segmented_boundaries_lie_on_the_noisy_masks():
    ph = ring_phantom(FRAMES, noise=0.5, sector=(60.0, 120.0, 0.0), twist=10.0)
    clean = ring_phantom(FRAMES, sector=(60.0, 120.0, 0.0), twist=10.0)
    for k, radius in enumerate((ph.inner, ph.outer)):
        ref = _circle(ph.centre, radius, 200)
        assert_allclose(clean.segmented(ref, 3, k), clean.move(ref, 3), atol=1e-12)
        p = ph.segmented(ref, 3, k)
        ray = (p - ph.centre) / np.linalg.norm(p - ph.centre, axis=1)[:, None]
        sign = 1 if k else -1  # into the wall: inward from the epicardium
        for step, inside in ((-1.0, True), (1.0, False)):  # a pixel is 0.71 px from its centre
            q = np.rint(p + sign * step * ray).astype(int)
            assert (ph.masks[3][q[:, 1], q[:, 0]] == inside).all()


def test_cli_gives_the_library_defaults_and_its_flags_change_them(tmp_path, phantom):
    """The command line measures what mm.strain measures with its defaults (the strain's
    morph tolerance included), and a morph flag changes only that field."""
    np.save(tmp_path / "ring.npy", phantom.masks[:4].astype(np.uint8))
    assert main(["strain", str(tmp_path / "ring.npy"), "--out", str(tmp_path / "a"), "-q",
                 "--no-figures"]) == 0
    got = np.genfromtxt(tmp_path / "a" / "strain.csv", delimiter=",", names=True)
    ref = mm.strain(phantom.masks[:4])
    assert_allclose(got["radial"][got["segment"] == 0], ref.radial[:, 0], atol=1e-3)
    assert main(["strain", str(tmp_path / "ring.npy"), "--out", str(tmp_path / "b"), "-q",
                 "--no-figures", "--tol", "0.02"]) == 0
    record = json.loads((tmp_path / "a" / "strain.json").read_text())["options"]
    loose = json.loads((tmp_path / "b" / "strain.json").read_text())["options"]
    assert record["morph"]["tol"] == 0.001 and loose["morph"]["tol"] == 0.02
    assert loose["morph"]["k"] == record["morph"]["k"]  # the other fields kept
    assert record["track"]["correspondence"] == "normal"


def _exact(ph, spacing=(1.0, 1.0)) -> dict:
    """The definitions on the exact motion of any phantom (elliptical too), in mm."""
    f = range(len(ph.masks))
    return wall_strain(*[np.array([ph.move(ph.wall(r, n), i) for i in f]) * spacing
                         for r, n in ((ph.inner, 720), (ph.outer, 4000))])


def test_rounding_stretch_is_the_walls_ellipse():
    assert_allclose(rounding_stretch(_circle((40.0, 30.0), 20.0, 200)), np.eye(2),
                    atol=1e-3)
    ellipse = _circle((0.0, 0.0), 1.0, 400) * [np.sqrt(1.3) * 20, 20 / np.sqrt(1.3)]
    stretch = rounding_stretch(ellipse)
    assert_allclose(stretch, np.diag([np.sqrt(1.3), 1 / np.sqrt(1.3)]), atol=1e-3)
    assert np.linalg.det(stretch) == pytest.approx(1.0)


@pytest.mark.parametrize("aspect", [1.15, 1.3])
def test_elliptical_ring_has_no_false_hypokinesis(aspect):
    # review17: plain normals slid the material points towards the long axis, segments
    # 2 and 5 of aspect 1.3 at -12 % against -17 % (6.4 points; 0.4 made round)
    ph = ring_phantom(FRAMES, aspect=aspect)
    truth, got = _exact(ph), mm.strain(ph.masks)
    for kind in ("circumferential", "circumferential_endo"):  # measured 0.6-1.0
        assert np.abs(getattr(got, kind) - truth[kind]).max() < 1.5, kind


def test_anisotropic_pixels_have_no_false_hypokinesis(tmp_path):
    # a circle in pixels of 1.5 x 0.8 mm is an ellipse in mm (review17: segments 2 and
    # 5 at -6.7 % against -17.9 %)
    nibabel = pytest.importorskip("nibabel")
    ph = ring_phantom(FRAMES)
    data = np.transpose(ph.masks, (2, 1, 0))[:, :, None, :].astype(np.int16)
    nibabel.save(nibabel.Nifti1Image(data, np.diag([1.5, 0.8, 8.0, 1.0])),
                 tmp_path / "cine.nii.gz")
    truth, got = _exact(ph, (1.5, 0.8)), mm.strain(tmp_path / "cine.nii.gz")
    for kind in ("circumferential", "circumferential_endo"):
        assert np.abs(getattr(got, kind) - truth[kind]).max() < 1.5, kind


def test_short_cine_keeps_its_peaks():
    # review17: a 12-frame cine smoothed (sigma 1 frame) lost 1.9 points of peak radial
    # strain; under SMOOTH_MIN_FRAMES frames it is not smoothed
    ph = ring_phantom(12)
    truth, got = _exact(ph), mm.strain(ph.masks)
    for kind in ("radial", "circumferential"):  # measured 0.65 / 0.09 points
        assert got.peak(kind)[0][0] == pytest.approx(truth[kind][6, 0], abs=1.0), kind


def test_a_ring_beside_a_larger_solid_blob_is_taken_and_said(phantom):
    masks = phantom.masks[:2].copy()
    masks[:, 100:128, 0:80] = True  # a solid object larger than the ring
    with pytest.warns(UserWarning, match=r"object 1 of 2 \(the largest with a hole"):
        got = mm.strain(masks)
    assert got.params["object"] == "largest" and np.isfinite(got.radial).all()
    solid = np.zeros_like(masks)
    solid[:, 10:30, 10:30] = solid[:, 60:70, 60:70] = True
    with pytest.raises(ShapeError, match="none of the mask's objects has one"):
        mm.strain(solid)


def test_rv_point_off_the_image_or_on_the_centre_is_refused(tmp_path, phantom):
    with pytest.raises(OptionError, match=r"rv_point \(500, -300\) lies outside the image: "
                                          r"x -0.5..127.5"):
        mm.strain(phantom.masks[:2], rv_point=(500.0, -300.0))
    with pytest.raises(OptionError, match="from the ventricle's centre"):
        mm.strain(phantom.masks[:2], rv_point=tuple(phantom.centre))
    np.save(tmp_path / "ring.npy", phantom.masks[:2].astype(np.uint8))
    assert main(["strain", str(tmp_path / "ring.npy"), "--out", str(tmp_path / "o"), "-q",
                 "--rv-point=500,-300"]) == 2
