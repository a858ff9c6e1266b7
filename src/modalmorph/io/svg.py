"""SVG drawings: the outline chosen (the largest), sampled uniformly by arc length.

The outlines are the ``<path>``, ``<polygon>``, ``<polyline>``, ``<circle>``, ``<ellipse>``
and ``<rect>`` elements drawn (not in ``<defs>``; transforms applied), read with
svgelements. Those that draw no shape are passed over: drawn invisibly (no fill and no
stroke, or opacity 0: an icon's bounding box, a figure's transparent background), a first
outline that covers the whole page while others follow (a background), filled in the
page's colour with no stroke (a plot's white axes patch), or straight (ticks, axes). Of
the others, as for images (``ReadOptions.object``), ``"largest"`` takes the one of the
largest bounding box (a plot's curve, not its tick labels), ``"center"`` the one whose box
is centred nearest the page's centre, a number that outline in the order drawn, ``"all"``
every one. The choice is logged when there are several. A path of several subpaths (a
glyph "o" or "B", a ring: an outline and its holes) gives a shape of as many contours, in
the order drawn. Closed if every subpath ends with ``Z``, is a polygon, circle, ellipse or
rect, or ends where it starts; contours mixing closed and open are refused. Coordinates
are the file's user units (before any ``viewBox`` scaling), y pointing down
(:data:`SVG_FRAME`). A drawing of more than
:data:`~modalmorph.io.limits.MAX_SVG_ELEMENTS` elements once each ``<use>`` is expanded
(each draws the element it refers to again: a kilobyte can draw millions) is refused
before it is drawn.
"""

from __future__ import annotations

import logging
import os
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from ..core.shape import ImageFrame
from ..errors import InputFileError
from ..options import ReadOptions
from .base import DEFAULT_NODES, RawShape
from .limits import LimitError, check_svg

__all__ = ["SVG_FRAME", "SVG_SAMPLES", "read_svg"]

# Points per segment when an SVG segment is flattened before arc-length resampling; the
# chord error of a quarter circle sampled this finely is below 1e-4 of its radius.
SVG_SAMPLES = 128

# SVG coordinates are the file's user units, y pointing down (no image to draw under them).
SVG_FRAME = ImageFrame(unit="SVG user units")


# A background covers the page to within this fraction of its size (matplotlib writes its
# figure's patch exactly on the page, to 1e-13 relative).
PAGE_TOLERANCE = 1e-6

# What a viewer shows where an SVG paints nothing (browsers, Inkscape's export, matplotlib's
# savefig: a white page), unless a background outline covers the page.
PAGE_COLOR = "white"

# An outline is a straight line where its points' second singular value is below this
# fraction of the first (rounding of coordinates written to 6 digits: 1e-7 relative).
STRAIGHT = 1e-6

# The outlines read from an SVG, in document order; svgelements gives <circle>, <ellipse>
# and <rect> as paths too.
_SVG_TAGS = ("path", "polygon", "polyline", "circle", "ellipse", "rect")

_log = logging.getLogger(__name__)


def read_svg(path: Path, name: str, options: ReadOptions) -> RawShape:
    """The chosen outline(s) of an SVG file (see the module's docstring)."""
    try:
        import svgelements as se
    except ImportError:
        raise ImportError("reading SVG needs svgelements: pip install 'modalmorph[images]'"
                          ) from None
    try:  # the drawing's size bounded before svgelements expands it (on any thread)
        check_svg(path, name=name)
    except LimitError as exc:
        raise InputFileError(str(exc)) from None
    try:
        svg = se.SVG.parse(os.fspath(path))
    except (ET.ParseError, ValueError) as exc:
        raise InputFileError(f"{name}: not a valid SVG (XML) file: {exc}") from None
    if not isinstance(svg, se.SVG):
        raise InputFileError(f"{name}: not an SVG file (its root element is not <svg>)")
    loops = []
    for element in _chosen(se, svg, name, options.object):
        tag = type(element).__name__.lower()
        _check_svg_source(se, element, f"{name}: <{tag}>")
        if svg.viewbox is not None:  # back from the viewport to the file's user units
            element = element * ~se.Matrix(svg.viewbox_transform)
        drawn = [list(sub) for sub in abs(se.Path(element)).as_subpaths()]  # transformed
        drawn = [segs for segs in drawn  # a lone move, or a subpath of no length: not drawn
                 if len(segs) > 1 and sum(seg.length() for seg in segs) > 0]
        if not drawn:
            raise InputFileError(f"{name}: the <{tag}> read has no segments")
        loops += [_sampled(se, segments) for segments in drawn]
    closed = {c for _, c in loops}
    if len(closed) > 1:
        kinds = ", ".join("closed" if c else "open" for _, c in loops)
        raise InputFileError(f"{name}: the outline read mixes closed and open contours "
                             f"({kinds}): the contours of a shape are all closed or all open")
    pts = [p for p, _ in loops]
    return RawShape(np.vstack(pts), closed=closed.pop(), frame=SVG_FRAME,
                    default_nodes=DEFAULT_NODES,
                    contours=tuple(map(len, pts)) if len(pts) > 1 else None)


def _chosen(se, svg, name: str, choice) -> list:
    """The outline(s) read: of those that draw a shape (:func:`_shapes`), ``choice``."""
    shapes, drawn = _shapes(se, svg, name)
    if choice == "all":
        return shapes
    boxes = np.array([e.bbox() or (0.0,) * 4 for e in shapes], dtype=float)
    if choice == "center":
        centre = (np.array([svg.width or 0.0, svg.height or 0.0]) / 2 if svg.width
                  and svg.height else (boxes[:, :2].min(0) + boxes[:, 2:].max(0)) / 2)
        pick = int(np.argmin(np.hypot(*((boxes[:, :2] + boxes[:, 2:]) / 2 - centre).T)))
        why = "centred nearest the page's centre"
    elif isinstance(choice, str):
        pick = int(np.argmax(np.prod(boxes[:, 2:] - boxes[:, :2], axis=1)))
        why = "the largest"
    elif choice > len(shapes):
        raise InputFileError(f"{name}: object={choice}, but the file draws {len(shapes)} "
                             f"outline(s) of a shape (numbered 1..{len(shapes)} in the "
                             f"order drawn)")
    else:
        pick, why = choice - 1, "as asked"
    if len(drawn) > 1:
        w, h = boxes[pick, 2:] - boxes[pick, :2]  # in the viewport (px): in user units
        if svg.viewbox is not None:  # (the results' units) as read, below
            scale = se.Matrix(svg.viewbox_transform)
            w, h = w / abs(scale.a), h / abs(scale.d)
        _log.info("%s: outline %d of %d drawing a shape (%s): <%s> %.4g x %.4g; %d drawing "
                  "none passed over; object= chooses another", name, pick + 1, len(shapes),
                  why, type(shapes[pick]).__name__.lower(), w, h, len(drawn) - len(shapes))
    return [shapes[pick]]


def _shapes(se, svg, name: str) -> tuple[list, list]:
    """The outlines that draw a shape, in the order drawn (all outlines if none does), and
    all outlines drawn."""
    kinds = tuple(getattr(se, tag.capitalize()) for tag in _SVG_TAGS)
    drawn = [e for e in svg.elements() if isinstance(e, kinds)]  # not <defs>
    if not drawn:
        raise InputFileError(f"{name}: no {', '.join(f'<{t}>' for t in _SVG_TAGS[:-1])} or "
                             f"<{_SVG_TAGS[-1]}> element")
    shown = [e for e in drawn if _shows(e)] or drawn  # nothing shows: all drawn
    page = se.Color(PAGE_COLOR)
    if len(shown) > 1 and _covers_page(svg, shown[0]):
        page, shown = (shown[0].fill if _paints(shown[0].fill) else page), shown[1:]
    # filled in the page's colour with no stroke (a plot's white axes patch on its white
    # figure), or a straight line (a tick, an axis): no shape to see
    shown = [e for e in shown if not (_in_page_color(e, page) or _straight(se, e))] or shown
    return shown, drawn


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

    width = element.stroke_width or 0.0
    return _paints(element.fill) or (_paints(element.stroke) and width > 0)


def _paints(color) -> bool:
    """Whether a fill or stroke colour paints anything."""
    return color is not None and color.value is not None and color.alpha > 0


def _in_page_color(element, page) -> bool:
    """Whether an outline is filled in the page's colour ``page`` and not stroked."""
    fill, width = element.fill, element.stroke_width or 0.0
    return (_paints(fill) and (fill.red, fill.green, fill.blue) == (page.red, page.green,
            page.blue) and not (_paints(element.stroke) and width > 0))


def _straight(se, element) -> bool:
    """Whether an outline lies on one straight line (its points' second singular value
    within ``STRAIGHT`` of the first)."""
    t = np.linspace(0.0, 1.0, 5)
    pts = [seg.npoint(t) for seg in abs(se.Path(element))
           if seg.start is not None and seg.end is not None]
    if not pts:
        return False
    pts = np.vstack(pts)
    s = np.linalg.svd(pts - pts.mean(axis=0), compute_uv=False)
    return bool(s[1] <= STRAIGHT * s[0])


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
    tol = 1e-12 * np.abs(pts).max()  # a circle's closing arc ends 4e-15 from its start
    keep = np.r_[True, np.any(np.abs(np.diff(pts, axis=0)) > tol, axis=1)]
    pts = pts[keep]  # zero-length segments add nothing to the outline
    if len(pts) > 1 and np.allclose(pts[0], pts[-1], rtol=0, atol=tol):
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

