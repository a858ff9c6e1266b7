"""Figures, animations and VTK series of a morph, on fake results (no solver needed)."""

import sys
import xml.etree.ElementTree as ET
from types import SimpleNamespace

import numpy as np
import pytest
from numpy.testing import assert_allclose

from modalmorph.core.shape import Shape
from modalmorph.io import write_vtk_series

pytest.importorskip("matplotlib")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from PIL import Image  # noqa: E402

from modalmorph.figures import (  # noqa: E402
    MAX_ANIMATION_FRAMES,
    TARGET_COLOR,
    animate,
    frame_steps,
    plot_energy,
    plot_matches,
    plot_shapes,
    save_figures,
)

T = 10
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(autouse=True)
def _close_figures():
    yield
    plt.close("all")


def fake_morph(src, tgt, *, closed=True, faces=None, ordered=None, steps=T):
    """A morph-like result moving ``src`` to ``tgt`` (node i to node i) in ``steps`` steps.

    Loads are target minus current position; the local energy grows with the displacement
    and is negative on a few nodes, as the real one can be.
    """
    m, d = src.shape
    t = 1.0 - (1.0 - np.linspace(0.0, 1.0, steps + 1)) ** 2  # fast, then slowing down
    shapes = src + t[:, None, None] * (tgt - src)
    loads = tgt - shapes
    disp2 = np.sum((shapes - src) ** 2, axis=2)
    node_energy = disp2 * np.where(np.arange(m) % 7 == 0, -0.3, 1.0)
    ordered = d == 2 if ordered is None else ordered
    return SimpleNamespace(
        shapes=shapes, loads=loads, energy=disp2.sum(axis=1), node_energy=node_energy,
        mean_distance=np.linalg.norm(loads, axis=2).mean(axis=1),
        matching=SimpleNamespace(pairs=np.c_[np.arange(0, m, 2), np.arange(0, m, 2)]),
        similarity=None, converged=True, stop_reason="tolerance",
        message="converged after 5 steps",
        source=Shape(src, closed=closed, faces=faces, ordered=ordered),
        target=Shape(tgt, closed=closed, faces=faces, ordered=ordered),
        steps=steps,
    )


def circle_to_ellipse(m=40, *, steps=T):
    a = np.linspace(0.0, 2.0 * np.pi, m, endpoint=False)
    return fake_morph(np.c_[np.cos(a), np.sin(a)], np.c_[2.0 * np.cos(a), 0.8 * np.sin(a)],
                      steps=steps)


def sphere_to_ellipsoid(n=40, *, surface=True, steps=T):
    from scipy.spatial import ConvexHull

    i = np.arange(n) + 0.5  # Fibonacci lattice: nearly uniform nodes on the sphere
    phi, theta = np.arccos(1.0 - 2.0 * i / n), np.pi * (1.0 + 5**0.5) * i
    p = np.c_[np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)]
    faces = ConvexHull(p).simplices if surface else None
    return fake_morph(p, p * [1.5, 1.0, 0.7], faces=faces, steps=steps)


MORPHS = {
    "contour2d": circle_to_ellipse,
    "surface3d": sphere_to_ellipsoid,
    "cloud3d": lambda steps=T: sphere_to_ellipsoid(surface=False, steps=steps),
}


@pytest.fixture(params=list(MORPHS))
def morph(request):
    return MORPHS[request.param]()


def is_3d(ax):
    return ax.name == "3d"


def test_plot_matches(morph):
    ax = plot_matches(morph.source, morph.target, morph.matching.pairs)
    assert isinstance(ax, Axes)
    assert is_3d(ax) == (morph.shapes.shape[2] == 3)
    labels = ax.get_legend_handles_labels()[1]
    assert labels == ["source (40 nodes)", "target (40 nodes)"]
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert legend[-1] == f"matches ({len(morph.matching.pairs)})"


def test_plot_matches_on_bare_arrays_and_given_axes():
    morph = circle_to_ellipse()
    fig, ax = plt.subplots()
    out = plot_matches(morph.shapes[0], morph.target.points, morph.matching.pairs, ax=ax)
    assert out is ax
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("x (input units)", "y (input units)")
    assert ax.get_ylim()[0] < ax.get_ylim()[1]  # plain coordinates: y up


def test_plot_matches_rejects_bad_pairs():
    morph = circle_to_ellipse()
    with pytest.raises(ValueError, match=r"pairs must be an integer array of shape \(K, 2\)"):
        plot_matches(morph.source, morph.target, [0.5, 1.0])
    with pytest.raises(ValueError, match="pairs index nodes outside"):
        plot_matches(morph.source, morph.target, [[0, 40]])
    with pytest.raises(ValueError, match="same dimension"):
        plot_matches(morph.source, sphere_to_ellipsoid().target, [[0, 0]])


@pytest.mark.parametrize(("color_by", "label"), [
    ("load", "load magnitude"), ("energy", "strain energy per node"), (None, "step"),
])
def test_plot_shapes_has_a_labelled_colour_bar(morph, color_by, label):
    ax = plot_shapes(morph, color_by=color_by)
    assert isinstance(ax, Axes)
    cbar_axes = [a for a in ax.figure.axes if a is not ax]
    assert len(cbar_axes) == 1  # the colour bar
    assert label in cbar_axes[0].get_ylabel()
    if not is_3d(ax):
        assert ax.get_aspect() == 1.0  # equal aspect
        assert (ax.get_xlabel(), ax.get_ylabel()) == ("x (input units)", "y (input units)")
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert legend[0].startswith("source") and legend[-1] == "target"


def test_plot_shapes_energy_scale_is_signed_robust_and_centred_on_zero():
    morph = circle_to_ellipse()  # its local energy has both signs
    ax = plot_shapes(morph, color_by="energy")
    lines = ax.collections[0]
    e = morph.node_energy
    lo, hi = np.percentile(e, [2, 98])  # the scale spans these, symmetric about zero
    assert lines.norm.vmin == pytest.approx(-lines.norm.vmax)  # zero in the middle
    assert lines.norm.vmax == pytest.approx(max(-lo, hi))
    assert lines.norm.vmax < np.abs(e).max()  # (so the largest values are clipped ...)
    bar = ax.figure.axes[-1]
    assert "signed" in bar.get_ylabel()
    colorbar = bar._colorbar  # ... and the bar says so with an arrow
    assert colorbar.extend == "max"


def test_a_few_strained_nodes_do_not_set_the_energy_colours():
    morph = circle_to_ellipse()
    e = np.abs(morph.node_energy)
    e[-1, 3] = 1e3 * e.max()  # one node far above the rest
    morph.node_energy = e
    ax = plot_shapes(morph, color_by="energy")
    norm = ax.collections[0].norm
    assert norm.vmin == 0.0 and norm.vmax < 2 * np.percentile(e, 98)  # grey to red from 0
    assert ax.figure.axes[-1]._colorbar.extend == "max"


def test_a_rigid_motion_is_drawn_as_no_deformation():
    morph = circle_to_ellipse()
    morph.node_energy = 2e-14 * np.sin(np.arange(morph.node_energy.size)).reshape(
        morph.node_energy.shape)  # round-off of a pure translation (measured +-2e-14)
    ax = plot_shapes(morph, color_by="energy")
    bar = ax.figure.axes[-1]
    assert bar.get_ylabel().startswith("no deformation")
    colours = ax.collections[0].to_rgba(morph.node_energy.ravel())
    assert np.ptp(colours, axis=0).max() == 0  # one colour for every node
    assert [t.get_text() for t in bar.get_yticklabels()] == ["0"]


def test_plot_shapes_loads_start_at_zero_with_units():
    ax = plot_shapes(circle_to_ellipse(), color_by="load")
    assert ax.collections[0].norm.vmin == 0.0
    assert ax.figure.axes[-1].get_ylabel().endswith("(k x input units)")


def test_plot_shapes_draws_every_kth_step_and_the_last():
    morph = circle_to_ellipse(m=40)
    ax = plot_shapes(morph, color_by=None, every=3)
    # steps 0, 3, 6, 9 and 10; each closed contour is 40 edges split in two halves
    assert len(ax.collections[0].get_segments()) == 5 * 40 * 2
    assert sorted(set(ax.collections[0].get_array())) == [0, 3, 6, 9, 10]


def test_plot_shapes_frames_along_the_path():
    morph = circle_to_ellipse(m=40, steps=40)
    ax = plot_shapes(morph, color_by=None, every=10, frames="path")
    drawn = sorted(set(ax.collections[0].get_array()))
    assert drawn == frame_steps(morph, "path", 5).tolist()


def test_frame_steps_spread_evenly_in_time_or_along_the_path():
    morph = circle_to_ellipse(steps=40)  # moves fast, then slows down: t = 1 - (1 - s)^2
    assert frame_steps(morph).tolist() == list(range(41))
    assert frame_steps(morph, "time", 5).tolist() == [0, 10, 20, 30, 40]
    steps = frame_steps(morph, "path", 5)
    assert steps[0] == 0 and steps[-1] == 40 and np.all(np.diff(steps) > 0)
    s = np.linspace(0.0, 1.0, 41)
    way = 1.0 - (1.0 - s) ** 2  # the fraction of the path made at each step
    assert_allclose(np.diff(way[steps]), 0.25, atol=0.03)  # 1/40 of a step's rounding
    timed = np.diff(way[[0, 10, 20, 30, 40]])
    assert timed.max() > 5 * timed.min()  # evenly in time: a jump, then a crawl
    with pytest.raises(ValueError, match="frames must be one of time, path"):
        frame_steps(morph, "steps")


def test_plot_shapes_rejects_bad_options():
    morph = circle_to_ellipse()
    with pytest.raises(ValueError, match=r"color_by must be one of 'load', 'energy' or None"):
        plot_shapes(morph, color_by="stress")
    with pytest.raises(ValueError, match="every must be a positive integer"):
        plot_shapes(morph, every=0)


def test_plot_energy(morph):
    ax = plot_energy(morph)
    assert isinstance(ax, Axes)
    assert ax.get_xlabel() == "step"
    twin = [a for a in ax.figure.axes if a is not ax]
    assert len(twin) == 1 and twin[0].get_ylabel() == "distance (input units)"
    assert ax.get_ylabel().endswith("($k_{ref} L^2$)")
    ticks = ax.get_xticks()
    assert np.allclose(ticks, np.round(ticks))  # integer steps
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert legend == ["global strain energy $E$ (22)", "mean distance of matched pairs"]


def test_plot_energy_draws_the_stop_distance_and_its_tolerance():
    """The stop test's distance (what converged compares) is drawn, named apart from the
    matched pairs' mean distance, with the tolerance as a line."""
    morph = circle_to_ellipse()
    morph.distance, morph.tolerance = 0.0123, 0.05
    ax = plot_energy(morph)
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert legend[1:] == ["mean distance of matched pairs", "tolerance 0.05",
                          "distance (stop test): 0.0123"]
    twin = ax.figure.axes[-1]
    star = [line for line in twin.get_lines() if line.get_marker() == "*"][0]
    assert_allclose(star.get_xydata(), [[T, 0.0123]])
    tol = [line for line in twin.get_lines() if line.get_linestyle() == ":"][0]
    assert_allclose(tol.get_ydata(), [0.05, 0.05])
    title = ax.get_legend().get_title().get_text()
    assert "\n" not in morph.message and title == morph.message  # one clause a line


@pytest.mark.parametrize(("kind", "formats"), [
    ("contour2d", ("png", "svg")), ("surface3d", ("png",)), ("cloud3d", ("png",)),
])
def test_save_figures_writes_what_it_says(tmp_path, kind, formats):
    morph = MORPHS[kind](steps=4)
    paths = save_figures(morph, tmp_path / "figs", formats=formats, dpi=40)
    stems = ["matches", "shapes_plain", "shapes_load", "shapes_energy", "energy"]
    assert [p.name for p in paths] == [f"{s}.{f}" for s in stems for f in formats]
    for p in paths:
        head = p.read_bytes()[:8]
        assert head == PNG_MAGIC if p.suffix == ".png" else head.startswith(b"<?xml")
    assert plt.get_fignums() == []  # no pyplot figure left open


@pytest.mark.parametrize(("kind", "steps", "color_by"), [
    ("contour2d", T, "energy"), ("surface3d", 3, "load"), ("cloud3d", 3, None),
])
def test_animate_writes_one_gif_frame_per_step(tmp_path, kind, steps, color_by):
    morph = MORPHS[kind](steps=steps)
    path = animate(morph, tmp_path / "morph.gif", fps=5, color_by=color_by, dpi=30)
    assert path == tmp_path / "morph.gif"
    with Image.open(path) as im:
        assert im.format == "GIF"
        assert im.n_frames == steps + 1
    assert [p.name for p in tmp_path.iterdir()] == ["morph.gif"]  # no temporary left
    assert plt.get_fignums() == []


@pytest.mark.parametrize("frames", ["time", "path"])
def test_animate_caps_the_frames(tmp_path, frames):
    morph = circle_to_ellipse(m=12, steps=3 * MAX_ANIMATION_FRAMES)
    path = animate(morph, tmp_path / "morph.gif", dpi=20, frames=frames)
    with Image.open(path) as im:
        assert im.n_frames == len(frame_steps(morph, frames, MAX_ANIMATION_FRAMES))
        assert 0.8 * MAX_ANIMATION_FRAMES <= im.n_frames <= MAX_ANIMATION_FRAMES


def _mask_png(tmp_path):
    """A 60 x 80 mask with one rectangle in its top-left quadrant (rows 6-20, columns
    8-30), read as a shape (pixel coordinates, y down, its image remembered)."""
    from modalmorph.io import read_shape

    mask = np.zeros((60, 80), dtype=np.uint8)
    mask[6:21, 8:31] = 255
    Image.fromarray(mask).save(tmp_path / "mask.png")
    return read_shape(tmp_path / "mask.png", nodes=40)


@pytest.mark.parametrize("background", [True, False])
def test_image_shapes_are_drawn_y_down_over_their_image(tmp_path, background):
    from matplotlib.figure import Figure

    shape = _mask_png(tmp_path)
    fig = Figure(figsize=(4, 3), dpi=100)  # 400 x 300 px, like the image's 80 x 60
    ax = fig.add_axes((0, 0, 1, 1))
    plot_matches(shape, shape, [], background=background, ax=ax)
    fig.savefig(tmp_path / "fig.png", dpi=100)
    rgb = np.asarray(Image.open(tmp_path / "fig.png").convert("RGB")).astype(float)
    assert rgb.shape == (300, 400, 3)
    colour = np.array([int(TARGET_COLOR[i:i + 2], 16) for i in (1, 3, 5)])
    rows, cols = np.nonzero(np.abs(rgb - colour).max(axis=2) < 30)
    x, y = ax.transData.transform(shape.points.mean(axis=0))
    assert_allclose((cols.mean(), rows.mean()), (x, 300 - y), atol=3)  # where it says
    assert ax.yaxis.get_inverted() and ax.get_ylabel() == "y (px)"
    if not background:  # the axes fit the shape; no image under it
        assert (rgb[5, 5] == 255).all()
        return
    # the whole image shows, pixel (r, c) at PNG pixel (5 r + 2, 5 c + 2): the object's
    # outline in the top-left quadrant, not the bottom-left (y up would put it there)
    assert rows.max() < 150 and cols.max() < 200
    assert_allclose((rows.min(), rows.max()), (5 * 6, 5 * 21), atol=4)
    assert_allclose((cols.min(), cols.max()), (5 * 8, 5 * 31), atol=4)
    inside, outside = rgb[5 * 13 + 2, 5 * 19 + 2], rgb[5 * 45 + 2, 5 * 60 + 2]
    assert (inside == 255).all()  # white object
    assert_allclose(outside, 255 * 0.75, atol=2)  # black background at 25 % opacity


def test_animate_rejects_unknown_formats_and_mp4_without_ffmpeg(tmp_path, monkeypatch):
    from matplotlib import animation

    morph = circle_to_ellipse()
    with pytest.raises(ValueError, match=r"\.gif or \.mp4"):
        animate(morph, tmp_path / "morph.avi")
    with pytest.raises(ValueError, match="color_by must be one of"):
        animate(morph, tmp_path / "morph.gif", color_by="strain")
    monkeypatch.setattr(animation.writers, "is_available", lambda name: False)
    with pytest.raises(ValueError, match="ffmpeg"):
        animate(morph, tmp_path / "morph.mp4")
    assert list(tmp_path.iterdir()) == []


def test_animate_leaves_no_partial_file_on_failure(tmp_path, monkeypatch):
    save = Image.Image.save

    def fail_after_writing_some(self, fp, *args, **kwargs):
        save(self, fp, *args, **{**kwargs, "append_images": []})  # a truncated file
        raise RuntimeError("disk full")

    monkeypatch.setattr(Image.Image, "save", fail_after_writing_some)
    with pytest.raises(RuntimeError, match="disk full"):
        animate(circle_to_ellipse(steps=3), tmp_path / "morph.gif", dpi=30)
    assert list(tmp_path.iterdir()) == []


def test_write_vtk_series(tmp_path, morph):
    meshio = pytest.importorskip("meshio")
    pvd = write_vtk_series(morph, tmp_path / "vtk")
    entries = ET.parse(pvd).getroot().find("Collection").findall("DataSet")
    assert [int(e.get("timestep")) for e in entries] == list(range(T + 1))
    files = sorted(p.name for p in pvd.parent.glob("*.vtu"))
    assert [e.get("file") for e in entries] == files and len(files) == T + 1
    last = meshio.read(pvd.parent / files[-1])
    m = morph.shapes.shape[1]
    assert last.points.shape == (m, 3)
    np.testing.assert_allclose(last.points[:, : morph.shapes.shape[2]], morph.shapes[-1])
    assert last.point_data["load"].shape == (m, 3)
    np.testing.assert_allclose(last.point_data["energy"], morph.node_energy[-1])
    expected = {"contour2d": "line", "surface3d": "triangle", "cloud3d": "vertex"}
    kind = ("contour2d" if morph.shapes.shape[2] == 2 else
            "surface3d" if morph.source.faces is not None else "cloud3d")
    assert last.cells[0].type == expected[kind]


def test_missing_dependencies_name_what_to_install(tmp_path, monkeypatch):
    morph = circle_to_ellipse()
    monkeypatch.setitem(sys.modules, "meshio", None)
    with pytest.raises(ImportError, match=r"pip install meshio"):
        write_vtk_series(morph, tmp_path)
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    with pytest.raises(ImportError, match=r"pip install matplotlib"):
        save_figures(morph, tmp_path)


def test_axes_must_match_the_dimension():
    fig = plt.figure()
    flat, deep = fig.add_subplot(1, 2, 1), fig.add_subplot(1, 2, 2, projection="3d")
    with pytest.raises(ValueError, match=r"3D shapes need a 3D Axes"):
        plot_shapes(sphere_to_ellipsoid(), ax=flat)
    with pytest.raises(ValueError, match=r"2D shapes need a 2D Axes"):
        plot_matches(circle_to_ellipse().source, circle_to_ellipse().target, [[0, 0]], ax=deep)


def test_a_real_morph_result(tmp_path):
    from modalmorph import morph

    a = np.linspace(0.0, 2.0 * np.pi, 30, endpoint=False)
    result = morph(np.c_[np.cos(a), np.sin(a)],
                   np.c_[1.6 * np.cos(a), 0.8 * np.sin(a) + 0.1 * np.cos(3 * a)],
                   remove_rigid=True)
    paths = save_figures(result, tmp_path, formats=("png",), dpi=30)
    assert all(p.read_bytes()[:8] == PNG_MAGIC for p in paths)
    gif = animate(result, tmp_path / "morph.gif", dpi=30)
    with Image.open(gif) as im:
        assert im.n_frames == result.steps + 1
    assert len(list(write_vtk_series(result, tmp_path / "vtk").parent.glob("*.vtu"))) == (
        result.steps + 1)


def fake_track(names=("frame_1", "frame_2", "frame_3")):
    """A tracked sequence of three frames (a circle growing into an ellipse)."""
    morph = circle_to_ellipse(steps=len(names) - 1)
    frames = [SimpleNamespace(points=p, closed=True, faces=None, ordered=True, dim=2)
              for p in morph.shapes]
    strain = np.linspace(0.0, -0.2, len(names))  # its minimum at the end
    return SimpleNamespace(
        points=morph.shapes, node_energy=morph.node_energy, frames=frames,
        names=tuple(names), n_frames=len(names), strain=strain,
        segment_strain=np.c_[strain, 0.5 * strain], cumulative_energy=np.arange(3.0),
        source_frame=np.zeros(len(names), dtype=int), shape=lambda f: frames[f])


def test_track_figures_name_the_frames_and_the_legend_hides_no_curve():
    from modalmorph.figures import plot_track_curves, plot_trajectories

    track = fake_track()
    ax = plot_trajectories(track)
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["frame_1", "frame_3"]
    ax.figure.canvas.draw()
    bar = ax.figure.axes[-1]  # the names' differing parts, the pattern in the label
    assert [t.get_text() for t in bar.get_yticklabels()] == ["1", "2", "3"]
    assert bar.get_ylabel() == "frame (frame_*)"
    ax = plot_track_curves(track)
    ax.figure.canvas.draw()
    assert [t.get_text() for t in ax.get_xticklabels()] == ["1", "2", "3"]
    assert ax.get_xlabel() == "frame (frame_*)"
    legend = ax.get_legend().get_window_extent()
    assert legend.y0 >= ax.get_window_extent().y1 - 1  # above the axes, over no data
    ax = plot_shapes(SimpleNamespace(**vars(circle_to_ellipse(steps=2)), names=track.names))
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels[0] == "frame_1 (first frame)" and labels[-1] == "frame_3 (observed)"


def test_track_animation_frames_are_titled_by_their_names(tmp_path):
    from modalmorph.figures.animation import _Scene

    morph = SimpleNamespace(**vars(circle_to_ellipse(steps=2)), names=("a", "b", "c"))
    scene = _Scene(morph, "energy", background=False, dpi=30)
    assert [scene.caption(j) for j in range(3)] == [
        "a (frame 1 of 3)", "b (frame 2 of 3)", "c (frame 3 of 3)"]
    morph.options = SimpleNamespace(dt=0.1)
    del morph.names
    scene = _Scene(morph, "energy", background=False, dpi=30)
    assert scene.caption(2) == "step 2 / 2, t = 0.2 / $\\omega_{ref}$"


def test_frame_names_shortened_for_figures():
    """Figures name frames by what differs: no shared folder, no shared prefix/suffix."""
    from modalmorph.figures._draw import short_names
    from modalmorph.figures.track import differing_parts

    names = short_names(["/data/lv/SC-03-0009.csv", "/data/lv/SC-03-0020.csv"])
    assert names == ("SC-03-0009.csv", "SC-03-0020.csv")
    assert differing_parts(names) == (("0009", "0020"), "SC-03-*.csv")
    assert differing_parts(["frame 0", "frame 12"]) == (("0", "12"), "frame *")
    assert differing_parts(["a.csv"]) == (("a.csv",), "")
    assert short_names(["x.npy[0]", "x.npy[1]"]) == ("x.npy[0]", "x.npy[1]")
