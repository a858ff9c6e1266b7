"""Sequences of masks as pixels: for measurements made on the pixels themselves (the
cardiac strain traces its own boundaries on them and draws the contours over them).

:func:`read_masks` reads what :func:`modalmorph.io.read_frames` reads as images (PNG,
TIFF pages, NPY/NPZ stacks, NIfTI 2D+t, folders and glob patterns of them) but returns
the arrays, with the pixel spacing of NIfTI files (1 elsewhere).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputFileError
from .base import extension
from .nifti import NIFTI_EXTENSIONS, nifti_slices
from .points import load_npy, npz_arrays
from .sequences import image_pages, sequence_files

__all__ = ["MASK_FILES", "Masks", "read_masks"]

MASK_FILES = (".png", ".tif", ".tiff", ".bmp", ".gif", ".npy", ".npz", *NIFTI_EXTENSIONS)


@dataclass(frozen=True)
class Masks:
    """Mask frames with their grid.

    Attributes
    ----------
    frames : ndarray, shape (F, H, W)
        The masks or label images, row ``r`` and column ``c`` at ``(x, y) = (c dx, r dy)``.
    spacing : (float, float)
        ``(dx, dy)``: the pixel spacing (NIfTI header; 1 for other files).
    unit : str
        Unit of ``spacing`` (``"px"`` unless a NIfTI header names one).
    names : tuple of str
        A name per frame for messages (``file``, ``file[3]``).
    """

    frames: np.ndarray
    spacing: tuple
    unit: str
    names: tuple


def read_masks(inputs) -> Masks:
    """The masks of one or several files, folders or glob patterns, in order.

    Raises
    ------
    InputFileError
        A file that is missing or unreadable, a frame that is not a 2D array, frames of
        different sizes or pixel spacings (named).
    """
    inputs = [inputs] if isinstance(inputs, str | os.PathLike) else list(inputs)
    files = []
    for item in inputs:
        found = sequence_files(item, MASK_FILES)
        files += [Path(item)] if found is None else [Path(f) for f in found]
    frames, names, grid = [], [], None
    for path in files:
        stack, spacing, unit = _stack(path, os.fspath(path))
        if grid is not None and (spacing, unit) != grid[1:]:
            raise InputFileError(f"{path}: pixel spacing {spacing[0]:g} x {spacing[1]:g} "
                                 f"{unit}, the first file ({grid[0]}) {grid[1][0]:g} x "
                                 f"{grid[1][1]:g} {grid[2]}: the frames share one grid")
        grid = grid or (path, spacing, unit)
        names += [os.fspath(path)] if len(stack) == 1 else [f"{path}[{i}]"
                                                             for i in range(len(stack))]
        frames += stack
    for name, frame in zip(names, frames, strict=True):
        if frame.shape != frames[0].shape:
            raise InputFileError(f"{name}: the mask is {frame.shape[1]} x {frame.shape[0]} "
                                 f"px, the first ({names[0]}) {frames[0].shape[1]} x "
                                 f"{frames[0].shape[0]} px: the frames share one grid")
    return Masks(np.asarray(frames), grid[1], grid[2], tuple(names))


def _stack(path: Path, name: str) -> tuple[list, tuple, str]:
    """The frames (H, W) of one file, its spacing and unit."""
    if not path.is_file():
        raise InputFileError(f"{name}: file not found")
    ext = extension(path)
    if ext in NIFTI_EXTENSIONS:
        return nifti_slices(path, name)
    if ext in (".npy", ".npz"):
        array = load_npy(path, name) if ext == ".npy" else npz_arrays(path, name)[0]
        if array.ndim not in (2, 3) or array.dtype.kind not in "biuf":
            raise InputFileError(f"{name}: masks must be a numeric (H, W) or (F, H, W) "
                                 f"array, got {array.dtype} {array.shape}")
        return list(array[None] if array.ndim == 2 else array), (1.0, 1.0), "px"
    return image_pages(path, name), (1.0, 1.0), "px"
