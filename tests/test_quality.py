"""Quality measures: exact against brute force, invariants, known counts."""

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from modalmorph.core import quality
from modalmorph.core.align import Similarity
from modalmorph.core.quality import (
    area,
    check_simple,
    correspondence_rotation,
    crossing_segments,
    curve_distances,
    knot_count,
    roughness,
    self_crossings,
    step_crossings,
)
from modalmorph.core.shape import Shape, resample

from .conftest import random_rotation, self_intersections


def brute_to_polyline(p, poly, closed):
    """Distance from each row of p to every segment of poly, minimum: the reference."""
    a = poly if closed else poly[:-1]
    b = np.roll(poly, -1, axis=0)[:len(a)]
    ab = b - a
    t = np.einsum("mkd,kd->mk", p[:, None] - a[None], ab) / np.sum(ab * ab, axis=1)
    foot = a[None] + np.clip(t, 0, 1)[..., None] * ab[None]
    return np.linalg.norm(p[:, None] - foot, axis=-1).min(axis=1)


def star_shaped(n, rng, spread=0.6):
    """A random simple polygon: random radii at increasing angles."""
    theta = np.sort(rng.uniform(0, 2 * np.pi, n))
    r = 1 + spread * rng.uniform(-1, 1, n)
    return np.c_[r * np.cos(theta), r * np.sin(theta)]


def star_polygon(n, k):
    """The regular star polygon {n/k}: n (k - 1) crossings."""
    theta = 2 * np.pi * k * np.arange(n) / n
    return np.c_[np.cos(theta), np.sin(theta)]


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("closed", [True, False])
def test_curve_distances_match_brute_force(rng, dim, closed):
    for trial in range(5):
        # random walks with uneven steps: long segments beside short ones, sharp turns
        steps = rng.standard_normal((60, dim)) * rng.exponential(1.0, (60, 1)) ** 2
        b = np.cumsum(steps, axis=0)
        a = b[rng.integers(0, 60, 40)] + rng.standard_normal((40, dim)) * (trial + 0.5)
        d_ab, d_ba = curve_distances(a, b, closed_a=False, closed_b=closed)
        assert_allclose(d_ab, brute_to_polyline(a, b, closed), atol=1e-12)  # exact
        assert_allclose(d_ba, brute_to_polyline(b, a, False), atol=1e-12)


def test_curve_distances_on_resampled_circle():
    theta = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    b = np.c_[np.cos(theta), np.sin(theta)]
    a = 1.1 * b[::7]
    d_ab, d_ba = curve_distances(a, b)
    # distance to the inscribed 400-gon: 1.1 - cos(pi/400) at most, 0.1 at the nodes
    assert np.all((d_ab >= 0.1 - 1e-12) & (d_ab <= 0.1 + (1 - np.cos(np.pi / 400)) + 1e-12))
    # from b to the 58-gon a: at least the gap at a's chord midpoints, at most 0.1
    assert np.all((d_ba >= 1.1 * np.cos(7 * np.pi / 400) - 1 - 1e-12) & (d_ba <= 0.1 + 1e-12))


def test_curve_distances_unordered_is_nearest_node(rng):
    a, b = rng.standard_normal((30, 3)), rng.standard_normal((50, 3))
    d_ab, d_ba = curve_distances(a, b, ordered=False)
    full = np.linalg.norm(a[:, None] - b[None], axis=-1)
    assert_allclose(d_ab, full.min(axis=1), atol=1e-12)
    assert_allclose(d_ba, full.min(axis=0), atol=1e-12)


def test_curve_distances_of_a_curve_to_itself_is_zero(hand200):
    d_ab, d_ba = curve_distances(hand200, np.roll(hand200, 17, axis=0))
    assert_allclose(d_ab, 0, atol=1e-9)  # the nodes lie on the polyline
    assert_allclose(d_ba, 0, atol=1e-9)


def test_curve_distances_validation():
    with pytest.raises(ValueError, match="same dimension"):
        curve_distances(np.zeros((3, 2)), np.zeros((3, 3)))
    with pytest.raises(ValueError, match=r"b must have shape"):
        curve_distances(np.zeros((3, 2)), np.zeros(4))


def test_self_crossings_known_counts():
    assert self_crossings(np.array([[0, 0], [1, 0], [1, 1], [0, 1]])) == 0  # square
    assert self_crossings(np.array([[0, 0], [1, 1], [1, 0], [0, 1]])) == 1  # figure eight
    assert self_crossings(np.array([[0, 0], [1, 0], [1, 1], [0, 1]]), closed=False) == 0
    assert self_crossings(np.array([[0, 0], [1, 1], [1, 0], [0, 1]]), closed=False) == 1
    for n, k in [(5, 2), (7, 2), (7, 3), (11, 4)]:
        assert self_crossings(star_polygon(n, k)) == n * (k - 1)


def test_self_crossings_simple_polygons_and_brute_force(rng, hand200):
    assert self_crossings(hand200) == 0
    for _ in range(5):
        assert self_crossings(star_shaped(300, rng)) == 0
        walk = np.cumsum(rng.standard_normal((80, 2)), axis=0)  # crosses itself often
        for closed in (True, False):
            assert self_crossings(walk, closed) == self_intersections(walk, closed=closed)


def test_self_crossings_many_candidates(rng):
    """More candidate pairs than one chunk (long horizontal zigzag): same as brute force."""
    x = np.tile([0.0, 1.0], 800) + rng.uniform(-0.01, 0.01, 1600)
    y = np.arange(1600) * 1e-3 + rng.uniform(-1e-2, 1e-2, 1600)
    p = np.c_[x, y]
    assert self_crossings(p, closed=False) == self_intersections(p, closed=False)


def test_self_crossings_touching_does_not_count():
    # a bow tie whose two loops touch at one node of a non-adjacent segment
    p = np.array([[0, 0], [2, 0], [1, 0], [1, 1]])  # node 2 lies on segment 0
    assert self_crossings(p, closed=False) == 0


@pytest.mark.parametrize("segments", [4000, 50])
def test_step_crossings_as_one_sweep_a_step(rng, monkeypatch, segments):
    """The steps swept together count what crossing_segments finds step by step: random
    walks that cross often, coordinates rounded to ties and collinear overlaps, one or
    two contours, open or closed; also swept a few steps at a time."""
    monkeypatch.setattr(quality, "_STEP_SEGMENTS", segments)
    folded = 0
    for trial in range(60):
        m, steps = int(rng.integers(9, 60)), int(rng.integers(1, 9))
        t = np.linspace(0, 2 * np.pi, m, endpoint=False)
        base = np.c_[np.cos(t), np.sin(t)]
        shapes = base + rng.normal(0, [0.05, 0.3, 1.0][trial % 3], (steps, m, 2))
        if trial % 2:
            shapes = np.round(shapes, 1)  # ties and touching segments
        k = m // 3
        shape = Shape(base, closed=trial % 4 != 1, contours=(k, m - k)) if trial % 5 == 0 \
            else Shape(base, closed=trial % 4 != 1)
        each = [len(quality.crossing_segments(p, edges=shape.edges)) for p in shapes]
        assert step_crossings(shapes, shape).tolist() == each
        folded += sum(each) > 0
    assert folded >= 30  # most of the noisier steps cross (the test tests something)


def test_roughness_invariant_to_pose_and_scale(hand200, rng):
    r = roughness(hand200)
    moved = Similarity(random_rotation(2, rng), 37.0, np.array([1e3, -5.0])).apply(hand200)
    assert_allclose(roughness(moved), r, rtol=1e-9)  # a ratio of lengths
    assert_allclose(roughness(np.roll(hand200, 50, axis=0)), r, rtol=2e-2)  # start node
    p3 = np.c_[hand200, np.zeros(200)] @ random_rotation(3, rng).T
    assert_allclose(roughness(p3), r, rtol=1e-9)


def test_roughness_depends_little_on_node_count(hearts):
    ed = hearts[0]
    r = roughness(ed)
    # the same outline at more nodes; measured: -10 % at 400, -2 % at 1000 (resampling
    # twice cuts the corners of the staircase a little). Fewer nodes than the 247 pixel
    # steps change the outline itself (the staircase goes): 0.0029 at 150.
    for n in (400, 1000, 3000):
        assert_allclose(roughness(resample(ed, n)), r, rtol=0.15)


def test_roughness_of_circle_and_noise(rng):
    theta = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    circle = np.c_[np.cos(theta), np.sin(theta)]
    base = roughness(circle)
    assert_allclose(base, 1 - np.exp(-(2 * np.pi * 4 / 512) ** 2 / 2), rtol=0.05)
    noisy = circle + 0.01 * rng.standard_normal(circle.shape)  # 1 % of the radius
    assert roughness(noisy) > 2 * base
    line = np.c_[np.linspace(0, 1, 50), np.zeros(50)]
    assert roughness(line, closed=False) < 1e-12  # an open straight line is smooth


def test_area_sign_and_invariance(hand200, rng):
    square = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])
    assert area(square) == 4.0  # counter-clockwise: positive, exact in binary
    assert area(square[::-1]) == -4.0
    moved = 3.0 * hand200 @ random_rotation(2, rng).T + [10.0, -5.0]
    assert_allclose(area(moved), 9.0 * area(hand200), rtol=1e-10)  # rounding only


def test_correspondence_rotation(hand200, rng):
    pairs = np.c_[np.arange(200), np.arange(200)]
    for angle in (0.0, 30.0, -170.0, 180.0):
        t = np.radians(angle)
        R = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
        got = correspondence_rotation(hand200, 2.5 * hand200 @ R.T + 3.0, pairs)
        assert_allclose(got, angle, atol=1e-9)  # Horn is exact on similar sets
    R3 = random_rotation(3, rng)
    p3 = rng.standard_normal((40, 3))
    want = np.degrees(np.arccos((np.trace(R3) - 1) / 2))
    got = correspondence_rotation(p3, p3 @ R3.T, np.c_[np.arange(40), np.arange(40)])
    assert_allclose(got, want, atol=1e-7)
    with pytest.raises(ValueError, match="pairs must be an integer array"):
        correspondence_rotation(hand200, hand200, np.zeros((3, 2)))


def test_check_simple_refuses_stars_and_figure_eights_and_says_where():
    from modalmorph.core.quality import check_simple, crossing_segments
    from modalmorph.errors import ShapeError

    t = np.linspace(0.0, 2.0 * np.pi, 5, endpoint=False)
    star = np.c_[np.cos(2 * t), np.sin(2 * t)]  # {5/2}: five crossings
    assert crossing_segments(star).tolist() == [[0, 2], [0, 3], [1, 3], [1, 4], [2, 4]]
    with pytest.raises(ShapeError, match=r"star crosses itself: the segment from node 0 to "
                                         r"1 crosses the one from node 2 to 3 at \(0.309, "):
        check_simple(star, "star")
    s = np.linspace(0.0, 2.0 * np.pi, 100, endpoint=False) + 0.01
    with pytest.raises(ShapeError, match="eight crosses itself"):
        check_simple(np.c_[np.sin(s), np.sin(2 * s)], "eight")


def test_check_simple_accepts_the_tiny_loops_of_real_outlines():
    from modalmorph.core.quality import check_simple, crossing_segments
    from modalmorph.datasets import load_hand

    hand = load_hand(3)  # statismo's annotation has loops of a few nodes
    assert len(crossing_segments(hand)) > 0
    check_simple(hand, "hand 3")


def test_step_crossings_counts_folds_not_tracing_knots():
    """A knot of tracing noise's size (a loop of 1e-5 of the squared RMS radius, which
    check_simple accepts) is no fold where the inputs carry as many knots as given
    (``knots``), and is one (two nodes swapped) on clean inputs; a figure eight's lobe
    is one, within a contour or between two."""
    t = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    circle = np.c_[np.cos(t), np.sin(t)]
    knot = circle.copy()
    knot[[50, 51]] = knot[[51, 50]]  # two neighbours swapped: a tiny loop
    u = t + np.pi / 200  # no node at the crossing
    eight = np.c_[np.sin(u), np.sin(u) * np.cos(u)]
    shape = Shape(circle)
    assert len(crossing_segments(knot)) == 1
    check_simple(knot, "knot")
    assert knot_count(Shape(knot)) == 1 and knot_count(shape) == 0
    assert_array_equal(step_crossings([circle, knot, eight], shape), [0, 1, 1])
    assert_array_equal(step_crossings([circle, knot, eight], shape, (Shape(knot),)), [0, 0, 1])
    two = Shape(np.r_[circle, 0.5 * circle], contours=(200, 200))
    assert_array_equal(step_crossings([two.points, np.r_[circle, 0.5 * circle + [0.8, 0]]],
                                      two), [0, 2])


def test_long_thin_or_twisted_loops_are_folds():
    """Loops of small area but long (a tip folded back along 6 of 10 units at 0.1 %
    offset; lobes of opposite turn whose signed areas cancel) are folds, not noise."""
    from modalmorph.core.quality import LOOP_LENGTH

    x = np.linspace(0.0, 10.0, 101)
    line = np.c_[x, 0.001 * np.sin(x)]
    back = np.c_[x[::-1][1:61], -0.001 + 0.0 * x[::-1][1:61]]  # folded back
    tip = np.r_[line, back]
    tip[-1, 1] = 0.002  # the last segment crosses the line
    shape = Shape(tip, closed=False)
    if len(crossing_segments(tip, closed=False)):
        assert step_crossings([tip], shape)[0] >= 1
    assert LOOP_LENGTH < 1.0
