"""The animation of a morph: a GIF (Pillow) or an MP4 (ffmpeg), one step per frame, the
fixed parts drawn once in fixed axes and each frame only the moving shape and its title
over them; one drawing path (:func:`render_frames`) for both formats."""

from __future__ import annotations

import os
import secrets
from pathlib import Path

import numpy as np

from ._draw import (
    SHAPE_COLOR,
    SOURCE_COLOR,
    TARGET_COLOR,
    check_color_by,
    check_frames,
    colorbar,
    colormap,
    describe,
    draw_image,
    edges_of,
    finish_axes,
    half_segments,
    import_matplotlib,
    line_collection,
    new_figure,
    node_values,
    view_of,
)
from .morph import frame_steps

MAX_ANIMATION_FRAMES = 40  # frames at most (heart GIF: 1.16 s with 40 frames, 2.83 s with 101)
GIF_DPI = 80  # 512 x 432 px frames, text legible (heart GIF: 1.16 s at 80 dpi, 1.67 s at 100)


def animate(morph, path, *, fps: int = 10, color_by="energy", dpi: int = GIF_DPI,
            frames: str = "time", background: bool = True,
            max_frames: int = MAX_ANIMATION_FRAMES) -> Path:
    """Write an animation of the deformation.

    Each frame shows the shape at one step coloured per node (as :func:`plot_shapes`,
    one colour scale for all frames), the source and the target drawn faintly, and is
    titled with its step and time (a track's frame: its name). The axes are fixed once
    for the whole animation; the fixed parts are drawn once, each frame only the moving
    shape over them.

    Parameters
    ----------
    morph : Morph
        A morph result.
    path : str or Path
        Output file: ``.gif`` (Pillow) or ``.mp4`` (needs ffmpeg on the PATH).
    fps, dpi : int, optional
        Frames per second; resolution of the frames.
    color_by : {"energy", "load", None}, optional
        As in :func:`plot_shapes`; None draws every frame in one colour.
    frames : {"time", "path"}, optional
        Steps shown (:func:`frame_steps`), at most ``max_frames``: evenly spaced in time,
        or along the path (the damped motion makes most of its way in the first steps).
    background : bool, optional
        Draw the target's source image under the shapes (shapes read from an image).

    Returns
    -------
    Path
        ``path``, written atomically (a temporary file renamed at the end, so a failure
        leaves no partial file). A ValueError for a suffix other than ``.gif`` or
        ``.mp4``, or ``.mp4`` without ffmpeg.
    """
    check_color_by(color_by)
    check_frames(frames)
    if fps <= 0:
        raise ValueError(f"fps must be positive, got {fps!r}")
    path = Path(path)
    suffix = path.suffix.lower()
    import_matplotlib()
    from matplotlib import animation

    if suffix not in (".gif", ".mp4"):
        raise ValueError(f"path must end in .gif or .mp4, got {path.name!r}")
    if suffix == ".mp4" and not animation.writers.is_available("ffmpeg"):
        raise ValueError(f"writing {path.name} needs ffmpeg on the PATH; install it or ask "
                         f"for a .gif")
    scene = _Scene(morph, color_by, background=background, dpi=dpi)
    steps = frame_steps(morph, frames, max_frames)
    # a unique name beside the target, same suffix (ffmpeg picks its format from it)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}-{secrets.token_hex(4)}.tmp{suffix}")
    try:
        images = render_frames(scene, steps)
        if suffix == ".gif":
            _write_gif(images, tmp, fps=fps)
        else:
            _write_mp4(images, tmp, fps=fps)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def _write_gif(images: list, path: Path, *, fps: int) -> None:
    """The frames (RGB arrays) as a looping GIF of palette images (Pillow)."""
    from PIL import Image

    frames = [Image.fromarray(rgb).quantize(colors=255, method=Image.Quantize.FASTOCTREE)
              for rgb in images]
    frames[0].save(path, format="GIF", save_all=True, append_images=frames[1:],
                   duration=round(1000 / fps), loop=0)


def _write_mp4(images: list, path: Path, *, fps: int) -> None:
    """The frames (RGB arrays) as an H.264 MP4: raw frames piped to ffmpeg (the command
    matplotlib's FFMpegWriter runs, fed the frames the GIF is made of)."""
    import subprocess

    from matplotlib import animation

    h, w = images[0].shape[:2]
    cmd = [animation.FFMpegWriter.bin_path(), "-loglevel", "error", "-f", "rawvideo",
           "-vcodec", "rawvideo", "-s", f"{w}x{h}", "-pix_fmt", "rgb24", "-r", str(fps),
           "-i", "pipe:", "-vcodec", "h264", "-pix_fmt", "yuv420p",
           "-vf", "scale=trunc(iw/2)*2:trunc(ih/2)*2", "-y", str(path)]
    done = subprocess.run(cmd, input=b"".join(rgb.tobytes() for rgb in images),
                          capture_output=True, check=False)
    if done.returncode:
        raise OSError(f"ffmpeg could not write {path.name}: "
                      f"{done.stderr.decode(errors='replace').strip()[-300:]}")


def render_frames(scene, steps) -> list:
    """The frames of ``steps`` as RGB arrays (h, w, 3), the one drawing path of the GIF
    and the MP4: the fixed parts rendered once (Agg), then for each step that background
    restored and only the moving shape and the title drawn, in the fixed axes."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(scene.fig)
    scene.show(steps[0], animated=True)  # the title in place when the layout is drawn
    canvas.draw()
    clean = canvas.copy_from_bbox(scene.fig.bbox)
    images = []
    for j in steps:
        canvas.restore_region(clean)
        for artist in scene.show(j, animated=True):
            if hasattr(artist, "do_3d_projection"):
                artist.do_3d_projection()  # (what Axes3D.draw does before drawing)
            scene.ax.draw_artist(artist)
        scene.ax.draw_artist(scene.title)
        images.append(np.array(np.asarray(canvas.buffer_rgba())[..., :3]))
    return images


class _Scene:
    """An animation's figure: the fixed parts (image, faint source and target, colour
    bar, legend) laid out once in fixed axes; :meth:`show` draws the shape at one step
    over them and titles the frame with its step and time (a track: its frame's name)."""

    def __init__(self, morph, color_by, *, background: bool, dpi: int):
        shapes = np.asarray(morph.shapes, dtype=np.float64)
        _, closed, ordered, faces, sizes = describe(morph.source, "morph.source")
        self.shapes, self.last = shapes, len(shapes) - 1
        self.names = getattr(morph, "names", None)
        self.dt = getattr(getattr(morph, "options", None), "dt", None)
        self.faces = faces
        self.edges = edges_of(shapes.shape[1], closed, ordered, None, sizes)
        self.values = np.zeros(shapes.shape[:2]) if color_by is None else \
            node_values(morph, color_by)
        scale = None if color_by is None else colormap(color_by, self.values)
        self.cmap, self.norm = (None, None) if scale is None else (scale.cmap, scale.norm)
        self.fig, self.ax = new_figure(shapes.shape[2])
        self.fig.set_dpi(dpi)
        view = view_of(morph.target, morph.source, background=background)
        image = draw_image(self.ax, view)
        handles = _faint_ends(self.ax, shapes[0], morph.source, morph.target, self.names)
        if scale is not None:  # before the limits are fixed: the bar takes its room
            from matplotlib.cm import ScalarMappable

            colorbar(self.ax, ScalarMappable(norm=self.norm, cmap=self.cmap), color_by,
                     unit=view.unit, scale=scale)
        tgt = describe(morph.target, "morph.target")[0]
        finish_axes(self.ax, np.vstack([shapes.reshape(-1, shapes.shape[2]), tgt]), view,
                    image=image)
        handles.insert(0, _current_handle(self.cmap, self.faces is not None,
                                          bool(len(self.edges))))
        self.ax.legend(handles=handles, loc="lower right", bbox_to_anchor=(1.0, 1.0),
                       ncols=3, frameon=False, fontsize="small")  # the frame's title above it
        self.title = self.ax.set_title(" ", loc="left", fontsize="medium", pad=18)
        self.artists = []

    def show(self, j: int, *, animated: bool = False) -> list:
        """Replace the moving shape by the one at step ``j``; the new artists."""
        for artist in self.artists:
            artist.remove()
        self.artists = _draw_frame(self.ax, self.shapes[j], self.edges, self.faces,
                                   self.values[j], self.cmap, self.norm)
        for artist in self.artists:
            artist.set_animated(animated)
        self.title.set_text(self.caption(j))
        self.title.set_animated(animated)
        return self.artists

    def caption(self, j: int) -> str:
        """The title of step ``j``'s frame: its step and time, or a track's frame name."""
        if self.names is not None:
            return f"{self.names[j]} (frame {j + 1} of {self.last + 1})"
        time = "" if self.dt is None else f", t = {j * self.dt:.3g} / $\\omega_{{ref}}$"
        return f"step {j} / {self.last}{time}"


def _faint_ends(ax, start, source, target, names=None) -> list:
    """The fixed background of the animation, faint: the source at step 0 (``start``) and
    the target, contours as lines, surfaces and clouds as nodes; their legend handles
    (labelled by the first and last frames' ``names`` for a track)."""
    from matplotlib.lines import Line2D

    _, s_closed, s_ordered, _, s_sizes = describe(source, "morph.source")
    tgt, t_closed, t_ordered, _, t_sizes = describe(target, "morph.target")
    first, last = ("source", "target") if names is None else (names[0], names[-1])
    handles = []
    for pts, closed, ordered, sizes, color, marker, label in (
        (start, s_closed, s_ordered, s_sizes, SOURCE_COLOR, "o", first),
        (tgt, t_closed, t_ordered, t_sizes, TARGET_COLOR, "s", last),
    ):
        e = edges_of(len(pts), closed, ordered, None, sizes)
        if len(e):
            ax.add_collection(line_collection(pts[e], ax, colors=color, linewidths=0.9,
                                              alpha=0.35, zorder=1))
        ax.scatter(*pts.T, s=5, c=color, marker=marker, alpha=0.35, linewidths=0, zorder=1)
        handles.append(Line2D([], [], color=color, alpha=0.5, marker=marker, ms=3,
                              ls="-" if len(e) else "none", label=label))
    return handles


def _current_handle(cmap, surface: bool, lines: bool):
    """The legend handle of the moving shape."""
    one = SHAPE_COLOR if cmap is None else cmap(0.75)
    if surface:
        from matplotlib.patches import Patch

        return Patch(facecolor=one, edgecolor="0.3", label="shape at the step")
    from matplotlib.lines import Line2D

    return Line2D([], [], color=one, lw=2.0, marker="o", ms=3, mec="0.15",
                  ls="-" if lines else "none", label="shape at the step")


def _draw_frame(ax, points, edges, faces, values, cmap, norm):
    """The artists of one animation frame: the shape at one step, coloured per node."""
    if faces is not None:
        from mpl_toolkits.mplot3d.art3d import Poly3DCollection

        kw = {"facecolors": SHAPE_COLOR} if cmap is None else {"cmap": cmap, "norm": norm}
        surf = Poly3DCollection(points[faces], edgecolors="0.3", linewidths=0.15,
                                alpha=0.9, zorder=3, **kw)
        if cmap is not None:
            surf.set_array(values[faces].mean(axis=1))
        ax.add_collection3d(surf)
        return [surf]
    artists = []
    if len(edges):
        kw = {"colors": SHAPE_COLOR} if cmap is None else {"cmap": cmap, "norm": norm}
        # a dark casing under the coloured line: the moving shape stands out from the
        # faint source and target even where its colour is pale (values near zero)
        casing = line_collection(points[edges], ax, colors="0.15", linewidths=3.0,
                                 zorder=3, capstyle="round")
        segs, vals = half_segments(points, edges, values)
        lines = line_collection(segs, ax, linewidths=1.8, zorder=3, capstyle="round", **kw)
        if cmap is not None:
            lines.set_array(vals)
        for artist in (casing, lines):
            ax.add_collection(artist, autolim=False)
            artists.append(artist)
    kw = {"c": SHAPE_COLOR} if cmap is None else {"c": values, "cmap": cmap, "norm": norm}
    artists.append(ax.scatter(*points.T, s=10 if len(edges) else 16, zorder=4,
                              edgecolors="0.15", linewidths=0.5, **kw))
    return artists
