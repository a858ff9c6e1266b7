"""Real shapes bundled with modalmorph (see ``data/README.md`` for origin and licences)."""

from __future__ import annotations

from importlib import resources

import numpy as np

from .core.shape import ImageFrame, Shape, resample

__all__ = ["load_hand", "load_hands", "load_heart", "data_path", "hand_shape", "heart_shape",
           "PIXELS"]

# The bundled outlines were traced on images: pixel coordinates, y pointing down.
PIXELS = ImageFrame(unit="px")

_HEART = {
    "diastole": "SC-HF-I-07-IM-0001-0080-icontour-manual.csv",
    "systole": "SC-HF-I-07-IM-0001-0087-icontour-manual.csv",
}


def data_path(*parts: str):
    """Path of a bundled data file, e.g. ``data_path("hands", "hand-0.csv")``."""
    return resources.files("modalmorph").joinpath("data", *parts)


def _read(path) -> np.ndarray:
    with path.open("r") as fh:
        return np.loadtxt(fh, delimiter=",", skiprows=1)


def load_hand(i: int = 0) -> np.ndarray:
    """Outline of hand ``i`` (0-7), shape (1590, 2), in pixels.

    Row ``r`` is the same anatomical point in every hand (ground truth for matching).
    From the statismo project, University of Basel, BSD-3-Clause.
    """
    if i not in range(8):
        raise ValueError(f"hand index must be 0-7, got {i}")
    return _read(data_path("hands", f"hand-{i}.csv"))


def load_hands(indices=(0, 3), n: int = 1590) -> list[np.ndarray]:
    """Several hands sampled at the same ``n`` contour parameters, each (n, 2).

    Rows are interpolated linearly between the 1590 bundled rows, so row ``r`` of every
    returned hand is still the same anatomical point: ground truth for matching and
    morphing at any node count.
    """
    s = np.linspace(0, 1590, n, endpoint=False)
    i = np.floor(s).astype(int)
    f = (s - i)[:, None]
    nxt = (i + 1) % 1590
    return [h[i] * (1 - f) + h[nxt] * f for h in map(load_hand, indices)]


def load_heart(phase: str = "diastole") -> np.ndarray:
    """Left-ventricle endocardial contour at ``"diastole"`` (247 nodes) or ``"systole"``
    (180 nodes), in pixels. Sunnybrook Cardiac Data (Radau et al. 2009), CC0 1.0."""
    if phase not in _HEART:
        raise ValueError(f"phase must be 'diastole' or 'systole', got {phase!r}")
    return _read(data_path("heart", _HEART[phase]))


def heart_shape(phase: str = "diastole") -> Shape:
    """:func:`load_heart` as a closed :class:`~modalmorph.Shape` in image coordinates
    (:data:`PIXELS`: figures draw it with y down, as on the MRI slice)."""
    return Shape(load_heart(phase), frame=PIXELS)


def hand_shape(i: int = 0, nodes: int | None = None) -> Shape:
    """:func:`load_hand` as a closed :class:`~modalmorph.Shape` in image coordinates,
    resampled to ``nodes`` nodes evenly by arc length if given."""
    points = load_hand(i)
    return Shape(points if nodes is None else resample(points, nodes), frame=PIXELS)
