"""The app's HTTP API on Starlette: each route checks who asks (:mod:`.guard`), bounds what
it is asked (:mod:`.policy`, :mod:`modalmorph.io.limits`), then does the work off the
event loop.

``GET /`` (the page, with the session's token), ``GET /api/schema`` (the form), ``GET
/api/examples``, ``POST /api/example`` ``{"name"}``, ``POST
/api/upload?name=&threshold=&nodes=`` (the file as the body), ``POST /api/run``
``{"source", "target", "options"}`` -> ``{"job"}``, ``GET /api/job/<id>`` (state, step,
distance, error), ``GET /api/job/<id>/result`` (the viewer's JSON), ``GET
/api/job/<id>/file/<name>`` (downloads), ``POST /api/job/<id>/stop``. Every POST carries
the token in :data:`~modalmorph.apps.guard.TOKEN_HEADER`.
"""

from __future__ import annotations

import asyncio
import html
import json
import logging
import secrets
import threading
import uuid
from concurrent.futures import Future
from http import HTTPStatus
from pathlib import Path

import anyio
import numpy as np
from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import HTMLResponse, Response
from starlette.routing import Route

from ..io import SUPPORTED_EXTENSIONS, extension, read_shape
from ..io import limits as file_limits
from ..io.limits import LimitError
from .form import check_run, examples, field_of, morph_options, parse_options
from .guard import check_request, read_body, read_json
from .jobs import Job, Jobs
from .policy import APP_LIMITS, AppLimits, Refused
from .report import image_data, render_page

__all__ = ["AppState", "build_app"]

log = logging.getLogger(__name__)

_HEADERS = {"Cache-Control": "no-store", "X-Content-Type-Options": "nosniff",
            "X-Frame-Options": "DENY", "Referrer-Policy": "no-referrer"}
# The page runs its own inline script and talks to its own origin only.
_PAGE_POLICY = ("default-src 'none'; script-src 'unsafe-inline'; style-src 'unsafe-inline'; "
                "img-src data: blob:; connect-src 'self'; form-action 'none'; "
                "frame-ancestors 'none'; base-uri 'none'")
_TOKEN_SLOT = '<meta name="mm-token" content="">'
_TYPES = {".json": "application/json", ".csv": "text/csv", ".png": "image/png",
          ".gif": "image/gif", ".html": "text/html; charset=utf-8"}


class AppState:
    """What one app session holds: its token, its folder, its shapes and runs."""

    def __init__(self, address: tuple, folder: Path, limits: AppLimits = APP_LIMITS):
        self.address, self.folder, self.limits = address, Path(folder), limits
        self.token = secrets.token_urlsafe(32)
        self.shapes: dict[str, dict] = {}
        self.lock = threading.Lock()
        self.jobs = Jobs(self.folder, limits)
        self.readers = anyio.CapacityLimiter(limits.max_running)  # uploads parsed at once
        self.writers = anyio.CapacityLimiter(1)  # matplotlib draws one figure at a time

    def keep_shape(self, shape, name: str, image) -> dict:
        sid = uuid.uuid4().hex
        with self.lock:
            self.shapes[sid] = dict(shape=shape, name=name, image=image)
            while len(self.shapes) > self.limits.keep_shapes:
                self.shapes.pop(next(iter(self.shapes)))
        pts = np.asarray(shape.points)
        return {"id": sid, "name": name, "points": pts.tolist(), "dim": int(pts.shape[1]),
                "closed": bool(shape.closed), "image": image,
                "contours": None if shape.contours is None else list(shape.contours),
                "faces": None if shape.faces is None else shape.faces.tolist(),
                "y_up": shape.frame is None or not shape.frame.y_down}


def _json(obj, status=HTTPStatus.OK) -> Response:
    return Response(json.dumps(obj, allow_nan=False), status, _HEADERS,
                    media_type="application/json")


def _refusal(request: Request, status, message: str, field=None) -> Response:
    """The JSON answer of a refusal. A body left unread is discarded by the server as it
    arrives (never read as a request); one announced over 8 uploads, or chunked, is not
    waited for."""
    response = _json({"error": message, "field": field}, status)
    length = request.headers.get("content-length", "")
    limit = request.app.state.session.limits.files.max_file_bytes
    if (length.isdigit() and int(length) > 8 * limit) \
            or "transfer-encoding" in request.headers:
        response.headers["Connection"] = "close"
    return response


def _guarded(endpoint):
    """The route with the checks of :func:`check_request` first, and every refusal or bad
    input as a 4xx JSON ``{"error", "field"}`` (a 500 only for a bug, logged)."""

    async def route(request: Request) -> Response:
        state: AppState = request.app.state.session
        try:
            check_request(request, state.address, state.token)
            return await endpoint(request, state)
        except Refused as exc:
            return _refusal(request, exc.status, str(exc), exc.field)
        except LimitError as exc:
            return _refusal(request, HTTPStatus.REQUEST_ENTITY_TOO_LARGE, str(exc), exc.limit)
        except (ValueError, OSError, ImportError) as exc:  # a bad input: say why
            return _refusal(request, HTTPStatus.BAD_REQUEST, str(exc).splitlines()[0])
        except Exception as exc:
            log.exception("request failed")
            return _refusal(request, HTTPStatus.INTERNAL_SERVER_ERROR,
                            f"internal error: {type(exc).__name__}")

    return route


async def _page(request: Request, state: AppState) -> Response:
    page = render_page(None).replace(
        _TOKEN_SLOT, f'<meta name="mm-token" content="{html.escape(state.token)}">', 1)
    return HTMLResponse(page, headers={**_HEADERS, "Content-Security-Policy": _PAGE_POLICY})


async def _schema(request: Request, state: AppState) -> Response:
    return _json(morph_options())


async def _examples(request: Request, state: AppState) -> Response:
    return _json([{"name": k, "label": v[0]} for k, v in examples().items()])


async def _example(request: Request, state: AppState) -> Response:
    name = (await read_json(request, state.limits)).get("name")
    known = examples()
    if not isinstance(name, str) or name not in known:
        raise Refused(HTTPStatus.BAD_REQUEST, f"no example {name!r}; "
                      f"choose one of {sorted(known)}")
    source, target = known[name][1]()
    return _json({"source": state.keep_shape(source, f"{name} source", None),
                  "target": state.keep_shape(target, f"{name} target", None)})


def _query_number(query, key: str, kind, low, high):
    text = query.get(key, "").strip()
    if not text:
        return None
    try:
        value = kind(text)
    except ValueError:
        raise Refused(HTTPStatus.BAD_REQUEST, f"{key} must be a number, got {text!r}",
                      key) from None
    if not low <= value <= high:
        raise Refused(HTTPStatus.BAD_REQUEST, f"{key} must be in [{low}, {high}], got "
                      f"{value}", key)
    return value


def _read_upload(path: Path, name: str, nodes, threshold, limits: AppLimits):
    """The shape and its picture from a stored upload, every header checked first."""
    suffix = extension(path)
    if suffix == ".npy":
        file_limits.check_npy(path, limits.files)
    elif suffix == ".npz":
        file_limits.check_npz(path, limits.files)
    elif suffix == ".json":
        file_limits.check_json(path.read_bytes(), name, limits.files)
    elif suffix in (".nii", ".nii.gz"):
        file_limits.check_nifti(path, limits.files)
    elif suffix == ".svg":
        file_limits.check_svg(path, limits.files, name)
    image = file_limits.check_image(path, limits.files)
    shape = read_shape(path, nodes=nodes, threshold=threshold if image is not None else None)
    if shape.m > limits.max_nodes:
        raise Refused(HTTPStatus.REQUEST_ENTITY_TOO_LARGE, f"{name}: {shape.m} nodes, the "
                      f"limit (max_nodes) is {limits.max_nodes}: pass nodes= to resample",
                      "max_nodes")
    try:  # the background is a nicety: a shape without it is still a shape
        picture = image_data(path) if image is not None else None
    except (OSError, ValueError):
        picture = None
    return shape, picture


async def _on_daemon_thread(limiter: anyio.CapacityLimiter, function, *args):
    """``function(*args)`` on a daemon thread of its own, at most ``limiter``'s tokens at
    once. A read runs off the main thread, where no alarm can stop it; the process
    must still exit at Ctrl-C or SIGTERM while one runs (anyio's worker threads are joined
    at exit: a read that never ended held the stopped app alive)."""
    async with limiter:
        future: Future = Future()

        def work():
            if future.set_running_or_notify_cancel():
                try:
                    future.set_result(function(*args))
                except BaseException as exc:  # noqa: BLE001 - handed to the request
                    future.set_exception(exc)

        threading.Thread(target=work, name="modalmorph reader", daemon=True).start()
        try:
            return await asyncio.wrap_future(future)
        except asyncio.CancelledError:  # the server stops: answered, the read left behind
            raise Refused(HTTPStatus.SERVICE_UNAVAILABLE, "the app is stopping: the file was "
                          "not read") from None


async def _upload(request: Request, state: AppState) -> Response:
    query = request.query_params
    name = Path(query.get("name", "")).name
    suffix = extension(name)  # .nii.gz whole
    if suffix not in SUPPORTED_EXTENSIONS:
        raise Refused(HTTPStatus.BAD_REQUEST, f"{name or 'the file'}: unsupported file type "
                      f"{suffix!r}; supported: {', '.join(SUPPORTED_EXTENSIONS)}")
    limits = state.limits
    nodes = _query_number(query, "nodes", int, 3, limits.max_nodes)
    threshold = _query_number(query, "threshold", float, -1e300, 1e300)
    data = await read_body(request, limits.files.max_file_bytes, limits)
    path = state.folder / f"{uuid.uuid4().hex}{suffix}"
    path.write_bytes(data)
    try:
        shape, picture = await _on_daemon_thread(
            state.readers, _read_upload, path, name, nodes, threshold, limits)
    except (ValueError, OSError) as exc:  # the reader names the temporary file: use the user's
        text = str(exc).replace(str(path), name).replace(path.name, name)
        if isinstance(exc, LimitError):
            raise LimitError(text, exc.limit) from None
        raise ValueError(text) from None
    finally:
        path.unlink(missing_ok=True)
    return _json(state.keep_shape(shape, name, picture))


def _options(body: dict) -> dict:
    options = body.get("options") or {}
    if not isinstance(options, dict) or not all(
            isinstance(v, str | bool | int | float) for v in options.values()):
        raise Refused(HTTPStatus.BAD_REQUEST, "options must be an object of option names to "
                      "text, numbers or booleans")
    return options


async def _run(request: Request, state: AppState) -> Response:
    body = await read_json(request, state.limits)
    with state.lock:
        shapes = [state.shapes.get(str(body.get(side))) for side in ("source", "target")]
    if None in shapes:
        raise Refused(HTTPStatus.BAD_REQUEST, "choose the source and the target shapes first")
    try:
        settings = parse_options(_options(body))
    except ValueError as exc:
        raise Refused(HTTPStatus.BAD_REQUEST, str(exc), field_of(str(exc))) from None
    src, tgt = shapes
    check_run(settings, max(src["shape"].m, tgt["shape"].m), state.limits)
    images = {k: s["image"] for k, s in zip(("source", "target"), shapes, strict=True)
              if s["image"]}
    jid = state.jobs.submit(src["shape"], tgt["shape"], settings,
                            f"{src['name']} → {tgt['name']}", images)
    return _json({"job": jid})


def _job(request: Request, state: AppState) -> Job:
    job = state.jobs.get(request.path_params["job"])
    if job is None:
        raise Refused(HTTPStatus.NOT_FOUND, "no such run (the server keeps the last "
                      f"{state.limits.keep}, each for {state.limits.job_ttl:g} s)")
    return job


async def _status(request: Request, state: AppState) -> Response:
    return _json(_job(request, state).status())


async def _result(request: Request, state: AppState) -> Response:
    job = _job(request, state)
    if job.payload is None:
        raise Refused(HTTPStatus.CONFLICT, f"the run is {job.state}")
    text = await anyio.to_thread.run_sync(json.dumps, job.payload)
    return Response(text, 200, _HEADERS, media_type="application/json")


async def _file(request: Request, state: AppState) -> Response:
    job, name = _job(request, state), request.path_params["name"]
    try:
        path = await anyio.to_thread.run_sync(job.file, name, limiter=state.writers)
        data = path.read_bytes()
    except FileNotFoundError:
        raise Refused(HTTPStatus.NOT_FOUND, f"no file {name!r}") from None
    return Response(data, 200, {**_HEADERS,
                                "Content-Disposition": f'attachment; filename="{path.name}"'},
                    media_type=_TYPES.get(path.suffix, "application/octet-stream"))


async def _stop(request: Request, state: AppState) -> Response:
    job = _job(request, state)
    await read_json(request, state.limits)
    job.cancel("stopped by the user")
    return _json(job.status())


async def _missing(request: Request, state: AppState) -> Response:
    raise Refused(HTTPStatus.NOT_FOUND, f"no such page: {request.url.path}")


def build_app(state: AppState) -> Starlette:
    """The Starlette application of one session."""
    routes = [Route("/", _guarded(_page)),
              Route("/api/schema", _guarded(_schema)),
              Route("/api/examples", _guarded(_examples)),
              Route("/api/example", _guarded(_example), methods=["POST"]),
              Route("/api/upload", _guarded(_upload), methods=["POST"]),
              Route("/api/run", _guarded(_run), methods=["POST"]),
              Route("/api/job/{job}", _guarded(_status)),
              Route("/api/job/{job}/result", _guarded(_result)),
              Route("/api/job/{job}/file/{name}", _guarded(_file)),
              Route("/api/job/{job}/stop", _guarded(_stop), methods=["POST"]),
              Route("/{path:path}", _guarded(_missing), methods=["GET", "POST", "HEAD"])]
    app = Starlette(routes=routes)
    app.state.session = state
    return app
