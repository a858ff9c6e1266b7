"""Outputs for graphics programs: the animated glTF 2.0 file (io/gltf.py) and the per-step
meshes (io/steps.py), read back by parsing the GLB container, with pygltflib, and with
meshio (what wrote the meshes)."""

import json
import struct

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

import modalmorph as mm
from modalmorph.apps.runs import Settings, morph_files
from modalmorph.io import write_gltf, write_step_meshes
from modalmorph.options import OutputOptions


def torus(nu=16, nv=8, a=1.0, b=0.4):
    """A closed triangle surface with no poles: (points (nu nv, 3), faces (2 nu nv, 3))."""
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, nu, endpoint=False),
                       np.linspace(0, 2 * np.pi, nv, endpoint=False), indexing="ij")
    points = np.c_[((a + b * np.cos(v)) * np.cos(u)).ravel(),
                   ((a + b * np.cos(v)) * np.sin(u)).ravel(), (b * np.sin(v)).ravel()]
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    p, q = i * nv + j, ((i + 1) % nu) * nv + j
    r, s = i * nv + (j + 1) % nv, ((i + 1) % nu) * nv + (j + 1) % nv
    faces = np.r_[np.c_[p.ravel(), q.ravel(), s.ravel()], np.c_[p.ravel(), s.ravel(), r.ravel()]]
    return points, faces


@pytest.fixture(scope="module")
def surface_morph():
    points, faces = torus()
    target = points * [1.3, 0.9, 1.1] + [0.2, 0.0, 0.1]
    src = mm.Shape(points, faces=faces)
    pairs = np.c_[np.arange(len(points)), np.arange(len(points))]
    return mm.morph(src, mm.Shape(target, faces=faces), matching=pairs, max_steps=12)


def read_glb(path):
    """(JSON document, binary buffer) of a GLB file, its container checked."""
    data = path.read_bytes()
    magic, version, length = struct.unpack_from("<4sII", data, 0)
    assert (magic, version, length) == (b"glTF", 2, len(data))
    json_len, json_type = struct.unpack_from("<II", data, 12)
    assert json_type == 0x4E4F534A and json_len % 4 == 0
    doc = json.loads(data[20:20 + json_len])
    bin_len, bin_type = struct.unpack_from("<II", data, 20 + json_len)
    assert bin_type == 0x004E4942 and bin_len % 4 == 0
    blob = data[28 + json_len:28 + json_len + bin_len]
    assert doc["buffers"][0]["byteLength"] <= bin_len
    return doc, blob


def accessor(doc, blob, index):
    """An accessor's data as a numpy array (count, components)."""
    acc = doc["accessors"][index]
    view = doc["bufferViews"][acc["bufferView"]]
    dtype = {5126: np.float32, 5125: np.uint32}[acc["componentType"]]
    width = {"SCALAR": 1, "VEC3": 3}[acc["type"]]
    start = view["byteOffset"] + acc.get("byteOffset", 0)
    assert start % 4 == 0  # components aligned to their size
    out = np.frombuffer(blob, dtype=dtype, count=acc["count"] * width, offset=start)
    return out.reshape(acc["count"], width)


def test_gltf_surface_morph_targets_and_animation(surface_morph, tmp_path):
    """One morph target per step, the last one the last step's displacement; accessor
    min/max those of their data; the animation's weights pick step k at time k / fps."""
    r = surface_morph
    path = write_gltf(r, tmp_path / "morph.glb", fps=10.0)
    doc, blob = read_glb(path)
    assert doc["asset"]["version"] == "2.0"
    (prim,) = doc["meshes"][0]["primitives"]
    assert prim["mode"] == 4  # triangles
    base = accessor(doc, blob, prim["attributes"]["POSITION"])
    assert_allclose(base, r.shapes[0], rtol=1e-6, atol=1e-6)  # float32
    faces = accessor(doc, blob, prim["indices"]).reshape(-1, 3)
    assert_array_equal(faces, r.source.faces)
    assert len(prim["targets"]) == r.steps == len(doc["meshes"][0]["weights"])
    last = accessor(doc, blob, prim["targets"][-1]["POSITION"])
    assert_allclose(last, r.shapes[-1] - r.shapes[0], rtol=1e-6, atol=1e-6)  # float32
    for index in [prim["attributes"]["POSITION"]] + [t["POSITION"] for t in prim["targets"]]:
        data, acc = accessor(doc, blob, index), doc["accessors"][index]
        assert_array_equal(acc["min"], data.min(axis=0))
        assert_array_equal(acc["max"], data.max(axis=0))
    (sampler,) = doc["animations"][0]["samplers"]
    times = accessor(doc, blob, sampler["input"]).ravel()
    assert_allclose(times, np.arange(r.steps + 1) / 10.0, rtol=1e-6)
    weights = accessor(doc, blob, sampler["output"]).reshape(r.steps + 1, r.steps)
    assert_array_equal(weights[0], 0)  # the source
    assert_array_equal(weights[1:], np.eye(r.steps))  # step k: target k - 1 at weight 1
    channel = doc["animations"][0]["channels"][0]
    assert channel["target"] == {"node": 0, "path": "weights"}


def test_gltf_reads_back_with_pygltflib(surface_morph, tmp_path):
    pygltflib = pytest.importorskip("pygltflib")
    r = surface_morph
    gltf = pygltflib.GLTF2().load(str(write_gltf(r, tmp_path / "m.glb")))
    prim = gltf.meshes[0].primitives[0]
    assert len(prim.targets) == r.steps
    acc = gltf.accessors[prim.attributes.POSITION]
    assert acc.count == r.source.m and acc.type == "VEC3"
    blob = gltf.binary_blob()
    last = gltf.accessors[prim.targets[-1]["POSITION"]]
    view = gltf.bufferViews[last.bufferView]
    d = np.frombuffer(blob, np.float32, last.count * 3, view.byteOffset).reshape(-1, 3)
    assert_allclose(d, r.shapes[-1] - r.shapes[0], rtol=1e-6, atol=1e-6)  # float32


def test_gltf_contour_and_point_cloud(tmp_path):
    """A 2D contour is a line loop in z = 0; a 3D point cloud is points; a shape morphed
    into itself (no step) has no morph target and no animation."""
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    circle = np.c_[np.cos(t), np.sin(t)]
    r = mm.morph(circle, circle * [1.4, 0.8], max_steps=5)
    doc, blob = read_glb(write_gltf(r, tmp_path / "c.glb"))
    prim = doc["meshes"][0]["primitives"][0]
    assert prim["mode"] == 2 and "indices" not in prim  # line loop
    end = accessor(doc, blob, prim["attributes"]["POSITION"]) + accessor(
        doc, blob, prim["targets"][-1]["POSITION"])
    assert_allclose(end[:, :2], r.shapes[-1], atol=1e-5)  # float32
    assert_array_equal(end[:, 2], 0)
    rng = np.random.default_rng(0)
    cloud = rng.normal(size=(30, 3))
    same = mm.morph(cloud, cloud, matching=np.c_[np.arange(30), np.arange(30)])
    doc, _ = read_glb(write_gltf(same, tmp_path / "p.glb"))
    prim = doc["meshes"][0]["primitives"][0]
    assert prim["mode"] == 0  # points
    if same.steps == 0:
        assert "targets" not in prim and "animations" not in doc


@pytest.mark.parametrize("fmt", ["ply", "obj"])
def test_step_meshes_read_back_with_meshio(surface_morph, tmp_path, fmt):
    meshio = pytest.importorskip("meshio")
    r = surface_morph
    paths = write_step_meshes(r, tmp_path, fmt=fmt)
    assert [p.name for p in paths] == [f"morph_{j:04d}.{fmt}" for j in range(r.steps + 1)]
    for j in (0, r.steps):
        mesh = meshio.read(paths[j])
        assert_allclose(mesh.points, r.shapes[j], rtol=1e-12)
        assert_array_equal(mesh.cells_dict["triangle"], r.source.faces)


def test_step_meshes_refuse_an_unknown_format(surface_morph, tmp_path):
    with pytest.raises(ValueError, match="fmt must be one of ply, obj, got 'stl'"):
        write_step_meshes(surface_morph, tmp_path, fmt="stl")


def test_morph_files_writes_gltf_and_meshes(tmp_path):
    """``modalmorph morph --gltf --meshes ply`` writes morph.glb and meshes/."""
    meshio = pytest.importorskip("meshio")
    points, faces = torus(12, 6)
    bent = points * [1.2, 1.0, 0.9] + 0.5 * points[:, :1] ** 2 * [0, 0, 1]
    for name, p in (("a.ply", points), ("b.ply", bent)):
        meshio.write(tmp_path / name, meshio.Mesh(p, [("triangle", faces.astype(np.int32))]))
    settings = Settings(output=OutputOptions(figures=False, gif=False, gltf=True,
                                             meshes="ply"))
    run = morph_files(tmp_path / "a.ply", tmp_path / "b.ply", tmp_path / "out", settings)
    names = {p.relative_to(tmp_path / "out").as_posix() for p in run.files}
    assert "morph.glb" in names
    assert {f"meshes/morph_{j:04d}.ply" for j in range(run.result.steps + 1)} <= names
    doc, _ = read_glb(tmp_path / "out" / "morph.glb")
    assert run.result.steps > 0
    assert len(doc["meshes"][0]["primitives"][0]["targets"]) == run.result.steps


@pytest.mark.parametrize("output", [OutputOptions(gltf=True), OutputOptions(meshes="obj")])
def test_track_refuses_gltf_and_meshes(tmp_path, output):
    from modalmorph.apps.runs import track_files
    from modalmorph.errors import OptionError

    with pytest.raises(OptionError, match="track writes no VTK, glTF, per-step meshes"):
        track_files(tmp_path / "frames", tmp_path / "out", Settings(output=output))


def test_meshes_option_is_checked():
    from modalmorph.errors import OptionError

    with pytest.raises(OptionError, match="meshes must be one of none, ply, obj, got 'stl'"):
        OutputOptions(meshes="stl")
