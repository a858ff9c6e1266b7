"""Results of a fixed corpus saved for a bitwise comparison across versions.

What a change that claims "results unchanged" is checked with: 22 morphs and 3 tracks
(8 shared heart pairs, hands at 120, 250 and 1590 nodes, glyphs of two fonts, a warped
horse, the explicit scheme, nodal loads, no free motion, a 600-point 3D cloud), each
run with one BLAS thread; ``compare`` prints every array that differs (113 in all).

    OMP_NUM_THREADS=1 MODALMORPH_BLAS_THREADS=1 PYTHONPATH=src python \\
        benchmarks/regression.py save before.npz
    ... change the code, save after.npz the same way ...
    python benchmarks/regression.py compare before.npz after.npz
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import numpy as np
from realdata import DATA, glyph_outline, heart_pairs, horse_contour, smooth_warp
from threadpoolctl import threadpool_limits

import modalmorph as mm
from modalmorph.core.shape import resample

MORPH_KEYS = ("shapes", "loads", "energy", "node_energy", "mean_distance")


def hand(i: int) -> np.ndarray:
    """The shared hand ``i``'s points as written, (m, 2) (a header line skipped)."""
    with open(DATA / "hands" / f"hand-{i}.csv") as f:
        rows = [r for r in csv.reader(f) if r]
    try:
        float(rows[0][0])
    except ValueError:
        rows = rows[1:]
    return np.array(rows, float)[:, :2]


def cases():
    """(name, source, target, options) of every morph of the corpus."""
    for name, a, b in heart_pairs(DATA / "heart")[:8]:
        yield "heart-" + name, a, b, {}
    h0 = hand(0)
    for k in (1, 3):
        yield f"hand-250-{k}", resample(h0, 250), resample(hand(k), 250), {}
        yield f"hand-rigid-{k}", resample(h0, 120), resample(hand(k), 120), {"remove_rigid": True}
    yield "hand-1590", h0, hand(2), {}
    for ch in "aRg5":
        yield (f"glyph-{ch}", resample(glyph_outline(ch, "DejaVu Sans"), 150),
               resample(glyph_outline(ch, "DejaVu Serif"), 150), {})
    horse = resample(horse_contour(), 200)
    yield "horse", horse, smooth_warp(horse, 0.05, 1), {}
    a, b = resample(h0, 100), resample(hand(1), 100)
    yield "explicit", a, b, {"k": 5, "scheme": "explicit", "max_steps": 30}
    yield "nodal", a, b, {"loads": "nodal", "damping": (0.5, 1.0)}
    yield "free-none", a, b, {"free_motion": "none"}
    rng = np.random.default_rng(3)
    p = rng.normal(size=(600, 3))
    p = p / np.linalg.norm(p, axis=1)[:, None] * (3, 2, 1)
    q = p @ np.array([[0.8, -0.6, 0], [0.6, 0.8, 0], [0, 0, 1.0]]) * 1.1 + 0.05 * np.sin(3 * p)
    yield "cloud-600", p, q[rng.permutation(600)], {}


def save(out: Path) -> None:
    """Run the corpus and write every result array to ``out``."""
    arrays = {}
    with threadpool_limits(1):
        for name, a, b, options in cases():
            r = mm.morph(a, b, **options)
            arrays.update({f"{name}/{key}": np.asarray(getattr(r, key)) for key in MORPH_KEYS})
            arrays[f"{name}/pairs"] = np.asarray(r.matching.pairs)
            arrays[f"{name}/distance"] = np.float64(r.distance)
        t = np.linspace(0, 2 * np.pi, 80, endpoint=False)
        frames = [np.c_[(1 + 0.1 * f) * np.cos(t), np.sin(t) + 0.05 * f * np.cos(2 * t)]
                  for f in range(5)]
        tracks = {"track-previous": {"reference": "previous"},
                  "track-first": {"reference": "first"},
                  "track-modal": {"correspondence": "modal", "cycle": True}}
        for name, options in tracks.items():
            tr = mm.track(frames, **options)
            keys = ("points", "energy") + (("node_energy",) if name != "track-modal" else ())
            arrays.update({f"{name}/{key}": getattr(tr, key) for key in keys})
    np.savez(out, **arrays)
    print(len(arrays), "arrays")


def compare(first: Path, second: Path) -> None:
    """Print each array that differs (pairs: how many entries; others: the largest
    relative difference), then how many are bitwise equal."""
    a, b = np.load(first), np.load(second)
    worst, same, names = 0.0, 0, sorted(set(a) | set(b))
    for k in names:
        if k not in a or k not in b:
            print("MISSING", k)
        elif a[k].shape != b[k].shape:
            print("SHAPE", k, a[k].shape, b[k].shape)
        elif np.array_equal(a[k], b[k]):
            same += 1
        elif k.endswith("/pairs"):
            print("PAIRS", k, int((a[k] != b[k]).sum()), "entries differ")
        else:
            rel = float(np.max(np.abs(a[k] - b[k])) / max(np.max(np.abs(a[k])), 1e-300))
            worst = max(worst, rel)
            print(f"{k}: max rel {rel:.3g}")
    print(f"{same} of {len(names)} arrays bitwise equal; worst relative difference {worst:.3g}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("save").add_argument("out", type=Path)
    both = sub.add_parser("compare")
    both.add_argument("first", type=Path)
    both.add_argument("second", type=Path)
    args = parser.parse_args()
    save(args.out) if args.command == "save" else compare(args.first, args.second)


if __name__ == "__main__":
    main()
