"""Myocardium phantoms with a known material motion, for validating strain.

A short-axis slice of the left-ventricle wall is a ring between the endocardium (radius
``inner``) and the epicardium (radius ``outer``) at end-diastole (frame 0). A material
point at reference polar position ``(R, Theta)`` around the centre moves at frame ``f`` to

    r = sqrt(R**2 + Ri(f, Theta)**2 - inner**2),    theta = Theta + twist(f),

where ``Ri(f, Theta) = inner * (1 - c(f) * k(Theta))`` is the endocardial radius: the
contraction ``c(f) = contraction * sin(pi f / (F - 1))**2`` (end-systole in the middle of
the sequence), scaled by the kinesis ``k`` of the material point's sector (1 normal, 0
akinetic, 0.5 hypokinetic, blended over ``blend`` degrees). ``r dr = R dR`` along every
ray: the wall is incompressible (its area is kept in every angular wedge), so it thickens
as it contracts. The twist is a rotation of the whole slice.

An elliptical ring (``aspect`` q > 1) is that circular ring seen through the area-keeping
stretch ``(x, y) -> (x sqrt(q), y / sqrt(q))`` about the centre: its walls are ellipses
(long axis along x, q times the short one) shrinking about the centre, every material
point moving along its ray from the centre, and the wall still incompressible (the
stretch keeps areas). Uniform contraction then gives every sector the same circumferential
strain (the truth's segments differ by under 0.5 points at q = 1.3).

The masks are rendered by mapping every pixel centre back to the reference ring (exact),
with a smooth random perturbation of both boundaries (``noise`` pixels, a few angular
harmonics, new each frame) standing for segmentation error. The truth is the same motion
applied to any reference material points: :meth:`RingPhantom.move`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

__all__ = ["RingPhantom", "ring_phantom"]

SIZE = 128  # image side, pixels: a clinical cine short-axis matrix (LV 50-70 px across)
NOISE_HARMONICS = 6  # angular harmonics of the boundary noise (a smooth, wavy edge)


@dataclass(frozen=True, repr=False)
class RingPhantom:
    """A myocardium ring moving with a known material motion (module docstring).

    Attributes
    ----------
    masks : ndarray of bool, shape (F, H, W)
        The rendered wall (True inside the myocardium), pixel ``[row, col]`` centred at
        ``(x, y) = (col, row)``.
    centre : ndarray, shape (2,)
        The ventricle's centre (x, y) in pixels.
    inner, outer : float
        Endocardial and epicardial radii at frame 0, pixels.
    contraction : ndarray, shape (F,)
        Fraction of the endocardial radius lost at each frame (normal segments).
    twist : ndarray, shape (F,)
        Rotation of the slice at each frame, radians (counterclockwise on the image).
    sector : tuple
        ``(start, stop, kinesis)``: an abnormal sector between two angles (degrees,
        counterclockwise on the image from +x) moving ``kinesis`` times as much, or ().
    blend : float
        Width (degrees) of the transition to the abnormal sector.
    waves : ndarray, shape (F, 2, 2, NOISE_HARMONICS) or None
        The boundary noise: per frame, for the endocardium then the epicardium, the
        amplitudes (pixels) and phases (turns) of its angular harmonics (None: none).
    aspect : float
        Long over short axis of the elliptical walls (1: circles; module docstring);
        ``inner`` and ``outer`` are then the radii of the circles the walls stretch.
    """

    masks: np.ndarray
    centre: np.ndarray
    inner: float
    outer: float
    contraction: np.ndarray
    twist: np.ndarray
    sector: tuple = ()
    blend: float = 30.0
    waves: np.ndarray | None = None
    aspect: float = 1.0

    def __repr__(self) -> str:
        n_frames, h, w = self.masks.shape
        return (f"RingPhantom({n_frames} frames of {h}x{w}, radii {self.inner:g}/"
                f"{self.outer:g} px, contraction {self.contraction.max():.0%})")

    def kinesis(self, theta: np.ndarray) -> np.ndarray:
        """Motion factor of material points at reference angles ``theta`` (radians)."""
        if not self.sector:
            return np.ones_like(theta)
        start, stop, k = self.sector
        mid, half = np.radians((start + stop) / 2), np.radians((stop - start) / 2)
        gap = np.abs(np.angle(np.exp(1j * (theta - mid)))) - half  # < 0 inside
        ramp = np.clip(0.5 - gap / np.radians(self.blend), 0.0, 1.0)
        return 1.0 - (1.0 - k) * ramp

    def segmented(self, points: np.ndarray, f: int, boundary: int) -> np.ndarray:
        """Reference material points of a boundary (0 endocardium, 1 epicardium) moved to
        frame ``f`` and off by that frame's boundary noise along their ray: where an
        exact tracking of the noisy masks' boundaries would put them."""
        moved = self.move(points, f)
        if self.waves is None:
            return moved
        d = self.unstretched(points)
        theta = np.arctan2(-d[:, 1], d[:, 0])
        a, phase = self.waves[f, boundary]
        k = np.arange(1, len(a) + 1)
        off = (a * np.cos(np.outer(theta, k) + 2 * np.pi * phase)).sum(axis=1)
        ray = moved - self.centre
        return moved + off[:, None] * ray / np.linalg.norm(ray, axis=1)[:, None]

    def move(self, points: np.ndarray, f: int) -> np.ndarray:
        """Reference material points (m, 2) of the wall at frame 0, moved to frame ``f``."""
        d = self.unstretched(points)
        big_r = np.hypot(d[:, 0], d[:, 1])
        theta = np.arctan2(-d[:, 1], d[:, 0])  # counterclockwise as the image is shown
        ri = self.inner * (1.0 - self.contraction[f] * self.kinesis(theta))
        r = np.sqrt(np.maximum(big_r ** 2 + ri ** 2 - self.inner ** 2, 0.0))
        angle = theta + self.twist[f]
        return self.centre + np.c_[r * np.cos(angle), -r * np.sin(angle)] * self._stretch

    def unstretched(self, points: np.ndarray) -> np.ndarray:
        """Points (m, 2) relative to the centre, in the circular ring's frame."""
        return (np.asarray(points, dtype=float) - self.centre) / self._stretch

    def wall(self, radius: float, n: int) -> np.ndarray:
        """``n`` reference material points (n, 2) of the wall at ``radius`` of the
        circular ring (``inner``: the endocardium, ``outer``: the epicardium)."""
        th = np.linspace(0, 2 * np.pi, n, endpoint=False)
        return self.centre + radius * np.c_[np.cos(th), -np.sin(th)] * self._stretch

    @property
    def _stretch(self) -> np.ndarray:
        return np.array([np.sqrt(self.aspect), 1.0 / np.sqrt(self.aspect)])


def ring_phantom(frames: int = 30, *, radii: tuple = (20.0, 30.0),
                 contraction: float = 0.3, twist: float = 0.0,
                 sector: tuple = (), noise: float = 0.0, seed: int = 0,
                 aspect: float = 1.0) -> RingPhantom:
    """A :class:`RingPhantom` rendered on :data:`SIZE` x :data:`SIZE` pixels.

    Parameters
    ----------
    frames : int
        Number of frames F (end-diastole at 0, end-systole at ``F // 2``).
    radii : (float, float)
        Endocardial and epicardial radii at end-diastole, pixels (clinical: LV 50-70 px
        across on a 128 x 128 cine slice).
    contraction : float
        Fraction of the endocardial radius lost at end-systole.
    twist : float
        Rotation of the slice at end-systole, degrees (counterclockwise on the image).
    sector : tuple
        ``(start, stop, kinesis)`` of an abnormal sector (degrees), or ().
    noise : float
        Standard deviation of the boundary perturbation, pixels.
    seed : int
        Seed of the noise.
    aspect : float
        Long (x) over short (y) axis of the walls (1: circles).
    """
    size = SIZE  # the ring is centred, a quarter pixel off the grid
    inner, outer = radii
    t = np.sin(np.pi * np.arange(frames) / max(frames - 1, 1)) ** 2
    centre = np.array([size / 2 - 0.25, size / 2 + 0.25])
    ph = RingPhantom(masks=np.zeros((frames, size, size), dtype=bool), centre=centre,
                     inner=float(inner), outer=float(outer), contraction=contraction * t,
                     twist=np.radians(twist) * t, sector=tuple(sector),
                     aspect=float(aspect))
    rng = np.random.default_rng(seed)
    waves = np.array([[_waves(rng, noise) for _ in range(2)] for _ in range(frames)]) \
        if noise > 0 else None
    ph = replace(ph, waves=waves)
    rows, cols = np.mgrid[0:size, 0:size]
    d = ph.unstretched(np.c_[cols.ravel(), rows.ravel()])
    r2 = (d ** 2).sum(axis=1)
    angle = np.arctan2(-d[:, 1], d[:, 0])
    k = np.arange(1, NOISE_HARMONICS + 1)
    for f in range(frames):
        theta = angle - ph.twist[f]  # the reference angle of the material at each pixel
        ri = inner * (1.0 - ph.contraction[f] * ph.kinesis(theta))
        lo, hi = ri, np.sqrt(ri ** 2 + outer ** 2 - inner ** 2)
        if waves is not None:  # a smooth, wavy edge
            lo, hi = (r + (a * np.cos(np.outer(theta, k) + 2 * np.pi * phase)).sum(axis=1)
                      for r, (a, phase) in zip((lo, hi), waves[f], strict=True))
        ph.masks[f] = ((r2 >= lo ** 2) & (r2 <= hi ** 2)).reshape(size, size)
    return ph


def _waves(rng, noise: float) -> np.ndarray:
    """Amplitudes and phases (2, NOISE_HARMONICS) of a smooth random boundary offset of
    standard deviation ``noise`` (pixels)."""
    a, phase = rng.normal(size=(2, NOISE_HARMONICS))
    a *= noise * np.sqrt(2.0 / (a ** 2).sum())  # rms of sum a_k cos(.) is |a| / sqrt(2)
    return np.array([a, phase])
