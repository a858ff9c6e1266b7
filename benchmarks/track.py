"""``track``'s reference, ``"previous"`` against ``"first"``, on a broad corpus of sequences.

Families (each sequence tracked with both references in one run, default options else):

- ``synthetic``: the bundled end-diastole heart deformed by a smooth periodic field over
  20 frames, each frame resampled to another node count from another start
  (tests/test_track.py), at ``--sizes`` nodes; truth known at every frame.
- ``demo``: the 12-frame cycle of ``examples/plot_track.py`` (80-90 nodes); truth known.
- ``glyphs``, ``horse``: outlines of ``GHSk&`` (DejaVu Sans) and scikit-image's horse,
  warped progressively by a smooth field and turned progressively up to ``TURNS`` degrees
  over 20 frames, every frame resampled to another node count from another start, at
  ``--sizes`` nodes; truth known at every frame.
- ``ed-es-ed``: the 15 same-slice ED -> ES -> ED cycles of the shared Sunnybrook hearts
  and the demo pair, nodes as drawn; truth known at the return (frame 2 is frame 0).
- ``sc-hf-ni-03``: that patient's 20 contours in file order at 250 nodes, ``cycle=True``.
- ``pressure``: every part of jiku-data's stance phases (subjects 0-2, trials 0 and 30,
  25 Hz) that ``stance()`` follows through 4 frames or more, its boundary per frame
  resampled at half a sensor, the first 20 frames (optional dependency: skipped when
  jiku-data is absent).

Columns (per family and reference): ``seq`` sequences, ``nodes`` their frame 0 node
counts, ``cpu s`` median CPU seconds of one ``track`` call, ``err med`` / ``err max``
node error against the truth in frame 0's mean node spacing (median and worst over every
node of every frame with a truth), ``closure`` median / worst ``closure_error`` in
spacings (``cycle=True`` families), ``fit max`` the worst two-way distance of a tracked
frame to its contour in spacings, ``crossed`` frames whose tracked contour crosses
itself, ``conv`` converged morphs / morphs, ``failed`` sequences that raised,
``redone`` frames (2 and later) of ``"first"`` morphed from the previous frame instead
(``Track.source_frame``), ``warned`` frames where neither morph passed (a warning).

Run from the repository root, single-threaded BLAS for comparable numbers:

    OMP_NUM_THREADS=1 PYTHONPATH=src:tests:benchmarks python benchmarks/track.py
    ... --families synthetic glyphs --sizes 70 250
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np
from realdata import DATA, glyph_outline, heart_pairs, horse_contour
from test_track import FRAMES, synthetic_sequence

from modalmorph import track
from modalmorph.core.shape import resample

REFERENCES = ("previous", "first")
FAMILIES = ("synthetic", "demo", "glyphs", "horse", "ed-es-ed", "sc-hf-ni-03", "pressure")
TURNS = (0.0, 90.0, 180.0)  # degrees turned over the sequence
WARP = 0.12  # amplitude of the smooth warp at the last frame, fraction of the RMS radius
CHARS = "GHSk&"
DENSE = 4000  # nodes of the dense outline each frame is resampled from
SEED = 20050328


def rms_radius(p):
    return float(np.sqrt(((p - p.mean(axis=0)) ** 2).sum(axis=1).mean()))


def warp(points, s, centre, size, turn, seed=SEED):
    """The map of frame ``s`` (0..1 along the sequence): a smooth field (two sine waves of
    wavelength 4 RMS radii, amplitude ``s * WARP``) then a turn by ``s * turn`` degrees,
    about ``centre``."""
    rng = np.random.default_rng(seed)
    u = (points - centre) / size
    out = u.copy()
    for axis in range(2):
        a = rng.uniform(0, 2 * np.pi)
        k = 2 * np.pi / 4 * np.array([np.cos(a), np.sin(a)])
        out[:, axis] += s * WARP * np.sin(u @ k + rng.uniform(0, 2 * np.pi))
    t = np.radians(s * turn)
    rot = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    return centre + size * out @ rot.T


def warped_sequence(outline, m, turn, rng):
    """(frames, truth (F, m, 2)): ``outline`` at ``m`` nodes, then FRAMES - 1 frames of
    the progressive map, each resampled to 0.7-1.4 m nodes from a random start."""
    dense = resample(outline, DENSE)
    centre, size = dense.mean(axis=0), rms_radius(dense)
    x0 = resample(outline, m)
    frames, truth = [x0], [x0]
    for f in range(1, FRAMES):
        s = f / (FRAMES - 1)
        n = int(rng.integers(int(0.7 * m), int(1.4 * m)))
        curve = np.roll(warp(dense, s, centre, size, turn), rng.integers(DENSE), axis=0)
        frames.append(resample(curve, n))
        truth.append(warp(x0, s, centre, size, turn))
    return frames, np.array(truth)


def demo_sequence():
    """examples/plot_track.py's 12 frames and the truth of frame 0's nodes."""
    from modalmorph.datasets import load_heart

    heart = resample(load_heart("diastole"), 90)
    centre, low, span = heart.mean(0), heart[:, 1].min(), np.ptp(heart[:, 1])

    def squeeze(p, f):
        along = (p[:, 1] - low) / span
        return centre + (p - centre) * (1 - 0.25 * np.sin(np.pi * f / 11) ** 2
                                        * (0.6 + 0.4 * along))[:, None]

    frames = [np.roll(resample(squeeze(heart, f), 80 + f % 3 * 5), 7 * f, axis=0)
              for f in range(12)]
    return frames, np.array([squeeze(frames[0], f) for f in range(12)])


def sequences(family, sizes):
    """(group, name, frames, truth or None, cycle): truth (F, m, 2), NaN where unknown."""
    rng = np.random.default_rng(SEED)
    if family == "synthetic":
        for m in sizes:
            frames, truth, _ = synthetic_sequence(m, rng)
            yield f"synthetic@{m}", f"heart field @{m}", frames, truth, False
    elif family == "demo":
        frames, truth = demo_sequence()
        yield family, "plot_track", frames, truth, True
    elif family in ("glyphs", "horse"):
        outlines = [(c, glyph_outline(c, "DejaVu Sans")) for c in CHARS] \
            if family == "glyphs" else [("horse", horse_contour())]
        for m in sizes:
            for name, outline in outlines:
                for turn in TURNS:
                    frames, truth = warped_sequence(outline, m, turn, rng)
                    yield (f"{family}@{m} {turn:g}deg", f"{name} {turn:g}deg @{m}", frames,
                           truth, False)
    elif family == "ed-es-ed":
        for name, ed, es in heart_pairs(DATA):
            truth = np.full((3, *ed.shape), np.nan)
            truth[2] = ed  # the return: ED resampled on its own, frame 0's nodes on it
            back = np.roll(resample(ed, int(rng.integers(int(0.7 * len(ed)), int(1.4 * len(ed))))),
                           rng.integers(len(ed)), axis=0)
            yield family, name, [ed, es, back], truth, False
    elif family == "sc-hf-ni-03":
        files = sorted((DATA / "heart").glob("SC-HF-NI-03-*.csv"))
        frames = [resample(np.loadtxt(f, delimiter=",", skiprows=1), 250) for f in files]
        yield family, "SC-HF-NI-03 @250", frames, None, True
    elif family == "pressure":
        yield from pressure_sequences()


def pressure_sequences(subjects=(0, 1, 2), trials=(0, 30), least=4, spacing=0.5):
    """Each part of a stance phase followed by ``stance()`` through ``least`` frames or
    more: its observed boundaries, resampled every ``spacing`` sensors."""
    try:
        from modalmorph.io.pressure import jiku_trial
        from modalmorph.pedobarography import stance
        trial = jiku_trial(subjects[0], trials[0], every=20)
    except ImportError:
        print("# pressure: jiku-data not installed, skipped")
        return
    for s in subjects:
        for t in trials:
            trial = jiku_trial(s, t, every=20)
            result = stance(trial)
            for p in result.parts:
                if len(p.frames) < least:
                    continue
                contours = [result.observed[f].contours[q - 1]
                            for f, q in zip(p.frames, p.labels, strict=True)][:FRAMES]
                frames = [resample(c, max(8, int(np.ceil(perimeter(c) / spacing))))
                          for c in contours]
                yield "pressure", f"s{s} t{t} part {p.part}", frames, None, False


def perimeter(p):
    return float(np.linalg.norm(np.diff(p, axis=0, append=p[:1]), axis=1).sum())


def measure(frames, truth, cycle, reference, correspondence="nearest"):
    """One track: CPU seconds and its numbers in frame 0's mean node spacing."""
    spacing = np.linalg.norm(np.diff(frames[0], axis=0, append=frames[0][:1]),
                             axis=1).mean()
    start = time.process_time()
    try:
        with warnings.catch_warnings(record=True) as said:
            warnings.simplefilter("always")
            result = track(frames, reference=reference, cycle=cycle,
                           correspondence=correspondence)
    except ValueError as exc:
        return dict(failed=1, error=str(exc).splitlines()[0])
    seconds = time.process_time() - start
    err = np.linalg.norm(result.points - truth, axis=2) / spacing if truth is not None \
        else np.full(1, np.nan)
    return dict(failed=0, seconds=seconds, nodes=result.points.shape[1],
                err=err[np.isfinite(err)],
                closure=result.closure_error / spacing if cycle else np.nan,
                fit=float(result.distance.max() / spacing),
                crossed=int(result.crossed.sum()),
                conv=sum(r.converged for r in result.morphs), morphs=len(result.morphs),
                redone=int(np.sum(result.source_frame[2:] != 0)) if reference == "first" else 0,
                warned=sum(issubclass(w.category, UserWarning) for w in said))


def pair(values, fmt="{:.2f}"):
    """'median / max' of ``values``, '-' for none."""
    return (fmt.format(np.median(values)) + " / " + fmt.format(np.max(values))) \
        if len(values) else "-"


def row(family, reference, runs):
    ok = [r for r in runs if not r["failed"]]
    err = np.concatenate([r["err"] for r in ok]) if ok else np.zeros(0)
    closure = [r["closure"] for r in ok if np.isfinite(r["closure"])]
    nodes = sorted({r["nodes"] for r in ok})
    nodes = f"{nodes[0]}-{nodes[-1]}" if len(nodes) > 1 else (str(nodes[0]) if nodes else "-")

    return (f"{family:<18} {reference:<9} {len(runs):>4} {nodes:>9} "
            f"{np.median([r['seconds'] for r in ok]) if ok else np.nan:>7.3f} "
            f"{pair(err):>13} {pair(closure):>13} "
            f"{max((r['fit'] for r in ok), default=np.nan):>7.2f} "
            f"{sum(r['crossed'] for r in ok):>7} "
            f"{sum(r['conv'] for r in ok):>5}/{sum(r['morphs'] for r in ok):<5} "
            f"{sum(r['failed'] for r in runs):>6} {sum(r['redone'] for r in ok):>6} "
            f"{sum(r['warned'] for r in ok):>6}")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--families", nargs="*", default=list(FAMILIES), choices=FAMILIES)
    parser.add_argument("--sizes", nargs="*", type=int, default=[70, 250, 1000])
    parser.add_argument("--references", nargs="*", default=list(REFERENCES))
    parser.add_argument("--correspondence", default="nearest",
                        help="track's correspondence (default: track's default)")
    parser.add_argument("--verbose", action="store_true", help="a line per sequence")
    args = parser.parse_args(argv)
    print(f"{'family':<18} {'reference':<9} {'seq':>4} {'nodes':>9} {'cpu s':>7} "
          f"{'err med/max':>13} {'closure':>13} {'fit max':>7} {'crossed':>7} "
          f"{'conv':>11} {'failed':>6} {'redone':>6} {'warned':>6}", flush=True)
    for family in args.families:
        runs = {}
        for group, name, frames, truth, cycle in sequences(family, args.sizes):
            for ref in args.references:
                r = measure(frames, truth, cycle, ref, args.correspondence)
                runs.setdefault(group, {}).setdefault(ref, []).append(r)
                if args.verbose:
                    print(f"#   {name:<24} {ref:<9} " + (
                        r["error"] if r["failed"] else
                        f"{r['seconds']:.3f} s err {pair(r['err'])} "
                        f"closure {r['closure']:.2f} fit {r['fit']:.2f} "
                        f"crossed {r['crossed']} conv {r['conv']}/{r['morphs']} "
                        f"redone {r['redone']} warned {r['warned']}"), flush=True)
        for group, by_ref in runs.items():
            for ref, rs in by_ref.items():
                print(row(group, ref, rs), flush=True)


if __name__ == "__main__":
    main()
