"""Reading shapes from files, writing points and results, and atomic output.

:func:`read_shape` picks a reader by the file's extension:

=====================================  ==================================  ===============
extensions                             content                             needs
=====================================  ==================================  ===============
``.csv`` ``.tsv`` ``.txt``             ``x, y[, z]`` per row               numpy
``.npy`` ``.npz``                      an (m, d) array                     numpy
``.json``                              ``[[x, y], ...]`` or an object      numpy
``.svg``                               the first path/polygon/polyline     numpy
``.png`` ``.tif`` ``.tiff`` ``.jpg``   the largest object's contour        ``[images]``
``.jpeg`` ``.bmp``
``.ply`` ``.obj`` ``.stl`` ``.off``    a triangle surface or point cloud   ``[mesh]``
``.vtk`` ``.vtu`` ``.msh`` ``.mesh``
=====================================  ==================================  ===============

Every problem with a file is a :class:`ValueError` whose message starts with the file's
name, so the command line can print it as it is.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import re
import shutil
import tempfile
import warnings
import xml.etree.ElementTree as ET
from contextlib import contextmanager, redirect_stderr, redirect_stdout
from io import StringIO
from pathlib import Path

import numpy as np

from .shape import Shape, resample

__all__ = [
    "DEFAULT_NODES",
    "SUPPORTED_EXTENSIONS",
    "atomic_output_dir",
    "atomic_write",
    "read_shape",
    "save_result",
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

# Points per segment when an SVG segment is flattened before arc-length resampling; the
# chord error of a quarter circle sampled this finely is below 1e-4 of its radius.
_SVG_SAMPLES = 128


# --------------------------------------------------------------------------------------
# reading


def read_shape(path, *, nodes: int | None = None, threshold: float | None = None,
               closed: bool | None = None) -> Shape:
    """Read a shape from a file, choosing the reader by the file's extension.

    Parameters
    ----------
    path : str or os.PathLike
        The file. Supported extensions are listed in :data:`SUPPORTED_EXTENSIONS`:

        - ``.csv``, ``.tsv``, ``.txt``: one node per line, ``x, y`` or ``x, y, z``,
          separated by commas, tabs, semicolons or spaces (with semicolons a decimal comma
          is accepted). An optional first line of column names; if it names columns
          ``x`` and ``y`` (and ``z``), those columns are used and others ignored. Blank
          lines and lines starting with ``#`` are skipped.
        - ``.npy``: an (m, 2) or (m, 3) array; ``.npz``: the array ``points`` (or the
          only array in the file), and optionally ``faces`` and ``closed``.
        - ``.json``: a list ``[[x, y], ...]`` or an object ``{"points": [...],
          "closed": bool, "faces": [[i, j, k], ...]}`` (``closed`` and ``faces``
          optional).
        - ``.svg``: the first ``<path>``, ``<polygon>`` or ``<polyline>`` (transforms
          applied; for a path with several subpaths, the first), sampled uniformly by arc
          length. Coordinates are SVG user units, with y pointing down.
        - ``.png``, ``.tif``/``.tiff``, ``.jpg``/``.jpeg``, ``.bmp``: the outer contour of
          the largest object, in pixel coordinates ``(x, y) = (column, row)``. A two-level
          image is a mask; a grey-level image needs ``threshold``. Whichever side covers
          most of the image border is the background, so dark objects on a light
          background work too. Colour is converted to grey; an alpha channel that varies
          is used as the mask.
        - ``.ply``, ``.obj``, ``.stl``, ``.off``, ``.vtk``, ``.vtu``, ``.msh``, ``.mesh``:
          a 3D surface (points and triangles; quads and polygons are split into
          triangles; unreferenced and exactly repeated points dropped) or, with no
          surface cells, a point cloud of all its points.

        A final row repeating the first (a contour written closed) is dropped.
    nodes : int, optional
        Resample a 2D contour to this many nodes, equally spaced by arc length. Defaults to
        the file's nodes for point files and to :data:`DEFAULT_NODES` for images and SVG.
        Not allowed for 3D shapes.
    threshold : float, optional
        Images only: grey level separating the object from the background, in the
        image's own units (0-255 for 8-bit images).
    closed : bool, optional
        Whether a contour closes on itself; overrides the file (an SVG path's ``Z``, a
        JSON ``"closed"``). Defaults to closed.

    Returns
    -------
    Shape
        2D shapes are ordered contours; 3D shapes are surfaces (with ``faces``) or point
        clouds.

    Raises
    ------
    ValueError
        Whenever the file cannot give a valid shape: missing, empty, unknown extension,
        non-numeric or non-finite values (with the line or node), wrong number of
        columns, fewer than 3 nodes, an image with no object, an unreadable image or
        mesh. The message starts with the file's name.
    ImportError
        When an image or mesh needs an optional library that is not installed.
    """
    name = os.fspath(path)
    path = Path(path)
    if nodes is not None and (isinstance(nodes, bool) or not isinstance(nodes, int | np.integer)
                              or nodes < 3):
        raise ValueError(f"nodes must be an integer >= 3, got {nodes!r}")
    if threshold is not None and (isinstance(threshold, bool) or not (
            isinstance(threshold, int | float | np.number) and math.isfinite(threshold))):
        raise ValueError(f"threshold must be a finite number, got {threshold!r}")
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

    if ext in _IMAGE:
        pts = _read_image(path, name, threshold)
        return _make_shape(name, pts, nodes=nodes or DEFAULT_NODES,
                           closed=True if closed is None else closed)
    if ext == ".svg":
        pts, file_closed = _read_svg(path, name)
        return _make_shape(name, pts, nodes=nodes or DEFAULT_NODES,
                           closed=file_closed if closed is None else closed)
    if ext in _MESH:
        pts, faces = _read_mesh(path, name)
        return _make_shape(name, pts, faces=faces, nodes=nodes, closed=closed)

    if ext in _TEXT:
        pts, faces, file_closed = _read_text(path, name), None, None
    elif ext == ".npy":
        pts, faces, file_closed = _read_npy(path, name), None, None
    elif ext == ".npz":
        pts, faces, file_closed = _read_npz(path, name)
    else:
        pts, faces, file_closed = _read_json(path, name)
    if closed is None:
        closed = True if file_closed is None else file_closed
    if faces is None and len(pts) > 1 and np.array_equal(pts[0], pts[-1]):
        pts = pts[:-1]  # a closed contour written with its first node repeated
    return _make_shape(name, pts, faces=faces, nodes=nodes, closed=closed)


def _make_shape(name, pts, *, faces=None, nodes=None, closed=True) -> Shape:
    """Check an (m, d) array of coordinates from ``name``; resample; build the Shape."""
    pts = np.asarray(pts, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] not in (2, 3):
        raise ValueError(f"{name}: expected an (m, 2) or (m, 3) array of coordinates, got "
                         f"shape {pts.shape}")
    if len(pts) < 3:
        raise ValueError(f"{name}: only {len(pts)} node{'s' if len(pts) != 1 else ''}; a "
                         f"shape needs at least 3")
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
        return Shape(pts, closed=bool(closed), faces=faces)
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
    except (ValueError, OSError, EOFError) as exc:
        raise ValueError(f"{name}: cannot read it as a {kind} file: {exc}") from None


def _numeric(name: str, array, what: str) -> np.ndarray:
    array = np.asarray(array)
    if array.dtype.kind not in "iuf":
        raise ValueError(f"{name}: {what} must be numeric, got an array of dtype {array.dtype}")
    return array


def _read_npy(path: Path, name: str) -> np.ndarray:
    array = _load_array(lambda p: np.load(p, allow_pickle=False), path, name, ".npy")
    return _numeric(name, array, "the array")


def _read_npz(path: Path, name: str):
    def load(p):
        with np.load(p, allow_pickle=False) as data:
            return {key: data[key] for key in data.files}

    arrays = _load_array(load, path, name, ".npz")
    if "points" in arrays:
        points = arrays["points"]
    elif len(arrays) == 1:
        points = next(iter(arrays.values()))
    else:
        raise ValueError(f"{name}: no array named 'points' among {sorted(arrays)}")
    faces = arrays.get("faces") if "points" in arrays else None
    closed = bool(arrays["closed"]) if "points" in arrays and "closed" in arrays else None
    if faces is not None:
        faces = _faces(name, faces)
    return _numeric(name, points, "'points'"), faces, closed


def _faces(name: str, faces) -> np.ndarray:
    faces = np.asarray(faces)
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
    except json.JSONDecodeError as exc:
        raise ValueError(f"{name}: not valid JSON: {exc}") from None
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
                raise ValueError(f"{name}: node {k}: {value!r} is not a number")
    return np.array(data, dtype=np.float64), faces, closed


# -- SVG --------------------------------------------------------------------------------

_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
_SEPARATORS = re.compile(r"[\s,]*")
_ARGS = {"M": 2, "L": 2, "H": 1, "V": 1, "C": 6, "S": 4, "Q": 4, "T": 2, "A": 7, "Z": 0}


def _read_svg(path: Path, name: str):
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise ValueError(f"{name}: not a valid SVG (XML) file: {exc}") from None
    try:
        found = _first_outline(root, np.eye(3))
    except ValueError as exc:
        raise ValueError(f"{name}: {exc}") from None
    if found is None:
        raise ValueError(f"{name}: no <path>, <polygon> or <polyline> element")
    element, matrix = found
    tag = _local(element.tag)
    try:
        if tag == "path":
            subpaths = _parse_path(element.get("d", ""))
        else:
            coords = [float(v) for v in _numbers(element.get("points", ""))]
            if len(coords) % 2:
                raise ValueError("odd number of coordinates in 'points'")
            subpaths = [(np.reshape(coords, (-1, 2)), tag == "polygon")]
    except ValueError as exc:
        raise ValueError(f"{name}: <{tag}>: {exc}") from None
    subpaths = [(p, c) for p, c in subpaths if len(p) > 1]
    if not subpaths:
        raise ValueError(f"{name}: the first <{tag}> has no segments")
    if len(subpaths) > 1:
        warnings.warn(f"{name}: the <{tag}> has {len(subpaths)} subpaths; using the first",
                      stacklevel=3)
    pts, closed = subpaths[0]
    pts = pts @ matrix[:2, :2].T + matrix[:2, 2]
    keep = np.r_[True, np.any(np.diff(pts, axis=0) != 0, axis=1)]
    pts = pts[keep]  # zero-length segments add nothing to the outline
    if len(pts) > 1 and np.allclose(pts[0], pts[-1], rtol=0, atol=1e-12 * np.abs(pts).max()):
        pts, closed = pts[:-1], True  # ends where it starts
    return pts, closed


def _local(tag) -> str:
    return tag.rsplit("}", 1)[-1] if isinstance(tag, str) else ""


def _first_outline(element, matrix):
    """The first path/polygon/polyline in document order, with its accumulated transform."""
    if element.get("transform"):
        matrix = matrix @ _parse_transform(element.get("transform"))
    if _local(element.tag) in ("path", "polygon", "polyline"):
        return element, matrix
    if _local(element.tag) in ("defs", "clipPath", "mask", "symbol", "marker", "pattern"):
        return None  # not drawn where it is defined
    for child in element:
        found = _first_outline(child, matrix)
        if found is not None:
            return found
    return None


def _numbers(text: str) -> list[str]:
    rest = _NUMBER.sub(" ", text)
    if rest.strip(" \t\r\n,"):
        bad = rest.strip(" \t\r\n,")[0]
        raise ValueError(f"unexpected character {bad!r} in {text[:40]!r}")
    return _NUMBER.findall(text)


def _parse_transform(text: str) -> np.ndarray:
    matrix = np.eye(3)
    for func, args in re.findall(r"(\w+)\s*\(([^)]*)\)", text):
        v = [float(a) for a in _NUMBER.findall(args)]
        m = np.eye(3)
        if func == "matrix" and len(v) == 6:
            m[:2] = [[v[0], v[2], v[4]], [v[1], v[3], v[5]]]
        elif func == "translate" and len(v) in (1, 2):
            m[:2, 2] = [v[0], v[1] if len(v) == 2 else 0.0]
        elif func == "scale" and len(v) in (1, 2):
            m[0, 0], m[1, 1] = v[0], v[-1]
        elif func == "rotate" and len(v) in (1, 3):
            c, s = math.cos(math.radians(v[0])), math.sin(math.radians(v[0]))
            m[:2, :2] = [[c, -s], [s, c]]
            if len(v) == 3:
                m[:2, 2] = np.array(v[1:]) - m[:2, :2] @ v[1:]
        elif func == "skewX" and len(v) == 1:
            m[0, 1] = math.tan(math.radians(v[0]))
        elif func == "skewY" and len(v) == 1:
            m[1, 0] = math.tan(math.radians(v[0]))
        else:
            raise ValueError(f"unsupported transform {func}({args})")
        matrix = matrix @ m
    return matrix


class _PathScanner:
    """Reads an SVG path's d-attribute: commands, numbers and arc flags."""

    def __init__(self, d: str):
        self.d, self.i = d, 0

    def skip(self):
        self.i = _SEPARATORS.match(self.d, self.i).end()

    def done(self) -> bool:
        self.skip()
        return self.i >= len(self.d)

    def command(self) -> str | None:
        self.skip()
        if self.i < len(self.d) and self.d[self.i].upper() in _ARGS:
            self.i += 1
            return self.d[self.i - 1]
        return None

    def number(self) -> float:
        self.skip()
        match = _NUMBER.match(self.d, self.i)
        if match is None:
            found = self.d[self.i:self.i + 10] or "the end"
            raise ValueError(f"expected a number at character {self.i} of d, found "
                             f"{found!r}")
        self.i = match.end()
        return float(match.group())

    def flag(self) -> bool:
        self.skip()
        if self.i >= len(self.d) or self.d[self.i] not in "01":
            raise ValueError(f"expected an arc flag 0 or 1 at character {self.i} of d")
        self.i += 1
        return self.d[self.i - 1] == "1"


def _parse_path(d: str) -> list[tuple[np.ndarray, bool]]:
    """Flatten an SVG path into polylines, one (points (n, 2), closed) per subpath."""
    scan = _PathScanner(d)
    subpaths: list[tuple[np.ndarray, bool]] = []
    current: list[np.ndarray] = []
    pos = start = np.zeros(2)
    last_control, last_cmd = None, None
    cmd = scan.command()
    if cmd is None and not scan.done():
        raise ValueError(f"d must start with a command, got {d[:20]!r}")
    if cmd is not None and cmd.upper() != "M":
        raise ValueError(f"d must start with M or m, got {cmd!r}")

    def finish(closed):
        if current:
            subpaths.append((np.vstack(current), closed))
        current.clear()

    while cmd is not None:
        upper, rel = cmd.upper(), cmd.islower()
        origin = pos if rel else np.zeros(2)
        while True:
            if upper == "Z":
                if current:
                    current.append(start[None])
                finish(True)
                pos, last_control = start, None
            elif upper == "M":
                finish(False)
                pos = start = origin + [scan.number(), scan.number()]
                current.append(pos[None])
                last_control = None
            elif upper in "LHV":
                if not current:
                    current.append(pos[None])
                if upper == "L":
                    end = origin + [scan.number(), scan.number()]
                elif upper == "H":
                    end = np.array([scan.number() + origin[0], pos[1]])
                else:
                    end = np.array([pos[0], scan.number() + origin[1]])
                current.append(end[None])
                pos, last_control = end, None
            elif upper in "CSQT":
                if not current:
                    current.append(pos[None])
                smooth = {"S": "CS", "T": "QT"}.get(upper)
                if smooth:
                    reflect = last_control is not None and last_cmd in smooth
                    c1 = 2 * pos - last_control if reflect else pos
                    ctrl = [c1] + [origin + [scan.number(), scan.number()]
                                   for _ in range(_ARGS[upper] // 2)]
                else:
                    ctrl = [origin + [scan.number(), scan.number()]
                            for _ in range(_ARGS[upper] // 2)]
                control = np.vstack([pos, *ctrl])
                current.append(_bezier(control)[1:])
                pos, last_control = control[-1], control[-2]
            else:  # A
                if not current:
                    current.append(pos[None])
                rx, ry, phi = abs(scan.number()), abs(scan.number()), scan.number()
                large, sweep = scan.flag(), scan.flag()
                end = origin + [scan.number(), scan.number()]
                current.append(_arc(pos, end, rx, ry, phi, large, sweep)[1:])
                pos, last_control = end, None
            last_cmd = upper
            next_cmd = scan.command()
            if next_cmd is not None or scan.done():
                cmd = next_cmd
                break
            if upper == "Z":
                raise ValueError(f"unexpected number after Z at character {scan.i} of d")
            # repeated arguments: the same command again (a moveto continues as lineto)
            if upper == "M":
                upper = "L"
            origin = pos if rel else np.zeros(2)
    if not scan.done():
        raise ValueError(f"unexpected {d[scan.i:scan.i + 10]!r} at character {scan.i} of d")
    finish(False)
    return subpaths


def _bezier(control: np.ndarray) -> np.ndarray:
    """Points on the Bézier curve with these control points (Bernstein form)."""
    n = len(control) - 1
    t = np.linspace(0.0, 1.0, _SVG_SAMPLES + 1)[:, None]
    coeff = [math.comb(n, k) * t**k * (1 - t) ** (n - k) for k in range(n + 1)]
    return sum(c * p for c, p in zip(coeff, control, strict=True))


def _arc(p0, p1, rx, ry, phi_deg, large, sweep) -> np.ndarray:
    """Points on an SVG elliptical arc (endpoint to centre form, SVG 1.1 appendix F.6.5)."""
    if rx == 0 or ry == 0 or np.array_equal(p0, p1):
        return np.vstack([p0, p1])  # F.6.2: a straight line (or nothing)
    phi = math.radians(phi_deg % 360)
    c, s = math.cos(phi), math.sin(phi)
    rot = np.array([[c, -s], [s, c]])
    x1, y1 = rot.T @ ((p0 - p1) / 2)
    lam = (x1 / rx) ** 2 + (y1 / ry) ** 2
    if lam > 1:  # F.6.6: radii too small, scale them up
        rx, ry = rx * math.sqrt(lam), ry * math.sqrt(lam)
    num = max(0.0, (rx * ry) ** 2 - (rx * y1) ** 2 - (ry * x1) ** 2)
    coef = math.sqrt(num / ((rx * y1) ** 2 + (ry * x1) ** 2))
    if large == sweep:
        coef = -coef
    cx1, cy1 = coef * rx * y1 / ry, -coef * ry * x1 / rx
    centre = rot @ [cx1, cy1] + (p0 + p1) / 2
    theta1 = math.atan2((y1 - cy1) / ry, (x1 - cx1) / rx)
    theta2 = math.atan2((-y1 - cy1) / ry, (-x1 - cx1) / rx)
    delta = (theta2 - theta1) % (2 * math.pi)
    if not sweep and delta > 0:
        delta -= 2 * math.pi
    theta = theta1 + np.linspace(0.0, delta, _SVG_SAMPLES + 1)
    pts = np.column_stack([rx * np.cos(theta), ry * np.sin(theta)]) @ rot.T + centre
    pts[0], pts[-1] = p0, p1  # exact endpoints
    return pts


# -- images -----------------------------------------------------------------------------


def _read_image(path: Path, name: str, threshold: float | None) -> np.ndarray:
    try:
        from PIL import Image, UnidentifiedImageError
        from skimage.measure import find_contours
    except ImportError as exc:
        raise ImportError(f"reading images needs scikit-image and pillow ({exc}); install "
                          f"them with: pip install 'modalmorph[images]'") from None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            with Image.open(path) as image:
                grey = _grey_levels(image)
    except (OSError, UnidentifiedImageError, Image.DecompressionBombWarning,
            Image.DecompressionBombError, ValueError) as exc:
        raise ValueError(f"{name}: cannot read the image: {exc}") from None

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

    padded = np.pad(mask, 1).astype(np.float64)  # closes contours at the image's edge
    contours = find_contours(padded, 0.5)
    areas = [_signed_area(c) for c in contours]
    best = contours[int(np.argmax(np.abs(areas)))]
    pts = best[:-1, ::-1] - 1.0  # (row, col) -> (x, y); drop the closing repeat
    if _signed_area(pts) < 0:
        pts = pts[::-1]  # one orientation for every image: positive area in (x, y)
    return pts


def _grey_levels(image) -> np.ndarray:
    """A 2D array of grey levels (or alpha, if it varies) from a PIL image."""
    image.seek(0)  # the first frame of a multi-page TIFF
    bands = image.getbands()
    if "A" in bands:
        alpha = np.asarray(image.getchannel("A"))
        if alpha.min() != alpha.max():
            return alpha
    if image.mode in ("1", "L", "I", "F") or image.mode.startswith("I;"):
        grey = np.asarray(image)
    else:
        grey = np.asarray(image.convert("L"))
    if grey.dtype == bool:
        grey = grey.astype(np.uint8)  # 1-bit images: levels 0 and 1
    if grey.ndim != 2 or min(grey.shape) < 1:
        raise ValueError(f"expected a 2D image, got an array of shape {grey.shape}")
    return grey


def _signed_area(pts: np.ndarray) -> float:
    """Shoelace area of a closed polygon, positive when counter-clockwise in its axes."""
    x, y = pts[:, 0], pts[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


# -- meshes -----------------------------------------------------------------------------


def _read_mesh(path: Path, name: str):
    try:
        import meshio
    except ImportError as exc:
        raise ImportError(f"reading meshes needs meshio ({exc}); install it with: "
                          f"pip install 'modalmorph[mesh]'") from None
    # meshio prints its diagnostics and calls sys.exit() when no reader succeeds; its STL
    # reader overflows a uint32 on purpose while guessing ASCII from binary.
    said = StringIO()
    try:
        with redirect_stdout(said), redirect_stderr(said), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            mesh = meshio.read(path)
    except (Exception, SystemExit) as exc:  # meshio raises many types for a bad file
        detail = " ".join(said.getvalue().split()) or f"{type(exc).__name__}: {exc}"
        raise ValueError(f"{name}: cannot read the mesh: {detail}") from None
    if said.getvalue().strip():
        warnings.warn(f"{name}: meshio: {' '.join(said.getvalue().split())}", stacklevel=3)
    points = np.asarray(mesh.points, dtype=np.float64)
    triangles = []
    for block in mesh.cells:
        cells = np.asarray(block.data)
        if block.type.startswith(("triangle", "quad", "polygon")) and cells.ndim == 2:
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


def save_result(morph, out_dir, *, params: dict) -> None:
    """Write a morph's result into ``out_dir`` (created if needed), one file at a time.

    Three files are written, each atomically (wrap the call in :func:`atomic_output_dir`
    for all or nothing):

    ``result.json``
        A summary, with this schema::

            {
              "modalmorph_version": str,      # the library that wrote it
              "parameters": {...},            # params, as given (made JSON-safe)
              "converged": bool,              # the stopping criterion was met
              "stop_reason": str,             # why the integration stopped
              "steps": int,                   # T, the number of time steps taken
              "matches": int,                 # K, the number of matched node pairs
              "source_nodes": int,            # m
              "target_nodes": int,            # n
              "dim": int,                     # 2 or 3
              "mean_distance": [float, ...],  # T + 1 values, per step (step 0 = source)
              "energy": [float, ...]          # T + 1 values, strain energy per step
            }

        Non-finite numbers are written as ``null`` (strict JSON).

    ``shapes.npz``
        Arrays ``shapes`` (T+1, m, d), ``loads`` (T+1, m, d), ``node_energy`` (T+1, m),
        ``energy`` (T+1,), ``mean_distance`` (T+1,) and ``pairs`` (K, 2), int: source and
        target node indices of each match.

    ``final_shape.csv``
        The last intermediate shape, ``shapes[-1]``, with a header ``x,y[,z]``.

    Parameters
    ----------
    morph : morph result
        Has ``shapes``, ``loads``, ``energy``, ``node_energy``, ``mean_distance``,
        ``matching.pairs``, ``converged``, ``stop_reason``, ``source``, ``target`` and
        ``steps``.
    out_dir : str or os.PathLike
    params : dict
        The parameters of the run, stored in ``result.json``. Numpy scalars and arrays
        and paths are converted; anything else not JSON-serialisable is an error.

    Raises
    ------
    ValueError
        If ``params`` holds a value that cannot be written as JSON.
    """
    from . import __version__

    out_dir = Path(out_dir)
    shapes = np.asarray(morph.shapes, dtype=np.float64)
    pairs = np.asarray(morph.matching.pairs, dtype=np.intp).reshape(-1, 2)
    summary = {
        "modalmorph_version": __version__,
        "parameters": params,
        "converged": bool(morph.converged),
        "stop_reason": str(morph.stop_reason),
        "steps": int(morph.steps),
        "matches": len(pairs),
        "source_nodes": int(morph.source.m),
        "target_nodes": int(morph.target.m),
        "dim": int(morph.source.dim),
        "mean_distance": _finite_or_none(morph.mean_distance),
        "energy": _finite_or_none(morph.energy),
    }
    try:
        text = json.dumps(summary, indent=2, default=_json_default, allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"params cannot be written as JSON: {exc}") from None
    out_dir.mkdir(parents=True, exist_ok=True)
    with atomic_write(out_dir / "result.json") as tmp:
        tmp.write_text(text + "\n", encoding="utf-8")
    with atomic_write(out_dir / "shapes.npz") as tmp:
        np.savez_compressed(
            tmp, shapes=shapes, loads=np.asarray(morph.loads, dtype=np.float64),
            node_energy=np.asarray(morph.node_energy, dtype=np.float64),
            energy=np.asarray(morph.energy, dtype=np.float64),
            mean_distance=np.asarray(morph.mean_distance, dtype=np.float64), pairs=pairs)
    write_points(out_dir / "final_shape.csv", shapes[-1])


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
    tmp_dir = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent))
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
    """Fill a folder all or nothing: yield a temporary sibling folder to write into.

    When the block ends normally, everything in the temporary folder is moved into
    ``final_dir`` (created if needed; same-named files and folders there are replaced,
    others kept). When it raises, the temporary folder is deleted and ``final_dir`` is
    left as it was, so a failed run leaves no half-written output.

    Examples
    --------
    >>> with atomic_output_dir("results") as tmp:  # doctest: +SKIP
    ...     save_result(morph, tmp, params=params)
    """
    final = Path(final_dir)
    if final.exists() and not final.is_dir():
        raise ValueError(f"{os.fspath(final_dir)}: exists and is not a directory")
    parent = final.absolute().parent
    parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{final.name}.", suffix=".tmp", dir=parent))
    try:
        yield tmp
        final.mkdir(exist_ok=True)
        for item in sorted(tmp.iterdir()):
            dest = final / item.name
            if dest.is_dir() and not dest.is_symlink():
                shutil.rmtree(dest)
            elif item.is_dir() and (dest.exists() or dest.is_symlink()):
                dest.unlink()
            os.replace(item, dest)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
