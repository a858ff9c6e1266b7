"""3D morphs driven by the matcher's pairs (or the true ones) on benchmarks/match3d.py's
cases: steps, convergence and the end shape's distance to the target both ways.

    PYTHONPATH=src python benchmarks/morph3d.py --shape blob --points 2000 20000 \
        --angles 0 90 --noise 0 0.01 [--pairs matcher|true]

``--surfaces`` morphs meshes with faces instead (icospheres of trimesh onto finer or
coarser turned ellipsoids, radii (1.3, 1, 0.8) or as named, the bunny onto warped and
turned copies of itself) and reports the self-intersections of every step's surface
(faces cutting another face, pymeshlab): the largest count, the number of steps with
any, and the counts per step.

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


def run_surface(name, src, tgt):
    start = time.perf_counter()
    result = mm.morph(src, tgt)
    seconds = time.perf_counter() - start
    counts = result.self_intersections
    if counts is None:
        crossed = "not checked (no pymeshlab)"
    else:
        crossed = (f"{counts.max():5d} {np.count_nonzero(counts):5d}  "
                   + ",".join(map(str, counts)))
    print(f"{name:>18} {src.m:6d} {tgt.m:6d} {result.steps:5d} {str(result.converged):>5} "
          f"{result.distance / result.tolerance:6.2f} {seconds:6.1f}  {crossed}", flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--surfaces", action="store_true",
                        help="the mesh cases, with self-intersections per step")
    parser.add_argument("--shape", default="blob", choices=("blob", "bunny"))
    parser.add_argument("--points", type=int, nargs="+", default=[2000, 20000])
    parser.add_argument("--angles", type=float, nargs="+", default=[0.0, 90.0])
    parser.add_argument("--noise", type=float, nargs="+", default=[0.0, 0.01])
    parser.add_argument("--pairs", default="matcher", choices=("matcher", "true"))
    args = parser.parse_args()
    if args.surfaces:
        print(f"{'case':>18} {'source':>6} {'target':>6} {'steps':>5} {'conv':>5} "
              f"{'d/tol':>6} {'time s':>6}  {'max':>5} {'steps':>5}  self-intersecting "
              f"faces per step")
        for case in surface_cases():
            run_surface(*case)
        return
    print(" shape  points angle noise    pairs steps  conv  end->t%  t->end%  time s")
    for m in args.points:
        for angle in args.angles:
            for noise in args.noise:
                run(args.shape, m, angle, noise, args.pairs)


if __name__ == "__main__":
    main()
