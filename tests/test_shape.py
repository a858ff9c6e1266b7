"""Shape validation: every bad input names its problem."""

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from numpy.testing import assert_allclose

from modalmorph import Shape
from modalmorph.core.shape import ImageFrame, resample, traces_curve
from modalmorph.errors import ShapeError

SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])


@pytest.mark.parametrize(
    "points, match",
    [
        (np.array([[0.0, np.nan], [1, 0], [0, 1]]), r"non-finite .* node\(s\) \[0\]"),
        (np.array([[0.0, 0.0], [1, np.inf], [0, 1]]), r"non-finite .* node\(s\) \[1\]"),
        (np.zeros((5,)), r"shape \(m, 2\) or \(m, 3\), got \(5,\)"),
        (np.zeros((5, 4)), r"shape \(m, 2\) or \(m, 3\), got \(5, 4\)"),
        (np.zeros((5, 1)), r"shape \(m, 2\) or \(m, 3\), got \(5, 1\)"),
        (SQUARE[:2], "at least 3 nodes, got 2"),
        (np.vstack([SQUARE, SQUARE[1]]), "repeated nodes: node 1 and node 4"),
        (np.ones((4, 2)) * 7.0, "all 4 nodes lie \\(nearly\\) at one point"),
        (np.ones((4, 3)) + 1e-14 * np.arange(12).reshape(4, 3), "nearly\\) at one point"),
        ([["a", "b"], ["c", "d"], ["e", "f"]], "must be numeric"),
    ],
)
def test_bad_points(points, match):
    with pytest.raises(ValueError, match=match):
        Shape(points)


def test_a_file_name_is_not_coordinates():
    """as_shape (morph, match) names a file given where coordinates go, and the reader."""
    from modalmorph.core.shape import as_shape

    for path in ("a.csv", Path("a.csv")):
        with pytest.raises(ValueError, match=r"source is a file name \('a.csv'\), not "
                                             r"coordinates: read it with modalmorph.read_shape"):
            as_shape(path, "source")


def test_bad_faces():
    pts = np.random.default_rng(0).normal(size=(6, 3))
    with pytest.raises(ValueError, match="faces index nodes outside"):
        Shape(pts, faces=[[0, 1, 9]])
    with pytest.raises(ValueError, match=r"faces must be an integer array of shape \(f, 3\)"):
        Shape(pts, faces=[[0.0, 1.0, 2.0]])


def test_normalisation():
    s = Shape(SQUARE * 10 + 3)
    assert_allclose(s.normalized.mean(axis=0), 0, atol=1e-15)
    assert_allclose(np.sqrt(np.mean(np.sum(s.normalized**2, axis=1))), 1.0)
    assert_allclose(s.to_user(s.normalized), s.points)
    assert s.ordered and s.closed
    assert not Shape(np.eye(3)).ordered  # 3D defaults to a point cloud


def test_points_read_only():
    s = Shape(SQUARE)
    with pytest.raises(ValueError):
        s.points[0, 0] = 5.0


@settings(max_examples=50, deadline=None)
@given(arrays(np.float64, st.tuples(st.integers(3, 12), st.sampled_from([2, 3])),
              elements=st.floats(-1e3, 1e3, allow_nan=False)))
def test_valid_or_clear_error(points):
    """Any finite array is either accepted or rejected with a ValueError, never crashes."""
    try:
        s = Shape(points)
    except ValueError as exc:
        assert "repeated nodes" in str(exc) or "one point" in str(exc)
    else:
        assert np.isfinite(s.normalized).all()


def test_resample_arc_length():
    out = resample(SQUARE, 8)
    steps = np.linalg.norm(np.diff(np.vstack([out, out[:1]]), axis=0), axis=1)
    assert_allclose(steps, 0.5)  # perimeter 4 in 8 equal steps
    with pytest.raises(ValueError, match="n must be >= 3"):
        resample(SQUARE, 2)


def test_image_frame_is_carried_and_checked():
    from modalmorph.datasets import PIXELS, heart_shape

    frame = ImageFrame(image="a.png", size=(60, 80))
    shape = Shape(SQUARE, frame=frame)
    assert shape.frame.y_down and shape.frame.unit == "px"
    moved = shape.with_points(SQUARE * 2.0)
    assert moved.frame is frame and moved.closed == shape.closed
    assert Shape(SQUARE).frame is None  # plain coordinates
    with pytest.raises(ValueError, match="frame must be an ImageFrame or None"):
        Shape(SQUARE, frame="px")
    assert heart_shape("systole").frame is PIXELS  # traced on an image: y down


def test_spread_indices_of_a_huge_cloud_is_linear_and_even():
    """Above HUGE nodes the farthest points are chosen among an even grid subset: n
    distinct sorted indices, spread so that every node lies within a few of their
    spacings of one (as the farthest points of all the nodes would)."""
    from scipy.spatial import cKDTree

    from modalmorph.core.shape import HUGE, spread_indices

    rng = np.random.default_rng(3)
    p = rng.normal(size=(HUGE + 1000, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    idx = spread_indices(Shape(p), 200)
    assert len(idx) == 200 and np.all(np.diff(idx) > 0)
    gap = cKDTree(p[idx]).query(p)[0].max()
    spacing = np.sqrt(4 * np.pi / 200)  # of 200 points spread evenly over the sphere
    assert gap < spacing  # measured 0.82 of it; the farthest of all the nodes: 0.79


def _ring(n_outer=40, n_inner=24, r_outer=2.0, r_inner=1.0):
    t = np.linspace(0, 2 * np.pi, n_outer, endpoint=False)
    s = np.linspace(0, 2 * np.pi, n_inner, endpoint=False)
    pts = np.vstack([r_outer * np.c_[np.cos(t), np.sin(t)],
                     r_inner * np.c_[np.cos(s), np.sin(s)]])
    return Shape(pts, contours=(n_outer, n_inner))


def test_contours_split_the_rows_and_close_each_loop():
    ring = _ring()
    assert ring.sizes == (40, 24) and ring.slices == [slice(0, 40), slice(40, 64)]
    assert ring.contour_of.tolist() == [0] * 40 + [1] * 24
    e = ring.edges
    assert e.shape == (64, 2)
    assert [40 - 1, 0] in e.tolist() and [63, 40] in e.tolist()  # each loop closes on itself
    assert not any(ring.contour_of[a] != ring.contour_of[b] for a, b in e)  # no bridge
    assert_allclose(ring.contour(1).points, ring.points[40:])
    assert ring.with_points(ring.points * 3).sizes == (40, 24)
    assert "x2" in repr(ring)
    open_ = Shape(ring.points, closed=False, contours=(40, 24))
    assert len(open_.edges) == 62


def test_one_contour_is_stored_as_none_and_behaves_as_before():
    one = Shape(_ring().points[:40], contours=[40])
    assert one.contours is None and one.sizes == (40,)
    assert one.edges.tolist() == [[i, (i + 1) % 40] for i in range(40)]
    cloud = Shape(np.random.default_rng(0).normal(size=(10, 3)))
    assert cloud.sizes == () and cloud.edges.shape == (0, 2)


@pytest.mark.parametrize("kwargs, match", [
    (dict(contours=(40, 20)), "summing"),
    (dict(contours=(62, 2)), "at least 3"),
    (dict(contours=(32, 32), ordered=False), "ordered"),
    (dict(contours="ab"), "node counts"),
])
def test_bad_contours_are_refused_by_name(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Shape(_ring().points, **kwargs)


def test_coarsen_and_spread_share_nodes_by_length():
    from modalmorph.core.shape import coarsen, share, spread_indices
    ring = _ring(200, 200)
    assert share(ring, 30) == [19, 11]  # 3 each + 24 in proportion 2:1 (16, 8)
    small = coarsen(ring, 30)
    assert small.sizes == (19, 11)
    sag = 1 - np.cos(np.pi / 200)  # resampled nodes lie on the 200-gon's chords
    assert_allclose(np.linalg.norm(small.contour(0).points, axis=1), 2.0, rtol=sag)
    assert_allclose(np.linalg.norm(small.contour(1).points, axis=1), 1.0, rtol=sag)
    idx = spread_indices(ring, 30)
    assert len(idx) == 30 and (ring.contour_of[idx] == 0).sum() == 19


def test_check_contours_refuses_contours_that_cross_each_other():
    from modalmorph.core.quality import check_contours
    check_contours(_ring(), "ring")
    ring = _ring()
    moved = ring.points.copy()
    moved[40:] += [1.5, 0.0]  # the hole pokes out through the outer boundary
    with pytest.raises(ValueError, match="contour 0 crosses contour 1"):
        check_contours(ring.with_points(moved), "ring")


def test_a_check_that_passed_is_not_run_again_and_one_that_failed_is():
    from modalmorph.core.shape import check_once, forget_checks

    runs = []
    pts = np.random.default_rng(5).normal(size=(40, 2))
    forget_checks()
    for _ in range(3):
        check_once("test", pts, lambda: runs.append(1))
    assert len(runs) == 1
    check_once("test", pts + 1e-12, lambda: runs.append(1))  # other numbers: run
    check_once("test", pts, lambda: runs.append(1), "closed")  # another key: run
    assert len(runs) == 3
    forget_checks()
    check_once("test", pts, lambda: runs.append(1))
    assert len(runs) == 4

    def fail():
        runs.append(1)
        raise ShapeError("no")

    for _ in range(2):  # a failure is not remembered
        with pytest.raises(ShapeError):
            check_once("failing", pts, fail)
    assert len(runs) == 6
    bad = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 0.0], [0.0, 1.0]])
    for _ in range(2):  # repeated nodes refused every time
        with pytest.raises(ShapeError, match="repeated nodes"):
            Shape(bad)


def test_3d_points_along_a_curve_in_order_are_ordered_by_default():
    """3D points that trace a curve in the order given (a contour with a z column, a
    helix) are an ordered polyline by default; the same points shuffled, and points on a
    surface, are a point set."""
    rng = np.random.default_rng(3)
    t = np.linspace(0, 2 * np.pi, 1000, endpoint=False)
    curves = {"planar": np.c_[30 * np.cos(t), 20 * np.sin(t), np.zeros_like(t)],
              "helix": np.c_[np.cos(3 * t), np.sin(3 * t), 0.3 * t]}
    for name, pts in curves.items():
        assert traces_curve(pts) and Shape(pts).ordered, name
        shuffled = pts[rng.permutation(len(pts))]
        assert not traces_curve(shuffled) and not Shape(shuffled).ordered, name
    u = rng.normal(size=(2000, 3))
    sphere = u / np.linalg.norm(u, axis=1, keepdims=True)
    assert not traces_curve(sphere) and not Shape(sphere).ordered
    assert not Shape(curves["planar"], ordered=False).ordered  # said: kept
    ring = np.linspace(0, 2 * np.pi, 90, endpoint=False)
    stack = np.vstack([np.c_[(20 - k) * np.cos(ring), (20 - k) * np.sin(ring),
                             np.full(90, 10.0 * k)] for k in range(6)])  # slice by slice
    u, v = np.meshgrid(np.arange(200.0), 10.0 * np.arange(20.0))  # scan rows 10 apart
    for name, pts in {"stack": stack, "rows": np.c_[u.ravel(), v.ravel(), 0 * u.ravel()]}.items():
        assert not traces_curve(pts) and not Shape(pts).ordered, name


def test_spacing_brute_force_is_the_k_d_trees():
    """Up to BRUTE_NEAREST nodes the spacing comes from every pair's distance: the k-d
    tree's numbers, bit for bit (what it replaced), in 2D and 3D, at and past the limit."""
    from scipy.spatial import cKDTree

    from modalmorph.core.nearest import BRUTE_NEAREST

    rng = np.random.default_rng(11)
    for m in (3, 4, 17, 70, BRUTE_NEAREST, BRUTE_NEAREST + 1):
        for d in (2, 3):
            pts = rng.normal(size=(m, d)) * rng.uniform(0.01, 100)
            shape = Shape(pts)
            dist, _ = cKDTree(shape.normalized).query(shape.normalized, k=2)
            assert shape.spacing == float(dist[:, 1].mean())  # exact: same operations
