"""The multilevel solver on hard 3D point sets: iterations, largest residual, time, memory.

Cases (fixed seeds):

- ``ellipsoid-100k``: 100 000 points uniform in area on the ellipsoid with semi-axes
  (3, 2, 1) (:func:`ellipsoid_surface`: uniform directions mapped onto the ellipsoid,
  kept by rejection with probability proportional to the area element). Its modes come
  in near-degenerate clusters.
- ``ellipsoid-20k``: the same on 20 000 points.
- ``sphere-100k``: 100 000 points uniform on the unit sphere (normalised Gaussian
  vectors): rotational symmetry, so every frequency above the rigid modes is a cluster of
  2l + 1 nearly equal ones, broken only by the random sampling.
- ``blob-100k``: the 3D object of ``benchmarks/scale.py`` (``blob``).
- ``scan-20k``: a scanned-like surface, 20 000 points (:func:`scan_surface`): a lumpy
  closed surface, sampled more densely on the side facing the scanner, with a hole
  where it is occluded and 0.3% noise normal to the surface.

Each case runs ``FEModel(points).modes(n)`` (``solver="auto"``: multilevel for all of
them; with ``--threads``, the multilevel solver with that many threads) in its own
subprocess; the child's wall and CPU seconds (``time.process_time``: on a shared machine
the CPU seconds of one thread are what the wall seconds would be on a quiet one), its
peak RSS (``resource.getrusage``) and the 1-minute load average at its end are reported.
Run ``OPENBLAS_NUM_THREADS=1 python benchmarks/multilevel.py`` (``--cases`` for some;
``--threads 1`` for everything on one thread).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from scale import blob  # noqa: E402

from modalmorph import FEModel  # noqa: E402
from modalmorph.core.solvers import multilevel  # noqa: E402


def ellipsoid_surface(m: int, radii=(3.0, 2.0, 1.0), seed: int = 0) -> np.ndarray:
    """``m`` points uniform in area on an ellipsoid, shape (m, 3): directions ``u``
    uniform on the sphere, ``x = radii * u`` kept with probability
    ``dA_ellipsoid / dA_sphere / max = c_min * |u / radii|``."""
    rng = np.random.default_rng(seed)
    radii = np.asarray(radii, dtype=float)
    out = []
    while sum(map(len, out)) < m:
        u = rng.standard_normal((2 * m, 3))
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        keep = rng.random(2 * m) < radii.min() * np.linalg.norm(u / radii, axis=1)
        out.append(u[keep] * radii)
    return np.concatenate(out)[:m]


def sphere_surface(m: int, seed: int = 0) -> np.ndarray:
    """``m`` points uniform on the unit sphere (normalised Gaussian vectors), (m, 3)."""
    u = np.random.default_rng(seed).standard_normal((m, 3))
    return u / np.linalg.norm(u, axis=1, keepdims=True)


def scan_surface(m: int, seed: int = 0) -> np.ndarray:
    """A scanned-like closed surface, (m, 3): radius ``1 + 0.15 (lumps)`` over the
    sphere, directions drawn with density ``1 + 0.8 u_x`` (denser on the side facing a
    scanner on +x), none within 25 degrees of -z (an occluded hole), noise of 0.3% of
    the radius along it."""
    rng = np.random.default_rng(seed)
    out = []
    while sum(map(len, out)) < m:
        u = rng.standard_normal((2 * m, 3))
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        keep = (rng.random(2 * m) < (1 + 0.8 * u[:, 0]) / 1.8) & (u[:, 2] > -np.cos(0.44))
        out.append(u[keep])
    u = np.concatenate(out)[:m]
    x, y, z = u.T
    r = 1 + 0.15 * (np.sin(3 * x) * np.cos(2 * y) + 0.5 * np.sin(4 * z + x))
    return u * (r * (1 + 0.003 * rng.standard_normal(m)))[:, None]


CASES = {
    "ellipsoid-100k": lambda: ellipsoid_surface(100_000),
    "ellipsoid-20k": lambda: ellipsoid_surface(20_000),
    "sphere-100k": lambda: sphere_surface(100_000),
    "blob-100k": lambda: blob(100_000),
    "scan-20k": lambda: scan_surface(20_000),
}


class _SolverLog(logging.Handler):
    """The multilevel solver's iterations and largest residual, from its summary line."""

    def emit(self, record):
        if record.msg.startswith("multilevel:"):
            _, _, self.iterations, self.residual = record.args


def _child(case: str, n: int, threads: int | None) -> dict:
    points = CASES[case]()
    log = _SolverLog()
    logger = logging.getLogger("modalmorph.core.solvers.multilevel")
    logger.addHandler(log)
    logger.setLevel(logging.INFO)
    t0, c0 = time.perf_counter(), time.process_time()
    model = FEModel(points)
    row = {"nodes": model.m, "solver": model.solver}
    try:
        modes = (model.modes(n) if threads is None or model.solver != "multilevel" else
                 multilevel.solve(model, n, threads=threads))
        row.update(iterations=log.iterations, residual=log.residual,
                   f1=float(modes.frequencies[0]), fn=float(modes.frequencies[-1]))
    except ValueError as e:
        row["error"] = str(e)[:200]
    row["seconds"] = time.perf_counter() - t0
    row["cpu"] = time.process_time() - c0
    row["load"] = os.getloadavg()[0]
    row["peak_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return row


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cases", default=",".join(CASES))
    parser.add_argument("--modes", type=int, default=50)
    parser.add_argument("--threads", type=int, help="the multilevel solver's threads "
                        "(default: its own, THREADS)")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        print(json.dumps(_child(args.child, args.modes, args.threads)))
        return 0
    threads = multilevel.THREADS if args.threads is None else args.threads
    print(f"# lowest {args.modes} modes, FEModel(points) defaults, {threads} solver "
          f"thread(s); peak = child's max RSS, load = 1-minute load average at its end")
    print(f"{'case':>15} {'nodes':>6} {'solver':>10} {'its':>3} {'resid':>7} {'s':>6} "
          f"{'cpu s':>6} {'peak MB':>7} {'load':>4}  result")
    extra = [] if args.threads is None else ["--threads", str(args.threads)]
    for case in args.cases.split(","):
        done = subprocess.run([sys.executable, __file__, "--child", case, "--modes",
                               str(args.modes), *extra], capture_output=True, text=True)
        if done.returncode:
            print(f"{case:>15} failed: {done.stderr.strip().splitlines()[-1][:120]}")
            continue
        r = json.loads(done.stdout.strip().splitlines()[-1])
        its = f"{r['iterations']:3d}" if "iterations" in r else "  -"
        res = f"{r['residual']:7.1e}" if "residual" in r else "      -"
        print(f"{case:>15} {r['nodes']:6d} {r['solver']:>10} {its} {res} "
              f"{r['seconds']:6.1f} {r['cpu']:6.1f} {r['peak_mb']:7.0f} {r['load']:4.1f}  "
              f"{r.get('error', 'converged')}",
              flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
