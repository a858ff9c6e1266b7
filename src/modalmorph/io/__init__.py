"""Reading shapes from files, writing points and results, and atomic output.

:func:`read_shape` picks a reader in :data:`READERS` by the file's extension:

=====================================  ==================================  ==============
extensions                             content                             module
=====================================  ==================================  ==============
``.csv`` ``.tsv`` ``.txt`` ``.xyz``    ``x, y[, z]`` per row               :mod:`.points`
``.npy`` ``.npz``                      an (m, d) array                     :mod:`.points`
``.json``                              ``[[x, y], ...]`` or an object      :mod:`.points`
``.svg``                               one outline (path, polygon, etc.)   :mod:`.svg`
``.png`` ``.tif`` ``.tiff`` ``.jpg``   one object's contours (and holes)   :mod:`.images`
``.jpeg`` ``.bmp`` ``.gif``
``.ply`` ``.obj`` ``.stl`` ``.off``    a triangle surface or point cloud   :mod:`.meshes`
``.vtk`` ``.vtu`` ``.msh`` ``.mesh``
``.nii`` ``.nii.gz``                   a label slice or volume, in mm      :mod:`.nifti`
=====================================  ==================================  ==============

Each module's docstring says what it reads, in detail. SVG and images need svgelements,
scikit-image and pillow, meshes meshio (dependencies of modalmorph, imported when read);
NIfTI needs nibabel (optional: ``pip install 'modalmorph[nifti]'``).
The other modules: :mod:`.sequences` (the frames of :func:`read_frames`), :mod:`.results`
(:func:`save_result`, :func:`save_track`), :mod:`.atomic` (atomic output, used by every
writer), :mod:`.vtk` (:func:`write_vtk_series`), :mod:`.gltf` (:func:`write_gltf`: an
animated glTF 2.0 file), :mod:`.steps` (:func:`write_step_meshes`: PLY or OBJ per step),
:mod:`.guard` (the read's deadline and errors) and :mod:`.base`
(:class:`~.base.RawShape`, what every reader returns).

Every problem with a file is an :class:`~modalmorph.errors.InputFileError` (a
``ValueError``) whose message starts with the file's name, so the command line can print
it as it is: third-party parsers' own exceptions, memory errors for absurd sizes and a
parse that runs past :data:`~.guard.READ_SECONDS` included (read there: set it in
:mod:`.guard`). The read options are
:class:`~modalmorph.options.ReadOptions`, which validates them.

Output folders are written whole (:func:`atomic_output_dir`): built in a hidden sibling
``.NAME.modalmorph-tmp-PID-XXXX`` and renamed into place, so the destination is at every
instant the old complete folder, the new complete folder or absent; temporary folders
left by killed runs are removed by the next run writing beside them.

Adding a format: write ``read_x(path: Path, name: str, options: ReadOptions) ->
RawShape`` in the module of its family (or a new one), raising ``InputFileError`` with
messages that start with ``name`` and importing its third-party library inside the
function; add its extensions to :data:`READERS` below and a line to the table above.
:func:`read_shape` does the rest: the file checks, the deadline, the closing repeat,
resampling and the :class:`~modalmorph.core.shape.Shape`.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np

from ..core.shape import Shape
from ..errors import InputFileError, OptionError
from ..options import ReadOptions
from .atomic import (
    OUTPUT_MARKER,
    OUTPUT_MARKERS,
    atomic_output_dir,
    atomic_write,
    remove_leftovers,
)
from .base import (
    DEFAULT_NODES,
    FLIPPED_FRAME,
    OPEN_LOOKING,
    UNEVEN_SPACING,
    RawShape,
    Reader,
    extension,
    looks_open,
    make_shape,
    uneven_nodes,
    y_down,
)
from .gltf import write_gltf
from .guard import READ_SECONDS, guarded, read_guarded
from .images import (
    INSIDE_FRACTION,
    MAX_PARTIAL_ALPHA,
    MIN_HOLE_AREA,
    MIN_OBJECT_PIXELS,
    mask_shape,
    read_image,
)
from .meshes import read_mesh
from .nifti import read_nifti
from .points import read_json, read_npy, read_npz, read_text, read_xyz, write_points
from .results import result_summary, save_result, save_track
from .sequences import Frames, check_grids, file_frames, sequence_files
from .steps import MESH_FORMATS, write_step_meshes
from .svg import SVG_FRAME, read_svg
from .vtk import write_vtk_series

__all__ = [
    "DEFAULT_NODES",
    "Frames",
    "INSIDE_FRACTION",
    "MAX_PARTIAL_ALPHA",
    "MIN_HOLE_AREA",
    "MESH_FORMATS",
    "MIN_OBJECT_PIXELS",
    "OPEN_LOOKING",
    "OUTPUT_MARKER",
    "OUTPUT_MARKERS",
    "READERS",
    "READ_SECONDS",
    "RawShape",
    "SUPPORTED_EXTENSIONS",
    "SVG_FRAME",
    "UNEVEN_SPACING",
    "atomic_output_dir",
    "atomic_write",
    "mask_shape",
    "read_frames",
    "read_shape",
    "remove_leftovers",
    "result_summary",
    "save_result",
    "save_track",
    "write_points",
    "write_gltf",
    "write_step_meshes",
    "write_vtk_series",
    "y_down",
]

_log = logging.getLogger(__name__)

# THE reader table: a file's extension (lower case) -> the function reading it.
READERS: dict[str, Reader] = {
    ".csv": read_text, ".tsv": read_text, ".txt": read_text, ".xyz": read_xyz,
    ".npy": read_npy, ".npz": read_npz,
    ".json": read_json,
    ".svg": read_svg,
    ".png": read_image, ".tif": read_image, ".tiff": read_image, ".jpg": read_image,
    ".jpeg": read_image, ".bmp": read_image, ".gif": read_image,
    ".nii": read_nifti, ".nii.gz": read_nifti,
    ".ply": read_mesh, ".obj": read_mesh, ".stl": read_mesh, ".off": read_mesh,
    ".vtk": read_mesh, ".vtu": read_mesh, ".msh": read_mesh, ".mesh": read_mesh,
}
SUPPORTED_EXTENSIONS = tuple(READERS)


def read_shape(path, options: ReadOptions | None = None, *, closed: bool | None = None,
               **overrides) -> Shape:
    """Read a shape from a file, choosing the reader by the file's extension.

    Parameters
    ----------
    path : str or os.PathLike
        The file; the formats, by extension, are in the module's docstring
        (:data:`SUPPORTED_EXTENSIONS`). A final row repeating the first (a contour written
        closed) is dropped.
    options : ReadOptions, optional
        How to read it: ``nodes`` (resample a 2D contour to this many nodes, equally
        spaced by arc length; default the file's nodes for point files, unless they are
        unevenly spaced (the longest edge over :data:`UNEVEN_SPACING` times the median:
        then ``max(DEFAULT_NODES, m)``, logged), and :data:`DEFAULT_NODES` for images and
        SVG; not allowed for 3D shapes), ``flip_y`` (2D point files: mirror y into image
        coordinates, y down, as images and SVG: for inputs mixing the two),
        ``open_curves`` (the contours of a point file that does not say are open curves;
        closed, such a file whose closing edge is over :data:`OPEN_LOOKING` times its
        median edge warns),
        ``threshold`` (images only: grey level separating the object from the
        background, in the image's own units, 0-255 for 8-bit images) and ``object``
        (images and SVG: which object or outline to take, ``"largest"`` (in images, not
        touching the border if a large enough one does not), ``"center"`` (nearest the
        image's or page's centre), ``"all"`` or a number, 1 = the first in reading order
        (in SVG, drawn); the choice is logged).
    closed : bool, optional
        Whether a contour closes on itself; overrides the file (an SVG path's ``Z``, a
        JSON ``"closed"``) and ``open_curves``. Defaults to closed.
    **overrides
        Fields of ``options`` by name: ``read_shape(p, nodes=80, threshold=0.5)``.

    Returns
    -------
    Shape
        2D shapes are ordered contours; 3D shapes are surfaces (with ``faces``) or point
        clouds. Shapes from images and SVG carry an :class:`~modalmorph.core.shape.ImageFrame`
        (y down; the image file, drawn under the figures).

    Raises
    ------
    InputFileError
        Whenever the file cannot give a valid shape: missing, empty, unknown extension,
        non-numeric or non-finite values (with the line or node), wrong number of
        columns, fewer than 3 nodes, an image with no object, an unreadable image, SVG or
        mesh. The message starts with the file's name.
    OptionError
        If an option is unknown or out of range.
    """
    opts = _read_options(options, overrides)
    name = os.fspath(path)
    path = Path(path)
    raw = read_guarded(_reader(path, name, opts), path, name, opts)
    # a point file that does not say whether it closes (not an outline traced on an image
    # or an SVG drawing, not a mesh): open_curves decides, closed by default
    unsaid = closed is None and raw.closed is None and raw.default_nodes is None and (
        raw.faces is None)
    if closed is None:
        closed = not opts.open_curves if unsaid else raw.closed is not False
    pts, contours = raw.points, raw.contours
    if raw.drop_closing_repeat and raw.faces is None:
        pts, contours = _drop_repeats(pts, contours, name)
    if closed and unsaid:
        looks_open(name, pts, contours)
    frame = raw.frame
    if opts.flip_y and frame is None and pts.ndim == 2 and pts.shape[1] == 2:
        pts, frame = pts * [1.0, -1.0], FLIPPED_FRAME  # y up -> image coordinates
    nodes = opts.nodes or raw.default_nodes
    if nodes is None and raw.faces is None:
        nodes = uneven_nodes(name, pts, closed, contours)
    return make_shape(name, pts, faces=raw.faces, nodes=nodes, closed=closed, frame=frame,
                      contours=contours)


def _drop_repeats(pts: np.ndarray, contours, name: str) -> tuple[np.ndarray, tuple | None]:
    """Each contour's nodes that repeat the node before them exactly (a digitiser's or an
    exporter's doubled points; said in the log) and its last node where it repeats its
    first (written closed), dropped: they carry no shape, and a model of two nodes at one
    place has no solution."""
    sizes = contours or (len(pts),)
    ends = np.cumsum(sizes)
    keep = np.ones(len(pts), dtype=bool)
    keep[1:] = np.any(pts[1:] != pts[:-1], axis=1)
    keep[ends[:-1]] = True  # a contour's first node never repeats the last contour's
    doubled = int(np.count_nonzero(~keep))
    for k, end in zip(sizes, ends, strict=True):
        kept = np.flatnonzero(keep[end - k:end]) + end - k if end <= len(pts) else []
        if len(kept) > 1 and np.array_equal(pts[kept[0]], pts[kept[-1]]):
            keep[kept[-1]] = False  # its last node kept, where it repeats its first
    if keep.all() or np.count_nonzero(keep) < 3:  # a point: the shape's check says so
        return pts, contours
    if doubled:
        _log.info("%s: %d node(s) repeating the node before them dropped", name, doubled)
    if contours is None:
        return pts[keep], None
    return pts[keep], tuple(int(np.count_nonzero(keep[e - k:e])) for k, e in zip(
        sizes, ends, strict=True))


def _read_options(options: ReadOptions | None, overrides: dict) -> ReadOptions:
    """The :class:`ReadOptions` of a call: ``options`` (default ones when None) with the
    keyword ``overrides`` of its fields."""
    if options is None:
        options = ReadOptions()
    elif not isinstance(options, ReadOptions):
        raise OptionError(f"options must be a ReadOptions, got {type(options).__name__}")
    return options.replace(**overrides) if overrides else options


def _reader(path: Path, name: str, options: ReadOptions) -> Reader:
    """The reader of the file at ``path``, after checking the file is there to read."""
    if not path.exists():
        raise InputFileError(f"{name}: no such file")
    if path.is_dir():
        raise InputFileError(f"{name}: is a directory, not a file")
    ext = extension(path)
    if ext not in READERS:
        raise InputFileError(f"{name}: unknown file extension {path.suffix!r}; supported: "
                             f"{', '.join(SUPPORTED_EXTENSIONS)}")
    if path.stat().st_size == 0:
        raise InputFileError(f"{name}: the file is empty")
    for option in ("threshold", "label"):
        if getattr(options, option) is not None and READERS[ext] not in (read_image,
                                                                          read_nifti):
            raise InputFileError(f"{name}: {option}= applies to images only, not {ext} "
                                 f"files")
    return READERS[ext]


def read_frames(inputs, options: ReadOptions | None = None, **overrides) -> Frames:
    """Read a sequence of shapes (frames) from files.

    Parameters
    ----------
    inputs : str, os.PathLike or a sequence of them
        Either several files, one frame each (any format of :func:`read_shape`), or one of:

        - a folder: its files with a supported extension (images or CSVs, ...), in natural
          order (``frame2`` before ``frame10``);
        - a glob pattern (``"masks/*.png"``), in natural order;
        - a multi-page TIFF or an animated GIF: one mask or grey image per page;
        - a NIfTI file (``.nii``, ``.nii.gz``) of a 2D+t label volume, in mm (see
          :mod:`.nifti`);
        - an ``.npy`` file, or an ``.npz`` file's ``points`` (or only) array: an
          (F, n, d) array of F shapes of n nodes (d = 2 or 3), or an (F, H, W) stack of
          masks or grey images;
        - a CSV/TSV/TXT file with a header naming a ``frame`` column and ``x``, ``y``
          (``z``): one frame per value of ``frame``, in increasing order.
    options : ReadOptions, optional
        As in :func:`read_shape`: ``threshold`` (grey images: level separating the object
        from the background), ``nodes`` (resample 2D contours to this many nodes; default:
        as in the file, 200 for images) and ``object`` (images: which object of each frame
        to outline).
    **overrides
        Fields of ``options`` by name.

    Returns
    -------
    Frames

    Raises
    ------
    InputFileError
        When an input cannot be read, gives fewer than 2 frames, a frame is not a valid
        shape, or frames read from images differ in size or (NIfTI) pixel spacing; the
        message starts with the frame's name (file, page or index).
    OptionError
        If an option is unknown or out of range.
    """
    opts = _read_options(options, overrides)
    paths = [inputs] if isinstance(inputs, str | os.PathLike) else list(inputs)
    if not paths:
        raise InputFileError("inputs: no file given")
    if len(paths) == 1:
        names, shapes, files = _frames_of(paths[0], opts)
    else:
        names = files = [os.fspath(p) for p in paths]
        shapes = [read_shape(p, opts) for p in paths]
    check_grids(names, shapes, files)
    if len(shapes) < 2:
        raise InputFileError(f"{names[0] if names else os.fspath(paths[0])}: a sequence "
                             f"needs at least 2 frames, got {len(shapes)}")
    return Frames(shapes=tuple(shapes), names=tuple(names))


def _frames_of(path, options: ReadOptions) -> tuple[list, list]:
    """(names, shapes, files) of the frames of one input: a pattern, a folder (a file per
    frame) or a file (``files`` None)."""
    files = sequence_files(path, SUPPORTED_EXTENSIONS)
    if files is not None:
        names = [os.fspath(f) for f in files]
        return names, [read_shape(f, options) for f in files], names
    size = Path(path).stat().st_size if Path(path).is_file() else 0
    with guarded(os.fspath(path), size):  # a file of several frames: read as read_shape's
        return (*file_frames(path, options, read_shape), None)
