"""BLAS threads: the library's default policy against one thread and against every core.

For each size, a heart pair of the shared data (ED -> ES, resampled by arc length to that
many nodes) is matched and morphed with default options (``modalmorph.morph``) three ways
in the same process: the library's policy (``modalmorph.threads``), forced to one BLAS
thread, and forced to every core (what numpy does without the policy). Median of
``--repeat`` interleaved rounds, after one warm-up round. ``--busy N`` first starts N
processes that spin on the cores (a busy machine), and stops them at the end. The ratio
columns are the policy's time over the others' (<= 1: the policy is not slower).

    PYTHONPATH=src python benchmarks/threads.py [--sizes 70,250,1000,4000] [--repeat 5]
    PYTHONPATH=src python benchmarks/threads.py --busy 2
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import statistics
import time
from pathlib import Path

import modalmorph as mm
from modalmorph.core.shape import resample
from modalmorph.threads import blas_threads, set_blas_threads

# Seconds to wait after a run on every core: OpenBLAS's idle workers spin for about 0.1 s
# (its THREAD_TIMEOUT of 2^28 cycles) before they sleep.
SPIN_PAUSE = 0.3
DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "heart"


def heart_pair(nodes: int):
    """The first ED/ES pair of the shared hearts (the bundled pair without them)."""
    files = sorted(DATA.glob("SC-HF-NI-03-*.csv"))[:2] if DATA.exists() else []
    if len(files) == 2:
        a, b = (mm.read_shape(f).points for f in files)
    else:
        from modalmorph.datasets import load_heart
        a, b = load_heart("diastole"), load_heart("systole")
    return resample(a, nodes), resample(b, nodes)


def timed(a, b, threads, repeat: int) -> float:
    """Median seconds of ``mm.morph(a, b)`` under each BLAS thread setting of
    ``threads`` (None: the policy), in interleaved rounds so that load that comes and goes
    falls on every setting alike; after a run on every core, a pause lets OpenBLAS's
    workers stop spinning (they busy-wait for a while after a call and would slow the
    next setting's run on a 2-core machine)."""
    times = {t: [] for t in threads}
    for round_ in range(repeat + 1):  # round 0 warms up
        for t in threads:
            set_blas_threads(t)
            try:
                start = time.perf_counter()
                mm.morph(a, b)
                if round_:
                    times[t].append(time.perf_counter() - start)
            finally:
                set_blas_threads(None)
            if t is not None and t > 1:
                time.sleep(SPIN_PAUSE)
    return [statistics.median(times[t]) for t in threads]


def _spin(stop):
    while not stop.is_set():
        sum(i * i for i in range(10_000))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", default="70,250,1000,4000")
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--busy", type=int, default=0, help="spinning processes")
    args = parser.parse_args(argv)
    cores = len(os.sched_getaffinity(0))
    stop = multiprocessing.Event()
    spinners = [multiprocessing.Process(target=_spin, args=(stop,), daemon=True)
                for _ in range(args.busy)]
    for p in spinners:
        p.start()
    time.sleep(2.0 if spinners else 0.0)
    print(f"# {cores} cores, {args.busy} busy processes, load average "
          f"{os.getloadavg()[0]:.1f}; median of {args.repeat}, seconds")
    print(f"{'nodes':>6} {'threads':>7} {'one s':>8} {'all s':>8} "
          f"{'policy s':>8} {'/one':>6} {'/all':>6}")
    try:
        for nodes in (int(s) for s in args.sizes.split(",")):
            a, b = heart_pair(nodes)
            one, policy, every = timed(a, b, (1, None, cores), args.repeat)
            print(f"{nodes:>6} {blas_threads(nodes):>7} {one:8.4f} {every:8.4f} "
                  f"{policy:8.4f} {policy / one:6.2f} {policy / every:6.2f}")
    finally:
        stop.set()
        for p in spinners:
            p.join()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
