"""Every loaded part of real stance phases followed by modalmorph.stance (issue 24).

Data: the 600 stance phases of Pataky et al. (2008) in the optional package jiku-data
(GPL-3; `pip install jiku-data`): 10 subjects x 3 walking speeds x 20 trials, 500 Hz,
taken at 25 Hz (every 20th frame). Per trial, in sensors (mm / pixel size):

- node: the largest distance of a tracked node to its part's boundary (the iso-line of
  the smoothed field), every frame; raw: the same to the nearest boundary of the loaded
  region of the raw field (no smoothing, every contact), the stricter check;
- gap: the largest distance of a boundary point of a part of >= 12 sensors to its
  nearest tracked node, every frame;
- crossed: frames where a tracked contour crosses itself (all parts).

Goals: node and raw <= 1, gap <= 1.5, crossed 0, seconds < 2. Run from the repository
root (single-threaded BLAS for comparable times):

    OMP_NUM_THREADS=1 PYTHONPATH=src python benchmarks/pedobarography.py [TRIALS_PER_SUBJECT]
"""

import logging
import sys
import time

import numpy as np

from modalmorph import stance
from modalmorph.core.quality import curve_distances
from modalmorph.io.pressure import frame_parts, jiku_conditions, jiku_trial

try:
    import jikudata  # noqa: F401
except ImportError:
    print("skipped: this benchmark needs the optional package jiku-data (pip install "
          "jiku-data)")
    sys.exit(0)

logging.getLogger("modalmorph").setLevel(logging.WARNING)
EVERY = 20  # 500 Hz -> 25 Hz
LARGE = 12  # sensors: parts whose whole boundary must be covered (issue 24)
SPEEDS = {1: "slow", 2: "normal", 3: "fast"}


def raw_distance(result) -> float:
    """Largest distance (sensors) of a tracked node to the raw field's boundaries."""
    worst = 0.0
    for part in result.parts:
        for k, f in enumerate(part.frames):
            raw = frame_parts(result.pressure[f], result.level, smooth=0, min_sensors=1)
            nodes = part.points[k] / result.pixel_size
            d = np.min([curve_distances(nodes, b)[0] for b in raw.contours], axis=0)
            worst = max(worst, float(d.max()))
    return worst


def row(subject: int, trial: int, cond: int) -> tuple:
    stack = jiku_trial(subject, trial, every=EVERY)
    start = time.perf_counter()
    result = stance(stack)
    seconds = time.perf_counter() - start
    px = result.pixel_size
    node = max(float(p.node_distance.max()) for p in result.parts) / px
    gaps = [p.boundary_gap[p.sensors >= LARGE] for p in result.parts]
    gap = max((float(g.max()) for g in gaps if len(g)), default=0.0) / px
    crossed = sum(int(p.crossed.sum()) for p in result.parts)
    return (subject, trial, SPEEDS[cond], result.n_frames, len(result.parts), node,
            raw_distance(result), gap, crossed, float(result.energy.sum()), seconds)


def main(per_subject: int) -> None:
    print(f"{'subj':>4} {'trial':>5} {'speed':>6} {'frames':>6} {'parts':>5} {'node':>5} "
          f"{'raw':>5} {'gap':>5} {'crossed':>7} {'energy':>8} {'s':>5}")
    rows = []
    for subject in range(10):
        cond, _ = jiku_conditions(subject)
        trials = [t for c in (1, 2, 3) for t in np.flatnonzero(cond == c)[:per_subject]]
        for trial in sorted(trials):
            r = row(subject, int(trial), int(cond[trial]))
            rows.append(r)
            print(f"{r[0]:>4} {r[1]:>5} {r[2]:>6} {r[3]:>6} {r[4]:>5} {r[5]:>5.2f} "
                  f"{r[6]:>5.2f} {r[7]:>5.2f} {r[8]:>7} {r[9]:>8.3g} {r[10]:>5.2f}",
                  flush=True)
    a = np.array([r[3:] for r in rows], dtype=float)
    print(f"{len(rows)} trials of 10 subjects: frames {a[:, 0].min():.0f}-{a[:, 0].max():.0f}, "
          f"worst node {a[:, 2].max():.2f}, raw {a[:, 3].max():.2f}, gap {a[:, 4].max():.2f} "
          f"sensors, crossed frames {a[:, 5].sum():.0f}, seconds median {np.median(a[:, 7]):.2f} "
          f"max {a[:, 7].max():.2f}")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 2)
