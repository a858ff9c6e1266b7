"""Sequences of shapes (frames): the files of a glob pattern or a folder, and the files
that hold several frames (multi-page TIFF, animated GIF, NPY/NPZ stacks, text with a
``frame`` column).

:func:`modalmorph.io.read_frames` is the entry point; it reads single-frame files with
:func:`modalmorph.io.read_shape`, which it passes to :func:`file_frames`.
"""

from __future__ import annotations

import dataclasses
import glob
import os
import re
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..core.shape import ImageFrame, Shape
from ..errors import InputFileError
from ..options import ReadOptions
from .base import DEFAULT_NODES, extension, make_shape
from .images import grey_levels, image_contours
from .nifti import NIFTI_EXTENSIONS, nifti_frames, nifti_grid
from .points import TEXT_SEPARATORS, contour_runs, load_npy, npz_arrays, parse_float

__all__ = ["Frames", "check_grids", "file_frames", "image_pages", "natural_key",
           "sequence_files"]

# The files that may hold several frames (by extension); any other is one frame.
_STACKS = (".npy", ".npz")
_TABLES = tuple(TEXT_SEPARATORS)
_PAGED = (".tif", ".tiff", ".gif")


@dataclasses.dataclass(frozen=True)
class Frames:
    """A sequence of shapes read from files, with a name per frame for messages.

    Attributes
    ----------
    shapes : tuple of Shape
        The frames in time order.
    names : tuple of str
        Where each frame came from: a file, ``file[page 3]``, ``file[3]`` or
        ``file[frame 5]``.
    """

    shapes: tuple
    names: tuple


def natural_key(path) -> list:
    """Sort key putting ``frame2`` before ``frame10``."""
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", os.fspath(path))]


def sequence_files(path, extensions) -> list | None:
    """The files of a glob pattern (that is not a file's name) or of a folder (those with
    one of ``extensions``, not hidden), in natural order; None for anything else."""
    name = os.fspath(path)
    if any(c in name for c in "*?[") and not Path(path).exists():
        files = sorted(glob.glob(name), key=natural_key)
        if not files:
            raise InputFileError(f"{name}: no file matches the pattern")
        return files
    path = Path(path)
    if not path.is_dir():
        return None
    files = sorted((p for p in path.iterdir() if p.is_file() and not p.name.startswith(".")
                    and extension(p) in extensions), key=natural_key)
    if not files:
        raise InputFileError(f"{name}: no shape file in the folder (extensions: "
                             f"{', '.join(extensions)})")
    return files


def file_frames(path, options: ReadOptions,
                read: Callable[[Path, ReadOptions], Shape]) -> tuple[list, list]:
    """(names, shapes) of the frames in one file; ``read`` reads a file of one frame."""
    name = os.fspath(path)
    path = Path(path)
    ext = extension(path)
    if not path.exists() or path.stat().st_size == 0 or ext not in (*_STACKS, *_TABLES,
                                                                    *_PAGED,
                                                                    *NIFTI_EXTENSIONS):
        return [name], [read(path, options)]
    if ext in NIFTI_EXTENSIONS:
        frames = nifti_frames(path, name, options)
        return [n for n, _ in frames], [
            make_shape(n, raw.points, nodes=options.nodes or raw.default_nodes,
                       frame=raw.frame, contours=raw.contours) for n, raw in frames]
    if ext in _PAGED:
        pages = image_pages(path, name)
        if len(pages) == 1:
            return [name], [read(path, options)]
        return _image_frames(pages, f"{name}[page {{}}]", options)
    if ext in _TABLES:
        return _csv_frames(path, name, options, read)
    array = load_npy(path, name) if ext == ".npy" else npz_arrays(path, name)[0]
    array = array.astype(np.uint8) if array.dtype == bool else array  # a stack of masks
    if array.dtype.kind not in "iuf":
        raise InputFileError(f"{name}: the array must be numeric, got dtype {array.dtype}")
    if array.ndim != 3:
        return [name], [read(path, options)]
    if array.shape[-1] in (2, 3):  # (F, n, d): F shapes
        if options.threshold is not None:
            raise InputFileError(f"{name}: threshold= applies to images, not to an (F, n, "
                                 f"{array.shape[-1]}) array of points")
        names = [f"{name}[{f}]" for f in range(len(array))]
        return names, [make_shape(n, a, nodes=options.nodes)
                       for n, a in zip(names, array, strict=True)]
    return _image_frames(list(array), f"{name}[{{}}]", options)


def check_grids(names, shapes, files=None) -> None:
    """InputFileError naming the first frame whose image size (or, for NIfTI files among
    ``files``, pixel spacing) differs from the first image frame's: the frames of a
    sequence share one pixel grid, or their coordinates do not compare."""
    grids = []  # (name, size, spacing) of the frames read from an image
    for k, shape in enumerate(shapes):
        size = getattr(shape.frame, "size", None)
        if size is not None:
            nifti = files is not None and extension(files[k]) in NIFTI_EXTENSIONS
            grids.append((names[k], size, nifti_grid(Path(files[k]), names[k])[1] if nifti
                          else None))
    for name, size, spacing in grids[1:]:
        first, size0, spacing0 = grids[0]
        if size != size0:
            raise InputFileError(f"{name}: the image is {size[1]} x {size[0]} px, the first "
                                 f"frame ({first}) {size0[1]} x {size0[0]} px: the frames of "
                                 f"a sequence share one pixel grid")
        if spacing != spacing0:
            raise InputFileError(f"{name}: pixel spacing {spacing[0]:g} x {spacing[1]:g}, "
                                 f"the first frame ({first}) {spacing0[0]:g} x "
                                 f"{spacing0[1]:g}: the frames of a sequence share one pixel "
                                 f"grid")


def image_pages(path: Path, name: str) -> list:
    """The grey levels (H, W) of every page of an image file (one for PNG)."""
    from PIL import Image, ImageSequence

    try:
        with Image.open(path) as image:
            return [grey_levels(page.copy()) for page in ImageSequence.Iterator(image)]
    except (OSError, ValueError) as exc:
        raise InputFileError(f"{name}: cannot read the image: {exc}") from None


def _image_frames(images, pattern: str, options: ReadOptions):
    """(names, shapes) of a stack of images (pages, or an (F, H, W) array): in pixels, y
    down, with no image file to draw under them."""
    names = [pattern.format(f) for f in range(len(images))]
    shapes = []
    for n, g in zip(names, map(np.asarray, images), strict=True):
        parts = image_contours(g, n, options)
        shapes.append(make_shape(n, np.vstack(parts), nodes=options.nodes or DEFAULT_NODES,
                                 frame=ImageFrame(size=g.shape),
                                 contours=tuple(map(len, parts)) if len(parts) > 1 else None))
    return names, shapes


def _csv_frames(path: Path, name: str, options: ReadOptions, read):
    """One frame per value of the ``frame`` column of a text file with a header (a
    ``contour`` column splits each frame into contours); the file as one frame (read with
    ``nodes`` only) when it has no such column."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        text = ""  # not text: the reader of one frame says so
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    sep = next((s for s in ("\t", ";", ",") if s in lines[0]), None) if lines else None
    header = [h.strip().strip("\"'").lower() for h in lines[0].split(sep)] if lines else []
    if "frame" not in header:
        return [name], [read(path, ReadOptions(nodes=options.nodes))]
    if "x" not in header or "y" not in header:
        raise InputFileError(f"{name}: a 'frame' column needs 'x' and 'y' columns too, got "
                             f"{header}")
    cols = [header.index(c) for c in ("frame", "x", "y", "z", "contour") if c in header]
    rows = []
    for lineno, line in enumerate(lines[1:], start=2):
        parts = line.split(sep)
        try:
            rows.append([parse_float(parts[c]) for c in cols])
        except (ValueError, IndexError):
            raise InputFileError(f"{name}: data line {lineno}: cannot read the frame and "
                                 f"coordinates from {line.strip()!r}") from None
    table = np.array(rows).reshape(-1, len(cols))
    values = np.unique(table[:, 0])
    names = [f"{name}[frame {v:g}]" for v in values]
    contour = "contour" in header  # the last column: each frame's contours
    rows = [table[table[:, 0] == v, 1:] for v in values]
    return names, [make_shape(n, r[:, :-1] if contour else r, nodes=options.nodes,
                              contours=contour_runs(n, r[:, -1]) if contour else None)
                   for n, r in zip(names, rows, strict=True)]
