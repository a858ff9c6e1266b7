"""Strain of the myocardium on phantoms with analytic motion, and on the shared hearts.

For each phantom (:func:`modalmorph.phantoms.ring_phantom`: 30 frames of 128 x 128, LV 60
px across, an incompressible wall contracting 30 % of its endocardial radius; circular,
twisting, with an akinetic or hypokinetic sector, elliptical of aspect 1.15 and 1.3, and
circular in pixels of 1.5 x 0.8 mm, read from a NIfTI file: an ellipse in mm) the table
gives, per segment (0 = global), the truth at end-systole (the strain definitions applied
to the exact material motion), modalmorph's (:func:`modalmorph.strain`) and the baseline's
(nearest-point tracking: each node moves to the nearest point of the next frame's
contour), then the largest error of each over all frames, in percentage points, and the
errors of an exact tracking of the noisy boundaries (what the segmentation noise alone
leaves: the floor), of one ring track, and of the strain with nearest pairs (before the normal
correspondence). Then the time of one 30-frame sequence, and the endocardial
circumferential strain ED -> ES of the shared hearts (``--endo-only``).

``--modes``: every correspondence on every phantom (plain normals as before 2026-11-25,
normals of the wall made round: the default), worst errors and times. ``--frames``: the
error of the peaks with and without the smoothing over time, by frame count.

Run: ``OMP_NUM_THREADS=1 PYTHONPATH=src python benchmarks/strain.py [--noise 0.2]
[--modes] [--frames]``
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.spatial import cKDTree

from modalmorph import Shape, TrackOptions, cardiac, track
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
    "ellipse 1.15": dict(aspect=1.15),
    "ellipse 1.3": dict(aspect=1.3),
    "pixels 1.5 x 0.8 mm": dict(spacing=(1.5, 0.8)),  # a circle in pixels
}
MODES = ("nearest", "plain normal", "normal", "modal")
FRAME_COUNTS = (8, 10, 12, 14, 16, 20, 24, 30, 40)
TRUTH_NODES = (720, 4000)  # endocardial chords, epicardial nodes of the exact motion
HEARTS = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "heart"


def phantom(name: str, noise: float, frames: int = FRAMES, folder: str | None = None):
    """``(phantom, spacing, input)``: the named phantom, its pixel size, and what strain()
    reads (the masks, or a NIfTI file of them in ``folder`` for another pixel size)."""
    kw = dict(PHANTOMS[name])
    spacing = kw.pop("spacing", (1.0, 1.0))
    ph = ring_phantom(frames, noise=noise, **kw)
    if spacing == (1.0, 1.0):
        return ph, spacing, ph.masks
    import nibabel

    path = str(Path(folder or tempfile.mkdtemp()) / f"{name.split()[0]}.nii.gz")
    data = np.transpose(ph.masks, (2, 1, 0))[:, :, None, :].astype(np.int16)
    image = nibabel.Nifti1Image(data, np.diag([*spacing, 8.0, 1.0]))
    image.header.set_xyzt_units("mm", "sec")
    nibabel.save(image, path)
    return ph, spacing, path


def truth(ph, spacing=(1.0, 1.0)) -> dict:
    """The strain definitions applied to the exact material motion."""
    f = range(len(ph.masks))
    return wall_strain(*[np.array([ph.move(c, i) for i in f]) * spacing
                         for c in _circles(ph)])


def floor(ph, spacing=(1.0, 1.0)) -> dict:
    """The same of an exact tracking of the noisy boundaries (the material points of the
    truth moved off by the boundary noise along their ray), smoothed over time as
    strain() does: the error the segmentation noise (and the smoothing) alone leave."""
    f = range(len(ph.masks))
    walls = [np.array([ph.segmented(c, i, k) for i in f]) * spacing
             for k, c in enumerate(_circles(ph))]
    sigma = StrainOptions().smooth_frames
    if sigma and len(ph.masks) >= SMOOTH_MIN_FRAMES:
        walls = [gaussian_filter1d(w, sigma, axis=0, mode="nearest") for w in walls]
    return wall_strain(*walls)


def _circles(ph):
    """Dense material points of the endocardium and epicardium at the reference."""
    return ph.wall(ph.inner, TRUTH_NODES[0]), ph.wall(ph.outer, TRUTH_NODES[1])


def baseline(ph, nodes: int, spacing=(1.0, 1.0)) -> dict:
    """Nearest-point tracking: frame to frame, each node to the nearest point of the next
    frame's contour (resampled densely), then the same definitions."""
    rings = [mask_ring(m, f"frame {i}", spacing=spacing) for i, m in enumerate(ph.masks)]
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


def ring_track(ph, nodes: int, spacing=(1.0, 1.0)) -> dict:
    """The alternative to strain()'s contour-by-contour tracking: one track of the ring
    (one FE model over both contours, each matched with its partner), same inputs and
    options (without the smoothing over time, nor the rounding)."""
    rings = [mask_ring(m, f"frame {i}", spacing=spacing) for i, m in enumerate(ph.masks)]
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
    folder = tempfile.mkdtemp()
    for name, kw in PHANTOMS.items():
        ph, spacing, frames = phantom(name, noise, folder=folder)
        nodes = StrainOptions().nodes
        tr, base, best = truth(ph, spacing), baseline(ph, nodes, spacing), floor(ph, spacing)
        got, ring = strain(frames), ring_track(ph, nodes, spacing)
        before = strain(frames, correspondence="nearest", smooth_frames=0.0,
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


def modes(noise: float) -> None:
    """Every correspondence on every phantom: worst errors over the frames (points)."""
    print(f"correspondences, boundary noise {noise} px: largest error over all frames "
          f"(points), global / worst segment; time of the sequence")
    print(f"{'phantom':<20} {'correspondence':<14} {'circumferential':>16} "
          f"{'radial':>14} {'endocardial':>14} {'time s':>7}")
    folder = tempfile.mkdtemp()
    for name in PHANTOMS:
        ph, spacing, frames = phantom(name, noise, folder=folder)
        tr = truth(ph, spacing)
        for mode in MODES:
            cardiac.ROUNDING = mode != "plain normal"
            start = time.perf_counter()
            got = strain(frames, correspondence=mode.split()[-1])
            seconds = time.perf_counter() - start
            cardiac.ROUNDING = True
            cells = []
            for kind in ("circumferential", "radial", "circumferential_endo"):
                e = np.abs(getattr(got, kind) - tr[kind]).max(axis=0)
                cells.append(f"{e[0]:6.2f} / {e[1:].max():5.2f}")
            print(f"{name:<20} {mode:<14} {cells[0]:>16} {cells[1]:>14} {cells[2]:>14} "
                  f"{seconds:7.2f}")


def frame_counts(noise: float) -> None:
    """Error of the global peaks, smoothed (sigma 1 frame) or not, by frame count."""
    print(f"\nsmoothing over time by frame count (contracting phantom, noise {noise} px): "
          f"error of the global peak (points) and worst segment error over all frames")
    print(f"{'frames':>6} {'smoothing':>9} {'radial peak':>11} {'worst seg':>9} "
          f"{'circ peak':>9} {'worst seg':>9}")
    for count in FRAME_COUNTS:
        ph = ring_phantom(count, noise=noise, seed=1)
        tr = truth(ph)
        for sigma in (0.0, 1.0):
            cardiac.SMOOTH_MIN_FRAMES = 2  # every count, to measure
            got = strain(ph.masks, smooth_frames=sigma)
            cardiac.SMOOTH_MIN_FRAMES = SMOOTH_MIN_FRAMES
            cells = []
            for kind in ("radial", "circumferential"):
                t = tr[kind]
                peak = got.peak(kind)[0][0] - t[np.abs(t[:, 0]).argmax(), 0]
                cells.append(f"{peak:+11.2f} {np.abs(getattr(got, kind) - t)[:, 1:].max():9.2f}")
            print(f"{count:>6} {sigma:>9g} {cells[0]} {cells[1]}")


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
    parser.add_argument("--modes", action="store_true",
                        help="only the correspondences' table (every phantom)")
    parser.add_argument("--frames", action="store_true",
                        help="only the smoothing's table by frame count")
    args = parser.parse_args()
    if args.modes or args.frames:
        for level in args.noise:
            if args.modes:
                modes(level)
            if args.frames:
                frame_counts(level)
            print()
    else:
        for level in args.noise:
            table(level)
            print()
        timing()
        hearts()
