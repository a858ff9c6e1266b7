"""The 3D route of 10 000-100 000 points stage by stage (issue 25, session 16 "big11").

Two measures of one case of ``match3d.py`` (same generator, noise 0.01):

- ``times`` (default): ``mm.match`` with timers wrapped round the route's functions (CPU
  seconds, ``time.process_time``, and calls per function; ``refine`` by node count and
  levels, transports and graphs by their larger side), then the median / p90 pair error.
- ``--levels``: ``matching._refined``'s stages run one level at a time, each printed as
  the median distance from the landings to the truth and the median / p90 error of the
  pairs (nearest target point), in target spacings: where the route gains or loses;
  ``--repose N``: the second level N times more, each from its landings' best similarity
  (measured in docs/issue25/scale.md, session 16; not in the route).
- ``--floor``: the median pair error (nearest target point) of landings moved r target
  spacings from the truth along the surface, r = 0 (the benchmark's ``best``) to 2.

    OMP_NUM_THREADS=1 MODALMORPH_BLAS_THREADS=1 OPENBLAS_NUM_THREADS=1 PYTHONPATH=src \\
        python benchmarks/route_stages.py blob 100000 30 base [--levels]
"""

from __future__ import annotations

import argparse
import collections
import sys
import time
from functools import partial
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

sys.path.insert(0, str(Path(__file__).parent))
from match3d import VARIANTS, errors, make_case  # noqa: E402

import modalmorph as mm  # noqa: E402
import modalmorph.matching as M  # noqa: E402
from modalmorph.core.align import align  # noqa: E402
from modalmorph.core.shape import Shape, even_subset  # noqa: E402
from modalmorph.matching import clouds as C  # noqa: E402
from modalmorph.options import MatchOptions  # noqa: E402


def times(src, tgt, truth) -> None:
    spent, calls = collections.defaultdict(float), collections.Counter()

    def wrap(module, name, key=None):
        f = getattr(module, name)

        def timed(*a, **k):
            t = time.process_time()
            try:
                return f(*a, **k)
            finally:
                kk = key(*a, **k) if key else name
                spent[kk] += time.process_time() - t
                calls[kk] += 1
        setattr(module, name, timed)

    def side(name):
        def key(*a, **k):
            s = max(len(a[0]), len(a[2]))
            return f"{name} {'<=10k' if s <= 10_000 else '<=60k' if s <= 60_000 else '>60k'}"
        return key

    wrap(C, "_transport", side("transport"))
    wrap(C, "_graph", lambda z, y: side("graph")(z, None, y))
    for name in ("_smoother", "_area", "_nearest", "_average", "_affine", "_means"):
        wrap(C, name)
    for name in ("_coarse_landing", "stretch", "rigid_pose", "surface_gap", "_carried"):
        wrap(M, name)
    wrap(M, "refine", lambda *a, **k: f"refine(m={len(a[0])}, levels={k.get('levels')})")
    t0 = time.process_time()
    pairs = mm.match(src, tgt).pairs
    cpu = time.process_time() - t0
    err = errors(src, tgt, truth, pairs)[0]
    err = err[np.isfinite(err)]
    print(f"median {np.median(err):.3f} p90 {np.percentile(err, 90):.3f} CPU s {cpu:.2f}")
    for k in sorted(spent, key=lambda k: -spent[k]):
        print(f"  {k:40s} {calls[k]:5d} {spent[k]:7.2f}")


def levels(src, tgt, truth, args_repose: int = 0) -> None:
    s, t = Shape(src, ordered=False), Shape(tgt, ordered=False)
    x, y, true = s.normalized, t.normalized, t.to_normalized(truth)
    tree = cKDTree(y)
    h = tree.query(y, k=2)[0][:, 1].mean()

    def score(name, z):
        e = np.linalg.norm(y[tree.query(z)[1]] - true, axis=1) / h
        land = np.median(np.linalg.norm(z - true, axis=1)) / h
        print(f"  {name:32s} landing {land:5.2f}  pairs {np.median(e):5.2f} "
              f"p90 {np.percentile(e, 90):5.2f}", flush=True)

    landed, start = M._coarse_landing(s, t, M.DEFAULT_MODES, MatchOptions())
    z, trim = t.to_normalized(landed), M._GAP_TRIM * t.spacing
    stretched = C.stretch(z, y)
    if M.surface_gap(stretched, y, trim, tree=tree) < M._STRETCH_GAIN * M.surface_gap(
            z, y, trim, tree=tree):
        z = stretched
    start //= M.REFINE_COARSER
    score("coarse landing", z)
    i = even_subset(x, M.CHOICE_NODES)
    yj = y[even_subset(y, max(M.CHOICE_NODES * len(y) // len(x), 1))]
    posed = align(x, z).apply(x)
    starts = (z, M.rigid_pose(posed, y).apply(posed))
    known = C.measures(x[i], yj, True)
    once = partial(C.refine, decay=M.POSE_DECAY)
    firsts = [once(x[i], p[i], yj, start, levels=1, known=known) for p in starts]
    gaps = [M.surface_gap(f, yj, M._GAP_TRIM * known.spacing, tree=cKDTree(yj)) for f in firsts]
    best = int(gaps[1] < gaps[0])
    z = starts[best] + M._carried(x[i], firsts[best] - starts[best][i], x, 1.0)
    score(f"first level ({('coarse', 'rigid')[best]} start)", z)
    known = C.measures(x, y, True)
    z = once(x, z, y, C.finer(start, 1), levels=1, known=known)
    score("second level", z)
    for k in range(args_repose):  # the second level again from its landings' similarity
        z = once(x, align(x, z).apply(x), y, C.finer(start, 1), levels=1, known=known)
        score(f"second level from its similarity {k + 1}", z)
    for k in range(C.cube_levels(len(y), C.finer(start, 2))):
        z = once(x, z, y, C.finer(start, 2 + k), levels=1, known=known, decay=0.0,
                 smoothing=M.HUGE_SMOOTHING)
        score(f"level {3 + k}", z)
    score("the nodes + average (the route)", once(
        x, z, y, C.finer(start, 2 + k + 1), known=known, decay=0.0, smoothing=M.HUGE_SMOOTHING))


def floor(src, tgt, truth) -> None:
    """The median pair error (nearest target point) of landings r target spacings from the
    truth along the surface (a random tangential direction: the target's local plane)."""
    tree = cKDTree(tgt)
    h = tree.query(tgt, k=2)[0][:, 1].mean()
    near = tgt[tree.query(truth, k=16)[1]]
    near = near - near.mean(axis=1, keepdims=True)
    normal = np.linalg.eigh(np.einsum("nki,nkj->nij", near, near))[1][:, :, 0]
    d = np.random.default_rng(1).normal(size=truth.shape)
    d -= np.sum(d * normal, axis=1)[:, None] * normal
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    for r in (0.0, 0.25, 0.5, 0.75, 1.0, 1.5, 2.0):
        e = np.linalg.norm(tgt[tree.query(truth + r * h * d)[1]] - truth, axis=1) / h
        print(f"  landing {r:4.2f} spacings off: pairs {np.median(e):5.2f}")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("shape")
    p.add_argument("points", type=int)
    p.add_argument("angle", type=float)
    p.add_argument("variant", choices=list(VARIANTS))
    p.add_argument("--levels", action="store_true", help="landings level by level")
    p.add_argument("--floor", action="store_true", help="pair error against landing error")
    p.add_argument("--repose", type=int, default=0, help="with --levels: the second level "
                   "this many times more, each from its landings' best similarity")
    args = p.parse_args(argv)
    if args.points <= M.CHOICE_NODES and not args.floor:
        p.error(f"the route measured here runs above {M.CHOICE_NODES} points")
    src, tgt, truth = make_case(args.shape, args.points, args.angle, 0.01,
                                **VARIANTS[args.variant])
    if args.floor:
        floor(src, tgt, truth)
    elif args.levels:
        levels(src, tgt, truth, args.repose)
    else:
        times(src, tgt, truth)
    return 0


if __name__ == "__main__":
    sys.exit(main())
