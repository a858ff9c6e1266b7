"""``Track.slid``: does ``track`` (defaults: "nearest", reference "first") say when its
frames turn, and stay silent when they do not? The measurement behind
``modalmorph.slide.SLIDE_FRACTION`` and ``SLIDE_GAIN``.

Sequences that turn: a star of 8 unequal arms drawn as masks turning 6 degrees a frame
(12 frames, as a reviewer's cell rolling); a hand, an LV, 'G' and 'k' (DejaVu Sans) at
200 nodes turned 2, 6 and 15 degrees a frame over 12 frames, each frame resampled to
another node count from another start; benchmarks/track.py's glyphs and horse turned 90
or 180 degrees over 20 frames. Sequences that do not turn: benchmarks/track.py's
synthetic, demo, ED-ES-ED, SC-HF-NI-03 and pressure families and its unturned glyphs and
horse; hands 0-7 of the shared data as a sequence.

Columns: ``seq`` sequences, ``said`` sequences with a frame said (``Track.slid``),
``frames`` frames said / frames, ``gain`` the smallest share of the misfit that the best
shift leaves among frames shifted by more than SLIDE_FRACTION (said at or below
SLIDE_GAIN), ``slide`` the largest ``|Track.slide|`` (fraction of the outline), ``err``
the median node error of the track against the truth in frame 0's node spacings (where
known), ``warned`` sequences with the warning.

    OMP_NUM_THREADS=1 PYTHONPATH=src:tests:benchmarks python benchmarks/track_slide.py
    ... --correspondence modal
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np
from realdata import DATA, glyph_outline
from skimage import draw, measure
from track import sequences

from modalmorph import track
from modalmorph.core.shape import resample
from modalmorph.slide import SLIDE_FRACTION, contour_slide

TURNING = ("star", "turn2", "turn6", "turn15", "glyphs", "horse")
STILL = ("synthetic", "demo", "ed-es-ed", "sc-hf-ni-03", "pressure", "hands", "glyphs",
         "horse")
ARMS = np.array([80, 40, 60, 40, 70, 35, 50, 40])  # the star's arm lengths, pixels


def turned(points, degrees, centre):
    t = np.radians(degrees)
    return (points - centre) @ np.array([[np.cos(t), np.sin(t)], [-np.sin(t), np.cos(t)]]) \
        + centre


def star_sequence():
    """12 masks of the star turning 6 degrees a frame, traced (skimage.measure)."""
    frames = []
    for f in range(12):
        angle = np.linspace(0, 2 * np.pi, 9)[:-1] + np.radians(6 * f)
        mask = np.zeros((200, 200), bool)
        mask[draw.polygon(100 + ARMS * np.sin(angle), 100 + ARMS * np.cos(angle),
                          mask.shape)] = True
        outline = max(measure.find_contours(mask.astype(float), 0.5), key=len)[:-1]
        frames.append(resample(outline[:, ::-1], 200))
    return frames


def turning_sequences(step):
    """(name, frames, truth) of four outlines turned ``step`` degrees a frame."""
    outlines = {"hand": np.loadtxt(DATA / "hands" / "hand-0.csv", delimiter=",",
                                   skiprows=1),
                "LV": np.loadtxt(DATA / "heart" / "SC-HF-NI-03-0009.csv", delimiter=",",
                                 skiprows=1),
                "G": glyph_outline("G", "DejaVu Sans"), "k": glyph_outline("k", "DejaVu Sans")}
    for name, outline in outlines.items():
        dense = resample(outline, 2000)
        centre = dense.mean(axis=0)
        frames = [np.roll(resample(turned(dense, step * f, centre), 180 + 7 * f), 11 * f,
                          axis=0) for f in range(12)]
        truth = np.array([turned(frames[0], step * f, centre) for f in range(12)])
        yield f"{name} {step:g}deg/frame", frames, truth


def family(name, turning):
    """(name, frames, truth or None) of one family."""
    if name == "star":
        yield "star 6deg/frame", star_sequence(), None
    elif name.startswith("turn"):
        yield from turning_sequences(float(name[4:]))
    elif name == "hands":
        yield "hands 0-7", [np.loadtxt(DATA / "hands" / f"hand-{i}.csv", delimiter=",",
                                       skiprows=1) for i in range(8)], None
    else:
        for group, label, frames, truth, _ in sequences(name, (70, 250)):
            if name not in ("glyphs", "horse") or group.endswith(" 0deg") != turning:
                yield label, frames, truth


def measure_one(frames, truth, correspondence):
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        result = track(frames, correspondence=correspondence)
    shift, gain = contour_slide(result.points)
    far = np.abs(shift) > SLIDE_FRACTION
    p = result.points[0]
    spacing = np.linalg.norm(np.diff(p, axis=0, append=p[:1]), axis=1).mean()
    err = np.nan if truth is None or truth.shape != result.points.shape else float(
        np.nanmedian(np.linalg.norm(result.points - truth, axis=2)) / spacing)
    return dict(said=bool(result.slid.any()), frames=int(result.slid.sum()),
                total=result.n_frames - 1, gain=gain[far].min() if far.any() else np.inf,
                slide=float(np.nanmax(np.abs(result.slide))), err=err,
                warned=any("slid along the outline" in str(w.message) for w in said))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--correspondence", default="nearest")
    correspondence = parser.parse_args().correspondence
    print(f"{'family':>12} {'turns':>5} {'seq':>4} {'said':>4} {'frames':>8} {'gain':>7} "
          f"{'slide':>6} {'err':>6} {'warned':>6}")
    for turning, names in ((True, TURNING), (False, STILL)):
        for name in names:
            rows = [measure_one(frames, truth, correspondence)
                    for _, frames, truth in family(name, turning)]
            if not rows:
                continue
            err = [r["err"] for r in rows if np.isfinite(r["err"])]
            print(f"{name:>12} {'yes' if turning else 'no':>5} {len(rows):4d} "
                  f"{sum(r['said'] for r in rows):4d} "
                  f"{sum(r['frames'] for r in rows):>3d}/{sum(r['total'] for r in rows):<4d} "
                  f"{(max if turning else min)(r['gain'] for r in rows):7.4f} "
                  f"{max(r['slide'] for r in rows):6.3f} "
                  f"{np.median(err) if err else np.nan:6.2f} "
                  f"{sum(r['warned'] for r in rows):6d}", flush=True)


if __name__ == "__main__":
    main()
