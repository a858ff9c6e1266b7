"""VTK output: a morph as one VTU file per step and a ParaView ``.pvd`` collection, each
file written atomically."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .atomic import atomic_write

__all__ = ["write_vtk_series"]


def write_vtk_series(morph, out_dir, *, name: str = "morph") -> Path:
    """Write one VTU file per step and a ParaView ``.pvd`` collection of them.

    Each ``{name}_{step:04d}.vtu`` holds the shape at that step (2D padded with z = 0)
    with line cells for contours (each its own loop), triangles for surfaces or vertices
    for point clouds, and point data ``load`` (vectors), ``energy`` (local strain energy) and
    ``displacement`` (from the source). Open ``{name}.pvd`` in ParaView to play it.

    Parameters
    ----------
    morph : Morph
        A morph result.
    out_dir : str or Path
        Directory to write into (created if missing).
    name : str, optional
        Stem of the file names.

    Returns
    -------
    Path
        The ``.pvd`` file.
    """
    try:
        import meshio
    except ImportError as exc:  # pragma: no cover - exercised on a bare install
        raise ImportError("writing VTK needs meshio (a dependency of modalmorph): "
                          "pip install meshio") from exc
    from xml.sax.saxutils import quoteattr

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    shapes = np.asarray(morph.shapes, dtype=np.float64)
    dim = shapes.shape[2]
    cells = _vtk_cells(morph.source, shapes.shape[1])
    loads = np.asarray(morph.loads, dtype=np.float64)
    energy = np.asarray(morph.node_energy, dtype=np.float64)

    def pad(a):
        return np.pad(a, ((0, 0), (0, 3 - dim))) if dim == 2 else a

    entries = []
    for j, points in enumerate(shapes):
        fname = f"{name}_{j:04d}.vtu"
        mesh = meshio.Mesh(pad(points), cells, point_data={
            "load": pad(loads[j]), "energy": energy[j],
            "displacement": pad(points - shapes[0]),
        })
        with atomic_write(out / fname) as tmp:
            mesh.write(tmp)
        entries.append(f'    <DataSet timestep="{j}" group="" part="0" '
                       f"file={quoteattr(fname)}/>")
    pvd = out / f"{name}.pvd"
    with atomic_write(pvd) as tmp:
        tmp.write_text('<?xml version="1.0"?>\n'
                       '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">\n'
                       "  <Collection>\n" + "\n".join(entries) + "\n  </Collection>\n"
                       "</VTKFile>\n")
    return pvd


def _vtk_cells(source, m: int) -> list:
    """meshio cells of the source's topology: triangles, lines or vertices."""
    if source.has_faces:
        return [("triangle", np.asarray(source.faces, dtype=np.int64))]
    if source.ordered:  # each contour's segments (the shape's edges), none between them
        return [("line", np.asarray(source.edges, dtype=np.int64))]
    return [("vertex", np.arange(m, dtype=np.int64)[:, None])]
