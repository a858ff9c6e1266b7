"""What the figures show is what was computed: run ``modalmorph morph`` on CSV, SVG,
image and mesh inputs, read the PNGs and every GIF frame back, and check that the shapes
are drawn where the results say (within 2 px).

The moving shape is drawn in one known colour (the energy palette replaced by pure
green), so its pixels are found by colour. The data -> pixel map of a 2D figure is not
taken from the library: the axes' box is found from its frame in the picture, and the
limits follow the documented rule (the box of what is drawn grown by 4 % of its larger
side, widened about its centre to the axes' aspect, equal scales; images whole). 3D
projections are not linear: there each GIF frame is checked against the PNG of the same
run, which draws the same steps in the same axes.
"""

import json

import numpy as np
import pytest
from PIL import Image

pytest.importorskip("matplotlib")
from modalmorph.apps.cli import main  # noqa: E402
from modalmorph.figures import _draw  # noqa: E402
from modalmorph.io import read_shape  # noqa: E402

GREEN = "#00c000"  # the moving shape's colour in these runs: in no other part of a figure
TOL_PX = 2.0  # the brief: drawn within 2 px of where it was computed
MARGIN = 0.04  # the limits' rule (see the module docstring)
NODES = 60


# ------------------------------------------------------------------------------ inputs


def _glyph(n=NODES):
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    r = 1.0 + 0.3 * np.cos(3 * t)
    return np.c_[2.0 * r * np.cos(t), r * np.sin(t)]


def _csv_pair(d):
    g = _glyph()
    np.savetxt(d / "a.csv", g, delimiter=",", header="x,y", comments="")
    # the case of the issue: a translated copy (the GIF drew it 2.2x too tall)
    np.savetxt(d / "b.csv", g * [1.1, 0.9] + [3.0, 1.5], delimiter=",", header="x,y",
               comments="")
    return [d / "a.csv", d / "b.csv"]


def _svg(path, rx, ry, cx=100):
    path.write_text(
        '<svg xmlns="http://www.w3.org/2000/svg" width="200" height="200">'
        f'<path d="M {cx - rx} 100 A {rx} {ry} 0 1 0 {cx + rx} 100 '
        f'C {cx + rx} 60, {cx + 30} {100 - ry}, {cx} {100 - ry} '
        f'S {cx - rx} 60, {cx - rx} 100 Z"/></svg>')
    return path


def _svg_pair(d):
    return [_svg(d / "a.svg", 60, 40, 90), _svg(d / "b.svg", 50, 55, 110), "--nodes",
            str(NODES)]


def _mask(path, centre, radii, size=(160, 200)):
    yy, xx = np.mgrid[: size[0], : size[1]]
    inside = ((xx - centre[0]) / radii[0]) ** 2 + ((yy - centre[1]) / radii[1]) ** 2 <= 1
    inside |= (np.abs(xx - centre[0]) < radii[0] / 3) & (yy > centre[1])  # a "stem"
    inside &= yy < size[0] - 10
    Image.fromarray((inside * 255).astype(np.uint8)).save(path)
    return path


def _image_pair(d):
    return [_mask(d / "a.png", (80, 65), (50, 35)), _mask(d / "b.png", (110, 75), (40, 45)),
            "--nodes", str(NODES)]


def _mesh_pair(d):
    from scipy.spatial import ConvexHull

    rng = np.random.default_rng(5)
    u = rng.standard_normal((120, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    faces = ConvexHull(u).simplices
    p = u * [1.6, 1.0, 0.6] + 0.4 * np.exp(-8 * np.sum((u - [0.6, 0.6, 0.5]) ** 2, axis=1,
                                                       keepdims=True))
    q = p * [1.1, 0.9, 1.0] + 0.05 * p**2 + [0.5, 0.0, 0.2]
    for name, pts in (("a.off", p), ("b.off", q)):
        lines = ["OFF", f"{len(pts)} {len(faces)} 0"]
        lines += [" ".join(f"{v:.9g}" for v in row) for row in pts]
        lines += [f"3 {a} {b} {c}" for a, b, c in faces]
        (d / name).write_text("\n".join(lines) + "\n")
    return [d / "a.off", d / "b.off"]


INPUTS = {"csv": _csv_pair, "svg": _svg_pair, "image": _image_pair, "mesh": _mesh_pair}


@pytest.fixture(scope="module", params=list(INPUTS))
def run(request, tmp_path_factory):
    """The command line's output folder for one kind of input, its moving shape green."""
    d = tmp_path_factory.mktemp(request.param)
    args = [str(a) for a in INPUTS[request.param](d)]
    out = d / "out"
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(_draw, "ENERGY_COLORS", (GREEN, GREEN, GREEN))
        assert main(["morph", *args, "--out", str(out), "-q"]) == 0
    result = json.loads((out / "result.json").read_text())
    assert result["converged"]
    nodes = [] if request.param == "mesh" else ["--nodes", str(NODES)]
    target = read_shape(args[1], nodes=int(nodes[1]) if nodes else None)
    shapes = np.load(out / "shapes.npz")["shapes"]
    image = None
    if request.param == "image":
        with Image.open(args[1]) as im:
            image = im.size
    return dict(kind=request.param, out=out, shapes=shapes, target=target.points,
                y_down=request.param in ("svg", "image"), image=image)


# ------------------------------------------------------------------------------ pixels


def _rgb(im):
    return np.asarray(im.convert("RGB"), dtype=np.int16)


def _png(path):
    with Image.open(path) as im:
        return _rgb(im)


def _green(rgb):
    """Pixels drawn in GREEN (or blended with what is under them)."""
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return (g - np.maximum(r, b)) > 60


def _inside(shape, box):
    """Pixels inside the axes' frame (the colour bar, green too, lies outside)."""
    left, top, right, bottom = box
    mask = np.zeros(shape[:2], dtype=bool)
    mask[int(top) + 3:int(bottom) - 2, int(left) + 3:int(right) - 2] = True
    return mask


def _plot_area(mask):
    """A 3D figure's mask without the legend above (its green handle) and the colour bar
    on the right (green too): rows below the top 25 %, columns left of 72 %."""
    h, w = mask.shape
    out = np.zeros_like(mask)
    out[int(0.25 * h):, : int(0.72 * w)] = mask[int(0.25 * h):, : int(0.72 * w)]
    return out


def _bbox(mask):
    rows, cols = np.nonzero(mask)
    assert rows.size, "nothing drawn in the shape's colour"
    return np.array([cols.min(), rows.min(), cols.max(), rows.max()], dtype=float)


def _axes_box(rgb):
    """(left, top, right, bottom) pixel centres of the 2D axes' frame: its top and bottom
    are the rows holding the longest dark runs, its sides the columns dark all the way
    between them nearest those runs' ends (tick marks may lengthen the runs)."""
    dark = rgb.max(axis=2) < 90
    spans = []
    for row in np.nonzero(dark.sum(axis=1) > 0.4 * dark.shape[1])[0]:
        cols = np.nonzero(dark[row])[0]
        run = max(np.split(cols, np.nonzero(np.diff(cols) > 1)[0] + 1), key=len)
        if len(run) > 0.4 * dark.shape[1]:
            spans.append((row, run[0], run[-1]))
    rows = np.array([s[0] for s in spans])
    top = rows[rows < rows.min() + 3].mean()
    bottom = rows[rows > rows.max() - 3].mean()
    inner = dark[int(top) + 4:int(bottom) - 3]
    full = np.nonzero(inner.mean(axis=0) > 0.95)[0]  # dark from top to bottom
    start, end = np.median([s[1] for s in spans]), np.median([s[2] for s in spans])
    left = full[np.abs(full - start) <= 8]
    right = full[np.abs(full - end) <= 8]
    return left.mean(), top, right.mean(), bottom


def _to_pixels(points, drawn, box, y_down, image=None):
    """The documented map of data ``points`` to pixels (x right, rows down) for a figure
    whose limits fit ``drawn`` (and the whole image)."""
    lo, hi = drawn.min(axis=0), drawn.max(axis=0)
    pad = MARGIN * (hi - lo).max()
    lo, hi = lo - pad, hi + pad
    if image is not None:
        lo, hi = np.minimum(lo, -0.5), np.maximum(hi, np.array(image) - 0.5)
    left, top, right, bottom = box
    scale = min((right - left) / (hi[0] - lo[0]), (bottom - top) / (hi[1] - lo[1]))
    centre = 0.5 * (lo + hi)
    col = 0.5 * (left + right) + (points[:, 0] - centre[0]) * scale
    row = 0.5 * (top + bottom) + (points[:, 1] - centre[1]) * scale * (1 if y_down else -1)
    return np.c_[col, row]


def _frames(path):
    with Image.open(path) as gif:  # (every frame, as a viewer shows it)
        frames = []
        for k in range(gif.n_frames):
            gif.seek(k)
            frames.append(_rgb(gif))
    return frames


# ------------------------------------------------------------------------------- tests


def test_every_gif_frame_draws_its_step_where_it_was_computed(run):
    if run["kind"] == "mesh":
        pytest.skip("3D: checked against the PNG below")
    shapes, frames = run["shapes"], _frames(run["out"] / "morph.gif")
    assert len(frames) == len(shapes)  # one frame per step (fewer than 40 steps here)
    drawn = np.vstack([shapes.reshape(-1, 2), run["target"]])
    box = _axes_box(frames[0])
    # the green reaches past the nodes by a node marker's face (10 pt^2: radius 1.6 pt;
    # the coloured line is 1.8 pt wide), at the GIF's 80 dpi
    reach = np.sqrt(10) / 2 * 80 / 72
    for j, rgb in enumerate(frames):
        assert _axes_box(rgb) == pytest.approx(box, abs=0.01)  # fixed for the whole run
        px = _to_pixels(shapes[j], drawn, box, run["y_down"], run["image"])
        want = np.r_[px.min(axis=0) - reach, px.max(axis=0) + reach]
        got = _bbox(_green(rgb) & _inside(rgb.shape, box))
        assert np.abs(got - want).max() <= TOL_PX, (j, got, want)


def test_gif_frames_are_titled_and_the_titles_change(run):
    frames = _frames(run["out"] / "morph.gif")
    h, w = frames[0].shape[:2]  # 3D: no frame; the title lies in the top left quarter
    left, top, right, _ = _axes_box(frames[0]) if run["kind"] != "mesh" else (0, h / 4, w, 0)
    band = (slice(0, int(top) - 2), slice(0, int(left + 0.4 * (right - left))))
    ink = [(f[band].max(axis=2) < 100).sum() for f in frames]
    assert min(ink) > 20  # text above the axes, on the left
    assert not np.array_equal(frames[0][band], frames[-1][band])  # step 0 != last step


def test_the_shapes_png_draws_every_step_where_it_was_computed(run):
    """The steps (green lines), the source's nodes (black, on top) and the target (magenta
    squares, on top) together cover what was computed, where it was computed."""
    if run["kind"] == "mesh":
        pytest.skip("3D: checked against the GIF below")
    shapes, target = run["shapes"], run["target"]
    assert len(shapes) <= 30  # every step drawn (MAX_FIGURE_SHAPES)
    rgb = _png(run["out"] / "shapes_energy.png")
    box = _axes_box(rgb)
    r, g = rgb[..., 0], rgb[..., 1]
    ink = _green(rgb) | (rgb.max(axis=2) < 60) | ((r > 150) & (r - g > 90))
    drawn = np.vstack([shapes.reshape(-1, 2), target])
    pt = 150 / 72  # pixels per point in the PNG
    want = []  # each part's box, grown by how far its line or marker reaches
    for points, reach in ((shapes.reshape(-1, 2), 0.6 * pt),  # 1.2 pt lines
                          (shapes[0], np.sqrt(9) / 2 * pt),  # the source's 9 pt^2 dots
                          (target, np.sqrt(12) / 2 * pt)):  # the target's 12 pt^2 squares
        px = _to_pixels(points, drawn, box, run["y_down"], run["image"])
        want.append(np.r_[px.min(axis=0) - reach, px.max(axis=0) + reach])
    want = np.r_[np.min(want, axis=0)[:2], np.max(want, axis=0)[2:]]
    got = _bbox(ink & _inside(rgb.shape, box))
    assert np.abs(got - want).max() <= TOL_PX, (got, want)


def test_the_matches_png_draws_the_source_where_it_was_computed(run):
    if run["kind"] == "mesh":
        pytest.skip("3D")
    source, target = run["shapes"][0], run["target"]
    rgb = _png(run["out"] / "matches.png")
    box = _axes_box(rgb)
    black = _inside(rgb.shape, box) & (rgb.max(axis=2) < 60)  # the source's nodes: black dots
    px = _to_pixels(source, np.vstack([source, target]), box, run["y_down"], run["image"])
    reach = np.sqrt(14) / 2 * 150 / 72  # a node's 14 pt^2 marker at 150 dpi
    want = np.r_[px.min(axis=0) - reach, px.max(axis=0) + reach]
    got = _bbox(black)
    assert np.abs(got - want).max() <= TOL_PX, (got, want)


def test_3d_gif_frames_and_png_share_their_axes(run):
    """A surface: the moving shape of every frame lies inside what the PNG draws (the
    paths of all nodes over all steps and the final surface), and all frames together
    cover the same pixels, the GIF's 80 dpi scaled to the PNG's 150."""
    if run["kind"] != "mesh":
        pytest.skip("2D: checked in pixels above")
    frames = _frames(run["out"] / "morph.gif")
    png = _plot_area(_green(_png(run["out"] / "shapes_energy.png")))
    boxes = np.array([_bbox(_plot_area(_green(f))) for f in frames]) * 150 / 80
    union = np.r_[boxes[:, :2].min(axis=0), boxes[:, 2:].max(axis=0)]
    # 2 px at 80 dpi, plus the PNG's own thin node paths reaching past the surfaces
    assert np.abs(union - _bbox(png)).max() <= TOL_PX * 150 / 80 + 2, (union, _bbox(png))
    last = boxes[-1]
    assert np.all(last[:2] >= _bbox(png)[:2] - 4) and np.all(last[2:] <= _bbox(png)[2:] + 4)
