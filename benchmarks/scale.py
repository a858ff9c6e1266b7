"""Large objects: time and peak memory per stage, sparse against dense (issue 6).

Cases: the bundled hand outline resampled to 1k, 4k, 16k and 64k nodes (2D contours), and
deformed ellipsoids (Fibonacci lattice) of 10k and 100k nodes (3D point sets).

Each case runs in its own subprocess, so that its peak memory can be read honestly: the
child's peak resident set size (``resource.getrusage(...).ru_maxrss``, which includes the
interpreter and numpy, about 60 MB) is reported, not a tracemalloc count (that misses
memory allocated by SuperLU and ARPACK). A child gets a wall-clock timeout and an address
space limit (``--mem-limit``) so that a case too large for the machine fails instead of
swapping; such a case is reported as ``timeout`` or ``out of memory``.

Stages (one function each; matching and morphing columns are to be added the same way):

- ``model``: build the sparse model (cKDTree pairs within the cutoff, sparse ``G``,
  ``Gamma``, ``K_g``) and its lowest ``n`` modes (``solver="sparse"``);
- ``dense``: the same with ``solver="dense"``, where it fits (up to 4k nodes in 2D);
- ``agreement``: for cases with both, the largest relative difference of the lowest ``n``
  frequencies, and the smallest cosine of the principal angles between the two mode
  subspaces in the exact model's mass inner product (``svd(Phi_d^T M Phi_s)``; all
  cosines are 1 when the subspaces agree; the gap after mode n is printed since a small
  gap makes the n-th subspace itself ill-defined).

Run ``python benchmarks/scale.py`` (all cases; the 100k-node 3D case is expected to fail
its limits, see the report) or ``--cases 2d-1k,2d-4k`` for some of them.
"""

from __future__ import annotations

import argparse
import json
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from model import ellipsoid, hand  # noqa: E402

from modalmorph import FEModel  # noqa: E402

CASES = {
    "2d-1k": ("hand", 1000),
    "2d-4k": ("hand", 4000),
    "2d-16k": ("hand", 16000),
    "2d-64k": ("hand", 64000),
    "3d-10k": ("ellipsoid", 10000),
    "3d-100k": ("ellipsoid", 100000),
}
DENSE_UP_TO = 4000  # nodes, 2D: the dense solver's (2m)^2 matrices are 1 GB at 4000 nodes


def points_for(case: str) -> np.ndarray:
    kind, m = CASES[case]
    return hand(m) if kind == "hand" else ellipsoid(m)


# -- stages, each run inside a child process ----------------------------------------


def stage_model(points: np.ndarray, n: int, out: Path) -> dict:
    """Sparse model and its lowest n modes."""
    t0 = time.perf_counter()
    model = FEModel(points, solver="sparse")
    _ = model.gram_sparse, model.stiffness_gaussian_sparse
    t1 = time.perf_counter()
    modes = model.modes(n)
    t2 = time.perf_counter()
    np.savez(out, frequencies=modes.frequencies, shapes=modes.shapes)
    return {"build_s": t1 - t0, "modes_s": t2 - t1,
            "pairs_per_node": 2 * len(model.pairs) / model.m,
            "nnz_Kg": int(model.stiffness_gaussian_sparse.nnz)}


def stage_dense(points: np.ndarray, n: int, out: Path) -> dict:
    """Dense model and its lowest n modes."""
    t0 = time.perf_counter()
    model = FEModel(points, solver="dense")
    _ = model.gram, model.stiffness_gaussian
    t1 = time.perf_counter()
    modes = model.modes(n + 1)
    t2 = time.perf_counter()
    np.savez(out, frequencies=modes.frequencies, shapes=modes.shapes)
    return {"build_s": t1 - t0, "modes_s": t2 - t1}


STAGES = {"model": stage_model, "dense": stage_dense}


def agreement(points: np.ndarray, dense: Path, sparse_: Path, n: int) -> dict:
    """Frequencies and subspaces of the two solvers (run in the parent, after both)."""
    d, s = np.load(dense), np.load(sparse_)
    fd, fs = d["frequencies"], s["frequencies"]
    exact = FEModel(points, solver="dense")
    C = d["shapes"][:, :n].T @ exact.apply_mass(s["shapes"])
    return {"freq_rel_diff": float(np.max(np.abs(fs / fd[:n] - 1))),
            "min_cosine": float(np.linalg.svd(C, compute_uv=False).min()),
            "gap_after_n": float(fd[n] / fd[n - 1] - 1)}


# -- driver ----------------------------------------------------------------------------


def _child(args) -> int:
    if args.mem_limit:
        limit = int(args.mem_limit * 2**30)
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    points = points_for(args.case)
    try:
        row = STAGES[args.stage](points, args.modes, Path(args.out))
    except MemoryError:
        row = {"error": "out of memory"}
    row["peak_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(json.dumps(row))
    return 0


def run_stage(case: str, stage: str, n: int, out: Path, timeout: float,
              mem_limit: float) -> dict:
    cmd = [sys.executable, __file__, "--child", "--case", case, "--stage", stage,
           "--modes", str(n), "--out", str(out), "--mem-limit", str(mem_limit)]
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"error": f"timeout {timeout:.0f} s"}
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["?"])[-1]
        return {"error": "out of memory" if "MemoryError" in done.stderr else last[:60]}
    return json.loads(done.stdout.strip().splitlines()[-1])


def _fmt(row: dict, key: str, spec: str) -> str:
    width = int(re.match(r"\d+", spec).group())
    return format(row[key], spec) if key in row else "-".rjust(width)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cases", default=",".join(CASES),
                        help=f"comma-separated, from {', '.join(CASES)}")
    parser.add_argument("--modes", type=int, default=50, help="lowest modes to compute")
    parser.add_argument("--timeout", type=float, default=300.0, help="seconds per stage")
    parser.add_argument("--mem-limit", type=float, default=8.0,
                        help="address-space limit per stage, GiB")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--case", help=argparse.SUPPRESS)
    parser.add_argument("--stage", help=argparse.SUPPRESS)
    parser.add_argument("--out", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        return _child(args)

    cases = args.cases.split(",")
    unknown = set(cases) - set(CASES)
    if unknown:
        parser.error(f"unknown case(s) {sorted(unknown)}; choose from {list(CASES)}")
    n = args.modes
    header = (f"{'case':>8} {'nodes':>7} {'nbrs':>5} {'nnz K_g':>10} {'build s':>8} "
              f"{'modes s':>8} {'peak MB':>8} | {'dense s':>8} {'peak MB':>8} | "
              f"{'freq diff':>9} {'1-min cos':>9} {'gap n':>7}")
    print(header)
    with tempfile.TemporaryDirectory() as tmp:
        for case in cases:
            kind, m = CASES[case]
            sp_out, de_out = Path(tmp, f"{case}-s.npz"), Path(tmp, f"{case}-d.npz")
            sp = run_stage(case, "model", n, sp_out, args.timeout, args.mem_limit)
            de = {}
            if kind == "hand" and m <= DENSE_UP_TO:
                de = run_stage(case, "dense", n, de_out, args.timeout, args.mem_limit)
            ag = {}
            if "error" not in sp and de and "error" not in de:
                ag = agreement(points_for(case), de_out, sp_out, n)
                ag["angle"] = 1 - ag["min_cosine"]
            sp_t = f"{sp['build_s']:8.2f} {sp['modes_s']:8.2f}" if "error" not in sp else \
                f"{sp['error']:>17}"
            de_t = (f"{de['build_s'] + de['modes_s']:8.2f}" if de and "error" not in de else
                    f"{de.get('error', '-'):>8}")
            print(f"{case:>8} {m:7d} {_fmt(sp, 'pairs_per_node', '5.0f')} "
                  f"{_fmt(sp, 'nnz_Kg', '10d')} {sp_t} {_fmt(sp, 'peak_mb', '8.0f')} | "
                  f"{de_t} {_fmt(de, 'peak_mb', '8.0f')} | "
                  f"{_fmt(ag, 'freq_rel_diff', '9.1e')} "
                  f"{_fmt(ag, 'angle', '9.1e')} "
                  f"{_fmt(ag, 'gap_after_n', '7.1e')}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
