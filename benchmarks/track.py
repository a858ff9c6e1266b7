"""Time per frame of modalmorph.track on 20-frame sequences of 70, 250 and 1000 nodes.

The sequence is the bundled end-diastole heart contour deformed by a smooth periodic
field (tests/test_track.py), each frame resampled to a different node count. Run from
the repository root, single-threaded BLAS for comparable numbers:

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=src:tests python benchmarks/track.py
"""

import time

import numpy as np
from test_track import FRAMES, synthetic_sequence

from modalmorph import track

print(f"{'nodes':>6} {'frames':>6} {'total s':>8} {'s/frame':>8} {'steps/frame':>11} "
      f"{'median err / spacing':>21}")
for m in (70, 250, 1000):
    frames, truth, _ = synthetic_sequence(m, np.random.default_rng(20050328))
    start = time.perf_counter()
    result = track(frames)
    total = time.perf_counter() - start
    spacing = np.linalg.norm(np.diff(frames[0], axis=0), axis=1).mean()
    err = np.median(np.linalg.norm(result.points - truth, axis=2), axis=1).max() / spacing
    steps = np.mean([r.steps for r in result.morphs])
    print(f"{m:>6} {FRAMES:>6} {total:>8.2f} {total / (FRAMES - 1):>8.3f} {steps:>11.1f} "
          f"{err:>21.2f}")
