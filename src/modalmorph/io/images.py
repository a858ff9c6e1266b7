"""Images: every boundary of one object (or of each object), in pixel coordinates.

The contours are in ``(x, y) = (column, row)``, y pointing down (the shape's
:class:`~modalmorph.core.shape.ImageFrame` names the image, drawn under the figures),
sub-pixel (marching squares at half level). A two-level image is a mask; a grey-level image
needs ``threshold``; a label image (a segmentation) needs ``label``, the value of the
object's pixels. Whichever side covers most of the image border is the background (not with
``label``), so dark objects on a light background work too. Colour is converted to grey; an
alpha channel is the mask only when it is one (:data:`MIN_OBJECT_PIXELS`,
:data:`MAX_PARTIAL_ALPHA`). Of the mask's 4-connected objects, ``object="largest"`` takes
the largest, but one inside the image over a larger one touching the border
(:data:`INSIDE_FRACTION`); ``"center"`` the one nearest the image centre; a number, that
object in reading order; ``"all"`` every object of :data:`MIN_OBJECT_PIXELS` or more, in
reading order (the parts of a footprint). The choice is logged (its area, whether it
touches the border).

The shape holds the object's outer boundary (counter-clockwise in (x, y): positive area),
then each of its holes of :data:`MIN_HOLE_AREA` or more (clockwise, largest first): a
myocardium ring gives its epicardium then its endocardium. Its ``contours`` are their node
counts, the nodes shared among them by length. :func:`mask_shape` does the same for an
array.
"""
from __future__ import annotations

import logging
import os
import warnings
from pathlib import Path

import numpy as np

from ..core.quality import area
from ..core.shape import ImageFrame, Shape
from ..errors import InputFileError
from ..options import ReadOptions
from .base import DEFAULT_NODES, RawShape, make_shape

__all__ = ["INSIDE_FRACTION", "MAX_PARTIAL_ALPHA", "MIN_HOLE_AREA", "MIN_OBJECT_PIXELS",
           "grey_levels", "image_contours", "mask_contours", "mask_shape", "object_mask",
           "read_image"]

# An object inside the image is taken over a larger one touching the border when
# its area is at least this fraction of the larger one's. A choice, not a measurement: an
# object the user means is rarely ten times smaller than a strip cut by the border, while
# specks of a noisy threshold (a few px) are far below it and never outrank a large object.
INSIDE_FRACTION = 0.1
# An alpha channel is read as the mask only when at least this many pixels are opaque
# and as many transparent (an outline of >= 3 nodes needs a 2 x 2 block at least: 3 x 3
# keeps a margin) and at most this fraction of the pixels is partly transparent, between 10
# and 90 % opacity. Measured on 256 x 256 images: the antialiased edge of a disc of radius
# 100 px covers 0.73 % of the pixels (radius 50: 0.36 %); a radial vignette 89 %.
MIN_OBJECT_PIXELS = 9
MAX_PARTIAL_ALPHA = 0.2
# A hole of an object is a contour of the shape when its area (marching squares) is at
# least this: a 3 x 3 block of background (9 px less its 4 cut corners, 0.5 px^2). Measured
# on 17 scikit-image sample images thresholded by Otsu's method (the largest object of
# each): 2010 holes, 38 % of one pixel (area 0.5), 18 % of two (1.5), 81 % below this;
# their sizes run on without a gap up to 5940 px^2, so this drops only specks of noise.
MIN_HOLE_AREA = MIN_OBJECT_PIXELS - 0.5
# An image of at most this many levels may be a label image (a segmentation), and its
# refusal also proposes ``label``. A choice: segmentations name a few structures (ACDC: 4
# values, background included; the 17 AHA segments: 18), grey images have tens to 256.
MAX_LABELS = 20

_log = logging.getLogger(__name__)


def read_image(path: Path, name: str, options: ReadOptions) -> RawShape:
    """Every boundary (outer, then holes) of the chosen object of an image file (see the
    module's docstring), with the image's frame."""
    try:
        import skimage.measure  # noqa: F401  (the contour of the mask, below)
        from PIL import Image, UnidentifiedImageError
    except ImportError as exc:
        raise ImportError(f"reading images needs scikit-image and pillow ({exc}); install "
                          f"them with: pip install 'modalmorph[images]'") from None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            with Image.open(path) as image:
                _check_pixels(image)
                grey = grey_levels(image, name)
    except (OSError, UnidentifiedImageError, Image.DecompressionBombWarning,
            Image.DecompressionBombError, ValueError) as exc:
        raise InputFileError(f"{name}: cannot read the image: {exc}") from None
    parts = image_contours(grey, name, options)
    return RawShape(np.vstack(parts), frame=ImageFrame(image=os.fspath(path), size=grey.shape),
                    default_nodes=DEFAULT_NODES, contours=_sizes(parts))


def _check_pixels(image) -> None:
    """Refuse (ValueError), before decoding, an image of more pixels than Pillow's
    decompression-bomb bound (``PIL.Image.MAX_IMAGE_PIXELS``). Pillow only warns between
    1 and 2 times it, and the warning made an error above is lost when another thread
    leaves its own ``warnings.catch_warnings`` meanwhile (the filters are global): this
    check holds on any thread."""
    from PIL import Image

    width, height = image.size
    limit = Image.MAX_IMAGE_PIXELS
    if limit is not None and width * height > limit:
        raise ValueError(f"{width} x {height} pixels, over Pillow's bound against "
                         f"decompression bombs (PIL.Image.MAX_IMAGE_PIXELS = {limit})")


def mask_shape(mask, name: str = "mask", *, label=None, nodes: int | None = None,
               frame: ImageFrame | None = None, choice="largest") -> Shape:
    """The boundaries of an object of a mask or label image, as one shape.

    Parameters
    ----------
    mask : array_like, shape (H, W)
        A mask (bool, or two levels: the higher one is the object) or a label image
        (integers, with ``label``).
    name : str
        Named in messages (a file, a frame).
    label : int, optional
        The value of the object's pixels in a label image (needed when ``mask`` has more
        than two values).
    nodes : int, optional
        Nodes in all, shared among the contours by length (default :data:`DEFAULT_NODES`).
    frame : ImageFrame, optional
        The shape's frame (default: pixels, y down, the mask's size).
    choice : str or int
        Which 4-connected object: ``"largest"``, ``"center"``, ``"all"`` (every object of
        :data:`MIN_OBJECT_PIXELS` or more, in reading order) or its number in reading order.

    Returns
    -------
    Shape
        In ``(x, y) = (column, row)`` pixels: the object's outer boundary first
        (counter-clockwise in (x, y), positive area), then each hole of
        :data:`MIN_HOLE_AREA` or more (clockwise, by decreasing area), each resampled by
        arc length; ``contours`` gives their node counts (None when there is no hole).

    Raises
    ------
    InputFileError
        Not a 2D numeric array, no pixel of ``label``, a label image without ``label``,
        no object or no such object; the message starts with ``name``.
    """
    array = np.asarray(mask)
    if array.ndim != 2 or min(array.shape) < 1 or array.dtype.kind not in "biuf":
        raise InputFileError(f"{name}: a mask must be a 2D numeric or bool array, got "
                             f"{array.dtype} {array.shape}")
    parts = mask_contours(_label_pixels(array, name, label), name, choice)
    frame = frame or ImageFrame(size=array.shape)
    return make_shape(name, np.vstack(parts), nodes=nodes or DEFAULT_NODES, frame=frame,
                      contours=_sizes(parts))


def _sizes(parts: list) -> tuple[int, ...] | None:
    return tuple(len(p) for p in parts) if len(parts) > 1 else None


def _label_pixels(array: np.ndarray, name: str, label) -> np.ndarray:
    """The object's pixels (bool) of a mask (the higher of two levels) or, with ``label``,
    of a label image."""
    if array.dtype.kind == "f" and not np.isfinite(array).all():
        raise InputFileError(f"{name}: the mask has {np.count_nonzero(~np.isfinite(array))} "
                             f"non-finite (NaN or inf) pixels")
    levels = np.unique(array)
    if label is not None:
        pixels = array == label
        if not pixels.any():
            raise InputFileError(f"{name}: no pixel has label {label} (values: "
                                 f"{_listed(levels)})")
        return pixels
    if len(levels) > 2:
        raise InputFileError(f"{name}: a label image ({len(levels)} values: "
                             f"{_listed(levels)}): give label= the object's value")
    if len(levels) == 1:
        raise InputFileError(f"{name}: no object in the mask: every pixel is {levels[0]}")
    return array == levels[-1]


def _listed(levels: np.ndarray, most: int = 8) -> str:
    shown = ", ".join(f"{v:g}" for v in levels[:most].tolist())
    return shown + (f", ... ({len(levels)} in all)" if len(levels) > most else "")


def image_contours(grey: np.ndarray, name: str, options: ReadOptions) -> list[np.ndarray]:
    """The boundaries (:func:`mask_contours`) of the object ``options`` choose in a 2D grey,
    mask or label array (:func:`object_mask`)."""
    return mask_contours(object_mask(grey, name, options), name, options.object)


def object_mask(grey: np.ndarray, name: str, options: ReadOptions) -> np.ndarray:
    """The object's pixels (bool) of a grey, mask or label array of any dimension: those of
    ``options.label``, else of :func:`_image_mask` (``options.threshold``)."""
    if options.label is None:
        return _image_mask(grey, name, options.threshold)
    if options.threshold is not None:
        raise InputFileError(f"{name}: give label= or threshold=, not both")
    return _label_pixels(grey, name, options.label)


def mask_contours(mask: np.ndarray, name: str, choice="largest") -> list[np.ndarray]:
    """The boundaries of the object ``choice`` names among the 4-connected objects of a
    bool mask (every object of :data:`MIN_OBJECT_PIXELS` or more for ``"all"``): its outer
    contour (positive area in ``(x, y) = (column, row)``), then its holes of
    :data:`MIN_HOLE_AREA` or more (negative area, largest first); each (k, 2), sub-pixel
    (marching squares at half level), without closing repeat."""
    from skimage.measure import find_contours

    out = []
    for chosen in choose_objects(mask, choice, name):
        padded = np.pad(chosen, 1).astype(np.float64)  # closes contours at the image's edge
        loops = [c[:-1, ::-1] - 1.0 for c in find_contours(padded, 0.5)]  # (x, y), open
        areas = np.array([area(c) for c in loops])
        order = np.argsort(-np.abs(areas))  # the outer first, then holes, largest first
        holes = [k for k in order[1:] if abs(areas[k]) >= MIN_HOLE_AREA]
        if len(order) - 1 - len(holes):
            _log.info("%s: %d hole(s) under %g px^2 ignored (noise)", name,
                      len(order) - 1 - len(holes), MIN_HOLE_AREA)
        for k, sign in [(order[0], 1.0)] + [(k, -1.0) for k in holes]:
            out.append(loops[k] if sign * areas[k] > 0 else loops[k][::-1])
    return out


def _image_mask(grey: np.ndarray, name: str, threshold: float | None) -> np.ndarray:
    """The object side of a grey or mask array (bool): the brighter of two levels or
    above ``threshold``, flipped when it covers most of the image's border."""
    if grey.dtype.kind == "f" and not np.isfinite(grey).all():
        raise InputFileError(f"{name}: the image has {np.count_nonzero(~np.isfinite(grey))} "
                             f"non-finite (NaN or inf) pixels")
    levels = np.unique(grey)
    if threshold is None:
        if len(levels) > 2:
            from skimage.filters import threshold_otsu

            labels = (f" or, for a label image, label= the object's value (one of "
                      f"{_listed(levels)})" if len(levels) <= MAX_LABELS else "")
            raise InputFileError(f"{name}: a grey-level image ({len(levels)} levels, "
                                 f"{levels[0]}..{levels[-1]}), not a two-level mask: pass a "
                                 f"threshold, e.g. threshold={float(threshold_otsu(grey)):.6g} "
                                 f"(Otsu's){labels}")
        mask = grey == levels[-1]
        if len(levels) == 1:
            raise InputFileError(f"{name}: no object in the image: every pixel is {levels[0]}")
    else:
        mask = grey > threshold
        if mask.all() or not mask.any():
            side = "above" if mask.all() else "at or below"
            raise InputFileError(f"{name}: no object in the image: every pixel is {side} the "
                                 f"threshold {threshold} (levels {levels[0]}..{levels[-1]})")
    interior = np.zeros(mask.shape, dtype=bool)
    interior[(slice(1, -1),) * mask.ndim] = True
    border = mask[~interior]  # each cell on the array's border once, in any dimension
    if 2 * np.count_nonzero(border) > len(border):
        mask = ~mask  # the border is mostly "object": that side is the background
    return mask


def choose_objects(mask: np.ndarray, choice, name: str, connectivity: int = 1,
                   say=None) -> list[np.ndarray]:
    """The pixels (bool, like ``mask``) of the object ``choice`` names among the objects
    of ``mask``, logged; for ``"all"``, of each object of :data:`MIN_OBJECT_PIXELS` or
    more (the largest if none). ``connectivity`` 1 (4-connected: the connectivity of the
    contour, the default) or 2 (8-connected: a myocardial wall one pixel thick in places
    stays one object). ``say``: a callable that takes the sentence naming the choice when
    there are several objects, instead of the log."""
    from scipy import ndimage
    from skimage.measure import label

    labels, count = label(mask, connectivity=connectivity, return_num=True)  # reading order
    index = np.arange(1, count + 1)
    area = np.bincount(labels.ravel(), minlength=count + 1)[1:]
    if isinstance(choice, str) and choice == "all":
        kept = np.flatnonzero(area >= MIN_OBJECT_PIXELS)
        kept = kept if len(kept) else [int(np.argmax(area))]
        _log.info("%s: %d object(s) of %d (%s px)", name, len(kept), count,
                  ", ".join(str(area[k]) for k in kept))
        return [labels == k + 1 for k in kept]
    edge = np.unique(np.concatenate([np.take(labels, [0, -1], axis=a).ravel()
                                     for a in range(labels.ndim)]))  # any dimension
    border = np.isin(index, edge)
    if isinstance(choice, str) and choice == "center":
        centre = np.sqrt(sum((at - (n - 1) / 2) ** 2 for at, n in zip(
            np.indices(mask.shape), mask.shape, strict=True)))
        pick = int(np.argmin(ndimage.minimum(centre, labels, index)))
        why = "nearest the image centre"
    elif isinstance(choice, str):
        pick, why = _largest_object(area, border, name)
    elif choice > count:
        raise InputFileError(f"{name}: object={choice}, but the image has {count} object(s) "
                             f"(numbered 1..{count} in reading order)")
    else:
        pick, why = choice - 1, "as asked"
    where = "touches the image border" if border[pick] else "inside the image"
    sentence = (f"{name}: object {pick + 1} of {count} ({why}): {area[pick]} px, {where}; "
                f"object= chooses another")
    if say is not None and count > 1:
        say(sentence)
    else:
        _log.log(logging.INFO if count > 1 else logging.DEBUG, sentence)  # a choice is said
    return [labels == pick + 1]


def _largest_object(area: np.ndarray, border: np.ndarray, name: str) -> tuple[int, str]:
    """Index of the largest object, preferring one inside the image (see
    :data:`INSIDE_FRACTION`), and why it was chosen."""
    largest = int(np.argmax(area))
    inside = np.flatnonzero(~border)
    if not border[largest] or not len(inside):
        return largest, "the largest"
    best = int(inside[np.argmax(area[inside])])
    if area[best] >= INSIDE_FRACTION * area[largest]:
        _log.warning("%s: object %d touches the image border and is larger (%d px) than "
                     "object %d (%d px) inside the image: taking the one inside; "
                     "object=%d takes the other", name, largest + 1, area[largest], best + 1,
                     area[best], largest + 1)
        return best, "the largest not touching the border"
    return largest, (f"the largest, though it touches the border: the largest object "
                     f"inside, {best + 1}, has {area[best]} px")


def grey_levels(image, name: str = "image") -> np.ndarray:
    """A 2D array of grey levels from a PIL image, or its alpha channel as a 0/1 mask
    when that is a real mask (:func:`_alpha_mask`)."""
    image.seek(0)  # the first frame of a multi-page TIFF or animated GIF
    if "A" in image.getbands():
        mask = _alpha_mask(np.asarray(image.getchannel("A")), name)
        if mask is not None:
            return mask
    if image.mode in ("1", "L", "I", "F") or image.mode.startswith("I;"):
        grey = np.asarray(image)
    else:
        grey = np.asarray(image.convert("L"))
    if grey.dtype == bool:
        grey = grey.astype(np.uint8)  # 1-bit images: levels 0 and 1
    if grey.ndim != 2 or min(grey.shape) < 1:
        raise ValueError(f"expected a 2D image, got an array of shape {grey.shape}")
    return grey


def _alpha_mask(alpha: np.ndarray, name: str) -> np.ndarray | None:
    """Opaque pixels (uint8 0/1) when the alpha channel is a real mask: at least
    :data:`MIN_OBJECT_PIXELS` pixels each side of half opacity and at most
    :data:`MAX_PARTIAL_ALPHA` of the pixels partly transparent; else None (logged)."""
    top = float(np.iinfo(alpha.dtype).max) if alpha.dtype.kind in "iu" else 1.0
    opaque = alpha >= 0.5 * top
    partial = np.count_nonzero((alpha > 0.1 * top) & (alpha < 0.9 * top)) / alpha.size
    n_opaque = int(np.count_nonzero(opaque))
    if min(n_opaque, alpha.size - n_opaque) >= MIN_OBJECT_PIXELS and (
            partial <= MAX_PARTIAL_ALPHA):
        _log.info("%s: the alpha channel is the mask (%d opaque px)", name, n_opaque)
        return opaque.astype(np.uint8)
    _log.info("%s: alpha channel ignored (not a mask: %d of %d px opaque, %.0f %% partly "
              "transparent); reading the grey levels", name, n_opaque, alpha.size,
              100 * partial)
    return None

