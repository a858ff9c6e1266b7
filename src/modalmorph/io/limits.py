"""Bounds on what a file may cost before it is read: sizes, shapes and pixels from headers.

A compressed file can declare far more than it weighs: an NPZ of 1 MB can inflate to
1 GiB, a PNG of a few kB can declare 20 000 x 20 000 pixels. Each function here reads
only the headers (the zip central directory, the ``.npy`` header, the image header, a
scan of JSON brackets) and raises :class:`LimitError`, naming the limit, before anything
is inflated or decoded. numpy, Pillow and the standard library only.

Which reader calls which: the NPY reader :func:`check_npy`, the NPZ reader
:func:`check_npz`, the image reader :func:`check_image`, the JSON reader
:func:`check_json`, the NIfTI reader :func:`check_nifti`; every reader
:func:`check_file_size` first.
"""

from __future__ import annotations

import gzip
import re
import struct
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["LimitError", "Limits", "DEFAULT_LIMITS", "check_file_size", "check_npy",
           "check_npz", "check_image", "check_json", "check_nifti", "json_depth",
           "check_shape"]


class LimitError(ValueError):
    """A file or request over one of the :class:`Limits` (``limit`` names the field)."""

    def __init__(self, message: str, limit: str):
        super().__init__(message)
        self.limit = limit


@dataclass(frozen=True)
class Limits:
    """What one input may cost. The defaults are the web app's (``modalmorph app``).

    Attributes
    ----------
    max_file_bytes : int
        Bytes of the file as stored (16 MiB: a 4000 x 4000 grey PNG or a CSV of 100 000
        2D nodes fit).
    max_array_bytes : int
        Bytes of all the arrays of an NPY/NPZ once inflated (64 MiB: 4 million 2D nodes
        of float64, far above what the model takes, far below the memory of a laptop).
    max_array_dim : int
        Dimensions of one array (3: a stack of shapes (T, m, d) is the largest there is).
    max_members : int
        Arrays in one NPZ (64: a saved result holds about 10).
    max_pixels : int
        Width x height of an image (25 Mpixel: 25 MB grey, about 2 s to trace its contour).
    max_json_depth : int
        Nesting of JSON (32: a shape file nests 3 deep, the app's requests 2).
    """

    max_file_bytes: int = 16 * 2**20
    max_array_bytes: int = 64 * 2**20
    max_array_dim: int = 3
    max_members: int = 64
    max_pixels: int = 25_000_000
    max_json_depth: int = 32


DEFAULT_LIMITS = Limits()


def check_file_size(path, limits: Limits = DEFAULT_LIMITS) -> int:
    """The file's size in bytes; :class:`LimitError` over ``max_file_bytes``."""
    path = Path(path)
    size = path.stat().st_size
    if size > limits.max_file_bytes:
        raise LimitError(f"{path.name}: the file is too large: {size} bytes, the limit "
                         f"(max_file_bytes) is {limits.max_file_bytes} bytes",
                         "max_file_bytes")
    return size


def check_shape(name: str, shape: tuple, dtype: np.dtype, limits: Limits = DEFAULT_LIMITS
                ) -> int:
    """Bytes of an array of ``shape`` and ``dtype``, checked against the limits."""
    if dtype.hasobject:
        raise LimitError(f"{name}: arrays of Python objects are not read (pickles run code)",
                         "dtype")
    if any(n < 0 for n in shape):
        raise ValueError(f"{name}: a negative dimension in the array's shape {shape}")
    if len(shape) > limits.max_array_dim:
        raise LimitError(f"{name}: an array of {len(shape)} dimensions {shape}, the limit "
                         f"(max_array_dim) is {limits.max_array_dim}", "max_array_dim")
    nbytes = int(np.prod(shape, dtype=object)) * dtype.itemsize
    if nbytes > limits.max_array_bytes:
        raise LimitError(f"{name}: the array {shape} of {dtype} would take {nbytes} bytes, "
                         f"the limit (max_array_bytes) is {limits.max_array_bytes} bytes",
                         "max_array_bytes")
    return nbytes


def _npy_header(stream, name: str) -> tuple[tuple, np.dtype]:
    """(shape, dtype) from the header of an ``.npy`` stream (nothing else is read)."""
    fmt = np.lib.format
    try:
        version = fmt.read_magic(stream)
        if version == (1, 0):
            shape, _, dtype = fmt.read_array_header_1_0(stream)
        elif version in ((2, 0), (3, 0)):
            shape, _, dtype = fmt.read_array_header_2_0(stream)
        else:
            raise ValueError(f"unknown .npy version {version}")
    except ValueError as exc:
        raise ValueError(f"{name}: not a NumPy array file: {exc}") from None
    return tuple(shape), np.dtype(dtype)


def check_npy(path, limits: Limits = DEFAULT_LIMITS) -> tuple:
    """The shape of the array in an ``.npy`` file, from its header; :class:`LimitError`
    over the limits, ``ValueError`` when the header is not one of NumPy's."""
    path = Path(path)
    check_file_size(path, limits)
    with open(path, "rb") as stream:
        shape, dtype = _npy_header(stream, path.name)
    check_shape(path.name, shape, dtype, limits)
    return shape


def check_npz(path, limits: Limits = DEFAULT_LIMITS) -> dict[str, tuple]:
    """``{name: shape}`` of the arrays of an ``.npz``, from the zip's central directory and
    each member's ``.npy`` header (at most a few hundred bytes inflated per member).

    The sizes the zip declares bound what :mod:`zipfile` will inflate (it stops at the
    declared size), so they are checked first, then each array's shape and dtype.
    """
    path = Path(path)
    check_file_size(path, limits)
    try:
        archive = zipfile.ZipFile(path)
    except zipfile.BadZipFile as exc:
        raise ValueError(f"{path.name}: not an NPZ (zip) file: {exc}") from None
    with archive:
        members = archive.infolist()
        if len(members) > limits.max_members:
            raise LimitError(f"{path.name}: {len(members)} arrays, the limit (max_members) "
                             f"is {limits.max_members}", "max_members")
        declared = sum(m.file_size for m in members)
        if declared > limits.max_array_bytes:
            raise LimitError(f"{path.name}: inflates to {declared} bytes, the limit "
                             f"(max_array_bytes) is {limits.max_array_bytes} bytes",
                             "max_array_bytes")
        shapes, total = {}, 0
        for member in members:
            name = f"{path.name}[{member.filename}]"
            with archive.open(member) as stream:
                shape, dtype = _npy_header(stream, name)
            total += check_shape(name, shape, dtype, limits)
            shapes[member.filename.removesuffix(".npy")] = shape
        if total > limits.max_array_bytes:
            raise LimitError(f"{path.name}: the arrays take {total} bytes, the limit "
                             f"(max_array_bytes) is {limits.max_array_bytes} bytes",
                             "max_array_bytes")
    return shapes


def check_image(path, limits: Limits = DEFAULT_LIMITS) -> tuple[int, int] | None:
    """(width, height) of an image from its header, or None when Pillow does not know the
    file; :class:`LimitError` over ``max_pixels`` (nothing is decoded)."""
    from PIL import Image, UnidentifiedImageError

    path = Path(path)
    check_file_size(path, limits)
    try:
        with Image.open(path) as image:
            width, height = image.size
    except Image.DecompressionBombError as exc:  # Pillow's own, far higher, bound
        raise LimitError(f"{path.name}: the image is too large ({exc}); the limit "
                         f"(max_pixels) is {limits.max_pixels} pixels", "max_pixels") from None
    except (UnidentifiedImageError, OSError):
        return None
    if width * height > limits.max_pixels:
        raise LimitError(f"{path.name}: the image is too large: {width} x {height} pixels, "
                         f"the limit (max_pixels) is {limits.max_pixels} pixels",
                         "max_pixels")
    return width, height


# Bytes a voxel of each NIfTI datatype code (what nibabel reads, whatever bitpix says); an
# unknown code counts as the largest.
_NIFTI_BYTES = {2: 1, 4: 2, 8: 4, 16: 4, 32: 8, 64: 8, 128: 3, 256: 1, 512: 2, 768: 4,
                1024: 8, 1280: 8, 1536: 16, 1792: 16, 2048: 32, 2304: 4}


def check_nifti(path, limits: Limits = DEFAULT_LIMITS) -> tuple[int, ...] | None:
    """The array shape a NIfTI-1 or -2 file declares, from its header (a few hundred bytes
    inflated), or None when the header is not one; :class:`LimitError` when the data
    would take over ``max_array_bytes``."""
    path = Path(path)
    check_file_size(path, limits)
    opener = gzip.open if path.name.endswith(".gz") else open
    try:
        with opener(path, "rb") as stream:
            head = stream.read(544)
    except (OSError, EOFError, zlib.error):
        return None  # not a NIfTI file: the reader says what is wrong
    for order in "<>":
        if len(head) >= 348 and struct.unpack(order + "i", head[:4])[0] == 348:  # NIfTI-1
            dim, (code, bitpix) = struct.unpack(order + "8h", head[40:56]), struct.unpack(
                order + "2h", head[70:74])
        elif len(head) >= 540 and struct.unpack(order + "i", head[:4])[0] == 540:
            (code, bitpix), dim = struct.unpack(order + "2h", head[12:16]), struct.unpack(
                order + "8q", head[16:80])
        else:
            continue
        shape = tuple(int(n) for n in dim[1:1 + min(max(dim[0], 0), 7)])
        item = max(_NIFTI_BYTES.get(code, max(_NIFTI_BYTES.values())), bitpix // 8)
        nbytes = int(np.prod([max(n, 0) for n in shape], dtype=object)) * item
        if nbytes > limits.max_array_bytes:
            raise LimitError(f"{path.name}: the NIfTI data {shape} of {item} bytes a voxel would "
                             f"take {nbytes} bytes, the limit (max_array_bytes) is "
                             f"{limits.max_array_bytes} bytes", "max_array_bytes")
        return shape
    return None


_JSON_STRING = re.compile(rb'"(?:[^"\\]|\\.)*"', re.DOTALL)


def json_depth(text: bytes | str) -> int:
    """How deep the arrays and objects of a JSON text nest (brackets in strings ignored),
    without parsing it."""
    raw = text.encode("utf-8", "surrogatepass") if isinstance(text, str) else bytes(text)
    codes = np.frombuffer(_JSON_STRING.sub(b'""', raw), dtype=np.uint8)
    step = np.isin(codes, (ord("["), ord("{"))).astype(np.int64) \
        - np.isin(codes, (ord("]"), ord("}")))
    return int(np.cumsum(step).max(initial=0))


def check_json(text: bytes | str, name: str = "the JSON",
               limits: Limits = DEFAULT_LIMITS) -> None:
    """:class:`LimitError` when ``text`` is larger than ``max_file_bytes`` or nests deeper
    than ``max_json_depth`` (checked before :func:`json.loads` recurses into it)."""
    if len(text) > limits.max_file_bytes:
        raise LimitError(f"{name}: {len(text)} bytes, the limit (max_file_bytes) is "
                         f"{limits.max_file_bytes} bytes", "max_file_bytes")
    depth = json_depth(text)
    if depth > limits.max_json_depth:
        raise LimitError(f"{name}: nested {depth} deep, the limit (max_json_depth) is "
                         f"{limits.max_json_depth}", "max_json_depth")
