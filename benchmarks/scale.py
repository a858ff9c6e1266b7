"""Large objects: time and peak memory per stage, sparse against dense (issue 6).

Cases: pairs of objects at 1k, 4k, 16k and 64k nodes (2D contours) and 10k and 100k nodes
(3D point sets), each a source and a different target:

- 2D: the bundled hands 0 and 3, both resampled at the same ``m`` contour parameters
  (linear interpolation between rows: ``modalmorph.datasets.load_hands``). The
  hands are in row correspondence, so node ``i`` of the source belongs with node ``i`` of
  the target: the ground truth (anatomical, fuzzy by some ten rows; see
  ``benchmarks/matching.py``).
- 3D: a deformed ellipsoid (Fibonacci lattice, a bump on top and one off the axes, so no
  symmetry is left) and a smoothly bent, twisted and rotated copy whose rows are shuffled;
  the shuffle is the ground truth. Both are unordered point clouds.

Each stage runs in its own subprocess, so that its peak memory can be read honestly: the
child's peak resident set size (``resource.getrusage(...).ru_maxrss``, which includes the
interpreter and numpy, about 60 MB) is reported, not a tracemalloc count (that misses
memory allocated by SuperLU and ARPACK). A child gets a wall-clock timeout and an address
space limit (``--mem-limit``) so that a case too large for the machine fails instead of
swapping; such a stage is reported as ``timeout`` or ``out of memory``.

Stages (one function each):

- ``model``: the lowest ``n`` modes of the source's full model. 2D: the sparse solver
  (cKDTree pairs within the cutoff, sparse ``G``, ``Gamma``, ``K_g``, shift-invert
  Lanczos; ``solver="sparse"``). 3D: the multilevel solver (``solver="multilevel"``, the
  automatic choice from 2500 3D nodes: cutoff 1e-6, ~190 neighbours per node, a
  1000-node coarse model's modes as the start of a preconditioned LOBPCG on the full
  model), since the sparse factor does not fit (each node has ~300 neighbours within
  the default cutoff; 10k nodes ran out of 8 GB); its iterations and largest residual
  are printed under the row. ``build s`` is the assembly of the sparse matrices (for
  the multilevel solver only the pair search: it assembles its own matrices, inside
  ``modes s``).
- ``dense``: the full model with ``solver="dense"``, where it fits (up to 4k nodes in 2D).
- ``agreement``: for cases with both, the largest relative difference of the lowest ``n``
  frequencies, and the smallest cosine of the principal angles between the two mode
  subspaces in the exact model's mass inner product (``svd(Phi_d^T M Phi_s)``; all
  cosines are 1 when the subspaces agree; the gap after mode n is printed since a small
  gap makes the n-th subspace itself ill-defined).
- ``match``: ``modalmorph.match(source, target)`` (method ``"auto"``); the pairs found,
  and their error against the ground truth: median and 90th percentile, 2D in rows of the
  1590-row hands (cyclic), 3D in target node spacings.
- ``morph``: ``modalmorph.morph(source, target, matching=pairs)`` with the pairs of the
  ``match`` stage, or the ground-truth pairs (marked ``*``) when that stage failed;
  steps and whether it converged.
- ``reference`` (2D cases up to ``--reference-up-to`` nodes): the dense transcription of
  matching and morphing in ``benchmarks/morph.py`` (``reference_match``, ``reference`` for
  as many steps as ``morph`` took), timed in the same run; speed-up = reference time /
  (match + morph time).

A second table, ``--reduced-check`` (default on), compares at 2000 3D nodes, where the
exact sparse solver (cutoff 1e-10) still fits, the multilevel solver and the *reduced*
route (``reduced_modes``: ``coarsen`` to 500 or 1000 nodes, that model's modes evaluated
at all nodes with ``modes_at``) against it: lowest ``n`` frequencies (largest and median
relative difference) and mode subspaces (principal angles in the exact model's mass inner
product). The multilevel modes are the full model's, to the residual tolerance; the
reduced model is a coarser discretisation with sigma scaled to its node spacing, whose
frequencies differ by tens of percent.

Run ``python benchmarks/scale.py`` (all cases, about 10 minutes on 2 loaded cores) or
``--cases 2d-1k,2d-4k`` for some of them; ``--timeout`` is per stage.
"""

from __future__ import annotations

import argparse
import json
import logging
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

sys.path.insert(0, str(Path(__file__).parent))
from model import ellipsoid  # noqa: E402
from morph import reference, reference_match  # noqa: E402

import modalmorph as mm  # noqa: E402
from modalmorph import FEModel, Shape  # noqa: E402
from modalmorph.core.shape import coarsen  # noqa: E402
from modalmorph.core.solvers.multilevel import COARSE_NODES  # noqa: E402
from modalmorph.datasets import load_hand, load_hands  # noqa: E402

CASES = {
    "2d-1k": ("hand", 1000),
    "2d-4k": ("hand", 4000),
    "2d-16k": ("hand", 16000),
    "2d-64k": ("hand", 64000),
    "3d-10k": ("ellipsoid", 10000),
    "3d-100k": ("ellipsoid", 100000),
}
DENSE_UP_TO = 4000  # nodes, 2D: the dense solver's (2m)^2 matrices are 1 GB at 4000 nodes
REDUCED_NODES = 2000  # 3D reduced model: 16 s for 50 modes (sparse; dense 36 s), 1.6 GB
CHECK_NODES = 2000  # 3D size where the full sparse model still runs (3000: out of 8 GiB)


# -- the objects ------------------------------------------------------------------------


def hands(m: int) -> tuple[np.ndarray, np.ndarray]:
    """Hands 0 and 3 at the same ``m`` contour parameters; row i belongs with row i."""
    return tuple(load_hands((0, 3), m))


def blob(m: int) -> np.ndarray:
    """``model.ellipsoid`` plus a second bump off every axis: no symmetry left, (m, 3)."""
    p = ellipsoid(m)
    c = np.array([0.55, 0.45, -0.2])
    return p + 0.25 * np.exp(-np.sum((p - c) ** 2, axis=1) / 0.1)[:, None] * c


def deform(p: np.ndarray) -> np.ndarray:
    """A smooth bend, twist and rotation of a 3D object."""
    x, y, z = p.T
    q = p + 0.08 * np.c_[np.sin(2 * y), z**2 - 0.5 * x, x * y]  # bend
    t = 0.4 * q[:, 0]  # twist about x, growing along x
    q = np.c_[q[:, 0], q[:, 1] * np.cos(t) - q[:, 2] * np.sin(t),
              q[:, 1] * np.sin(t) + q[:, 2] * np.cos(t)]
    a = 0.3  # and a rotation about z
    rot = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    return q @ rot.T + [0.1, -0.05, 0.02]


def objects(case: str):
    """Source, target and ``truth`` (truth[i]: the target row of source node i)."""
    kind, m = CASES[case]
    if kind == "hand":
        a, b = hands(m)
        return a, b, np.arange(m)
    a = blob(m)
    perm = np.random.default_rng(1).permutation(m)
    b = deform(a)[perm]
    truth = np.empty(m, dtype=np.intp)
    truth[perm] = np.arange(m)
    return Shape(a), Shape(b), truth


def pair_error(case: str, b, pairs: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Error of pairs against the ground truth: 2D in rows of the 1590-row hands
    (cyclic), 3D in mean node spacings of the target."""
    kind, m = CASES[case]
    i, j = pairs[:, 0], pairs[:, 1]
    if kind == "hand":
        d = np.abs(j - truth[i]) % m
        return np.minimum(d, m - d) * len(load_hand(0)) / m
    pts = b.points
    spacing = cKDTree(pts).query(pts, k=2)[0][:, 1].mean()
    return np.linalg.norm(pts[j] - pts[truth[i]], axis=1) / spacing


# -- stages, each run inside a child process ----------------------------------------


def reduced_modes(shape: Shape, n: int, nodes: int):
    """The reduced route: a model on ``coarsen(shape, nodes)``, its lowest ``n`` modes, and
    those modes at every node of ``shape``, shape (d*m, n), with the coarse model's
    modes and the times of the three steps."""
    t0 = time.perf_counter()
    coarse = coarsen(shape, nodes)
    model = FEModel(coarse, solver="sparse")
    _ = model.gram_sparse, model.stiffness_gaussian_sparse
    t1 = time.perf_counter()
    modes = model.modes(n)
    t2 = time.perf_counter()
    phi = model.modes_at(modes, coarse.to_normalized(shape.points))
    t3 = time.perf_counter()
    return phi, modes, (t1 - t0, t2 - t1, t3 - t2)


def stage_model(case: str, args, out: Path) -> dict:
    """Lowest n modes of the full model: sparse (2D) or multilevel (3D, the automatic
    choice there), with the multilevel solver's iterations and largest residual."""
    a, _, _ = objects(case)
    n = args.modes
    t0 = time.perf_counter()
    model = FEModel(a, solver="multilevel" if CASES[case][0] == "ellipsoid" else "sparse")
    if model.solver == "multilevel":  # it assembles its own matrices from the pairs
        _ = model.pairs
    else:
        _ = model.gram_sparse, model.stiffness_gaussian_sparse
    t1 = time.perf_counter()
    with _SolverLog() as log:
        modes = model.modes(n)
    t2 = time.perf_counter()
    if model.solver != "multilevel":  # the 100k 3D shapes are not saved
        np.savez(out, frequencies=modes.frequencies, shapes=modes.shapes)
    return {"build_s": t1 - t0, "modes_s": t2 - t1, "model_nodes": model.m,
            "solver": model.solver, "pairs_per_node": 2 * len(model.pairs) / model.m,
            **log.result}


class _SolverLog(logging.Handler):
    """Collects the multilevel solver's iterations and largest residual from its log."""

    def __enter__(self):
        self.result = {}
        self._logger = logging.getLogger("modalmorph.core.solvers.multilevel")
        self._logger.addHandler(self)
        self._logger.setLevel(logging.INFO)
        return self

    def __exit__(self, *exc):
        self._logger.removeHandler(self)

    def emit(self, record):
        if record.msg.startswith("multilevel:"):  # the solver's summary line
            _, _, its, res = record.args
            self.result.update(iterations=its, residual=res)


def stage_dense(case: str, args, out: Path) -> dict:
    """Dense model and its lowest n modes."""
    a, _, _ = objects(case)
    t0 = time.perf_counter()
    model = FEModel(a, solver="dense")
    _ = model.gram, model.stiffness_gaussian
    t1 = time.perf_counter()
    modes = model.modes(args.modes + 1)
    t2 = time.perf_counter()
    np.savez(out, frequencies=modes.frequencies, shapes=modes.shapes)
    return {"build_s": t1 - t0, "modes_s": t2 - t1}


def stage_match(case: str, args, out: Path) -> dict:
    """modalmorph.match, and the pairs' error against the ground truth."""
    a, b, truth = objects(case)
    t0 = time.perf_counter()
    matching = mm.match(a, b)
    t = time.perf_counter() - t0
    np.save(out, matching.pairs)
    err = pair_error(case, b, matching.pairs, truth)
    return {"match_s": t, "pairs": len(matching), "err50": float(np.median(err)),
            "err90": float(np.percentile(err, 90))}


def stage_morph(case: str, args, out: Path) -> dict:
    """modalmorph.morph with the matched pairs (or the ground truth when none)."""
    a, b, truth = objects(case)
    found = out.with_name(out.name.replace("-morph", "-match") + ".npy")
    if found.exists():
        pairs, given = np.load(found), False
    else:
        pairs, given = np.c_[np.arange(len(truth)), truth], True
    t0 = time.perf_counter()
    r = mm.morph(a, b, matching=pairs)
    return {"morph_s": time.perf_counter() - t0, "steps": r.steps,
            "converged": bool(r.converged), "truth_pairs": given,
            "stop": r.stop_reason.split(":")[0]}


def stage_reference(case: str, args, out: Path) -> dict:
    """The dense transcription (benchmarks/morph.py) for as many steps as morph took."""
    a, b, _ = objects(case)
    done = json.loads(Path(str(out).replace("-reference", "-morph") + ".json").read_text())
    t0 = time.perf_counter()
    pairs = reference_match(a, b)
    t1 = time.perf_counter()
    reference(a, b, pairs, done["steps"])
    return {"ref_match_s": t1 - t0, "ref_morph_s": time.perf_counter() - t1}


def stage_check(case: str, args, out: Path) -> dict:
    """3D, CHECK_NODES nodes: the multilevel solver (default cutoff 1e-6) and the reduced
    route against the exact sparse solver (cutoff 1e-10)."""
    n = args.modes
    shape = Shape(blob(CHECK_NODES))
    t0 = time.perf_counter()
    full = FEModel(shape, solver="sparse")
    fm = full.modes(n + 1)
    t_full = time.perf_counter() - t0
    ff = fm.frequencies[:n]
    gap = float(fm.frequencies[n] / fm.frequencies[n - 1] - 1)
    rows = []
    t0 = time.perf_counter()
    multi = FEModel(shape, solver="multilevel")
    with _SolverLog() as log:
        mm = multi.modes(n)
    t_multi = time.perf_counter() - t0
    # the same nodes: principal angles in the exact sparse model's Gaussian-basis mass
    Mpsi = full.material.rho * np.concatenate(
        [full.gram_sparse[1] @ p for p in fm.gaussian[:, :n].reshape(3, full.m, -1)])
    cos = np.linalg.svd(mm.gaussian.T @ Mpsi, compute_uv=False)
    cos10 = np.linalg.svd(mm.gaussian[:, :10].T @ Mpsi[:, :10], compute_uv=False)
    err = mm.frequencies / ff - 1
    rows.append({"route": f"multilevel {COARSE_NODES}", "full_s": t_full, "route_s": t_multi,
                 "freq_diff1": float(err[0]), "freq_diff": float(np.max(np.abs(err))),
                 "freq_med": float(np.median(np.abs(err))), "angle10": float(1 - cos10.min()),
                 "angle": float(1 - cos.min()), "gap": gap, **log.result})
    for nodes in (500, 1000):
        t0 = time.perf_counter()
        phi, rm, _ = reduced_modes(shape, n, nodes)
        t_red = time.perf_counter() - t0
        # principal angles in the full model's mass inner product: M-orthonormalise phi
        cos = np.linalg.svd(fm.shapes[:, :n].T @ full.apply_mass(_orth(phi, full)),
                            compute_uv=False)
        cos10 = np.linalg.svd(fm.shapes[:, :10].T @ full.apply_mass(_orth(phi[:, :10], full)),
                              compute_uv=False)
        err = rm.frequencies / ff - 1
        rows.append({"route": f"reduced {nodes}", "full_s": t_full, "route_s": t_red,
                     "freq_diff1": float(err[0]), "freq_diff": float(np.max(np.abs(err))),
                     "freq_med": float(np.median(np.abs(err))),
                     "angle10": float(1 - cos10.min()), "angle": float(1 - cos.min()),
                     "gap": gap})
    return {"rows": rows}


def _orth(phi: np.ndarray, full: FEModel) -> np.ndarray:
    """Columns of phi made orthonormal in full's mass inner product."""
    w, v = np.linalg.eigh(phi.T @ full.apply_mass(phi))
    return phi @ (v / np.sqrt(w))


STAGES = {"model": stage_model, "dense": stage_dense, "match": stage_match,
          "morph": stage_morph, "reference": stage_reference, "check": stage_check}


def agreement(case: str, dense: Path, sparse_: Path, n: int) -> dict:
    """Frequencies and subspaces of the two solvers (run in the parent, after both)."""
    d, s = np.load(dense), np.load(sparse_)
    fd, fs = d["frequencies"], s["frequencies"]
    exact = FEModel(objects(case)[0], solver="dense")
    C = d["shapes"][:, :n].T @ exact.apply_mass(s["shapes"])
    return {"freq_rel_diff": float(np.max(np.abs(fs / fd[:n] - 1))),
            "min_cosine": float(np.linalg.svd(C, compute_uv=False).min()),
            "gap_after_n": float(fd[n] / fd[n - 1] - 1)}


# -- driver ----------------------------------------------------------------------------


def _child(args) -> int:
    if args.mem_limit:
        limit = int(args.mem_limit * 2**30)
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    out = Path(args.out)
    try:
        row = STAGES[args.stage](args.case, args, out)
    except MemoryError:
        row = {"error": "out of memory"}
    row["peak_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    Path(str(out) + ".json").write_text(json.dumps(row))
    print(json.dumps(row))
    return 0


def run_stage(case: str, stage: str, args, tmp: str) -> dict:
    out = Path(tmp, f"{case}-{stage}")
    cmd = [sys.executable, __file__, "--child", "--case", case, "--stage", stage,
           "--modes", str(args.modes), "--out", str(out), "--mem-limit",
           str(args.mem_limit), "--reduced-nodes", str(args.reduced_nodes)]
    t0 = time.perf_counter()
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=args.timeout)
    except subprocess.TimeoutExpired:
        return {"error": f"timeout {args.timeout:.0f} s"}
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["?"])[-1]
        return {"error": "out of memory" if "MemoryError" in done.stderr else last[:60]}
    row = json.loads(done.stdout.strip().splitlines()[-1])
    row["wall_s"] = time.perf_counter() - t0
    return row


def _fmt(row: dict, key: str, spec: str) -> str:
    width = int(re.match(r"\d+", spec).group())
    return format(row[key], spec) if key in row else "-".rjust(width)


def _err(row: dict, width: int) -> str:
    return f"{row.get('error', '-')[:width]:>{width}}"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cases", default=",".join(CASES),
                        help=f"comma-separated, from {', '.join(CASES)}")
    parser.add_argument("--modes", type=int, default=50, help="lowest modes to compute")
    parser.add_argument("--timeout", type=float, default=120.0, help="seconds per stage")
    parser.add_argument("--mem-limit", type=float, default=8.0,
                        help="address-space limit per stage, GiB")
    parser.add_argument("--reduced-nodes", type=int, default=REDUCED_NODES,
                        help="3D: nodes of the reduced model")
    parser.add_argument("--reference-up-to", type=int, default=1000,
                        help="2D: run the dense transcription up to this many nodes")
    parser.add_argument("--no-reduced-check", action="store_true",
                        help="skip the reduced-against-full 3D comparison")
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
    print(f"# {n} modes; peak = child's max RSS, MB; timeout {args.timeout:.0f} s and "
          f"{args.mem_limit:g} GiB address space per stage")
    print(f"{'case':>7} {'nodes':>6} {'model':>5} {'build s':>7} {'modes s':>7} "
          f"{'eval s':>6} {'peak':>5} | {'dense s':>7} {'peak':>5} {'fdiff':>7} "
          f"{'1-cos':>7} | {'match s':>7} {'peak':>5} {'pairs':>6} {'err50':>5} "
          f"{'err90':>5} | {'morph s':>7} {'peak':>5} {'steps':>5} {'conv':>5} | "
          f"{'ref s':>6} {'speedup':>7}")
    with tempfile.TemporaryDirectory() as tmp:
        for case in cases:
            kind, m = CASES[case]
            md = run_stage(case, "model", args, tmp)
            de, ag = {}, {}
            if kind == "hand" and m <= DENSE_UP_TO:
                de = run_stage(case, "dense", args, tmp)
                if "error" not in md and "error" not in de:
                    ag = agreement(case, Path(tmp, f"{case}-dense.npz"),
                                   Path(tmp, f"{case}-model.npz"), n)
                    ag["angle"] = 1 - ag["min_cosine"]
            ma = run_stage(case, "match", args, tmp)
            mo = run_stage(case, "morph", args, tmp)
            ref = {}
            if kind == "hand" and m <= args.reference_up_to and "error" not in mo:
                ref = run_stage(case, "reference", args, tmp)
            md_t = (f"{md['build_s']:7.2f} {md['modes_s']:7.2f} "
                    f"{_fmt(md, 'eval_s', '6.2f')}" if "error" not in md else _err(md, 22))
            de_t = (f"{de['build_s'] + de['modes_s']:7.2f}" if de and "error" not in de
                    else _err(de, 7))
            ma_t = f"{ma['match_s']:7.2f}" if "error" not in ma else _err(ma, 7)
            mo_t = (f"{mo['morph_s']:7.2f}" if "error" not in mo else _err(mo, 7))
            steps = (f"{mo['steps']:4d}{'*' if mo['truth_pairs'] else ' '}"
                     if "steps" in mo else "    -")
            conv = f"{str(mo['converged']):>5}" if "converged" in mo else "    -"
            speed = "      -      -"
            if ref and "error" not in ref and "error" not in ma:
                t_ref = ref["ref_match_s"] + ref["ref_morph_s"]
                speed = f"{t_ref:6.1f} {t_ref / (ma['match_s'] + mo['morph_s']):6.1f}x"
            elif ref:
                speed = _err(ref, 14)
            print(f"{case:>7} {m:6d} {_fmt(md, 'model_nodes', '5d')} {md_t} "
                  f"{_fmt(md, 'peak_mb', '5.0f')} | {de_t} {_fmt(de, 'peak_mb', '5.0f')} "
                  f"{_fmt(ag, 'freq_rel_diff', '7.1e')} {_fmt(ag, 'angle', '7.1e')} | "
                  f"{ma_t} {_fmt(ma, 'peak_mb', '5.0f')} {_fmt(ma, 'pairs', '6d')} "
                  f"{_fmt(ma, 'err50', '5.1f')} {_fmt(ma, 'err90', '5.1f')} | "
                  f"{mo_t} {_fmt(mo, 'peak_mb', '5.0f')} {steps} {conv} | {speed}",
                  flush=True)
            if "residual" in md:
                print(f"#   {case}: multilevel solver, {md['iterations']} LOBPCG iterations, "
                      f"largest relative residual {md['residual']:.1e}, "
                      f"{md['pairs_per_node']:.0f} neighbours per node", flush=True)
        if not args.no_reduced_check and any(CASES[c][0] == "ellipsoid" for c in cases):
            ck = run_stage("3d-10k", "check", args, tmp)
            print(f"\n# 3D multilevel solver and reduced route against the exact sparse "
                  f"solver, {CHECK_NODES} nodes, lowest {n} modes "
                  f"(peak {_fmt(ck, 'peak_mb', '5.0f')} MB)")
            if "error" in ck:
                print(f"  {ck['error']}")
            else:
                print(f"{'route':>15} {'exact s':>7} {'route s':>7} {'f1 diff':>7} "
                      f"{'max fdiff':>9} {'med fdiff':>9} {'1-cos 10':>8} {'1-cos n':>8} "
                      f"{'gap n':>6} {'its':>3} {'resid':>7}")
                for r in ck["rows"]:
                    print(f"{r['route']:>15} {r['full_s']:7.1f} {r['route_s']:7.1f} "
                          f"{r['freq_diff1']:+7.1%} {r['freq_diff']:9.2e} "
                          f"{r['freq_med']:9.2e} {r['angle10']:8.1e} {r['angle']:8.1e} "
                          f"{r['gap']:6.1e} {_fmt(r, 'iterations', '3d')} "
                          f"{_fmt(r, 'residual', '7.1e')}")
    print("# err50/err90: pair error against the ground truth, median and 90th percentile "
          "(2D: rows of the 1590-row hands; 3D: target node spacings); steps*: morph ran "
          "on the ground-truth pairs because matching failed")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
