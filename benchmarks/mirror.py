"""Mirror images (method.md §2, "Mirror images"): how well ``Matching.mirror`` tells a
target that is the source's mirror image from one that is not, over a broad corpus.

Pairs (source, target), each target as given and in five poses:

- ``glyphs``: letters, digits and symbols (``--chars``) of the fonts matplotlib ships,
  cross-font (DejaVu Sans -> DejaVu Serif, STIXGeneral -> cmr10, cmss10 -> cmtt10, DejaVu
  Sans Mono -> STIXGeneral, cmr10 -> DejaVu Sans) and same-font (cmr10, DejaVu Serif), the
  outer contour alone and every contour of the glyph (a shape of several contours, where
  it has them), resampled to ``--nodes`` (100, 200) by arc length;
- ``heart``: the shared hearts ED -> ES (``realdata.heart_pairs``), resampled to 100;
- ``hands``: hand 0 -> hand k, k = 1..7, resampled to 200;
- ``horse``: skimage's horse -> itself warped (``realdata.smooth_warp``), 200 nodes.

Poses of the target about its centroid: ``as`` (as given), ``turn`` (turned 34 deg),
``mx`` (x mirrored), ``my`` (y mirrored: upside down), ``mx_turn`` and ``my_turn`` (mirrored,
then turned 34 deg). For each, with the module's gate lifted (``MIRROR_SUSPECT`` = -1):
``g0`` (the gap of the source placed by the pairs' similarity, :func:`mirror_gap`), ``g1``
(the reflected source's, matched again in any pose), ``gf`` (the source's as given, matched
again in any pose) and ``min(g0, gf) / g1``; ``asym``, the
source's own gap to its mirror image in its best pose (reflection about any line through
its centroid, 1 deg steps; the largest contour's for a shape of several contours): a
mirror image of a near-symmetric shape is not one to call. ``--morph`` adds the morph's
final energy, convergence and folds (slow).

The table: false calls on targets not mirrored, and calls on mirrored ones (all; those
to call: the source's ``asym`` over ``ASYM`` (0.05) and over twice the pair's own gap),
for the module's rule and others (``free too``: g0 the nearer of the first pose's and any
pose's, as the module does), the margins, then per family; ``--speed``: the pairs of
``benchmarks/speed.py``'s corpus (as given, 70 / 250 / 1000 nodes) that pay the second
match at the module's gate and others. Measured (4602 targets, ~3 min on one core): the
module's rule 0 false calls, 1049 of 1148 to call said; see ``matching/mirror.py``.

    OMP_NUM_THREADS=1 PYTHONPATH=src python benchmarks/mirror.py [--save rows.csv]
        [--load rows.csv] [--nodes 100 200] [--chars ...] [--morph] [--speed]
"""

from __future__ import annotations

import argparse
import csv
import os
import time

import numpy as np
from realdata import DATA, heart_pairs, horse_contour, smooth_warp
from scipy.spatial import cKDTree

import modalmorph as mm
from modalmorph.core.shape import Shape, share
from modalmorph.matching import mirror

FONT_PAIRS = (("DejaVuSans", "DejaVuSerif"), ("STIXGeneral", "cmr10"),
              ("cmss10", "cmtt10"), ("DejaVuSansMono", "STIXGeneral"),
              ("cmr10", "DejaVuSans"), ("cmr10", "cmr10"), ("DejaVuSerif", "DejaVuSerif"))
CHARS = "AbdFGHJKLNOPQRSTZaefghkrtyz0234578&?%"
TURN = 34.0  # degrees: the turned poses
ASYM = 0.05  # a source whose own mirror image lies farther than this (RMS radii) is asymmetric
POSES = ("as", "turn", "mx", "my", "mx_turn", "my_turn")
FIELDS = ("family", "name", "nodes", "pose", "g0", "g1", "gf", "asym", "seconds", "energy",
          "converged", "folds")


def glyph(ch: str, font: str, n: int, every: bool) -> Shape:
    """The glyph's outer contour (``every`` False) or all its contours, largest first,
    ``n`` nodes shared by length."""
    import matplotlib
    from matplotlib.font_manager import FontProperties
    from matplotlib.textpath import TextPath

    path = os.path.join(matplotlib.get_data_path(), "fonts", "ttf", f"{font}.ttf")
    polys = [p[:-1] for p in TextPath((0, 0), ch, size=100, prop=FontProperties(
        fname=path)).to_polygons(closed_only=True) if len(p) > 3]
    polys.sort(key=lambda p: -abs(np.sum(p[:, 0] * np.roll(p[:, 1], -1)
                                         - np.roll(p[:, 0], -1) * p[:, 1])))
    polys = polys if every else polys[:1]
    if len(polys) == 1:
        return Shape(mm.resample(polys[0], n))
    whole = Shape(np.vstack(polys), contours=tuple(len(p) for p in polys))
    sizes = share(whole, n)
    return Shape(np.vstack([mm.resample(p, k) for p, k in zip(polys, sizes, strict=True)]),
                 contours=tuple(int(k) for k in sizes))


def corpus(chars: str, nodes) -> list[tuple[str, str, Shape, Shape]]:
    """(family, name, source, target) as given."""
    out = []
    for a, b in FONT_PAIRS:
        family = "same-font" if a == b else "cross-font"
        for ch in chars:
            for n in nodes:
                for every in (False, True):
                    try:
                        s, t = glyph(ch, a, n, every), glyph(ch, b, n, every)
                    except (ValueError, IndexError):
                        continue  # a glyph the font lacks
                    if every and s.contours is None and t.contours is None:
                        continue  # one contour: the outer-contour pair already
                    out.append((family, f"{ch} {a}->{b}{' all' if every else ''}", s, t))
    out += [("heart", name, Shape(mm.resample(a, 100)), Shape(mm.resample(b, 100)))
            for name, a, b in heart_pairs(DATA)]
    hands = [np.loadtxt(DATA / "hands" / f"hand-{i}.csv", delimiter=",", skiprows=1)
             for i in range(8)]
    out += [("hands", f"0->{k}", Shape(mm.resample(hands[0], 200)),
             Shape(mm.resample(hands[k], 200))) for k in range(1, 8)]
    horse = mm.resample(horse_contour(), 200)
    out += [("horse", f"warp {seed}", Shape(horse), Shape(smooth_warp(horse, 0.05, seed)))
            for seed in range(2)]
    return out


def posed(shape: Shape, pose: str) -> Shape:
    """The target in ``pose`` about its centroid (module docstring)."""
    p = shape.points
    c = p.mean(axis=0)
    q = (p - c) * {"x": [-1.0, 1.0], "y": [1.0, -1.0]}.get(pose[1:2] if pose[0] == "m" else
                                                          "", [1.0, 1.0])
    if pose.endswith("turn"):
        t = np.radians(TURN)
        q = q @ np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]]).T
    return shape.with_points(c + q)


def asymmetry(shape: Shape) -> float:
    """The gap (RMS radii, both ways' nearest nodes) of the largest contour to its mirror
    image about the best line through its centroid (1 deg steps)."""
    p = shape.contour(0).points if shape.contours else shape.points
    q = p - p.mean(axis=0)
    size = np.mean(np.sum(q ** 2, axis=1))
    tree, best = cKDTree(q), np.inf
    for t in np.radians(np.arange(180.0)):
        c, s = np.cos(2 * t), np.sin(2 * t)
        r = q @ np.array([[c, s], [s, -c]])  # reflection about the line at angle t
        d = (np.mean(tree.query(r)[0] ** 2) + np.mean(cKDTree(r).query(q)[0] ** 2)) / 2
        best = min(best, d)
    return float(np.sqrt(best / size))


def gaps(src: Shape, tgt: Shape) -> tuple[float, float, float, float, mm.Matching]:
    """g0, g1, gf with the module's tests lifted, the match's seconds, and the matching."""
    seen, gap, suspect, called = [], mirror.mirror_gap, mirror.MIRROR_SUSPECT, \
        mirror.mirror_called

    def record(*args):
        seen.append(gap(*args))
        return seen[-1]
    mirror.mirror_gap, mirror.MIRROR_SUSPECT = record, -1.0
    mirror.mirror_called = lambda g0, g1: True
    try:
        tic = time.perf_counter()
        found = mm.match(src, tgt)
        seconds = time.perf_counter() - tic
    finally:
        mirror.mirror_gap, mirror.MIRROR_SUSPECT, mirror.mirror_called = gap, suspect, called
    return seen[0], seen[1], seen[2], seconds, found


def measure(pairs, with_morph: bool) -> list[dict]:
    rows = []
    for family, name, src, tgt in pairs:
        asym = asymmetry(src)
        for pose in POSES:
            t = posed(tgt, pose)
            g0, g1, gf, seconds, found = gaps(src, t)
            row = dict(family=family, name=name, nodes=src.m, pose=pose, g0=g0, g1=g1, gf=gf,
                       asym=asym, seconds=seconds, energy="", converged="", folds="")
            if with_morph:
                r = mm.morph(src, t, matching=found)
                row.update(energy=float(r.energy[-1]), converged=int(r.converged),
                           folds=int(np.max(r.self_intersections)))
            rows.append(row)
            print(f"{family:10s} {name:32s} {src.m:4d} {pose:8s} g0 {g0:.3f} g1 {g1:.3f} "
                  f"gf {gf:.3f} ratio {min(g0, gf) / max(g1, 1e-12):7.2f} asym {asym:.3f} "
                  f"{row['energy']}", flush=True)
    return rows


def load(path: str) -> list[dict]:
    with open(path) as f:
        rows = list(csv.DictReader(f))
    for r in rows:
        for k in ("g0", "g1", "gf", "asym", "seconds"):
            r[k] = float(r[k])
    return rows


def save(rows: list[dict], path: str) -> None:
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=FIELDS)
        w.writeheader()
        w.writerows(rows)


def module_rule(g0, g1, gf) -> np.ndarray:
    """The module's test on recorded gaps (:func:`~modalmorph.matching.mirror.mirror_ratio`)."""
    return np.array([a > mirror.MIRROR_SUSPECT and mirror.mirror_called(a, b)
                     and mirror.mirror_called(min(a, f), b)
                     for a, b, f in zip(g0, g1, gf, strict=True)])


def rule(gate: float, ratio: float, free: bool):
    """g0 > gate and g0 > ratio x g1, g0 the nearer of both poses' where ``free``."""
    return lambda g0, g1, gf: (g0 > gate) & ((np.minimum(g0, gf) if free else g0) > ratio * g1)


RULES = {"module": module_rule, "old: g0 > 0.12, ratio > 3": rule(0.12, 3.0, False)}
RULES.update({f"g0 > {gate:.2f}, ratio > {ratio:.2g}{', free too' if free else ''}":
              rule(gate, ratio, free) for free in (False, True) for gate in (0.12, 0.1, 0.08, 0.06)
              for ratio in (3.0, 2.0, 1.5, 1.4, 1.3)})


def classes(rows: list[dict]) -> tuple[np.ndarray, np.ndarray]:
    """Targets mirrored, and those that are a mirror image to call: the source asymmetric
    (``asym`` over ``ASYM``) and its mirror image farther than twice the pair's own gap
    (the least of g0, gf over its poses not mirrored), so that the mirror image of an
    'O' or a heart, or of an 'A' onto another font's, is not one."""
    mirrored = np.array([r["pose"].startswith("m") for r in rows])
    pair = [(r["family"], r["name"], r["nodes"]) for r in rows]
    own: dict = {}
    for k, r, m in zip(pair, rows, mirrored, strict=True):
        if not m:
            own[k] = min(own.get(k, np.inf), r["g0"], r["gf"])
    asym = np.array([r["asym"] for r in rows])
    return mirrored, mirrored & (asym > ASYM) & (asym > 2 * np.array([own[k] for k in pair]))


def table(rows: list[dict]) -> str:
    g0, g1, gf = (np.array([r[k] for r in rows]) for k in ("g0", "g1", "gf"))
    mirrored, to_call = classes(rows)
    out = [f"{len(rows)} targets: {np.sum(~mirrored)} not mirrored, {np.sum(mirrored)} mirrored "
           f"({np.sum(to_call)} to call: source asym > {ASYM} and > 2 x the pair's gap)",
           f"{'rule':36s} {'false calls':>12s} {'to call said':>13s} {'mirrored said':>14s}"]
    for name, test in RULES.items():
        said = test(g0, g1, gf)
        out.append(f"{name:36s} {np.sum(said & ~mirrored):5d} of {np.sum(~mirrored):4d} "
                   f"{np.sum(said & to_call):5d} of {np.sum(to_call):4d} "
                   f"{np.sum(said & mirrored):6d} of {np.sum(mirrored):4d}")
    ratio = np.minimum(g0, gf) / np.maximum(g1, 1e-12)
    gated = ~mirrored & (g0 > mirror.MIRROR_SUSPECT)
    out.append(f"margins, ratio = min(g0, gf) / g1: not mirrored max {ratio[~mirrored].max():.3f} "
               f"(g0 over MIRROR_SUSPECT: {ratio[gated].max():.3f}); to call: min "
               f"{ratio[to_call].min():.2f}, g0 min {g0[to_call].min():.3f}")
    turn = ~mirrored & (g0 > 1.5 * gf)
    poses = sorted({r["pose"] for r, t in zip(rows, turn, strict=True) if t})
    out.append(f"not mirrored whose first pose lies over 1.5 x farther than the free pose's: "
               f"{np.sum(turn)} (poses: {poses})")
    said = module_rule(g0, g1, gf)
    for family in sorted({r["family"] for r in rows}):
        f = np.array([r["family"] == family for r in rows])
        out.append(f"  {family:10s} module: false {np.sum(said & f & ~mirrored)} of "
                   f"{np.sum(f & ~mirrored)}; to call said {np.sum(said & f & to_call)} of "
                   f"{np.sum(f & to_call)}; mirrored said {np.sum(said & f & mirrored)} of "
                   f"{np.sum(f & mirrored)}; second match paid by "
                   f"{np.sum(f & ~mirrored & (g0 > mirror.MIRROR_SUSPECT))} not mirrored")
    return "\n".join(out + morphs(rows, said, mirrored))


def morphs(rows: list[dict], said: np.ndarray, mirrored: np.ndarray) -> list[str]:
    """The morphs' final energy, convergence and folds (``--morph``), by class."""
    if any(r["energy"] in ("", None) for r in rows):
        return []
    e, c, f = (np.array([float(r[k]) for r in rows]) for k in ("energy", "converged", "folds"))
    return [f"  morphs, {name}: {np.sum(s)}, median energy {np.median(e[s]):.3g}, converged "
            f"{int(np.sum(c[s]))}, folded {int(np.sum(f[s] > 0))}"
            for name, s in (("not mirrored", ~mirrored), ("mirrored said", mirrored & said),
                            ("mirrored not said", mirrored & ~said)) if np.any(s)]


def speed_paying() -> str:
    """How many of benchmarks/speed.py's pairs (as given) pay the second match, at the
    module's gate and others."""
    from speed import corpus as speed_corpus

    g0 = []
    for pairs in speed_corpus("AGRSaegs25").values():
        for size in (70, 250, 1000):
            g0 += [gaps(Shape(mm.resample(a, size)), Shape(mm.resample(b, size)))[0]
                   for _, a, b in pairs]
    g0 = np.array(g0)
    return "speed corpus, pairs that pay the second match: " + ", ".join(
        f"g0 > {gate:.2f}: {np.sum(g0 > gate)} of {len(g0)}"
        for gate in sorted({mirror.MIRROR_SUSPECT, 0.12, 0.1, 0.08, 0.06}, reverse=True))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--nodes", type=int, nargs="+", default=[100, 200])
    ap.add_argument("--chars", default=CHARS)
    ap.add_argument("--save")
    ap.add_argument("--load")
    ap.add_argument("--only", default="", help="pairs whose name holds this text")
    ap.add_argument("--morph", action="store_true")
    ap.add_argument("--speed", action="store_true")
    args = ap.parse_args(argv)
    rows = load(args.load) if args.load else measure(
        [p for p in corpus(args.chars, args.nodes) if args.only in p[1]], args.morph)
    if args.save:
        save(rows, args.save)
    print(table(rows))
    if args.speed:
        print(speed_paying())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
