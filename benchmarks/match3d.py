"""3D correspondence on scanned and procedural surfaces: modalmorph against CPD and BCPD
(issues 16, 25).

Each case is a surface sampled evenly (area-weighted random points on its faces) at
``m`` points: the source. The target is the same points moved by a smooth random warp
(displacements of 5-15 % of the size), turned by ``angle`` degrees about a random axis,
with Gaussian noise (``--noise``, a fraction of the size), of which a random 80 % is kept,
shuffled. The ground truth of source point ``i`` is where the warp and turn take it
(without the noise). A pair's error is the distance from the target point it names to
that true position, in units of the target's mean nearest-neighbour spacing.

Shapes:

- ``torus``: trimesh's torus (radii 1 and 0.35; ``pip install trimesh``), a smooth body
  symmetric about its axis.
- ``twisted``: the twisted ellipsoid of ``benchmarks/scale.py`` (its blob, bent, twisted
  and turned by its ``deform`` instead of the random warp); with ``--variants all
  --noise 0 --angles 0`` it is scale.py's case.
- ``bunny``: the Stanford bunny (Stanford 3D Scanning Repository; public domain), the
  1839-vertex, 3674-face mesh of the npm package ``bunny`` 1.0.1, stored in
  ``benchmarks/data/bunny.npz`` (40 KB).
- ``blob``: the asymmetric bumpy ellipsoid of ``benchmarks/scale.py`` (procedural),
  sampled through uniform points on the sphere.
- ``cow``, ``bone``, ``airplane``: the sample meshes that ship inside pymeshlab (GPL-3;
  read from the installed package at run time, never copied here; ``pip install
  pymeshlab``), each closed: a cow, a bone, an airplane with thin wings.

Columns: best (the median distance from the true position to the nearest target point:
what no pairing can beat; with noise or uneven sampling it is not 0), sim (the median
error of pairing each source point with the target point nearest to where the truth's
best similarity takes it: the pose alone, no deformation), med/p90 (median
and 90th percentile error of the pairs returned), paired (the fraction of source points
given a partner), <=1 / <=3 (fraction of source points whose pair is within 1 and 3
spacings; unpaired points count as wrong), med/best (the median over the floor `best`:
how far a row is from what a pairing can reach), sym (for a body with a symmetry, the torus and
the bone (:func:`bone_turns`): the median error under the best of its symmetries, what a
correspondence can identify there; NaN for the others), time and peak memory (each case
in its own process: peak resident set size of the child, MB), and the machine's load
average (1 minute) when the case ended: on a shared machine wall time grows with it.

Variants (``--variants``,
:data:`VARIANTS`): ``base`` as above; ``warp5`` and ``warp25`` a warp of exactly 5 % and
25 % of the size; ``cut``, 20 % of the target cut away as one cap instead of at random;
``resampled``, the target's points sampled anew on the same surface, evenly as the source
(as many, area-weighted on a mesh's faces, with the generator's next draws), then warped,
turned, noised and 80 % kept as in ``base``: two scans of one surface share no samples,
and in every variant but this one and ``uneven`` a route can find each source point's own
moved copy. Its best (the median distance from the truth to the nearest of independent
random target points) is then 0.82-0.95 spacings (measured at 2000-1 000 000 points; for
uniform random points in a plane sqrt(ln 2 / pi) / (1/2) = 0.94 of their mean
nearest-neighbour spacing), so no pairing gets much under 1 spacing there (``twisted`` is a
lattice, the same points again: there it is ``base``);
``uneven``, the target sampled anew with a density growing 20 times across it, as a
scanner sees a surface (errors then include the distance from the true position to the
nearest target sample); ``all``, every target point kept.

Peers (``--methods``, :data:`PEERS`): ``cpd``, pycpd's deformable CPD; ``cpdr``, pycpd's
rigid CPD and then its deformable CPD, on both sets scaled to unit RMS radius
(:func:`run_cpd_rigid`); ``bcpd``,
probreg's Python BCPD (:func:`run_bcpd`; the issue's BCPD++ is a C program that no
package registry ships). Both are optional (``pip install pycpd probreg``) and run up
to ``--cpd-up-to`` points.

Run ``python benchmarks/match3d.py`` for the whole table (the peers only up to
``--cpd-up-to`` points, 2000 by default: pycpd took over 600 s at 10 000; each case limited by
``--timeout`` seconds), or
``--sizes 2000 --angles 0,180 --shapes bunny`` for part of it; issue 25's large rows:
``--shapes blob --sizes 100000,1000000 --angles 30 --methods modalmorph`` (about 40 s and
0.6 GB at 1 000 000 points).
"""

from __future__ import annotations

import argparse
import functools
import importlib.util
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

DATA = Path(__file__).parent / "data" / "bunny.npz"
KEEP = 0.8  # fraction of the target's points kept
WARP = (0.05, 0.15)  # largest displacement of the warp, fraction of the size


def bunny_mesh() -> tuple[np.ndarray, np.ndarray]:
    with np.load(DATA) as f:
        return f["positions"].astype(np.float64), f["faces"].astype(np.intp)


def sample_mesh(points: np.ndarray, faces: np.ndarray, m: int, rng) -> np.ndarray:
    """``m`` points on a triangle mesh, uniform by area."""
    a, b, c = (points[faces[:, k]] for k in range(3))
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    f = rng.choice(len(faces), size=m, p=area / area.sum())
    u, v = rng.random((2, m))
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    return a[f] + u[:, None] * (b[f] - a[f]) + v[:, None] * (c[f] - a[f])


def sample_blob(m: int, rng) -> np.ndarray:
    p = rng.normal(size=(m, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    p *= [1.0, 0.7, 0.5]  # the ellipsoid of benchmarks/model.py, with its bump on top
    p += 0.3 * np.exp(-np.sum((p - [0, 0, 0.5]) ** 2, axis=1) / 0.1)[:, None] * [0, 0, 1]
    c = np.array([0.55, 0.45, -0.2])  # and scale.py's second bump, off every axis
    return p + 0.25 * np.exp(-np.sum((p - c) ** 2, axis=1) / 0.1)[:, None] * c


def warp_field(p: np.ndarray, rng, span=WARP):
    """A smooth random displacement field built on ``p``: 6 Gaussian bumps of width
    0.3-0.6 x the size, scaled so that the largest displacement over ``p`` is a fraction
    ``span`` (drawn in that range) of the size; returns ``field(q) -> (len(q), 3)``."""
    c = p.mean(axis=0)
    size = np.sqrt(np.mean(np.sum((p - c) ** 2, axis=1)))
    centres = p[rng.choice(len(p), 6, replace=False)]
    width = size * rng.uniform(0.3, 0.6, 6)
    dirs = rng.normal(size=(6, 3))

    def bumps(q):
        return sum(np.exp(-np.sum((q - centres[k]) ** 2, axis=1) / (2 * width[k] ** 2))[:, None]
                   * dirs[k] for k in range(6))

    scale = rng.uniform(*span) * size / np.linalg.norm(bumps(p), axis=1).max()
    return lambda q: bumps(q) * scale


def warp(p: np.ndarray, rng, span=WARP) -> np.ndarray:
    """``p`` moved by :func:`warp_field` (5-15 % of the size by default)."""
    return p + warp_field(p, rng, span)(p)


def torus_mesh() -> tuple[np.ndarray, np.ndarray]:
    """trimesh's torus (radii 1 and 0.35): a smooth body symmetric about its axis."""
    import trimesh
    mesh = trimesh.creation.torus(major_radius=1.0, minor_radius=0.35)
    return np.asarray(mesh.vertices), np.asarray(mesh.faces)


# Meshes that ship inside a package: pymeshlab's sample meshes (GPL-3, loaded from the
# installed package at run time, never copied here; ``pip install pymeshlab``): a cow
# (2903 vertices), a bone (1513) and an airplane (5400, thin wings), each closed.
PACKAGED = {"cow": "cow.obj", "bone": "bone.ply", "airplane": "airplane.obj"}


def packaged_mesh(shape: str) -> tuple[np.ndarray, np.ndarray]:
    """One of :data:`PACKAGED`, read with trimesh from pymeshlab's installed tests."""
    import pymeshlab
    import trimesh
    path = Path(pymeshlab.__file__).parent / "tests" / "sample_meshes" / PACKAGED[shape]
    mesh = trimesh.load(path, force="mesh")
    return np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces)


def torus_turns() -> tuple[np.ndarray, np.ndarray]:
    """The torus's symmetries that a proper correspondence can follow: turns about its
    axis (z) every degree, each also flipped over (half a turn about x), as rotations
    (720, 3, 3) and shifts (720, 3) (zero: it is centred)."""
    about = Rotation.from_euler("z", np.arange(360.0)[:, None], degrees=True)
    flip = Rotation.from_euler("x", 180, degrees=True)
    return np.concatenate([about.as_matrix(), (about * flip).as_matrix()]), np.zeros((720, 3))


@functools.cache
def bone_turns() -> tuple[np.ndarray, np.ndarray]:
    """The bone's symmetries as rotations (4, 3, 3) and shifts (4, 3) (``p -> R p + t``):
    the identity and the half turns about its principal axes, each fitted by ICP to lay
    the bone (40 000 points) on itself. Each does so as closely as two samplings of the
    bone lie on each other (median distance 0.15 target spacings of 1000 points, 90th
    percentile 0.28, either way; the cow's half turns 1.8-2.7 and 5.5-6.7): end for end
    and side for side it is one shape, so where the target is sampled anew (``uneven``)
    nothing but the warp tells its ends apart, and the warp turned over is as smooth a
    warp."""
    points, faces = packaged_mesh("bone")
    dense = sample_mesh(points, faces, 40_000, np.random.default_rng(0))
    centre = dense.mean(axis=0)
    axes = np.linalg.eigh((dense - centre).T @ (dense - centre))[1]
    tree = cKDTree(dense)
    turns, shifts = [np.eye(3)], [np.zeros(3)]
    for k in range(3):
        R = axes @ np.diag(np.where(np.arange(3) == k, 1.0, -1.0)) @ axes.T
        t = centre - R @ centre
        for _ in range(20):  # ICP: the half turn that lays the bone on itself
            q = dense @ R.T + t
            near = dense[tree.query(q)[1]]
            turn = Rotation.align_vectors(near - near.mean(axis=0), q - q.mean(axis=0))[0]
            R = turn.as_matrix() @ R
            t = turn.apply(t - q.mean(axis=0)) + near.mean(axis=0)
        turns.append(R)
        shifts.append(t)
    return np.array(turns), np.array(shifts)


def twisted(m: int) -> np.ndarray:
    """benchmarks/scale.py's blob (an ellipsoid with two bumps; Fibonacci lattice)."""
    from scale import blob
    return blob(m)


def sample(shape: str, m: int, rng) -> np.ndarray:
    """``m`` points spread evenly over the shape's surface."""
    if shape == "bunny":
        return sample_mesh(*bunny_mesh(), m, rng)
    if shape == "torus":
        return sample_mesh(*torus_mesh(), m, rng)
    if shape == "twisted":
        return twisted(m)
    if shape in PACKAGED:
        return sample_mesh(*packaged_mesh(shape), m, rng)
    return sample_blob(m, rng)


def uneven(shape: str, m: int, rng) -> np.ndarray:
    """``m`` points sampled unevenly, as a scanner sees a surface: the density grows
    e^3 = 20 times from one side to the other along a random direction."""
    p = sample(shape, 4 * m, rng)
    d = rng.normal(size=3)
    x = p @ (d / np.linalg.norm(d))
    w = np.exp(3 * (x - x.min()) / np.ptp(x))
    return p[rng.choice(len(p), m, replace=False, p=w / w.sum())]


def make_case(shape: str, m: int, angle: float, noise: float, seed: int = 0, *,
              span=WARP, overlap: str = "random", sampling: str = "even", keep=KEEP,
              carry: bool = False):
    """Source (m, 3), target (n, 3), truth (m, 3): where each source point belongs; with
    ``carry`` also the map that takes the source's points to their true places.

    ``span``: the warp's largest displacement, a fraction of the size drawn in that
    range (the twisted shape is bent and twisted by scale.py's ``deform`` instead);
    ``overlap``: ``"random"`` keeps a random fraction ``keep`` of the target's points,
    ``"cut"`` cuts away the rest as one cap (the points farthest along a random
    direction); ``sampling``: ``"even"`` samples the target at the source's points,
    ``"resampled"`` samples it anew as the source is sampled (:func:`sample`, the same
    density, the generator's next draws), ``"uneven"`` anew, unevenly (:func:`uneven`)."""
    rng = np.random.default_rng([seed, m, int(angle)])
    src = sample(shape, m, rng)
    size = np.sqrt(np.mean(np.sum((src - src.mean(axis=0)) ** 2, axis=1)))
    axis = rng.normal(size=3)
    rot = Rotation.from_rotvec(np.deg2rad(angle) * axis / np.linalg.norm(axis))
    if shape == "twisted":
        from scale import deform
        field = lambda q: deform(q) - q  # noqa: E731
    else:
        field = warp_field(src, rng, span)
    shift = size * rng.normal(size=3)
    def move(q):
        return rot.apply(q + field(q)) + shift

    truth = move(src)
    tgt = truth + noise * size * rng.normal(size=truth.shape)
    if sampling != "even":  # sampled anew: evenly as the source, or unevenly
        q = (uneven if sampling == "uneven" else sample)(shape, m, rng)
        tgt = move(q) + noise * size * rng.normal(size=q.shape)
    n = int(round(keep * len(tgt)))
    if overlap == "cut":
        d = rng.normal(size=3)
        tgt = tgt[rng.permutation(np.argsort(tgt @ d)[:n])]
    else:
        tgt = tgt[rng.permutation(len(tgt))[:n]]
    return (src, tgt, truth, move) if carry else (src, tgt, truth)


def similar(src: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """``src`` moved by the similarity (turn, scale, shift) nearest to ``truth`` in least
    squares (Umeyama 1991): where no deformation, only the pose, takes it."""
    a, b = src - src.mean(axis=0), truth - truth.mean(axis=0)
    u, d, vt = np.linalg.svd(b.T @ a)
    flip = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    turn = u @ flip @ vt
    scale = np.sum(d * np.diag(flip)) / np.sum(a**2)
    return scale * a @ turn.T + truth.mean(axis=0)


def errors(src, tgt, truth, pairs) -> tuple[np.ndarray, float]:
    """Per source point: the error of its pair in target spacings (inf: unpaired)."""
    h = cKDTree(tgt).query(tgt, k=2)[0][:, 1].mean()
    err = np.full(len(src), np.inf)
    err[pairs[:, 0]] = np.linalg.norm(tgt[pairs[:, 1]] - truth[pairs[:, 0]], axis=1) / h
    return err, h


def run_modalmorph(src, tgt):
    import modalmorph as mm
    return mm.match(src, tgt).pairs


def run_cpd(src, tgt):
    """pycpd's deformable registration (defaults: beta 2, lambda 2), then each moved source
    point paired with its nearest target point."""
    from pycpd import DeformableRegistration
    moved, _ = DeformableRegistration(X=tgt, Y=src).register()
    return np.c_[np.arange(len(src)), cKDTree(tgt).query(moved)[1]]


def run_bcpd(src, tgt):
    """probreg's BCPD (Bayesian coherent point drift, Hirose 2021; ``pip install
    probreg``) on both sets centred and scaled to unit RMS radius (its defaults assume
    such a scale: on the bunny's own units it did not converge), outlier weight
    w = 0.1, at most 100 iterations; each moved source point paired with its nearest
    target point."""
    from probreg import bcpd

    y = unit_rms(tgt)
    moved = np.asarray(bcpd.registration_bcpd(unit_rms(src), y, w=0.1, maxiter=100)
                       .transform(unit_rms(src)))
    return np.c_[np.arange(len(src)), cKDTree(y).query(moved)[1]]


def unit_rms(p: np.ndarray) -> np.ndarray:
    """``p`` centred and scaled to unit RMS radius."""
    c = p - p.mean(axis=0)
    return c / np.sqrt(np.mean(np.sum(c**2, axis=1)))


def run_cpd_rigid(src, tgt):
    """pycpd's rigid CPD (rotation, scale, shift), then its deformable CPD (defaults: beta
    2, lambda 2) from there, both sets centred and scaled to unit RMS radius first (CPD's
    own normalisation, Myronenko & Song 2010); each moved source point paired with its
    nearest target point. The deformable CPD alone cannot undo a large turn."""
    from pycpd import DeformableRegistration, RigidRegistration
    x, y = unit_rms(tgt), unit_rms(src)
    turned, _ = RigidRegistration(X=x, Y=y).register()
    moved, _ = DeformableRegistration(X=x, Y=turned).register()
    return np.c_[np.arange(len(src)), cKDTree(x).query(moved)[1]]


PEERS = {"modalmorph": run_modalmorph, "cpd": run_cpd, "cpdr": run_cpd_rigid,
         "bcpd": run_bcpd}
SYMMETRIES = {"torus": torus_turns, "bone": bone_turns}  # the error modulo them too


def modulo_symmetry(shape, src, tgt, move, pairs, h) -> float:
    """The median pair error (target spacings) under the best of the body's symmetries
    g (the truth taken as where ``move`` takes g(source)): what is identifiable of a
    correspondence on a symmetric body; NaN for a body with none known."""
    if shape not in SYMMETRIES:
        return float("nan")
    i, j = pairs[:, 0], pairs[:, 1]
    return min(float(np.median(np.linalg.norm(tgt[j] - move(src[i] @ g.T + t), axis=1))) / h
               for g, t in zip(*SYMMETRIES[shape](), strict=True))


# The kinds of case beside the base one (a random 5-15 % warp, 80 % of the target kept at
# random, the target sampled at the source's points): make_case's keyword arguments.
VARIANTS = {
    "base": {},
    "warp5": {"span": (0.05, 0.05)},
    "warp25": {"span": (0.25, 0.25)},
    "cut": {"overlap": "cut"},
    "resampled": {"sampling": "resampled"},
    "uneven": {"sampling": "uneven"},
    "all": {"keep": 1.0},
}


def one(method: str, shape: str, m: int, angle: float, noise: float,
        variant: str = "base") -> dict:
    src, tgt, truth, move = make_case(shape, m, angle, noise, carry=True,
                                      **VARIANTS[variant])
    t0, c0 = time.perf_counter(), time.process_time()
    pairs = PEERS[method](src, tgt)
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # before the scoring
    load = os.getloadavg()[0]
    err, h = errors(src, tgt, truth, pairs)
    paired = err[np.isfinite(err)]
    tree = cKDTree(tgt)
    best = tree.query(truth)[0] / h  # the nearest target point: no pairing does better
    near = tree.query(similar(src, truth))[1]  # the truth's best similarity, no warp
    sim = np.linalg.norm(tgt[near] - truth, axis=1) / h
    return dict(best=float(np.median(best)), sim=float(np.median(sim)),
                med=float(np.median(paired)),
                sym=modulo_symmetry(shape, src, tgt, move, pairs, h),
                p90=float(np.percentile(paired, 90)),
                paired=len(paired) / len(err), w1=float(np.mean(err <= 1)),
                w3=float(np.mean(err <= 3)), s=seconds, cpu=cpu, peak=peak, load=load)


def child(args, method, shape, m, angle, variant="base") -> dict | str:
    cmd = [sys.executable, __file__, "--child", method, shape, str(m), str(angle),
           str(args.noise), variant]
    try:
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=args.timeout)
    except subprocess.TimeoutExpired:
        return "timeout"
    if out.returncode:
        return "out of memory" if "MemoryError" in out.stderr else "failed"
    return json.loads(out.stdout.strip().splitlines()[-1])


def available(method: str, shape: str) -> bool:
    """Whether a peer's package (pycpd: ``pip install pycpd``; probreg) and the shape's
    (trimesh, pymeshlab) are installed."""
    need = {"cpd": ["pycpd"], "cpdr": ["pycpd"], "bcpd": ["probreg"]}.get(method, [])
    need += {"torus": ["trimesh"]}.get(shape, ["trimesh", "pymeshlab"] if shape in PACKAGED
                                              else [])
    return all(importlib.util.find_spec(name) is not None for name in need)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--child", nargs="+", help=argparse.SUPPRESS)
    p.add_argument("--shapes", default="bunny,blob",
                   help="of bunny, blob, torus, twisted, " + ", ".join(PACKAGED))
    p.add_argument("--sizes", default="500,2000,10000,50000,100000")
    p.add_argument("--angles", default="0,30,90,180")
    p.add_argument("--variants", default="base", help=f"of {', '.join(VARIANTS)}")
    p.add_argument("--methods", default="modalmorph,cpd,cpdr,bcpd", help="of " + ", ".join(PEERS))
    p.add_argument("--noise", type=float, default=0.01, help="fraction of the size")
    p.add_argument("--cpd-up-to", type=int, default=2000, help="the peers (CPD, BCPD) "
                   "run up to this many points")
    p.add_argument("--timeout", type=float, default=600.0)
    args = p.parse_args(argv)
    if args.child:
        method, shape, m, angle, noise, *variant = args.child
        print(json.dumps(one(method, shape, int(m), float(angle), float(noise), *variant)))
        return 0
    print(f"# noise {args.noise} x size; base: {KEEP:.0%} of the target kept, warp "
          f"{WARP[0]:.0%}-{WARP[1]:.0%}; variants: {VARIANTS}; error in target spacings; "
          f"peak RSS in MB")
    print(f"{'shape':>7} {'variant':>7} {'points':>7} {'angle':>5} {'method':>10} {'best':>5} "
          f"{'sim':>5} {'med':>6} {'/best':>5} {'sym':>5} "
          f"{'p90':>6} {'paired':>6} {'<=1':>5} {'<=3':>5} {'time s':>7} {'cpu s':>6} {'peak':>6} "
          f"{'load':>5}",
          flush=True)
    for shape in args.shapes.split(","):
        for variant in args.variants.split(","):
            for m in map(int, args.sizes.split(",")):
                for angle in map(float, args.angles.split(",")):
                    for method in args.methods.split(","):
                        head = f"{shape:>7} {variant:>7} {m:>7} {angle:>5.0f} {method:>10}"
                        if method != "modalmorph" and m > args.cpd_up_to:
                            continue
                        r = (child(args, method, shape, m, angle, variant)
                             if available(method, shape) else "not installed")
                        print(f"{head} {r:>6}" if isinstance(r, str) else
                              f"{head} {r['best']:>5.2f} {r['sim']:>5.2f} {r['med']:>6.2f} "
                              f"{r['med'] / r['best']:>5.2f} {r['sym']:>5.2f} "
                              f"{r['p90']:>6.2f} "
                              f"{r['paired']:>6.2f} "
                              f"{r['w1']:>5.2f} {r['w3']:>5.2f} {r['s']:>7.2f} "
                              f"{r['cpu']:>6.2f} "
                              f"{r['peak']:>6.0f} {r['load']:>5.1f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
