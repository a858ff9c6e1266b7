"""Meshes, read with meshio: a 3D triangle surface or, with no surface cells, a point cloud.

PLY, OBJ and STL files that meshio refuses but graphics software writes (a PLY with further
elements, such as a range scanner's ``camera``; an OBJ with fewer texture coordinates than
vertices; an ASCII STL with a blank line, as trimesh writes it) are read with trimesh, the
graphics library, instead.

Quads and polygons are split into triangles (a fan from their first corner); points no
triangle uses and exactly repeated points are dropped, and so are the triangles that
become degenerate. A mesh with no surface cells is a point cloud of all its points.
"""

from __future__ import annotations

import re
import warnings
from contextlib import redirect_stderr, redirect_stdout
from io import StringIO
from pathlib import Path

import numpy as np

from ..errors import InputFileError
from ..options import ReadOptions
from .base import RawShape

__all__ = ["read_mesh"]

GRAPHICS_FORMATS = (".ply", ".obj", ".stl")  # read with trimesh where meshio refuses them


def read_mesh(path: Path, name: str, options: ReadOptions) -> RawShape:
    """A mesh file's triangle surface, or its points (see the module's docstring); its
    points are never closed and kept as they are (no closing repeat dropped)."""
    try:
        import meshio
    except ImportError as exc:
        raise ImportError(f"reading meshes needs meshio ({exc}); install it with: "
                          f"pip install 'modalmorph[mesh]'") from None
    _check_mesh_header(path.read_bytes(), name, path.suffix.lower())
    try:
        mesh = _meshio_read(meshio, path, name)
        points, triangles = np.asarray(mesh.points, dtype=np.float64), _triangles(mesh)
        if any(t.size and t.min() < 0 for t in triangles):  # OBJ's relative (negative)
            raise InputFileError(f"{name}: triangles refer to points outside "  # indices,
                                 f"0..{len(points) - 1}")  # which meshio reads as absolute
    except InputFileError as refused:
        if path.suffix.lower() not in GRAPHICS_FORMATS:
            raise
        points, triangles = _trimesh_read(path, refused)
    if points.ndim != 2 or len(points) == 0:
        raise InputFileError(f"{name}: the mesh has no points")
    if not triangles:  # no surface: a point cloud
        return RawShape(points, closed=False, drop_closing_repeat=False)
    points, faces = _surface(points, np.vstack(triangles).astype(np.intp), name)
    return RawShape(points, faces=faces, closed=False, drop_closing_repeat=False)


def _meshio_read(meshio, path: Path, name: str):
    """``meshio.read(path)``, its failures and its printed diagnostics named."""
    # meshio prints its diagnostics and calls sys.exit() when no reader succeeds; its STL
    # reader overflows a uint32 on purpose while guessing ASCII from binary.
    said = StringIO()
    try:
        with redirect_stdout(said), redirect_stderr(said), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            mesh = meshio.read(path)
    except (Exception, SystemExit) as exc:  # meshio raises many types for a bad file
        printed = " ".join(said.getvalue().split())
        detail = printed if isinstance(exc, SystemExit) else (
            f"{type(exc).__name__}: {' '.join(str(exc).split())}"  # one line: numpy's
            + (f" (meshio: {printed})" if printed else ""))      # errors list lines
        raise InputFileError(f"{name}: cannot read the mesh: {detail}") from None
    if said.getvalue().strip():
        warnings.warn(f"{name}: meshio: {' '.join(said.getvalue().split())}", stacklevel=4)
    return mesh


def _trimesh_read(path: Path, refused: InputFileError) -> tuple[np.ndarray, list]:
    """The points and triangles of a PLY or OBJ file as trimesh reads it; ``refused``,
    meshio's error, where trimesh finds no points either."""
    try:
        import trimesh

        loaded = trimesh.load(path, force="mesh", process=False, skip_materials=True)
        points = np.asarray(loaded.vertices, dtype=np.float64).reshape(-1, 3)
        faces = np.asarray(getattr(loaded, "faces", ()), dtype=np.intp).reshape(-1, 3)
    except Exception:  # trimesh raises many types for a bad file
        raise refused from None
    if len(points) == 0:
        raise refused from None
    return points, [faces] if len(faces) else []


def _triangles(mesh) -> list:
    """The (f, 3) triangles of each surface block: quads and polygons split in fans."""
    triangles = []
    for block in mesh.cells:
        cells = np.asarray(block.data)
        if block.type.startswith(("triangle", "quad", "polygon")) and cells.ndim == 2 and (
                cells.size):
            corners = {"triangle": 3, "quad": 4}.get(block.type.rstrip("0123456789"))
            cells = cells[:, :corners] if corners else cells  # drop higher-order nodes
            for k in range(1, cells.shape[1] - 1):  # fan: (0, k, k + 1)
                triangles.append(cells[:, [0, k, k + 1]])
    return triangles


def _surface(points: np.ndarray, faces: np.ndarray, name: str):
    """(points, faces) of a surface: unreferenced points, repeated points (all but the
    first) and degenerate triangles dropped, the points left in the file's order."""
    if faces.min() < 0 or faces.max() >= len(points):
        raise InputFileError(f"{name}: triangles refer to points outside "
                             f"0..{len(points) - 1}")
    used = np.unique(faces)
    points, faces = points[used], np.searchsorted(used, faces)  # drop unreferenced points
    _, first, inverse = np.unique(points, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)  # the merged points in the order they first appear
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    points, faces = points[first[order]], rank[inverse.reshape(-1)][faces]
    degenerate = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (
        faces[:, 0] == faces[:, 2])
    faces = faces[~degenerate]
    if len(faces) == 0:
        raise InputFileError(f"{name}: every triangle of the mesh is degenerate")
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
            raise InputFileError(f"{name}: cannot read the mesh: not an OFF file: it must start "
                                 f"with 'OFF' and the numbers of vertices and faces")
        nv, nf = int(counts[0]), int(counts[1])
        body = len(lines) - (1 if inline else 2)
        if nv < 0 or nf < 0 or nv + nf > body:
            raise InputFileError(f"{name}: cannot read the mesh: the OFF header announces {nv} "
                                 f"vertices and {nf} faces but {body} line(s) follow")
    elif ext == ".ply":
        end = data.find(b"end_header")
        if not data.startswith(b"ply") or end < 0:
            raise InputFileError(f"{name}: cannot read the mesh: not a PLY file: it must start "
                                 f"with 'ply' and have an 'end_header' line")
        counts = [int(c) for c in re.findall(rb"^element\s+\S+\s+(-?\d+)", data[:end], re.M)]
        left = len(data) - end - len(b"end_header")
        if any(c < 0 for c in counts) or sum(counts) > left:
            raise InputFileError(f"{name}: cannot read the mesh: the PLY header announces "
                                 f"{sum(counts)} elements but only {left} bytes follow it")
    elif ext == ".msh" and data.lstrip()[:1] == b"(" and data.rstrip()[-1:] != b")":
        raise InputFileError(f"{name}: cannot read the mesh: a truncated ANSYS mesh (it does not "
                             f"end with ')')")

