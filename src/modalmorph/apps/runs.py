"""What one run of the command line does: read the inputs, compute, write one output folder.

:func:`morph_files` (``modalmorph morph``) and :func:`track_files` (``modalmorph track``)
are shared by the command line, the batch workers (:mod:`modalmorph.apps.batch`) and the web
app (:mod:`modalmorph.apps.app`). Their options are :class:`Settings`: one option object per
stage (:mod:`modalmorph.options`), so that the flags, the config file, the form and the
record in ``result.json`` are generated from all of them alike (flat names:
:func:`modalmorph.options.flat_fields`).
"""

from __future__ import annotations

import glob
import hashlib
import os
import warnings
from dataclasses import MISSING, dataclass, field
from pathlib import Path

from .. import figures
from ..core.material import Material
from ..core.quality import check_contours
from ..errors import OptionError, ShapeError
from ..io import (
    atomic_output_dir,
    read_frames,
    read_shape,
    save_result,
    save_track,
    write_gltf,
    write_step_meshes,
    write_vtk_series,
    y_down,
)
from ..matching import match
from ..options import (
    MatchOptions,
    MorphOptions,
    OutputOptions,
    ReadOptions,
    StanceOptions,
    TrackOptions,
    flat_fields,
    split,
)
from ..pipeline import morph
from ..threads import limit
from ..tracking import track
from .report import input_images, write_html

__all__ = ["Settings", "ItemRun", "PAIR_CLASSES",
           "SEQUENCE_CLASSES", "BATCH_CLASSES", "FORM_CLASSES",
           "check_tools", "check_y_directions", "default_text", "file_record", "input_records",
           "read_pair", "compute_morph", "morph_files", "track_files", "write_morph"]



# The option classes of each command, in the order of their flags and records.
PAIR_CLASSES = (ReadOptions, MatchOptions, MorphOptions, OutputOptions)
SEQUENCE_CLASSES = (*PAIR_CLASSES, TrackOptions)
BATCH_CLASSES = (ReadOptions, MatchOptions, MorphOptions, TrackOptions)
FORM_CLASSES = (MatchOptions, MorphOptions)
_ATTRIBUTE = {ReadOptions: "read", MatchOptions: "match", MorphOptions: "morph",
              OutputOptions: "output", TrackOptions: "sequence", StanceOptions: "stance"}


@dataclass(frozen=True)
class Settings:
    """Every option of one run, one object per stage (``stance``: the pressure items of
    a batch)."""

    read: ReadOptions = field(default_factory=ReadOptions)
    match: MatchOptions = field(default_factory=MatchOptions)
    morph: MorphOptions = field(default_factory=MorphOptions)
    output: OutputOptions = field(default_factory=OutputOptions)
    sequence: TrackOptions = field(default_factory=TrackOptions)
    stance: StanceOptions = field(default_factory=StanceOptions)

    @classmethod
    def from_flat(cls, values: dict, classes=SEQUENCE_CLASSES, *, where: str = "options"):
        """Settings from flat names and values (text or TOML), as in a config file;
        the classes not in ``classes`` keep their defaults."""
        objects = split(values, classes, where=where)
        return cls(**{_ATTRIBUTE[c]: obj for c, obj in objects.items()})

    def flat(self, classes=SEQUENCE_CLASSES) -> dict:
        """The options that differ from their defaults, by flat name (for
        :meth:`from_flat`: ``Settings.from_flat({**s.flat(), **more})``)."""
        return {name: getattr(self._of(cls), f.name)
                for name, cls, f in flat_fields(classes)
                if getattr(self._of(cls), f.name) != f.default}

    def record(self, classes=SEQUENCE_CLASSES) -> dict:
        """Every option by flat name, as plain JSON values (``result.json``)."""
        records = {cls: self._of(cls).record() for cls in classes}
        return {name: records[cls][f.name] for name, cls, f in flat_fields(classes)}

    def _of(self, cls):
        return getattr(self, _ATTRIBUTE[cls])


@dataclass(frozen=True)
class ItemRun:
    """What one ``morph`` or ``track`` run computed, and the files it wrote.

    Attributes
    ----------
    result : Morph or Track
    files : tuple of Path
        The files written, under the output folder.
    """

    result: object
    files: tuple


def default_text(f) -> str:
    """A field's default as typed on the command line or in the form ('' for None)."""
    value = f.default if f.default is not MISSING else f.default_factory()
    if value is None:
        return ""
    if isinstance(value, Material):
        return value.name
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, tuple):
        return " ".join(f"{x:g}" for x in value)
    return str(value)


def check_tools(output: OutputOptions) -> None:
    """Refuse, before any computation, outputs whose tools are missing (ffmpeg)."""
    if output.mp4:
        from matplotlib import animation

        if not animation.writers.is_available("ffmpeg"):
            raise OptionError("mp4 needs ffmpeg, which is not installed (or not on PATH): "
                              "install it, or leave out --mp4")


def file_record(path) -> dict:
    """``{"path", "sha256"}`` of an input file (a folder or pattern: its path only)."""
    path = Path(path)
    if not path.is_file():
        return {"path": os.fspath(path.absolute()), "sha256": None}
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(2**20), b""):
            digest.update(block)
    return {"path": os.fspath(path.absolute()), "sha256": digest.hexdigest()}


def input_records(inputs) -> list[dict]:
    """:func:`file_record` of every file the inputs name: a file, each file of a folder,
    each match of a glob pattern."""
    records = []
    for path in map(Path, [inputs] if isinstance(inputs, str | os.PathLike) else inputs):
        if any(c in path.name for c in "*?["):
            files = sorted(map(Path, glob.glob(os.fspath(path))))
        elif path.is_dir():
            files = sorted(p for p in path.iterdir() if p.is_file())
        else:
            files = [path]
        records.extend(file_record(p) for p in files)
    return records


def read_pair(source_path, target_path, read: ReadOptions):
    """The two shapes of a pair, read with the same options."""
    source, target = read_shape(source_path, read), read_shape(target_path, read)
    if source.dim != target.dim:
        raise ShapeError(f"{source_path} is {source.dim}D but {target_path} is "
                         f"{target.dim}D: both shapes must have the same dimension")
    check_y_directions([source_path, target_path], [source, target])
    for path, shape in ((source_path, source), (target_path, target)):
        if shape.dim == 2 and shape.ordered:  # named by its file (match() says "source")
            check_contours(shape, os.fspath(path))
    return source, target


def check_y_directions(names, shapes) -> None:
    """Warn once when 2D inputs mix y up (point files) and y down (images, SVG): the same
    outline in both conventions is its own mirror image, which a morph reaches happily."""
    flat = [(os.fspath(n), y_down(s)) for n, s in zip(names, shapes, strict=True)
            if s.dim == 2]
    up = [n for n, down in flat if not down]
    down = [n for n, down in flat if down]
    if up and down:
        warnings.warn(f"{up[0]} has y pointing up (a point file) but {down[0]} has y "
                      f"pointing down (image coordinates): the same outline in the two is "
                      f"mirrored; flip_y=True mirrors the point files' y to match",
                      stacklevel=2)


def compute_morph(source, target, settings: Settings, *, progress=None):
    """:func:`modalmorph.match` then :func:`modalmorph.morph` with the settings."""
    with limit(max(source.m, target.m)):
        matching = match(source, target, options=settings.match)
        return morph(source, target, matching=matching, options=settings.morph,
                     progress=progress)


def morph_files(source, target, out, settings: Settings | None = None, *,
                progress=None) -> ItemRun:
    """What ``modalmorph morph`` does: read two shape files, morph, write ``out``.

    ``out`` is replaced all or nothing (:func:`modalmorph.io.atomic_output_dir`), and
    missing tools are refused, before any computation. ``progress(step, distance)`` is
    called after every time step.
    """
    settings = settings or Settings()
    check_tools(settings.output)
    out = Path(out)
    with atomic_output_dir(out) as folder:  # checks out before any work
        result = compute_morph(*read_pair(source, target, settings.read), settings,
                               progress=progress)
        inputs = input_records([source, target])
        written = write_morph(result, folder, settings, inputs=inputs,
                              images=(Path(source), Path(target)))
    return ItemRun(result=result, files=tuple(out / name for name in written))


def write_morph(result, folder: Path, settings: Settings, *, inputs=(), images=None):
    """Write a morph's results and the outputs of ``settings.output`` into ``folder``;
    returns the files' paths relative to it."""
    output = settings.output
    save_result(result, folder, options=settings.record(PAIR_CLASSES),
                inputs=list(inputs))
    if output.figures or output.gif or output.mp4:
        look = dict(frames=output.frames, background=output.background)
        if output.figures:
            figures.save_figures(result, folder, formats=("png", "svg") if output.svg else
                              ("png",), **look)
        for wanted, name in ((output.gif, "morph.gif"), (output.mp4, "morph.mp4")):
            if wanted:
                figures.animate(result, folder / name, **look)
    if output.vtk:
        write_vtk_series(result, folder / "vtk")
    if output.gltf:
        write_gltf(result, folder / "morph.glb")
    if output.meshes != "none":
        write_step_meshes(result, folder / "meshes", fmt=output.meshes)
    if output.html:
        title = None if images is None else f"{images[0].name} → {images[1].name}"
        write_html(result, folder / "report.html", title=title,
                   images=input_images(*images) if images else None)
    return sorted(p.relative_to(folder) for p in folder.rglob("*") if p.is_file())


def track_files(inputs, out, settings: Settings | None = None, *, progress=None) -> ItemRun:
    """What ``modalmorph track`` does: read the frames, track, write ``out``.

    ``inputs`` is anything :func:`modalmorph.io.read_frames` reads. ``out`` is replaced
    all or nothing. ``progress(frame, None)`` is called after every frame.
    """
    settings = settings or Settings()
    output, seq = settings.output, settings.sequence
    if output.vtk or output.html or output.gltf or output.meshes != "none":
        raise OptionError("track writes no VTK, glTF, per-step meshes or HTML report: "
                          "leave out --vtk, --gltf, --meshes and --html")
    check_tools(output)
    out = Path(out)
    with atomic_output_dir(out) as tmp:
        frames = read_frames(inputs, settings.read)
        check_y_directions(frames.names, frames.shapes)
        with limit(max(shape.m for shape in frames.shapes)):
            result = track(frames.shapes, names=frames.names, options=seq,
                           match_options=settings.match
                           if seq.correspondence == "modal" else None,
                           morph_options=settings.morph, progress=progress)
        save_track(result, tmp, options=settings.record(SEQUENCE_CLASSES),
                   input_files=input_records(inputs))
        _write_track_renderings(result, tmp, output)
        names = sorted(p.relative_to(tmp) for p in tmp.rglob("*") if p.is_file())
    return ItemRun(result=result, files=tuple(out / name for name in names))


def _write_track_renderings(result, folder: Path, output: OutputOptions) -> None:
    if not (output.figures or output.gif or output.mp4):
        return
    if output.figures:
        figures.save_track_figures(result, folder)
    for wanted, name in ((output.gif, "track.gif"), (output.mp4, "track.mp4")):
        if wanted:
            figures.animate_track(result, folder / name)
