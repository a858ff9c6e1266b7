"""Time of match + morph over a corpus of real shapes, and of track over a sequence.

Families, each pair resampled by arc length to every size of ``--sizes`` (70, 250, 1000):

- ``hearts``: every ED -> ES pair of the shared Sunnybrook hearts and the demo pair
  (``realdata.heart_pairs``, 16 pairs);
- ``hands``: hand-0 -> hand-k, k = 1..7 (shared data, or the bundled hands);
- ``glyphs``: the outer contour of ``--chars`` in three pairs of fonts (DejaVu Sans ->
  DejaVu Serif, DejaVu Sans Mono -> STIXGeneral, cmss10 -> cmr10; matplotlib TextPath,
  ``realdata.glyph_outline``).

Each pair: ``modalmorph.match`` then ``modalmorph.morph`` with default options (the
library's BLAS thread policy: one thread up to 1000 nodes), the best of ``--repeat``
runs after one warm-up, in wall-clock seconds and in CPU seconds of this process
(``time.process_time``: on a busy machine the wall clock counts the time other work
held the cores, the CPU time does not). A row per family and size: pairs, median, 90th
percentile and worst; also the median and worst CPU seconds of ``match`` alone (best of
the same runs), and the median over the family of each pair's median minor page faults a
run (``resource.getrusage``; glibc hands freed memory back at the top of its heap, and
fresh pages cost ~1.7 us each to fault in: issue 22). ``--reference K`` also times the
dense transcription of the paper (``morph.py``: G inverted, ``eigh(K, M)``, the
affinity (8), the same Newmark steps) on the first K pairs of each family at each size,
and prints the speed-up (reference / match + morph, CPU seconds, both on one BLAS
thread; median and worst over those pairs). ``--track`` times ``modalmorph.track``
(default options, then ``reference="first"``) on the 20 contours of SC-HF-NI-03
resampled to 250 nodes. The load average is printed first and last.

    PYTHONPATH=src python benchmarks/speed.py [--sizes 70 250 1000] [--repeat 3]
        [--reference 3] [--track]
"""

from __future__ import annotations

import argparse
import os
import platform
import resource
import time

import numpy as np
from morph import reference, reference_match
from realdata import DATA, glyph_outline, heart_pairs
from threadpoolctl import threadpool_limits

import modalmorph as mm
from modalmorph.core.shape import forget_checks, resample
from modalmorph.datasets import load_hand

FONT_PAIRS = (("DejaVu Sans", "DejaVu Serif"), ("DejaVu Sans Mono", "STIXGeneral"),
              ("cmss10", "cmr10"))
CHARS = "AGRSaegs25"


def corpus(chars: str) -> dict[str, list[tuple[str, np.ndarray, np.ndarray]]]:
    """Pairs (name, source, target) per family, as read (not resampled)."""
    hands_dir = DATA / "hands"

    def hand(i):
        path = hands_dir / f"hand-{i}.csv"
        return np.loadtxt(path, delimiter=",", skiprows=1) if path.exists() else load_hand(i)

    glyphs = []
    for a_face, b_face in FONT_PAIRS:
        for ch in chars:
            glyphs.append((f"{ch} {a_face}->{b_face}", glyph_outline(ch, a_face),
                           glyph_outline(ch, b_face)))
    return {"hearts": heart_pairs(DATA),
            "hands": [(f"0->{k}", hand(0), hand(k)) for k in range(1, 8)],
            "glyphs": glyphs}


def _faults() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt


def timed(fn, repeat: int, faults: list | None = None):
    """Best wall and CPU seconds of ``repeat`` runs after a warm-up, and the last result;
    appends the median minor page faults of a run to ``faults``."""
    out = fn()
    wall, cpu, flt = [], [], []
    for _ in range(repeat):
        f, w, c = _faults(), time.perf_counter(), time.process_time()
        out = fn()
        wall.append(time.perf_counter() - w)
        cpu.append(time.process_time() - c)
        flt.append(_faults() - f)
    if faults is not None:
        faults.append(np.median(flt))
    return min(wall), min(cpu), out


def match_morph(a, b, match_cpu: list):
    """``match`` then ``morph``; appends the CPU seconds of ``match`` to ``match_cpu``.
    Each run checks its objects as the first run on them does (``forget_checks``)."""
    forget_checks()
    c = time.process_time()
    matching = mm.match(a, b)
    match_cpu.append(time.process_time() - c)
    return matching, mm.morph(a, b, matching=matching)


def dense_reference(a, b, pairs, steps) -> float:
    """CPU seconds of the dense transcription (match, then morph with the same steps), on
    one BLAS thread like the library's calls up to 1000 nodes (more threads spin and
    count CPU time without doing more work)."""
    with threadpool_limits(1):
        c = time.process_time()
        reference_match(a, b)
        reference(a, b, pairs, steps)
        return time.process_time() - c


def distribution(values) -> str:
    v = np.asarray(values)
    return (f"{np.median(v):>8.4f} {np.percentile(v, 90):>8.4f} {v.max():>8.4f}"
            if len(v) else f"{'-':>8} {'-':>8} {'-':>8}")


def run_size(family: str, pairs, n: int, repeat: int, n_reference: int) -> str:
    walls, cpus, matches, ratios, faults, failed = [], [], [], [], [], 0
    for k, (_, a, b) in enumerate(pairs):
        a, b = resample(a, n), resample(b, n)
        match_cpu = []
        try:
            wall, cpu, (matching, result) = timed(
                lambda a=a, b=b, t=match_cpu: match_morph(a, b, t), repeat, faults)
        except ValueError:  # a glyph outline the library refuses (it says why)
            failed += 1
            continue
        walls.append(wall)
        cpus.append(cpu)
        matches.append(min(match_cpu[1:]))  # after the warm-up
        if k < n_reference:
            ratios.append(dense_reference(a, b, matching.pairs, result.steps) / cpu)
    speed = (f"{np.median(ratios):>6.1f}x {min(ratios):>6.1f}x" if ratios
             else f"{'-':>7} {'-':>7}")
    match = (f"{np.median(matches):>8.4f} {max(matches):>8.4f}" if matches
             else f"{'-':>8} {'-':>8}")
    flt = f"{np.median(faults):>7.0f}" if faults else f"{'-':>7}"
    return (f"{family:>7} {n:>5} {len(walls):>5} {failed:>4}  {distribution(walls)}  "
            f"{distribution(cpus)}  {match}  {speed}  {flt}")


def run_track(repeat: int) -> str:
    files = sorted((DATA / "heart").glob("SC-HF-NI-03-*.csv"))
    if len(files) < 2:
        return "track: the shared hearts are missing"
    frames = [resample(np.loadtxt(f, delimiter=",", skiprows=1), 250) for f in files]
    lines = []
    default = mm.TrackOptions().reference
    for ref in ("first", "previous"):  # frame 0's model reused, then frame to frame
        wall, cpu, result = timed(lambda ref=ref: mm.track(frames, reference=ref), repeat)
        steps = np.mean([r.steps for r in result.morphs])
        lines.append(f"track: {len(frames)} frames of 250 nodes (SC-HF-NI-03), "
                     f"reference={ref!r}{' (default)' * (ref == default)}: "
                     f"wall {wall:.3f} s, CPU {cpu:.3f} s (best of {repeat}), "
                     f"{steps:.1f} steps/frame")
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="*", default=[70, 250, 1000])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--families", nargs="*", default=["hearts", "hands", "glyphs"])
    parser.add_argument("--chars", default=CHARS)
    parser.add_argument("--reference", type=int, default=0, metavar="K",
                        help="time the dense transcription on the first K pairs per family")
    parser.add_argument("--track", action="store_true")
    parser.add_argument("--tuned", action="store_true",
                        help="tune glibc's allocator first, as the command line does "
                        "(modalmorph.threads.tune_allocator); default: the library's")
    args = parser.parse_args(argv)
    tuned = args.tuned and mm.threads.tune_allocator()
    print(f"# {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"numpy {np.__version__}, modalmorph {mm.__version__}, best of {args.repeat}; "
          f"allocator {'tuned' if tuned else 'as the library leaves it'}; "
          f"load average {os.getloadavg()[0]:.1f}")
    families = corpus(args.chars)
    print(f"{'family':>7} {'nodes':>5} {'pairs':>5} {'fail':>4}  {'wall med':>8} "
          f"{'wall p90':>8} {'wall max':>8}  {'CPU med':>8} {'CPU p90':>8} {'CPU max':>8}  "
          f"{'match med':>8} {'match max':>8}  {'ref/ours':>7} {'worst':>7}  {'faults':>7}")
    for n in args.sizes:
        for family in args.families:
            print(run_size(family, families[family], n, args.repeat, args.reference),
                  flush=True)
    if args.track:
        print(run_track(args.repeat))
    print(f"# load average at the end {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
