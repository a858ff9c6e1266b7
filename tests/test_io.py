"""Reading shapes from every supported format, writing results, atomic output."""

import json
import logging
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

import modalmorph
from modalmorph.core.shape import ImageFrame, Shape
from modalmorph.errors import InputFileError, OptionError
from modalmorph.io import (
    DEFAULT_NODES,
    OUTPUT_MARKER,
    READERS,
    SUPPORTED_EXTENSIONS,
    RawShape,
    atomic,
    atomic_output_dir,
    atomic_write,
    read_shape,
    remove_leftovers,
    save_result,
    write_points,
)
from modalmorph.options import ReadOptions, parameters

# A small non-symmetric 2D contour (a pentagon-ish outline) and a 3D point set.
SQUARE = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.5, 1.5], [0.0, 1.0]])
CLOUD = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.5], [0.0, 1.0, 0.25], [1.0, 1.0, 1.0]])


def _err(path):
    """A pattern for a message that starts with this file's name."""
    return "^" + re.escape(str(path)) + ": "


# -- text, arrays, JSON ------------------------------------------------------------------


@pytest.mark.parametrize("ext", ["csv", "tsv", "txt", "npy", "npz", "json"])
@pytest.mark.parametrize("points", [SQUARE, CLOUD], ids=["2d", "3d"])
def test_write_read_round_trip(tmp_path, ext, points):
    path = tmp_path / f"shape.{ext}"
    write_points(path, points)
    shape = read_shape(path)
    assert_array_equal(shape.points, points)  # written in shortest round-trip form
    assert shape.closed
    assert shape.ordered == (points.shape[1] == 2)
    assert not list(tmp_path.glob(".*"))  # no temporary left behind


def test_text_written_with_a_header(tmp_path):
    write_points(tmp_path / "a.csv", SQUARE)
    assert (tmp_path / "a.csv").read_text().splitlines()[0] == "x,y"
    write_points(tmp_path / "a.tsv", CLOUD)
    assert (tmp_path / "a.tsv").read_text().splitlines()[0] == "x\ty\tz"


@pytest.mark.parametrize("text", [
    "0,0\n2,0\n2,1\n0.5,1.5\n0,1\n",
    "x,y\n0,0\n2,0\n2,1\n0.5,1.5\n0,1\n",
    '"x","y"\n"0","0"\n2,0\n2,1\n0.5,1.5\n0,1\n',
    "X, Y\n0, 0\n2, 0\n\n2, 1\n0.5, 1.5\n0, 1\n",
    "# outline\n0\t0\n2\t0\n2\t1\n0.5\t1.5\n0\t1\n",
    "0 0\n2   0\n2 1\n  0.5 1.5\n0 1\n",
    "x;y\n0;0\n2;0\n2;1\n0,5;1,5\n0;1\n",  # semicolons with decimal commas
    "\ufeffx,y\r\n0,0\r\n2,0\r\n2,1\r\n0.5,1.5\r\n0,1\r\n",  # BOM and CRLF
    "id,y,x,label\n1,0,0,a\n2,0,2,b\n3,1,2,c\n4,1.5,0.5,d\n5,1,0,e\n",  # named columns
    "0,0\n2,0\n2,1\n0.5,1.5\n0,1\n0,0\n",  # closed contour written with its first node
    "0,0\n2,0\n2,0\n2,1\n0.5,1.5\n0.5,1.5\n0.5,1.5\n0,1\n0,0\n",  # doubled nodes
    "0,0\n2,0\n2,1\n0.5,1.5\n0,1\n0,0\n0,0\n",  # the closing node doubled
], ids=["plain", "header", "quoted", "spaces", "tabs", "whitespace", "semicolon", "bom",
        "named", "repeated-first", "doubled", "closing-doubled"])
def test_text_variants(tmp_path, text):
    path = tmp_path / "shape.csv"
    path.write_text(text, encoding="utf-8")
    assert_array_equal(read_shape(path).points, SQUARE)


def test_text_extensions_read_the_same(tmp_path):
    for ext, sep in [("tsv", "\t"), ("txt", " "), ("csv", ";")]:
        path = tmp_path / f"s.{ext}"
        path.write_text("\n".join(sep.join(map(str, row)) for row in CLOUD))
        shape = read_shape(path)
        assert_array_equal(shape.points, CLOUD)
        assert shape.dim == 3 and not shape.ordered


def test_npz_key_and_json_object(tmp_path):
    np.savez(tmp_path / "one.npz", anything=SQUARE)  # the only array
    assert_array_equal(read_shape(tmp_path / "one.npz").points, SQUARE)
    np.savez(tmp_path / "two.npz", points=SQUARE, other=np.zeros(3))
    assert_array_equal(read_shape(tmp_path / "two.npz").points, SQUARE)

    path = tmp_path / "open.json"
    path.write_text(json.dumps({"points": SQUARE.tolist(), "closed": False}))
    shape = read_shape(path)
    assert not shape.closed
    assert read_shape(path, closed=True).closed  # the argument wins over the file

    faces = [[0, 1, 2], [1, 3, 2]]
    path.write_text(json.dumps({"points": CLOUD.tolist(), "faces": faces}))
    assert_array_equal(read_shape(path).faces, faces)


def test_shape_round_trip_keeps_topology(tmp_path):
    surface = Shape(CLOUD, faces=[[0, 1, 2], [1, 3, 2]])
    contour = Shape(SQUARE, closed=False)
    for ext in ("json", "npz"):
        back = read_shape(_written(tmp_path / f"s.{ext}", surface))
        assert_array_equal(back.faces, surface.faces)
        assert not read_shape(_written(tmp_path / f"c.{ext}", contour)).closed


def _written(path, points):
    write_points(path, points)
    return path


def test_nodes_resamples_2d_contours(tmp_path):
    path = _written(tmp_path / "s.csv", SQUARE)
    shape = read_shape(path, nodes=40)
    assert shape.m == 40
    assert_allclose(shape.points[0], SQUARE[0])  # arc-length resampling keeps node 0
    edges = np.linalg.norm(np.diff(np.vstack([shape.points, shape.points[:1]]), axis=0),
                           axis=1)
    # equal spacing by arc length; chords cut corners, so allow a corner's worth
    assert edges.max() - edges.min() < 0.05


# -- SVG -------------------------------------------------------------------------------

_SVG = '<svg xmlns="http://www.w3.org/2000/svg" width="200" height="200">{}</svg>'
_K = 0.5522847498  # cubic Bézier approximation of a quarter circle


def _svg(tmp_path, body, name="shape.svg"):
    path = tmp_path / name
    path.write_text(_SVG.format(body))
    return path


def _dist_to_polygon(points, vertices, closed=True):
    """Distance from each point to the nearest edge of a polygon."""
    a = vertices
    b = np.roll(vertices, -1, axis=0) if closed else vertices[1:]
    a = a[: len(b)]
    ab = b - a
    t = np.clip(np.einsum("pkd,kd->pk", points[:, None] - a, ab) / np.sum(ab**2, axis=1),
                0, 1)
    nearest = a + t[..., None] * ab
    return np.linalg.norm(points[:, None] - nearest, axis=2).min(axis=1)


@pytest.mark.parametrize("d", [
    "M 60 100 A 40 40 0 0 1 140 100 A 40 40 0 0 1 60 100 Z",
    "m60,100a40,40 0 1,1 80,0a40,40 0 1,1 -80,0z",
    "M100 60 C{a} 60 140 {b} 140 100 S{a} 140 100 140 S60 {a} 60 100 S{b} 60 100 60Z",
], ids=["arcs", "relative-arcs", "cubic"])
def test_svg_circle(tmp_path, d):
    d = d.format(a=100 + 40 * _K, b=100 - 40 * _K)
    shape = read_shape(_svg(tmp_path, f'<g><path fill="none" d="{d}"/></g>'))
    assert shape.m == DEFAULT_NODES and shape.closed
    radius = np.linalg.norm(shape.points - [100, 100], axis=1)
    # on the circle: exact for arcs, within the Bézier approximation's 0.03 % otherwise
    assert_allclose(radius, 40, rtol=4e-4)
    spacing = np.linalg.norm(np.diff(shape.points, axis=0), axis=1)
    assert_allclose(spacing, 2 * np.pi * 40 / DEFAULT_NODES, rtol=1e-3)  # by arc length


def test_svg_polygon_polyline_and_lines(tmp_path):
    verts = np.array([[10, 10], [90, 10], [90, 60], [50, 90], [10, 60]], dtype=float)
    pts = " ".join(f"{x},{y}" for x, y in verts)
    forms = {
        "polygon": f'<polygon points="{pts}"/>',
        "absolute": '<path d="M10 10 L90 10 L90 60 L50 90 L10 60 Z"/>',
        "relative": '<path d="m10 10 h80 v50 l-40 30 -40-30z"/>',
        "implicit": '<path d="M10,10 90,10 90,60 50,90 10,60 z"/>',
        "hv": '<path d="M10 10 H90 V60 L50 90 L10 60 V10"/>',
    }
    for label, body in forms.items():
        shape = read_shape(_svg(tmp_path, body, f"{label}.svg"), nodes=64)
        assert shape.m == 64 and shape.closed, label
        assert _dist_to_polygon(shape.points, verts).max() < 1e-9, label
        assert_allclose(shape.points[0], [10, 10], err_msg=label)

    shape = read_shape(_svg(tmp_path, f'<polyline points="{pts}"/>'), nodes=30)
    assert not shape.closed
    assert_allclose(shape.points[[0, -1]], verts[[0, -1]])
    assert _dist_to_polygon(shape.points, verts, closed=False).max() < 1e-9


def test_svg_quadratic_and_transform(tmp_path):
    # a lens: two quadratic arcs (Q then T mirrored), inside translate + scale
    body = ('<defs><path d="M0 0 L1 1"/></defs>'
            '<g transform="translate(10, 20)"><path transform="scale(2)" '
            'd="M0 0 Q 20 20 40 0 T 80 0 L 80 -10 Z"/></g>')
    shape = read_shape(_svg(tmp_path, body), nodes=100)
    t = np.linspace(0, 1, 2001)[:, None]
    first = (1 - t) ** 2 * [0, 0] + 2 * t * (1 - t) * [20, 20] + t**2 * [40, 0]
    second = (1 - t) ** 2 * [40, 0] + 2 * t * (1 - t) * [60, -20] + t**2 * [80, 0]
    truth = np.vstack([first, second, [[80, -10]]]) * 2 + [10, 20]
    dist = np.linalg.norm(shape.points[:, None] - truth[None], axis=2).min(axis=1)
    on_curves = dist[shape.points[:, 1] > 20.5]  # leave out the closing straight edges
    assert on_curves.max() < 0.1  # 2001 samples of a curve about 200 long
    assert_allclose(shape.points[0], [10, 20])


def test_svg_rotation_and_matrix(tmp_path):
    square = "M20 10 L30 10 L30 20 L20 20 Z"
    body = f'<g transform="rotate(90, 10, 10)"><path d="{square}"/></g><path d="M0 0 H1 V1"/>'
    shape = read_shape(_svg(tmp_path, body), nodes=4)  # the first path, rotated about (10, 10)
    assert_allclose(shape.points, [[10, 20], [10, 30], [0, 30], [0, 20]], atol=1e-12)
    body = f'<path transform="matrix(0 1 -1 0 0 0) translate(1)" d="{square}"/>'
    shape = read_shape(_svg(tmp_path, body, "matrix.svg"), nodes=4)
    assert_allclose(shape.points, [[-10, 21], [-10, 31], [-20, 31], [-20, 21]], atol=1e-12)


def test_svg_several_subpaths_are_contours(tmp_path):
    path = _svg(tmp_path, '<path d="M0 0 H10 V10 Z M20 20 H30 V30 Z"/>')
    shape = read_shape(path, nodes=12)
    assert shape.sizes == (6, 6) and shape.closed
    assert shape.contour(0).points.max() <= 10 and shape.contour(1).points.min() >= 20
    mixed = _svg(tmp_path, '<path d="M0 0 H10 V10 Z M20 20 H30 V30"/>', "mixed.svg")
    with pytest.raises(ValueError, match="mixes closed and open contours"):
        read_shape(mixed)
    stray = _svg(tmp_path, '<path d="M10,10 L90,10 L90,90 Z M 20 20 L 20 20"/>', "stray.svg")
    assert read_shape(stray).sizes == (200,)  # a subpath of no length draws nothing


def test_svg_circle_ellipse_rect_and_viewbox(tmp_path):
    body = ('<g transform="translate(100, 0)"><circle cx="0" cy="100" r="40"/></g>'
            '<rect width="5" height="5"/>')
    shape = read_shape(_svg(tmp_path, body, "circle.svg"))
    assert shape.closed
    # chords of 128 samples per quarter circle sag by 1 - cos(pi / 512) = 1.9e-5 of r
    assert_allclose(np.linalg.norm(shape.points - [100, 100], axis=1), 40, rtol=3e-5)
    shape = read_shape(_svg(tmp_path, '<ellipse cx="50" cy="40" rx="30" ry="20"/>',
                            "ellipse.svg"))
    assert_allclose(np.hypot((shape.points[:, 0] - 50) / 30, (shape.points[:, 1] - 40) / 20),
                    1, rtol=5e-5)  # on the ellipse, up to chord sag as above
    verts = np.array([[10, 20], [40, 20], [40, 30], [10, 30]], dtype=float)
    shape = read_shape(_svg(tmp_path, '<rect x="10" y="20" width="30" height="10"/>',
                            "rect.svg"), nodes=80)
    assert shape.closed and _dist_to_polygon(shape.points, verts).max() < 1e-9
    # a viewBox scales the drawing to width x height; the shape stays in user units
    path = tmp_path / "viewbox.svg"
    path.write_text('<svg xmlns="http://www.w3.org/2000/svg" width="10cm" height="5cm" '
                    'viewBox="0 0 100 50"><rect x="10" y="20" width="30" height="10"/></svg>')
    shape = read_shape(path, nodes=80)
    assert _dist_to_polygon(shape.points, verts).max() < 1e-9


@pytest.mark.parametrize("before, passed", [
    ('<path d="M0 0h200v200H0z" fill="none"/>', 1),  # an icon's box (Material icons)
    ('<rect width="200" height="200" style="fill:#ffffff"/>', 1),  # a page's background
    ('<rect width="200" height="200" style="fill:none;opacity:0"/>'  # matplotlib's
     '<path d="M 20 20 L 180 20 L 180 180 Z" style="fill:#000;opacity:0"/>', 2),
    ('<rect width="200" height="200" style="fill:#ffffff"/>'  # a plot's white axes patch
     '<rect x="10" y="10" width="180" height="180" style="fill:#ffffff"/>', 2),
    ('<rect x="10" y="10" width="180" height="180" fill="white"/>', 1),  # on a bare page
    ('<path d="M 10 190 L 190 190" stroke="black"/>'  # an axis and a slanted tick
     '<polyline points="0,0 10,5 20,10" stroke="black"/>', 2),
    ('<rect x="90" y="90" width="5" height="5" fill="red"/>', 0),  # drawn, but smaller
])
def test_svg_reads_the_largest_shape_drawn(tmp_path, before, passed, caplog):
    """The outline read is the largest that draws a shape: not one drawn invisibly, nor a
    first one covering the page while others follow, nor one filled in the page's colour
    with no stroke, nor a straight line; the choice is logged."""
    path = _svg(tmp_path, before + '<circle cx="100" cy="100" r="40"/>', "page.svg")
    with caplog.at_level(logging.INFO, logger="modalmorph"):
        shape = read_shape(path)
    assert np.allclose(np.linalg.norm(shape.points - 100, axis=1), 40, rtol=1e-4)
    assert f"({'the largest'}): <circle> 80 x 80; {passed} drawing none passed over" in (
        caplog.text)


def test_svg_white_on_a_dark_page_shows(tmp_path):
    """Filled white on a dark background is drawn: read, past the background only."""
    path = _svg(tmp_path, '<rect width="200" height="200" fill="navy"/>'
                          '<rect x="20" y="20" width="160" height="160" fill="white"/>'
                          '<circle cx="100" cy="100" r="40"/>')
    shape = read_shape(path, nodes=80)
    assert np.allclose(shape.points.min(axis=0), 20) and np.allclose(shape.points.max(axis=0),
                                                                      180)


def test_svg_choice_is_logged_in_user_units(tmp_path, caplog):
    """The logged size of the outline read is in the file's user units (the results'),
    not in the viewport's px: a page of 100 mm drawn with a viewBox of 100 units."""
    path = tmp_path / "mm.svg"
    path.write_text('<svg xmlns="http://www.w3.org/2000/svg" width="100mm" height="80mm" '
                    'viewBox="0 0 100 80"><rect width="40" height="30" x="5" y="5"/>'
                    '<circle cx="80" cy="60" r="3"/></svg>')
    with caplog.at_level(logging.INFO, logger="modalmorph"):
        shape = read_shape(path)
    assert_allclose(np.ptp(shape.points, axis=0), [40, 30], rtol=1e-6)
    assert "<rect> 40 x 30;" in caplog.text


def test_svg_object_choice(tmp_path):
    """object= picks an outline as for images: a number in the order drawn, the one
    centred nearest the page's centre, or all of them as contours."""
    body = ('<rect x="0" y="0" width="10" height="10"/>'
            '<circle cx="100" cy="100" r="20"/><rect x="140" y="10" width="50" height="50"/>')
    path = _svg(tmp_path, body)
    assert_allclose(read_shape(path, nodes=40).points.max(axis=0), [190, 60])  # largest
    assert_allclose(read_shape(path, nodes=40, object=1).points.max(axis=0), [10, 10])
    centre = read_shape(path, object="center").points
    assert_allclose(np.linalg.norm(centre - 100, axis=1), 20, rtol=1e-4)
    every = read_shape(path, nodes=90, object="all")
    assert len(every.sizes) == 3 and every.closed
    with pytest.raises(ValueError, match="object=4, but the file draws 3 outline"):
        read_shape(path, object=4)
    off_grid = _svg(tmp_path, '<circle cx="30" cy="30" r="10"/><rect x="50" y="50" '
                    'width="30" height="20"/>', "off.svg")  # its arc ends 4e-15 from its start
    both = read_shape(off_grid, nodes=90, object="all")
    assert len(both.sizes) == 2 and both.closed
    mixed = _svg(tmp_path, '<rect width="9" height="9"/><polyline points="20,0 30,9 40,0"/>',
                 "mixed.svg")
    with pytest.raises(ValueError, match="mixes closed and open contours"):
        read_shape(mixed, object="all")


@pytest.mark.parametrize("body, message", [
    ('<line x1="0" y1="0" x2="1" y2="1"/><text>M0 0</text>',
     "no <path>, <polygon>, <polyline>, <circle>, <ellipse> or <rect>"),
    ('<path d="M 0 0 L 10 x"/>', "<path>: malformed path data at character 11 of d: 'x'"),
    ('<path d="M 0 0 L 10 10 junk"/>', "<path>: malformed path data at character 14"),
    ('<path d="M 0 0 L 1 2 3"/>', "<path>: malformed path data"),
    ('<path d="L 0 0 L 10 0"/>', "must start with M"),
    ('<path d="M 0 0"/>', "has no segments"),
    ('<polygon points="0,0 1"/>', "<polygon>: cannot read '1' in 'points'"),
    ('<path d="M0 0 L1 0 L1 1" transform="wobble(3)"/>', "cannot read 'wobble(3)' in 'transform'"),
    ('<g transform="skewX(5) bend(1)"><path d="M0 0 L1 0 L1 1"/></g>', "'bend(1)'"),
])
def test_svg_errors(tmp_path, body, message):
    path = _svg(tmp_path, body)
    with pytest.raises(ValueError, match=_err(path) + ".*" + re.escape(message)):
        read_shape(path)


def test_svg_not_xml(tmp_path):
    path = tmp_path / "bad.svg"
    path.write_text("<svg><path d='M0 0'></svg")
    with pytest.raises(ValueError, match=_err(path) + "not a valid SVG"):
        read_shape(path)


# -- images ------------------------------------------------------------------------------


def _ellipse_mask(shape=(120, 160), centre=(70.0, 50.0), axes=(40.0, 25.0)):
    """A filled ellipse: centre and semi-axes given as (x, y) = (column, row)."""
    rows, cols = np.mgrid[: shape[0], : shape[1]]
    return ((cols - centre[0]) / axes[0]) ** 2 + ((rows - centre[1]) / axes[1]) ** 2 <= 1


def _area(points):
    x, y = points.T
    return 0.5 * (np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def _check_ellipse(shape, mask, centre=(70.0, 50.0), axes=(40.0, 25.0)):
    assert shape.dim == 2 and shape.closed
    assert_allclose(_area(shape.points), mask.sum(), rtol=0.02)  # contour through edges
    assert_allclose(shape.points.mean(axis=0), centre, atol=0.5)  # nodes evenly spaced
    extent = shape.points.max(axis=0) - shape.points.min(axis=0)
    assert_allclose(extent, 2 * np.array(axes), atol=1.5)  # x = column, y = row


@pytest.mark.parametrize("ext", ["png", "tif", "bmp"])
def test_image_mask(tmp_path, ext):
    from PIL import Image

    mask = _ellipse_mask()
    path = tmp_path / f"mask.{ext}"
    Image.fromarray(mask.astype(np.uint8) * 255).save(path)
    shape = read_shape(path)
    assert shape.m == DEFAULT_NODES
    _check_ellipse(shape, mask)
    assert read_shape(path, nodes=50).m == 50


def test_image_dark_object_one_bit_and_holes(tmp_path):
    from PIL import Image

    mask = _ellipse_mask()
    hole = _ellipse_mask(axes=(10.0, 8.0))
    ring = mask & ~hole  # a hole: a second contour, after the outer one
    small = _ellipse_mask(centre=(145.0, 10.0), axes=(5.0, 5.0))  # a smaller object
    Image.fromarray(np.where(ring | small, 0, 255).astype(np.uint8)).save(tmp_path / "a.png")
    Image.fromarray(ring).save(tmp_path / "b.png")  # a 1-bit image
    with Image.open(tmp_path / "b.png") as image:
        assert image.mode == "1"
    for name in ("a.png", "b.png"):
        shape = read_shape(tmp_path / name)
        assert len(shape.sizes) == 2
        _check_ellipse(shape.contour(0), mask)
        assert_allclose(-_area(shape.points[shape.slices[1]]), hole.sum(), rtol=0.1)


def test_image_grey_with_threshold(tmp_path, rng):
    from PIL import Image

    mask = _ellipse_mask()
    grey = np.where(mask, 180.0, 60.0) + rng.normal(0, 10, mask.shape)
    path = tmp_path / "grey.png"
    Image.fromarray(np.clip(grey, 0, 255).astype(np.uint8)).save(path)
    _check_ellipse(read_shape(path, threshold=120), mask)
    with pytest.raises(ValueError, match=_err(path) + "a grey-level image .*threshold="):
        read_shape(path)

    tif = tmp_path / "grey16.tif"  # 16-bit TIFF, threshold in its own units
    Image.fromarray((np.where(mask, 40000, 1000)).astype(np.uint16)).save(tif)
    _check_ellipse(read_shape(tif, threshold=20000), mask)

    jpg = tmp_path / "rgb.jpg"  # lossy colour: not a clean mask, so a threshold is needed
    Image.fromarray(np.stack([mask * 200 + 20] * 3, axis=-1).astype(np.uint8)).save(jpg)
    _check_ellipse(read_shape(jpg, threshold=110), mask)


def test_image_with_varying_alpha_uses_it(tmp_path):
    from PIL import Image

    mask = _ellipse_mask()
    rgba = np.zeros((*mask.shape, 4), dtype=np.uint8)
    rgba[..., 3] = mask * 255  # black everywhere, opaque on the object
    Image.fromarray(rgba).save(tmp_path / "alpha.png")
    _check_ellipse(read_shape(tmp_path / "alpha.png"), mask)


def test_image_alpha_is_the_mask_only_when_it_is_one(tmp_path):
    from PIL import Image

    mask = _ellipse_mask()
    grey = (mask * 255).astype(np.uint8)
    for name, alpha in (
        ("opaque", np.full(mask.shape, 255)),  # uniformly opaque: the grey levels
        ("stray", np.where(np.arange(mask.size).reshape(mask.shape) < 4, 0, 255)),  # 4 px
        ("soft", np.linspace(60, 250, mask.size).reshape(mask.shape)),  # a gradient
    ):
        rgba = np.dstack([grey, grey, grey, alpha.astype(np.uint8)])
        Image.fromarray(rgba).save(tmp_path / f"{name}.png")
        _check_ellipse(read_shape(tmp_path / f"{name}.png"), mask)
    # a cut-out with an antialiased edge: the alpha is the mask, whatever the colours
    rgba = np.dstack([np.full(mask.shape, 90, np.uint8)] * 3 + [grey])
    top = mask.nonzero()[0][0]
    rgba[top, mask[top], 3] = 200  # the object's top row partly transparent (an edge)
    Image.fromarray(rgba).save(tmp_path / "cutout.png")
    _check_ellipse(read_shape(tmp_path / "cutout.png"), mask)


def _objects_image(tmp_path):
    """An 80 x 120 mask: a strip along the left border (2400 px), a disc inside (r = 12,
    453 px), a small square inside near the centre (36 px) and a 1 px speck."""
    mask = np.zeros((80, 120), dtype=bool)
    mask[:, :30] = True
    mask |= _ellipse_mask((80, 120), centre=(95.0, 20.0), axes=(12.0, 12.0))
    mask[37:43, 57:63] = True
    mask[70, 100] = True
    path = tmp_path / "objects.png"
    from PIL import Image

    Image.fromarray(mask.astype(np.uint8) * 255).save(path)
    return path, mask


def test_image_object_choice_is_logged_and_prefers_objects_inside(tmp_path, caplog):
    path, mask = _objects_image(tmp_path)
    with caplog.at_level("INFO", logger="modalmorph.io"):
        shape = read_shape(path)  # the disc, not the larger strip touching the border
    assert_allclose(shape.points.mean(axis=0), (95.0, 20.0), atol=0.5)
    said = caplog.text
    assert "touches the image border and is larger (2400 px)" in said
    assert f"{path}: object 1 touches the image border" in said
    disc = _ellipse_mask((80, 120), centre=(95.0, 20.0), axes=(12.0, 12.0)).sum()
    assert re.search(rf"object \d of 4 \(the largest not touching the border\): {disc} px, "
                     r"inside the image", said)
    caplog.clear()
    with caplog.at_level("INFO", logger="modalmorph.io"):
        centre = read_shape(path, object="center")
    assert_allclose(centre.points.mean(axis=0), (59.5, 39.5), atol=0.5)
    assert "(nearest the image centre): 36 px, inside the image" in caplog.text
    strip = read_shape(path, object=1)  # reading order: the strip starts at pixel (0, 0)
    assert_allclose(np.ptp(strip.points, axis=0), (29.0, 79.0), atol=1.0)
    with pytest.raises(ValueError, match=_err(path) + r"object=9, but the image has 4 "):
        read_shape(path, object=9)
    with pytest.raises(OptionError, match="object must be one of largest, center, all or a "):
        read_shape(path, object="biggest")  # checked once, by ReadOptions


def test_image_a_speck_inside_does_not_outrank_a_large_object_on_the_border(tmp_path,
                                                                           caplog):
    from PIL import Image

    mask = np.zeros((60, 90), dtype=bool)
    mask[:, :40] = True  # a large object cut by the border
    mask[30, 70] = True  # a 1 px speck inside
    Image.fromarray(mask.astype(np.uint8) * 255).save(tmp_path / "cut.png")
    with caplog.at_level("INFO", logger="modalmorph.io"):
        shape = read_shape(tmp_path / "cut.png")
    assert_allclose(np.ptp(shape.points, axis=0), (39.0, 59.0), atol=1.0)
    assert "though it touches the border" in caplog.text
    assert "touches the image border" in caplog.text


def test_image_and_svg_shapes_carry_their_frame(tmp_path):
    from PIL import Image

    mask = _ellipse_mask()
    Image.fromarray(mask.astype(np.uint8) * 255).save(tmp_path / "m.png")
    shape = read_shape(tmp_path / "m.png")
    assert shape.frame == ImageFrame(unit="px", image=str(tmp_path / "m.png"),
                                     size=mask.shape, y_down=True)
    assert shape.with_points(shape.points + 1.0).frame is shape.frame  # kept
    svg = tmp_path / "a.svg"
    svg.write_text('<svg xmlns="http://www.w3.org/2000/svg"><circle cx="5" cy="5" r="3"/>'
                   "</svg>")
    assert read_shape(svg).frame.y_down and read_shape(svg).frame.image is None
    np.savetxt(tmp_path / "a.csv", SQUARE, delimiter=",")
    assert read_shape(tmp_path / "a.csv").frame is None  # plain coordinates, y up


def test_image_errors(tmp_path):
    from PIL import Image

    blank = tmp_path / "blank.png"
    Image.fromarray(np.zeros((20, 30), dtype=np.uint8)).save(blank)
    with pytest.raises(ValueError, match=_err(blank) + "no object in the image"):
        read_shape(blank)
    grey = tmp_path / "grey.png"
    Image.fromarray(np.arange(600, dtype=np.uint8).reshape(20, 30)).save(grey)
    with pytest.raises(ValueError, match=_err(grey) + "no object .* above the threshold"):
        read_shape(grey, threshold=-1)
    with pytest.raises(ValueError, match=_err(grey) + "no object .* at or below"):
        read_shape(grey, threshold=255)

    broken = tmp_path / "broken.png"
    broken.write_bytes(b"\x89PNG\r\n\x1a\n this is not an image")
    with pytest.raises(ValueError, match=_err(broken) + "cannot read the image"):
        read_shape(broken)


# -- meshes ------------------------------------------------------------------------------


def _icosphere():
    """A once-subdivided icosahedron on the unit sphere: 42 points, 80 triangles."""
    g = (1 + 5**0.5) / 2
    verts = [(-1, g, 0), (1, g, 0), (-1, -g, 0), (1, -g, 0), (0, -1, g), (0, 1, g),
             (0, -1, -g), (0, 1, -g), (g, 0, -1), (g, 0, 1), (-g, 0, -1), (-g, 0, 1)]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9),
             (5, 11, 4), (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2),
             (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10),
             (8, 6, 7), (9, 8, 1)]
    verts = [np.array(v, dtype=float) / np.linalg.norm(v) for v in verts]
    midpoint = {}

    def mid(i, j):
        key = (min(i, j), max(i, j))
        if key not in midpoint:
            v = verts[i] + verts[j]
            verts.append(v / np.linalg.norm(v))
            midpoint[key] = len(verts) - 1
        return midpoint[key]

    out = []
    for a, b, c in faces:
        ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
        out += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
    return np.array(verts), np.array(out)


def _same_surface(shape, points, faces, atol):
    """Points equal up to order (and float32 storage); the same set of triangles."""
    dist = np.linalg.norm(shape.points[:, None] - points[None], axis=2)
    order = dist.argmin(axis=1)
    assert_allclose(shape.points, points[order], atol=atol)
    assert len(set(order)) == len(points)
    got = {tuple(sorted(t)) for t in order[shape.faces].tolist()}
    assert got == {tuple(sorted(t)) for t in faces.tolist()}
    assert len(shape.faces) == len(faces)


@pytest.mark.parametrize("ext", ["ply", "obj", "stl", "vtk", "vtu", "off"])
def test_mesh_round_trip(tmp_path, ext):
    import meshio

    points, faces = _icosphere()
    path = tmp_path / f"sphere.{ext}"
    extra = np.array([[5.0, 5.0, 5.0]])  # an unreferenced point, dropped on reading
    meshio.write_points_cells(path, np.vstack([points, extra]), [("triangle", faces)])
    shape = read_shape(path)
    assert shape.dim == 3 and not shape.ordered
    _same_surface(shape, points, faces, atol=1e-6)  # STL stores float32


@pytest.mark.parametrize("ext", ["ply", "obj", "off"])
def test_mesh_nodes_keep_the_files_vertex_order(tmp_path, ext):
    """Node i is the file's vertex i (pairs.csv and per-step meshes index the user's
    vertices; they came sorted by coordinate before, review17); a repeated vertex is
    merged into its first appearance, the rest keep their order."""
    import meshio

    points, faces = _icosphere()
    rng = np.random.default_rng(0)
    shuffled = rng.permutation(len(points))  # an order no sort gives
    points, faces = points[shuffled], np.argsort(shuffled)[faces]
    path = tmp_path / f"sphere.{ext}"
    meshio.write_points_cells(path, points, [("triangle", faces)])
    shape = read_shape(path)
    assert_allclose(shape.points, points, atol=1e-6)
    assert np.array_equal(shape.faces, faces)
    repeated = np.vstack([points, points[:1]])  # vertex 0 again, used by the last face
    faces2 = np.vstack([faces[:-1], np.where(faces[-1] == 0, len(points), faces[-1])])
    meshio.write_points_cells(path, repeated, [("triangle", faces2)])
    again = read_shape(path)
    assert_allclose(again.points, points, atol=1e-6) and np.array_equal(again.faces, faces)


def test_mesh_quads_and_point_cloud(tmp_path):
    import meshio

    cube = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], float)
    quads = np.array([[0, 1, 3, 2], [4, 5, 7, 6], [0, 1, 5, 4], [2, 3, 7, 6], [0, 2, 6, 4],
                      [1, 3, 7, 5]])
    meshio.write_points_cells(tmp_path / "cube.vtk", cube, [("quad", quads)])
    shape = read_shape(tmp_path / "cube.vtk")
    assert shape.m == 8 and len(shape.faces) == 12  # each quad split in two

    meshio.write_points_cells(tmp_path / "cloud.vtk", cube, [("vertex", np.arange(8)[:, None])])
    cloud = read_shape(tmp_path / "cloud.vtk")
    assert cloud.faces is None and cloud.m == 8 and not cloud.ordered
    with pytest.raises(ValueError, match="nodes= resamples 2D contours"):
        read_shape(tmp_path / "cloud.vtk", nodes=5)


def test_mesh_files_meshio_refuses(tmp_path):
    """A range scanner's PLY (a ``camera`` element beside the vertices and faces: MeshLab's
    range maps), a textured OBJ (fewer texture coordinates than vertices) and trimesh's
    ASCII STL are valid files meshio refuses: they read as the surfaces they hold."""
    points, faces = _icosphere()
    header = ["ply", "format ascii 1.0", "element camera 1", "property float view_px",
              "property float view_py", f"element vertex {len(points)}", "property float x",
              "property float y", "property float z", f"element face {len(faces)}",
              "property list uchar int vertex_indices", "end_header", "0.5 0.5"]
    rows = [" ".join(f"{v:.9g}" for v in p) for p in points] + [
        "3 " + " ".join(map(str, f)) for f in faces]
    (tmp_path / "scan.ply").write_text("\n".join(header + rows) + "\n")
    _same_surface(read_shape(tmp_path / "scan.ply"), points, faces, atol=1e-6)

    uv = ["vt 0 0", "vt 1 0", "vt 0 1"]  # three texture coordinates for every vertex
    lines = [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in points] + uv + [
        "f " + " ".join(f"{i + 1}/{k + 1}" for k, i in enumerate(f)) for f in faces]
    (tmp_path / "textured.obj").write_text("\n".join(lines) + "\n")
    _same_surface(read_shape(tmp_path / "textured.obj"), points, faces, atol=1e-6)

    relative = [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in points] + [  # OBJ's negative
        "f " + " ".join(str(i - len(points)) for i in f) for f in faces]  # indices
    (tmp_path / "relative.obj").write_text("\n".join(relative) + "\n")
    _same_surface(read_shape(tmp_path / "relative.obj"), points, faces, atol=1e-6)

    # an ASCII STL with a blank line before ``endsolid``, as trimesh writes it
    facets = ["facet normal 0 0 1\nouter loop\n" + "".join(
        f"vertex {x:.9g} {y:.9g} {z:.9g}\n" for x, y, z in points[f]) + "endloop\nendfacet"
        for f in faces]
    (tmp_path / "ascii.stl").write_text("solid s\n" + "\n".join(facets) + "\n\nendsolid\n")
    _same_surface(read_shape(tmp_path / "ascii.stl"), points, faces, atol=1e-6)


def test_mesh_unreadable(tmp_path):
    path = tmp_path / "junk.ply"
    path.write_text("this is not a ply file\n")
    with pytest.raises(ValueError, match=_err(path) + "cannot read the mesh"):
        read_shape(path)


# -- bad inputs --------------------------------------------------------------------------


@pytest.mark.parametrize("name, content, message", [
    ("empty.csv", "", "the file is empty"),
    ("blank.csv", "\n  \n# just a comment\n", "the file has no data"),
    ("header.csv", "x,y\n", "a header line but no data"),
    ("text.csv", "x,y\n0,0\n1,0\n1,abc\n0,1\n", "line 4: 'abc' in column 2 is not a number"),
    ("nan.csv", "0,0\n1,0\nnan,1\n0,1\n", "line 3: non-finite coordinates"),
    ("inf.tsv", "0\t0\n1\tinf\n0\t1\n", "line 2: non-finite coordinates"),
    ("one.csv", "x,y\n1,2\n", "only 1 node; a shape needs at least 3"),
    ("two.txt", "1 2\n3 4\n", "only 2 nodes"),
    ("wide.csv", "1,2,3,4\n5,6,7,8\n9,1,2,3\n", "line 1 has 4 columns, expected 2 or 3"),
    ("narrow.csv", "1\n2\n3\n", "line 1 has 1 column, expected 2 or 3"),
    ("ragged.csv", "# c\n1,2\n3,4\n5,6,7\n", "line 4 has 3 columns, expected 2 like line 2"),
    ("wideheader.csv", "a,b,c,d\n1,2,3,4\n", "line 1 .header. has 4 columns"),
    ("repeat.csv", "0,0\n1,0\n0,1\n1,0\n0.5,-1\n", "node 1 and node 3 coincide"),
    ("point.csv", "1,1\n1,1\n1,1\n1,1\n", "lie .nearly. at one point"),
    ("binary.csv", b"\xff\xfe\x00\x01", "not a text file"),
    ("bad.json", "[[0, 0], [1, 0]", "not valid JSON"),
    ("keys.json", '{"nodes": [[0, 0]]}', "no \"points\""),
    ("str.json", '[[0, 0], [1, "a"], [0, 1]]', "node 1: 'a' is not a number"),
    ("ragged.json", "[[0, 0], [1, 0, 2], [0, 1]]", "node 1 has 3 coordinates, expected 2"),
    ("nan.json", "[[0, 0], [1, 0], [NaN, 1]]", "node 2 has non-finite coordinates"),
    ("one.json", "[[0, 0]]", "only 1 node"),
    ("none.json", '{"points": []}', "no points"),
    ("wide.json", "[[0, 0, 0, 0], [1, 0, 0, 0], [0, 1, 0, 0]]", "got shape .3, 4."),
    ("shape.xyz", "0 0\n1 0\n0 1\n", "line 1 has 2 columns, fewer than x, y, z"),
    ("shape.pcd", "0 0\n1 0\n0 1\n", "unknown file extension '.pcd'; supported: .csv, .tsv"),
])
def test_bad_files(tmp_path, name, content, message):
    path = tmp_path / name
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content)
    with pytest.raises(ValueError, match=_err(path) + ".*" + message):
        read_shape(path)


def test_bad_arrays(tmp_path):
    cases = {
        "one.npy": (np.array([[1.0, 2.0]]), "only 1 node"),
        "flat.npy": (np.arange(6.0), r"the array must have shape \(m, 2\) or \(m, 3\), got "
                                     r"shape \(6,\)"),
        "nan.npy": (np.array([[0, 0], [1, np.inf], [0, 1.0]]), "node 1 has non-finite"),
        "text.npy": (np.array([["a", "b"]] * 3), "the array must be numeric"),
    }
    for name, (array, message) in cases.items():
        np.save(tmp_path / name, array)
        with pytest.raises(ValueError, match=_err(tmp_path / name) + message):
            read_shape(tmp_path / name)
    np.savez(tmp_path / "many.npz", a=SQUARE, b=SQUARE)
    with pytest.raises(ValueError, match="no array named 'points' among"):
        read_shape(tmp_path / "many.npz")
    (tmp_path / "junk.npy").write_text("not numpy")
    with pytest.raises(ValueError, match=_err(tmp_path / "junk.npy") + "cannot read it"):
        read_shape(tmp_path / "junk.npy")


def test_missing_file_directory_and_options(tmp_path):
    missing = tmp_path / "nope.csv"
    with pytest.raises(ValueError, match=_err(missing) + "no such file"):
        read_shape(missing)
    with pytest.raises(ValueError, match="is a directory"):
        read_shape(tmp_path)
    path = _written(tmp_path / "s.csv", SQUARE)
    with pytest.raises(ValueError, match="threshold= applies to images only"):
        read_shape(path, threshold=3)
    with pytest.raises(ValueError, match="nodes must be an integer >= 3, got 2"):
        read_shape(path, nodes=2)
    cloud = _written(tmp_path / "c.csv", CLOUD)
    with pytest.raises(ValueError, match=_err(cloud) + "nodes= resamples 2D contours"):
        read_shape(cloud, nodes=10)
    assert ".png" in SUPPORTED_EXTENSIONS and ".ply" in SUPPORTED_EXTENSIONS


def test_write_points_errors(tmp_path):
    with pytest.raises(ValueError, match="cannot write '.pcd' files; supported: .csv"):
        write_points(tmp_path / "a.pcd", SQUARE)
    with pytest.raises(ValueError, match=r"points must have shape \(m, 2\) or \(m, 3\)"):
        write_points(tmp_path / "a.csv", np.zeros((3, 4)))
    assert not list(tmp_path.iterdir())


# -- the reader table, the options, the error type ---------------------------------------


def test_every_file_problem_is_an_input_file_error(tmp_path):
    (tmp_path / "words.csv").write_text("x,y\n1,a\n")
    (tmp_path / "junk.npy").write_text("not numpy")  # numpy's own failure, named
    (tmp_path / "a.pcd").write_text("1,2\n")
    (tmp_path / "empty.json").write_text("")
    for name, message in [("nope.csv", "no such file"), ("words.csv", "line 2: 'a'"),
                          ("junk.npy", "cannot read it as a .npy file"),
                          ("a.pcd", "unknown file extension"),
                          ("empty.json", "the file is empty")]:
        with pytest.raises(InputFileError, match=_err(tmp_path / name) + message):
            read_shape(tmp_path / name)
    with pytest.raises(InputFileError, match=_err(tmp_path / "words.csv")):
        modalmorph.io.read_frames([tmp_path / "words.csv", tmp_path / "words.csv"])
    with pytest.raises(InputFileError, match="no file matches the pattern"):
        modalmorph.io.read_frames(tmp_path / "none-*.png")
    assert issubclass(InputFileError, ValueError)  # callers catching ValueError still do


def test_read_options_object_and_keyword_overrides(tmp_path):
    path = _written(tmp_path / "s.csv", SQUARE)
    by_keyword = read_shape(path, nodes=40)
    by_options = read_shape(path, ReadOptions(nodes=40))
    assert_array_equal(by_options.points, by_keyword.points)
    overridden = read_shape(path, options=ReadOptions(nodes=40), nodes=30)
    assert overridden.m == 30  # a keyword overrides the options' field
    with pytest.raises(OptionError, match="unknown ReadOptions option 'node'"):
        read_shape(path, node=40)
    with pytest.raises(OptionError, match="options must be a ReadOptions, got int"):
        read_shape(path, 40)
    frames = modalmorph.io.read_frames([path, path], ReadOptions(nodes=12))
    assert [s.m for s in frames.shapes] == [12, 12]


def test_the_reader_table(tmp_path, monkeypatch):
    assert tuple(READERS) == SUPPORTED_EXTENSIONS
    assert all(ext == ext.lower() and ext.startswith(".") for ext in READERS)
    seen = []

    def reader(path, name, options):  # a new reader: the table is the only place to add it
        seen.append((name, options.nodes))
        return RawShape(SQUARE, closed=False)

    path = tmp_path / "s.csv"
    path.write_text("anything")
    monkeypatch.setitem(READERS, ".csv", reader)
    shape = read_shape(path, nodes=None)
    assert seen == [(str(path), None)]
    assert_array_equal(shape.points, SQUARE) and not shape.closed


def test_every_writer_writes_through_atomic_write(tmp_path, monkeypatch):
    from modalmorph.io import points, results, vtk

    written = []

    def recording(path):
        written.append(Path(path).name)
        return atomic.atomic_write(path)

    for module in (points, results, vtk):
        monkeypatch.setattr(module, "atomic_write", recording)
    morph = _small_morph()
    save_result(morph, tmp_path / "out")
    assert sorted(written) == ["final_shape.csv", "result.json", "shapes.npz"]
    written.clear()
    pytest.importorskip("meshio")
    modalmorph.io.write_vtk_series(morph, tmp_path / "vtk")
    assert sorted(written) == sorted(p.name for p in (tmp_path / "vtk").iterdir())
    assert len(written) == morph.steps + 2  # one .vtu per state and the .pvd


# -- results and atomic output -------------------------------------------------------------


def _small_morph():
    """A real morph of a 12-node circle onto an ellipse, from given pairs."""
    a = np.linspace(0.0, 2.0 * np.pi, 12, endpoint=False)
    circle, ellipse = np.c_[np.cos(a), np.sin(a)], np.c_[1.5 * np.cos(a), np.sin(a)]
    return modalmorph.morph(circle, ellipse, matching=np.c_[0:12:2, 0:12:2], max_steps=5)


def test_save_result(tmp_path):
    morph = _small_morph()
    inputs = [{"path": "/data/a.csv", "sha256": "0" * 64}]
    save_result(morph, tmp_path / "out", options={"k": 100.0}, inputs=inputs)
    out = tmp_path / "out"
    assert sorted(p.name for p in out.iterdir()) == ["final_shape.csv", "result.json",
                                                    "shapes.npz"]
    result = json.loads((out / "result.json").read_text())
    assert result == {
        "modalmorph_version": modalmorph.__version__, "inputs": inputs,
        "options": {"k": 100.0},
        "parameters": json.loads(json.dumps(parameters(morph))),
        "converged": morph.converged, "stop_reason": morph.stop_reason,
        "message": morph.message, "distance": morph.distance, "tolerance": morph.tolerance,
        "steps": morph.steps, "matches": 6, "source_nodes": 12, "target_nodes": 12, "dim": 2,
        "mean_distance": morph.mean_distance.tolist(), "energy": morph.energy.tolist(),
        "self_intersections": [0] * (morph.steps + 1),  # a contour that never crosses
        "similarity": None, "co_rotation": None,  # no rigid part removed or turned
        "mirror": None,  # given pairs: no mirror image looked for
    }
    assert result["parameters"]["k"] == morph.options.k
    assert result["parameters"]["model_nodes"] == morph.resolved.model_nodes == 12
    with np.load(out / "shapes.npz") as data:
        assert sorted(data.files) == ["energy", "loads", "mean_distance", "node_energy",
                                      "pairs", "shapes"]
        for key in ("shapes", "loads", "node_energy", "energy", "mean_distance"):
            assert_array_equal(data[key], getattr(morph, key))
        assert_array_equal(data["pairs"], morph.matching.pairs)
    assert_array_equal(read_shape(out / "final_shape.csv").points, morph.shapes[-1])


def test_result_json_records_the_similarity_removed_or_turned(tmp_path):
    """result.json gives the similarity a morph removed first (remove_rigid) or took
    along the steps (co_rotation): its angle, scale, rotation and translation."""
    a = np.linspace(0.0, 2.0 * np.pi, 24, endpoint=False)
    egg = np.c_[np.cos(a) + 0.2 * np.cos(2 * a), 0.6 * np.sin(a)]
    turn = np.array([[0.0, -1.0], [1.0, 0.0]])  # 90 deg
    pairs = np.c_[0:24, 0:24]
    for kind, options in (("co_rotation", {}), ("similarity", {"remove_rigid": True})):
        morph = modalmorph.morph(egg, 1.2 * egg @ turn.T + 3.0, matching=pairs, **options)
        save_result(morph, tmp_path / kind)
        result = json.loads((tmp_path / kind / "result.json").read_text())
        other = "similarity" if kind == "co_rotation" else "co_rotation"
        assert result[other] is None
        assert result[kind]["angle"] == pytest.approx(90.0, abs=1e-6)
        assert result[kind]["scale"] == pytest.approx(1.2, rel=1e-9)
        assert_allclose(result[kind]["rotation"], turn, atol=1e-9)
        assert_allclose(result[kind]["translation"], [3.0, 3.0], atol=1e-9)


def test_save_result_rejects_unwritable_options(tmp_path):
    with pytest.raises(ValueError, match="options cannot be written as JSON"):
        save_result(_small_morph(), tmp_path / "out", options={"f": object()})
    assert not (tmp_path / "out").exists()


def _dead_pid() -> int:
    proc = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)
    return int(proc.stdout)


def test_atomic_output_dir(tmp_path):
    final = tmp_path / "results"
    with atomic_output_dir(final) as tmp:
        assert tmp.parent == tmp_path and tmp != final and not final.exists()
        (tmp / OUTPUT_MARKER).write_text("first")
        (tmp / "sub").mkdir()
        (tmp / "sub" / "b.txt").write_text("b")
    assert (final / OUTPUT_MARKER).read_text() == "first"
    assert (final / "sub" / "b.txt").read_text() == "b"

    with atomic_output_dir(final) as tmp:  # a previous output is replaced as a whole
        (tmp / OUTPUT_MARKER).write_text("second")
    assert sorted(p.name for p in final.iterdir()) == [OUTPUT_MARKER]
    assert (final / OUTPUT_MARKER).read_text() == "second"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["results"]  # no temporary left


def test_atomic_output_dir_without_exchange(tmp_path, monkeypatch):
    monkeypatch.setattr(atomic, "_exchange", lambda a, b: False)  # rename aside instead
    final = tmp_path / "results"
    final.mkdir()
    (final / OUTPUT_MARKER).write_text("old")
    with atomic_output_dir(final) as tmp:
        (tmp / OUTPUT_MARKER).write_text("new")
    assert (final / OUTPUT_MARKER).read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["results"]


def test_atomic_output_dir_nested_and_refusals(tmp_path):
    nested = tmp_path / "a" / "b" / "results"
    with pytest.raises(RuntimeError), atomic_output_dir(nested) as tmp:
        assert tmp.parent == tmp_path  # the nearest existing folder
        raise RuntimeError("boom")
    assert not list(tmp_path.iterdir())  # no parent folders left either
    with atomic_output_dir(nested) as tmp:
        (tmp / "x.txt").write_text("x")
    assert (nested / "x.txt").read_text() == "x"

    foreign = tmp_path / "home"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    (tmp_path / "file").write_text("")
    for path, message in ((foreign, "a folder with other files"),
                          (tmp_path / "file", "exists and is not a folder"),
                          (tmp_path / "file" / "out", "cannot create the folder")):
        with pytest.raises(ValueError, match=_err(path) + message), atomic_output_dir(path):
            pass
    assert (foreign / "notes.txt").read_text() == "mine"


def test_leftovers_of_dead_runs_are_removed(tmp_path):
    dead = tmp_path / f".results.modalmorph-tmp-{_dead_pid()}-abc123"
    (dead / "sub").mkdir(parents=True)
    dead_file = tmp_path / f".pairs.csv.modalmorph-tmp-{_dead_pid()}-x_y-old"
    dead_file.write_text("")
    alive = tmp_path / f".results.modalmorph-tmp-{os.getpid()}-abc123"
    alive.mkdir()
    other = tmp_path / ".results.other-tmp-1-abc"
    other.mkdir()
    assert sorted(remove_leftovers(tmp_path)) == sorted([dead, dead_file])
    assert alive.exists() and other.exists() and not dead.exists()
    dead.mkdir()
    with atomic_output_dir(tmp_path / "results"):  # the next run cleans up
        assert not dead.exists()


def test_atomic_output_dir_leaves_nothing_on_error(tmp_path):
    final = tmp_path / "results"
    with pytest.raises(RuntimeError, match="boom"), atomic_output_dir(final) as tmp:
        (tmp / "half.txt").write_text("half-written")
        raise RuntimeError("boom")
    assert not list(tmp_path.iterdir())

    final.mkdir()
    (final / OUTPUT_MARKER).write_text("old")
    with pytest.raises(RuntimeError), atomic_output_dir(final) as tmp:
        (tmp / OUTPUT_MARKER).write_text("new")
        raise RuntimeError("boom")
    assert (final / OUTPUT_MARKER).read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["results"]


def test_atomic_write(tmp_path):
    path = tmp_path / "sub" / "data.npy"
    with atomic_write(path) as tmp:
        assert tmp.name == "data.npy" and tmp.parent.parent == path.parent
        np.save(tmp, SQUARE)
    assert_array_equal(np.load(path), SQUARE)
    with pytest.raises(RuntimeError), atomic_write(path) as tmp:
        np.save(tmp, CLOUD)
        raise RuntimeError("boom")
    assert_array_equal(np.load(path), SQUARE)  # untouched
    assert sorted(p.name for p in path.parent.iterdir()) == ["data.npy"]


@pytest.mark.parametrize("module, filename, extra", [
    ("meshio", "a.ply", "modalmorph[mesh]"),
    ("PIL", "a.png", "modalmorph[images]"),
    ("skimage.measure", "a.png", "modalmorph[images]"),
    ("svgelements", "a.svg", "modalmorph[images]"),
])
def test_missing_optional_library(tmp_path, monkeypatch, module, filename, extra):
    monkeypatch.setitem(sys.modules, module, None)  # import fails as if not installed
    (tmp_path / filename).write_bytes(b"something")
    with pytest.raises(ImportError, match=re.escape(f"pip install '{extra}'")):
        read_shape(tmp_path / filename)


def test_xyz_point_cloud_leaves_its_attributes_out(tmp_path):
    """An ASCII XYZ cloud: x y z first, then colours or normals, left out."""
    rng = np.random.default_rng(5)
    u = rng.normal(size=(60, 3))
    pts = u / np.linalg.norm(u, axis=1, keepdims=True)
    path = tmp_path / "cloud.xyz"
    np.savetxt(path, np.c_[pts, pts, rng.integers(0, 255, (60, 3))], fmt="%.9f")
    shape = read_shape(path)
    assert shape.dim == 3 and not shape.ordered
    assert_allclose(shape.points, pts, atol=1e-9)
