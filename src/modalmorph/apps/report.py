"""The interactive viewer of a result, and the self-contained HTML report built on it.

One page, ``web/viewer.html`` (vanilla JavaScript, no framework, no network), draws a
result given as JSON (:func:`result_payload`): the intermediate shapes with a time
slider and play button, coloured plain, by load or by local strain energy with a colour
bar, the matches, the energy and distance curves, and the load and energy of the node
under the pointer. 2D shapes are drawn in SVG; 3D shapes with three.js (WebGL): surfaces
shaded with their faces, point clouds as points, orbit (drag), zoom (wheel) and pan
(right drag). :func:`render_page` inlines three.js (``web/three.min.js``, see
``web/README.md``) and :func:`write_html` the JSON into the page, giving one file that
opens from disk with no network; :mod:`modalmorph.apps.app` serves the same page with a
form around it.
"""

from __future__ import annotations

import base64
import json
from importlib import resources
from pathlib import Path

import numpy as np

from ..io import atomic_write
from ..options import parameters
from ..version import __version__

__all__ = ["image_data", "image_size", "input_images", "render_page", "result_payload",
           "write_html"]

# The line of viewer.html that receives the result as JSON; ``null`` when the page is
# served by the app, which fetches results instead.
_DATA_SLOT = '<script id="mm-data" type="application/json">null</script>'
# The line of viewer.html that receives three.js (the 3D view), inlined.
_THREE_SLOT = '<script id="three-js"></script>'


def _array(values) -> list:
    """A nested list of floats with non-finite numbers as None (strict JSON)."""
    a = np.asarray(values, dtype=np.float64)
    if np.all(np.isfinite(a)):
        return a.tolist()
    return np.where(np.isfinite(a), a, None).tolist()


def _points(shape) -> list:
    return _array(np.asarray(getattr(shape, "points", shape)))


def image_data(path) -> dict:
    """An image file as the viewer's background: ``{"href": data URL, "width", "height"}``.

    The contour read from an image is in pixel coordinates ``(column, row)``, y down, so
    the image is drawn with its pixel centres on integer coordinates.
    """
    from PIL import Image

    path = Path(path)
    with Image.open(path) as image:
        width, height = image.size
        if image.format != "PNG":  # browsers do not all show TIFF or BMP: send PNG
            import io

            buffer = io.BytesIO()
            image.convert("RGBA" if "A" in image.getbands() else "RGB").save(buffer, "PNG")
            raw = buffer.getvalue()
        else:
            raw = path.read_bytes()
    href = "data:image/png;base64," + base64.b64encode(raw).decode("ascii")
    return {"href": href, "width": width, "height": height}


def image_size(path) -> tuple[int, int] | None:
    """(width, height) when the file is an image Pillow knows, else None (header only)."""
    try:
        from PIL import Image, UnidentifiedImageError
    except ImportError:
        return None
    try:
        with Image.open(path) as image:
            return image.size
    except (UnidentifiedImageError, OSError):
        return None


def input_images(source, target) -> dict:
    """``images`` for :func:`result_payload`: the input files that are images."""
    return {side: image_data(path) for side, path in (("source", source), ("target", target))
            if image_size(path) is not None}


def _track_energy_label(track) -> str:
    """The chart's words for a track's ``energy``: each frame's morph from where it
    started (frame 0, the previous frame, or either: ``track.source_frame``)."""
    source = track.source_frame[1:]
    if not source.any():
        start = track.names[0]
    elif np.array_equal(source, np.arange(len(source))):
        start = "the previous frame"
    else:
        start = f"{track.names[0]} or the previous frame"
    return f"strain energy of each frame's morph from {start} (k_ref L²)"


def result_payload(result, *, title: str | None = None, images: dict | None = None) -> dict:
    """The viewer's JSON for a :class:`~modalmorph.Morph` or a :class:`~modalmorph.Track`.

    Parameters
    ----------
    result : Morph or Track
        A finished morph, or a tracked sequence (its frames are the viewer's steps).
    title : str, optional
        Shown above the viewer.
    images : dict, optional
        ``{"source": image_data(...), "target": ...}``: images drawn under the shapes
        when the inputs were read from images.

    Returns
    -------
    dict
        JSON-ready, with ``kind`` ("morph" or "track"), ``dim``, ``steps`` (T), ``shapes``
        (T+1, m, d), ``node_energy`` (T+1, m), ``energy`` (T+1,), ``mean_distance``
        (T+1,: a morph's mean distance of matched pairs per step, a track's distance of
        the tracked shape to each frame), ``distance`` and ``tolerance`` (a morph's stop
        test, the one ``converged`` reports; None for a track), ``source`` and ``target``
        points with ``source_closed`` and ``target_closed``, ``source_contours`` and
        ``target_contours`` (node counts of their contours, None for one), ``faces`` and
        ``target_faces`` (triangles (f, 3) of 3D surfaces, None for contours and point
        clouds; ``faces`` are those of every drawn shape), ``pairs`` (K, 2),
        ``parameters``, ``converged``,
        ``stop_reason``, ``modalmorph_version`` and ``y_up`` (coordinates not from an
        image or SVG: drawn with y up); for a morph also ``loads``
        (T+1, m, d); for a track ``frames`` (the observed object of every frame),
        ``frame_contours``, ``source_frame`` (the frame each frame's morph started from;
        ``energy`` is that morph's) and ``energy_label`` (what ``energy`` is, for the
        chart).
        Non-finite numbers are None.
    """


    is_track = hasattr(result, "morphs")
    shapes = np.asarray(result.points if is_track else result.shapes, dtype=np.float64)
    if shapes.ndim != 3:
        raise ValueError(f"result must hold shapes of shape (T+1, m, d), got {shapes.shape}")
    payload = {
        "kind": "track" if is_track else "morph",
        "title": title or ("modalmorph track" if is_track else "modalmorph morph"),
        "modalmorph_version": __version__,
        "dim": int(shapes.shape[2]),
        "steps": int(shapes.shape[0] - 1),
        "shapes": _array(shapes),
        "node_energy": _array(result.node_energy),
        "energy": _array(result.energy),
        "parameters": json.loads(json.dumps(result.params if is_track else parameters(result),
                                            default=_json_value)),
        "images": images or {},
    }
    if is_track:
        first, last = result.frames[0], result.frames[-1]
        payload.update(
            mean_distance=_array(result.distance), frames=[_points(f) for f in result.frames],
            frame_contours=[_contours(f) for f in result.frames],
            names=list(result.names), source_frame=result.source_frame.tolist(),
            energy_label=_track_energy_label(result), pairs=[], converged=True, distance=None,
            tolerance=None, stop_reason=f"{result.n_frames} frames of {shapes.shape[1]} nodes")
    else:
        first, last = result.source, result.target
        payload.update(
            mean_distance=_array(result.mean_distance), loads=_array(result.loads),
            pairs=result.matching.pairs.tolist(), distance=_number(result.distance),
            tolerance=_number(result.tolerance), converged=bool(result.converged),
            stop_reason=result.message)
    frame = getattr(last, "frame", None)  # shapes from images (and SVG) are drawn y down
    source = _points(first)
    payload.update(y_up=frame is None or not frame.y_down,
                   unit="input units" if frame is None else frame.unit,
                   source=source, target=_points(last),
                   source_closed=bool(getattr(first, "closed", True)),
                   target_closed=bool(getattr(last, "closed", True)),
                   source_contours=_contours(first), target_contours=_contours(last),
                   # the drawn shapes have the nodes, so the triangles, of the first
                   faces=_faces(first) if len(source) == shapes.shape[1] else None,
                   target_faces=_faces(last))
    return payload


def _contours(shape) -> list | None:
    """The node counts of a shape's contours; None for one contour."""
    contours = getattr(shape, "contours", None)
    return None if contours is None else list(contours)


def _faces(shape) -> list | None:
    """A surface's triangles as nested lists; None for contours and point clouds."""
    faces = getattr(shape, "faces", None)
    return None if faces is None else np.asarray(faces).tolist()


def _number(value) -> float | None:
    value = float(value)
    return value if np.isfinite(value) else None


def _json_value(obj):
    if isinstance(obj, np.generic | np.ndarray):
        return obj.tolist()
    return str(obj)


def render_page(payload: dict | None) -> str:
    """The viewer page with ``payload`` inlined, or empty (``None``) for the app."""
    web = resources.files("modalmorph").joinpath("apps", "web")
    three = web.joinpath("three.min.js").read_text("utf-8")
    page = web.joinpath("viewer.html").read_text("utf-8").replace(
        _THREE_SLOT, f"<script id=\"three-js\">\n{three}</script>", 1)
    if payload is None:
        return page
    # "</script" would end the element and "<!--" would start a comment that swallows
    # it (a file named "<!--<script>.csv" blanked the page): no "<", ">" or "&" is left,
    # each written as the same JSON string's \\u escape
    text = json.dumps(payload, allow_nan=False, separators=(",", ":"))
    text = text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")
    return page.replace(_DATA_SLOT, _DATA_SLOT.replace("null", text), 1)


def write_html(result, path, *, title: str | None = None, images: dict | None = None) -> Path:
    """Write one self-contained HTML file (no network, no server) to view ``result``.

    Parameters
    ----------
    result : Morph or Track
    path : str or os.PathLike
        The ``.html`` file to write.
    title, images : optional
        As in :func:`result_payload`.

    Returns
    -------
    Path
    """
    path = Path(path)
    text = render_page(result_payload(result, title=title, images=images))
    with atomic_write(path) as tmp:
        Path(tmp).write_text(text, encoding="utf-8")
    return path
