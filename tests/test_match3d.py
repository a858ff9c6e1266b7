"""The 3D point-set matcher (issue 16): warped, turned, noisy, subsampled, shuffled copies
with a known ground truth."""

import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

import modalmorph as mm
from modalmorph.matching.clouds import refine
from modalmorph.simulation.stop import to_surface


def blob(m, rng):
    """An asymmetric bumpy ellipsoid, as in benchmarks/match3d.py, (m, 3)."""
    p = rng.normal(size=(m, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    p *= [1.0, 0.7, 0.5]
    p += 0.3 * np.exp(-np.sum((p - [0, 0, 0.5]) ** 2, axis=1) / 0.1)[:, None] * [0, 0, 1]
    c = np.array([0.55, 0.45, -0.2])
    return p + 0.25 * np.exp(-np.sum((p - c) ** 2, axis=1) / 0.1)[:, None] * c


def case(m, angle, noise, seed=0):
    """Source, target (80 % of the points, shuffled) and the true positions (m, 3)."""
    rng = np.random.default_rng(seed)
    src = blob(m, rng)
    bumps = src[rng.choice(m, 4, replace=False)]
    dirs = rng.normal(size=(4, 3))
    u = sum(np.exp(-np.sum((src - c) ** 2, axis=1) / (2 * 0.4**2))[:, None] * v
            for c, v in zip(bumps, dirs, strict=True))
    u *= 0.1 * 0.6 / np.linalg.norm(u, axis=1).max()  # largest move: 10 % of the size
    rot = Rotation.from_rotvec(np.deg2rad(angle) * np.array([0.3, -0.5, 0.8]) / np.sqrt(0.98))
    truth = rot.apply(src + u) + [0.2, -0.1, 0.3]
    tgt = truth + noise * 0.6 * rng.normal(size=truth.shape)  # size (RMS radius) ~ 0.6
    keep = rng.permutation(m)[: int(0.8 * m)]
    return src, tgt[keep], truth


def pair_error(tgt, truth, pairs):
    h = cKDTree(tgt).query(tgt, k=2)[0][:, 1].mean()
    return np.linalg.norm(tgt[pairs[:, 1]] - truth[pairs[:, 0]], axis=1) / h


@pytest.mark.parametrize("m", [800, 3000])
@pytest.mark.parametrize("angle", [30, 180])
def test_pairs_within_a_spacing(m, angle):
    src, tgt, truth = case(m, angle, noise=0.01)
    pairs = mm.match(src, tgt).pairs
    err = pair_error(tgt, truth, pairs)
    assert len(pairs) >= 0.95 * m  # nearly every source point gets a partner
    assert np.median(err) <= 1.0  # the goal of issue 16: within one target spacing
    assert np.percentile(err, 90) <= 3.0


def test_morph_with_own_pairs_reaches_target():
    src, tgt, _ = case(800, 90, noise=0.005)
    matching = mm.match(src, tgt)
    result = mm.morph(src, tgt, matching=matching, model_nodes=800)
    end, size = result.shapes[-1], mm.Shape(tgt).size
    # the end shape within 1 % of the size both ways: its nodes to the target's surface
    # (the 800 nodes outnumber the 640 target points, so those sharing a partner are
    # carried between them, not onto them), the target's points to the end's surface.
    # (The pairs turn the source by 90 deg: co-rotated, the turned source is within the
    # tolerance from the start, 0.76 / 0.78 % both ways; its nodes lie half a spacing
    # from the target's points, 1.7 % of the size, as two samplings of one surface do.)
    assert result.converged and result.co_rotation is not None
    assert to_surface(end, tgt, cKDTree(tgt)).mean() <= 0.01 * size
    assert to_surface(tgt, end, cKDTree(end)).mean() <= 0.01 * size


def test_refine_keeps_the_true_correspondence():
    """Started where every source node truly belongs, the refinement stays there (its
    coarse levels summarise both objects by cube densities, not random subsets)."""
    src, tgt, truth = case(20000, 90, noise=0.01)
    s, t = mm.Shape(src), mm.Shape(tgt)
    y = t.normalized
    z = refine(s.normalized, t.to_normalized(truth), y, 250)
    h = cKDTree(y).query(y, k=2)[0][:, 1].mean()
    drift = np.linalg.norm(z - t.to_normalized(truth), axis=1) / h
    assert np.median(drift) <= 0.3  # measured 0.10 (random subsets: 0.14 here, 1.25 on the
    # benchmark's 100 000-point blob)


def test_refine_first_level_recovers_a_turned_pose():
    """The first level of the refinement alone (``levels=1``, the pose passes of sets above
    FINE_CLOUD) takes a start turned 4 degrees from the true pose back to it (measured
    0.11 degrees); with more levels than there are it is the whole refinement, bit for
    bit."""
    src, tgt, truth = case(6000, 30, noise=0.01)
    s, t = mm.Shape(src), mm.Shape(tgt)
    x, y, z = s.normalized, t.normalized, t.to_normalized(truth)
    turn = Rotation.from_rotvec(np.deg2rad(4.0) * np.array([1.0, 2.0, -1.0]) / np.sqrt(6))
    centre = z.mean(axis=0)
    start = turn.apply(mm.align(x, z).apply(x) - centre) + centre
    one = refine(x, start, y, 250, levels=1)
    off = Rotation.from_matrix(mm.align(z, one).rotation).magnitude()
    assert np.degrees(off) <= 0.5  # from 4 degrees
    assert np.array_equal(refine(x, start, y, 250, levels=99), refine(x, start, y, 250))


def sampled_anew(m, angle, seed=0):
    """As :func:`case`, but the target's points sampled anew on the blob (as two scans of
    one surface share no samples) before the same warp and turn: source, target, truth."""
    rng = np.random.default_rng(seed)
    src, again = blob(m, rng), blob(m, rng)
    bumps, dirs = src[rng.choice(m, 4, replace=False)], rng.normal(size=(4, 3))

    def field(p):
        return sum(np.exp(-np.sum((p - c) ** 2, axis=1) / (2 * 0.4**2))[:, None] * v
                   for c, v in zip(bumps, dirs, strict=True))

    scale = 0.1 * 0.6 / np.linalg.norm(field(src), axis=1).max()
    rot = Rotation.from_rotvec(np.deg2rad(angle) * np.array([0.3, -0.5, 0.8]) / np.sqrt(0.98))

    def move(p):
        return rot.apply(p + scale * field(p)) + [0.2, -0.1, 0.3]

    tgt = move(again) + 0.01 * 0.6 * rng.normal(size=again.shape)
    return src, tgt[rng.permutation(m)[: int(0.8 * m)]], move(src)


def test_refine_decay_gives_the_turn_back_to_the_pose():
    """On two independent samplings the first level's smooth field keeps part of a turn
    the pose should take; shrinking its departure from the best affine map every round
    (``decay``, matching.POSE_DECAY) leaves the landings nearer the true pose (from 4
    degrees off: measured 2.30 -> 2.11 degrees; with the target the source's own points,
    test above, 0.11); decay 0 is the refinement as it was, bit for bit."""
    src, tgt, truth = sampled_anew(20000, 30)
    s, t = mm.Shape(src), mm.Shape(tgt)
    x, y, z = s.normalized, t.normalized, t.to_normalized(truth)
    turn = Rotation.from_rotvec(np.deg2rad(4.0) * np.array([1.0, 2.0, -1.0]) / np.sqrt(6))
    centre = z.mean(axis=0)
    start = turn.apply(mm.align(x, z).apply(x) - centre) + centre
    true = mm.align(x, z).rotation

    def off(decay):
        one = refine(x, start, y, 250, levels=1, decay=decay)
        return np.degrees(Rotation.from_matrix(mm.align(x, one).rotation @ true.T).magnitude())

    assert off(0.02) <= off(0.0) - 0.1  # measured 2.11 and 2.30
    assert np.array_equal(refine(x[:3000], start[:3000], y, 250, levels=1, decay=0.0),
                          refine(x[:3000], start[:3000], y, 250, levels=1))


def test_huge_sets_matched_on_subsets(monkeypatch):
    """Above FINE_CLOUD nodes the match runs on even subsets and carries every node (here
    FINE_CLOUD lowered to 2000 so that 6000 points take that route): every source node
    is paired (not only the subsets' nodes), and issue 16's goal, a target spacing at the
    median, holds through the subsets (measured 0.60; 0.47 on all the nodes)."""
    import modalmorph.matching as matching
    monkeypatch.setattr(matching, "FINE_CLOUD", 2000)
    src, tgt, truth = case(6000, 30, noise=0.01)
    pairs = mm.match(src, tgt).pairs
    err = pair_error(tgt, truth, pairs)
    assert len(pairs) >= 0.95 * len(src)  # every node carried, not only the subset's
    assert np.median(err) <= 1.0


@pytest.mark.parametrize("radii", [(1.3, 1.0, 0.8), (1.5, 1.0, 0.7)])
def test_a_featureless_sphere_keeps_the_common_frame(radii):
    # Every turn fits a sphere alike, so the identity's start must reach the pose's
    # finalists: it lost there, and the pairs turned the sphere 169-171 degrees, which
    # the morph took as a deformation whose halfway surfaces cut through themselves.
    trimesh = pytest.importorskip("trimesh")
    sphere = trimesh.creation.icosphere(3)  # 642 vertices
    ellipsoid = trimesh.creation.icosphere(2)  # 162
    src = mm.Shape(sphere.vertices, faces=sphere.faces)
    tgt = mm.Shape(ellipsoid.vertices * radii, faces=ellipsoid.faces)
    pairs = mm.match(src, tgt).pairs
    turn = mm.core.align.align(src.points[pairs[:, 0]], tgt.points[pairs[:, 1]]).angle
    assert turn <= 20.0, turn  # the common frame's reach (pose._COMMON_ANGLE)


def test_stretch_recovers_an_affine_map_and_takes_flat_sets():
    """``clouds.stretch`` of a sphere's points onto the same points stretched (2, 1, 0.5)
    recovers the stretch (singular values within 0.1: measured 2.05, 0.97, 0.47); a flat
    set (a plate, or points all at z = 0) is summarised as a round one is, and matched
    (a zero extent gave cubes of width 0: NaN)."""
    from modalmorph.matching.clouds import stretch

    rng = np.random.default_rng(0)
    ball = rng.normal(size=(2000, 3))
    ball /= np.linalg.norm(ball, axis=1, keepdims=True)
    moved = stretch(ball, ball * [2.0, 1.0, 0.5])
    fit = np.linalg.lstsq(np.c_[ball, np.ones(len(ball))], moved, rcond=None)[0][:3]
    np.testing.assert_allclose(np.linalg.svd(fit)[1], [2.0, 1.0, 0.5], atol=0.1)
    flat = rng.random((500, 3)) * [1.0, 1.0, 0.0]
    assert np.all(np.isfinite(stretch(flat, flat * [1.2, 0.9, 1.0])))
    pairs = mm.match(flat, rng.random((600, 3)) * [1.2, 0.9, 0.0]).pairs
    assert len(pairs) > 400  # measured 489 of 500


@pytest.mark.parametrize("choice_nodes", [None, 1000])
def test_refine_starts_from_the_similarity_where_the_coarse_deformation_is_wrong(
        monkeypatch, choice_nodes):
    """Landings at the true similarity but twisted by up to 30 degrees about the long
    axis (as a coarse deformation carried from coarse nodes can be): the refinement from
    them stays twisted (measured 2.68 target spacings), from whichever start, the
    landings or their best similarity, lies nearer the target's surface after its first
    level it reaches the truth (0.05); so too where the two starts are tried on even
    subsets and the choice carried to every node (``CHOICE_NODES`` below the 3000)."""
    from modalmorph import matching
    from modalmorph.matching import _refined
    if choice_nodes is not None:
        monkeypatch.setattr(matching, "CHOICE_NODES", choice_nodes)
    src, tgt, truth = case(3000, 30, noise=0.01)
    s, t = mm.Shape(src), mm.Shape(tgt)
    x, y, true = s.normalized, t.normalized, t.to_normalized(truth)
    h = cKDTree(y).query(y, k=2)[0][:, 1].mean()
    posed = mm.align(x, true).apply(x)
    centre = posed.mean(axis=0)
    axis = np.linalg.eigh((posed - centre).T @ (posed - centre))[1][:, -1]
    along = (posed - centre) @ axis
    twist = Rotation.from_rotvec(np.radians(30) * (along / np.abs(along).max())[:, None] * axis)
    z = centre + twist.apply(posed - centre)  # 4.1 spacings from the truth at the median
    start = matching.COARSE // 4 // matching.REFINE_COARSER  # as the matcher's, 62
    assert np.median(np.linalg.norm(refine(x, z, y, start) - true, axis=1)) / h >= 1.5
    assert np.median(np.linalg.norm(_refined(x, z, y, start) - true, axis=1)) / h <= 0.3


def test_rigid_pose_recovers_a_similarity_between_independent_samplings():
    """Rigid CPD (coherent.rigid_pose) lays one sampling of the blob on another, drawn
    anew, turned 8 deg, scaled 1.1 and shifted, with 1 % noise and 20 % dropped: the
    turn it finds within a fifth of the true one (0.78 deg off: the two samplings' chance
    clumps), the scale within 1 %; on one sampling turned the same, exactly."""
    from modalmorph.matching.coherent import rigid_pose
    rng = np.random.default_rng(3)
    src, other = blob(4000, rng), blob(4000, rng)
    rot = Rotation.from_rotvec(np.deg2rad(8.0) * np.array([0.6, 0.0, 0.8]))
    tgt = 1.1 * rot.apply(other) + [0.1, -0.2, 0.05]
    tgt = (tgt + 0.006 * rng.normal(size=tgt.shape))[rng.permutation(4000)[:3200]]
    sim = rigid_pose(src, tgt)
    off = Rotation.from_matrix(sim.rotation) * rot.inv()
    assert np.rad2deg(off.magnitude()) < 8.0 / 5
    assert abs(sim.scale / 1.1 - 1) < 0.01
    same = rigid_pose(src[:1000], 1.1 * rot.apply(src[:1000]) + [0.1, -0.2, 0.05])
    assert np.rad2deg((Rotation.from_matrix(same.rotation) * rot.inv()).magnitude()) < 1e-6


def test_a_torus_stretched_in_its_frame_is_not_turned():
    """A torus stretched in z and squeezed in x, in one frame: its symmetric poses (turned
    180 degrees about any axis) fit it within 5 %, and the common frame keeps it (the
    pairs turned 178 degrees: median pair distance 1.31 against 0.19)."""
    trimesh = pytest.importorskip("trimesh")
    torus = trimesh.creation.torus(1.0, 0.35)
    src = mm.Shape(torus.vertices, faces=torus.faces)
    tgt = mm.Shape(torus.vertices * [0.8, 1.0, 1.5], faces=torus.faces)
    pairs = mm.match(src, tgt).pairs
    gap = np.linalg.norm(src.points[pairs[:, 0]] - tgt.points[pairs[:, 1]], axis=1)
    assert np.median(gap) <= 0.3  # 0.19 measured; turned 1.31


def test_a_turned_body_with_a_small_feature_is_still_found():
    """A cylinder with a knob turned 90 degrees about its axis: without the knob every
    turn about the axis fits alike, and the common frame's mean gap lies within
    _COMMON_GAP_3D of the best (1.13); its farthest node, the knob, does not (1.59), so
    the turn is kept and the knob lands on the knob (1.35 off when it was not)."""
    trimesh = pytest.importorskip("trimesh")
    from scipy.spatial.transform import Rotation

    mesh = trimesh.util.concatenate([trimesh.creation.cylinder(1, 2, sections=64),
                                     trimesh.creation.icosphere(2, 0.2).apply_translation(
                                         [1.12, 0, 0.3])])
    a = trimesh.sample.sample_surface_even(mesh, 800, seed=1)[0]
    b = trimesh.sample.sample_surface_even(mesh, 900, seed=2)[0]
    turn = Rotation.from_euler("z", 90, degrees=True)
    m = mm.match(a, turn.apply(b))
    knob = np.array([[1.12, 0.0, 0.3]])
    assert np.linalg.norm(m.similarity.apply(knob) - turn.apply(knob)) < 0.1  # 0.02


def test_refine_measures_once_and_reused_graphs():
    """``clouds.measures`` given to ``refine`` (what the large route measures once per
    pair) is the refinement as it measures them itself, bit for bit; with its graphs kept
    for ``_REGRAPH`` rounds at every level (``reuse``, the route above CHOICE_NODES) the
    landings stay within a small part of a spacing of those (measured: median 5e-7,
    largest 3e-6 target spacings, 3000 points) and as near the truth (0.055)."""
    from modalmorph.matching.clouds import measures

    src, tgt, truth = case(3000, 30, noise=0.01)
    s, t = mm.Shape(src), mm.Shape(tgt)
    x, y, z = s.normalized, t.normalized, t.to_normalized(truth)
    start = mm.align(x, z).apply(x)
    plain = refine(x, start, y, 60)
    assert np.array_equal(refine(x, start, y, 60, known=measures(x, y)), plain)
    kept = refine(x, start, y, 60, known=measures(x, y, reuse=True))
    h = t.spacing
    apart = np.linalg.norm(kept - plain, axis=1) / h
    assert np.median(apart) <= 0.01 and apart.max() <= 0.05

    def error(landed):
        return np.median(np.linalg.norm(landed - z, axis=1)) / h

    assert error(kept) <= error(plain) + 0.01


def test_a_cloud_onto_a_needle_is_refused_with_its_reason():
    """30 points of a sphere onto 300 of a needle (5 x 0.01 x 0.01): the pose's nearest-point
    rounds fitted a similarity to one source node and raised 'source_points all coincide'
    (review18); the matcher now says how few nodes land near the target."""
    from modalmorph.errors import ShapeError

    rng = np.random.default_rng(0)
    sphere = rng.standard_normal((30, 3))
    sphere /= np.linalg.norm(sphere, axis=1, keepdims=True)
    needle = rng.standard_normal((300, 3))
    needle = needle / np.linalg.norm(needle, axis=1, keepdims=True) * [5.0, 0.01, 0.01]
    with pytest.raises(ShapeError, match="land within"):
        mm.match(sphere, needle)

