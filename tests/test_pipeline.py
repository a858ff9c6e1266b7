"""morph(): the paper's findings as trends, and the invariants of the method."""

import json
import re

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from modalmorph import FEModel, Matching, MatchOptions, MorphOptions, Shape, match, track
from modalmorph.datasets import load_hand, load_hands
from modalmorph.errors import OptionError, ShapeError
from modalmorph.options import parameters
from modalmorph.pipeline import MorphDivergedError, morph

from .conftest import self_intersections, sphere_points


def _hands(i, j, n=100):
    """Hands i and j sampled at the same n anatomical points: ground-truth pairs."""
    idx = np.linspace(0, 1590, n, endpoint=False).astype(int)
    return load_hand(i)[idx], load_hand(j)[idx], np.c_[np.arange(n), np.arange(n)]


def _rms(points):
    return np.sqrt(np.mean(np.sum((points - points.mean(axis=0)) ** 2, axis=1)))


def _rotate(points, angle, scale=1.0, shift=(0.0, 0.0)):
    c, s = np.cos(angle), np.sin(angle)
    return scale * points @ np.array([[c, -s], [s, c]]).T + np.asarray(shift)


@pytest.mark.parametrize("i, j, n", [(0, 3, 100), (1, 5, 100), (2, 7, 70), (4, 6, 250)])
def test_defaults_converge_on_hands(i, j, n):
    a, b, pairs = _hands(i, j, n)
    r = morph(a, b, matching=pairs)
    assert r.converged and r.steps <= 100
    assert r.mean_distance[-1] <= 0.01 * _rms(b)  # within 1% of the target's size
    assert np.isfinite(r.shapes).all() and np.isfinite(r.energy).all()
    assert all(self_intersections(s) == 0 for s in r.shapes)  # source and target are simple
    assert_allclose(r.shapes[0], a)  # step 0 is the source
    assert r.shapes.shape == (r.steps + 1, n, 2) and r.loads.shape == r.shapes.shape
    assert r.node_energy.shape == (r.steps + 1, n)


def test_full_resolution_hands_with_the_matcher():
    """The bundled outlines as they are (1590 nodes each, a reduced model) and the default
    matcher, which leaves runs of up to ~100 nodes unmatched: the arclength rule spreads
    them along the target (the paper's mean (20) folded them: thousands of crossings)."""
    a, b = load_hand(0), load_hand(7)
    assert self_intersections(a) == 0 and self_intersections(b) == 0
    r = morph(a, b)
    assert r.converged and r.steps <= 100
    assert r.mean_distance[-1] <= 0.01 * _rms(b)
    assert all(self_intersections(s) == 0 for s in r.shapes)


def test_a_contour_folded_through_itself_is_said(monkeypatch):
    """A hand onto another turned half round, the turn taken as straight node paths (as
    before co-rotation): the shape passes through a flattened one whose segments cross;
    the result counts them at every step and the message says so with the hint; the turn
    taken first, no step crosses."""
    import modalmorph.pipeline as pipeline

    monkeypatch.setattr(pipeline, "CO_ROTATE", 360.0)
    a, b, pairs = _hands(0, 1, 100)
    r = morph(a, _rotate(b, np.pi), matching=pairs)
    crossings = np.array([self_intersections(s) for s in r.shapes])
    # folds: every crossing but those closing a loop of tracing noise's size (LOOP_AREA)
    assert np.all(r.self_intersections <= crossings)
    assert_array_equal(r.self_intersections > 0, crossings > 0)
    assert r.self_intersections[0] == 0 and r.self_intersections.max() > 0
    assert "steps' contours cross themselves" in r.message
    turn = re.search(r"the pairs turn the source by (\d+) deg", r.message)
    assert turn and int(turn[1]) > 150
    turned = morph(a, _rotate(b, np.pi), matching=pairs, remove_rigid=True)
    assert not np.any(turned.self_intersections) and "cross" not in turned.message


def test_tracing_knots_of_the_source_are_no_fold():
    """The shared hands 1-6 carry 9-17 tiny knots as given (digitiser loops of under
    4e-5 of the squared size, accepted as simple); they ride along every step: the morph
    neither counts them as folds nor says that its steps cross themselves."""
    a, b = load_hand(1), load_hand(2)
    assert self_intersections(a) > 0  # as given
    r = morph(a, b)
    assert r.converged and not np.any(r.self_intersections), r.self_intersections
    assert "cross" not in r.message


@pytest.mark.parametrize("angle", [60, 120, 180])
def test_a_large_turn_is_taken_as_a_rigid_motion_along_the_steps(angle):
    """Pairs that turn the source by more than CO_ROTATE: the shapes turn with the steps
    instead of shrinking through straight paths (a half turn passed through a point): they
    keep their size, never cross, start at the source as given and end where the run of
    the turned source ends; the energies are that run's (no similarity strains)."""
    a, b, pairs = _hands(0, 1, 100)
    target = _rotate(b, np.radians(angle), shift=(40.0, -25.0))
    r = morph(a, target, matching=pairs)
    first = morph(a, target, matching=pairs, remove_rigid=True)  # the turn taken first
    assert r.co_rotation is not None and r.similarity is None
    assert r.co_rotation.angle == pytest.approx(angle, abs=10)
    assert_array_equal(r.shapes[0], a)
    assert_array_equal(r.shapes[-1], first.shapes[-1])
    assert_array_equal(r.energy, first.energy)
    assert r.converged and not np.any(r.self_intersections)
    size = np.array([_rms(s) for s in r.shapes])
    assert size.min() >= 0.97 * min(size[0], size[-1])  # straight paths: 0.04-0.88
    assert "taken as a rigid motion along the steps" in r.message
    assert_allclose(r.mean_distance[-1], first.mean_distance[-1])
    assert np.all(np.diff(r.mean_distance[1:]) <= 1e-9 * r.mean_distance[0])


def test_a_turn_alone_takes_one_step():
    """A shape onto itself turned half round: the turned source is already there (the run
    takes no step), and the turn still takes one: the last shape is the target."""
    a = _hands(0, 1, 100)[0]
    r = morph(a, _rotate(a, np.pi, shift=(5.0, 0.0)))
    assert r.steps == 1 and r.converged and r.message.startswith("converged after 1 steps")
    assert_array_equal(r.shapes[0], a)
    assert_allclose(r.shapes[1], _rotate(a, np.pi, shift=(5.0, 0.0)), atol=1e-9)


def test_co_rotation_edges():
    """Two pairs fix a 2D turn (co-rotated); free_motion='none', where a turn strains, is
    not co-rotated; pairs that all name one target node fix no similarity: the morph
    ends as before (the hint's similarity is left out), no error after the run."""
    u = np.linspace(0, 2 * np.pi, 60, endpoint=False)
    ellipse = np.c_[2 * np.cos(u), np.sin(u)]
    turned = _rotate(ellipse, np.radians(170))
    two = morph(ellipse, turned, matching=np.c_[[0, 30], [0, 30]], max_steps=30)
    assert two.co_rotation is not None
    size = np.array([_rms(s) for s in two.shapes])
    assert size.min() >= 0.9 * size[0]  # straight paths: 0.11 of it
    a, b, pairs = _hands(0, 1, 100)
    none = morph(a, _rotate(b, np.pi / 2), matching=pairs, free_motion="none", max_steps=10)
    assert none.co_rotation is None
    one = morph(ellipse, 1.2 * ellipse, matching=np.c_[np.arange(60), np.zeros(60, int)],
                max_steps=20)
    assert one.co_rotation is None and one.steps > 0


def test_node_energies_do_not_follow_the_pose():
    """The node energies (25) are those of the displacement less its similarity part: the
    target turned 20 deg gives nearly the map of 0 deg (correlation 0.97; 0.44 when the
    similarity part's +- terms were shared out), and they still add up to the energy."""
    a, b, pairs = _hands(0, 3, 100)
    still = morph(a, b, matching=pairs)
    turned = morph(a, _rotate(b, np.radians(20)), matching=pairs)
    assert turned.co_rotation is None  # straight paths
    for r in (still, turned):
        assert_allclose(r.node_energy.sum(axis=1), r.energy, rtol=1e-9, atol=1e-12)
    assert np.corrcoef(still.node_energy[-1], turned.node_energy[-1])[0, 1] > 0.95


def test_a_small_turn_keeps_straight_paths():
    """Pairs turning by less than CO_ROTATE morph as they always did: no co-rotation."""
    a, b, pairs = _hands(0, 1, 100)
    r = morph(a, _rotate(b, np.radians(10)), matching=pairs)
    assert r.co_rotation is None and "rigid motion" not in r.message


def test_result_fields_consistent():
    a, b, pairs = _hands(0, 3, 80)
    r = morph(a, b, matching=pairs)
    # (25) sums to (22); relative to the largest energy, round-off only
    assert_allclose(r.node_energy.sum(axis=1), r.energy, atol=1e-9 * r.energy.max())
    assert np.all(r.energy >= 0)  # global strain energy is never negative
    assert r.energy[0] == 0
    d = np.linalg.norm(r.shapes[:, pairs[:, 0]] - b[pairs[:, 1]], axis=2).mean(axis=1)
    assert_allclose(r.mean_distance, d, rtol=1e-12)
    assert r.options.k == 100.0 and r.stop_reason == "tolerance"


def test_identity_does_not_move():
    a, _, pairs = _hands(0, 0, 60)
    r = morph(a, a, matching=pairs)
    assert r.converged and r.steps == 0
    assert_allclose(r.energy, 0.0)
    assert_allclose(r.shapes[-1], a)


def test_larger_k_converges_in_fewer_steps():
    a, b, pairs = _hands(1, 5, 100)
    slow = morph(a, b, matching=pairs, k=10, tol=0.01)
    fast = morph(a, b, matching=pairs, k=60, tol=0.01)
    assert fast.converged and fast.steps < slow.steps


def test_explicit_with_large_k_diverges():
    a, b, pairs = _hands(0, 3, 100)
    stable = morph(a, b, matching=pairs, scheme="explicit", k=1, max_steps=30, tol=0.02)
    assert np.isfinite(stable.shapes).all()
    with pytest.raises(MorphDivergedError, match="diverged at step .* explicit") as info:
        morph(a, b, matching=pairs, scheme="explicit", k=30)
    assert info.value.steps > 0


def test_two_thirds_of_modes_slower_and_less_accurate():
    a, b, pairs = _hands(2, 7, 70)
    full = morph(a, b, matching=pairs, tol=0.002, max_steps=60)
    part = morph(a, b, matching=pairs, modes=2 / 3, tol=0.002, max_steps=60)
    assert part.resolved.modes == round(2 / 3 * 140)
    assert part.steps > full.steps
    assert part.mean_distance[-1] > full.mean_distance[-1]


@pytest.mark.parametrize("angle", [0.4, 0.8])  # 23 deg: straight paths; 46: co-rotated
def test_removing_rigid_part_takes_fewer_steps(angle):
    a, b, pairs = _hands(0, 3, 100)
    moved = _rotate(b, angle, scale=1.3, shift=(50, -20))
    plain = morph(a, moved, matching=pairs)
    rigid = morph(a, moved, matching=pairs, remove_rigid=True)
    assert rigid.similarity is not None and rigid.converged
    if plain.co_rotation is None:
        assert rigid.steps < plain.steps
    else:  # the same run, shown in the source's frame
        assert rigid.steps == plain.steps


def test_numerical_damping_with_delta():
    """delta > 0.5 damps: with the paper's light damping the oscillation about the target
    dies out sooner."""
    a, b, pairs = _hands(0, 3, 80)
    opts = dict(matching=pairs, damping=(0.005, 0.03), max_steps=60, tol=1e-6,
                equilibrium_tol=0)
    plain = morph(a, b, **opts)
    damped = morph(a, b, delta=0.9, alpha=(0.9 + 0.5) ** 2 / 4, **opts)  # (16)
    late = slice(30, None)
    assert damped.mean_distance[late].mean() < plain.mean_distance[late].mean()


def test_units_do_not_matter():
    a, b, pairs = _hands(1, 5, 80)
    r1 = morph(a, b, matching=pairs)
    r2 = morph(1000 * a, 1000 * b, matching=pairs)
    assert r1.steps == r2.steps
    assert_allclose(r2.mean_distance, 1000 * r1.mean_distance, rtol=1e-6)
    assert_allclose(r2.energy, r1.energy, rtol=1e-6, atol=1e-12)


def test_unmatched_nodes_follow_neighbours():
    a, b, pairs = _hands(0, 3, 120)
    keep = pairs[::3]  # a third of the nodes matched, as in the paper's heart (43 of 70)
    r = morph(a, b, matching=keep)
    assert r.converged
    # unmatched nodes end near the target contour too (within 2% of its size)
    from scipy.spatial import cKDTree

    dense = load_hand(3)
    gap, _ = cKDTree(dense).query(r.shapes[-1])
    assert gap.mean() < 0.02 * _rms(b)
    assert self_intersections(r.shapes[-1]) == 0


def test_open_contour():
    a, b, pairs = _hands(0, 3, 100)
    from modalmorph import Shape

    src = Shape(a[10:90], closed=False)
    tgt = Shape(b[10:90], closed=False)
    part = np.c_[np.arange(5, 75, 2), np.arange(5, 75, 2)]  # ends unmatched
    r = morph(src, tgt, matching=part)
    assert r.converged and np.isfinite(r.shapes).all()


def test_3d_point_sets(rng):
    a = sphere_points(150, rng, radii=(1.0, 0.8, 0.6))
    b = a * np.array([1.2, 0.7, 0.9]) + 0.1 * np.sin(3 * a[:, [1, 2, 0]])
    pairs = np.c_[np.arange(150), np.arange(150)][::2]  # half matched: neighbour rule in 3D
    r = morph(a, b, matching=pairs)
    assert r.converged
    assert r.shapes.shape[1:] == (150, 3)
    assert np.all(r.energy >= 0)


def test_a_curve_written_in_3d_is_morphed_as_a_curve(rng):
    """A contour written with a z column (x, y, 0), ordered or not, is not called reached
    while it is 3-8 units from the target: it morphs onto the target's curve."""
    t = np.linspace(0, 2 * np.pi, 80, endpoint=False)
    a = np.c_[30 * np.cos(t), 20 * np.sin(t), np.zeros_like(t)]
    b = np.c_[25 * np.cos(t) + 3, 24 * np.sin(t), np.zeros_like(t)]
    order = rng.permutation(80)
    for src, tgt in ((a, b), (Shape(a, ordered=False), Shape(b, ordered=False)),
                     (a[order], b[order])):
        r = morph(src, tgt)
        gap = np.linalg.norm(r.shapes[-1][:, None] - b[None], axis=2).min(axis=1)
        assert r.converged and r.steps >= 3
        assert gap.mean() < 0.1 * 2 * np.pi * 25 / 80  # a tenth of the target's spacing


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"k": 0}, r"k must be a number in \[1e-06, 1e\+06\]"),
        ({"dt": -1}, r"dt must be a number in \[1e-06, 1e\+06\]"),
        ({"alpha": 0.1, "delta": 0.5}, "not unconditionally stable"),
        ({"delta": 0.4}, "not unconditionally stable"),
        ({"scheme": "magic"}, "scheme must be"),
        ({"modes": 1.5}, r"modes must be None \(all\), a count >= 1 or a fraction in \(0, 1\]"),
        ({"modes": 10_000}, "modes must be None, a count between 1 and 200"),
        ({"matching": np.zeros((0, 2), int)}, "no node is matched"),
        ({"matching": np.array([[0, 500]])}, "out of range"),
        ({"damping": (0.1, -0.1)}, "damping must be a ratio"),
        ({"max_steps": 0}, "max_steps must be an integer >= 1"),
        ({"unmatched": "nearest"}, "unmatched must be one of"),
    ],
)
def test_bad_options(kwargs, match):
    a, b, pairs = _hands(0, 3, 100)
    kwargs.setdefault("matching", pairs)
    with pytest.raises(ValueError, match=match):
        morph(a, b, **kwargs)


def test_dimension_mismatch(rng):
    a, _, pairs = _hands(0, 3, 50)
    with pytest.raises(ValueError, match="same dimension, got 2D and 3D"):
        morph(a, sphere_points(50, rng), matching=pairs)


def _dense_hands(n):
    """Hands 0 and 3 at the same n contour parameters: ground-truth pairs."""
    return load_hands((0, 3), n)


def test_reduced_model_for_large_contours():
    a, b = _dense_hands(2000)
    pairs = np.c_[np.arange(2000), np.arange(2000)]
    r = morph(a, b, matching=pairs, model_nodes=200)
    assert r.resolved.model_nodes == 200 and r.converged
    assert r.mean_distance[-1] <= 0.01 * _rms(b)
    # local energies spread from the model nodes still add up to the global energy
    assert_allclose(r.node_energy.sum(axis=1), r.energy, atol=1e-9 * r.energy.max())
    assert np.all(r.energy >= 0)


def test_reduced_model_close_to_full():
    a, b = _dense_hands(240)
    pairs = np.c_[np.arange(240), np.arange(240)]
    # (a reduced model is loaded node by node: compare with the full one loaded so)
    full = morph(a, b, matching=pairs, model_nodes=300, max_steps=6, tol=1e-9, loads="nodal")
    reduced = morph(a, b, matching=pairs, model_nodes=160, max_steps=6, tol=1e-9)
    # the same physics on a coarser mesh: intermediate shapes within 2.5% of the size
    # (measured 2.0%: the damping's rate follows the springs of each model)
    gap = np.linalg.norm(full.shapes - reduced.shapes, axis=2).max()
    assert gap < 0.025 * _rms(b)


@pytest.mark.parametrize("n, model_nodes", [(100, 300), (600, 200)])
def test_initial_displacement_moves_faster(n, model_nodes):
    """(17)-(18): larger c_x and c_v give larger first steps, as the paper reports."""
    a, b = _dense_hands(n)
    pairs = np.c_[np.arange(n), np.arange(n)]
    rest = morph(a, b, matching=pairs, model_nodes=model_nodes)
    quick = morph(a, b, matching=pairs, c_x=0.5, c_v=0.5, model_nodes=model_nodes)
    assert_allclose(quick.shapes[0], a)  # step 0 is still the source
    assert quick.mean_distance[1] < rest.mean_distance[1]
    assert quick.converged and quick.steps <= rest.steps


# ---------------------------------------------------------------------- options


def test_options_object_same_as_keywords():
    a, b, pairs = _hands(0, 3, 80)
    kw = dict(k=60, dt=0.2, damping=(0.1, 0.4), modes=2 / 3, loads="nodal", max_steps=40)
    by_keywords = morph(a, b, matching=pairs, **kw)
    by_object = morph(a, b, matching=pairs, options=MorphOptions(**kw))
    # the object and keyword overrides on top of it: later wins, field by field
    mixed = morph(a, b, matching=pairs, options=MorphOptions(k=1.0, dt=0.2), k=60,
                  damping=(0.1, 0.4), modes=2 / 3, loads="nodal", max_steps=40)
    for r in (by_object, mixed):
        assert_array_equal(r.shapes, by_keywords.shapes)  # bitwise: the same computation
        assert r.options == by_keywords.options == MorphOptions(**kw)
        assert parameters(r) == parameters(by_keywords)


def test_overrides_routed_to_the_matcher():
    a, b, _ = _hands(0, 3, 60)
    r = morph(a, b, rotation="none", match_sigma=1.5, method="global", max_steps=2)
    assert r.match_options == MatchOptions(rotation="none", sigma=1.5, method="global")
    assert_array_equal(r.matching.pairs,
                       match(a, b, rotation="none", sigma=1.5, method="global").pairs)
    assert r.match_options.rotation == "none" and r.match_options.sigma == 1.5
    assert parameters(r)["max_steps"] == 2 and r.options.max_steps == 2
    # a MatchOptions as the matching: computed with those, overrides on top
    given = morph(a, b, matching=MatchOptions(method="global"), rotation="none",
                  match_sigma=1.5, max_steps=2)
    assert_array_equal(given.matching.pairs, r.matching.pairs)


@pytest.mark.parametrize("kwargs, match", [
    ({"kk": 1}, "unknown morph option 'kk'"),
    ({"options": {"k": 1}}, "options must be a MorphOptions, got dict"),
    ({"rotation": "sideways"}, "rotation must be one of auto, free, none"),
])
def test_unknown_or_bad_override_refused(kwargs, match):
    a, b, pairs = _hands(0, 3, 40)
    with pytest.raises(OptionError, match=match):
        morph(a, b, **kwargs)


def test_given_pairs_are_a_matching_that_saves_reports_plots_and_tracks(tmp_path):
    """A morph from given pairs crosses every seam whole: its matching is a Matching of
    method "given", and the result saves, renders as HTML, plots and tracks."""
    from modalmorph.apps.report import write_html
    from modalmorph.figures import save_figures
    from modalmorph.io import save_result

    a = np.linspace(0.0, 2.0 * np.pi, 40, endpoint=False)
    circle, ellipse = np.c_[np.cos(a), np.sin(a)], np.c_[1.6 * np.cos(a), np.sin(a)]
    r = morph(circle, ellipse, matching=np.c_[0:40, 0:40][::-1])
    assert isinstance(r.matching, Matching) and r.matching.method == "given"
    assert_array_equal(r.matching.pairs, np.c_[0:40, 0:40])  # sorted by source node
    assert r.converged and r.stop_reason == "tolerance" and r.distance <= r.tolerance
    save_result(r, tmp_path / "out")
    assert json.loads((tmp_path / "out" / "result.json").read_text())["matches"] == 40
    assert "<html" in write_html(r, tmp_path / "r.html").read_text()[:400].lower()
    assert {p.name for p in save_figures(r, tmp_path / "fig", formats=("png",))} >= {
        "matches.png", "energy.png"}
    tr = track([circle, ellipse, 1.1 * ellipse])
    assert all(m.matching.method == "given" for m in tr.morphs)  # nearest pairs
    write_html(tr, tmp_path / "t.html")


def test_given_pairs_must_belong_to_the_objects():
    a = np.linspace(0.0, 2.0 * np.pi, 20, endpoint=False)
    circle = np.c_[np.cos(a), np.sin(a)]
    with pytest.raises(ShapeError, match="out of range for 20 source and 20 target"):
        morph(circle, circle, matching=np.c_[0:21, 0:21])
    with pytest.raises(ShapeError, match="found for 10 source and 10 target nodes"):
        morph(circle, circle, matching=match(circle[:10], circle[:10]))


def test_results_print_in_a_few_lines():
    a = np.linspace(0.0, 2.0 * np.pi, 30, endpoint=False)
    circle = np.c_[np.cos(a), np.sin(a)]
    r = morph(circle, 1.2 * circle, remove_rigid=True)
    tr = track([circle, 1.1 * circle])
    for obj in (r, r.matching, r.similarity, r.source, r.resolved, tr,
                FEModel(circle).modes()):
        text = repr(obj)
        assert len(text.splitlines()) <= 10 and len(text) <= 800, text
        assert "array(" not in text  # no array dumped


def test_a_source_too_coarse_for_the_target_is_said():
    """A 4-node square onto a 200-node circle converges by the stop test's allowance for
    its node count (the circle drawn through 4 nodes is 1.9 units from itself), and the
    message says so with the remedy; the same square resampled to 200 nodes is not
    said to be coarse."""
    t = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    circle = 10 * np.c_[np.cos(t), np.sin(t)]
    u = np.pi / 4 + np.linspace(0, 2 * np.pi, 4, endpoint=False)
    square = 11 * np.c_[np.cos(u), np.sin(u)]
    r = morph(square, circle)
    found = re.search(r"the source has 4 nodes for the target's 200: .* lies ([\d.]+) input "
                      r"units from itself", r.message)
    assert r.converged and found and 1.5 < float(found[1]) < 2.5, r.message
    assert "resample the source" in r.message
    from modalmorph.core.shape import resample
    assert "resample" not in morph(resample(square, 200), circle).message


def test_a_source_short_of_a_finer_target_is_told_to_resample():
    """DejaVu Sans 'f' as TextPath gives its vertices (22) onto the Serif 'f' (33): the
    run stops short (the stem's foot of 2 nodes cannot cover a 6-node serif) and the
    message says to resample the source; resampled to the target's count it converges."""
    from matplotlib.font_manager import FontProperties
    from matplotlib.textpath import TextPath

    from modalmorph.core.shape import resample

    def outline(face):
        polygons = TextPath((0, 0), "f", size=10, prop=FontProperties(family=face))
        p = max(polygons.to_polygons(), key=len)[:-1]
        return p[np.r_[True, np.any(np.diff(p, axis=0) != 0, axis=1)]]

    a, b = outline("DejaVu Sans"), outline("DejaVu Serif")
    r = morph(a, b)
    assert not r.converged and len(a) < len(b)
    assert f"the source has {len(a)} nodes for the target's {len(b)}: " in r.message
    assert "resample" in r.message  # with the stop test's allowance: the coarse clause
    assert morph(resample(a, len(b)), b).converged


def test_a_coarse_source_converged_within_the_allowance_is_told():
    """cmr10's 'I' of 28 vertices onto its 'T' of 55, each resampled at its own count:
    converged within the stop test's allowance for a coarser source (6 tolerances: the
    serifs cut), and the message says so; at the target's count nothing is said."""
    from matplotlib.font_manager import FontProperties, findfont
    from matplotlib.textpath import TextPath

    from modalmorph.core.shape import resample

    def outline(ch):
        prop = FontProperties(fname=findfont(FontProperties(family="cmr10")))
        p = max(TextPath((0, 0), ch, size=100, prop=prop).to_polygons(), key=len)[:-1]
        return resample(p, len(p))

    a, b = outline("I"), outline("T")
    r = morph(a, b)
    assert r.converged and len(a) <= 0.8 * len(b)
    assert f"the source has {len(a)} nodes for the target's {len(b)}: drawn" in r.message
    assert "resample" not in morph(resample(a, len(b)), b).message
