"""Shapes of several contours from files and masks: rings, holes, labels, glyphs, NIfTI."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.path import Path as MplPath
from numpy.testing import assert_allclose

from modalmorph.core.quality import area
from modalmorph.errors import InputFileError
from modalmorph.io.images import MIN_HOLE_AREA, mask_shape


def ring(size=100, outer=30.0, inner=15.0, centre=(50.0, 45.0)):
    """A ring mask (H, W) bool: a disc of radius ``outer`` with a hole of ``inner``."""
    rows, cols = np.indices((size, size))
    r = np.hypot(cols - centre[0], rows - centre[1])
    return (r <= outer) & (r > inner)


def test_mask_shape_ring_outer_then_hole():
    shape = mask_shape(ring(), "ring", nodes=120)
    assert len(shape.sizes) == 2 and sum(shape.sizes) == 120
    outer, hole = (shape.points[s] for s in shape.slices)
    assert area(outer) > 0 > area(hole)  # outer counter-clockwise, hole clockwise in (x, y)
    # nodes shared by length (3 each, the rest in proportion): within one node of rounding
    length = np.array([np.linalg.norm(p - np.roll(p, 1, axis=0), axis=1).sum()
                       for p in (outer, hole)])
    assert np.all(np.abs(np.subtract(shape.sizes, 3) - 114 * length / length.sum()) <= 1)
    # sub-pixel boundaries at half level: radii within a pixel of the truth
    r_out = np.hypot(*(outer - [50.0, 45.0]).T)
    r_in = np.hypot(*(hole - [50.0, 45.0]).T)
    assert np.all(np.abs(r_out - 30.0) < 1.0) and np.all(np.abs(r_in - 15.0) < 1.0)
    inside = MplPath(outer).contains_points(hole)
    assert inside.all()  # the hole lies inside the outer boundary
    assert shape.frame.size == (100, 100) and shape.frame.y_down


def test_mask_shape_without_hole_is_one_contour():
    disc = ring(inner=-1.0)
    shape = mask_shape(disc, "disc")
    assert shape.contours is None and shape.m == 200


def test_mask_shape_noise_holes_ignored():
    mask = ring(inner=-1.0)
    mask[50, 50] = mask[40, 40:42] = False  # holes of 1 and 2 px: specks of noise
    assert mask_shape(mask, "specks").contours is None
    mask[55:58, 45:48] = False  # a 3 x 3 hole: area MIN_HOLE_AREA
    shape = mask_shape(mask, "hole")
    assert len(shape.sizes) == 2
    assert abs(area(shape.points[shape.slices[1]])) == pytest.approx(MIN_HOLE_AREA, rel=0.2)


def test_details_finer_than_the_node_spacing_are_resolved_or_dropped(caplog):
    """scikit-image's astronaut above Otsu's level: an outline and 45 holes. At the
    default 200 nodes, thin holes crossed themselves and holes a pixel inside the
    outline were cut by its chords (refused by every command); a contour crossing itself
    gets more nodes, the shorter of two crossing is dropped (logged), and the shape is
    valid."""
    from skimage import color, data, filters

    from modalmorph.core.quality import check_contours

    grey = color.rgb2gray(data.astronaut())
    mask = grey > filters.threshold_otsu(grey)
    with caplog.at_level("INFO"), pytest.warns(UserWarning, match="crossed another"):
        shape = mask_shape(mask, "astronaut")  # two holes a pixel inside: dropped, warned
    check_contours(shape, "astronaut")  # refused before
    assert "crossed themselves" in caplog.text  # the outline and a hole: more nodes
    assert 200 <= shape.m <= 300  # 241 measured: five contours given more nodes
    ring_shape = mask_shape(ring(), "ring", nodes=120)  # nothing finer: as shared
    assert sum(ring_shape.sizes) == 120


def test_mask_shape_label_image_picks_the_label():
    labels = np.zeros((90, 120), dtype=np.uint8)
    labels[10:40, 10:40] = 1
    labels[50:80, 60:110] = 2
    labels[20:30, 70:100] = 3
    shape = mask_shape(labels, "labels", label=2)
    x, y = shape.points.T
    assert x.min() == pytest.approx(59.5) and x.max() == pytest.approx(109.5)
    assert y.min() == pytest.approx(49.5) and y.max() == pytest.approx(79.5)
    with pytest.raises(InputFileError, match="labels: a label image .*label"):
        mask_shape(labels, "labels")
    with pytest.raises(InputFileError, match="no pixel has label 7"):
        mask_shape(labels, "labels", label=7)


def test_mask_shape_all_objects():
    labels = np.zeros((60, 100), dtype=bool)
    labels[10:30, 10:30] = labels[35:55, 50:90] = True
    labels[2, 95] = True  # a speck: not an object of "all"
    shape = mask_shape(labels, "two", choice="all")
    assert len(shape.sizes) == 2
    first, second = (shape.points[s] for s in shape.slices)
    assert first[:, 0].max() < 31 and second[:, 0].min() > 49  # reading order


@pytest.mark.parametrize("bad, match", [
    (np.zeros((4, 4, 2)), "2D"), (np.zeros((5, 5)), "no object"),
    (np.full((5, 5), np.nan), "non-finite")])
def test_mask_shape_bad_input(bad, match):
    with pytest.raises(InputFileError, match=f"frame 3: .*{match}"):
        mask_shape(bad, "frame 3")


# ------------------------------------------------------------------------------ NIfTI


def _ring_labels(t: int, size=64):
    """A label slice (X, Y): 1 = right ventricle blob, 2 = a myocardium ring contracting
    with ``t``, 3 = its blood pool."""
    i, j = np.indices((size, size))  # voxel indices (first axis i = x)
    r = np.hypot(i - 32.0, j - 30.0)
    outer, inner = 20.0 - 0.5 * t, 12.0 - 0.8 * t
    out = np.zeros((size, size), dtype=np.int16)
    out[r <= outer] = 2
    out[r <= inner] = 3
    out[(i < 8) & (j > 20) & (j < 40)] = 1
    return out


def _save_nifti(path, data, spacing):
    nib = pytest.importorskip("nibabel")
    spacing = (*spacing, 1.0)[:3] if len(spacing) < 3 else spacing
    image = nib.Nifti1Image(data, np.diag([*spacing, 1.0]))
    image.header.set_zooms(spacing[: data.ndim] + (1.0,) * (data.ndim - len(spacing)))
    image.header.set_xyzt_units("mm", "msec")
    nib.save(image, path)
    return path


def test_nifti_2d_t_frames_in_mm(tmp_path):
    from modalmorph.io import read_frames, read_shape

    volume = np.stack([_ring_labels(t) for t in range(4)], axis=-1)[:, :, None, :]
    path = _save_nifti(tmp_path / "cine.nii.gz", volume, (1.5, 1.5, 8.0))
    frames = read_frames(path, label=2)
    assert len(frames.shapes) == 4 and frames.names[1] == f"{path}[frame 1]"
    for t, shape in enumerate(frames.shapes):
        assert len(shape.sizes) == 2 and shape.frame.unit == "mm"
        outer, hole = (shape.points[s] for s in shape.slices)
        # voxel (i, j) -> (1.5 i, 1.5 j) mm; ring radii within a voxel (1.5 mm) of the truth
        assert_radii(outer, (48.0, 45.0), 1.5 * (20.0 - 0.5 * t), 1.5)
        assert_radii(hole, (48.0, 45.0), 1.5 * (12.0 - 0.8 * t), 1.5)
    with pytest.raises(InputFileError, match="2D\\+t volume of 4 frames"):
        read_shape(path, label=2)
    two_d = _save_nifti(tmp_path / "ed.nii", _ring_labels(0), (1.5, 1.5))
    shape = read_shape(two_d, label=3)  # the blood pool: one contour
    assert shape.contours is None
    assert_radii(shape.points, (48.0, 45.0), 18.0, 1.5)
    with pytest.raises(InputFileError, match="label image, label= the object"):
        read_shape(two_d)


def test_nifti_volume_is_read_as_its_object_surface_in_mm(tmp_path):
    """An (X, Y, Z) volume read as one shape is its object's surface: a closed mesh with
    outward faces, in mm (voxel (i, j, k) at (i dx, j dy, k dz)), on the object's boundary
    within a voxel, enclosing its volume within 8 % (5.5: the smoothing rounds a ball 5
    voxels thick); the largest object by default."""
    from modalmorph.io import read_shape

    spacing = np.array([0.8, 0.9, 2.0])
    i, j, k = np.indices((40, 44, 24))
    radii = np.array([12.0, 10.0, 5.0])  # voxels
    ball = ((i - 20) / radii[0]) ** 2 + ((j - 22) / radii[1]) ** 2 + ((k - 12) / radii[2]) ** 2
    labels = np.where(ball <= 1, 2, 0).astype(np.uint8)
    labels[1:4, 1:4, 1:4] = 2  # a speck: not the largest object
    labels[30:34, 2:5, 2:5] = 1
    path = _save_nifti(tmp_path / "organ.nii.gz", labels, tuple(spacing))
    shape = read_shape(path, label=2)
    assert shape.dim == 3 and shape.faces is not None and shape.frame.unit == "mm"
    rel = (shape.points / spacing - [20, 22, 12]) / radii  # back to the ball's own units
    assert np.abs(np.linalg.norm(rel, axis=1) - 1).max() < 1.0 / radii.min()
    a, b, c = (shape.points[shape.faces[:, n]] for n in range(3))
    enclosed = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6  # > 0: faces turn out
    assert abs(enclosed / (np.count_nonzero(ball <= 1) * spacing.prod()) - 1) < 0.08
    with pytest.raises(InputFileError, match="for a label image, label= the object's value"):
        read_shape(path)
    with pytest.raises(InputFileError, match="no object in the image: every pixel is at or"):
        read_shape(path, threshold=5)
    trailing = _save_nifti(tmp_path / "organ4d.nii", labels[..., None], tuple(spacing))
    assert_allclose(read_shape(trailing, label=2).points, shape.points)  # (X, Y, Z, 1)


def assert_radii(points, centre, radius, tol):
    r = np.hypot(*(points - centre).T)
    assert np.all(np.abs(r - radius) < tol), (r.min(), r.max(), radius)


def test_nifti_frames_of_different_grids_are_refused(tmp_path):
    from modalmorph.io import read_frames

    a = _save_nifti(tmp_path / "f0.nii", _ring_labels(0), (1.5, 1.5))
    b = _save_nifti(tmp_path / "f1.nii", _ring_labels(1), (1.2, 1.2))
    c = _save_nifti(tmp_path / "f2.nii", _ring_labels(1, size=70), (1.5, 1.5))
    with pytest.raises(InputFileError, match=f"{b}: pixel spacing .*first frame"):
        read_frames([a, b], label=2)
    with pytest.raises(InputFileError, match=f"{c}: the image is 70 x 70 px"):
        read_frames([a, c], label=2)
    volume = np.zeros((8, 8, 3, 2), dtype=np.uint8)
    bad = _save_nifti(tmp_path / "vol.nii", volume, (1.0, 1.0, 1.0))
    with pytest.raises(InputFileError, match="vol.nii: expected a 2D slice"):
        read_frames(bad)


def test_nifti_without_nibabel_says_how_to_install(tmp_path, monkeypatch):
    import sys

    from modalmorph.io import read_shape

    path = tmp_path / "a.nii"
    path.write_bytes(b"\0" * 400)
    monkeypatch.setitem(sys.modules, "nibabel", None)
    with pytest.raises(InputFileError, match=r"a.nii: reading NIfTI .*modalmorph\[nifti\]"):
        read_shape(path)


# ----------------------------------------------------------------- SVG and point files


def _glyph_svg(path, text):
    """An SVG of one <path> tracing ``text`` with matplotlib's TextPath (y flipped down)."""
    from matplotlib.textpath import TextPath

    glyph = TextPath((0, 0), text, size=100)
    letter = {MplPath.MOVETO: "M", MplPath.LINETO: "L", MplPath.CURVE3: "Q",
              MplPath.CURVE4: "C", MplPath.CLOSEPOLY: "Z"}
    d = []
    for verts, code in glyph.iter_segments():
        xy = verts.reshape(-1, 2) * [1.0, -1.0] + [0.0, 100.0]
        d.append(letter[code] + ("" if code == MplPath.CLOSEPOLY else
                                 " ".join(f"{x:.4f} {y:.4f}" for x, y in xy)))
    path.write_text('<svg xmlns="http://www.w3.org/2000/svg"><path d="'
                    + " ".join(d) + '"/></svg>')
    return path


@pytest.mark.parametrize("text, count", [("B", 3), ("o", 2), ("l", 1)])
def test_svg_glyph_gives_every_contour(tmp_path, text, count):
    from modalmorph.core.quality import check_contours
    from modalmorph.io import read_shape

    shape = read_shape(_glyph_svg(tmp_path / f"{text}.svg", text))
    assert len(shape.sizes) == count and shape.m == 200 and shape.closed
    check_contours(shape, text)  # each contour simple, none crossing another
    loops = [shape.points[s] for s in shape.slices]  # in the order drawn (the font's)
    k = int(np.argmax([abs(area(p)) for p in loops]))
    for j, hole in enumerate(loops):  # the holes inside the outline
        assert j == k or MplPath(loops[k]).contains_points(hole).all()


@pytest.mark.parametrize("ext", [".csv", ".tsv", ".txt", ".json", ".npz"])
def test_contours_written_and_read_back(tmp_path, ext):
    from modalmorph.io import read_shape, write_points

    shape = mask_shape(ring(), "ring", nodes=90)
    write_points(tmp_path / f"ring{ext}", shape)
    back = read_shape(tmp_path / f"ring{ext}")
    assert back.contours == shape.contours and len(back.sizes) == 2
    np.testing.assert_array_equal(back.points, shape.points)  # written exactly


def test_contour_column_rows_must_be_consecutive(tmp_path):
    from modalmorph.io import read_shape

    path = tmp_path / "bad.csv"
    path.write_text("x,y,contour\n0,0,0\n1,0,0\n1,1,0\n5,5,1\n6,5,1\n6,6,1\n0,1,0\n")
    with pytest.raises(InputFileError, match="rows of contour 0 are not consecutive"):
        read_shape(path)
    path.write_text('{"points": [[0, 0], [1, 0], [1, 1], [0, 1]], "contours": [2, 1.5]}')
    path = path.rename(tmp_path / "bad.json")
    with pytest.raises(InputFileError, match="contours must be a list of node counts"):
        read_shape(path)
    path.write_text('{"points": [[0, 0], [1, 0], [1, 1], [0, 1]], "contours": [3, 3]}')
    with pytest.raises(InputFileError, match="bad.json: contours must be node counts"):
        read_shape(path)


# ------------------------------------------------------------------------------ writers


def _ring_morph(nodes=60, steps=3):
    """What the writers read of a morph (source, shapes, loads, node energy): a ring
    growing by 10 % a step. A stand-in: the writers are tested apart from the dynamics."""
    from types import SimpleNamespace

    source = mask_shape(ring(), "ring", nodes=nodes)
    c = source.points.mean(axis=0)
    shapes = np.stack([c + (source.points - c) * 1.1**j for j in range(steps)])
    return SimpleNamespace(source=source, shapes=shapes, loads=np.zeros_like(shapes),
                           node_energy=np.zeros(shapes.shape[:2]))


def _loops(edges, shape):
    """Edges as sorted pairs; asserts each joins two nodes of one contour."""
    edges = np.asarray(edges)
    assert np.all(shape.contour_of[edges[:, 0]] == shape.contour_of[edges[:, 1]])
    return {tuple(sorted(e)) for e in edges.tolist()}


def test_vtk_and_ply_lines_are_the_contours(tmp_path):
    import meshio

    from modalmorph.io import write_step_meshes, write_vtk_series

    morph = _ring_morph()
    truth = _loops(morph.source.edges, morph.source)
    assert len(truth) == morph.source.m  # closed: as many segments as nodes
    write_vtk_series(morph, tmp_path / "vtk")
    vtu = meshio.read(tmp_path / "vtk" / "morph_0002.vtu")
    np.testing.assert_allclose(vtu.points[:, :2], morph.shapes[2])
    assert _loops(vtu.cells_dict["line"], morph.source) == truth
    (ply,) = write_step_meshes(morph, tmp_path / "ply", fmt="ply")[-1:]
    assert _loops(meshio.read(ply).cells_dict["line"], morph.source) == truth


def test_gltf_lines_are_the_contours(tmp_path):
    from modalmorph.io import write_gltf

    from .test_gltf import accessor, read_glb

    morph = _ring_morph()
    doc, blob = read_glb(write_gltf(morph, tmp_path / "ring.glb"))
    (prim,) = doc["meshes"][0]["primitives"]
    assert prim["mode"] == 1  # lines: pairs of indices, none joining the two loops
    pairs = accessor(doc, blob, prim["indices"]).reshape(-1, 2)
    assert _loops(pairs, morph.source) == _loops(morph.source.edges, morph.source)
    one = _ring_morph()
    one.source = one.source.contour(0)
    one.shapes = one.shapes[:, : one.source.m]
    doc, _ = read_glb(write_gltf(one, tmp_path / "one.glb"))
    assert doc["meshes"][0]["primitives"][0]["mode"] == 2  # one contour: a line loop


def test_result_files_keep_the_contours(tmp_path):
    import modalmorph as mm
    from modalmorph.io import read_shape, save_result

    ring_morph = _ring_morph(steps=2)
    source, target = ring_morph.source, ring_morph.source.with_points(ring_morph.shapes[1])
    pairs = np.c_[np.arange(source.m), np.arange(source.m)]  # the known correspondence
    morph = mm.morph(source, target, matching=pairs, max_steps=12)
    save_result(morph, tmp_path)
    final = read_shape(tmp_path / "final_shape.csv")
    assert final.contours == source.contours
    np.testing.assert_array_equal(final.points, morph.shapes[-1])
    with np.load(tmp_path / "shapes.npz") as data:
        assert tuple(data["contours"]) == source.contours


# ------------------------------------------------------------------------------ figures


def _pixels(fig):
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())[..., :3]


def _background_between_loops(ax, rgb, centre, radii):
    """Whether every pixel of the annulus ``radii`` (data units) about ``centre``, where
    no loop runs, is the axes' white, and the hole's centre too."""
    t = np.linspace(0, 2 * np.pi, 720, endpoint=False)
    r = np.linspace(*radii, 9)
    pts = np.concatenate([centre + np.c_[np.cos(t), np.sin(t)] * k for k in r] + [[centre]])
    xy = ax.transData.transform(pts)
    cols = np.round(xy[:, 0]).astype(int)
    rows = np.round(rgb.shape[0] - xy[:, 1]).astype(int)
    return np.all(rgb[rows, cols] > 240, axis=1)


def test_ring_figures_draw_separate_loops(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import modalmorph as mm
    from modalmorph.figures import animate, plot_matches, plot_shapes

    ring_morph = _ring_morph(steps=2)  # radii 30 and 15 about (50, 45), then 10 % larger
    source, target = ring_morph.source, ring_morph.source.with_points(ring_morph.shapes[1])
    pairs = np.c_[np.arange(source.m), np.arange(source.m)]
    morph = mm.morph(source, target, matching=pairs, max_steps=12)
    centre = source.points.mean(axis=0)
    # between the hole (r <= 16.5) and the outer loop (r >= 30) nothing is drawn: a
    # segment joining the two loops (the last node of one to the first of the next)
    # would cross this annulus; the hole's centre is background
    for draw in (lambda: plot_matches(source, target, pairs),
                 lambda: plot_shapes(morph, color_by=None)):
        ax = draw()
        blank = _background_between_loops(ax, _pixels(ax.figure), centre, (19.0, 27.0))
        assert blank.all(), f"{np.count_nonzero(~blank)} drawn pixels between the loops"
        bridge = mm.Shape(source.points)  # drawn as one contour: the check sees the bridge
        ax = plot_matches(bridge, bridge.with_points(target.points), pairs)
        assert not _background_between_loops(ax, _pixels(ax.figure), centre,
                                              (19.0, 27.0)).all()
        matplotlib.pyplot.close("all")
    animate(morph, tmp_path / "ring.gif", color_by=None)
    from PIL import Image

    with Image.open(tmp_path / "ring.gif") as gif:
        assert gif.n_frames == len(morph.shapes)


# ---------------------------------------------------------------------- command line


def _png(path, mask):
    from PIL import Image

    Image.fromarray(np.asarray(mask, dtype=np.uint8)).save(path)
    return path


def test_cli_morph_on_ring_masks_keeps_both_contours(tmp_path):
    from modalmorph.apps.cli import main
    from modalmorph.io import read_shape

    a = _png(tmp_path / "a.png", ring() * 255)
    b = _png(tmp_path / "b.png", ring(outer=32.0, inner=17.0) * 255)
    assert len(read_shape(a).sizes) == len(read_shape(b).sizes) == 2
    out = tmp_path / "out"
    assert main(["morph", str(a), str(b), "--out", str(out), "--nodes", "80", "-q",
                 "--no-figures", "--no-gif", "--max-steps", "4"]) in (0, 3)
    final = read_shape(out / "final_shape.csv")
    assert len(final.sizes) == 2 and final.sizes == read_shape(a, nodes=80).sizes


def test_cli_label_flag_and_bad_sequences(tmp_path, capsys):
    from modalmorph.apps.cli import main
    from modalmorph.io import read_shape

    labels = np.zeros((90, 120), dtype=np.uint8)
    labels[10:40, 10:40], labels[50:80, 60:110], labels[20:30, 70:100] = 1, 2, 3
    path = _png(tmp_path / "labels.png", labels)
    shape = read_shape(path, label=3)
    assert np.ptp(shape.points, axis=0) == pytest.approx([30.0, 10.0], abs=1.0)
    with pytest.raises(InputFileError, match="label= applies to images only"):
        read_shape(_save_csv(tmp_path / "a.csv"), label=2)
    small = _png(tmp_path / "small.png", (labels[:80] == 2) * 255)
    big = _png(tmp_path / "big.png", (labels == 2) * 255)
    assert main(["track", str(big), str(small), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{small}: the image is 120 x 80 px" in err[0]


def _save_csv(path):
    t = np.linspace(0, 2 * np.pi, 20, endpoint=False)
    np.savetxt(path, np.c_[np.cos(t), np.sin(t)], delimiter=",", header="x,y", comments="")
    return path


def test_csv_frames_with_contour_column(tmp_path):
    from modalmorph.io import read_frames

    rows = []
    for f in range(3):
        shape = mask_shape(ring(outer=30.0 - f, inner=15.0 - f), "ring", nodes=40)
        rows += [[f, *p, c] for p, c in zip(shape.points, shape.contour_of, strict=True)]
    path = tmp_path / "frames.csv"
    np.savetxt(path, rows, delimiter=",", header="frame,x,y,contour", comments="")
    frames = read_frames(path)
    assert len(frames.shapes) == 3 and all(len(s.sizes) == 2 for s in frames.shapes)
    np.testing.assert_allclose(frames.shapes[2].points, shape.points)


def test_track_files_keep_the_contours(tmp_path):
    import modalmorph as mm
    from modalmorph.io import save_track

    frames = [mask_shape(ring(outer=30.0 - f, inner=15.0 - 0.5 * f), "ring", nodes=60)
              for f in range(3)]
    result = mm.track(frames)
    save_track(result, tmp_path)
    with np.load(tmp_path / "track.npz") as data:
        assert tuple(data["contours"]) == frames[0].contours


def test_cli_morph_and_track_on_svg_o(tmp_path):
    from modalmorph.apps.cli import main
    from modalmorph.io import read_shape

    a = _glyph_svg(tmp_path / "a.svg", "o")
    b = tmp_path / "b.svg"  # the same glyph, 10 % wider
    b.write_text(a.read_text().replace("<path ", '<path transform="scale(1.1, 1)" '))
    for verb in ("morph", "track"):
        out = tmp_path / verb
        assert main([verb, str(a), str(b), "--out", str(out), "--nodes", "80", "-q",
                     "--no-figures", "--no-gif"]) in (0, 3)
    assert len(read_shape(tmp_path / "morph" / "final_shape.csv").sizes) == 2
    with np.load(tmp_path / "track" / "track.npz") as data:
        assert len(data["contours"]) == 2 and data["points"].shape[1] == 80


def test_resample_takes_a_shape_of_several_contours():
    """``modalmorph.resample`` on a Shape: every contour resampled, the count shared by
    length (more nodes than a contour had as well as fewer), frame and closure kept; a
    point set is refused (it raised a TypeError)."""
    import modalmorph as mm

    t = 2 * np.pi * np.arange(50) / 50
    c = np.c_[np.cos(t), np.sin(t)]
    ring_shape = mm.Shape(np.r_[2 * c, c[::-1]], contours=(50, 50))
    for n in (30, 300):
        r = mm.resample(ring_shape, n)
        assert r.m == n and abs(r.sizes[0] - 2 * r.sizes[1]) <= 3  # outer twice as long
        assert_allclose(np.linalg.norm(r.contour(1).points, axis=1), 1.0, atol=0.02)
    assert mm.resample(mm.Shape(c), 80).m == 80
    with pytest.raises(ValueError, match="ordered contours"):
        mm.resample(mm.Shape(c, ordered=False), 20)
