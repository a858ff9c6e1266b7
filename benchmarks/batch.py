"""Throughput of ``modalmorph batch`` on heart-sized pairs, against morph in a loop.

N items (default 200), each the bundled end-diastole -> end-systole heart pair (247 and 180
nodes), with --figures none. Two baselines in this process, one BLAS thread: the
computation alone (read, match, morph), and ``morph_files`` (what ``modalmorph morph
--no-figures --no-gif`` does per pair: also writes the folder) in a loop. Then the batch
with 1 and 2 workers on each engine, wall time including the start of the cluster or pool.
"CPU s/item" counts the CPU time of this process and of all its worker processes (and the
Dask scheduler), so it measures the batch's own cost even when other work shares the
cores; "in worker" is the mean wall time of one item inside its worker. Run from the
repository root:

    PYTHONPATH=src python benchmarks/batch.py [--pairs 200] [--engines dask processes]
        [--rerun 1000] [--startup]

Issue 26's goals are printed last: heart pairs per hour with 2 workers (goal >= 10 000 with
--figures none), and ``modalmorph batch`` run again on --rerun items that are all complete
(goal < 2 s for 1 000), the whole command in a fresh process as a user types it: the
1 000 folders are copies of one computed item (same inputs and options, so each is
fresh). ``--startup`` times a 2-item batch on each engine (start until done), the numbers
behind the engine "auto" chooses (``POOL_START_S``, ``CLUSTER_START_S`` in
``modalmorph/apps/batch/engines.py``).

The same batch on a running Dask cluster: ``modalmorph batch manifest.csv --out DIR
--scheduler tcp://host:8786`` (inputs and DIR on storage every worker reaches).
"""

import argparse
import os

os.environ.update({k: "1" for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS",
                                    "MKL_NUM_THREADS")})  # before numpy is imported

import resource  # noqa: E402
import shutil  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from modalmorph.apps.batch import Engine, Item, run  # noqa: E402
from modalmorph.apps.runs import Settings, morph_files  # noqa: E402
from modalmorph.core.shape import Shape  # noqa: E402
from modalmorph.datasets import load_heart  # noqa: E402
from modalmorph.matching import match  # noqa: E402
from modalmorph.options import OutputOptions  # noqa: E402
from modalmorph.pipeline import morph  # noqa: E402


def cpu_seconds():
    """CPU time of this process and of its finished child processes (the workers)."""
    return sum(r.ru_utime + r.ru_stime for r in (resource.getrusage(resource.RUSAGE_SELF),
                                                  resource.getrusage(resource.RUSAGE_CHILDREN)))


def timed(func, *args, **kwargs):
    wall, cpu = time.perf_counter(), cpu_seconds()
    result = func(*args, **kwargs)
    return result, time.perf_counter() - wall, cpu_seconds() - cpu


def compute_one(work):
    """Read, match and morph one pair: the computation of an item."""
    s, t = (Shape(np.loadtxt(work / name, delimiter=",", skiprows=1))
            for name in ("ed.csv", "es.csv"))
    morph(s, t, matching=match(s, t))


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--pairs", type=int, default=200)
    parser.add_argument("--engines", nargs="+", default=["dask", "processes"])
    parser.add_argument("--rerun", type=int, default=1000)
    parser.add_argument("--startup", action="store_true")
    args = parser.parse_args()
    n = args.pairs

    work = Path(tempfile.mkdtemp(prefix="modalmorph-batch-bench-"))
    for phase, name in (("diastole", "ed.csv"), ("systole", "es.csv")):
        np.savetxt(work / name, load_heart(phase), delimiter=",", header="x,y", comments="")
    items = [Item(id=f"p{i:04d}", source=str(work / "ed.csv"), target=str(work / "es.csv"))
             for i in range(n)]
    compute_one(work)  # warm up: the first call imports and fills caches
    _, wall, compute = timed(lambda: [compute_one(work) for _ in range(n)])
    print(f"{n} heart pairs (247 -> 180 nodes), --figures none, on "
          f"{len(os.sched_getaffinity(0))} cores")
    print(f"{'how':<36} {'wall s':>7} {'items/min':>9} {'CPU s/item':>10} {'vs compute':>10} "
          f"{'vs loop':>8} {'in worker':>9}")

    def row(name, wall, cpu, inside=""):
        print(f"{name:<36} {wall:>7.1f} {n / wall * 60:>9.1f} {cpu / n:>10.3f} "
              f"{cpu / compute - 1:>+10.1%} {cpu / loop - 1:>+8.1%} {inside:>9}", flush=True)

    loop = compute
    row("computation only, in a loop", wall, compute)
    _, wall, loop = timed(lambda: [morph_files(
        item.source, item.target, work / "loop" / item.id,
        Settings(output=OutputOptions(figures=False, gif=False)))
        for item in items])
    row("morph_files in a loop (= morph CLI)", wall, loop)
    for engine in args.engines:
        walls = []
        for workers in (1, 2):
            done, wall, cpu = timed(run, items, work / f"{engine}-{workers}",
                                    engine=Engine(engine, workers=workers))
            walls.append(wall)
            assert all(r.status == "ok" for r in done.results), done.results[0]
            inside = np.mean([r.seconds for r in done.results])  # wall s of one item there
            row(f"batch, {engine}, {workers} worker{'s' * (workers > 1)}", wall, cpu,
                f"{inside:.3f}")
        print(f"  {engine}: 2 workers / 1 worker throughput = {walls[0] / walls[1]:.2f}x, "
              f"{n / walls[1] * 3600:.0f} pairs per hour on 2 workers (goal >= 10 000)")
    if args.startup:
        startup(work, items[:2], args.engines)
    rerun(work, args.rerun)


def startup(work, items, engines):
    """Wall time of a 2-item batch, start of the engine included."""
    for engine in engines:
        _, wall, _ = timed(run, items, work / f"start-{engine}", engine=Engine(engine,
                                                                              workers=2))
        print(f"start-up, {engine}, 2 workers, 2 items: {wall:.2f} s", flush=True)


def rerun(work, n):
    """``modalmorph batch`` with nothing to do on n complete items, in a fresh process."""
    out = work / "rerun"
    manifest = work / "rerun.csv"
    manifest.write_text("id,source,target\n" + "".join(
        f"p{i:05d},ed.csv,es.csv\n" for i in range(n)))
    run([Item(id="p00000", source=str(work / "ed.csv"), target=str(work / "es.csv"))], out,
        engine=Engine("processes", workers=1))
    for i in range(1, n):
        shutil.copytree(out / "p00000", out / f"p{i:05d}", copy_function=os.link)
    command = [sys.executable, "-m", "modalmorph", "batch", str(manifest), "--out", str(out),
               "-q"]
    walls, cpus = [], []
    for _ in range(3):
        _, wall, cpu = timed(subprocess.run, command, check=True)
        walls.append(wall)
        cpus.append(cpu)
    print(f"rerun with nothing to do, {n} items (modalmorph batch, a fresh process): "
          f"best {min(walls):.2f} s of 3, CPU {min(cpus):.2f} s (goal < 2 s for 1 000)",
          flush=True)


if __name__ == "__main__":  # the workers of a spawned pool import this file
    main()
