"""Turned poses under ``rotation="auto"``: which turns the matcher finds (method.md §2, Pose).

Each pair is one shape onto another in one frame, the target then turned about its
centroid by +-A degrees for every A of ``--angles``: the 62 glyphs A-Z, a-z, 0-9 of DejaVu
Sans -> DejaVu Serif (outer contour, ``realdata.glyph_outline``) and the shared hands
hand-0 -> hand-k, k = 1..7, resampled by arc length to each size of ``--sizes``. A run is
right when its pairs lie within ``--within`` nodes per 120 (the arc of one node at 120
nodes; median over the pairs) of the pairs the same matcher finds unturned. A row per size
and angle: runs right with ``rotation="auto"`` and with ``"free"`` (any pose, by cost
alone: the same at every angle), out of all; at 0 degrees auto is right by definition.
Some glyphs have two fits alike ('o', 'l', 'I', '0', 'S', 'N', 'z' turned by half a
turn), which no pose tells apart: free's shortfall at every angle, and auto's at 180
degrees, where it keeps the common frame's fit of such a glyph (method.md §2: a symmetric
shape in one frame is not turned).

    PYTHONPATH=src python benchmarks/turns.py [--sizes 70 120 250] [--angles 0 10 ... 50]
"""

from __future__ import annotations

import argparse
import string
import warnings

import numpy as np
from realdata import glyph_outline

import modalmorph as mm
from modalmorph.core.shape import resample
from modalmorph.datasets import load_hand


def corpus() -> list[tuple[str, np.ndarray, np.ndarray]]:
    glyphs = [(ch, glyph_outline(ch, "DejaVu Sans"), glyph_outline(ch, "DejaVu Serif"))
              for ch in string.ascii_letters + string.digits]
    return glyphs + [(f"hand 0->{k}", load_hand(0), load_hand(k)) for k in range(1, 8)]


def turned(p: np.ndarray, degrees: float) -> np.ndarray:
    t = np.radians(degrees)
    c = p.mean(axis=0)
    return c + (p - c) @ np.array([[np.cos(t), np.sin(t)], [-np.sin(t), np.cos(t)]])


def offset(pairs: np.ndarray, reference: dict, n: int) -> float:
    """Median over the shared source nodes of the cyclic index gap between partners."""
    gaps = [min(abs(j - reference[i]), n - abs(j - reference[i])) for i, j in pairs
            if i in reference]
    return float(np.median(gaps)) if gaps else float(n)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[70, 120, 250])
    ap.add_argument("--angles", type=float, nargs="+",
                    default=[0, 10, 15, 20, 25, 30, 35, 40, 50, 90, 180])
    ap.add_argument("--within", type=float, default=1.0, help="nodes per 120 (default 1)")
    args = ap.parse_args(argv)
    cases = corpus()
    print(f"{len(cases)} pairs (62 glyphs, 7 hands), each turned by +A and -A degrees\n")
    print(f"{'nodes':>5} {'angle':>6} {'auto right':>11} {'free right':>11} {'runs':>5}")
    for n in args.sizes:
        tol = max(1.0, args.within * n / 120)
        right = {a: [0, 0, 0] for a in args.angles}
        for _, a, b in cases:
            src = resample(mm.Shape(a, closed=True), n)
            tgt = resample(mm.Shape(b, closed=True), n)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # mirror and slide warnings: not counted here
                reference = dict(mm.match(src, tgt).pairs.tolist())
                for angle in args.angles:
                    for sign in ((1,) if angle in (0, 180) else (1, -1)):
                        target = turned(tgt.points, sign * angle)
                        for k, rotation in enumerate(("auto", "free")):
                            pairs = mm.match(src, target, rotation=rotation).pairs
                            right[angle][k] += offset(pairs, reference, n) <= tol
                        right[angle][2] += 1
        for angle, (auto, free, runs) in right.items():
            print(f"{n:>5} {angle:>6g} {auto:>11} {free:>11} {runs:>5}")
        print()


if __name__ == "__main__":
    main()
