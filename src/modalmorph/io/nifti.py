"""NIfTI-1/2 label volumes (``.nii``, ``.nii.gz``): a 2D slice, a 2D+t sequence of masks or
a 3D volume's surface, in millimetres. Needs nibabel, an optional dependency (``pip
install 'modalmorph[nifti]'``).

Array shapes: (X, Y) or (X, Y, 1) is one frame; (X, Y, 1, T) and (X, Y, T) are T frames
of one slice for a sequence (:func:`nifti_frames`: ``read_frames``, ``track``, ``strain``);
(X, Y, Z, T) with Z > 1 is refused. Read as one shape (:func:`read_nifti`), an (X, Y, Z)
array with Z > 1 is a 3D volume, as the NIfTI standard says of its first three axes: the
surface of its object (marching cubes at the half level between object and background,
smoothed :data:`VOLUME_SMOOTHING` voxels wide, voxel ``(i, j, k)`` at ``(i dx, j dy, k
dz)``; scikit-image), a triangle mesh with outward faces. Each frame
is read as an image
(:mod:`.images`): a two-level mask, a label image with ``label`` (segmentations: ACDC's
myocardium is 2) or grey levels with ``threshold``.

The frame: voxel ``(i, j)`` (the first two array axes) is at ``(x, y) = (i * dx, j * dy)``
where ``(dx, dy)`` are the header's first two zooms (pixel spacing), in the header's
spatial unit (mm when it names none). The affine's origin and direction cosines are not
applied: x runs along the first voxel axis, y along the second, drawn y down as image rows
(the slice as ``data[:, :, t].T``, its first row at the top); the voxel axes' anatomical
directions (nibabel's ``aff2axcodes``, e.g. ``('R', 'A', 'S')``) are logged.
"""

from __future__ import annotations

import logging
import threading
from pathlib import Path

import numpy as np

from ..core.shape import ImageFrame
from ..errors import InputFileError
from ..options import ReadOptions
from .base import DEFAULT_NODES, RawShape
from .images import choose_objects, image_contours, object_mask

__all__ = ["NIFTI_EXTENSIONS", "VOLUME_SMOOTHING", "nifti_frames", "nifti_grid", "nifti_slices",
           "read_nifti"]

NIFTI_EXTENSIONS = (".nii", ".nii.gz")

# Standard deviation, in voxels, of the Gaussian that smooths a volume's object before its
# surface is taken (ITK-SNAP's default for meshes: 0.8). Voxel phantoms (0.8 x 0.8 x 2 mm;
# an ellipsoid, two fused ones, a shell 3 voxels thick) morphed onto their likes with the
# defaults: unsmoothed, none converged (equilibrium 1.4-2.1 tolerances off, self-
# intersecting steps); 0.7, two of three; 1.0, all three in 7-8 steps, volume within
# 1.2-3.1 %; Taubin smoothing of the mesh (30 iterations) two of three.
VOLUME_SMOOTHING = 1.0

_log = logging.getLogger(__name__)
_HEARING = threading.Lock()


def read_nifti(path: Path, name: str, options: ReadOptions) -> RawShape:
    """The contours of the chosen object of a one-frame NIfTI file, in its spatial unit."""
    image = _load(path, name)
    if len(image.shape) in (3, 4) and image.shape[2] > 1 and image.shape[3:] in ((), (1,)):
        return _volume_surface(image, name, options)  # (X, Y, Z) or (X, Y, Z, 1)
    slices, spacing, unit = nifti_slices(path, name)
    if len(slices) > 1:
        raise InputFileError(f"{name}: a 2D+t volume of {len(slices)} frames: read it as a "
                             f"sequence (read_frames, modalmorph track)")
    pts, contours = _contours(slices[0], name, options, spacing)
    return RawShape(pts, frame=_frame(unit, slices[0]), default_nodes=DEFAULT_NODES,
                    contours=contours)


def _volume_surface(image, name: str, options: ReadOptions) -> RawShape:
    """The surface of the chosen object of a 3D volume (see the module's docstring)."""
    from scipy import ndimage
    from skimage.measure import marching_cubes

    zooms = tuple(float(f"{z:.7g}") for z in image.header.get_zooms()[:3])  # float32
    if not all(np.isfinite(z) and z > 0 for z in zooms):
        raise InputFileError(f"{name}: the header's voxel spacing must be three positive "
                             f"numbers, got {zooms}")
    try:
        data = np.asanyarray(image.dataobj).reshape(image.shape[:3])
    except (OSError, ValueError, EOFError, MemoryError) as exc:
        raise InputFileError(f"{name}: cannot read the NIfTI data: {_line(exc)}") from None
    mask = object_mask(data, name, options)
    chosen = np.logical_or.reduce(choose_objects(mask, options.object, name))
    box = ndimage.find_objects(chosen.astype(np.int8))[0]  # work on the object's box only
    chosen = np.pad(chosen[box], 2)
    smooth = ndimage.gaussian_filter(chosen.astype(np.float32), VOLUME_SMOOTHING)
    if not smooth.max() > 0.5:  # an object thinner than the smoothing: as it is
        smooth = chosen.astype(np.float32)
    verts, faces, *_ = marching_cubes(smooth, 0.5, spacing=zooms, allow_degenerate=False,
                                      gradient_direction="ascent")  # faces turn outwards
    unit = _unit(_unit_name(image))
    _log.info("%s: the surface of a %d x %d x %d volume's object (voxels %g x %g x %g %s): "
              "%d vertices, %d triangles", name, *mask.shape, *zooms, unit, len(verts),
              len(faces))
    origin = np.array([b.start - 2 for b in box]) * zooms  # the box, less its padding
    return RawShape((verts + origin).astype(np.float64), faces=faces.astype(np.intp),
                    frame=ImageFrame(unit=unit, y_down=False), drop_closing_repeat=False)


def nifti_frames(path: Path, name: str, options: ReadOptions) -> list[tuple[str, RawShape]]:
    """``(frame name, RawShape)`` of each frame of a NIfTI file (one for a 2D file)."""
    slices, spacing, unit = nifti_slices(path, name)
    if len(slices) == 1:
        return [(name, read_nifti(path, name, options))]
    out = []
    for t, grey in enumerate(slices):
        frame_name = f"{name}[frame {t}]"
        pts, contours = _contours(grey, frame_name, options, spacing)
        out.append((frame_name, RawShape(pts, frame=_frame(unit, grey),
                                         default_nodes=DEFAULT_NODES, contours=contours)))
    return out


def nifti_grid(path: Path, name: str) -> tuple[tuple[int, int], tuple[float, float]]:
    """``((X, Y), (dx, dy))``: a NIfTI file's slice size and pixel spacing, from its header
    alone (for checking that the frames of a sequence share one grid)."""
    image = _load(path, name)
    return tuple(int(n) for n in image.shape[:2]), _spacing(image, name)


def _load(path: Path, name: str):
    try:
        import nibabel
    except ImportError:
        raise InputFileError(f"{name}: reading NIfTI files needs nibabel; install it with: "
                             f"pip install 'modalmorph[nifti]'") from None
    said = _Said()
    logger = logging.getLogger("nibabel.global")  # where nibabel says what it fixed
    with _HEARING:  # one reader at a time swaps the handlers (the app reads in threads)
        handlers = logger.handlers[:]
        logger.handlers = [said]
        try:
            image = nibabel.load(path)
        except (OSError, ValueError, EOFError,
                nibabel.filebasedimages.ImageFileError) as exc:
            raise InputFileError(f"{name}: cannot read the NIfTI file: {_line(exc)}") \
                from None
        finally:
            logger.handlers = handlers
    for text in said.lines:  # a spacing nibabel replaced by 1 is no spacing: refused
        if "pixdim" in text:
            raise InputFileError(f"{name}: the header's pixel spacing is invalid: {text}")
        _log.info("%s: nibabel: %s", name, text)
    return image


class _Said(logging.Handler):
    """Keeps the lines logged (nibabel's header fixes), instead of printing them."""

    def __init__(self):
        super().__init__()
        self.lines = []

    def emit(self, record):
        self.lines.append(_line(record.getMessage()))


def _line(exc: Exception) -> str:
    return " ".join(str(exc).split())  # nibabel's messages run over several lines


def _spacing(image, name: str) -> tuple[float, float]:
    zooms = tuple(float(f"{z:.7g}") for z in image.header.get_zooms()[:2])  # float32
    if len(zooms) < 2 or not all(np.isfinite(z) and z > 0 for z in zooms):
        raise InputFileError(f"{name}: the header's pixel spacing must be two positive "
                             f"numbers, got {zooms}")
    return zooms


def nifti_slices(path: Path, name: str
                 ) -> tuple[list[np.ndarray], tuple[float, float], str]:
    """The frames (H, W) = (Y, X) of a NIfTI file, its pixel spacing and spatial unit."""
    image = _load(path, name)
    shape = image.shape
    if len(shape) < 2 or len(shape) > 4 or (len(shape) == 4 and shape[2] != 1):
        raise InputFileError(f"{name}: expected a 2D slice (X, Y), (X, Y, T) or (X, Y, 1, T), "
                             f"or a 3D volume (X, Y, Z), got an array of shape {shape}")
    spacing = _spacing(image, name)
    unit = _unit_name(image)
    try:
        import nibabel

        axes = "".join(nibabel.aff2axcodes(image.affine)[:2])
        data = np.asanyarray(image.dataobj)
    except (OSError, ValueError, EOFError, MemoryError) as exc:
        raise InputFileError(f"{name}: cannot read the NIfTI data: {_line(exc)}") from None
    data = data.reshape(shape[0], shape[1], -1)  # (X, Y, frames)
    _log.info("%s: %d frame(s) of %d x %d voxels, spacing %g x %g %s, voxel axes towards %s",
              name, data.shape[2], shape[0], shape[1], *spacing, unit, axes)
    return [data[:, :, t].T for t in range(data.shape[2])], spacing, _unit(unit)


def _unit_name(image) -> str:
    unit = image.header.get_xyzt_units()[0]
    return unit if unit != "unknown" else "mm (the header names no unit)"


def _unit(unit: str) -> str:
    return {"micron": "µm", "meter": "m"}.get(unit, unit.split()[0])


def _contours(grey: np.ndarray, name: str, options: ReadOptions, spacing):
    """Every boundary of the chosen object, scaled from voxels to the spatial unit."""
    if grey.dtype == bool:
        grey = grey.astype(np.uint8)
    parts = [p * spacing for p in image_contours(grey, name, options)]  # (i, j) -> mm
    return np.vstack(parts), tuple(map(len, parts)) if len(parts) > 1 else None


def _frame(unit: str, grey: np.ndarray) -> ImageFrame:
    return ImageFrame(unit=unit, size=grey.shape, y_down=True)
