"""Track.slide / Track.slid: track says when its frames turn (or slide along the outline)
farther than its correspondence follows, and stays silent when they do not."""

import warnings

import numpy as np
import pytest

from modalmorph import Shape, track
from modalmorph.core.shape import resample
from modalmorph.slide import SLIDE_FRACTION, SLIDE_GAIN, SLIDE_SAMPLES, contour_slide

from .test_track import synthetic_sequence

ARMS = np.array([80, 40, 60, 40, 70, 35, 50, 40])  # a star of unequal arms (a cell)
STEP = 6.0  # degrees turned a frame


def star(turn_degrees, m=160, start=0):
    """The star's outline turned about its centre, ``m`` nodes from another start."""
    angle = np.linspace(0, 2 * np.pi, 9)[:-1] + np.radians(turn_degrees)
    corners = 100 + np.c_[ARMS * np.cos(angle), ARMS * np.sin(angle)]
    return np.roll(resample(resample(corners, 4000), m), start, axis=0)


def turning_star(frames=12):
    return [star(STEP * f, 160 + 5 * (f % 3), 13 * f) for f in range(frames)]


def test_the_turning_star_is_said_with_nearest():
    with pytest.warns(UserWarning, match=r"slid along the outline .*correspondence='modal'"):
        result = track(turning_star())
    assert result.slide.shape == result.slid.shape == (12,)
    assert not result.slid[0] and result.slide[0] == 0
    # the star turned 66 degrees: nearest pairs leave the nodes where they were in the
    # image, so they slid along the outline against the material (measured: 19 % of
    # the outline at the last frame, 9 of 11 frames said)
    assert result.slid[-6:].all()
    assert abs(result.slide[-1]) > 0.1
    # the same star turned without sliding its nodes (the truth): nothing to say
    truth = np.array([turned for turned in _truth(result.points[0])])
    shift, gain = contour_slide(truth)
    assert np.all(np.abs(shift) <= 1 / SLIDE_SAMPLES)


def _truth(first, frames=12):
    centre = np.array([100.0, 100.0])  # the star turns about its corners' centre
    for f in range(frames):
        t = np.radians(STEP * f)
        rot = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
        yield (first - centre) @ rot.T + centre


def test_modal_follows_the_turning_star_and_says_nothing():
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no warning at all
        result = track(turning_star(6), correspondence="modal")
    assert not result.slid.any()
    # measured: 1.2 % of the outline at frame 1 (its nodes lag 0.9 spacing on average
    # along the outline, 2.8 at worst), 0.01 % or less at frames 2-5
    assert np.all(np.abs(result.slide) <= SLIDE_FRACTION)
    assert np.all(np.abs(result.slide[2:]) <= 1 / SLIDE_SAMPLES)


def test_a_sequence_that_does_not_turn_is_not_said(rng):
    frames, truth, _ = synthetic_sequence(70, rng)  # an LV contracting, resampled
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        result = track(frames)
    assert not result.slid.any()
    # measured: the best shifts reach 3.2 % of the outline (2.2 spacings) but leave 0.43
    # or more of the misfit: the change of shape, not a slide, makes it
    shift, gain = contour_slide(result.points)
    assert np.all(gain[1:] > 10 * SLIDE_GAIN)


def test_contour_slide_measures_a_roll():
    first = star(0, 200)
    rolled = np.array([first, np.roll(first, -20, axis=0), np.roll(star(30, 200), 7, axis=0)])
    shift, gain = contour_slide(rolled)
    # node i now sits where node i + 20 was: 10 % of the outline, all of the misfit
    assert shift[1] == pytest.approx(0.1, abs=1 / SLIDE_SAMPLES)
    assert gain[1] <= SLIDE_GAIN
    assert gain[0] == 1.0  # frame 0 against itself: nothing to explain
    assert abs(shift[2]) > SLIDE_FRACTION and gain[2] <= SLIDE_GAIN


def test_round_and_open_objects_say_nothing():
    t = np.linspace(0, 2 * np.pi, 100, endpoint=False)
    circle = np.c_[np.cos(t), np.sin(t)]
    circles = np.array([np.roll(circle, 5 * f, axis=0) * (1 + 0.1 * f) for f in range(4)])
    shift, gain = contour_slide(circles)  # every shift fits a circle: no slide to see
    assert np.all(gain == 1.0) or np.all(gain > SLIDE_GAIN)
    arc = [Shape(circle[:60] * (1 + 0.05 * f), closed=False) for f in range(3)]
    result = track(arc)
    assert np.isnan(result.slide).all() and not result.slid.any()


def test_cli_summary_says_the_slide(tmp_path, capsys):
    from modalmorph.apps.cli import main

    for f, p in enumerate(turning_star(8)):
        np.savetxt(tmp_path / f"f{f:02d}.csv", p, delimiter=",")
    code = main(["track", *sorted(map(str, tmp_path.glob("*.csv"))), "--out",
                 str(tmp_path / "out"), "--no-figures", "--no-gif"])
    assert code == 0
    err = capsys.readouterr().err
    assert "the nodes slid along the outline at" in err
    assert "modalmorph: warning: the tracked nodes slid along the outline" in err
    assert "--correspondence modal" in err


def test_a_circle_growing_into_an_ellipse_has_no_slide():
    """Frame 0 a circle, then ellipses ever longer: many shifts fit a circle, none
    explains the misfit, so the slide is 0, not the best of meaningless shifts (up to
    0.47 of the outline was reported)."""
    t = 2 * np.pi * np.arange(120) / 120
    frames = [np.c_[(1 + 0.05 * f) * np.cos(t), np.sin(t)] for f in range(8)]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # nothing said
        result = track(frames)
    assert np.all(result.slide == 0) and not result.slid.any()
