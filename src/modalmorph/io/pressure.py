"""Pressure images and stacks (pedobarography): the loaded parts of each frame, with
sub-sensor boundaries.

A pressure array is (H, W) (a peak-pressure image) or (T, H, W) (a stance phase), one
value per sensor, in the plate's units. A sensor is *loaded* above a level: a threshold in
the array's units, or a fraction of the stack's peak (:func:`pressure_level`). The loaded
*parts* of a frame are the 4-connected regions of sensors above the level on the lightly
smoothed field (:data:`SMOOTH_SENSORS`); each part's boundary is the iso-line of that
field at the level, by marching squares (:func:`skimage.measure.find_contours`), so it
runs between sensors where the pressure crosses the level and not along the sensors'
edges. Coordinates are ``(x, y) = (column, row) * pixel_size`` (y down the rows, as
images), in mm when ``pixel_size`` is the sensor pitch in mm.

Files: NPY (one array) and NPZ (the array named ``pressure``, else the first), by
:func:`read_pressure`. The public data of Pataky et al. (2008) (PyPI ``jiku-data``,
GPL-3, an optional dependency never copied here) by :func:`jiku_trial` and
:func:`jiku_peaks`: 10 subjects x 3 walking speeds x 20 trials on a 500 Hz plate.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.quality import area
from ..errors import InputFileError, OptionError

__all__ = ["JIKU_RATE", "SMOOTH_SENSORS", "FrameParts", "check_pressure", "frame_parts",
           "jiku_conditions", "jiku_peaks", "jiku_trial", "pressure_level", "read_pressure"]

# Gaussian width (sensors) of the smoothing before the iso-line: a light one that rounds
# the sensors' quantisation without moving the boundary far: on 60 real stance phases of
# jiku-data (10 subjects, 25 Hz) the tracked nodes on the smoothed field's iso-line lie
# within 0.80 sensor of the raw field's (benchmarks/pedobarography.py, column raw).
SMOOTH_SENSORS = 0.5
JIKU_RATE = 500.0  # Hz, the plate of Pataky et al. (2008) (jiku-data's README)
_JIKU = "SpeedPP2DS"  # jiku-data's time series; SpeedPP2D holds the peak images


@dataclass(frozen=True)
class FrameParts:
    """The loaded parts of one pressure frame.

    Attributes
    ----------
    labels : ndarray of int, shape (H, W)
        Part of every sensor (1..P), 0 where unloaded (parts below ``min_sensors`` are 0).
    contours : tuple of ndarray (n_p, 2)
        The boundary of each part ``p + 1`` (closed, no repeated end, positive area in
        (x, y)), in ``pixel_size`` units.
    sensors : ndarray of int, shape (P,)
        Loaded sensors of each part.
    dropped : int
        Contacts smaller than ``min_sensors`` left out.
    """

    labels: np.ndarray
    contours: tuple
    sensors: np.ndarray
    dropped: int


def check_pressure(pressure, name: str = "pressure") -> np.ndarray:
    """The pressure as a float (T, H, W) array; an (H, W) image becomes one frame.
    Raises :class:`~modalmorph.errors.InputFileError` naming the first frame with a NaN
    or infinite value, and for anything but 2 or 3 axes."""
    array = np.asarray(pressure)
    if array.dtype.kind not in "iufb":
        raise InputFileError(f"{name}: pressure must be numeric, got dtype {array.dtype}")
    array = array.astype(np.float64)
    if array.ndim == 2:
        array = array[None]
    if array.ndim != 3 or min(array.shape) < 1:
        raise InputFileError(f"{name}: pressure must be an (H, W) image or a (T, H, W) "
                             f"stack, got shape {array.shape}")
    bad = ~np.isfinite(array).all(axis=(1, 2))
    if bad.any():
        f = int(np.argmax(bad))
        raise InputFileError(f"{name}: frame {f} has "
                             f"{np.count_nonzero(~np.isfinite(array[f]))} NaN or infinite "
                             f"values ({np.count_nonzero(bad)} such frames in all)")
    return array


def pressure_level(pressure: np.ndarray, *, threshold: float | None, fraction: float,
                   name: str = "pressure") -> float:
    """The level above which a sensor is loaded: ``threshold`` (array units), else
    ``fraction`` of the stack's peak. Raises InputFileError for a stack with no pressure
    and for a threshold at or above every value (naming the peak's frame)."""
    peak = float(pressure.max())
    if peak <= 0:
        low = float(pressure.min())
        values = f"is {peak + 0.0:g}" if low == peak else f"lies in {low:g} .. {peak + 0.0:g}"
        raise InputFileError(f"{name}: every value of the {len(pressure)} frame(s) {values}: "
                             "nothing is loaded (pressure is positive where loaded)")
    level = fraction * peak if threshold is None else float(threshold)
    if level >= peak:
        f = int(np.argmax(pressure.max(axis=(1, 2))))
        raise InputFileError(f"{name}: threshold {level:g} is at or above every value (the "
                             f"peak, {peak:g}, is in frame {f}): nothing is loaded")
    return level


def frame_parts(frame: np.ndarray, level: float, *, pixel_size: float = 1.0,
                smooth: float = SMOOTH_SENSORS, min_sensors: int = 2,
                regions: np.ndarray | None = None) -> FrameParts:
    """The loaded parts of one (H, W) frame and their sub-sensor boundaries.

    Parameters
    ----------
    frame : ndarray, shape (H, W)
        Pressure, array units.
    level : float
        Loaded above this (:func:`pressure_level`).
    pixel_size : float, optional
        Sensor pitch: the unit of the contours (mm per sensor).
    smooth : float, optional
        Gaussian width of the smoothing, sensors (0: none).
    min_sensors : int, optional
        Smaller contacts (a single loaded sensor) are left out and counted in ``dropped``.
    regions : ndarray of int, shape (H, W), optional
        Regions (anatomical masks) that cut the parts: a part lies in one region.

    Returns
    -------
    FrameParts
    """
    from scipy import ndimage
    from skimage.measure import find_contours

    field = ndimage.gaussian_filter(frame, smooth, mode="constant") if smooth > 0 else frame
    loaded = field > level
    below = min(0.0, level - 1.0)
    labels, count = ndimage.label(loaded)  # 4-connected: marching squares' sides
    if regions is not None:
        labels, count = np.zeros_like(labels), 0
        for r in np.unique(regions):
            lab, n = ndimage.label(loaded & (regions == r))
            labels[lab > 0] = lab[lab > 0] + count
            count += n
    # a part's size counts the sensors loaded in the frame itself: the smoothing spreads a
    # single loaded sensor over its neighbours, and that contact is still one sensor
    sizes = np.bincount(labels[frame > level], minlength=count + 1)[1:]
    keep = np.flatnonzero(sizes >= min_sensors) + 1
    relabel = np.zeros(count + 1, dtype=np.intp)
    relabel[keep] = np.arange(1, len(keep) + 1)
    labels = relabel[labels]
    contours = []
    for p in range(1, len(keep) + 1):
        # the other parts lowered below the level: only part p crosses it, and the values
        # next to part p (all at or below the level) are the field's own
        alone = np.pad(np.where(loaded & (labels != p), below, field), 1,
                       constant_values=below)
        lines = find_contours(alone, level)
        outer = max(lines, key=lambda c: abs(area(c)))  # holes are left out
        pts = (outer[:-1, ::-1] - 1.0) * pixel_size  # (row, col) -> (x, y), unpadded
        contours.append(pts if area(pts) > 0 else pts[::-1])
    return FrameParts(labels=labels, contours=tuple(contours), sensors=sizes[keep - 1],
                      dropped=int(count - len(keep)))


def read_pressure(path) -> np.ndarray:
    """The array of an NPY file, or of an NPZ (``pressure``, else its first array), as a
    float (T, H, W) stack (:func:`check_pressure`)."""
    name = os.fspath(path)
    path = Path(path)
    if path.suffix.lower() not in (".npy", ".npz"):
        raise InputFileError(f"{name}: pressure files are NPY or NPZ arrays, got "
                             f"{path.suffix or 'no extension'!r}")
    try:
        if path.suffix.lower() == ".npy":
            array = np.load(path, allow_pickle=False)
        else:
            with np.load(path, allow_pickle=False) as data:
                array = data["pressure" if "pressure" in data else data.files[0]]
    except (OSError, ValueError, IndexError) as exc:
        raise InputFileError(f"{name}: cannot read the array: {exc}") from None
    return check_pressure(array, name)


def _jiku_file(dataset: str, subject: int) -> Path:
    try:
        import jikudata
    except ImportError:
        raise ImportError("the pressure data of Pataky et al. (2008) needs the optional "
                          "package jiku-data (GPL-3): pip install jiku-data") from None
    if not (isinstance(subject, int | np.integer) and 0 <= subject <= 9):
        raise OptionError(f"subject must be 0..9, got {subject!r}")
    return Path(jikudata.__file__).parent / "datasets" / dataset / "data_y" / \
        f"subj{subject:03d}.h5"


def jiku_trial(subject: int, trial: int, *, every: int = 1) -> np.ndarray:
    """One stance phase of jiku-data's ``SpeedPP2DS``: a float (T, H, W) stack (rows:
    the walking direction), its zero padding at the end removed, every ``every``-th frame
    of the 500 Hz plate (``every=20``: 25 Hz)."""
    import tables  # a dependency of jiku-data

    if not (isinstance(trial, int | np.integer) and 0 <= trial < 60):
        raise OptionError(f"trial must be 0..59, got {trial!r}")
    with tables.open_file(_jiku_file(_JIKU, subject), mode="r") as f:
        y = np.asarray(f.get_node(f"/img{trial:03d}").read())
    loaded = np.flatnonzero(y.any(axis=(0, 1)))
    stack = np.moveaxis(y[:, :, : loaded[-1] + 1], 2, 0).astype(np.float64)
    return stack[::every]


def jiku_peaks(subject: int) -> np.ndarray:
    """The 60 peak-pressure images (60, H, W) of one subject (jiku-data's ``SpeedPP2D``)."""
    import tables

    with tables.open_file(_jiku_file("SpeedPP2D", subject), mode="r") as f:
        return np.asarray(f.get_node("/y").read(), dtype=np.float64)


def jiku_conditions(subject: int) -> tuple[np.ndarray, np.ndarray]:
    """(speed condition 1 slow / 2 normal / 3 fast, walking speed m/s) of one subject's 60
    trials."""
    folder = _jiku_file(_JIKU, subject).parent.parent / "data_x"
    cond = np.loadtxt(folder / "conditions.csv", delimiter=",", skiprows=1, dtype=int)
    speed = np.loadtxt(folder / "speeds.csv", delimiter=",", skiprows=1)
    return cond[:, 1 + subject], speed[:, 1 + subject]
