"""Triangle surfaces: the closest point on a surface's faces (numpy and scipy), and
self-intersections: whether a morph's intermediate surfaces cut through themselves
(method.md §5).

The test is MeshLab's (``pymeshlab``, an optional dependency: ``pip install
'modalmorph[surfaces]'``): the faces that intersect another face of the same surface,
faces that share a vertex or an edge not counted. It is imported inside the functions,
so the numeric core still imports numpy and scipy only; without it the check is skipped
and said (:func:`step_self_intersections` returns None and logs why).
"""

from __future__ import annotations

import logging

import numpy as np
from scipy.spatial import cKDTree

from .align import align

__all__ = ["FACE_CANDIDATES", "DISTINCT_PARTNERS", "FACING_SHARE", "TURN_HINT",
           "closest_on_band", "closest_on_faces", "face_distances", "face_tree",
           "facing_apart", "self_intersecting_faces", "vertex_normals",
           "step_self_intersections", "intersection_sentence", "unlike_sentence"]

log = logging.getLogger(__name__)

# Faces whose centroids are nearest a point, searched for its closest point. Against
# open3d's exact RaycastingScene.compute_closest_points (10 000 points a mesh, about a
# spacing off the bunny of 1839 vertices, the scikit-image blob of morph3d.py, icospheres
# and (2, 1, 0.5) ellipsoids of 42-2562 vertices): 4 faces missed the closest point for up
# to 1.8 % of the points (by up to 0.13 spacings), 8 for up to 0.04 % (0.06), 16 for none.
FACE_CANDIDATES = 16
BLOCK = 1 << 12  # points at once (x FACE_CANDIDATES faces): 35 MB peak for 100 000
# A turn of the pairs (degrees) beyond which the message suggests taking it first: the
# morph moves every node straight towards its target, and halfway through a turn by t a
# surface is flattened to cos(t / 2) across it. The bunny turned 90 deg (its true pairs)
# morphs with no face cutting another; a sphere of 642 vertices onto an ellipsoid of 162,
# by the matcher's pairs (turned 169 deg from the common frame), cut 19-71 faces at a step
# and none with the turn removed first.
TURN_HINT = 90.0
# Below this share of distinct partners (of the fewer nodes of the two objects) a morph
# that falls short is said to join objects too unlike for the matcher. benchmarks/
# morph3d.py: the real meshes, warped and turned, 0.95-1.00 (the skimage blobs 0.95), an
# icosphere onto an ellipsoid at another resolution 1.00; trimesh's primitives onto one
# another (--primitives; none converges) 0.21-0.56, but sphere <-> box 0.83-0.89.
DISTINCT_PARTNERS = 0.75
# Above this share of pairs whose surfaces face apart the normals say nothing (faces wound
# inconsistently): none is released (:func:`facing_apart`). benchmarks/morph3d.py
# --surfaces, the matcher's pairs: the skimage blobs 0.035 (100 of its 258 pairs more
# than a spacing from the truth, 14 of the 3005 nearer), every other case at most 0.001.
FACING_SHARE = 0.25


def vertex_normals(vertices, faces) -> np.ndarray:
    """Unit normals (m, 3) of a triangle surface's vertices: the sums of their faces'
    normals weighted by area, oriented as the faces are wound."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces)
    tri = vertices[faces]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # 2 area x normal
    out = np.zeros_like(vertices)
    for corner in range(3):
        np.add.at(out, faces[:, corner], cross)
    return out / np.maximum(np.linalg.norm(out, axis=1), 1e-300)[:, None]


def facing_apart(source, target, pairs: np.ndarray) -> np.ndarray:
    """Which pairs (K,) of two surfaces (``source``, ``target``: ``(points, faces)``)
    face apart: the source vertex's normal turned by the pairs' rotation and its
    partner's more than 90 degrees apart. Such a pair pulls the surface inside out
    (on the skimage blobs of benchmarks/morph3d.py, partners across a tube: the morph
    stopped 1.02 tolerances off, 0.99 and converged without them). The surfaces' windings
    may differ (most pairs facing apart then agree); above ``FACING_SHARE`` of pairs
    facing apart none is said to (faces wound inconsistently)."""
    rotation = align(source[0][pairs[:, 0]], target[0][pairs[:, 1]]).rotation
    turned = vertex_normals(*source)[pairs[:, 0]] @ rotation.T
    cosine = np.einsum("ij,ij->i", turned, vertex_normals(*target)[pairs[:, 1]])
    if np.median(cosine) < 0:  # wound the other way round
        cosine = -cosine
    apart = cosine < 0
    return apart if apart.mean() <= FACING_SHARE else np.zeros_like(apart)


def face_tree(vertices, faces) -> cKDTree:
    """A k-d tree of a triangle surface's face centroids, for :func:`closest_on_faces`
    and :func:`face_distances` called several times on one surface."""
    return cKDTree(np.asarray(vertices, dtype=np.float64)[np.asarray(faces)].mean(axis=1))


def face_distances(points, vertices, faces, tree: cKDTree | None = None) -> np.ndarray:
    """The distance (p,) of every point to a triangle surface (:func:`closest_on_faces`)."""
    points = np.asarray(points, dtype=np.float64)
    return np.linalg.norm(points - closest_on_faces(points, vertices, faces, tree), axis=1)


def closest_on_faces(points, vertices, faces, tree: cKDTree | None = None) -> np.ndarray:
    """The closest point (p, 3) of a triangle surface to every point (Ericson's
    closest point on a triangle, over the ``FACE_CANDIDATES`` faces whose centroids are
    nearest). ``tree``: :func:`face_tree` of the surface, when one is kept for several
    calls."""
    return _closest_faces(points, vertices, faces, tree)[0]


def _closest_faces(points, vertices, faces, tree: cKDTree | None = None):
    """:func:`closest_on_faces` and the index (p,) of the face each closest point is on."""
    points = np.asarray(points, dtype=np.float64)
    tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces)]  # (f, 3, 3)
    if tree is None:
        tree = cKDTree(tri.mean(axis=1))
    k = min(FACE_CANDIDATES, len(tri))
    out = np.empty_like(points)
    which = np.empty(len(points), dtype=np.intp)
    for b in range(0, len(points), BLOCK):
        p = points[b:b + BLOCK]
        cand = tree.query(p, k=k)[1].reshape(len(p), k)
        best = _closest_on_triangles(np.repeat(p, k, axis=0), tri[cand.ravel()])
        best = best.reshape(len(p), k, 3)
        pick = np.argmin(np.sum((best - p[:, None]) ** 2, axis=2), axis=1)
        out[b:b + BLOCK] = best[np.arange(len(p)), pick]
        which[b:b + BLOCK] = cand[np.arange(len(p)), pick]
    return out, which


def closest_on_band(points, vertices, faces, tree: cKDTree | None = None) -> np.ndarray:
    """The closest point (p, 3) of a coarse triangle surface *at its resolution* to every
    point: of the band between its faces (chords) and the smooth surface through its
    vertices, the curved point-normal triangles of Vlachos et al. (2001) over the faces
    (vertex normals: the main axis of the incident faces' area-weighted normals, of
    either sign, as the patches need): from the closest point of the faces along the
    face's normal up to the patch's height there. A finer surface on the smooth one stands off the
    faces by their sagitta (an icosphere of 642 vertices mapped onto the ellipsoid
    through one of 162: 1.6 tolerances on average; method.md §5); one on the faces or on
    the patches is on the band, and one beyond either is as far from it."""
    points = np.asarray(points, dtype=np.float64)
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces)
    on, face = _closest_faces(points, vertices, faces, tree)
    tri = vertices[faces[face]]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal /= np.maximum(np.linalg.norm(normal, axis=1), 1e-300)[:, None]
    height = np.einsum("ij,ij->i", _patch_offsets(on, face, vertices, faces), normal)
    along = np.einsum("ij,ij->i", points - on, normal)
    return on + np.clip(along, np.minimum(height, 0), np.maximum(height, 0))[:, None] * normal


def _vertex_axes(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """A unit normal (m, 3) at every vertex: the main axis of the area-weighted normals
    of its faces, sign-free (a scan's faces may be wound either way)."""
    tri = vertices[faces]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # 2 area x normal
    area = np.linalg.norm(cross, axis=1)
    outer = np.einsum("fi,fj->fij", cross, cross) / np.maximum(area, 1e-300)[:, None, None]
    scatter = np.zeros((len(vertices), 3, 3))
    for corner in range(3):
        np.add.at(scatter, faces[:, corner], outer)
    return np.linalg.eigh(scatter)[1][:, :, -1]


def _patch_offsets(on: np.ndarray, face: np.ndarray, vertices: np.ndarray,
                   faces: np.ndarray) -> np.ndarray:
    """The offset (p, 3) from points ``on`` faces ``face`` to the point-normal triangle
    (Vlachos et al. 2001) over that face at the same barycentric coordinates: the cubic
    patch through the face's vertices, tangent there to the planes of their normals."""
    normal = _vertex_axes(vertices, faces)
    corner = faces[face]  # (p, 3)
    P, N = vertices[corner], normal[corner]  # (p, 3, 3): corner, coordinate
    e1, e2, q = P[:, 1] - P[:, 0], P[:, 2] - P[:, 0], on - P[:, 0]
    gram = np.stack([np.einsum("ij,ij->i", e1, e1), np.einsum("ij,ij->i", e1, e2),
                     np.einsum("ij,ij->i", e2, e2)])
    rhs = np.stack([np.einsum("ij,ij->i", q, e1), np.einsum("ij,ij->i", q, e2)])
    det = gram[0] * gram[2] - gram[1] ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        v = np.nan_to_num((gram[2] * rhs[0] - gram[1] * rhs[1]) / det)
        w = np.nan_to_num((gram[0] * rhs[1] - gram[1] * rhs[0]) / det)
    bary = np.stack([1 - v - w, v, w], axis=1)  # (p, 3)

    def lift(i, j):  # the control point b_iij's offset from the flat triangle's
        return -np.einsum("pk,pk->p", P[:, j] - P[:, i], N[:, i])[:, None] * N[:, i] / 3

    edges = [(i, j) for i in range(3) for j in range(3) if i != j]
    lifts = {e: lift(*e) for e in edges}
    centre = 1.5 * sum(lifts.values()) / 6  # b_111's offset: E + (E - V) / 2
    out = 6 * np.prod(bary, axis=1)[:, None] * centre
    for i, j in edges:
        out += 3 * (bary[:, i] ** 2 * bary[:, j])[:, None] * lifts[i, j]
    return out


def _closest_on_triangles(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Closest point (n, 3) of triangle ``tri[i]`` (n, 3, 3) to ``p[i]`` (n, 3): the
    Voronoi regions of its vertices, edges and face (Ericson, Real-Time Collision
    Detection, 5.1.5)."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    ab, ac, ap = b - a, c - a, p - a
    bp, cp = p - b, p - c
    dot = lambda u, v: np.einsum("ij,ij->i", u, v)  # noqa: E731
    d1, d2, d3, d4, d5, d6 = dot(ab, ap), dot(ac, ap), dot(ab, bp), dot(ac, bp), \
        dot(ab, cp), dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = 1.0 / (va + vb + vc)
        v, w = vb * denom, vc * denom
        out = a + ab * v[:, None] + ac * w[:, None]  # inside the face
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        t_ac = d2 / (d2 - d6)
        t_ab = d1 / (d1 - d3)
    regions = (  # the later regions take precedence, as in Ericson's early returns
        (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0), b + (c - b) * t_bc[:, None],
        (vb <= 0) & (d2 >= 0) & (d6 <= 0), a + ac * t_ac[:, None],
        (vc <= 0) & (d1 >= 0) & (d3 <= 0), a + ab * t_ab[:, None],
        (d6 >= 0) & (d5 <= d6), c,
        (d3 >= 0) & (d4 <= d3), b,
        (d1 <= 0) & (d2 <= 0), a,
    )
    for where, at in zip(regions[::2], regions[1::2], strict=True):
        out = np.where(where[:, None], at, out)
    return out


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


def unlike_sentence(pairs: np.ndarray, m: int, n: int) -> str:
    """What a 3D morph's message adds when its pairs reach fewer distinct target nodes
    than ``DISTINCT_PARTNERS`` of the smaller node count (``m`` source, ``n`` target
    nodes): the objects are likely too unlike for the matcher; '' otherwise."""
    distinct, fewer = len(np.unique(pairs[:, 1])), min(m, n)
    if distinct >= DISTINCT_PARTNERS * fewer:
        return ""
    return (f"; the pairs reach only {distinct} distinct target nodes of {fewer}: the "
            f"objects may be too unlike for the matcher, which follows one shape warped by "
            f"up to a quarter of its size")


def intersection_sentence(counts, *, model_nodes: int | None = None,
                          nodes: int | None = None, turn: float | None = None,
                          contours: bool = False) -> str:
    """What a morph's message adds about its self-intersections: faces that cut another
    at each step of a surface, or with ``contours`` segments that cross another of a 2D
    shape (``counts[0]``: the source's own, as given; a scan or a sculpted mesh may have
    some): nothing when no step has more than the source; the source's own count when it
    has some; for steps with more, when the pairs turn the source by ``turn`` degrees,
    more than ``TURN_HINT``, and the morph takes that turn as a deformation, the hint to
    remove it first; else for a surface with a reduced model (``model_nodes`` <
    ``nodes``), the hint to model every node, which avoided them on the bunny when the
    reduced model moved with the element's field (method.md §5)."""
    if counts is None:
        return ""
    counts = np.asarray(counts)
    own = int(counts[0])
    what, cut, cuts, parts = (
        ("contours", "cross themselves", "crosses itself", "crossings") if contours else
        ("surfaces", "intersect themselves", "intersects itself", "faces"))
    said = f"; the source {what[:-1]} {cuts} as given ({own} {parts})" if own else ""
    steps = np.flatnonzero(counts > own)
    if not len(steps):
        return said + (", and no step adds any" if own else "")
    hint = (f"; model_nodes={nodes} (a model of every node, not {model_nodes}) may avoid "
            f"them" if not contours and model_nodes is not None and nodes is not None
            and model_nodes < nodes else "")
    if turn is not None and turn > TURN_HINT:
        hint = (f"; the pairs turn the source by {turn:.0f} deg, which the morph takes "
                f"straight, through a flattened shape: remove_rigid=true (the turn taken "
                f"first) may avoid them")
    more = f"{parts}, more than the source's {own}" if own else parts
    return (f"{said}; {len(steps)} of {len(counts)} steps' {what} {cut} "
            f"(up to {counts.max()} {more}, first at step {steps[0]}){hint}")
