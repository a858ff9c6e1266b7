"""Reading shapes from files, writing points and results, and atomic output.

:func:`read_shape` picks a reader by the file's extension:

=====================================  ==================================  ===============
extensions                             content                             needs
=====================================  ==================================  ===============
``.csv`` ``.tsv`` ``.txt``             ``x, y[, z]`` per row               numpy
``.npy`` ``.npz``                      an (m, d) array                     numpy
``.json``                              ``[[x, y], ...]`` or an object      numpy
``.svg``                               the first path, polygon, etc.       ``[images]``
``.png`` ``.tif`` ``.tiff`` ``.jpg``   one object's outer contour          ``[images]``
``.jpeg`` ``.bmp``
``.ply`` ``.obj`` ``.stl`` ``.off``    a triangle surface or point cloud   ``[mesh]``
``.vtk`` ``.vtu`` ``.msh`` ``.mesh``
=====================================  ==================================  ===============

In detail:

- text: one node per line, ``x, y`` or ``x, y, z``, separated by commas, tabs, semicolons
  or spaces (with semicolons a decimal comma is accepted). An optional first line of
  column names; if it names columns ``x`` and ``y`` (and ``z``), those columns are used
  and others ignored. Blank lines and lines starting with ``#`` are skipped.
- ``.npy``: an (m, 2) or (m, 3) array; ``.npz``: the array ``points`` (or the only array
  in the file), and optionally ``faces`` and ``closed``.
- ``.json``: a list ``[[x, y], ...]`` or an object ``{"points": [...], "closed": bool,
  "faces": [[i, j, k], ...]}`` (``closed`` and ``faces`` optional).
- ``.svg``: the first ``<path>``, ``<polygon>``, ``<polyline>``, ``<circle>``,
  ``<ellipse>`` or ``<rect>`` drawn (not in ``<defs>``; transforms applied; for a path
  with several subpaths, the first), read with svgelements and sampled uniformly by arc
  length. Closed if it ends with ``Z``, is a polygon, circle, ellipse or rect, or ends
  where it starts. Coordinates are the file's user units (before any ``viewBox``
  scaling), y pointing down (:data:`SVG_FRAME`).
- images: the outer contour of one object, in pixel coordinates ``(x, y) = (column,
  row)``, y pointing down (the shape's :class:`~modalmorph.core.shape.ImageFrame` names the
  image, drawn under the figures). A two-level image is a mask; a grey-level image needs
  ``threshold``. Whichever side covers most of the image border is the background, so
  dark objects on a light background work too. Colour is converted to grey; an alpha
  channel is the mask only when it is one (:data:`MIN_OBJECT_PIXELS`,
  :data:`MAX_PARTIAL_ALPHA`). Of the mask's 4-connected objects, ``object="largest"``
  takes the largest, but one inside the image over a larger one touching the border
  (:data:`INSIDE_FRACTION`); ``"center"`` the one nearest the image centre; a number,
  that object in reading order. The choice is logged (its area, whether it touches the
  border).
- meshes: a 3D surface (points and triangles; quads and polygons are split into
  triangles; unreferenced and exactly repeated points dropped) or, with no surface cells,
  a point cloud of all its points.

Every problem with a file is a :class:`ValueError` whose message starts with the file's
name, so the command line can print it as it is: third-party parsers' own exceptions,
memory errors for absurd sizes and a parse that runs past :data:`READ_SECONDS` included.

Output folders are written whole (:func:`atomic_output_dir`): built in a hidden sibling
``.NAME.modalmorph-tmp-PID-XXXX`` and renamed into place, so the destination is at every
instant the old complete folder, the new complete folder or absent; temporary folders
left by killed runs are removed by the next run writing beside them.
"""

from __future__ import annotations

import dataclasses
import glob
import json
import logging
import math
import os
import re
import shutil
import signal
import sys
import tempfile
import threading
import warnings
import xml.etree.ElementTree as ET
import zipfile
from contextlib import contextmanager, redirect_stderr, redirect_stdout, suppress
from io import StringIO
from pathlib import Path

import numpy as np

from ..core.quality import area
from ..core.shape import ImageFrame, Shape, resample
from ..options import OBJECTS, parameters
from ..version import __version__
from .vtk import write_vtk_series

__all__ = [
    "write_vtk_series",
    "DEFAULT_NODES",
    "Frames",
    "INSIDE_FRACTION",
    "MAX_PARTIAL_ALPHA",
    "MIN_OBJECT_PIXELS",
    "OUTPUT_MARKER",
    "OUTPUT_MARKERS",
    "READ_SECONDS",
    "SUPPORTED_EXTENSIONS",
    "SVG_FRAME",
    "atomic_output_dir",
    "atomic_write",
    "read_frames",
    "read_shape",
    "remove_leftovers",
    "result_summary",
    "save_result",
    "save_track",
    "write_points",
]

# Nodes sampled along an image contour or an SVG path when ``nodes`` is not given.
DEFAULT_NODES = 200

_TEXT = (".csv", ".tsv", ".txt")
_ARRAY = (".npy", ".npz")
_IMAGE = (".png", ".tif", ".tiff", ".jpg", ".jpeg", ".bmp")
_MESH = (".ply", ".obj", ".stl", ".off", ".vtk", ".vtu", ".msh", ".mesh")
SUPPORTED_EXTENSIONS = (*_TEXT, *_ARRAY, ".json", ".svg", *_IMAGE, *_MESH)
_WRITABLE = (".csv", ".tsv", ".txt", ".npy", ".npz", ".json")

# A read that takes longer than this is stopped (a parser stuck on a malformed file): base
# seconds plus seconds per MB. The slowest reader measured, meshio on ASCII PLY, takes
# 0.12 s per MB (100k vertices and 200k triangles, 9.8 MB, 1.17 s on a loaded 2-core
# machine; OBJ 0.075, Gmsh 0.061, OFF and VTK 0.02 s/MB): a margin of about 17x.
READ_SECONDS = 10.0
_READ_SECONDS_PER_MB = 2.0

# Points per segment when an SVG segment is flattened before arc-length resampling; the
# chord error of a quarter circle sampled this finely is below 1e-4 of its radius.
_SVG_SAMPLES = 128

# SVG coordinates are the file's user units, y pointing down (no image to draw under them).
SVG_FRAME = ImageFrame(unit="SVG user units")

# Images: an object inside the image is taken over a larger one touching the border when
# its area is at least this fraction of the larger one's. A choice, not a measurement: an
# object the user means is rarely ten times smaller than a strip cut by the border, while
# specks of a noisy threshold (a few px) are far below it and never outrank a large object.
INSIDE_FRACTION = 0.1
# An alpha channel is read as the mask only when at least this many pixels are opaque
# and as many transparent (an outline of >= 3 nodes needs a 2 x 2 block at least: 3 x 3
# keeps a margin) and at most this fraction of the pixels is partly transparent, between 10
# and 90 % opacity. Measured on 256 x 256 images: the antialiased edge of a disc of radius
# 100 px covers 0.73 % of the pixels (radius 50: 0.36 %); a radial vignette 89 %.
MIN_OBJECT_PIXELS = 9
MAX_PARTIAL_ALPHA = 0.2

_log = logging.getLogger(__name__)


# --------------------------------------------------------------------------------------
# reading


def read_shape(path, *, nodes: int | None = None, threshold: float | None = None,
               object: str | int = "largest", closed: bool | None = None) -> Shape:
    """Read a shape from a file, choosing the reader by the file's extension.

    Parameters
    ----------
    path : str or os.PathLike
        The file; the formats, by extension, are in the module's docstring
        (:data:`SUPPORTED_EXTENSIONS`). A final row repeating the first (a contour written
        closed) is dropped.
    nodes : int, optional
        Resample a 2D contour to this many nodes, equally spaced by arc length. Defaults to
        the file's nodes for point files and to :data:`DEFAULT_NODES` for images and SVG.
        Not allowed for 3D shapes.
    threshold : float, optional
        Images only: grey level separating the object from the background, in the
        image's own units (0-255 for 8-bit images).
    object : {"largest", "center"} or int, optional
        Images only: which object to outline (:func:`choose_object`): the largest (not
        touching the border if a large enough one does not), the one nearest the image
        centre, or a label number (1 = the first in reading order). The choice is logged.
    closed : bool, optional
        Whether a contour closes on itself; overrides the file (an SVG path's ``Z``, a
        JSON ``"closed"``). Defaults to closed.

    Returns
    -------
    Shape
        2D shapes are ordered contours; 3D shapes are surfaces (with ``faces``) or point
        clouds. Shapes from images and SVG carry an :class:`~modalmorph.core.shape.ImageFrame`
        (y down; the image file, drawn under the figures).

    Raises
    ------
    ValueError
        Whenever the file cannot give a valid shape: missing, empty, unknown extension,
        non-numeric or non-finite values (with the line or node), wrong number of
        columns, fewer than 3 nodes, an image with no object, an unreadable image, SVG or
        mesh. The message starts with the file's name.
    """
    name = os.fspath(path)
    path = Path(path)
    ext = _check_read_args(path, name, nodes, threshold, object)
    pts, faces, file_closed, frame = _read_guarded(path, name, ext, (threshold, object))
    if ext in _IMAGE or ext == ".svg":
        nodes = nodes or DEFAULT_NODES
    if closed is None and ext not in _MESH:  # (meshes: unordered, never closed)
        closed = True if file_closed is None else file_closed
    if ext not in _MESH and faces is None and len(pts) > 1 and np.array_equal(pts[0], pts[-1]):
        pts = pts[:-1]  # a closed contour written with its first node repeated
    return _make_shape(name, pts, faces=faces, nodes=nodes, closed=closed, frame=frame)


def _check_read_args(path: Path, name: str, nodes, threshold, choice) -> str:
    """Validate :func:`read_shape`'s options and the file's presence; its extension."""
    if nodes is not None and (isinstance(nodes, bool) or not isinstance(nodes, int | np.integer)
                              or nodes < 3):
        raise ValueError(f"nodes must be an integer >= 3, got {nodes!r}")
    if threshold is not None and (isinstance(threshold, bool) or not (
            isinstance(threshold, int | float | np.number) and math.isfinite(threshold))):
        raise ValueError(f"threshold must be a finite number, got {threshold!r}")
    _check_object(choice)
    if not path.exists():
        raise ValueError(f"{name}: no such file")
    if path.is_dir():
        raise ValueError(f"{name}: is a directory, not a file")
    ext = path.suffix.lower()
    if ext not in SUPPORTED_EXTENSIONS:
        raise ValueError(f"{name}: unknown file extension {path.suffix!r}; supported: "
                         f"{', '.join(SUPPORTED_EXTENSIONS)}")
    if path.stat().st_size == 0:
        raise ValueError(f"{name}: the file is empty")
    if threshold is not None and ext not in _IMAGE:
        raise ValueError(f"{name}: threshold= applies to images only, not {ext} files")
    return ext


def _check_object(choice) -> None:
    label = isinstance(choice, int | np.integer) and not isinstance(choice, bool)
    if not (choice in OBJECTS or label and choice >= 1):
        raise ValueError(f"object must be 'largest', 'center' or a label number >= 1, "
                         f"got {choice!r}")


def _read_file(path: Path, name: str, ext: str, image_options):
    """(points, faces or None, closed or None, ImageFrame or None) from the reader."""
    if ext in _IMAGE:
        pts, size = _read_image(path, name, *image_options)
        return pts, None, None, ImageFrame(image=os.fspath(path), size=size)
    if ext == ".svg":
        pts, closed = _read_svg(path, name)
        return pts, None, closed, SVG_FRAME
    if ext in _MESH:
        return (*_read_mesh(path, name), None, None)
    if ext in _TEXT:
        return _read_text(path, name), None, None, None
    if ext == ".npy":
        return _read_npy(path, name), None, None, None
    if ext == ".npz":
        return (*_read_npz(path, name), None)
    return (*_read_json(path, name), None)


def _read_guarded(path: Path, name: str, ext: str, image_options):
    """Run the reader with bounded time; every failure a ValueError naming the file.

    Third-party parsers raise many types for a malformed file (and numpy a MemoryError for
    an absurd size in a header); they are reported as the file's problem. A parse that runs
    past its deadline (:data:`READ_SECONDS`, more for large files) is interrupted.
    """
    seconds = READ_SECONDS + _READ_SECONDS_PER_MB * path.stat().st_size / 1e6
    try:
        with _deadline(seconds):
            return _read_file(path, name, ext, image_options)
    except ImportError:
        raise
    except _ReadTimeout:
        raise ValueError(f"{name}: cannot read it: the reader did not finish within "
                         f"{seconds:.0f} s (a malformed file?)") from None
    except ValueError as exc:
        if str(exc).startswith(name):
            raise
        raise ValueError(f"{name}: {exc}") from None
    except MemoryError as exc:
        raise ValueError(f"{name}: cannot read it: sizes in the file need more memory than "
                         f"there is ({exc})") from None
    except RecursionError:
        raise ValueError(f"{name}: cannot read it: nested too deeply") from None
    except Exception as exc:  # noqa: BLE001 - any parser failure is the file's problem
        raise ValueError(f"{name}: cannot read it: {type(exc).__name__}: {exc}") from None


class _ReadTimeout(BaseException):
    """Raised by the deadline's alarm; a BaseException so parsers' ``except Exception``
    clauses cannot swallow it."""


@contextmanager
def _deadline(seconds: float):
    """Interrupt the block after ``seconds`` with :class:`_ReadTimeout` (SIGALRM).

    Only in the main thread of a POSIX process with no interval timer already running;
    elsewhere the block runs without a deadline.
    """
    usable = (hasattr(signal, "setitimer") and threading.current_thread() is
              threading.main_thread() and signal.getitimer(signal.ITIMER_REAL)[0] == 0)
    if not usable:
        yield
        return

    def expire(signum, frame):
        raise _ReadTimeout

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def _make_shape(name, pts, *, faces=None, nodes=None, closed=True, frame=None) -> Shape:
    """Check an (m, d) array of coordinates from ``name``; resample; build the Shape."""
    pts = np.asarray(pts, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] not in (2, 3):
        raise ValueError(f"{name}: expected an (m, 2) or (m, 3) array of coordinates, got "
                         f"shape {pts.shape}")
    if len(pts) < 3:
        raise ValueError(f"{name}: only {len(pts)} node{'s' if len(pts) != 1 else ''}; a "
                         f"shape needs at least 3")
    if faces is not None and pts.shape[1] != 3:
        raise ValueError(f"{name}: has triangles but {pts.shape[1]}D points; triangles "
                         f"describe 3D surfaces (give a 2D contour without faces)")
    bad = np.flatnonzero(~np.isfinite(pts).all(axis=1))
    if len(bad):
        raise ValueError(f"{name}: node {bad[0]} has non-finite coordinates "
                         f"{pts[bad[0]].tolist()} ({len(bad)} such node(s))")
    if nodes is not None:
        if pts.shape[1] != 2 or faces is not None:
            raise ValueError(f"{name}: nodes= resamples 2D contours; this is a {pts.shape[1]}D "
                             f"{'surface' if faces is not None else 'point set'}")
        pts = resample(pts, int(nodes), closed=bool(closed))
    try:
        return Shape(pts, closed=bool(closed), faces=faces, frame=frame)
    except ValueError as exc:
        raise ValueError(f"{name}: {exc}") from None


def _parse_float(text: str) -> float:
    return float(text.strip().strip("\"'"))


def _read_text(path: Path, name: str) -> np.ndarray:
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ValueError(f"{name}: not a text file (cannot decode it as UTF-8: "
                         f"{exc.reason} at byte {exc.start})") from None
    lines = [(i, line.strip()) for i, line in enumerate(text.splitlines(), start=1)]
    lines = [(i, line) for i, line in lines if line and not line.startswith("#")]
    if not lines:
        raise ValueError(f"{name}: the file has no data")

    first = lines[0][1]
    sep = next((s for s in ("\t", ";", ",") if s in first), None)

    def fields(line):
        parts = line.split(sep) if sep else line.split()
        parts = [p.strip() for p in parts]
        return [p.replace(",", ".") for p in parts] if sep == ";" else parts

    columns = None  # indices of x, y[, z] when a header names them
    header_line, header = lines[0][0], fields(first)
    if not any(_is_number(f) for f in header):
        lines = lines[1:]
        if not lines:
            raise ValueError(f"{name}: the file has a header line but no data")
        names = [h.strip("\"'").strip().lower() for h in header]
        if "x" in names and "y" in names:
            columns = [names.index(c) for c in ("x", "y", "z") if c in names]
        elif len(names) not in (2, 3):
            raise ValueError(f"{name}: line {header_line} (header) has {len(names)} "
                             f"columns, expected 2 or 3 (x, y[, z])")

    rows, width = [], None
    for lineno, line in lines:
        parts = fields(line)
        if width is None:
            width = len(parts)
            if columns is None and width not in (2, 3):
                raise ValueError(f"{name}: line {lineno} has {width} column"
                                 f"{'s' if width != 1 else ''}, expected 2 or 3 (x, y[, z])")
        elif len(parts) != width:
            raise ValueError(f"{name}: line {lineno} has {len(parts)} columns, expected "
                             f"{width} like line {lines[0][0]}")
        if columns is not None and max(columns) >= len(parts):
            raise ValueError(f"{name}: line {lineno} has {len(parts)} columns, fewer than "
                             f"the header names")
        row = []
        for k in columns if columns is not None else range(len(parts)):
            try:
                value = _parse_float(parts[k])
            except ValueError:
                raise ValueError(f"{name}: line {lineno}: {parts[k]!r} in column {k + 1} is "
                                 f"not a number") from None
            row.append(value)
        if not all(math.isfinite(v) for v in row):
            raise ValueError(f"{name}: line {lineno}: non-finite coordinates "
                             f"({', '.join(parts)})")
        rows.append(row)
    return np.array(rows, dtype=np.float64)


def _is_number(text: str) -> bool:
    try:
        _parse_float(text)
    except ValueError:
        return False
    return True


def _load_array(loader, path: Path, name: str, kind: str):
    try:
        return loader(path)
    except (ValueError, OSError, EOFError, zipfile.BadZipFile) as exc:
        raise ValueError(f"{name}: cannot read it as a {kind} file: {exc}") from None


def _numeric(name: str, array, what: str) -> np.ndarray:
    array = np.asarray(array)
    if array.dtype.kind not in "iuf":
        raise ValueError(f"{name}: {what} must be numeric, got an array of dtype {array.dtype}")
    if array.ndim != 2 or array.shape[1] not in (2, 3):
        got = "a scalar" if array.ndim == 0 else f"shape {array.shape}"
        raise ValueError(f"{name}: {what} must have shape (m, 2) or (m, 3), got {got}")
    return array


def _load_npy(path: Path, name: str) -> np.ndarray:
    def load(p):
        with open(p, "rb") as fh:  # np.load(path) leaks its handle when the file is bad
            return np.load(fh, allow_pickle=False)

    return _load_array(load, path, name, ".npy")


def _read_npy(path: Path, name: str) -> np.ndarray:
    return _numeric(name, _load_npy(path, name), "the array")


def _read_npz(path: Path, name: str):
    points, faces, closed = _npz_arrays(path, name)
    return _numeric(name, points, "'points'"), faces, closed


def _npz_arrays(path: Path, name: str):
    """An .npz file's ``points`` (or only) array as it is, its ``faces`` and ``closed``."""
    def load(p):
        with open(p, "rb") as fh, np.load(fh, allow_pickle=False) as data:
            return {key: data[key] for key in data.files}

    arrays = _load_array(load, path, name, ".npz")
    if "points" in arrays:
        points = arrays["points"]
    elif len(arrays) == 1:
        points = next(iter(arrays.values()))
    else:
        raise ValueError(f"{name}: no array named 'points' among {sorted(arrays)}")
    faces = arrays.get("faces") if "points" in arrays else None
    closed = arrays.get("closed") if "points" in arrays else None
    if closed is not None:
        if closed.shape != () or closed.dtype.kind not in "biu":
            raise ValueError(f"{name}: 'closed' must be one boolean, got {closed.dtype} "
                             f"{closed.shape}")
        closed = bool(closed)
    if faces is not None:
        faces = _faces(name, faces)
    return points, faces, closed


def _faces(name: str, faces) -> np.ndarray:
    try:
        faces = np.asarray(faces)
    except (ValueError, OverflowError):  # ragged lists, integers beyond int64
        faces = np.asarray(faces, dtype=object)
    if faces.size == 0:
        return None
    if faces.ndim != 2 or faces.shape[1] != 3 or faces.dtype.kind not in "iu":
        raise ValueError(f"{name}: faces must be integer triangles of shape (f, 3), got "
                         f"{faces.dtype} {faces.shape}")
    return faces


def _read_json(path: Path, name: str):
    try:
        data = json.loads(path.read_text(encoding="utf-8-sig"))
    except UnicodeDecodeError as exc:
        raise ValueError(f"{name}: not a text file (cannot decode it as UTF-8: "
                         f"{exc.reason} at byte {exc.start})") from None
    except ValueError as exc:  # JSONDecodeError, or an integer of more than 4300 digits
        raise ValueError(f"{name}: not valid JSON: {exc}") from None
    except RecursionError:
        raise ValueError(f"{name}: not readable JSON: nested too deeply") from None
    closed = faces = None
    if isinstance(data, dict):
        if "points" not in data:
            raise ValueError(f"{name}: the JSON object has no \"points\" (keys: "
                             f"{', '.join(map(repr, data))})")
        closed = data.get("closed")
        if closed is not None and not isinstance(closed, bool):
            raise ValueError(f"{name}: \"closed\" must be true or false, got {closed!r}")
        if data.get("faces") is not None:
            faces = _faces(name, data["faces"])
        data = data["points"]
    if not isinstance(data, list) or not all(isinstance(row, list) for row in data):
        raise ValueError(f"{name}: expected a list of [x, y] or [x, y, z] lists")
    if not data:
        raise ValueError(f"{name}: no points (an empty list)")
    if len({len(row) for row in data}) > 1:
        first = len(data[0])
        k = next(k for k, row in enumerate(data) if len(row) != first)
        raise ValueError(f"{name}: node {k} has {len(data[k])} coordinates, expected {first} "
                         f"like node 0")
    for k, row in enumerate(data):
        for value in row:
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ValueError(f"{name}: node {k}: {str(value)[:40]!r} is not a number")
            if isinstance(value, int) and not -1e308 < value < 1e308:
                raise ValueError(f"{name}: node {k}: an integer of {len(str(value))} digits "
                                 f"is too large for a coordinate")
    return np.array(data, dtype=np.float64), faces, closed


# -- SVG --------------------------------------------------------------------------------

# The outlines read from an SVG, in document order; svgelements gives <circle>, <ellipse>
# and <rect> as paths too.
_SVG_TAGS = ("path", "polygon", "polyline", "circle", "ellipse", "rect")


def _read_svg(path: Path, name: str):
    try:
        import svgelements as se
    except ImportError:
        raise ImportError("reading SVG needs svgelements: pip install 'modalmorph[images]'"
                          ) from None
    try:
        svg = se.SVG.parse(os.fspath(path))
    except (ET.ParseError, ValueError) as exc:
        raise ValueError(f"{name}: not a valid SVG (XML) file: {exc}") from None
    if not isinstance(svg, se.SVG):
        raise ValueError(f"{name}: not an SVG file (its root element is not <svg>)")
    kinds = tuple(getattr(se, tag.capitalize()) for tag in _SVG_TAGS)
    element = next((e for e in svg.elements() if isinstance(e, kinds)), None)  # not <defs>
    if element is None:
        raise ValueError(f"{name}: no {', '.join(f'<{t}>' for t in _SVG_TAGS[:-1])} or "
                         f"<{_SVG_TAGS[-1]}> element")
    tag = type(element).__name__.lower()
    _check_svg_source(se, element, f"{name}: <{tag}>")
    if svg.viewbox is not None:  # back from the viewport to the file's user units
        element = element * ~se.Matrix(svg.viewbox_transform)
    drawn = [list(sub) for sub in abs(se.Path(element)).as_subpaths()]  # transforms applied
    drawn = [segs for segs in drawn if len(segs) > 1]
    if not drawn:
        raise ValueError(f"{name}: the first <{tag}> has no segments")
    if len(drawn) > 1:
        warnings.warn(f"{name}: the <{tag}> has {len(drawn)} subpaths; using the first",
                      stacklevel=3)
    segments = drawn[0]
    t = np.linspace(0.0, 1.0, _SVG_SAMPLES + 1)[1:]
    pts = np.vstack([np.array(segments[0].end)[None]]
                    + [seg.npoint(t) for seg in segments[1:]])
    closed = isinstance(segments[-1], se.Close)
    keep = np.r_[True, np.any(np.diff(pts, axis=0) != 0, axis=1)]
    pts = pts[keep]  # zero-length segments add nothing to the outline
    if len(pts) > 1 and np.allclose(pts[0], pts[-1], rtol=0, atol=1e-12 * np.abs(pts).max()):
        pts, closed = pts[:-1], True  # ends where it starts
    return pts, closed


def _check_svg_source(se, element, where: str) -> None:
    """Raise for what svgelements, like a browser, skips: bad path data, points, transforms."""
    d = element.values.get("d")
    if d is not None:
        lexer = se.SVGLexicalParser()
        try:
            lexer.parse(se.Path(), d)
            ok = not d[lexer.pos:].strip(" \t\r\n,")
        except ValueError:
            ok = False
        if not ok:
            raise ValueError(f"{where}: malformed path data at character {lexer.pos} of d: "
                             f"{d[lexer.pos:lexer.pos + 10] or 'the end'!r}")
        if d.strip()[:1] not in ("M", "m"):
            raise ValueError(f"{where}: path data must start with M or m, got {d[:20]!r}")
    for attr, grammar in (("points", se.REGEX_COORD_PAIR),
                          ("transform", se.REGEX_TRANSFORM_TEMPLATE)):
        rest = grammar.sub(" ", element.values.get(attr, "").lower()).strip(" \t\r\n,")
        if rest:
            raise ValueError(f"{where}: cannot read {rest[:20]!r} in {attr!r}")


# -- images -----------------------------------------------------------------------------


def _read_image(path: Path, name: str, threshold: float | None, choice="largest"):
    """The outline (m, 2) of the chosen object of an image file, and its (height, width)."""
    try:
        import skimage.measure  # noqa: F401  (the contour of the mask, below)
        from PIL import Image, UnidentifiedImageError
    except ImportError as exc:
        raise ImportError(f"reading images needs scikit-image and pillow ({exc}); install "
                          f"them with: pip install 'modalmorph[images]'") from None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            with Image.open(path) as image:
                grey = _grey_levels(image, name)
    except (OSError, UnidentifiedImageError, Image.DecompressionBombWarning,
            Image.DecompressionBombError, ValueError) as exc:
        raise ValueError(f"{name}: cannot read the image: {exc}") from None
    return _image_contour(grey, name, threshold, choice), grey.shape


def _image_mask(grey: np.ndarray, name: str, threshold: float | None) -> np.ndarray:
    """The object side of a 2D grey or mask array (bool): the brighter of two levels or
    above ``threshold``, flipped when it covers most of the image's border."""
    if grey.dtype.kind == "f" and not np.isfinite(grey).all():
        raise ValueError(f"{name}: the image has {np.count_nonzero(~np.isfinite(grey))} "
                         f"non-finite (NaN or inf) pixels")
    levels = np.unique(grey)
    if threshold is None:
        if len(levels) > 2:
            from skimage.filters import threshold_otsu

            raise ValueError(f"{name}: a grey-level image ({len(levels)} levels, "
                             f"{levels[0]}..{levels[-1]}), not a two-level mask: pass a "
                             f"threshold, e.g. threshold={float(threshold_otsu(grey)):.6g} "
                             f"(Otsu's)")
        mask = grey == levels[-1]
        if len(levels) == 1:
            raise ValueError(f"{name}: no object in the image: every pixel is {levels[0]}")
    else:
        mask = grey > threshold
        if mask.all() or not mask.any():
            side = "above" if mask.all() else "at or below"
            raise ValueError(f"{name}: no object in the image: every pixel is {side} the "
                             f"threshold {threshold} (levels {levels[0]}..{levels[-1]})")
    border = np.r_[mask[0], mask[-1], mask[1:-1, 0], mask[1:-1, -1]]
    if 2 * np.count_nonzero(border) > len(border):
        mask = ~mask  # the border is mostly "object": that side is the background
    return mask


def _image_contour(grey: np.ndarray, name: str, threshold: float | None,
                   choice="largest") -> np.ndarray:
    """The outer contour (m, 2) of the chosen object of a 2D grey or mask array, in
    ``(x, y) = (column, row)``, counter-clockwise in (x, y)."""
    from skimage.measure import find_contours

    chosen = _choose_object(_image_mask(grey, name, threshold), choice, name)
    padded = np.pad(chosen, 1).astype(np.float64)  # closes contours at the image's edge
    contours = find_contours(padded, 0.5)
    best = contours[int(np.argmax([abs(area(c)) for c in contours]))]  # the outer
    pts = best[:-1, ::-1] - 1.0  # (row, col) -> (x, y); drop the closing repeat
    if area(pts) < 0:
        pts = pts[::-1]  # one orientation for every image: positive area in (x, y)
    return pts


def _choose_object(mask: np.ndarray, choice, name: str) -> np.ndarray:
    """The pixels (bool, like ``mask``) of the object ``choice`` names among the
    4-connected objects of ``mask`` (the connectivity of the contour), logged."""
    from scipy import ndimage
    from skimage.measure import label

    labels, count = label(mask, connectivity=1, return_num=True)  # reading order
    index = np.arange(1, count + 1)
    area = np.bincount(labels.ravel(), minlength=count + 1)[1:]
    edge = np.unique(np.r_[labels[0], labels[-1], labels[:, 0], labels[:, -1]])
    border = np.isin(index, edge)
    if isinstance(choice, str) and choice == "center":
        rows, cols = np.indices(mask.shape)
        centre = np.hypot(rows - (mask.shape[0] - 1) / 2, cols - (mask.shape[1] - 1) / 2)
        pick = int(np.argmin(ndimage.minimum(centre, labels, index)))
        why = "nearest the image centre"
    elif isinstance(choice, str):
        pick, why = _largest_object(area, border, name)
    elif choice > count:
        raise ValueError(f"{name}: object={choice}, but the image has {count} object(s) "
                         f"(numbered 1..{count} in reading order)")
    else:
        pick, why = choice - 1, "as asked"
    where = "touches the image border" if border[pick] else "inside the image"
    _log.info("%s: object %d of %d (%s): %d px, %s", name, pick + 1, count, why,
              area[pick], where)
    return labels == pick + 1


def _largest_object(area: np.ndarray, border: np.ndarray, name: str) -> tuple[int, str]:
    """Index of the largest object, preferring one inside the image (see
    :data:`INSIDE_FRACTION`), and why it was chosen."""
    largest = int(np.argmax(area))
    inside = np.flatnonzero(~border)
    if not border[largest] or not len(inside):
        return largest, "the largest"
    best = int(inside[np.argmax(area[inside])])
    if area[best] >= INSIDE_FRACTION * area[largest]:
        _log.warning("%s: object %d touches the image border and is larger (%d px) than "
                     "object %d (%d px) inside the image: taking the one inside; "
                     "object=%d takes the other", name, largest + 1, area[largest], best + 1,
                     area[best], largest + 1)
        return best, "the largest not touching the border"
    return largest, (f"the largest, though it touches the border: the largest object "
                     f"inside, {best + 1}, has {area[best]} px")


def _grey_levels(image, name: str = "image") -> np.ndarray:
    """A 2D array of grey levels from a PIL image, or its alpha channel as a 0/1 mask
    when that is a real mask (:func:`_alpha_mask`)."""
    image.seek(0)  # the first frame of a multi-page TIFF
    if "A" in image.getbands():
        mask = _alpha_mask(np.asarray(image.getchannel("A")), name)
        if mask is not None:
            return mask
    if image.mode in ("1", "L", "I", "F") or image.mode.startswith("I;"):
        grey = np.asarray(image)
    else:
        grey = np.asarray(image.convert("L"))
    if grey.dtype == bool:
        grey = grey.astype(np.uint8)  # 1-bit images: levels 0 and 1
    if grey.ndim != 2 or min(grey.shape) < 1:
        raise ValueError(f"expected a 2D image, got an array of shape {grey.shape}")
    return grey


def _alpha_mask(alpha: np.ndarray, name: str) -> np.ndarray | None:
    """Opaque pixels (uint8 0/1) when the alpha channel is a real mask: at least
    :data:`MIN_OBJECT_PIXELS` pixels each side of half opacity and at most
    :data:`MAX_PARTIAL_ALPHA` of the pixels partly transparent; else None (logged)."""
    top = float(np.iinfo(alpha.dtype).max) if alpha.dtype.kind in "iu" else 1.0
    opaque = alpha >= 0.5 * top
    partial = np.count_nonzero((alpha > 0.1 * top) & (alpha < 0.9 * top)) / alpha.size
    n_opaque = int(np.count_nonzero(opaque))
    if min(n_opaque, alpha.size - n_opaque) >= MIN_OBJECT_PIXELS and (
            partial <= MAX_PARTIAL_ALPHA):
        _log.info("%s: the alpha channel is the mask (%d opaque px)", name, n_opaque)
        return opaque.astype(np.uint8)
    _log.info("%s: alpha channel ignored (not a mask: %d of %d px opaque, %.0f %% partly "
              "transparent); reading the grey levels", name, n_opaque, alpha.size,
              100 * partial)
    return None


# -- meshes -----------------------------------------------------------------------------


def _read_mesh(path: Path, name: str):
    try:
        import meshio
    except ImportError as exc:
        raise ImportError(f"reading meshes needs meshio ({exc}); install it with: "
                          f"pip install 'modalmorph[mesh]'") from None
    _check_mesh_header(path.read_bytes(), name, path.suffix.lower())
    # meshio prints its diagnostics and calls sys.exit() when no reader succeeds; its STL
    # reader overflows a uint32 on purpose while guessing ASCII from binary.
    said = StringIO()
    try:
        with redirect_stdout(said), redirect_stderr(said), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            mesh = meshio.read(path)
    except (Exception, SystemExit) as exc:  # meshio raises many types for a bad file
        printed = " ".join(said.getvalue().split())
        detail = printed if isinstance(exc, SystemExit) else f"{type(exc).__name__}: {exc}" + (
            f" (meshio: {printed})" if printed else "")
        raise ValueError(f"{name}: cannot read the mesh: {detail}") from None
    if said.getvalue().strip():
        warnings.warn(f"{name}: meshio: {' '.join(said.getvalue().split())}", stacklevel=3)
    points = np.asarray(mesh.points, dtype=np.float64)
    triangles = []
    for block in mesh.cells:
        cells = np.asarray(block.data)
        if block.type.startswith(("triangle", "quad", "polygon")) and cells.ndim == 2 and (
                cells.size):
            corners = {"triangle": 3, "quad": 4}.get(block.type.rstrip("0123456789"))
            cells = cells[:, :corners] if corners else cells  # drop higher-order nodes
            for k in range(1, cells.shape[1] - 1):  # fan: (0, k, k + 1)
                triangles.append(cells[:, [0, k, k + 1]])
    if points.ndim != 2 or len(points) == 0:
        raise ValueError(f"{name}: the mesh has no points")
    if not triangles:
        return points, None  # no surface: a point cloud
    faces = np.vstack(triangles).astype(np.intp)
    if faces.min() < 0 or faces.max() >= len(points):
        raise ValueError(f"{name}: triangles refer to points outside 0..{len(points) - 1}")
    used = np.unique(faces)
    points, faces = points[used], np.searchsorted(used, faces)  # drop unreferenced points
    points, inverse = np.unique(points, axis=0, return_inverse=True)  # merge repeated points
    faces = inverse.reshape(-1)[faces]
    degenerate = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (
        faces[:, 0] == faces[:, 2])
    faces = faces[~degenerate]
    if len(faces) == 0:
        raise ValueError(f"{name}: every triangle of the mesh is degenerate")
    used = np.unique(faces)
    return points[used], np.searchsorted(used, faces)


def _check_mesh_header(data: bytes, name: str, ext: str) -> None:
    """Refuse what meshio would loop on (header-only and truncated OFF, PLY and ANSYS files)
    or allocate for: element counts the file's size cannot hold."""
    if ext == ".off":
        lines = [ln.split(b"#")[0].split() for ln in data.splitlines()]
        lines = [ln for ln in lines if ln]
        head = lines[0][0].decode("latin-1") if lines else ""
        inline = len(lines[0]) > 1 if lines else False  # "OFF nv nf ne" on one line
        counts = lines[0][1:] if inline else (lines[1] if len(lines) > 1 else [])
        if not head.endswith("OFF") or len(counts) < 2 or not all(
                c.lstrip(b"-").isdigit() for c in counts[:2]):
            raise ValueError(f"{name}: cannot read the mesh: not an OFF file: it must start "
                             f"with 'OFF' and the numbers of vertices and faces")
        nv, nf = int(counts[0]), int(counts[1])
        body = len(lines) - (1 if inline else 2)
        if nv < 0 or nf < 0 or nv + nf > body:
            raise ValueError(f"{name}: cannot read the mesh: the OFF header announces {nv} "
                             f"vertices and {nf} faces but {body} line(s) follow")
    elif ext == ".ply":
        end = data.find(b"end_header")
        if not data.startswith(b"ply") or end < 0:
            raise ValueError(f"{name}: cannot read the mesh: not a PLY file: it must start "
                             f"with 'ply' and have an 'end_header' line")
        counts = [int(c) for c in re.findall(rb"^element\s+\S+\s+(-?\d+)", data[:end], re.M)]
        left = len(data) - end - len(b"end_header")
        if any(c < 0 for c in counts) or sum(counts) > left:
            raise ValueError(f"{name}: cannot read the mesh: the PLY header announces "
                             f"{sum(counts)} elements but only {left} bytes follow it")
    elif ext == ".msh" and data.lstrip()[:1] == b"(" and data.rstrip()[-1:] != b")":
        raise ValueError(f"{name}: cannot read the mesh: a truncated ANSYS mesh (it does not "
                         f"end with ')')")


# --------------------------------------------------------------------------------------
# writing


def write_points(path, points) -> None:
    """Write nodes to a file, the format chosen by its extension, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        ``.csv`` (header ``x,y`` or ``x,y,z``), ``.tsv`` (tab-separated, same header),
        ``.txt`` (space-separated, same header), ``.npy`` (the array), ``.npz`` (array
        ``points``, plus ``faces`` and ``closed`` for a :class:`Shape`) or ``.json``
        (``{"points": [[x, y], ...]}``, plus ``"closed"`` and ``"faces"`` for a
        :class:`Shape`). Numbers are written exactly (shortest round-trip form).
    points : array_like, shape (m, 2) or (m, 3), or Shape

    Raises
    ------
    ValueError
        If the extension is not one of these, or points do not have shape (m, 2) or
        (m, 3).
    """
    name = os.fspath(path)
    path = Path(path)
    shape = points if isinstance(points, Shape) else None
    pts = np.asarray(shape.points if shape is not None else points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] not in (2, 3):
        raise ValueError(f"points must have shape (m, 2) or (m, 3), got {pts.shape}")
    ext = path.suffix.lower()
    if ext not in _WRITABLE:
        raise ValueError(f"{name}: cannot write {path.suffix!r} files; supported: "
                         f"{', '.join(_WRITABLE)}")
    with atomic_write(path) as tmp:
        if ext in _TEXT:
            sep = {".csv": ",", ".tsv": "\t", ".txt": " "}[ext]
            header = sep.join("xyz"[: pts.shape[1]])
            body = "".join(sep.join(repr(float(v)) for v in row) + "\n" for row in pts)
            tmp.write_text(header + "\n" + body, encoding="utf-8")
        elif ext == ".npy":
            np.save(tmp, pts)
        elif ext == ".npz":
            extra = {}
            if shape is not None:
                extra["closed"] = np.bool_(shape.closed)
                if shape.faces is not None:
                    extra["faces"] = shape.faces
            np.savez(tmp, points=pts, **extra)
        else:
            data = {"points": pts.tolist()}
            if shape is not None:
                data["closed"] = bool(shape.closed)
                if shape.faces is not None:
                    data["faces"] = shape.faces.tolist()
            tmp.write_text(json.dumps(data) + "\n", encoding="utf-8")


def save_result(morph, out_dir, *, options: dict | None = None,
                inputs: list | None = None) -> None:
    """Write a morph's result into ``out_dir`` (created if needed), one file at a time.

    Three files are written, each atomically (wrap the call in :func:`atomic_output_dir`
    for all or nothing): ``result.json`` (the summary of :func:`result_summary`, strict
    JSON: non-finite numbers as ``null``); ``shapes.npz``, arrays ``shapes`` (T+1, m, d),
    ``loads`` (T+1, m, d), ``node_energy`` (T+1, m), ``energy`` (T+1,),
    ``mean_distance`` (T+1,) and ``pairs`` (K, 2), int: source and target node indices of
    each match; ``final_shape.csv``, the last shape ``shapes[-1]`` with a header
    ``x,y[,z]``.

    Parameters
    ----------
    morph : Morph
    out_dir : str or os.PathLike
    options : dict, optional
        Every option of the run by flat name, as given (the command line's record).
    inputs : list of dict, optional
        The input files, ``{"path", "sha256"}`` each.

    Raises
    ------
    ValueError
        If ``options`` hold a value that cannot be written as JSON.
    """
    out_dir = Path(out_dir)
    summary = result_summary(morph, options=options, inputs=inputs)
    try:
        text = json.dumps(summary, indent=2, default=_json_default, allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"options cannot be written as JSON: {exc}") from None
    out_dir.mkdir(parents=True, exist_ok=True)
    with atomic_write(out_dir / "result.json") as tmp:
        tmp.write_text(text + "\n", encoding="utf-8")
    shapes = np.asarray(morph.shapes, dtype=np.float64)
    with atomic_write(out_dir / "shapes.npz") as tmp:
        np.savez_compressed(
            tmp, shapes=shapes, loads=np.asarray(morph.loads, dtype=np.float64),
            node_energy=np.asarray(morph.node_energy, dtype=np.float64),
            energy=np.asarray(morph.energy, dtype=np.float64),
            mean_distance=np.asarray(morph.mean_distance, dtype=np.float64),
            pairs=_pairs_array(morph))
    write_points(out_dir / "final_shape.csv", shapes[-1])


def result_summary(morph, *, options: dict | None = None, inputs: list | None = None) -> dict:
    """The content of ``result.json``::

        {
          "modalmorph_version": str,      # the library that wrote it
          "inputs": [{"path", "sha256"}], # the input files (empty when not given)
          "options": {...},               # every option as given, by flat name
          "parameters": {...},            # what the run used (options.parameters)
          "converged": bool,              # the distance reached the tolerance
          "stop_reason": str,             # tolerance, equilibrium or max_steps
          "message": str,                 # the same in one sentence, with units
          "distance": float,              # the stop test's measure at the end
          "tolerance": float,             # its tolerance (input units)
          "steps": int,                   # T, the number of time steps taken
          "matches": int,                 # K, the number of matched node pairs
          "source_nodes": int,            # m
          "target_nodes": int,            # n
          "dim": int,                     # 2 or 3
          "mean_distance": [float, ...],  # T + 1 values, per step (step 0 = source)
          "energy": [float, ...]          # T + 1 values, strain energy per step
        }
    """


    return {
        "modalmorph_version": __version__,
        "inputs": list(inputs or []),
        "options": dict(options or {}),
        "parameters": parameters(morph),
        "converged": bool(morph.converged),
        "stop_reason": morph.stop_reason,
        "message": morph.message,
        "distance": float(morph.distance),
        "tolerance": float(morph.tolerance),
        "steps": int(morph.steps),
        "matches": len(_pairs_array(morph)),
        "source_nodes": int(morph.source.m),
        "target_nodes": int(morph.target.m),
        "dim": int(morph.source.dim),
        "mean_distance": _finite_or_none(morph.mean_distance),
        "energy": _finite_or_none(morph.energy),
    }


def _pairs_array(morph) -> np.ndarray:
    return morph.matching.pairs


def _finite_or_none(values) -> list:
    return [float(v) if math.isfinite(v) else None for v in np.asarray(values, dtype=float)]


def _json_default(obj):
    if isinstance(obj, np.generic):
        value = obj.item()
        return None if isinstance(value, float) and not math.isfinite(value) else value
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return dataclasses.asdict(obj)
    raise TypeError(f"{type(obj).__name__} {obj!r} is not JSON serializable")


# --------------------------------------------------------------------------------------
# atomic output


# Temporary files and folders are hidden siblings named ".NAME.modalmorph-tmp-PID-XXXX";
# one whose process is gone was left by a killed run and is removed by the next writer.
_TMP_TAG = ".modalmorph-tmp-"
_LEFTOVER = re.compile(r"^\..*\.modalmorph-tmp-(\d+)-[\w-]+$")
# A folder that is replaced as a whole must be empty or hold one of these files (a previous
# result of morph or of track).
OUTPUT_MARKER = "result.json"
OUTPUT_MARKERS = (OUTPUT_MARKER, "track.json")
# Seconds to sleep just before the final rename(s): read only here, set only by the tests
# that kill a run at that moment.
_PAUSE_ENV = "MODALMORPH_TEST_RENAME_PAUSE"


def remove_leftovers(folder) -> list[Path]:
    """Remove the temporary files and folders that killed runs left in ``folder``.

    These are the hidden ``.NAME.modalmorph-tmp-PID-XXXX`` entries whose process ``PID``
    is no longer running (POSIX only; elsewhere nothing is removed). Returns what was
    removed.
    """
    if os.name != "posix":
        return []
    removed = []
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return []
    for entry in entries:
        found = _LEFTOVER.match(entry.name)
        if found is None or _alive(int(found.group(1))):
            continue
        if entry.is_dir(follow_symlinks=False):
            shutil.rmtree(entry.path, ignore_errors=True)
        else:
            with suppress(FileNotFoundError):
                os.unlink(entry.path)
        removed.append(Path(entry.path))
    return removed


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):  # another user's process; not a PID
        return True
    try:  # a killed process not yet reaped by its parent (a zombie) is dead too
        with open(f"/proc/{pid}/stat", encoding="ascii", errors="replace") as fh:
            return fh.read().rsplit(")", 1)[-1].split()[0] != "Z"
    except OSError:  # no /proc (macOS): trust kill(0)
        return True


def _temp_sibling(folder: Path, name: str) -> Path:
    """A new hidden temporary folder in ``folder``, named after ``name`` and this process."""
    remove_leftovers(folder)
    return Path(tempfile.mkdtemp(prefix=f".{name}{_TMP_TAG}{os.getpid()}-", dir=folder))


def _pause_for_tests() -> None:
    seconds = os.environ.get(_PAUSE_ENV)
    if seconds:
        import time

        time.sleep(float(seconds))


def _exchange(a: Path, b: Path) -> bool:
    """Swap two paths in one step (Linux renameat2 RENAME_EXCHANGE); False if unsupported."""
    if not sys.platform.startswith("linux"):
        return False
    import ctypes
    import errno

    try:
        renameat2 = ctypes.CDLL(None, use_errno=True).renameat2
    except (OSError, AttributeError):  # glibc < 2.28, musl
        return False
    at_fdcwd, rename_exchange = -100, 2
    if renameat2(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP):  # file system or kernel
        return False
    raise OSError(err, os.strerror(err), os.fspath(b))


@contextmanager
def atomic_write(path):
    """Write one file all or nothing: yield a temporary path beside it, then move it.

    The caller writes the file at the yielded path (same name, in a temporary sibling
    folder, so writers that add an extension see the right one). When the block ends
    normally, the file replaces ``path`` with :func:`os.replace` (atomic on one file
    system); when it raises, the temporary file is deleted and ``path`` is untouched.

    Examples
    --------
    >>> with atomic_write("out.npy") as tmp:  # doctest: +SKIP
    ...     np.save(tmp, array)
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp_dir = _temp_sibling(path.parent, path.name)
    try:
        tmp = tmp_dir / path.name
        yield tmp
        if not tmp.exists():
            raise ValueError(f"{os.fspath(path)}: nothing was written to the temporary "
                             f"file {os.fspath(tmp)}")
        os.replace(tmp, path)
    finally:
        shutil.rmtree(tmp_dir, ignore_errors=True)


@contextmanager
def atomic_output_dir(final_dir):
    """Write a folder as a whole: yield a new temporary sibling folder to fill, then rename.

    On entry the destination is checked (a folder that exists must be empty or a previous
    output, holding one of :data:`OUTPUT_MARKERS`) and the temporary folder is created
    beside it: an unwritable destination fails here, before any work. Temporary folders of
    killed runs found there are removed (:func:`remove_leftovers`).

    When the block ends normally, the temporary folder becomes ``final_dir`` by one rename;
    an existing ``final_dir`` is swapped with it in one step (``renameat2`` with
    ``RENAME_EXCHANGE`` on Linux) or, where that is not supported, renamed aside first.
    So at every instant ``final_dir`` is the old complete folder, the new complete folder
    or (only in the fallback, between two renames) absent; the old one is deleted after,
    with every file of the previous run. Missing parent folders are created only then.
    When the block raises, the temporary folder is deleted and ``final_dir`` is left as
    it was.

    Raises
    ------
    ValueError
        If ``final_dir`` exists and is not a folder, is a folder holding other files, or
        its parent cannot be written. The message starts with ``final_dir`` as given.

    Examples
    --------
    >>> with atomic_output_dir("results") as tmp:  # doctest: +SKIP
    ...     save_result(morph, tmp)
    """
    name = os.fspath(final_dir)
    final = Path(os.path.abspath(final_dir))
    tmp = _staging_folder(final, name)
    try:
        yield tmp
        tmp = _put_in_place(tmp, final, name)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _staging_folder(final: Path, name: str) -> Path:
    """Check the destination and create the temporary folder that will replace it."""
    if final.is_symlink() or (final.exists() and not final.is_dir()):
        raise ValueError(f"{name}: exists and is not a folder")
    if final.is_dir() and any(final.iterdir()) and not any(
            (final / marker).is_file() for marker in OUTPUT_MARKERS):
        raise ValueError(f"{name}: a folder with other files in it (no "
                         f"{' or '.join(OUTPUT_MARKERS)}); the output folder is replaced "
                         f"as a whole, so give a new or empty one")
    anchor = final.parent  # the nearest existing ancestor holds the temporary folder
    while not anchor.is_dir():
        if anchor.exists() or anchor.parent == anchor:
            raise ValueError(f"{name}: cannot create the folder: {anchor} is not a folder")
        anchor = anchor.parent
    try:
        return _temp_sibling(anchor, final.name or "out")
    except OSError as exc:
        raise ValueError(f"{name}: cannot write the output folder: cannot create a folder in "
                         f"{anchor} ({exc.strerror})") from None


def _put_in_place(tmp: Path, final: Path, name: str) -> Path:
    """Rename the finished ``tmp`` to ``final``; returns what is left to delete."""
    try:
        final.parent.mkdir(parents=True, exist_ok=True)
        _pause_for_tests()
        if not final.is_dir():
            os.rename(tmp, final)
            return tmp
        if _exchange(tmp, final):
            return tmp  # tmp now holds the old folder
        old = tmp.with_name(tmp.name + "-old")
        os.rename(final, old)
        _pause_for_tests()
        os.rename(tmp, final)
        return old
    except OSError as exc:
        raise ValueError(f"{name}: cannot move the output folder into place "
                         f"({exc.strerror})") from None


# --------------------------------------------------------------------------------------
# sequences


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


def read_frames(inputs, *, threshold: float | None = None, nodes: int | None = None,
                object: str | int = "largest") -> Frames:
    """Read a sequence of shapes (frames) from files.

    Parameters
    ----------
    inputs : str, os.PathLike or a sequence of them
        Either several files, one frame each (any format of :func:`read_shape`), or one of:

        - a folder: its files with a supported extension (images or CSVs, ...), in natural
          order (``frame2`` before ``frame10``);
        - a glob pattern (``"masks/*.png"``), in natural order;
        - a multi-page TIFF: one mask or grey image per page;
        - an ``.npy`` file, or an ``.npz`` file's ``points`` (or only) array: an
          (F, n, d) array of F shapes of n nodes (d = 2 or 3), or an (F, H, W) stack of
          masks or grey images;
        - a CSV/TSV/TXT file with a header naming a ``frame`` column and ``x``, ``y``
          (``z``): one frame per value of ``frame``, in increasing order.
    threshold : float, optional
        Grey images: level separating the object from the background.
    nodes : int, optional
        Resample 2D contours to this many nodes (default: as in the file; 200 for images).
    object : {"largest", "center"} or int, optional
        Images: which object of each frame to outline (as in :func:`read_shape`).

    Returns
    -------
    Frames

    Raises
    ------
    ValueError
        When an input cannot be read, gives fewer than 2 frames, or a frame is not a valid
        shape; the message starts with the frame's name (file, page or index).
    """
    paths = [inputs] if isinstance(inputs, str | os.PathLike) else list(inputs)
    if not paths:
        raise ValueError("inputs: no file given")
    _check_object(object)
    read = dict(threshold=threshold, nodes=nodes, object=object)
    if len(paths) == 1:
        names, shapes = _read_sequence(paths[0], read)
    else:
        names = [os.fspath(p) for p in paths]
        shapes = [read_shape(p, **read) for p in paths]
    if len(shapes) < 2:
        raise ValueError(f"{names[0] if names else os.fspath(paths[0])}: a sequence needs "
                         f"at least 2 frames, got {len(shapes)}")
    return Frames(shapes=tuple(shapes), names=tuple(names))


def _natural_key(path) -> list:
    """Sort key putting ``frame2`` before ``frame10``."""
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", os.fspath(path))]


def _read_sequence(path, read: dict):
    """(names, shapes) of the frames in one input; ``read``: :func:`read_shape`'s options."""
    name = os.fspath(path)
    if any(c in name for c in "*?[") and not Path(path).exists():
        files = sorted(glob.glob(name), key=_natural_key)
        if not files:
            raise ValueError(f"{name}: no file matches the pattern")
        return files, [read_shape(f, **read) for f in files]
    path = Path(path)
    if path.is_dir():
        files = sorted((p for p in path.iterdir() if p.is_file() and not p.name.startswith(".")
                        and p.suffix.lower() in SUPPORTED_EXTENSIONS), key=_natural_key)
        if not files:
            raise ValueError(f"{name}: no shape file in the folder (extensions: "
                             f"{', '.join(SUPPORTED_EXTENSIONS)})")
        return ([os.fspath(f) for f in files],
                [read_shape(f, **read) for f in files])
    ext = path.suffix.lower()
    if not path.exists() or path.stat().st_size == 0 or ext not in (*_ARRAY, *_TEXT,
                                                                    ".tif", ".tiff"):
        return [name], [read_shape(path, **read)]
    if ext in (".tif", ".tiff"):
        pages = _tiff_pages(path, name)
        if len(pages) == 1:
            return [name], [read_shape(path, **read)]
        return _image_frames(pages, f"{name}[page {{}}]", read)
    if ext in _TEXT:
        return _csv_frames(path, name, read["nodes"])
    array = _load_npy(path, name) if ext == ".npy" else _npz_arrays(path, name)[0]
    array = array.astype(np.uint8) if array.dtype == bool else array  # a stack of masks
    if array.dtype.kind not in "iuf":
        raise ValueError(f"{name}: the array must be numeric, got dtype {array.dtype}")
    if array.ndim != 3:
        return [name], [read_shape(path, **read)]
    if array.shape[-1] in (2, 3):  # (F, n, d): F shapes
        if read["threshold"] is not None:
            raise ValueError(f"{name}: threshold= applies to images, not to an (F, n, "
                             f"{array.shape[-1]}) array of points")
        names = [f"{name}[{f}]" for f in range(len(array))]
        return names, [_make_shape(n, a, nodes=read["nodes"])
                       for n, a in zip(names, array, strict=True)]
    return _image_frames(list(array), f"{name}[{{}}]", read)


def _tiff_pages(path: Path, name: str) -> list:
    from PIL import Image, ImageSequence

    try:
        with Image.open(path) as image:
            return [_grey_levels(page.copy()) for page in ImageSequence.Iterator(image)]
    except (OSError, ValueError) as exc:
        raise ValueError(f"{name}: cannot read the image: {exc}") from None


def _image_frames(images, pattern: str, read: dict):
    """(names, shapes) of a stack of images (pages, or an (F, H, W) array): in pixels, y
    down, with no image file to draw under them."""
    names = [pattern.format(f) for f in range(len(images))]
    shapes = []
    for n, g in zip(names, map(np.asarray, images), strict=True):
        pts = _image_contour(g, n, read["threshold"], read["object"])
        shapes.append(_make_shape(n, pts, nodes=read["nodes"] or DEFAULT_NODES,
                                  frame=ImageFrame(size=g.shape)))
    return names, shapes


def _csv_frames(path: Path, name: str, nodes):
    """One frame per value of the ``frame`` column of a text file with a header."""
    lines = [ln for ln in path.read_text(encoding="utf-8-sig").splitlines()
             if ln.strip() and not ln.lstrip().startswith("#")]
    sep = next((s for s in ("\t", ";", ",") if s in lines[0]), None)
    header = [h.strip().strip("\"'").lower() for h in lines[0].split(sep)]
    if "frame" not in header:
        return [name], [read_shape(path, nodes=nodes)]
    if "x" not in header or "y" not in header:
        raise ValueError(f"{name}: a 'frame' column needs 'x' and 'y' columns too, got "
                         f"{header}")
    cols = [header.index(c) for c in ("frame", "x", "y", "z") if c in header]
    rows = []
    for lineno, line in enumerate(lines[1:], start=2):
        parts = line.split(sep)
        try:
            rows.append([_parse_float(parts[c]) for c in cols])
        except (ValueError, IndexError):
            raise ValueError(f"{name}: data line {lineno}: cannot read the frame and "
                             f"coordinates from {line.strip()!r}") from None
    table = np.array(rows).reshape(-1, len(cols))
    values = np.unique(table[:, 0])
    names = [f"{name}[frame {v:g}]" for v in values]
    return names, [_make_shape(n, table[table[:, 0] == v, 1:], nodes=nodes)
                   for n, v in zip(names, values, strict=True)]


def save_track(track, out_dir, *, options: dict | None = None,
               input_files: list | None = None) -> None:
    """Write a :class:`modalmorph.Track` into ``out_dir``, one file at a time (wrap the
    call in :func:`atomic_output_dir` for all or nothing).

    ``track.npz``
        Arrays ``points`` (F, m, d) (the trajectories), ``energy``, ``cumulative_energy``,
        ``strain``, ``distance`` (F,), ``node_energy`` (F, m), ``edges`` (e, 2),
        ``edge_strain`` (F, e), ``segment_strain`` (F, S), ``segment_of_edge`` (e,),
        ``crossed`` (F,).
    ``track.json``
        ``modalmorph_version``, ``parameters``, ``inputs`` (frame names), ``nodes``,
        ``input_files`` (each file's ``path`` and ``sha256``, when given), ``options``
        (every option of the run by flat name, when given), ``nodes``,
        ``dim``, ``closure_error`` (or null) and ``frames``: per frame ``name``,
        ``observed_nodes``, ``steps``, ``converged``, ``energy``, ``cumulative_energy``,
        ``strain``, ``segment_strain``, ``distance``, ``crossed`` (frame 0: no morph,
        ``steps`` 0).
    ``strain_segments.csv``
        One row per frame: ``frame,global,segment_1,...,segment_S``.
    """


    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    frames = []
    for f in range(track.n_frames):
        run = track.morphs[f - 1] if f else None
        frames.append({
            "name": track.names[f], "observed_nodes": int(track.frames[f].m),
            "steps": run.steps if run else 0, "converged": bool(run.converged) if run else True,
            "energy": float(track.energy[f]),
            "cumulative_energy": float(track.cumulative_energy[f]),
            "strain": float(track.strain[f]),
            "segment_strain": _finite_or_none(track.segment_strain[f]),
            "distance": float(track.distance[f]), "crossed": bool(track.crossed[f])})
    summary = {"modalmorph_version": __version__, "parameters": track.params,
               "inputs": list(track.names), "input_files": list(input_files or []),
               "options": dict(options or {}), "nodes": int(track.points.shape[1]),
               "dim": int(track.points.shape[2]), "closure_error": track.closure_error,
               "frames": frames}
    text = json.dumps(summary, indent=2, default=_json_default, allow_nan=False)
    with atomic_write(out_dir / "track.json") as tmp:
        tmp.write_text(text + "\n", encoding="utf-8")
    with atomic_write(out_dir / "track.npz") as tmp:
        np.savez_compressed(
            tmp, points=track.points, energy=track.energy, node_energy=track.node_energy,
            cumulative_energy=track.cumulative_energy, strain=track.strain,
            distance=track.distance, edges=track.edges, edge_strain=track.edge_strain,
            segment_strain=track.segment_strain, segment_of_edge=track.segment_of_edge,
            crossed=track.crossed)
    n_seg = track.segment_strain.shape[1]
    table = np.column_stack([np.arange(track.n_frames), track.strain, track.segment_strain])
    header = ",".join(["frame", "global", *[f"segment_{s + 1}" for s in range(n_seg)]])
    with atomic_write(out_dir / "strain_segments.csv") as tmp:
        np.savetxt(tmp, table, delimiter=",", header=header, comments="",
                   fmt=["%d"] + ["%.6g"] * (1 + n_seg))
