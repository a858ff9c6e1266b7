"""SVG drawings: the first outline drawn, sampled uniformly by arc length.

The first ``<path>``, ``<polygon>``, ``<polyline>``, ``<circle>``, ``<ellipse>`` or
``<rect>`` drawn (not in ``<defs>``; transforms applied), read with svgelements. Outlines
drawn invisibly (no fill and no stroke, or opacity 0: an icon's bounding box, a figure's
transparent background) and a first outline that covers the whole page while others
follow (a background) are passed over, with a warning. A path of
several subpaths (a glyph "o" or "B", a ring: an outline and its holes) gives a shape of
as many contours, in the order drawn. Closed if every subpath ends with ``Z``, is a
polygon, circle, ellipse or rect, or ends where it starts; a path mixing closed and open
subpaths is refused. Coordinates are the file's user units (before any ``viewBox``
scaling), y pointing down (:data:`SVG_FRAME`).
"""

from __future__ import annotations

import os
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from ..core.shape import ImageFrame
from ..errors import InputFileError
from ..options import ReadOptions
from .base import DEFAULT_NODES, RawShape

__all__ = ["SVG_FRAME", "SVG_SAMPLES", "read_svg"]

# Points per segment when an SVG segment is flattened before arc-length resampling; the
# chord error of a quarter circle sampled this finely is below 1e-4 of its radius.
SVG_SAMPLES = 128

# SVG coordinates are the file's user units, y pointing down (no image to draw under them).
SVG_FRAME = ImageFrame(unit="SVG user units")


# A background covers the page to within this fraction of its size (matplotlib writes its
# figure's patch exactly on the page, to 1e-13 relative).
PAGE_TOLERANCE = 1e-6

# The outlines read from an SVG, in document order; svgelements gives <circle>, <ellipse>
# and <rect> as paths too.
_SVG_TAGS = ("path", "polygon", "polyline", "circle", "ellipse", "rect")


def read_svg(path: Path, name: str, options: ReadOptions) -> RawShape:
    """The first outline drawn in an SVG file (see the module's docstring)."""
    try:
        import svgelements as se
    except ImportError:
        raise ImportError("reading SVG needs svgelements: pip install 'modalmorph[images]'"
                          ) from None
    try:
        svg = se.SVG.parse(os.fspath(path))
    except (ET.ParseError, ValueError) as exc:
        raise InputFileError(f"{name}: not a valid SVG (XML) file: {exc}") from None
    if not isinstance(svg, se.SVG):
        raise InputFileError(f"{name}: not an SVG file (its root element is not <svg>)")
    element = _first_outline(se, svg, name)
    tag = type(element).__name__.lower()
    _check_svg_source(se, element, f"{name}: <{tag}>")
    if svg.viewbox is not None:  # back from the viewport to the file's user units
        element = element * ~se.Matrix(svg.viewbox_transform)
    drawn = [list(sub) for sub in abs(se.Path(element)).as_subpaths()]  # transforms applied
    drawn = [segs for segs in drawn if len(segs) > 1]
    if not drawn:
        raise InputFileError(f"{name}: the first <{tag}> has no segments")
    loops = [_sampled(se, segments) for segments in drawn]
    closed = {c for _, c in loops}
    if len(closed) > 1:
        kinds = ", ".join("closed" if c else "open" for _, c in loops)
        raise InputFileError(f"{name}: the <{tag}> mixes closed and open subpaths ({kinds}): "
                             f"the contours of a shape are all closed or all open")
    pts = [p for p, _ in loops]
    return RawShape(np.vstack(pts), closed=closed.pop(), frame=SVG_FRAME,
                    default_nodes=DEFAULT_NODES,
                    contours=tuple(map(len, pts)) if len(pts) > 1 else None)


def _first_outline(se, svg, name: str):
    """The first outline drawn that shows (see the module's docstring)."""
    kinds = tuple(getattr(se, tag.capitalize()) for tag in _SVG_TAGS)
    drawn = [e for e in svg.elements() if isinstance(e, kinds)]  # not <defs>
    if not drawn:
        raise InputFileError(f"{name}: no {', '.join(f'<{t}>' for t in _SVG_TAGS[:-1])} or "
                             f"<{_SVG_TAGS[-1]}> element")
    shown = [e for e in drawn if _shows(e)] or drawn  # nothing shows: the first drawn
    if len(shown) > 1 and _covers_page(svg, shown[0]):
        shown = shown[1:]
    if shown[0] is not drawn[0]:
        skipped = drawn.index(shown[0])
        warnings.warn(f"{name}: passed over {skipped} outline(s) drawn invisibly or as the "
                      f"page's background", stacklevel=4)
    return shown[0]


def _shows(element) -> bool:
    """Whether an outline is drawn visibly: some opacity, and a fill or a stroke."""
    values = element.values
    if values.get("visibility") == "hidden" or values.get("display") == "none":
        return False
    try:
        if float(values.get("opacity", 1.0)) <= 0:
            return False
    except ValueError:
        pass  # an opacity that is not a number: as browsers, ignored

    def paints(color) -> bool:
        return color is not None and color.value is not None and color.alpha > 0

    width = element.stroke_width or 0.0
    return paints(element.fill) or (paints(element.stroke) and width > 0)


def _covers_page(svg, element) -> bool:
    """Whether an outline's bounding box covers the whole page (a background)."""
    box = element.bbox()
    if box is None or not svg.width or not svg.height:
        return False
    tol = PAGE_TOLERANCE * max(svg.width, svg.height)
    x0, y0, x1, y1 = box
    return x0 <= tol and y0 <= tol and x1 >= svg.width - tol and y1 >= svg.height - tol


def _sampled(se, segments) -> tuple[np.ndarray, bool]:
    """One subpath's points, :data:`SVG_SAMPLES` per segment, and whether it closes."""
    t = np.linspace(0.0, 1.0, SVG_SAMPLES + 1)[1:]
    pts = np.vstack([np.array(segments[0].end)[None]]
                    + [seg.npoint(t) for seg in segments[1:]])
    closed = isinstance(segments[-1], se.Close)
    keep = np.r_[True, np.any(np.diff(pts, axis=0) != 0, axis=1)]
    pts = pts[keep]  # zero-length segments add nothing to the outline
    if len(pts) > 1 and np.allclose(pts[0], pts[-1], rtol=0, atol=1e-12 * np.abs(pts).max()):
        pts, closed = pts[:-1], True  # ends where it starts
    return pts, closed


def _check_svg_source(se, element, where: str) -> None:
    """Raise for what svgelements, like a browser, skips: bad path data, points, transforms."""
    d = element.values.get("d")
    if d is not None:
        lexer = se.SVGLexicalParser()
        try:
            lexer.parse(se.Path(), d)
            ok = not d[lexer.pos:].strip(" \t\r\n,")
        except ValueError:
            ok = False
        if not ok:
            raise InputFileError(f"{where}: malformed path data at character {lexer.pos} of d: "
                                 f"{d[lexer.pos:lexer.pos + 10] or 'the end'!r}")
        if d.strip()[:1] not in ("M", "m"):
            raise InputFileError(f"{where}: path data must start with M or m, got {d[:20]!r}")
    for attr, grammar in (("points", se.REGEX_COORD_PAIR),
                          ("transform", se.REGEX_TRANSFORM_TEMPLATE)):
        rest = grammar.sub(" ", element.values.get(attr, "").lower()).strip(" \t\r\n,")
        if rest:
            raise InputFileError(f"{where}: cannot read {rest[:20]!r} in {attr!r}")

