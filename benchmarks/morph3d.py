"""3D morphs driven by the matcher's pairs (or the true ones) on benchmarks/match3d.py's
cases: steps, convergence and the end shape's distance to the target both ways.

    PYTHONPATH=src python benchmarks/morph3d.py --shape blob --points 2000 20000 \
        --angles 0 90 --noise 0 0.01 [--pairs matcher|true]

``--surfaces`` morphs meshes with faces instead and reports the self-intersections of
every step's surface (faces cutting another face, pymeshlab): the largest count, the
number of steps with any, and the counts per step. The meshes: icospheres of trimesh
onto finer or coarser turned ellipsoids, radii (1.3, 1, 0.8) or as named; the bunny
(``data/bunny.npz``) onto warped and turned copies of itself, and onto a coarser
(pymeshlab's quadric edge collapse) and a finer (trimesh's subdivision) copy, warped and
turned; the bone, cow and airplane scans that pymeshlab ships with its tests (GPL-3:
read from the installed package at run time, never copied), warped and turned; the
surface of scikit-image's 3D binary blobs (the largest blob, ``marching_cubes``,
4 voxels a step), warped and turned. ``--cases`` picks some by name (substrings),
``--model-nodes`` sets the reduced model's size.

``--resolutions`` morphs icospheres onto turned ellipsoids at other resolutions (42-2562
vertices, radii (1.3, 1, 0.8), (1.5, 1, 0.7), (2, 1, 0.5)) with the true pairs and the
matcher's.

``--levels`` morphs real meshes onto coarser and finer versions of themselves: pymeshlab's
scans and bunny of 10 000 vertices (GPL-3, read at run time) and the bunny of
``data/bunny.npz``, each as given (fine) and decimated to a third of its vertices
(pymeshlab's quadric edge collapse; coarse); one warp field (``match3d.warp_field``,
5-25 % of the size, built on the fine mesh) and a 30 degree turn move both, so the fine
mesh moved is the truth under the coarse target's chords: "true/tol" is the end shape's
mean distance to the true surface's faces, in tolerances (for a coarse source, the
target's own).

``--primitives`` morphs one shape onto another of trimesh's primitives (sphere, capsule,
cylinder, box, cone; the target turned, scaled by 1.3 and moved): shapes unlike each
other, beyond the warps of 5-25 % that ``match3d.py`` measures.

With faces, "ab/tol" and "ba/tol" are the end shape's mean distance to the target's
faces and the target's vertices' to the end shape's faces (the closest points on the
triangles), in tolerances, whatever the stop test measured; "turn" the turn of the
pairs (Horn), degrees.

Distances are mean nearest-point distances in % of the target's RMS radius ("size"): one
target node spacing is about 4 % of the size at 2000 points and 1.3 % at 20 000, and with
1 % noise the noise-free truth itself lies about 1.3-2 % from the noisy target.
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

import modalmorph as mm

sys.path.insert(0, str(Path(__file__).parent))
from match3d import bunny_mesh, make_case, warp  # noqa: E402


def run(shape, m, angle, noise, pairs_from):
    src, tgt, truth = make_case(shape, m, angle, noise)
    start = time.perf_counter()
    if pairs_from == "true":
        matching = np.c_[np.arange(m), cKDTree(tgt).query(truth)[1]]
    else:
        matching = mm.match(src, tgt)
    result = mm.morph(src, tgt, matching=matching)
    end, size = result.shapes[-1], mm.Shape(tgt).size
    fwd = cKDTree(tgt).query(end)[0].mean() / size
    bwd = cKDTree(end).query(tgt)[0].mean() / size
    print(f"{shape:>6} {m:7d} {angle:5.0f} {noise:5.2f} {pairs_from:>8} {result.steps:5d} "
          f"{str(result.converged):>5} {100 * fwd:8.2f} {100 * bwd:8.2f} "
          f"{time.perf_counter() - start:7.1f}", flush=True)


def surface_cases():
    """(name, source Shape, target Shape) of the mesh cases."""
    import trimesh
    from scipy.spatial.transform import Rotation

    ico = {s: trimesh.creation.icosphere(s) for s in (2, 3, 4)}
    turn = Rotation.from_rotvec([0.3, -0.5, 0.4])
    cases = []
    for a, b, radii in ((2, 3, (1.3, 1.0, 0.8)), (3, 2, (1.3, 1.0, 0.8)),
                        (2, 4, (1.3, 1.0, 0.8)), (3, 3, (1.3, 1.0, 0.8)),
                        (2, 3, (1.2, 1.0, 0.9)), (2, 3, (2.0, 1.0, 0.5))):
        src = mm.Shape(np.asarray(ico[a].vertices), faces=np.asarray(ico[a].faces))
        tgt = mm.Shape(turn.apply(np.asarray(ico[b].vertices) * radii),
                       faces=np.asarray(ico[b].faces))
        cases.append((f"ico{src.m}->ell{tgt.m}" + ("" if radii[0] == 1.3 else f"x{radii[0]:g}"),
                      src, tgt))
    points, faces = bunny_mesh()
    for angle in (0, 30, 90):
        rng = np.random.default_rng([1, angle])
        rot = Rotation.from_rotvec(np.deg2rad(angle) * np.array([0.3, -0.5, 0.8]) / 0.990)
        moved = rot.apply(warp(points, rng))
        cases.append((f"bunny->warp{angle}", mm.Shape(points, faces=faces),
                      mm.Shape(moved, faces=faces)))
    return cases


def _turn(points, angle, seed):
    """``points`` warped (``match3d.warp``, 5-25 % of the size) and turned by ``angle``
    degrees about an oblique axis."""
    from scipy.spatial.transform import Rotation
    rng = np.random.default_rng([seed, angle])
    rot = Rotation.from_rotvec(np.deg2rad(angle) * np.array([0.3, -0.5, 0.8]) / 0.990)
    return rot.apply(warp(points, rng, span=(0.05, 0.25)))


def _decimated(points, faces, vertices):
    """The mesh decimated to about ``vertices`` (pymeshlab's quadric edge collapse)."""
    import pymeshlab
    meshes = pymeshlab.MeshSet()
    meshes.add_mesh(pymeshlab.Mesh(points, faces.astype(np.int32)))
    meshes.meshing_decimation_quadric_edge_collapse(targetfacenum=2 * vertices - 4,
                                                    preservetopology=True)
    mesh = meshes.current_mesh()
    return mesh.vertex_matrix(), mesh.face_matrix().astype(np.intp)


def _sample_meshes():
    """(name, points, faces) of the scans pymeshlab ships (read, not copied: GPL-3)."""
    import pymeshlab
    import trimesh
    folder = Path(pymeshlab.__file__).parent / "tests" / "sample_meshes"
    for name in ("bone.ply", "cow.obj", "airplane.obj"):
        mesh = trimesh.load(folder / name, force="mesh", process=True)
        yield name.split(".")[0], np.asarray(mesh.vertices), np.asarray(mesh.faces)


def _blob_mesh():
    """The surface of the largest of scikit-image's 3D binary blobs (marching cubes every
    4 voxels; decimated by pymeshlab it cut itself), its faces on the same three
    vertices kept once (two pairs, which cut each other once moved)."""
    import trimesh
    from scipy import ndimage
    from skimage import data, measure
    volume = data.binary_blobs(length=64, n_dim=3, volume_fraction=0.25, rng=3)
    label = measure.label(volume)
    blob = ndimage.binary_fill_holes(label == np.argmax(np.bincount(label.ravel())[1:]) + 1)
    points, faces, *_ = measure.marching_cubes(np.pad(blob, 2).astype(float), 0.5,
                                               step_size=4)
    mesh = trimesh.Trimesh(points, faces, process=True)
    mesh.update_faces(mesh.unique_faces())
    mesh.remove_unreferenced_vertices()
    return np.asarray(mesh.vertices), np.asarray(mesh.faces)


def mesh_cases():
    """(name, source Shape, target Shape) of the real meshes: the bunny at other
    resolutions, pymeshlab's scans and scikit-image's blob, each onto a warped and
    turned copy; those whose package is missing are left out (and said)."""
    import trimesh
    points, faces = bunny_mesh()
    cases = []
    try:
        coarse = _decimated(points, faces, 900)
        for a, b, tag in ((coarse, (points, faces), "bunny900->1839"),
                          ((points, faces), coarse, "bunny1839->900")):
            cases.append((tag + "w30", mm.Shape(a[0], faces=a[1]),
                          mm.Shape(_turn(b[0], 30, 2), faces=b[1])))
        cases += [(f"{n}->warp30", mm.Shape(p, faces=f), mm.Shape(_turn(p, 30, 3), faces=f))
                  for n, p, f in _sample_meshes()]
        blob = _blob_mesh()
        cases.append(("blobs->warp30", mm.Shape(blob[0], faces=blob[1]),
                      mm.Shape(_turn(blob[0], 30, 4), faces=blob[1])))
    except ImportError as error:
        print(f"left out (no {error.name}): the decimated bunny, the scans, the blob")
    fine = trimesh.Trimesh(points, faces, process=False).subdivide()
    cases.append(("bunny1839->7k w30", mm.Shape(points, faces=faces),
                  mm.Shape(_turn(np.asarray(fine.vertices), 30, 5),
                           faces=np.asarray(fine.faces))))
    return cases


def resolution_grid():
    """Icospheres onto turned ellipsoids at other resolutions (42-2562 vertices; the
    coarser one's vertices are the first of the finer's, so the true pairs are known),
    with the true pairs and the matcher's: steps, why it stopped, d/tol, the largest
    count of self-intersecting faces, the end shape's mean distance to the true
    ellipsoid (Sampson's first-order distance), in tolerances."""
    import trimesh
    from scipy.spatial.transform import Rotation

    ico = {s: trimesh.creation.icosphere(s) for s in (1, 2, 3, 4)}
    turn = Rotation.from_rotvec([0.3, -0.5, 0.4])
    print(f"{'source':>6} {'target':>6} {'radii':>14} {'pairs':>7} {'stop':>11} "
          f"{'steps':>5} {'d/tol':>6} {'ab/tol':>6} {'ba/tol':>6} {'turn':>4} {'max':>5} "
          f"{'true/tol':>8}")
    for a, b in ((3, 2), (4, 2), (3, 1), (2, 3), (2, 4)):
        for radii in ((1.3, 1, 0.8), (1.5, 1, 0.7), (2, 1, 0.5)):
            va, vb = np.asarray(ico[a].vertices), np.asarray(ico[b].vertices)
            n = min(len(va), len(vb))
            src = mm.Shape(va, faces=np.asarray(ico[a].faces))
            tgt = mm.Shape(turn.apply(vb * radii), faces=np.asarray(ico[b].faces))
            for name, pairs in (("true", np.c_[np.arange(n), np.arange(n)]), ("matcher", None)):
                r = mm.morph(src, tgt, matching=pairs)
                crossed = "-" if r.self_intersections is None else r.self_intersections.max()
                local = turn.inv().apply(np.asarray(r.shapes[-1])) / radii
                grad = np.linalg.norm(2 * local / radii, axis=1)  # Sampson's distance
                true = np.abs(np.sum(local**2, axis=1) - 1) / grad
                print(f"{src.m:6d} {tgt.m:6d} {str(radii):>14} {name:>7} {r.stop_reason:>11} "
                      f"{r.steps:5d} {r.distance / r.tolerance:6.2f} {on_faces(r, src, tgt)} "
                      f"{crossed:>5} {true.mean() / r.tolerance:8.2f}", flush=True)


def _primitive(name: str):
    """(points, faces) of one of trimesh's primitives, about 500-1500 vertices, closed."""
    import trimesh

    make = {"sphere": lambda: trimesh.creation.icosphere(3),
            "capsule": lambda: trimesh.creation.capsule(height=2.0, radius=0.6,
                                                        count=[24, 24]),
            "cylinder": lambda: trimesh.creation.cylinder(0.7, 2.0, sections=32)
            .subdivide().subdivide(),
            "box": lambda: trimesh.creation.box([2, 1.2, 0.8]).subdivide().subdivide()
            .subdivide().subdivide(),
            "cone": lambda: trimesh.creation.cone(0.8, 1.6, sections=32).subdivide()
            .subdivide()}
    mesh = make[name]()
    mesh.merge_vertices()
    return np.asarray(mesh.vertices), np.asarray(mesh.faces)


def primitive_cases():
    """(name, source, target) of one primitive onto another, turned, scaled, moved."""
    from scipy.spatial.transform import Rotation

    turn = Rotation.from_rotvec([0.2, -0.3, 0.25])
    cases = []
    for a, b in (("sphere", "capsule"), ("capsule", "sphere"), ("sphere", "box"),
                 ("box", "sphere"), ("cylinder", "capsule"), ("capsule", "cylinder"),
                 ("sphere", "cone"), ("cone", "cylinder"), ("box", "capsule")):
        (pa, fa), (pb, fb) = _primitive(a), _primitive(b)
        cases.append((f"{a}->{b}", mm.Shape(pa, faces=fa),
                      mm.Shape(turn.apply(pb) * 1.3 + [0.5, 0, 0], faces=fb)))
    return cases


def level_cases():
    """(name, source, target, truth) of each real mesh onto a coarser and a finer version
    of itself, warped and turned (``--levels``)."""
    import pymeshlab
    import trimesh
    from match3d import warp_field
    from scipy.spatial.transform import Rotation
    folder = Path(pymeshlab.__file__).parent / "tests" / "sample_meshes"
    meshes = [("bunny", *bunny_mesh())]
    for name in ("bone.ply", "cow.obj", "airplane.obj", "bunny10k_textured.obj"):
        mesh = trimesh.load(folder / name, force="mesh", process=True)
        mesh.merge_vertices(merge_tex=True, merge_norm=True)  # the texture's seams
        meshes.append((name.split(".")[0][:8], np.asarray(mesh.vertices),
                       np.asarray(mesh.faces)))
    rot = Rotation.from_rotvec(np.deg2rad(30) * np.array([0.3, -0.5, 0.8]) / 0.990)
    cases = []
    for seed, (name, points, faces) in enumerate(meshes):
        coarse, coarse_faces = _decimated(points, faces, len(points) // 3)
        field = warp_field(points, np.random.default_rng([seed, 7]), span=(0.05, 0.25))
        move = lambda q, field=field: rot.apply(q + field(q))  # noqa: E731
        fine, small = mm.Shape(points, faces=faces), mm.Shape(coarse, faces=coarse_faces)
        truth = mm.Shape(move(points), faces=faces)
        cases.append((f"{name}{fine.m}->{small.m}", fine,
                      mm.Shape(move(coarse), faces=coarse_faces), truth))
        cases.append((f"{name}{small.m}->{fine.m}", small, truth, truth))
    return cases


def run_level(name, src, tgt, truth):
    """One ``--levels`` case: as :func:`run_surface`, and the end shape's distance to the
    true surface."""
    from modalmorph.core.surfaces import face_distances
    start = time.perf_counter()
    result = mm.morph(src, tgt)
    seconds = time.perf_counter() - start
    true = face_distances(np.asarray(result.shapes[-1]), truth.points, truth.faces).mean()
    counts = result.self_intersections
    crossed = "-" if counts is None else f"{counts.max():5d} {np.count_nonzero(counts):5d}"
    print(f"{name:>22} {result.steps:5d} {str(result.converged):>5} "
          f"{result.distance / result.tolerance:6.2f} {seconds:6.1f} {on_faces(result, src, tgt)} "
          f"{true / result.tolerance:8.2f}  {crossed}", flush=True)


def on_faces(result, src, tgt):
    """The end shape's mean distance to the target's faces and the target's vertices' to
    the end shape's faces, in tolerances; the pairs' turn (degrees)."""
    from modalmorph.core.align import align
    from modalmorph.core.surfaces import face_distances
    end, pairs = np.asarray(result.shapes[-1]), result.matching.pairs
    ab = face_distances(end, tgt.points, tgt.faces).mean()
    ba = face_distances(tgt.points, end, src.faces).mean()
    turn = align(src.points[pairs[:, 0]], tgt.points[pairs[:, 1]]).angle
    return f"{ab / result.tolerance:6.2f} {ba / result.tolerance:6.2f} {turn:4.0f}"


def run_surface(name, src, tgt, **options):
    start = time.perf_counter()
    result = mm.morph(src, tgt, **options)
    seconds = time.perf_counter() - start
    faces = on_faces(result, src, tgt)
    counts = result.self_intersections
    if counts is None:
        crossed = "not checked (no pymeshlab)"
    else:
        crossed = (f"{counts.max():5d} {np.count_nonzero(counts):5d}  "
                   + ",".join(map(str, counts)))
    print(f"{name:>20} {src.m:6d} {tgt.m:6d} {result.steps:5d} {str(result.converged):>5} "
          f"{result.distance / result.tolerance:6.2f} {seconds:6.1f} {faces}  {crossed}",
          flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--surfaces", action="store_true",
                        help="the mesh cases, with self-intersections per step")
    parser.add_argument("--resolutions", action="store_true",
                        help="icospheres onto ellipsoids at other resolutions, true and "
                        "matcher pairs")
    parser.add_argument("--primitives", action="store_true",
                        help="one of trimesh's primitives onto another, with "
                        "self-intersections per step")
    parser.add_argument("--levels", action="store_true",
                        help="real meshes onto coarser and finer versions of themselves")
    parser.add_argument("--model-nodes", type=int, default=None,
                        help="with --surfaces: the morphs' model_nodes (default: theirs)")
    parser.add_argument("--cases", nargs="+", default=None,
                        help="with --surfaces: only the cases whose names contain these")
    parser.add_argument("--shape", default="blob", choices=("blob", "bunny"))
    parser.add_argument("--points", type=int, nargs="+", default=[2000, 20000])
    parser.add_argument("--angles", type=float, nargs="+", default=[0.0, 90.0])
    parser.add_argument("--noise", type=float, nargs="+", default=[0.0, 0.01])
    parser.add_argument("--pairs", default="matcher", choices=("matcher", "true"))
    args = parser.parse_args()
    if args.resolutions:
        resolution_grid()
        return
    if args.levels:
        print(f"{'case':>22} {'steps':>5} {'conv':>5} {'d/tol':>6} {'time s':>6} "
              f"{'ab/tol':>6} {'ba/tol':>6} {'turn':>4} {'true/tol':>8}  {'max':>5} {'steps':>5}")
        for case in level_cases():
            if args.cases is None or any(c in case[0] for c in args.cases):
                run_level(*case)
        return
    if args.surfaces or args.primitives:
        print(f"{'case':>20} {'source':>6} {'target':>6} {'steps':>5} {'conv':>5} "
              f"{'d/tol':>6} {'time s':>6} {'ab/tol':>6} {'ba/tol':>6} {'turn':>4}  "
              f"{'max':>5} {'steps':>5}  self-intersecting faces per step")
        cases = primitive_cases() if args.primitives else surface_cases() + mesh_cases()
        for case in cases:
            if args.cases is None or any(c in case[0] for c in args.cases):
                run_surface(*case, **({} if args.model_nodes is None
                                      else {"model_nodes": args.model_nodes}))
        return
    print(" shape  points angle noise    pairs steps  conv  end->t%  t->end%  time s")
    for m in args.points:
        for angle in args.angles:
            for noise in args.noise:
                run(args.shape, m, angle, noise, args.pairs)


if __name__ == "__main__":
    main()
