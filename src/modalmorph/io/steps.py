"""A morph as one mesh file per step (PLY or OBJ, written with meshio), for graphics
programs that open meshes but not VTK series."""

from __future__ import annotations

from contextlib import redirect_stdout
from io import StringIO
from pathlib import Path

import numpy as np

from .atomic import atomic_write

__all__ = ["MESH_FORMATS", "write_step_meshes"]

MESH_FORMATS = ("ply", "obj")


def write_step_meshes(morph, out_dir, *, fmt: str = "ply", name: str = "morph") -> list[Path]:
    """Write ``{name}_{step:04d}.{fmt}``, the shape at every step, into ``out_dir``.

    Surfaces keep the source's triangles; contours are lines in PLY (the segments of
    each contour) (OBJ, as meshio
    writes it, holds triangles only: their nodes alone there); point clouds are vertices.
    2D shapes lie in z = 0. PLY files are binary, OBJ files text.

    Parameters
    ----------
    morph : Morph
        A morph result.
    out_dir : str or Path
        Directory to write into (created if missing).
    fmt : {"ply", "obj"}, optional
    name : str, optional
        Stem of the file names.

    Returns
    -------
    list of Path
        The files, in the order of the steps.
    """
    if fmt not in MESH_FORMATS:
        raise ValueError(f"fmt must be one of {', '.join(MESH_FORMATS)}, got {fmt!r}")
    try:
        import meshio
    except ImportError as exc:  # pragma: no cover - exercised on a bare install
        raise ImportError("writing meshes needs meshio (a dependency of modalmorph): "
                          "pip install meshio") from exc
    shapes = np.asarray(morph.shapes, dtype=np.float64)
    if shapes.shape[2] == 2:
        shapes = np.pad(shapes, ((0, 0), (0, 0), (0, 1)))
    cells = _cells(morph.source, fmt)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for j, points in enumerate(shapes):
        path = out / f"{name}_{j:04d}.{fmt}"
        with atomic_write(path) as tmp, redirect_stdout(StringIO()):  # meshio's notes
            meshio.write(tmp, meshio.Mesh(points, cells), file_format=fmt)
        paths.append(path)
    return paths


def _cells(source, fmt: str) -> list:
    """meshio cells of the source's topology in this format (int32: what PLY holds)."""
    if source.has_faces:
        return [("triangle", np.asarray(source.faces, dtype=np.int32))]
    if source.ordered and fmt == "ply":  # each contour's segments, none between them
        return [("line", np.asarray(source.edges, dtype=np.int32))]
    return []
