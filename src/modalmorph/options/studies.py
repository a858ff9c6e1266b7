"""The options of the studies built on the method: myocardial strain and pressure
plates."""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import OptionError
from .base import (
    CORRESPONDENCES,
    OBJECTS,
    Options,
    check_range,
    is_int,
    is_number,
    option,
)

__all__ = ['StrainOptions', 'StanceOptions']


@dataclass(frozen=True)
class StrainOptions(Options):
    """How :func:`modalmorph.strain` measures the wall of a myocardium sequence."""

    segments: int = option(
        6, "equal sectors by angle around the reference centre (6: the AHA mid-ventricular "
        "segments); segment 0 is the whole wall", group="strain", kind="int")
    reference_frame: int = option(
        0, "frame the strains are measured against (end-diastole)", group="strain",
        kind="int", flag="--reference")
    reference_angle: float = option(
        0.0, "where segment 1 starts, degrees counterclockwise from the image's +x axis as "
        "the image is shown (y down); segments follow counterclockwise", group="strain",
        kind="float")
    rv_point: tuple | None = option(
        None, "an RV insertion point x,y (image units) at the reference frame: segment 1 "
        "starts one segment clockwise of it (the AHA anterior segment, from the anterior "
        "insertion); overrides reference_angle", group="strain", kind="point")
    rv_label: int | None = option(
        None, "label images: the RV's label; segment 1 starts two segments clockwise of the "
        "direction of the RV's centre at the reference frame (the septum, segments 2-3, "
        "faces the RV); overrides reference_angle", group="strain", kind="int")
    label: int | None = option(
        None, "label images: the myocardium's label (default: every non-zero pixel)",
        group="strain", kind="int")
    object: str | int = option(
        "largest", "several objects in a mask: largest (the largest with a hole, a wall, "
        "when the largest has none), center (nearest the image centre) or a label number "
        "(1 = the first in reading order)", group="strain", kind="object",
        choices=OBJECTS)
    endo_only: bool = option(
        False, "masks of the blood pool or contours without an epicardium: endocardial "
        "circumferential strain only", group="strain", kind="bool")
    nodes: int = option(
        64, "nodes per contour (endocardium, epicardium)", group="strain", kind="int")
    frame_interval: float | None = option(
        None, "seconds between frames: strain rates per second (default: per frame)",
        group="strain", kind="float")
    correspondence: str = option(
        "normal", "how the tracking pairs nodes between frames (as track's; normal: "
        "along the normals of the reference wall made round (an area-keeping stretch of "
        "its second moments), on an ellipse its rays from the centre: no sliding along the "
        "wall; worst segment circumferential error 0.4-0.8 points on circular, elliptical "
        "(aspect 1.15, 1.3) and 1.5 x 0.8 mm-pixel phantoms, where plain normals gave "
        "3.6/6.4/12.9 and modal 0.9-6.0 (akinetic sector))",
        group="strain", kind="str", choices=CORRESPONDENCES)
    smooth_frames: float = option(
        1.0, "Gaussian smoothing of the tracked wall over time, standard deviation in "
        "frames (segmentation errors are independent frame to frame, the wall's motion is "
        "smooth); only for cines of 24 frames or more (on fewer it flattens the peaks: "
        "-0.7 points of peak radial strain at 20 frames, -2.5 at 12); 0 disables",
        group="strain", kind="float")

    def _check(self):
        for name, low in (("segments", 1), ("reference_frame", 0), ("nodes", 8)):
            value = getattr(self, name)
            if not (is_int(value) and value >= low):
                raise OptionError(f"{name} must be an integer >= {low}, got {value!r}")
        if not is_number(self.reference_angle):
            raise OptionError(f"reference_angle must be a number (degrees), got "
                              f"{self.reference_angle!r}")
        for name in ("rv_label", "label"):
            value = getattr(self, name)
            if value is not None and not (is_int(value) and value >= 0):
                raise OptionError(f"{name} must be a label value >= 0, got {value!r}")
        if self.frame_interval is not None and not (is_number(self.frame_interval)
                                                    and self.frame_interval > 0):
            raise OptionError(f"frame_interval must be a number of seconds > 0, got "
                              f"{self.frame_interval!r}")
        if self.rv_point is not None and not (
                isinstance(self.rv_point, tuple) and len(self.rv_point) == 2
                and all(map(is_number, self.rv_point))):
            raise OptionError(f"rv_point must be two numbers (x, y), got {self.rv_point!r}")
        if not (is_number(self.smooth_frames) and self.smooth_frames >= 0):
            raise OptionError(f"smooth_frames must be a number of frames >= 0, got "
                              f"{self.smooth_frames!r}")
        if not isinstance(self.endo_only, bool):
            raise OptionError(f"endo_only must be true or false, got {self.endo_only!r}")


@dataclass(frozen=True)
class StanceOptions(Options):
    """How :func:`modalmorph.stance` reads a pressure stack and follows its loaded parts
    (:mod:`modalmorph.io.pressure` says how the parts and their boundaries are found)."""

    threshold: float | None = option(
        None, "pressure above which a sensor is loaded, in the array's units (default: "
        "fraction x the peak)", group="pressure", kind="float")
    fraction: float = option(
        0.02, "without threshold: the loaded level as a fraction of the stack's peak",
        group="pressure", kind="float")
    pixel_size: float = option(
        1.0, "sensor pitch in mm: contours, areas and figures in mm (1: in sensors)",
        group="pressure", kind="float")
    smooth: float = option(
        0.5, "Gaussian width (sensors) of the smoothing before the boundary is drawn "
        "through the sensors (0: none)", group="pressure", kind="float")
    min_sensors: int = option(
        2, "smaller contacts (a single loaded sensor) are skipped, and said",
        group="pressure", kind="int")
    spacing: float = option(
        0.5, "node spacing along a part's boundary at its largest, in sensors",
        group="pressure", kind="float")
    every: int = option(
        1, "take every N-th frame (20: a 500 Hz plate at 25 Hz)", group="pressure",
        kind="int")
    pressure_unit: str = option(
        "", "unit of the pressure values (e.g. kPa), named on the figures' colour bars "
        "(empty: 'the input's units')", group="pressure", kind="str")

    def _check(self):
        if self.threshold is not None and not is_number(self.threshold):
            raise OptionError(f"threshold must be a number, got {self.threshold!r}")
        check_range("fraction", self.fraction, 0.0, 1.0, "of the peak")
        for name in ("pixel_size", "spacing"):
            value = getattr(self, name)
            if not (is_number(value) and value > 0):
                raise OptionError(f"{name} must be a number > 0, got {value!r}")
        if not (is_number(self.smooth) and self.smooth >= 0):
            raise OptionError(f"smooth must be a number >= 0, got {self.smooth!r}")
        if not isinstance(self.pressure_unit, str):
            raise OptionError(f"pressure_unit must be text, got {self.pressure_unit!r}")
        for name in ("min_sensors", "every"):
            value = getattr(self, name)
            if not (is_int(value) and value >= 1):
                raise OptionError(f"{name} must be an integer >= 1, got {value!r}")

