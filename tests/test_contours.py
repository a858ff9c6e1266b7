"""Objects of several contours through match, morph and track (issues 23 and 24): a
myocardium ring (epicardium + endocardium) and a footprint (heel, forefoot, toes)."""

from __future__ import annotations

import logging

import numpy as np
import pytest

import modalmorph as mm
from modalmorph.core.quality import correspondence_rotation, crossing_segments, curve_distances
from modalmorph.core.shape import Shape
from modalmorph.errors import ShapeError

ON_CURVE = 0.01  # a node "ends on" its target contour: within 1 % of the target's size


def blob(centre, radii, n, *, turn=0.0, wobble=0.0, lobes=3, reverse=False):
    """A closed contour of ``n`` nodes: an ellipse of ``radii`` about ``centre``, turned
    by ``turn`` radians, its radius modulated by ``wobble`` with ``lobes`` lobes."""
    t = 2 * np.pi * np.arange(n) / n
    r = 1 + wobble * np.cos(lobes * t)
    p = np.c_[radii[0] * r * np.cos(t), radii[1] * r * np.sin(t)]
    c, s = np.cos(turn), np.sin(turn)
    p = p @ np.array([[c, s], [-s, c]]) + centre
    return p[::-1] if reverse else p


def ring(outer, inner, n_outer, n_inner, *, turn=0.0, centre=(100.0, 50.0)):
    """A myocardium-like ring: the outer contour counter-clockwise, the hole clockwise,
    turned by ``turn`` degrees about ``centre``."""
    pts = np.vstack([blob((0, 0), (outer, outer), n_outer),
                     blob((0, 0), (inner, inner), n_inner, reverse=True)])
    c, s = np.cos(np.radians(turn)), np.sin(np.radians(turn))
    return Shape(pts @ np.array([[c, s], [-s, c]]) + centre, contours=(n_outer, n_inner))


def footprint(toes=True, *, shift=(0.0, 0.0), squash=1.0):
    """Heel, forefoot and (optionally) toes as three blobs."""
    parts = [blob((0, 0), (9 * squash, 12), 40, wobble=0.05),
             blob((2, 30), (13 * squash, 10), 50, turn=0.2, wobble=0.08),
             blob((4, 47), (8, 4 * squash), 24, wobble=0.05)][:3 if toes else 2]
    pts = np.vstack(parts) + shift
    return Shape(pts, contours=tuple(len(p) for p in parts))


def contour_gaps(shape_points, source: Shape, target: Shape, partners):
    """Per pair of partners, the largest distance of a source node to its target contour,
    in units of the target's RMS radius."""
    return [curve_distances(shape_points[source.slices[k]], target.points[target.slices[j]])
            [0].max() / target.size for k, j in partners]


def crossings(points, shape: Shape) -> int:
    """Pairs of crossing segments of every contour and between contours."""
    return len(crossing_segments(points, edges=shape.edges))


@pytest.fixture(scope="module")
def ring_morph():
    a, b = ring(30, 20, 60, 40), ring(27, 15, 70, 35)
    return a, b, mm.morph(a, b)


def test_ring_contracts_and_thickens(ring_morph):
    a, b, r = ring_morph
    assert r.stop_reason == "tolerance", r.message
    assert r.matching.contours.tolist() == [[0, 0], [1, 1]]
    pairs = r.matching.pairs
    assert np.array_equal(a.contour_of[pairs[:, 0]], b.contour_of[pairs[:, 1]])
    assert max(contour_gaps(r.shapes[-1], a, b, r.matching.contours)) < ON_CURVE
    assert max(crossings(p, a) for p in r.shapes) == 0  # none, within or across contours
    assert r.shape().contours == a.contours and r.shape(0).m == a.m


def lobed_ring(turn=0.0, outer=1.0, inner=1.0, n_outer=60, n_inner=40):
    """A ring whose contours are not circles (3 and 2 lobes, off centre), so that its
    turn can be found, turned by ``turn`` degrees about (100, 50)."""
    pts = np.vstack([blob((0, 0), (30 * outer, 26 * outer), n_outer, wobble=0.08),
                     blob((3, 0), (20 * inner, 15 * inner), n_inner, wobble=0.05, lobes=2,
                          reverse=True)])
    c, s = np.cos(np.radians(turn)), np.sin(np.radians(turn))
    return Shape(pts @ np.array([[c, s], [-s, c]]) + (100, 50), contours=(n_outer, n_inner))


@pytest.mark.parametrize("turn", [40.0, 160.0])
def test_ring_partners_survive_a_turn(turn):
    a, b = lobed_ring(), lobed_ring(turn, 0.9, 0.75, 70, 35)
    m = mm.match(a, b, rotation="auto")
    assert m.contours.tolist() == [[0, 0], [1, 1]]
    assert correspondence_rotation(a, b, m.pairs) == pytest.approx(turn, abs=2.0)
    assert np.array_equal(a.contour_of[m.pairs[:, 0]], b.contour_of[m.pairs[:, 1]])
    r = mm.morph(a, b, matching=m)
    assert r.converged, r.message
    assert max(contour_gaps(r.shapes[-1], a, b, m.contours)) < ON_CURVE
    assert max(crossings(p, a) for p in r.shapes) == 0


def test_unmatched_nodes_walk_along_their_own_contour():
    a, b = ring(30, 20, 60, 40), ring(27, 15, 60, 40)
    given = np.c_[np.arange(100), np.arange(100)]
    gap = np.r_[55:60, 60:65]  # the last outer nodes and the first inner ones
    r = mm.morph(a, b, matching=np.delete(given, gap, axis=0))
    assert r.converged, r.message
    assert max(contour_gaps(r.shapes[-1], a, b, [(0, 0), (1, 1)])) < ON_CURVE
    assert max(crossings(p, a) for p in r.shapes) == 0


def test_contours_listed_in_another_order_keep_their_partners():
    a = ring(30, 20, 60, 40)
    b = ring(27, 15, 70, 35)
    swapped = Shape(np.vstack([b.points[b.slices[1]], b.points[b.slices[0]]]),
                    contours=(35, 70))
    m = mm.match(a, swapped, rotation="none")
    assert m.contours.tolist() == [[0, 1], [1, 0]]
    assert np.array_equal(m.contours[a.contour_of[m.pairs[:, 0]], 1],
                          swapped.contour_of[m.pairs[:, 1]])


def test_footprint_three_blobs():
    a, b = footprint(), footprint(shift=(3.0, -2.0), squash=1.15)
    r = mm.morph(a, b)
    assert r.converged, r.message
    assert r.matching.contours.tolist() == [[0, 0], [1, 1], [2, 2]]
    assert max(contour_gaps(r.shapes[-1], a, b, r.matching.contours)) < ON_CURVE
    assert max(crossings(p, a) for p in r.shapes) == 0


def test_unequal_contour_counts_name_the_unpaired(caplog):
    a, b = footprint(), footprint(toes=False, shift=(1.0, 0.0))
    with caplog.at_level(logging.INFO, logger="modalmorph"):
        r = mm.morph(a, b)
    assert r.matching.contours.tolist() == [[0, 0], [1, 1]]
    assert "source contour 2 (24 nodes) without a partner contour" in r.message
    assert "source contour 2" in caplog.text
    assert r.converged, r.message  # the unpaired toes are not measured
    toes = r.shapes[-1][a.slices[2]]  # carried along with the forefoot, not collapsed
    assert np.ptp(toes, axis=0).min() > 0.5 * np.ptp(a.points[a.slices[2]], axis=0).min()
    back = mm.morph(b, a)  # the target's extra contour is named too
    assert "target contour 2 (24 nodes) without a partner contour" in back.message


@pytest.mark.parametrize("method", ["local", "global"])
def test_paper_searches_keep_partner_contours(method):
    a, b = ring(30, 20, 60, 40), ring(28, 17, 60, 40)
    m = mm.match(a, b, method=method)
    assert m.contours.tolist() == [[0, 0], [1, 1]]
    assert len(m) > 0
    assert np.array_equal(a.contour_of[m.pairs[:, 0]], b.contour_of[m.pairs[:, 1]])


@pytest.mark.parametrize("correspondence", ["nearest", "modal"])
def test_track_of_a_contracting_ring(correspondence):
    frames = [ring(30 - 0.4 * f, 20 - 0.6 * f, 60, 40) for f in range(10)]
    tr = mm.track(frames, correspondence=correspondence,
                  match_options=dict(rotation="none") if correspondence == "modal" else None)
    n = frames[0].m
    assert tr.points.shape == (10, n, 2)
    assert not tr.crossed.any()
    assert tr.distance.max() < ON_CURVE * frames[-1].size
    outer, inner = frames[0].slices
    radius = np.linalg.norm(tr.points - [100.0, 50.0], axis=2)
    assert np.allclose(radius[-1, outer], 30 - 3.6, atol=ON_CURVE * 30)  # stays on its own
    assert np.allclose(radius[-1, inner], 20 - 5.4, atol=ON_CURVE * 30)
    assert tr.edges.shape == (n, 2) and tr.segment_strain.shape == (10, 12)
    # circumferential strain of each contour: its radius ratio less 1 (to 1 %: nodes
    # that keep their angles on a shrinking circle)
    assert np.allclose(tr.segment_strain[-1, :6], (30 - 3.6) / 30 - 1, atol=0.01)
    assert np.allclose(tr.segment_strain[-1, 6:], (20 - 5.4) / 20 - 1, atol=0.01)


def test_track_with_changing_node_counts_stays_on_each_contour():
    frames = [ring(30 - 0.4 * f, 20 - 0.6 * f, 60 + f, 40 - f) for f in range(10)]
    tr = mm.track(frames)
    assert not tr.crossed.any()
    assert tr.distance.max() < ON_CURVE * frames[-1].size
    radius = np.linalg.norm(tr.points[-1] - [100.0, 50.0], axis=1)
    outer, inner = frames[0].slices
    assert np.allclose(radius[outer], 30 - 3.6, atol=ON_CURVE * 30)
    assert np.allclose(radius[inner], 20 - 5.4, atol=ON_CURVE * 30)


def test_track_segments_line_up_between_contours():
    frames = [ring(30, 20, 60, 40), ring(29, 19, 60, 40)]
    tr = mm.track(frames)
    mid = np.array([tr.points[0][e].mean(axis=0) for e in tr.edges]) - [100.0, 50.0]
    angle = np.degrees(np.arctan2(mid[:, 1], mid[:, 0])) % 360
    for s in range(6):  # segment s of the hole covers the sector of segment s outside
        out = angle[tr.segment_of_edge == s]
        inn = angle[tr.segment_of_edge == 6 + s]
        assert abs(np.median(out) - np.median(inn)) < 10.0


def test_track_orders_and_turns_each_frame_like_frame_0():
    a = ring(30, 20, 60, 40)
    b = ring(29, 19, 50, 45)
    listed = Shape(np.vstack([b.points[b.slices[1]][::-1], b.points[b.slices[0]]]),
                   contours=(45, 50))  # hole first, running the other way
    tr = mm.track([a, listed])
    assert tr.frames[1].contours == (50, 45)
    assert np.array_equal(tr.frames[1].points[50:], b.points[b.slices[1]])
    assert tr.distance[1] < ON_CURVE * b.size


def test_track_refuses_a_frame_of_another_contour_count():
    with pytest.raises(ShapeError, match=r"frame 1 \(frame 1\): it has 1 contour but "
                                         r"frame 0 has 2"):
        mm.track([ring(30, 20, 60, 40), Shape(blob((100, 50), (30, 30), 60))])


def test_curve_distance_is_contour_by_contour():
    a = ring(30, 20, 60, 40)
    assert mm.tracking.curve_distance(a, a) == pytest.approx(0.0, abs=1e-12)
    b = ring(30, 19, 60, 40)  # only the hole moved, by 1
    assert mm.tracking.curve_distance(a, b) == pytest.approx(40 / 100, rel=0.05)


def test_three_d_polylines_of_several_contours():
    def rings(scale=1.0, sizes=(40, 30), z=(0.0, 5.0), turn=0.0):
        p = np.c_[blob((0, 0), (10 * scale, 8 * scale), sizes[0], wobble=0.05),
                  z[0] + 0.5 * np.sin(np.arange(sizes[0]) / 3)]
        q = np.c_[blob((1, 0), (6 * scale, 5 * scale), sizes[1], wobble=0.05, lobes=2),
                  np.full(sizes[1], z[1])]
        c, s = np.cos(np.radians(turn)), np.sin(np.radians(turn))
        turned = np.vstack([p, q]) @ np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]])
        return Shape(turned, ordered=True, contours=sizes)

    a, b = rings(), rings(0.9, (45, 28), (0.5, 5.5), turn=40.0)
    m = mm.match(a, b)
    assert m.contours.tolist() == [[0, 0], [1, 1]]
    assert correspondence_rotation(a, b, m.pairs) == pytest.approx(40.0, abs=2.0)
    r = mm.morph(a, b, matching=m)
    assert r.converged, r.message
    assert max(contour_gaps(r.shapes[-1], a, b, m.contours)) < ON_CURVE


def test_crossing_contours_are_refused():
    a = ring(30, 20, 60, 40)
    bad = Shape(np.vstack([a.points[:60], a.points[60:] + [15.0, 0.0]]), contours=(60, 40))
    with pytest.raises(ShapeError, match="contour 0 crosses contour 1"):
        mm.morph(bad, a)
    with pytest.raises(ShapeError, match="contour 0 crosses contour 1"):
        mm.morph(bad, a, matching=np.c_[np.arange(100), np.arange(100)])
