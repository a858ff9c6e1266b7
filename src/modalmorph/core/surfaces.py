"""Self-intersections of triangle surfaces: whether a morph's intermediate surfaces cut
through themselves (method.md §5).

The test is MeshLab's (``pymeshlab``, an optional dependency: ``pip install
'modalmorph[surfaces]'``): the faces that intersect another face of the same surface,
faces that share a vertex or an edge not counted. It is imported inside the functions,
so the numeric core still imports numpy and scipy only; without it the check is skipped
and said (:func:`step_self_intersections` returns None and logs why).
"""

from __future__ import annotations

import logging

import numpy as np

__all__ = ["self_intersecting_faces", "step_self_intersections", "intersection_sentence"]

log = logging.getLogger(__name__)


def self_intersecting_faces(points, faces) -> int:
    """Number of triangles of a surface that intersect another of its triangles.

    Parameters
    ----------
    points : array_like, shape (m, 3)
    faces : array_like of int, shape (f, 3)

    Returns
    -------
    int

    Raises
    ------
    ImportError
        Without pymeshlab.
    """
    import pymeshlab

    points = np.asarray(points, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int32)
    meshes = pymeshlab.MeshSet()
    meshes.add_mesh(pymeshlab.Mesh(vertex_matrix=points, face_matrix=faces))
    meshes.compute_selection_by_self_intersections_per_face()
    return int(meshes.current_mesh().selected_face_number())


def step_self_intersections(shapes, faces) -> np.ndarray | None:
    """:func:`self_intersecting_faces` of the surface at every step, shape (T+1,), int;
    None (and a log line saying so) when pymeshlab is not installed."""
    try:
        import pymeshlab  # noqa: F401
    except ImportError:
        log.warning("self-intersections not checked: pymeshlab is not installed "
                    "(pip install 'modalmorph[surfaces]')")
        return None
    return np.array([self_intersecting_faces(shape, faces) for shape in shapes],
                    dtype=np.int64)


def intersection_sentence(counts, *, model_nodes: int | None = None,
                          nodes: int | None = None) -> str:
    """What a morph's message adds about its self-intersections: nothing when none of its
    steps has any (or they were not checked); with a reduced model (``model_nodes`` <
    ``nodes``), the hint to model every node, which avoided them on the bunny when the
    reduced model moved with the element's field (method.md §5)."""
    if counts is None or not np.any(counts):
        return ""
    counts = np.asarray(counts)
    steps = np.flatnonzero(counts)  # step 0: the source itself
    hint = (f"; model_nodes={nodes} (a model of every node, not {model_nodes}) may avoid "
            f"them" if model_nodes is not None and nodes is not None and model_nodes < nodes
            else "")
    return (f"; {len(steps)} of {len(counts)} steps' surfaces intersect themselves "
            f"(up to {counts.max()} faces, first at step {steps[0]}){hint}")
