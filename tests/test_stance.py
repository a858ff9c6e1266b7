"""stance(): every loaded part of a pressure stack, on small synthetic stance phases
(parts that appear, merge and leave); the command line; real data when jiku-data is
installed (opt-in: skipped without it)."""

import logging

import numpy as np
import pytest

from modalmorph import stance
from modalmorph.apps.cli import main
from modalmorph.errors import InputFileError
from modalmorph.io.pressure import frame_parts

H, W = 40, 20
NODE_TOL = 1.0  # sensors: a tracked node on its part's boundary (issue 24's goal)
GAP_TOL = 1.5  # sensors: a boundary point of a part of >= 12 sensors near a node (issue 24)
LARGE = 12


def blob(centre, radii, height):
    r, c = np.indices((H, W), dtype=float)
    return height * np.exp(-0.5 * (((r - centre[0]) / radii[0]) ** 2
                                   + ((c - centre[1]) / radii[1]) ** 2))


def synthetic_stance():
    """14 frames: nothing, a heel that grows, a forefoot that appears (frame 4), a
    midfoot joining them (frames 8-10: a merge), the heel leaving, nothing. Units kPa."""
    frames = []
    for t in range(14):
        p = np.zeros((H, W))
        if 1 <= t <= 11:
            p += blob((8, 10), (2 + 0.3 * min(t, 6), 3 + 0.2 * min(t, 6)),
                      100 * (1 - max(0, t - 8) / 4))
        if 4 <= t <= 12:
            p += blob((30, 10), (3 + 0.2 * (t - 4), 4), 80)
        if 8 <= t <= 10:
            p += blob((19, 10), (7, 2), 40)
        frames.append(np.where(p > 3, p, 0.0))  # the plate reads nothing below 3 kPa
    return np.array(frames)


@pytest.fixture(scope="module")
def result():
    return stance(synthetic_stance(), threshold=5.0)


def test_parts_appear_merge_and_leave(result):
    assert list(result.frames) == list(range(1, 13))  # frames 0 and 13 are empty: skipped
    text = " ".join(result.events)
    assert "part 1 appears" in text
    assert "merge into" in text
    starts = [p.start for p in result.parts]
    assert starts[0] == "first frame" and any(s.startswith("merge of parts") for s in starts)


def test_every_node_on_the_boundary_and_every_boundary_point_covered(result):
    for part in result.parts:
        assert part.node_distance.max() <= NODE_TOL
        large = part.sensors >= LARGE
        assert np.all(part.boundary_gap[large] <= GAP_TOL)
        assert not part.crossed.any()


def test_energy_per_part_and_in_all(result):
    assert np.all(result.energy >= 0)  # strain energy U^T K U of a stiffness matrix
    assert np.allclose(result.energy, np.nansum(result.part_energy, axis=1), atol=1e-12)
    for part in result.parts:
        assert part.energy[0] == 0.0  # a part's first frame has no deformation yet


def test_pixel_size_scales_contours_and_areas(result):
    mm = stance(synthetic_stance(), threshold=5.0, pixel_size=2.0)
    for a, b in zip(result.parts, mm.parts, strict=True):
        # the morph is scale-free (normalised shapes): the same path, twice as large
        assert np.allclose(b.points, 2.0 * a.points, atol=1e-6)
        assert np.allclose(b.area, 4.0 * a.area, rtol=1e-12)


def test_boundary_between_sensors():
    """Marching squares on the field: a disc's boundary is a smooth curve, no staircase:
    the radius varies by less than a quarter sensor round it."""
    r, c = np.indices((30, 30), dtype=float)
    disc = 100.0 * np.clip(1 - np.hypot(r - 15, c - 15) / 10, 0, None)
    parts = frame_parts(disc, 50.0, smooth=0)
    radius = np.hypot(*(parts.contours[0] - 15).T)
    assert len(parts.contours) == 1
    assert np.ptp(radius) < 0.25  # a staircase mask would vary by ~0.7 sensor


def test_single_sensor_contact_skipped_and_said(caplog):
    stack = synthetic_stance()
    stack[6, 39, 0] = 50.0  # one lone loaded sensor, in a corner
    with caplog.at_level(logging.INFO, logger="modalmorph"):
        result = stance(stack, threshold=5.0, smooth=0)
    assert "smaller than 2 sensors skipped" in caplog.text
    assert all(p.sensors.min() >= 2 for p in result.parts)


def test_image_is_one_frame():
    result = stance(synthetic_stance()[5], threshold=5.0)
    assert result.n_frames == 1 and len(result.parts) == 2


@pytest.mark.parametrize("change, match", [
    (lambda s: s.__setitem__((3, 5, 5), np.nan), "frame 3 has 1 NaN"),
    (lambda s: s.__imul__(0.0), "nothing is loaded"),
])
def test_bad_stacks_name_the_problem(change, match):
    stack = synthetic_stance()
    change(stack)
    with pytest.raises(InputFileError, match=match):
        stance(stack, threshold=5.0)


def test_threshold_above_every_value():
    stack = synthetic_stance()
    peak_frame = int(np.argmax(stack.max(axis=(1, 2))))
    with pytest.raises(InputFileError, match=rf"threshold 1000 is at or above every value "
                                             rf"\(the peak, {stack.max():g}, is in frame "
                                             rf"{peak_frame}\)"):
        stance(stack, threshold=1000.0)


def test_command_line(tmp_path, capsys):
    path = tmp_path / "stack.npy"
    np.save(path, synthetic_stance())
    assert main(["stance", str(path), "--threshold", "5", "--pixel-size", "5",
                 "--out", str(tmp_path / "out"), "-q"]) == 0
    names = {p.name for p in (tmp_path / "out").iterdir()}
    assert {"result.json", "stance.csv", "parts.npz", "stance.png"} <= names
    # track on a pressure stack follows every part too
    assert main(["track", str(path), "--threshold", "5", "--out", str(tmp_path / "t"),
                 "-q"]) == 0
    assert (tmp_path / "t" / "stance.csv").exists()
    bad = synthetic_stance()
    bad[7, 1, 1] = np.nan
    np.save(path, bad)
    assert main(["stance", str(path), "--out", str(tmp_path / "bad"), "-q"]) == 2
    assert "frame 7" in capsys.readouterr().err


def test_real_stance_phase():
    """Opt-in: a real trial of jiku-data (Pataky et al. 2008) at 25 Hz meets the goals."""
    pytest.importorskip("jikudata", reason="opt-in: needs the optional jiku-data")
    from modalmorph.io.pressure import jiku_trial

    result = stance(jiku_trial(3, 0, every=20))
    assert 15 <= result.n_frames <= 25
    for part in result.parts:
        assert part.node_distance.max() <= NODE_TOL
        assert np.all(part.boundary_gap[part.sensors >= LARGE] <= GAP_TOL)
        assert not part.crossed.any()


def test_footprints_registered_part_by_part():
    """Peak images: the template's own image costs no energy; a foot whose heel joins the
    forefoot through the midfoot is still registered part by part (the regions cut it)."""
    from modalmorph import register_footprints

    stack = synthetic_stance()
    peaks = np.array([stack[5], stack[6], stack.max(axis=0)])  # parts apart, apart, joined
    regs = register_footprints(peaks, template=0, threshold=5.0)
    assert len(regs[0].template) == 2  # heel and forefoot
    assert all(not r.missing for r in regs)
    # the template onto itself: every node already on its partner, no deformation
    assert regs[0].energy < 1e-8
    for r in regs:
        assert np.all(r.part_energy >= 0)  # U^T K U (22); node energies (25) are signed
        assert r.energy >= regs[0].energy
    assert regs[2].area > regs[0].area  # the whole stance's peak covers more
    from modalmorph.figures.stance import plot_footprints

    fig = plot_footprints(regs, titles=["5", "6", "peak"], ncols=3)
    assert len(fig.axes) == 4  # three footprints and the colour bar


def test_public_names_are_the_functions():
    """The verbs' module is not named after a verb: importing it never hides one."""
    import modalmorph as mm
    import modalmorph.apps.stance  # noqa: F401
    import modalmorph.pedobarography  # noqa: F401

    assert callable(mm.stance) and callable(mm.register_footprints)
    assert mm.stance.__module__ == "modalmorph.pedobarography"


def test_footprints_command(tmp_path):
    stack = synthetic_stance()
    path = tmp_path / "peaks.npy"
    np.save(path, np.array([stack[5], stack[6], stack.max(axis=0)]))
    assert main(["footprints", str(path), "--threshold", "5", "--template", "0",
                 "--out", str(tmp_path / "out"), "-q"]) == 0
    rows = (tmp_path / "out" / "footprints.csv").read_text().splitlines()
    assert len(rows) == 4 and rows[0].startswith("image,area_mm2,energy")
    assert (tmp_path / "out" / "footprints.png").exists()
    assert main(["footprints", str(path), "--template", "7", "--out",
                 str(tmp_path / "bad"), "-q"]) == 2  # no image 7: one line, exit 2


def test_a_single_loaded_sensor_is_skipped_though_the_smoothing_spreads_it(tmp_path, caplog):
    """One sensor loaded (the smoothing spreads it over its neighbours above the level):
    skipped and said, not tracked as a part."""
    stack = np.zeros((5, 20, 10))
    stack[:, 5:9, 3:7] = 50.0
    stack[1, 15, 5] = 80.0  # one sensor, in one frame
    with caplog.at_level("INFO"):
        result = stance(stack)
    assert len(result.parts) == 1
    assert "1 contact(s) smaller than 2 sensors skipped" in caplog.text


def test_a_template_of_the_other_foot_is_said(caplog):
    """A template mirrored left-right (the other foot's) deforms every part into its
    mirror image: each image is said to look like the other foot, its energy higher;
    the same foot as given never is."""
    from modalmorph import register_footprints
    from modalmorph.pedobarography import OTHER_FOOT

    r, c = np.indices((H, W), dtype=float)
    foot = [80 * np.exp(-0.5 * (((r - 8) / 3) ** 2 + ((c - 6) / 2.5) ** 2))  # heel, medial
            + 60 * np.exp(-0.5 * (((r - 28) / 4) ** 2 + ((c - 12 - k) / 4) ** 2))
            for k in range(3)]  # forefoot, lateral, a little differently each trial
    peaks = np.where(np.array(foot) > 3, foot, 0.0)
    same = register_footprints(peaks, template=0, threshold=5.0)
    assert all(reg.other_foot < 1 / OTHER_FOOT for reg in same)
    with caplog.at_level(logging.WARNING):
        other = register_footprints(peaks, template=peaks[0][:, ::-1], threshold=5.0)
    assert all(reg.other_foot > OTHER_FOOT for reg in other)
    assert "3 of 3 images look like the other foot" in caplog.text
    for a, b in zip(same, other, strict=True):  # the mirror image costs more: 0.09-0.40
        assert b.energy > a.energy + 0.05  # against 0-0.15 as given


def test_a_template_of_another_plate_size_is_refused():
    """A template image of another size than the images: one line naming both sizes (a
    numpy broadcasting error before)."""
    from modalmorph import register_footprints

    stack = synthetic_stance()
    with pytest.raises(InputFileError, match="template: an image of 30 x 20 sensors, the "
                                             "images 40 x 20"):
        register_footprints(stack[4:7], template=stack[5][:30], threshold=5.0)
