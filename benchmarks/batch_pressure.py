"""Pressure trials through `modalmorph batch` (issue 24): the 600 peak images of
Pataky et al. (2008) registered to each subject's template (10 `footprints` items of 60
images), and stance phases of the 10 subjects (`stance` items, 25 Hz), on the batch's
local process pool.

Data: the optional package jiku-data (GPL-3; `pip install jiku-data`). Prints, per
kind: the wall time of the whole batch (workers' start-up included), the seconds per
item in its worker (median, largest), then the batch's table per subject and walking
speed (`OUT/pressure.csv`: trials, area, strain energy median and quartiles, mean
location of the energy's peak; mm at 1 mm per sensor: jiku-data gives no pitch).
Goals: the 600 peak images in under 10 minutes on 2 cores; a stance under 2 s.
Run from the repository root:

    OMP_NUM_THREADS=1 PYTHONPATH=src python benchmarks/batch_pressure.py [WORKERS] [PER_SUBJECT]

(default 2 workers and 6 stance phases per subject: 2 per speed, 60 in all; 60 takes
all 600).
"""

import csv
import logging
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from modalmorph.apps import batch
from modalmorph.apps.runs import Settings
from modalmorph.io.pressure import jiku_conditions
from modalmorph.options import StanceOptions

try:
    import jikudata  # noqa: F401
except ImportError:
    print("skipped: this benchmark needs the optional package jiku-data (pip install "
          "jiku-data)")
    sys.exit(0)

EVERY = 20  # 500 Hz -> 25 Hz, the stance phases of 15-25 frames


def stance_items(per_subject: int) -> list:
    """``per_subject`` trials of every subject, as many of each speed as can be."""
    items = []
    for s in range(10):
        cond, _ = jiku_conditions(s)
        order = np.concatenate([np.flatnonzero(cond == c) for c in (1, 2, 3)])
        picked = order.reshape(3, -1).T.ravel()[:per_subject]  # slow, normal, fast, ...
        items += [batch.Item(id=f"jiku-s{s}-t{t:02d}", pressure=f"jiku:{s}:{t}",
                             study="stance") for t in sorted(picked)]
    return items


def measure(name: str, items: list, out: Path, workers: int, options) -> None:
    start = time.perf_counter()
    done = batch.run(items, out, engine=batch.Engine("processes", workers=workers),
                     settings=Settings(stance=options))
    wall = time.perf_counter() - start
    seconds = np.array([r.seconds for r in done.results if r.seconds is not None])
    print(f"{name}: {len(items)} items {done.counts} in {wall:.1f} s on {done.engine}; "
          f"per item median {np.median(seconds):.2f} s, largest {seconds.max():.2f} s")
    with open(out / "pressure.csv", newline="") as fh:
        rows = list(csv.reader(fh))
    print("  ".join(f"{c:>8}" for c in rows[0]))
    for row in rows[1:]:
        print("  ".join(f"{c:>8}" for c in row))
    print()


def main(workers: int, per_subject: int) -> None:
    logging.getLogger("modalmorph").setLevel(logging.WARNING)
    with tempfile.TemporaryDirectory() as tmp:
        measure("600 peak images (10 subjects)", batch.pressure_items("jiku", "footprints"),
                Path(tmp) / "footprints", workers, StanceOptions())
        measure(f"stance phases ({per_subject} per subject)", stance_items(per_subject),
                Path(tmp) / "stance", workers, StanceOptions(every=EVERY))


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 2,
         int(sys.argv[2]) if len(sys.argv) > 2 else 6)
