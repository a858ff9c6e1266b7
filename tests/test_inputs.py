"""What users see is what was computed (issue 21 B): conventions, inputs, output folders."""

import logging
import os
import re
import stat
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose

from modalmorph.apps.cli import flag_text
from modalmorph.apps.runs import read_pair
from modalmorph.io import DEFAULT_NODES, OUTPUT_MARKER, atomic_output_dir, read_shape, y_down
from modalmorph.options import ReadOptions

SRC = Path(__file__).resolve().parents[1] / "src"


@pytest.mark.skipif(os.name != "posix", reason="umask is POSIX")
@pytest.mark.parametrize("mask", [0o022, 0o077, 0o002])
def test_output_folders_follow_the_umask(tmp_path, mask):
    old = os.umask(mask)
    try:
        for final in (tmp_path / f"new{mask:o}", tmp_path / f"nested{mask:o}" / "out"):
            for _ in range(2):  # created, then replaced
                with atomic_output_dir(final) as tmp:
                    (tmp / OUTPUT_MARKER).write_text("x")
                assert stat.S_IMODE(final.stat().st_mode) == 0o777 & ~mask
                plain = tmp_path / "plain"  # what mkdir gives, the reference
                plain.mkdir()
                assert stat.S_IMODE(final.stat().st_mode) == stat.S_IMODE(plain.stat().st_mode)
                plain.rmdir()
    finally:
        os.umask(old)


# ------------------------------------------------------------------ shapes from files

def _glyph_p():
    """A "P": a straight stem of 2 vertices and a bowl of many (uneven spacing); not
    symmetric under y -> -y, so its mirror image is another shape."""
    t = np.linspace(np.pi / 2, -np.pi / 2, 30)
    bowl = np.c_[10 + 25 * np.cos(t), 55 + 25 * np.sin(t)]
    return np.vstack([[[0.0, 0.0]], [[0.0, 80.0]], bowl, [[10.0, 30.0]], [[10.0, 0.0]]])


def _write_csv(path, pts):
    np.savetxt(path, pts, delimiter=",", header="x,y", comments="")
    return path


def _write_svg(path, pts, height=100.0):
    """The same glyph in SVG: y down, so the y of its numbers is ``height - y``."""
    d = "M " + " L ".join(f"{x},{height - y}" for x, y in pts) + " Z"
    path.write_text(f'<svg xmlns="http://www.w3.org/2000/svg" width="100" height="{height}">'
                    f'<path d="{d}"/></svg>')
    return path


def test_uneven_polygons_are_resampled_by_arc_length(tmp_path, caplog):
    path = _write_csv(tmp_path / "p.csv", _glyph_p())
    with caplog.at_level(logging.INFO, logger="modalmorph.io"):
        shape = read_shape(path)
    assert shape.m == DEFAULT_NODES
    edges = np.linalg.norm(np.diff(np.vstack([shape.points, shape.points[:1]]), axis=0), axis=1)
    assert edges.max() < 1.01 * np.median(edges)  # even (chords across corners: shorter)
    assert "resampled from 34 to 200 nodes" in caplog.text and "nodes=N" in caplog.text
    assert read_shape(path, nodes=60).m == 60  # nodes= chooses
    circle = np.c_[np.cos(np.linspace(0, 6, 40)), np.sin(np.linspace(0, 6, 40))]
    assert read_shape(_write_csv(tmp_path / "c.csv", circle)).m == 40  # even: kept


def test_image_coordinates_written_to_csv_read_back_as_image_coordinates(tmp_path):
    """A morph's final shape from an SVG (y down) written to CSV says so on its first
    line and reads back y down, in the same unit: beside the SVG again it is not taken
    for a mirror image (the warning advised flip_y, which mirrored it)."""
    import modalmorph as mm
    from modalmorph.io.results import save_result

    svg = _write_svg(tmp_path / "p.svg", _glyph_p())
    shape = read_shape(svg)
    save_result(mm.morph(shape, shape), tmp_path / "out")
    written = tmp_path / "out" / "final_shape.csv"
    assert written.read_text().startswith("# y down (image coordinates), unit ")
    back = read_shape(written)
    assert y_down(back) and back.frame.unit == shape.frame.unit
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read_pair(written, svg, ReadOptions())
    csv = _write_csv(tmp_path / "p.csv", _glyph_p())  # the shapes lie in the target's frame
    save_result(mm.morph(read_shape(csv, flip_y=True), shape), tmp_path / "out2")
    assert y_down(read_shape(tmp_path / "out2" / "final_shape.csv"))
    save_result(mm.morph(shape, read_shape(csv)), tmp_path / "out3")
    assert not y_down(read_shape(tmp_path / "out3" / "final_shape.csv"))


@pytest.mark.parametrize("ext", [".csv", ".txt", ".npz", ".json"])
def test_every_shape_file_keeps_the_frame_it_was_written_in(tmp_path, ext):
    """Image coordinates written to any shape file read back y down in their unit, and
    a shape in y-up coordinates reads back y up (review16: only text files said it)."""
    import modalmorph as mm
    from modalmorph.io import write_points

    svg = read_shape(_write_svg(tmp_path / "p.svg", _glyph_p()))
    write_points(tmp_path / f"down{ext}", svg)
    back = read_shape(tmp_path / f"down{ext}")
    assert y_down(back) and back.frame.unit == svg.frame.unit
    np.testing.assert_array_equal(back.points, svg.points)
    write_points(tmp_path / f"up{ext}", mm.Shape(svg.points, closed=True))
    assert not y_down(read_shape(tmp_path / f"up{ext}"))


@pytest.mark.parametrize(("name", "body"), [
    ("f.json", '{"points": [[0, 0], [1, 0], [0, 1]], "frame": {"y_down": "yes"}}'),
    ("h.json", '{"points": [[0, 0], [1, 0], [0, 1]], "frame": {"y_down": true, "unit": 3}}')])
def test_a_frame_said_wrongly_is_named(tmp_path, name, body):
    (tmp_path / name).write_text(body)
    from modalmorph.errors import InputFileError

    with pytest.raises(InputFileError, match="y_down|frame|unit"):
        read_shape(tmp_path / name)


def test_a_json_frame_that_is_not_ours_is_left_alone(tmp_path):
    """Annotation exports write a frame's index under "frame": read as before (y up)."""
    for value in ("12", "null", "[true]"):
        (tmp_path / "f.json").write_text('{"points": [[0, 0], [1, 0], [0, 1]], "frame": '
                                         + value + "}")
        assert not y_down(read_shape(tmp_path / "f.json"))


def test_an_open_curve_in_a_point_file_is_said_and_read_open_when_told(tmp_path):
    """A centreline in a CSV was closed by a chord across it without a word (review17):
    it warns, naming --open-curves; open_curves=True reads it open; a closed outline
    with a long straight edge (a glyph's vertices) does not warn."""
    x = np.linspace(0.0, 60.0, 120)
    stroke = _write_csv(tmp_path / "vessel.csv", np.c_[x, 0.003 * x**2])
    with pytest.warns(UserWarning, match=r"vessel.csv: the contour is closed by an edge .* "
                      r"times its median edge: .*open_curves=True"):
        assert read_shape(stroke).closed
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert not read_shape(stroke, open_curves=True).closed
        assert not read_shape(stroke, closed=False).closed
        read_shape(_write_csv(tmp_path / "p.csv", _glyph_p()))
        # files that say, and outlines traced on a drawing, stay as they say (review18)
        assert read_shape(_write_svg(tmp_path / "p.svg", _glyph_p()), open_curves=True).closed
        (tmp_path / "c.json").write_text('{"points": [[0, 0], [1, 0], [0, 1]], "closed": true}')
        assert read_shape(tmp_path / "c.json", open_curves=True).closed
    from modalmorph.core.shape import ImageFrame
    from modalmorph.io import write_points

    write_points(tmp_path / "down.csv", np.c_[x, 0.003 * x**2], frame=ImageFrame())
    with pytest.warns(UserWarning, match="down.csv: the contour is closed by an edge"):
        read_shape(tmp_path / "down.csv")  # a point file in image coordinates says it too


def test_mixed_y_directions_warn_once_and_flip_y_mirrors(tmp_path):
    csv = _write_csv(tmp_path / "p.csv", _glyph_p())
    svg = _write_svg(tmp_path / "p.svg", _glyph_p())
    with pytest.warns(UserWarning) as caught:
        read_pair(csv, svg, ReadOptions())
    assert len(caught) == 1
    text = str(caught[0].message)
    assert str(csv) in text and str(svg) in text and "flip_y=True" in text
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        source, target = read_pair(csv, svg, ReadOptions(flip_y=True))
    assert y_down(source) and y_down(target)
    # the mirrored CSV is the SVG's glyph moved by (0, -height)
    assert_allclose(source.points, target.points - [0.0, 100.0], atol=1e-9)
    plain = read_shape(csv)
    assert not y_down(plain) and read_shape(csv, flip_y=True).points[0, 1] == \
        -plain.points[0, 1]


def test_ring_masks_give_the_outer_boundary_and_the_hole(tmp_path, caplog):
    from PIL import Image

    yy, xx = np.mgrid[:120, :120]
    r = np.hypot(xx - 60, yy - 60)
    Image.fromarray(((r < 40) & (r > 20)).astype(np.uint8) * 255).save(tmp_path / "ring.png")
    Image.fromarray((r < 40).astype(np.uint8) * 255).save(tmp_path / "disc.png")
    with caplog.at_level(logging.WARNING, logger="modalmorph.io"):
        assert read_shape(tmp_path / "disc.png").contours is None
        ring = read_shape(tmp_path / "ring.png")
    assert not caplog.records
    assert len(ring.sizes) == 2 and ring.m == 200
    radii = [np.hypot(*(ring.points[s] - 60.0).T).mean() for s in ring.slices]
    assert_allclose(radii, [40.0, 20.0], atol=1.0)  # boundaries at half level: within 1 px


def test_library_figures_follow_the_shapes_frame(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib import pyplot as plt

    from modalmorph import figures, morph
    from modalmorph.datasets import heart_shape

    heart = morph(heart_shape("diastole"), heart_shape("systole"), max_steps=1)
    assert figures.plot_shapes(heart).yaxis_inverted()  # pixels, y down: as `demo`
    bare = morph(heart.source.points, heart.target.points, max_steps=1)
    assert not figures.plot_shapes(bare).yaxis_inverted()  # plain numbers: y up
    plt.close("all")


# ---------------------------------------------------------------------- command line

def test_flag_text_names_flags():
    assert flag_text("pass a threshold, e.g. threshold=102 (Otsu's)") == \
        "pass a threshold, e.g. --threshold 102 (Otsu's)"
    assert flag_text("stopped at max_steps=3, far") == "stopped at --max-steps 3, far"
    assert flag_text("flip_y=True mirrors; remove_rigid=False.") == \
        "--flip-y mirrors; --no-remove-rigid."
    assert flag_text("x: threshold= applies") == "x: --threshold applies"
    assert flag_text("Shape(points, closed=False)") == "Shape(points, closed=False)"


def _cli(*args):
    env = {**os.environ, "PYTHONPATH": str(SRC)}
    return subprocess.run([sys.executable, "-m", "modalmorph", *map(str, args)],
                          capture_output=True, text=True, env=env, timeout=120)


def test_command_line_says_resampling_mixing_and_flags(tmp_path):
    csv = _write_csv(tmp_path / "p.csv", _glyph_p())
    svg = _write_svg(tmp_path / "p.svg", _glyph_p())
    run = _cli("morph", csv, svg, "--out", tmp_path / "out", "--no-figures", "--no-gif")
    assert run.returncode in (0, 3), run.stderr
    lines = run.stderr.splitlines()
    assert any("p.csv: uneven spacing" in x and "--nodes N" in x for x in lines), lines
    mixed = [x for x in lines if "y pointing up" in x]
    assert len(mixed) == 1 and "--flip-y" in mixed[0] and "flip_y" not in mixed[0]

    from PIL import Image

    yy, xx = np.mgrid[:80, :100]
    grey = (40 + 150 * (np.hypot(xx - 50, yy - 40) < 25) + (xx % 7)).astype(np.uint8)
    Image.fromarray(grey).save(tmp_path / "grey.png")
    run = _cli("morph", tmp_path / "grey.png", tmp_path / "grey.png", "--out", tmp_path / "o2")
    assert run.returncode == 2
    assert re.search(r"--threshold \d", run.stderr) and "threshold=" not in run.stderr
    helped = _cli("morph", "--help").stdout
    assert "Otsu" in helped and "default: Otsu" not in " ".join(helped.split())
