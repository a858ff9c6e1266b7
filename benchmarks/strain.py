"""Strain of the myocardium on phantoms with analytic motion, and on the shared hearts.

For each phantom (:func:`modalmorph.phantoms.ring_phantom`: 30 frames of 128 x 128, LV 60
px across, an incompressible wall contracting 30 % of its endocardial radius) the table
gives, per segment (0 = global), the truth at end-systole (the strain definitions applied
to the exact material motion), modalmorph's (:func:`modalmorph.strain`) and the baseline's
(nearest-point tracking: each node moves to the nearest point of the next frame's
contour), then the largest error of each over all frames, in percentage points, and the
errors of an exact tracking of the noisy boundaries (what the segmentation noise alone
leaves: the floor), of one ring track, and of the strain with nearest pairs (before the normal
correspondence). Then the time of one 30-frame sequence, and the endocardial
circumferential strain ED -> ES of the shared hearts (``--endo-only``).

Run: ``OMP_NUM_THREADS=1 PYTHONPATH=src python benchmarks/strain.py [--noise 0.2]``
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.spatial import cKDTree

from modalmorph import Shape, TrackOptions, track
from modalmorph.cardiac import (
    DENSE,
    MORPH_TOL,
    SMOOTH_MIN_FRAMES,
    TRACK_REFERENCE,
    StrainOptions,
    mask_ring,
    strain,
    wall_strain,
)
from modalmorph.core.shape import resample
from modalmorph.phantoms import ring_phantom

FRAMES, ES = 30, 15
PHANTOMS = {
    "contract": {},
    "twist 10 deg": dict(twist=10.0),
    "akinetic 60-120": dict(sector=(60.0, 120.0, 0.0)),
    "hypokinetic 180-240": dict(sector=(180.0, 240.0, 0.5)),
}
TRUTH_NODES = (720, 4000)  # endocardial chords, epicardial nodes of the exact motion
HEARTS = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "heart"


def truth(ph) -> dict:
    """The strain definitions applied to the exact material motion."""
    f = range(len(ph.masks))
    return wall_strain(*[np.array([ph.move(c, i) for i in f]) for c in _circles(ph)])


def floor(ph) -> dict:
    """The same of an exact tracking of the noisy boundaries (the material points of the
    truth moved off by the boundary noise along their ray), smoothed over time as
    strain() does: the error the segmentation noise (and the smoothing) alone leave."""
    f = range(len(ph.masks))
    walls = [np.array([ph.segmented(c, i, k) for i in f]) for k, c in enumerate(_circles(ph))]
    sigma = StrainOptions().smooth_frames
    if sigma and len(ph.masks) >= SMOOTH_MIN_FRAMES:
        walls = [gaussian_filter1d(w, sigma, axis=0, mode="nearest") for w in walls]
    return wall_strain(*walls)


def _circles(ph):
    """Dense material points of the endocardium and epicardium at the reference."""
    def circle(radius, n):
        th = np.linspace(0, 2 * np.pi, n, endpoint=False)
        return ph.centre + radius * np.c_[np.cos(th), -np.sin(th)]
    return circle(ph.inner, TRUTH_NODES[0]), circle(ph.outer, TRUTH_NODES[1])


def baseline(ph, nodes: int) -> dict:
    """Nearest-point tracking: frame to frame, each node to the nearest point of the next
    frame's contour (resampled densely), then the same definitions."""
    rings = [mask_ring(m, f"frame {i}") for i, m in enumerate(ph.masks)]
    tracked = []
    for k in range(2):
        p = resample(rings[0][k], nodes)
        path = [p]
        for ring in rings[1:]:
            dense = resample(ring[k], 16 * nodes)
            p = dense[cKDTree(dense).query(p)[1]]
            path.append(p)
        tracked.append(np.array(path))
    return wall_strain(*tracked)


def ring_track(ph, nodes: int) -> dict:
    """The alternative to strain()'s contour-by-contour tracking: one track of the ring
    (one FE model over both contours, each matched with its partner), same inputs and
    options (without the smoothing over time)."""
    rings = [mask_ring(m, f"frame {i}") for i, m in enumerate(ph.masks)]
    shapes = []
    for f, (endo, epi) in enumerate(rings):
        n = nodes if f == 0 else DENSE * nodes
        shapes.append(Shape(np.vstack([resample(epi, n), resample(endo, n)]),
                            contours=(n, n)))
    options = TrackOptions(reference=TRACK_REFERENCE,
                           correspondence=StrainOptions().correspondence)
    points = track(shapes, options=options, morph_options=dict(tol=MORPH_TOL)).points
    return wall_strain(points[:, nodes:], points[:, :nodes])


def table(noise: float) -> None:
    print(f"phantoms: {FRAMES} frames of 128 x 128, boundary noise {noise} px; values at "
          f"end-systole (frame {ES}), errors = largest over all frames (points)")
    print(f"{'phantom':<20} {'kind':<6} {'seg':>3} {'truth':>7} {'mm':>7} {'base':>7} "
          f"{'err mm':>7} {'err base':>8}")
    for name, kw in PHANTOMS.items():
        ph = ring_phantom(FRAMES, noise=noise, **kw)
        tr, base, best = truth(ph), baseline(ph, StrainOptions().nodes), floor(ph)
        got, ring = strain(ph.masks), ring_track(ph, StrainOptions().nodes)
        before = strain(ph.masks, correspondence="nearest", smooth_frames=0.0,
                        morph_options={})  # the correspondence of track (until 2026-11)
        for kind in ("radial", "circumferential"):
            t, m, b = tr[kind], getattr(got, kind), base[kind]
            em, eb = np.abs(m - t).max(axis=0), np.abs(b - t).max(axis=0)
            for s in range(t.shape[1]):
                print(f"{name:<20} {kind[:6]:<6} {s:>3} {t[ES, s]:7.2f} {m[ES, s]:7.2f} "
                      f"{b[ES, s]:7.2f} {em[s]:7.2f} {eb[s]:8.2f}")
            print(f"{'':<20} {kind[:6]:<6} max error: global {em[0]:.2f} (baseline "
                  f"{eb[0]:.2f}), worst segment {em[1:].max():.2f} (baseline "
                  f"{eb[1:].max():.2f}); at the reference {np.abs(m[0]).max():.2g}")
            ef = np.abs(best[kind] - t).max(axis=0)
            print(f"{'':<20} {kind[:6]:<6} floor (exact tracking of the noisy boundaries, "
                  f"smoothed alike): global {ef[0]:.2f}, worst segment {ef[1:].max():.2f}")
            er = np.abs(ring[kind] - t).max(axis=0)
            print(f"{'':<20} {kind[:6]:<6} one ring track instead: global {er[0]:.2f}, "
                  f"worst segment {er[1:].max():.2f}")
            eb = np.abs(getattr(before, kind) - t).max(axis=0)
            print(f"{'':<20} {kind[:6]:<6} nearest pairs, no smoothing, morph tol 0.005: "
                  f"global {eb[0]:.2f}, worst segment {eb[1:].max():.2f}")
        if kw.get("sector"):
            weakest = 1 + int(np.argmin(np.abs(got.peak("circumferential")[0][1:])))
            truest = 1 + int(np.argmin(np.abs(tr["circumferential"][ES, 1:])))
            print(f"{'':<20} weakest segment by peak circumferential strain: {weakest} "
                  f"(truth {truest})")


def timing() -> None:
    ph = ring_phantom(FRAMES, noise=0.2)
    strain(ph.masks[:2])  # imports, first calls
    best = min(_seconds(ph.masks) for _ in range(3))
    print(f"\ntiming: {FRAMES} frames of 128 x 128 masks, {StrainOptions().nodes} nodes per "
          f"contour: {best:.2f} s (best of 3)")


def _seconds(masks) -> float:
    start = time.perf_counter()
    strain(masks)
    return time.perf_counter() - start


def hearts() -> None:
    """Endocardial circumferential strain ED -> ES of each shared heart slice (pairs of
    one slice: image numbers in one block of 20 phases; ED the larger area)."""
    if not HEARTS.is_dir():
        print(f"\nhearts: {HEARTS} not found")
        return
    patients = {}
    for path in sorted(HEARTS.glob("*.csv")):
        stem = path.stem.replace("-icontour-manual", "")
        patient, number = stem.rsplit("-", 1)
        patients.setdefault(patient, []).append((int(number), path))
    pairs = []
    for files in patients.values():
        if len(files) == 2:  # one ED/ES pair
            pairs.append([p for _, p in files])
            continue
        blocks = {}
        for number, path in files:
            blocks.setdefault((number - 1) // 20, []).append(path)
        pairs += [b for b in blocks.values() if len(b) == 2]
    print("\nhearts (endocardium only): global endocardial circumferential strain ED -> ES "
          "(the contours' perimeter ratio as a check; whether the tracked ES crosses itself)")
    for paths in pairs:
        shapes = [np.loadtxt(p, delimiter=",", skiprows=1) for p in paths]
        area = [abs(_area(s)) for s in shapes]
        if area[1] > area[0]:
            shapes, paths = shapes[::-1], paths[::-1]
        got = strain(shapes, endo_only=True)
        perimeter = [np.linalg.norm(np.roll(s, -1, axis=0) - s, axis=1).sum()
                     for s in shapes]
        print(f"  {paths[0].stem} -> {paths[1].stem}: "
              f"{got.circumferential_endo[1, 0]:+.1f} % (perimeters "
              f"{100 * (perimeter[1] / perimeter[0] - 1):+.1f} %"
              f"{', crossed' if got.tracks[0].crossed.any() else ''})")


def _area(p) -> float:
    return 0.5 * float(np.dot(p[:, 0], np.roll(p[:, 1], -1)) -
                       np.dot(p[:, 1], np.roll(p[:, 0], -1)))


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--noise", type=float, nargs="+", default=[0.0, 0.2],
                        help="boundary noise of the phantoms, px")
    args = parser.parse_args()
    for level in args.noise:
        table(level)
        print()
    timing()
    hearts()
