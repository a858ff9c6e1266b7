"""Bounds on what a file may cost before it is read: sizes, shapes and pixels from headers.

A compressed file can declare far more than it weighs: an NPZ of 1 MB can inflate to
1 GiB, a PNG of a few kB can declare 20 000 x 20 000 pixels. Each function here reads
only the headers (the zip central directory, the ``.npy`` header, the image header, a
scan of JSON brackets) and raises :class:`LimitError`, naming the limit, before anything
is inflated or decoded. numpy, Pillow and the standard library only.

An SVG of a kilobyte can declare millions of outlines: each ``<use>`` draws the element it
refers to again, so groups that each use the one below ten times, six deep, draw a
million; :func:`check_svg` counts them from the XML before anything is drawn.

Which reader calls which: the NPY reader :func:`check_npy`, the NPZ reader
:func:`check_npz`, the image reader :func:`check_image`, the JSON reader
:func:`check_json`, the NIfTI reader :func:`check_nifti`, the SVG reader (library, CLI,
batch and app alike) :func:`check_svg`; every reader :func:`check_file_size` first.
"""

from __future__ import annotations

import gzip
import re
import struct
import xml.etree.ElementTree as ET
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["LimitError", "Limits", "DEFAULT_LIMITS", "check_file_size", "check_npy",
           "check_npz", "check_image", "check_json", "check_nifti", "json_depth",
           "check_shape", "check_svg", "svg_elements", "MAX_SVG_ELEMENTS"]


class LimitError(ValueError):
    """A file or request over one of the :class:`Limits` (``limit`` names the field)."""

    def __init__(self, message: str, limit: str):
        super().__init__(message)
        self.limit = limit


# Elements an SVG may have once every <use> is expanded (what svgelements builds and walks).
# The largest of the 838 SVGs on this machine (installed packages' logos and icons, this
# project's matplotlib figures) expand to 3 698 (requests' logo) and 3 051 (a shapes_load
# figure); a matplotlib scatter of 10 000 markers to 20 219. svgelements takes 70-340 us
# and about 3.5 kB per expanded element (47 000: 4 s, 180 MB peak), so the limit, 13x the
# largest real drawing, reads in at most about 17 s and 200 MB, on any thread.
MAX_SVG_ELEMENTS = 50_000


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
    max_svg_elements : int
        Elements of an SVG once every ``<use>`` is expanded (:data:`MAX_SVG_ELEMENTS`).
    """

    max_file_bytes: int = 16 * 2**20
    max_array_bytes: int = 64 * 2**20
    max_array_dim: int = 3
    max_members: int = 64
    max_pixels: int = 25_000_000
    max_json_depth: int = 32
    max_svg_elements: int = MAX_SVG_ELEMENTS


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


_XLINK_HREF = "{http://www.w3.org/1999/xlink}href"


def svg_elements(path, name: str | None = None) -> int:
    """How many elements the SVG at ``path`` has once every ``<use>`` is replaced by the
    element it refers to, as svgelements expands them (``href``, else ``xlink:href``, to
    an ``id``; the last element of an id wins; a reference to no element adds nothing).

    Parsed once with the standard library's XML parser (the one svgelements uses: no
    network, external entities not fetched, expat's bound on entity expansion); each
    element's count is computed once, so the time is linear in the file. ``ValueError``
    for a file that is not XML and for a ``<use>`` that draws an element containing it
    (an endless drawing).
    """
    path = Path(path)
    name = name or path.name
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise ValueError(f"{name}: not a valid SVG (XML) file: {exc}") from None
    ids = {e.attrib["id"]: e for e in root.iter() if "id" in e.attrib}
    counts: dict[int, int] = {}
    stack = [(root, False)]
    while stack:  # depth first, each element's count after its parts' (no recursion)
        element, ready = stack.pop()
        parts = list(element) + [ids[ref[1:]] for ref in [_use_ref(element)]
                                 if ref is not None and ref[1:] in ids]
        if ready:
            counts[id(element)] = 1 + sum(counts[id(p)] for p in parts)
            continue
        if id(element) in counts:
            continue
        counts[id(element)] = -1  # being counted: met again below it, a cycle
        stack.append((element, True))
        for part in parts:
            if counts.get(id(part)) == -1:
                raise ValueError(f"{name}: a <use> draws an element that contains it "
                                 f"(id {part.attrib.get('id')!r}): an endless drawing")
            if id(part) not in counts:
                stack.append((part, False))
    return counts[id(root)]


def _use_ref(element) -> str | None:
    """The reference of a ``<use>`` element (svgelements' choice: ``href`` over
    ``xlink:href``), or None."""
    if element.tag.rsplit("}", 1)[-1] != "use":
        return None
    return element.attrib.get("href", element.attrib.get(_XLINK_HREF))


def check_svg(path, limits: Limits = DEFAULT_LIMITS, name: str | None = None) -> int:
    """The elements of an SVG, every ``<use>`` expanded (:func:`svg_elements`);
    :class:`LimitError` over ``max_svg_elements``, before anything is drawn (the file's
    size is the caller's: the library reads SVGs of any size)."""
    path = Path(path)
    name = name or path.name
    count = svg_elements(path, name)
    if count > limits.max_svg_elements:
        raise LimitError(f"{name}: {count} elements once each <use> is expanded, the limit "
                         f"(max_svg_elements) is {limits.max_svg_elements}",
                         "max_svg_elements")
    return count
