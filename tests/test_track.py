"""track(): nodes of frame 0 followed through a sequence; readers and the command line."""

import numpy as np
import pytest

from modalmorph import Shape, track
from modalmorph.datasets import load_heart
from modalmorph.shape import resample

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
    # the bar: within one node spacing (median) at every frame
    # (measured max over frames: 0.46 at 70 nodes, 0.94 at 250)
    assert np.all(err <= spacing), err / spacing
    assert result.points.shape == (FRAMES, m, 2)
    assert np.all(result.distance <= 0.01 * radius)  # stays on every frame's contour
    assert not result.crossed.any()
    # the cycle closes: nodes come back within one spacing of where they started
    assert result.closure_error <= spacing
    # contraction: every segment shortens at mid-cycle, the perimeter most there
    assert np.all(result.segment_strain[FRAMES // 2] < 0)
    assert np.argmin(result.strain) in range(FRAMES // 2 - 2, FRAMES // 2 + 3)
    assert np.all(np.diff(result.cumulative_energy) >= 0)  # energies >= 0 (22)
    assert np.all(result.energy >= 0)


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
    with pytest.raises(ValueError, match="unknown option"):
        track([ed, ed], morph_options={"kk": 1})
    with pytest.raises(ValueError, match="reference"):
        track([ed, ed], reference="last")
    with pytest.raises(ValueError, match="start_node"):
        track([ed, ed], start_node=60)
    with pytest.raises(ValueError, match="correspondence='modal'"):
        track([ed, ed], match_options={"method": "local"})
