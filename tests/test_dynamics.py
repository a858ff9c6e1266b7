"""Loads (19)-(20) and Newmark (14)-(15) on their own."""

import numpy as np
import pytest
from numpy.testing import assert_allclose

from modalmorph.core import dynamics
from modalmorph.core.dynamics import LoadTargets, Newmark
from modalmorph.datasets import load_hand


def _pair(n=120):
    idx = np.linspace(0, 1590, n, endpoint=False).astype(int)
    return load_hand(0)[idx], load_hand(3)[idx]


@pytest.mark.parametrize("small", [0, 10**9])
def test_neighbourhood_rule_same_in_both_passes(monkeypatch, small):
    """The vectorised pass over small groups and the per-group pass give one answer."""
    a, b = _pair()
    rng = np.random.default_rng(3)
    keep = np.sort(rng.choice(120, 50, replace=False))
    pairs = np.c_[keep, keep]
    reference = LoadTargets(a, b, pairs, ordered=True, closed=(True, True),
                            rule="mean").targets(a + 1.0)
    monkeypatch.setattr(dynamics, "_SMALL_GROUP", small)
    got = LoadTargets(a, b, pairs, ordered=True, closed=(True, True), rule="mean").targets(a + 1.0)
    assert_allclose(got, reference, rtol=1e-12)


def test_weights_are_a_weighted_mean():
    """(20) normalised: an unmatched node's target is a convex combination of the target
    nodes between its neighbours' partners, so it lies in their bounding box."""
    a, b = _pair()
    pairs = np.c_[[0, 10], [0, 10]]
    t = LoadTargets(a, b, pairs, ordered=True, closed=(False, True), rule="mean").targets(a)
    inner = t[1:10]
    box = b[1:10]
    assert np.all(inner >= box.min(axis=0) - 1e-9) and np.all(inner <= box.max(axis=0) + 1e-9)


@pytest.mark.parametrize("closed", [True, False])
def test_arclength_rule_spreads_a_run_along_the_target(closed):
    """An unmatched run lands on the target stretch between its neighbours' partners, in
    order, at the source's arc-length fractions: on a straight stretch, evenly spaced."""
    src = np.c_[np.arange(12.0), np.zeros(12)]  # nodes 0..11 along a line, 1 apart
    tgt = np.c_[np.linspace(0.0, 22.0, 12), np.full(12, 3.0)]  # stretched x2, shifted
    pairs = np.c_[[0, 11], [0, 11]]
    if closed:  # closed by a matched arc of 20 nodes below the line
        u = np.linspace(0, np.pi, 22)[1:-1]
        src = np.r_[src, np.c_[5.5 + 5.5 * np.cos(u), -6 * np.sin(u)]]
        tgt = np.r_[tgt, np.c_[11 + 11 * np.cos(u), 3 - 6 * np.sin(u)]]
        pairs = np.r_[pairs, np.c_[np.arange(12, 32), np.arange(12, 32)]]
    t = LoadTargets(src, tgt, pairs, ordered=True, closed=(closed, closed),
                    rule="arclength").targets(src)
    assert_allclose(t[:12], tgt[:12], atol=1e-12)  # run 1..10 at x = 2, 4, ..., 20


def test_arclength_rule_backwards_round_a_closed_target():
    """Partners in decreasing target order (a reversed target): the stretch is walked
    the shorter way, backwards."""
    a, b = _pair(60)
    reversed_b = b[::-1].copy()  # source node i belongs with reversed_b[59 - i] = b[i]
    pairs = np.c_[[0, 10, 30], [59, 49, 29]]
    t = LoadTargets(a, reversed_b, pairs, ordered=True, closed=(True, True)).targets(a)
    from scipy.spatial import cKDTree

    # nodes 1..9 land on b's stretch from b[0] to b[10], in order
    gap, near = cKDTree(b[:11]).query(t[1:10])
    assert gap.max() <= np.linalg.norm(np.diff(b[:11], axis=0), axis=1).max()
    assert np.all(np.diff(near) >= 0)


# The stem of a sans-serif 'i' (4 nodes, DejaVu Sans) and of a serif one (10 nodes, DejaVu
# Serif: a foot of 26 units, a top serif), as matplotlib's TextPath gives them.
STEM = np.array([[9.42, 54.69], [18.41, 54.69], [18.41, 0.0], [9.42, 0.0]])
SERIF = np.array([[21.19, 5.17], [29.69, 5.17], [29.69, 0.0], [3.61, 0.0], [3.61, 5.17],
                  [12.2, 5.17], [12.2, 46.69], [3.61, 46.69], [3.61, 51.91], [21.19, 51.91]])


def test_arclength_rule_follows_the_partners_way_round_not_the_shorter():
    """A stretch of more than half the target is walked the way the partners run round it:
    the stem's foot corners (freed: they cannot cover the serif foot alone) land on the
    foot, not on the top serif, the shorter way from node 1's partner to node 0's."""
    t = LoadTargets(STEM, SERIF, np.c_[[0, 1, 2, 3], [6, 9, 0, 5]], ordered=True,
                    closed=(True, True))
    assert t.turn == 1
    assert_allclose(t.targets(STEM)[2:, 1], 0.0, atol=1e-9)  # on the foot's bottom (y = 0)
    assert np.all(np.diff(t.targets(STEM)[2:, 0]) < 0)  # in the source's order


def test_two_partners_take_the_contours_orientation():
    """Two matched nodes of a closed contour say nothing of the way round (their two
    stretches make one round either way): the contours' orientations do (both the same
    way: forwards). An exclamation
    mark's bar (6 nodes, DejaVu Sans Mono) onto a drop (18 nodes, STIX): the bar's top
    corners land on the drop's top, not on its bottom tip (the shorter way)."""
    bar = np.array([[25.2, 72.9], [35.1, 72.9], [35.1, 40.9], [34.1, 23.5], [26.2, 23.5],
                    [25.2, 40.9]])
    drop = np.array([[17.5, 17.6], [13.3, 55.7], [13.1, 58.3], [13.0, 60.0], [13.1, 61.8],
                     [13.7, 64.6], [15.1, 66.5], [17.1, 67.5], [18.3, 67.6], [19.5, 67.5],
                     [21.4, 66.4], [22.2, 65.4], [22.8, 64.2], [23.5, 61.3], [23.6, 59.5],
                     [23.5, 57.8], [23.4, 55.7], [18.9, 17.6]])
    t = LoadTargets(bar, drop, np.c_[[2, 5], [16, 1]], ordered=True, closed=(True, True))
    assert t.turn == 1
    assert np.all(t.targets(bar)[[0, 1], 1] > 60)  # on the drop's top (55.7..67.6)


def test_a_local_inversion_of_the_pairs_takes_the_shorter_way():
    """Partners running forwards but for two swapped ones: the stretch between the swapped
    pair is not walked the long way round (the mean rule (20) would average the whole
    target there and pull the node to the middle); it stays between its neighbours."""
    u = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    circle, ellipse = np.c_[np.cos(u), np.sin(u)], np.c_[1.5 * np.cos(u), np.sin(u)]
    src = np.arange(0, 60, 3)
    dst = src.copy()
    dst[10], dst[11] = 33, 30  # 30 -> 33 and 33 -> 30
    t = LoadTargets(circle, ellipse, np.c_[src, dst], ordered=True, closed=(True, True),
                    rule="mean")
    assert t.turn == 1
    assert np.linalg.norm(t.targets(circle)[31] - ellipse[31]) < 0.5  # it was 1.3 off


def test_newmark_free_oscillator_conserves_energy():
    """delta = 1/2, alpha = 1/4 (average acceleration): no numerical damping."""
    w = np.array([1.0, 3.0])
    nm = Newmark(np.diag(w**2), np.zeros((2, 2)), dt=0.05)
    x, v = np.array([1.0, 0.5]), np.zeros(2)
    a = -(w**2) * x
    e0 = 0.5 * (v**2 + w**2 * x**2)
    for _ in range(2000):
        x, v, a = nm.step(x, v, a, np.zeros(2))
    assert_allclose(0.5 * (v**2 + w**2 * x**2), e0, rtol=1e-10)


def test_newmark_checks_its_parameters():
    """Newmark refuses what would make it unstable or undefined, at construction."""
    K, C = np.eye(2), np.zeros((2, 2))
    with pytest.raises(ValueError, match="not unconditionally stable"):
        Newmark(K, C, dt=0.1, alpha=0.2, delta=0.5)
    with pytest.raises(ValueError, match="positive finite"):
        Newmark(K, C, dt=0.0)
    with pytest.raises(ValueError, match="square and of one size"):
        Newmark(K, np.zeros((3, 3)), dt=0.1)
    nm = Newmark(K, C, dt=0.1)
    assert nm.coefficients[0] == 1 / (0.25 * 0.1**2)  # a0 of (15), computed once


def test_newmark_with_a_lift_is_newmark_on_the_lifted_matrix_bitwise():
    """Newmark(K, C, lift=kappa) factors and steps as Newmark(K + kappa I, C), bit for bit,
    and leaves K as it was; its product with the stiffness is the lifted matrix's (x zero
    or not)."""
    rng = np.random.default_rng(5)
    A = rng.normal(size=(30, 30))
    K = A @ A.T
    C = 0.3 * K + 0.1 * np.eye(30)
    kappa = 0.7
    lifted = K.copy()
    lifted.flat[::31] += kappa
    kept = K.copy()
    a, b = Newmark(K, C, dt=0.2, lift=kappa), Newmark(lifted, C, dt=0.2)
    assert np.array_equal(a.factor, b.factor)
    assert np.array_equal(a.diagonal(), np.diagonal(lifted))
    x, v, acc, f = rng.normal(size=(4, 30))
    for got, want in zip(a.step(x, v, acc, f), b.step(x, v, acc, f), strict=True):
        assert np.array_equal(got, want)
    for y in (x, np.zeros(30)):
        assert np.array_equal(a.stiffness_dot(y), lifted @ y)
    assert np.array_equal(K, kept)


@pytest.mark.parametrize("run", [[39, 0], [39, 0, 1], [38, 39, 0, 1]])
def test_one_source_node_per_target_node_even_where_the_run_wraps(run):
    """A denser closed source whose nodes ``run`` share a partner across the wrap keeps one
    of them matched (review15: such a run was cut in two, both halves kept a node, and
    the two were pulled onto one point, which folded the last step)."""
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    src = np.c_[np.cos(t), np.sin(t)]
    tgt = 1.2 * src[::2]  # 20 nodes
    partner = np.arange(40) // 2  # nodes 2k, 2k+1 share partner k
    partner[run] = 0
    partner[1 if 1 not in run else 2] = 1
    pairs = np.c_[np.arange(40), partner]
    loads = LoadTargets(src, tgt, pairs, ordered=True, closed=(True, True), rule="arclength")
    kept = loads.pairs
    assert np.array_equal(np.sort(kept[:, 1]), np.unique(partner))  # one node per partner
    x = loads.targets(src)
    gaps = np.linalg.norm(np.diff(np.r_[x, x[:1]], axis=0), axis=1)
    assert gaps.min() > 0.3 * gaps.mean()  # spread along the target, none piled up
