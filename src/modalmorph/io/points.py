"""Point files: text (CSV, TSV, TXT), NumPy (NPY, NPZ) and JSON, read and written.

- text: one node per line, ``x, y`` or ``x, y, z``, separated by commas, tabs, semicolons
  or spaces (with semicolons a decimal comma is accepted). An optional first line of
  column names; if it names columns ``x`` and ``y`` (and ``z``), those columns are used
  and others ignored, but a ``contour`` column: the contour of each node (a shape of
  several contours, a ring's outer boundary and hole; each contour's rows consecutive).
  Blank lines and lines starting with ``#`` are skipped, but a first line ``# y down
  (image coordinates), unit U``: the numbers are image coordinates, y pointing down, in
  unit U (as :func:`write_points` writes a shape from an image or SVG).
- ``.xyz``: the same text, ``x y z`` first on each line, then any attributes (colours,
  normals), left out.
- ``.npy``: an (m, 2) or (m, 3) array; ``.npz``: the array ``points`` (or the only array
  in the file), and optionally ``faces``, ``closed`` and ``contours`` (node counts).
- ``.json``: a list ``[[x, y], ...]`` or an object ``{"points": [...], "closed": bool,
  "faces": [[i, j, k], ...], "contours": [n0, n1, ...]}`` (all but ``points`` optional).

:func:`write_points` writes the same formats back, exactly (``.npy``: the points only).
"""

from __future__ import annotations

import json
import math
import os
import zipfile
from pathlib import Path

import numpy as np

from ..core.shape import ImageFrame, Shape
from ..errors import InputFileError, ShapeError
from ..options import ReadOptions
from .atomic import atomic_write
from .base import RawShape

__all__ = ["TEXT_SEPARATORS", "WRITABLE", "contour_runs", "load_npy", "npz_arrays", "parse_float",
           "read_json", "read_npy", "read_npz", "read_text", "read_xyz", "write_points"]

# The first line of a text file of image coordinates (y down), then ", unit U".
Y_DOWN = "# y down (image coordinates)"
# The text formats written, with their column separator (any is read).
TEXT_SEPARATORS = {".csv": ",", ".tsv": "\t", ".txt": " "}
WRITABLE = (*TEXT_SEPARATORS, ".npy", ".npz", ".json")


def parse_float(text: str) -> float:
    return float(text.strip().strip("\"'"))


def read_xyz(path: Path, name: str, options: ReadOptions) -> RawShape:
    """An ASCII XYZ point cloud (CloudCompare, MeshLab, Open3D): ``x y z`` first on each
    line, then any attributes (colour, normal, intensity), which are left out."""
    return read_text(path, name, options, xyz=True)


def read_text(path: Path, name: str, options: ReadOptions, xyz: bool = False) -> RawShape:
    """A text file's nodes (see the module's docstring); ``xyz``: the first three columns
    of each line, whatever follows them."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputFileError(f"{name}: not a text file (cannot decode it as UTF-8: "
                             f"{exc.reason} at byte {exc.start})") from None
    lines = [(i, line.strip()) for i, line in enumerate(text.splitlines(), start=1)]
    frame = _frame(lines[0][1] if lines else "")
    lines = [(i, line) for i, line in lines if line and not line.startswith("#")]
    if not lines:
        raise InputFileError(f"{name}: the file has no data")

    first = lines[0][1]
    sep = next((s for s in ("\t", ";", ",") if s in first), None)

    def fields(line):
        parts = line.split(sep) if sep else line.split()
        parts = [p.strip() for p in parts]
        return [p.replace(",", ".") for p in parts] if sep == ";" else parts

    columns = [0, 1, 2] if xyz else None  # of x, y[, z] (then contour) if a header names them
    header = fields(first)
    names = [h.strip("\"'").strip().lower() for h in header]
    if not any(_is_number(f) for f in header):
        columns = _named_columns(name, names, lines[0][0])
        lines = lines[1:]
        if not lines:
            raise InputFileError(f"{name}: the file has a header line but no data")

    rows, width = [], None
    for lineno, line in lines:
        parts = fields(line)
        if width is None:
            width = len(parts)
            if columns is None and width not in (2, 3):
                raise InputFileError(f"{name}: line {lineno} has {width} column"
                                     f"{'s' if width != 1 else ''}, expected 2 or 3 (x, y[, z])")
        elif len(parts) != width:
            raise InputFileError(f"{name}: line {lineno} has {len(parts)} columns, expected "
                                 f"{width} like line {lines[0][0]}")
        if columns is not None and max(columns) >= len(parts):
            raise InputFileError(f"{name}: line {lineno} has {len(parts)} columns, fewer than "
                                 f"{'x, y, z' if xyz else 'the header names'}")
        row = []
        for k in columns if columns is not None else range(len(parts)):
            try:
                value = parse_float(parts[k])
            except ValueError:
                raise InputFileError(f"{name}: line {lineno}: {parts[k]!r} in column {k + 1} is "
                                     f"not a number") from None
            row.append(value)
        if not all(math.isfinite(v) for v in row):
            raise InputFileError(f"{name}: line {lineno}: non-finite coordinates "
                                 f"({', '.join(parts)})")
        rows.append(row)
    table = np.array(rows, dtype=np.float64)
    if columns is not None and "contour" in names:
        return RawShape(table[:, :-1], contours=contour_runs(name, table[:, -1]), frame=frame)
    return RawShape(table, frame=frame)


def _frame(first: str) -> ImageFrame | None:
    """The frame a text file's first line declares (:data:`Y_DOWN`), else None."""
    if not first.startswith(Y_DOWN):
        return None
    unit = first[len(Y_DOWN):].partition(", unit ")[2].strip()
    return ImageFrame(unit=unit or "px")


def _named_columns(name: str, names: list, line: int) -> list | None:
    """Indices of the columns ``x``, ``y`` (``z``, ``contour``) a header names, None when
    it names no x and y (then 2 or 3 columns, in order)."""
    if "x" in names and "y" in names:
        return [names.index(c) for c in ("x", "y", "z", "contour") if c in names]
    if len(names) not in (2, 3):
        raise InputFileError(f"{name}: line {line} (header) has {len(names)} columns, "
                             f"expected 2 or 3 (x, y[, z])")
    return None


def contour_runs(name: str, ids: np.ndarray) -> tuple[int, ...] | None:
    """Node counts of the contours named by a ``contour`` column (one run of consecutive
    rows each), None for one contour."""
    starts = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]])
    values = ids[starts]
    if len(np.unique(values)) < len(values):
        again = next(v for k, v in enumerate(values) if v in values[:k])
        raise InputFileError(f"{name}: the rows of contour {again:g} are not consecutive "
                             f"(row {starts[list(values).index(again, 1)] + 1} of the data "
                             f"starts it again)")
    sizes = np.diff(np.r_[starts, len(ids)])
    return tuple(int(k) for k in sizes) if len(sizes) > 1 else None


def _checked(contours, m: int) -> tuple[int, ...] | None:
    """Node counts given with an array, checked to split its ``m`` rows."""
    if contours is None or len(contours) < 2:
        return None
    if sum(contours) != m or min(contours) < 1:
        raise ShapeError(f"contours must be node counts summing to the {m} points, got "
                         f"{list(contours)}")
    return tuple(int(k) for k in contours)


def _is_number(text: str) -> bool:
    try:
        parse_float(text)
    except ValueError:
        return False
    return True


def _load_array(loader, path: Path, name: str, kind: str):
    try:
        return loader(path)
    except (ValueError, OSError, EOFError, zipfile.BadZipFile) as exc:
        raise InputFileError(f"{name}: cannot read it as a {kind} file: {exc}") from None


def _numeric(name: str, array, what: str) -> np.ndarray:
    array = np.asarray(array)
    if array.dtype.kind not in "iuf":
        raise InputFileError(f"{name}: {what} must be numeric, got an array of dtype "
                             f"{array.dtype}")
    if array.ndim != 2 or array.shape[1] not in (2, 3):
        got = "a scalar" if array.ndim == 0 else f"shape {array.shape}"
        raise InputFileError(f"{name}: {what} must have shape (m, 2) or (m, 3), got {got}")
    return array


def load_npy(path: Path, name: str) -> np.ndarray:
    def load(p):
        with open(p, "rb") as fh:  # np.load(path) leaks its handle when the file is bad
            return np.load(fh, allow_pickle=False)

    return _load_array(load, path, name, ".npy")


def read_npy(path: Path, name: str, options: ReadOptions) -> RawShape:
    """An .npy file's (m, d) array."""
    return RawShape(_numeric(name, load_npy(path, name), "the array"))


def read_npz(path: Path, name: str, options: ReadOptions) -> RawShape:
    """An .npz file's ``points`` (or only) array, its ``faces`` and ``closed``."""
    points, faces, closed, contours, frame = npz_arrays(path, name)
    return RawShape(_numeric(name, points, "'points'"), faces=faces, closed=closed,
                    contours=contours, frame=frame)


def npz_arrays(path: Path, name: str):
    """An .npz file's ``points`` (or only) array as it is, its ``faces``, ``closed``,
    ``contours`` and frame (``y_down`` and ``unit``: image coordinates)."""
    def load(p):
        with open(p, "rb") as fh, np.load(fh, allow_pickle=False) as data:
            return {key: data[key] for key in data.files}

    arrays = _load_array(load, path, name, ".npz")
    if "points" in arrays:
        points = arrays["points"]
    elif len(arrays) == 1:
        points = next(iter(arrays.values()))
    else:
        raise InputFileError(f"{name}: no array named 'points' among {sorted(arrays)}")
    faces = arrays.get("faces") if "points" in arrays else None
    closed = arrays.get("closed") if "points" in arrays else None
    if closed is not None:
        if closed.shape != () or closed.dtype.kind not in "biu":
            raise InputFileError(f"{name}: 'closed' must be one boolean, got {closed.dtype} "
                                 f"{closed.shape}")
        closed = bool(closed)
    if faces is not None:
        faces = _faces(name, faces)
    contours = arrays.get("contours") if "points" in arrays else None
    said = {key: arrays[key].tolist() for key in ("y_down", "unit")
            if key in arrays and "points" in arrays}
    frame = _declared(name, said.get("y_down", False), said.get("unit"))
    return points, faces, closed, _contours(name, contours), frame


def _declared(name: str, y_down, unit) -> ImageFrame | None:
    """The frame an .npz or JSON file declares: image coordinates where ``y_down``."""
    if y_down is not True and y_down is not False:
        raise InputFileError(f"{name}: y_down must be true or false, got {y_down!r:.40}")
    if unit is not None and not isinstance(unit, str):
        raise InputFileError(f"{name}: unit must be a string, got {unit!r:.40}")
    return ImageFrame(unit=unit or "px") if y_down else None


def _contours(name: str, counts) -> tuple[int, ...] | None:
    """Node counts of contours as read (a list or an array), checked to be integers;
    their sum is checked with the shape."""
    if counts is None:
        return None
    counts = np.asarray(counts, dtype=object if isinstance(counts, list) else None)
    if counts.ndim != 1 or not len(counts) or not all(
            isinstance(k, int | np.integer) and not isinstance(k, bool) for k in counts):
        raise InputFileError(f"{name}: contours must be a list of node counts (integers), "
                             f"got {counts.tolist()!r:.60}")
    return tuple(int(k) for k in counts) if len(counts) > 1 else None


def _faces(name: str, faces) -> np.ndarray:
    try:
        faces = np.asarray(faces)
    except (ValueError, OverflowError):  # ragged lists, integers beyond int64
        faces = np.asarray(faces, dtype=object)
    if faces.size == 0:
        return None
    if faces.ndim != 2 or faces.shape[1] != 3 or faces.dtype.kind not in "iu":
        raise InputFileError(f"{name}: faces must be integer triangles of shape (f, 3), got "
                             f"{faces.dtype} {faces.shape}")
    return faces


def read_json(path: Path, name: str, options: ReadOptions) -> RawShape:
    """A JSON list of nodes, or an object with ``points``, ``closed`` and ``faces``."""
    try:
        data = json.loads(path.read_text(encoding="utf-8-sig"))
    except UnicodeDecodeError as exc:
        raise InputFileError(f"{name}: not a text file (cannot decode it as UTF-8: "
                             f"{exc.reason} at byte {exc.start})") from None
    except ValueError as exc:  # JSONDecodeError, or an integer of more than 4300 digits
        raise InputFileError(f"{name}: not valid JSON: {exc}") from None
    except RecursionError:
        raise InputFileError(f"{name}: not readable JSON: nested too deeply") from None
    closed = faces = contours = frame = None
    if isinstance(data, dict):
        if "points" not in data:
            raise InputFileError(f"{name}: the JSON object has no \"points\" (keys: "
                                 f"{', '.join(map(repr, data))})")
        closed = data.get("closed")
        if closed is not None and not isinstance(closed, bool):
            raise InputFileError(f"{name}: \"closed\" must be true or false, got {closed!r}")
        if data.get("faces") is not None:
            faces = _faces(name, data["faces"])
        contours = _contours(name, data.get("contours"))
        declared = data.get("frame")  # other tools write a frame's index there: not ours
        if isinstance(declared, dict):
            frame = _declared(name, declared.get("y_down", False), declared.get("unit"))
        data = data["points"]
    if not isinstance(data, list) or not all(isinstance(row, list) for row in data):
        raise InputFileError(f"{name}: expected a list of [x, y] or [x, y, z] lists")
    if not data:
        raise InputFileError(f"{name}: no points (an empty list)")
    if len({len(row) for row in data}) > 1:
        first = len(data[0])
        k = next(k for k, row in enumerate(data) if len(row) != first)
        raise InputFileError(f"{name}: node {k} has {len(data[k])} coordinates, expected {first} "
                             f"like node 0")
    for k, row in enumerate(data):
        for value in row:
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise InputFileError(f"{name}: node {k}: {str(value)[:40]!r} is not a number")
            if isinstance(value, int) and not -1e308 < value < 1e308:
                raise InputFileError(f"{name}: node {k}: an integer of {len(str(value))} digits "
                                     f"is too large for a coordinate")
    return RawShape(np.array(data, dtype=np.float64), faces=faces, closed=closed,
                    contours=contours, frame=frame)


def write_points(path, points, *, contours=None, frame=None) -> None:
    """Write nodes to a file, the format chosen by its extension, atomically.

    Parameters
    ----------
    path : str or os.PathLike
        ``.csv`` (header ``x,y`` or ``x,y,z``, and ``contour`` for a :class:`Shape` of
        several contours), ``.tsv`` (tab-separated, same header), ``.txt``
        (space-separated, same header), ``.npy`` (the array), ``.npz`` (array ``points``,
        plus ``faces``, ``closed`` and ``contours`` for a :class:`Shape`) or ``.json``
        (``{"points": [[x, y], ...]}``, plus ``"closed"``, ``"faces"`` and ``"contours"``
        for a :class:`Shape`). Numbers are written exactly (shortest round-trip form).
    points : array_like, shape (m, 2) or (m, 3), or Shape
    contours : sequence of int, optional
        For an array: the node counts of its contours, written as a :class:`Shape`'s
        (a ``contour`` column, ``"contours"``); a Shape has its own.
    frame : ImageFrame, optional
        For an array: its frame; a Shape has its own. Image coordinates (y down) are
        said on the first line of a text file (:data:`Y_DOWN`), by ``y_down`` and
        ``unit`` in an ``.npz``, by ``"frame": {"y_down": true, "unit": ...}`` in a
        ``.json``, and read back so (an ``.npy`` holds the array only).

    Raises
    ------
    ValueError
        If the extension is not one of these.
    ShapeError
        If points do not have shape (m, 2) or (m, 3).
    """
    name = os.fspath(path)
    path = Path(path)
    shape = points if isinstance(points, Shape) else None
    pts = np.asarray(shape.points if shape is not None else points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] not in (2, 3):
        raise ShapeError(f"points must have shape (m, 2) or (m, 3), got {pts.shape}")
    ext = path.suffix.lower()
    if ext not in WRITABLE:
        raise ValueError(f"{name}: cannot write {path.suffix!r} files; supported: "
                         f"{', '.join(WRITABLE)}")
    contours = shape.contours if shape is not None else _checked(contours, len(pts))
    frame = shape.frame if shape is not None else frame
    down = frame if frame is not None and frame.y_down else None
    with atomic_write(path) as tmp:
        if ext in TEXT_SEPARATORS:
            sep = TEXT_SEPARATORS[ext]
            names = ["x", "y", "z"][: pts.shape[1]] + (["contour"] if contours else [])
            ids = ([[repr(int(k))] for k in np.repeat(np.arange(len(contours)), contours)]
                   if contours else [[]] * len(pts))
            body = "".join(sep.join([*(repr(float(v)) for v in row), *c]) + "\n"
                           for row, c in zip(pts, ids, strict=True))
            said = f"{Y_DOWN}, unit {down.unit}\n" if down is not None else ""
            tmp.write_text(said + sep.join(names) + "\n" + body, encoding="utf-8")
        elif ext == ".npy":
            np.save(tmp, pts)
        elif ext == ".npz":
            extra = {"contours": np.array(contours)} if contours else {}
            if shape is not None:
                extra["closed"] = np.bool_(shape.closed)
                if shape.faces is not None:
                    extra["faces"] = shape.faces
            if down is not None:
                extra.update(y_down=np.bool_(True), unit=np.str_(down.unit))
            np.savez(tmp, points=pts, **extra)
        else:
            data = {"points": pts.tolist(), **({"contours": list(contours)} if contours
                                               else {})}
            if shape is not None:
                data["closed"] = bool(shape.closed)
                if shape.faces is not None:
                    data["faces"] = shape.faces.tolist()
            if down is not None:
                data["frame"] = {"y_down": True, "unit": down.unit}
            tmp.write_text(json.dumps(data) + "\n", encoding="utf-8")
