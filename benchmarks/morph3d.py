"""3D morphs driven by the matcher's pairs (or the true ones) on benchmarks/match3d.py's
cases: steps, convergence and the end shape's distance to the target both ways.

    PYTHONPATH=src python benchmarks/morph3d.py --shape blob --points 2000 20000 \
        --angles 0 90 --noise 0 0.01 [--pairs matcher|true]

Distances are mean nearest-point distances in % of the target's RMS radius ("size"): one
target node spacing is about 4 % of the size at 2000 points and 1.3 % at 20 000, and with
1 % noise the noise-free truth itself lies about 1.3-2 % from the noisy target.
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

import modalmorph as mm

sys.path.insert(0, str(Path(__file__).parent))
from match3d import make_case  # noqa: E402


def run(shape, m, angle, noise, pairs_from):
    src, tgt, truth = make_case(shape, m, angle, noise)
    start = time.perf_counter()
    if pairs_from == "true":
        matching = np.c_[np.arange(m), cKDTree(tgt).query(truth)[1]]
    else:
        matching = mm.match(src, tgt)
    result = mm.morph(src, tgt, matching=matching)
    end, size = result.shapes[-1], mm.Shape(tgt).size
    fwd = cKDTree(tgt).query(end)[0].mean() / size
    bwd = cKDTree(end).query(tgt)[0].mean() / size
    print(f"{shape:>6} {m:7d} {angle:5.0f} {noise:5.2f} {pairs_from:>8} {result.steps:5d} "
          f"{str(result.converged):>5} {100 * fwd:8.2f} {100 * bwd:8.2f} "
          f"{time.perf_counter() - start:7.1f}", flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shape", default="blob", choices=("blob", "bunny"))
    parser.add_argument("--points", type=int, nargs="+", default=[2000, 20000])
    parser.add_argument("--angles", type=float, nargs="+", default=[0.0, 90.0])
    parser.add_argument("--noise", type=float, nargs="+", default=[0.0, 0.01])
    parser.add_argument("--pairs", default="matcher", choices=("matcher", "true"))
    args = parser.parse_args()
    print(" shape  points angle noise    pairs steps  conv  end->t%  t->end%  time s")
    for m in args.points:
        for angle in args.angles:
            for noise in args.noise:
                run(args.shape, m, angle, noise, args.pairs)


if __name__ == "__main__":
    main()
