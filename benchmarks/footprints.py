"""The 600 peak-pressure images of Pataky et al. (2008) registered to each subject's mean
footprint, part by part (modalmorph.register_footprints; issue 24).

Data: the optional package jiku-data (GPL-3; `pip install jiku-data`): 10 subjects x 3
walking speeds x 20 trials. Prints a row per subject and speed: trials, area of the
registered parts (mm^2 at PITCH mm per sensor), the registration's strain energy
(median and interquartile range), trials where a template part of >= 12 sensors found
no partner, the template part where the node energy peaks most often and the mean
location of that peak (mm); then the wall time
on WORKERS processes. Run from the repository root:

    OMP_NUM_THREADS=1 PYTHONPATH=src python benchmarks/footprints.py [WORKERS] [FIGURE.png]
"""

import logging
import sys
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from modalmorph import register_footprints
from modalmorph.io.pressure import jiku_conditions, jiku_peaks

try:
    import jikudata  # noqa: F401
except ImportError:
    print("skipped: this benchmark needs the optional package jiku-data (pip install "
          "jiku-data)")
    sys.exit(0)

PITCH = 1.0  # mm per sensor: the plate's pitch is not in jiku-data; results in sensors
SPEEDS = {1: "slow", 2: "normal", 3: "fast"}
LARGE = 12  # sensors: template parts counted when unpaired (toe specks are not)


def unpaired(reg) -> bool:
    """Whether a template part of LARGE sensors or more found no partner."""
    return any(reg.template_sensors[k] >= LARGE for k in reg.missing)


def subject(s: int):
    logging.getLogger("modalmorph").setLevel(logging.WARNING)
    return s, register_footprints(jiku_peaks(s), pixel_size=PITCH)


def main(workers: int, figure: str | None) -> None:
    start = time.perf_counter()
    with ProcessPoolExecutor(workers) as pool:
        done = dict(pool.map(subject, range(10)))
    seconds = time.perf_counter() - start
    print(f"{'subj':>4} {'speed':>6} {'n':>3} {'area':>6} {'energy':>7} {'IQR':>13} "
          f"{'unpaired':>8} {'peak part':>9} {'peak x, y':>12}")
    for s in range(10):
        cond, _ = jiku_conditions(s)
        for c in (1, 2, 3):
            regs = [done[s][t] for t in np.flatnonzero(cond == c)]
            e = np.array([r.energy for r in regs])
            q1, q3 = np.percentile(e, [25, 75])
            parts = np.bincount([r.peak_part for r in regs])
            peak = np.mean([r.peak for r in regs if r.peak_part == parts.argmax()], axis=0)
            print(f"{s:>4} {SPEEDS[c]:>6} {len(regs):>3} "
                  f"{np.mean([r.area for r in regs]):>6.0f} {np.median(e):>7.3g} "
                  f"{q1:>6.3g}-{q3:<6.3g} {sum(unpaired(r) for r in regs):>8} "
                  f"{parts.argmax():>9} {peak[0]:>5.1f}, {peak[1]:<5.1f}")
    print(f"{sum(len(v) for v in done.values())} peak images registered in {seconds:.1f} s "
          f"on {workers} processes")
    if figure:
        from matplotlib.figure import Figure

        from modalmorph.figures.stance import plot_footprints

        fig = Figure(figsize=(12, 4.4), layout="constrained")
        cond, _ = jiku_conditions(0)
        order = np.argsort(cond, kind="stable")
        plot_footprints([done[0][t] for t in order], fig=fig,
                        titles=[f"{SPEEDS[cond[t]]} {t}" for t in order], ncols=20)
        fig.savefig(figure, dpi=120)
        print(f"figure: {figure}")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 2,
         sys.argv[2] if len(sys.argv) > 2 else None)
