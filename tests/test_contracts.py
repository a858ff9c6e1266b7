"""The library's contracts under hypothesis (issue 27): booleans are booleans, a Matching
belongs to the shapes it is given, no NaN leaves a result silently, and the file limits
of :mod:`modalmorph.io.limits` read headers right."""

import io
import json
import zipfile

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import modalmorph as mm
from modalmorph.core.shape import Shape
from modalmorph.errors import OptionError, ShapeError
from modalmorph.io.limits import LimitError, Limits, check_json, check_npz, json_depth
from modalmorph.options import MorphOptions

SLOW = settings(max_examples=25, deadline=None,
                suppress_health_check=[HealthCheck.too_slow])
# not booleans, though Python reads most of them as true or false
NOT_BOOL = st.one_of(st.text(max_size=5), st.integers(), st.floats(allow_nan=False),
                     st.lists(st.booleans(), max_size=2))


def _polygon(m: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.sort(rng.uniform(0, 2 * np.pi, m)) + np.arange(m) * 1e-3  # distinct angles
    r = 1 + 0.3 * rng.uniform(-1, 1, m)
    return np.c_[r * np.cos(t), r * np.sin(t)]


@given(value=NOT_BOOL)
def test_shape_flags_must_be_booleans(value):
    with pytest.raises(ShapeError, match="closed must be True or False"):
        Shape(_polygon(8, 0), closed=value)
    with pytest.raises(ShapeError, match="ordered must be True or False"):
        Shape(_polygon(8, 0), ordered=value)


@given(value=NOT_BOOL)
def test_option_flags_must_be_booleans(value):
    with pytest.raises(OptionError, match="remove_rigid must be true or false"):
        MorphOptions(remove_rigid=value)


def test_no_is_refused_by_name():
    with pytest.raises(ShapeError, match="closed must be True or False, got 'no'"):
        Shape(_polygon(8, 0), closed="no")
    with pytest.raises(OptionError, match="remove_rigid"):
        mm.morph(_polygon(8, 0), _polygon(8, 1), remove_rigid="no")


@SLOW
@given(m=st.integers(8, 30), k=st.integers(3, 29), seed=st.integers(0, 2**16))
def test_a_matching_belongs_to_its_shapes(m, k, seed):
    a, b = _polygon(m, seed), _polygon(m, seed + 1)
    if k >= m:
        return
    with pytest.raises(ShapeError, match="the matching was found for"):
        mm.morph(a, b, matching=mm.Matching.given(np.c_[0:k, 0:k], k, k), max_steps=1)


@SLOW
@given(m=st.integers(4, 12), segments=st.integers(1, 16), seed=st.integers(0, 2**16))
def test_track_strains_are_finite_or_refused_by_name(m, segments, seed):
    a = _polygon(m, seed)
    frames = [a, a * 1.05, a * 1.1]
    try:
        result = mm.track(frames, segments=segments, morph_options={"max_steps": 5})
    except OptionError as exc:
        assert str(exc).startswith("segments:")
        assert segments > 1
        return
    for name in ("segment_strain", "edge_strain", "strain", "energy", "distance"):
        assert np.all(np.isfinite(getattr(result, name))), name


def test_square_with_six_segments_says_how_many_fit():
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1.0]])
    with pytest.raises(OptionError, match=r"segments: .* 4 edges, too few for 6 .* "
                                          r"segments=4 or fewer"):
        mm.track([square, square * 1.1])


def test_multilevel_on_a_triangle_names_the_solver():
    tri = np.array([[0, 0], [1, 0], [0, 1.0]])
    with pytest.raises(ValueError, match="solver='multilevel' needs at least 6 nodes"):
        mm.morph(tri, tri * 1.1, solver="multilevel")


# ------------------------------------------------------------------ io.limits


JSON_LEAVES = st.one_of(st.integers(), st.text(max_size=3, alphabet="[]{}\"\\ab"),
                       st.booleans(), st.none())
JSON_VALUES = st.recursive(JSON_LEAVES, lambda inner: st.one_of(
    st.lists(inner, max_size=3),
    st.dictionaries(st.text(max_size=3, alphabet="[]{}\"ab"), inner, max_size=3)),
    max_leaves=20)


def _depth(obj) -> int:
    if isinstance(obj, list):
        return 1 + max((_depth(v) for v in obj), default=0)
    if isinstance(obj, dict):
        return 1 + max((_depth(v) for v in obj.values()), default=0)
    return 0


@given(obj=JSON_VALUES)
def test_json_depth_is_read_without_parsing(obj):
    text = json.dumps(obj)
    assert json_depth(text) == _depth(obj)
    assert json_depth(text.encode()) == _depth(obj)


def test_check_json_refuses_deep_and_large_text():
    with pytest.raises(LimitError, match="max_json_depth") as info:
        check_json("[" * 40 + "]" * 40)
    assert info.value.limit == "max_json_depth"
    with pytest.raises(LimitError, match="max_file_bytes"):
        check_json("[]" * 10, limits=Limits(max_file_bytes=10))


@SLOW
@given(shape=st.lists(st.integers(0, 6), min_size=1, max_size=3),
       dtype=st.sampled_from(["<f8", "<i4", "|u1", "<c16"]))
def test_check_npz_reads_the_shapes_from_the_headers(tmp_path_factory, shape, dtype):
    path = tmp_path_factory.mktemp("npz") / "a.npz"
    arrays = {"points": np.zeros(shape, dtype), "other": np.ones(3)}
    np.savez_compressed(path, **arrays)
    assert check_npz(path) == {k: v.shape for k, v in arrays.items()}
    small = Limits(max_array_bytes=max(1, np.zeros(shape, dtype).nbytes + 23))
    with pytest.raises(LimitError, match="max_array_bytes"):
        check_npz(path, small)


def test_check_npz_refuses_what_is_not_an_npz(tmp_path):
    path = tmp_path / "a.npz"
    path.write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="not an NPZ"):
        check_npz(path)
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        archive.writestr("points.npy", b"\x93NUMPY garbage")
    path.write_bytes(buffer.getvalue())
    with pytest.raises(ValueError, match="not a NumPy array file"):
        check_npz(path)
