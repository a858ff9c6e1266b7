"""track(): nodes of frame 0 followed through a sequence; readers and the command line."""

import dataclasses
from functools import partial

import numpy as np
import pytest
from numpy.testing import assert_allclose

from modalmorph import Shape, morph, track
from modalmorph.core.shape import resample
from modalmorph.datasets import load_heart
from modalmorph.matching.normals import along_normals

FRAMES = 20


def periodic_field(points, t, centre, radius):
    """A smooth periodic deformation: contraction by up to 25 % with a non-uniform part,
    zero at t = 0 and t = FRAMES, largest at t = FRAMES / 2 (a cardiac-like cycle)."""
    y = (points - centre) / radius
    a = 0.5 * (1 - np.cos(2 * np.pi * t / FRAMES))
    th = np.arctan2(y[:, 1], y[:, 0])
    y = y * (1 - 0.25 * a) + 0.08 * a * np.c_[np.cos(2 * th) * y[:, 0], np.sin(th) * y[:, 1]]
    return y * radius + centre


def synthetic_sequence(m, rng):
    """The heart's end-diastole contour deformed by ``periodic_field`` over 20 frames,
    each frame resampled to a different node count from a different start point.
    Returns the frames and the true positions of frame 0's nodes in every frame."""
    ed = load_heart("diastole")
    centre, radius = ed.mean(axis=0), np.sqrt(((ed - ed.mean(axis=0)) ** 2).sum(1).mean())
    dense = resample(ed, 2000)
    x0 = resample(ed, m)
    frames, truth = [x0], [x0]
    for f in range(1, FRAMES):
        n = int(rng.integers(int(0.7 * m), int(1.4 * m)))
        curve = np.roll(periodic_field(dense, f, centre, radius), rng.integers(2000), axis=0)
        frames.append(resample(curve, n))
        truth.append(periodic_field(x0, f, centre, radius))
    return frames, np.array(truth), radius


@pytest.mark.parametrize("m", [70, 200])
def test_synthetic_sequence_follows_the_truth(m, rng):
    frames, truth, radius = synthetic_sequence(m, rng)
    result = track(frames, cycle=True)
    spacing = np.linalg.norm(np.diff(frames[0], axis=0), axis=1).mean()
    err = np.median(np.linalg.norm(result.points - truth, axis=2), axis=1)
    # the bar: within one node spacing (median) at every frame (measured max
    # over frames, reference "first" / "previous": 0.36 / 0.39 at 70 nodes, 0.71 / 0.79
    # at 200; closure error 0.04 / 0.43 and 0.12 / 0.38 spacings)
    assert np.all(err <= spacing), err / spacing
    assert result.points.shape == (FRAMES, m, 2)
    assert np.all(result.distance <= 0.01 * radius)  # stays on every frame's contour
    assert not result.crossed.any()
    # the cycle closes: nodes come back within one spacing of where they started
    assert result.closure_error <= spacing
    # contraction: every segment shortens at mid-cycle, the perimeter most there
    assert np.all(result.segment_strain[FRAMES // 2] < 0)
    assert np.argmin(result.strain) in range(FRAMES // 2 - 2, FRAMES // 2 + 3)
    assert np.all(result.energy >= 0)  # (22)
    assert result.energy[0] == 0 and result.cumulative_energy[0] == 0


def test_energies_mean_the_same_for_both_references(hearts):
    """energy[f]: frame f's morph from source_frame[f]; cumulative_energy[f]: summed over
    the morphs leading from frame 0 to frame f."""
    ed, es = (resample(h, 70) for h in hearts)
    frames = [ed, 0.5 * (ed + resample(np.roll(es, 3, axis=0), 70)), es]
    first = track(frames, correspondence="modal")  # the default reference: "first"
    assert first.params["reference"] == "first"
    assert first.source_frame.tolist() == [0, 0, 0]
    for f in (1, 2):  # a plain morph from frame 0 (modal matching, as track's "modal")
        plain = morph(frames[0], frames[f])
        assert_allclose(first.energy[f], plain.energy[-1], rtol=1e-9)  # same arithmetic
        assert_allclose(first.node_energy[f], plain.node_energy[-1], rtol=1e-9, atol=1e-15)
    assert_allclose(first.cumulative_energy, first.energy, rtol=0, atol=0)
    steps = track(frames, reference="previous", correspondence="modal")
    assert steps.source_frame.tolist() == [0, 0, 1]
    plain = morph(Shape(steps.points[1]), frames[2])
    assert_allclose(steps.energy[2], plain.energy[-1], rtol=1e-9)
    assert_allclose(steps.cumulative_energy, np.cumsum(steps.energy), rtol=1e-12)


def test_first_falls_back_to_the_previous_frame(hearts, monkeypatch):
    """A frame whose morph from frame 0 raises, does not converge or ends off the contour
    is morphed from the tracked previous frame, as "previous" does; when that one fails
    too, the morph from frame 0 is kept, with a warning."""
    from modalmorph import tracking

    ed = resample(hearts[0], 60)
    centre, radius = ed.mean(axis=0), np.sqrt(((ed - ed.mean(axis=0)) ** 2).sum(1).mean())
    frames = [periodic_field(ed, f, centre, radius) for f in range(5)]
    plain = tracking.morph

    def failing(source, target, fail=(2, 3), **kw):
        """The morph, but from frame 0 onto frame 2 it raises and onto frame 3 it stalls
        (onto frame ``fail[1]`` from anywhere when ``fail[0]`` is None)."""
        f = next(i for i, p in enumerate(frames) if np.array_equal(p, target.points))
        from_first = np.array_equal(source.points, ed)
        if f == fail[0] and from_first:
            raise ValueError("no morph")
        result = plain(source, target, **kw)
        if f == fail[1] and (from_first or fail[0] is None):
            return dataclasses.replace(result, stop_reason="max_steps")
        return result

    monkeypatch.setattr(tracking, "morph", failing)
    result = track(frames)
    steps = track(frames, reference="previous")
    assert result.source_frame.tolist() == [0, 0, 1, 2, 0]
    assert_allclose(result.points[:4], steps.points[:4], rtol=0, atol=0)  # same morphs
    assert_allclose(result.cumulative_energy[:4], np.cumsum(result.energy[:4]), rtol=1e-12)
    assert_allclose(result.cumulative_energy[4], result.energy[4], rtol=0)
    monkeypatch.setattr(tracking, "morph", partial(failing, fail=(None, 3)))
    with pytest.warns(UserWarning, match=r"frame 3 \(frame 3\): neither its morph"):
        kept = track(frames)
    assert kept.source_frame.tolist() == [0, 0, 0, 0, 0]

    def off(source, target, **kw):  # from frame 0 onto frame 4: 3 spacings off the contour
        result = plain(source, target, **kw)
        if np.array_equal(source.points, ed) and np.array_equal(target.points, frames[4]):
            shift = 3 * np.linalg.norm(np.diff(ed, axis=0), axis=1).mean()
            return dataclasses.replace(result, shapes=result.shapes + [shift, 0])
        return result

    monkeypatch.setattr(tracking, "morph", off)
    moved = track(frames)
    assert moved.source_frame.tolist() == [0, 0, 0, 0, 3]
    assert moved.distance[4] <= 0.5 * np.linalg.norm(np.diff(ed, axis=0), axis=1).mean()


def test_track_invariants(hearts):
    ed = resample(hearts[0], 60)
    # a sequence of one object repeated: nothing moves, no energy, no strain
    still = track([ed, ed, ed])
    np.testing.assert_allclose(still.points, np.broadcast_to(ed, (3, 60, 2)), atol=1e-9)
    np.testing.assert_allclose(still.strain, 0, atol=1e-9)
    np.testing.assert_allclose(still.energy, 0, atol=1e-9)
    # segments: 6 of equal arc length covering every edge once; strain of a uniform
    # scaling by 0.8 is -0.2 everywhere (scaling about the centroid in the common frame)
    scaled = (ed - ed.mean(0)) * 0.8 + ed.mean(0)
    both = track([ed, scaled], start_node=7)
    assert np.bincount(both.segment_of_edge).tolist() == [10] * 6
    assert both.segment_of_edge[7] == 0 and both.segment_of_edge[6] == 5
    np.testing.assert_allclose(both.strain[1], -0.2, atol=5e-3)  # morph tolerance 0.5 %
    np.testing.assert_allclose(both.segment_strain[1], -0.2, atol=2e-2)


def test_reference_first_and_modal(hearts):
    ed, es = (Shape(resample(h, 80)) for h in hearts)
    result = track([ed, es, ed], reference="first", correspondence="modal")
    assert len(result.morphs) == 2
    assert all(r.source is result.frames[0] or np.array_equal(r.source.points, ed.points)
               for r in result.morphs)
    assert result.strain[1] < 0  # the left ventricle shortens from ED to ES


def test_errors_name_the_frame(hearts):
    ed = resample(hearts[0], 60)
    with pytest.raises(ValueError, match=r"frame 2 \(c\.csv\).*3D"):
        track([ed, ed, np.c_[ed, ed[:, 0]]], names=["a.csv", "b.csv", "c.csv"])
    with pytest.raises(ValueError, match=r"frame 1 \(frame 1\)"):
        track([ed, ed[:2]])
    with pytest.raises(ValueError, match="at least 2"):
        track([ed])
    with pytest.raises(ValueError, match="morph_options: unknown MorphOptions option 'kk'"):
        track([ed, ed], morph_options={"kk": 1})
    with pytest.raises(ValueError, match="reference"):
        track([ed, ed], reference="last")
    with pytest.raises(ValueError, match="unknown TrackOptions option 'refrence'"):
        track([ed, ed], refrence="first")
    with pytest.raises(ValueError, match="start_node"):
        track([ed, ed], start_node=60)
    with pytest.raises(ValueError, match="correspondence='modal'"):
        track([ed, ed], match_options={"method": "local"})


# ------------------------------------------------------------------------- command line


def horse_masks(frames=4):
    """Masks of scikit-image's horse, squeezed a little more in every frame."""
    skimage = pytest.importorskip("skimage")
    from skimage import transform

    horse = ~skimage.data.horse()
    masks = []
    for f in range(frames):
        m = transform.rescale(horse.astype(float), (1, 1 - 0.03 * f), order=0) > 0.5
        masks.append(np.pad(m, ((0, 0), (0, horse.shape[1] - m.shape[1]))))
    return np.array(masks)


def write_inputs(kind, tmp_path, masks):
    from PIL import Image

    images = [Image.fromarray(m.astype(np.uint8) * 255) for m in masks]
    if kind == "png":
        for f, image in enumerate(images):  # natural order: frame10 after frame2
            image.save(tmp_path / f"frame{f * 5}.png")
        return [tmp_path]
    if kind in ("tiff", "gif"):  # a multi-page TIFF, an animated GIF
        path = tmp_path / f"stack.{kind[:3]}"
        images[0].save(path, save_all=True, append_images=images[1:])
        return [path]
    from modalmorph.io import read_frames

    shapes = read_frames(list(tmp_path.glob("*.png")) or write_inputs("png", tmp_path, masks),
                         nodes=60).shapes
    np.savez(tmp_path / "seq.npz", points=np.array([s.points for s in shapes]))
    return [tmp_path / "seq.npz"]


@pytest.mark.parametrize("kind", ["png", "tiff", "gif", "npz"])
def test_cli_track(kind, tmp_path):
    from modalmorph.apps.cli import main

    masks = horse_masks()
    inputs = write_inputs(kind, tmp_path, masks)
    out = tmp_path / "out"
    code = main(["track", *map(str, inputs), "--out", str(out), "--nodes", "60", "-q",
                 *(["--no-gif"] if kind != "png" else [])])
    assert code == 0
    files = {p.name for p in out.iterdir()}
    assert {"track.npz", "track.json", "strain_segments.csv", "trajectories.png",
            "curves.png", "frames_energy.png"} <= files
    assert ("track.gif" in files) == (kind == "png")
    with np.load(out / "track.npz") as data:
        assert data["points"].shape == (4, 60, 2)
        assert np.all(data["strain"][1:] < 0)  # squeezed horizontally: the outline shortens
        assert data["slide"].shape == (4,) and not data["slid"].any()  # squeezed, not turned
    import json

    summary = json.loads((out / "track.json").read_text())
    assert len(summary["frames"]) == 4 and summary["nodes"] == 60
    assert all(f["slid"] is False for f in summary["frames"])
    table = np.loadtxt(out / "strain_segments.csv", delimiter=",", skiprows=1)
    assert table.shape == (4, 8)


@pytest.mark.parametrize("bad, message", [
    ("empty", r"frame1\.png: the file is empty"),
    ("no_object", r"stack\.npy\[2\]: no object"),
    ("mixed", r"frame 2 \(.*c\.csv\) is 3D"),
])
def test_cli_track_bad_input(bad, message, tmp_path, capsys, hearts):
    from PIL import Image

    from modalmorph.apps.cli import main

    masks = horse_masks(3)
    if bad == "empty":
        for f, m in enumerate(masks):
            Image.fromarray(m.astype(np.uint8) * 255).save(tmp_path / f"frame{f}.png")
        (tmp_path / "frame1.png").write_bytes(b"")
        inputs = [tmp_path]
    elif bad == "no_object":
        masks[2] = False
        np.save(tmp_path / "stack.npy", masks)
        inputs = [tmp_path / "stack.npy"]
    else:
        ed = resample(hearts[0], 40)
        for name, pts in (("a", ed), ("b", ed), ("c", np.c_[ed, ed[:, 0]])):
            np.savetxt(tmp_path / f"{name}.csv", pts, delimiter=",")
        inputs = [tmp_path / f"{n}.csv" for n in "abc"]
    out = tmp_path / "out"
    assert main(["track", *map(str, inputs), "--out", str(out), "-q"]) == 2
    assert not out.exists()  # nothing written
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("modalmorph: error:")
    assert __import__("re").search(message, err), err


def test_real_cycle_ed_es_ed(hearts):
    """The bundled slice's cycle ED -> ES -> ED (observed contours; the second ED resampled
    to 1.3x the nodes from another start): the track stays on every contour, never crosses
    itself, the ventricle shortens at ES and the nodes come back near their start."""
    ed, es = hearts
    ed2 = np.roll(resample(ed, int(1.3 * len(ed))), 17, axis=0)
    result = track([ed, es, ed2])
    radius = Shape(ed).size
    assert np.all(result.distance <= 0.01 * radius)  # measured max 0.45 % on 15 slices
    assert not result.crossed.any()
    assert result.strain[1] < 0 and np.all(result.segment_strain[1] < 0)
    spacing = np.linalg.norm(np.diff(ed, axis=0), axis=1).mean()
    back = np.linalg.norm(result.points[2] - ed, axis=1).mean()
    assert back <= spacing  # measured 0.41-0.93 spacings on the 15 shared slices


def test_options_objects_same_as_dicts(hearts):
    from modalmorph import MatchOptions, MorphOptions, TrackOptions

    frames = [resample(hearts[0], 50), resample(hearts[1], 60), resample(hearts[0], 55)]
    by_dict = track(frames, correspondence="modal", match_options={"method": "global"},
                    morph_options={"k": 60, "max_steps": 20})
    by_object = track(frames, options=TrackOptions(correspondence="modal"),
                      match_options=MatchOptions(method="global"),
                      morph_options=MorphOptions(k=60, max_steps=20))
    np.testing.assert_array_equal(by_object.points, by_dict.points)  # bitwise
    assert by_object.params == by_dict.params
    assert by_object.params["match_options"]["method"] == "global"
    assert all(m.options == MorphOptions(k=60, max_steps=20) for m in by_object.morphs)


def test_normal_correspondence_moves_nodes_along_frame_0_normals():
    # an ellipse whose wall moves inward along its own normals, unevenly round it: with
    # correspondence="normal" node i stays on the normal line of node i in frame 0 (a
    # contour shows no motion along itself); nearest pairs slide along the wall
    th = np.linspace(0, 2 * np.pi, 48, endpoint=False)
    x0 = np.c_[30 * np.cos(th), 20 * np.sin(th)]
    t = np.roll(x0, -1, axis=0) - np.roll(x0, 1, axis=0)
    n = np.c_[t[:, 1], -t[:, 0]] / np.linalg.norm(t, axis=1)[:, None]  # outward
    dense = np.linspace(0, 2 * np.pi, 1200, endpoint=False)
    xd = np.c_[30 * np.cos(dense), 20 * np.sin(dense)]
    td = np.roll(xd, -1, axis=0) - np.roll(xd, 1, axis=0)
    nd = np.c_[td[:, 1], -td[:, 0]] / np.linalg.norm(td, axis=1)[:, None]
    depth = [0.0, 2.0, 4.0, 6.0]  # inward offset, times (1 + 0.8 cos theta)
    frames = [x0] + [xd - d * (1 + 0.8 * np.cos(dense))[:, None] * nd for d in depth[1:]]
    truth = np.array([x0 - d * (1 + 0.8 * np.cos(th))[:, None] * n for d in depth])
    error = {c: np.linalg.norm(track(frames, reference="first", correspondence=c,
                                     morph_options={"tol": 0.001}).points - truth,
                               axis=2).max() for c in ("normal", "nearest")}
    assert error["normal"] < 0.1 < error["nearest"]  # units; the ellipse is 60 x 40


def test_normal_correspondence_keeps_the_order_where_normals_cross(hearts):
    # ED -> ES straight, a large motion with concave stretches (normals of the nodes
    # without smoothing, and no repair of their order: the tracked ES contour crossed
    # itself and its perimeter was 0.9 points off)
    ed, es = resample(hearts[0], 80), resample(hearts[1], 320)
    result = track([ed, es], reference="first", correspondence="normal")
    perimeter = [np.linalg.norm(np.roll(c, -1, axis=0) - c, axis=1).sum() for c in hearts]
    assert not result.crossed.any()  # measured: 0.0007 off
    assert abs(result.strain[1] - (perimeter[1] / perimeter[0] - 1)) < 0.005


def test_normal_correspondence_needs_contours():
    cloud = np.random.default_rng(0).normal(size=(30, 3))
    with pytest.raises(ValueError, match="normal"):
        track([cloud, cloud + 0.1], correspondence="normal")


def test_along_normals_keeps_the_nodes_in_order():
    # a peanut shrinking to a small circle: the normal lines of its concave waists cross
    # before they reach the circle (without the repair a node went back 0.54 rad)
    th = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    r = 30 * (1 - 0.4 * np.cos(2 * th))
    small = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    hit = along_normals(Shape(np.c_[r * np.cos(th), r * np.sin(th)]),
                        Shape(6 * np.c_[np.cos(small), np.sin(small)]))
    assert_allclose(np.linalg.norm(hit, axis=1), 6.0, rtol=1e-3)  # on the circle
    angle = np.unwrap(np.arctan2(hit[:, 1], hit[:, 0]))
    assert (np.diff(np.r_[angle, angle[0] + 2 * np.pi]) > 0).all()  # in order, once round


def test_tracing_knots_are_no_fold_of_a_track():
    """The shared hands 1-6 as given carry 9-17 tiny knots (digitiser loops, accepted
    as simple): tracked one after another, no frame is said to cross itself and none
    warns (every frame was 'crossed' and warned before, and morphed twice)."""
    from modalmorph.datasets import load_hand

    tr = track([load_hand(i) for i in range(1, 7)])
    assert not tr.crossed.any() and (tr.source_frame == 0).all()
