"""How far tracked nodes slid along a closed 2D outline against frame 0.

Nodes that follow the material of an object that turns or slides along its outline keep
their places on it; nodes paired with the nearest points of each frame stay where they
were in the images and slide along the outline instead (``track``'s default
correspondence, "nearest"). The slide is the cyclic shift along the outline that, with
the best turn, fits a tracked frame to frame 0; it is said where the shift, not a change
of shape, explains why the nodes misfit frame 0's.
"""

from __future__ import annotations

import numpy as np

from .core.shape import Shape, resample

__all__ = ["SLIDE_FRACTION", "SLIDE_GAIN", "SLIDE_SAMPLES", "SLIDE_SPACINGS", "contour_slide",
           "outline_slides"]

# Slide of tracked nodes along a closed 2D contour (Track.slide, contour_slide): frame 0 and
# each tracked frame, resampled at SLIDE_SAMPLES points by arc length from node 0, are
# fitted by the best cyclic shift with its best turn (Procrustes over every shift, one
# FFT, the peak refined between samples by a parabola; under 1 ms a frame).
SLIDE_SAMPLES = 256
# A frame's nodes slid (Track.slid, a warning) where the best shift exceeds SLIDE_FRACTION
# of the outline and leaves at most SLIDE_GAIN of the misfit at no shift (1 - |c|^2 of
# the unit profiles). Measured with "nearest" (reference "first"),
# benchmarks/track_slide.py: in all 37 sequences of objects that turn (a star of unequal
# arms at 6 degrees a frame; a hand, an LV, 'G' and 'k' at 2, 6 and 15 degrees a frame;
# the glyphs and horse of benchmarks/track.py turned 90 or 180 degrees over 20 frames)
# some frame's shift leaves at most 0.012 of the misfit (median 0.002); in the 50 that do
# not turn (SC-HF-NI-03's 20 frames, 16 ED-ES-ED cycles, 17 pressure parts of jiku-data,
# hands 0-7, the synthetic and demo cycles, the unturned glyphs and horse; and a
# reviewer's breathing star and warped 'G') no frame shifted by more than SLIDE_FRACTION
# leaves less than 0.0295 (SC-HF-NI-03, a round LV that many shifts fit; next 0.068, a
# pressure part). SLIDE_GAIN lies between. SLIDE_FRACTION: 1.5 % of the outline, 1 to
# 3.75 node spacings at 70-250 nodes; turning 2 degrees a frame slid the nodes 2-6 % by
# the 12th frame, and the modal correspondence left a star turned by 6 degrees 1.2 %
# (2 spacings at 160 nodes; median node error 0.75 spacing) - not said.
SLIDE_FRACTION = 0.015
SLIDE_GAIN = 0.02
# ... and SLIDE_SPACINGS of the contour's mean node spacing: at 70 nodes the modal
# correspondence left unturned and turned glyphs 1.2-1.8 spacings (1.7-2.6 %) with a
# median node error of 0.2-0.8 spacing, within what a track follows; its slides of 2.5
# spacings and more (an LV turned 2-15 degrees a frame, 'G' turned 180) came with
# median node errors of 3-55 spacings (benchmarks/track_slide.py --correspondence modal).
SLIDE_SPACINGS = 2.0
# Misfits below this are rounding (a sum of 256 unit terms: about 256 float64 epsilons,
# 6e-14): every shift of a circle fits it as well, none is a slide.
SAME = 1e-12


def outline_slides(first: Shape, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``Track.slide`` and ``Track.slid``: per frame, the largest :func:`contour_slide` over
    the contours of frame 0 that explains their misfit (leaves at most
    :data:`SLIDE_GAIN` of it; else 0: a change of shape, such as a circle growing into an
    ellipse, is fitted by many shifts, none a slide), said beyond :data:`SLIDE_FRACTION`
    of the outline and :data:`SLIDE_SPACINGS` node spacings (closed 2D contours only;
    else NaN and False)."""
    n_frames = len(points)
    if first.dim != 2 or not first.closed or not first.ordered or first.faces is not None:
        return np.full(n_frames, np.nan), np.zeros(n_frames, dtype=bool)
    largest, slid = np.zeros(n_frames), np.zeros(n_frames, dtype=bool)
    for rows in first.slices:
        shift, gain = contour_slide(points[:, rows])
        shift = np.where(gain <= SLIDE_GAIN, shift, 0.0)
        said = np.abs(shift) > max(SLIDE_FRACTION, SLIDE_SPACINGS / len(points[0, rows]))
        larger = np.abs(shift) > np.abs(largest)
        largest[larger], slid = shift[larger], slid | said
    return largest, slid


def contour_slide(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The slide of one closed contour's tracked nodes (F, n, 2) along it against frame
    0, fraction of the outline (positive: forward in the node order), and the share of
    the misfit that shift leaves, ``d_k / d_0`` (1 where the frame fits frame 0 to
    rounding). Each frame and frame 0 are resampled at :data:`SLIDE_SAMPLES` points by
    arc length from node 0, centred and scaled to unit norm (complex ``z``); the fit of
    shift ``k`` with its best turn is ``|c_k|``, ``c_k = sum conj(z0[i]) z[i + k]``
    (every ``k`` by one FFT), its misfit ``d_k = 1 - |c_k|^2``. :func:`outline_slides`
    says a slide when the best shift exceeds :data:`SLIDE_FRACTION` of the outline and
    ``d_k <= SLIDE_GAIN d_0``: the shift, not a change of shape, explains why the nodes
    as they stand misfit frame 0's (the turn is free: nodes that follow an object that
    turns show no shift)."""
    z = np.array([_unit_profile(p) for p in points])
    spectra = np.fft.fft(z, axis=1)
    fit = np.abs(np.fft.ifft(spectra[:1].conj() * spectra, axis=1))  # (F, samples)
    best = np.argmax(fit, axis=1)
    rows = np.arange(len(z))
    d_best, d_zero = 1.0 - fit[rows, best] ** 2, 1.0 - fit[:, 0] ** 2
    before, after = fit[rows, best - 1], fit[rows, (best + 1) % SLIDE_SAMPLES]
    curve = before - 2 * fit[rows, best] + after  # the peak between samples (a parabola)
    between = np.where(curve < 0, 0.5 * (before - after) / np.where(curve < 0, curve, -1), 0)
    # node j sits where frame 0's j - k was: it moved -k along the node order
    shift = -((best + SLIDE_SAMPLES // 2) % SLIDE_SAMPLES - SLIDE_SAMPLES // 2 + between)
    gain = np.where(d_zero > SAME, d_best / np.maximum(d_zero, SAME), 1.0)
    return shift / SLIDE_SAMPLES, gain


def _unit_profile(points: np.ndarray) -> np.ndarray:
    """A closed contour resampled at :data:`SLIDE_SAMPLES` points by arc length from
    its first node, centred, as complex numbers of unit norm."""
    q = resample(points, SLIDE_SAMPLES)
    z = (q[:, 0] - q[:, 0].mean()) + 1j * (q[:, 1] - q[:, 1].mean())
    return z / max(np.linalg.norm(z), np.finfo(float).tiny)
