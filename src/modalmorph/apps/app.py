"""``modalmorph app``: the method as a local web application.

The user picks two shapes (a bundled example or uploaded files), sets the options
of :func:`modalmorph.match` and :func:`modalmorph.morph` in a form generated from the fields
of their option classes (:data:`modalmorph.apps.runs.FORM_CLASSES`), runs them,
follows its progress and explores the result in the viewer of :mod:`modalmorph.apps.report`.

The server is the standard library's :class:`http.server.ThreadingHTTPServer`: no
dependency beyond the readers', nothing leaves the machine, it binds to localhost by
default and answers only requests addressed to the name it was bound to. Uploads are read
into memory up to :data:`MAX_UPLOAD` bytes, written to a private temporary folder under
a random name with the file's extension, parsed by :func:`modalmorph.read_shape` (never
executed) and deleted.

HTTP API (JSON): ``GET /api/schema`` (the form), ``GET /api/examples``, ``POST
/api/example`` ``{"name"}``, ``POST /api/upload?name=&threshold=&nodes=`` (the file as the
body), ``POST /api/run`` ``{"source", "target", "options"}`` -> ``{"job"}``, ``GET
/api/job/<id>`` (state, step, distance, error), ``GET /api/job/<id>/result`` (the viewer's
JSON), ``GET /api/job/<id>/file/<name>`` (downloads), ``POST /api/job/<id>/stop``.
"""

from __future__ import annotations

import ipaddress
import json
import logging
import re
import tempfile
import threading
import uuid
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from urllib.parse import parse_qs, urlsplit

import numpy as np

from .. import figures
from ..datasets import hand_shape, heart_shape
from ..io import SUPPORTED_EXTENSIONS, read_shape, save_result
from ..options import flat_fields
from .report import image_data, image_size, render_page, result_payload, write_html
from .runs import FORM_CLASSES, Settings, compute_morph, default_text

__all__ = ["MAX_UPLOAD", "MAX_PIXELS", "make_server", "morph_options", "parse_options",
           "serve"]

log = logging.getLogger(__name__)

# Largest upload: a 4000 x 4000 8-bit grey PNG is at most 16 MB uncompressed, and a CSV
# of 100 000 2D nodes about 4 MB.
MAX_UPLOAD = 16 * 2**20
# Largest image decoded (width x height): 25 Mpixel grey is 25 MB in memory before the
# contour is traced (about 2 s on this machine for a mask of that size).
MAX_PIXELS = 25_000_000
# Largest JSON request body (the options form is under 2 KB).
_MAX_JSON = 64 * 2**10
# Shapes and runs kept in memory, the oldest forgotten beyond this count (a run of 1000
# nodes and 100 steps holds about 10 MB of viewer JSON).
_KEEP = 16
_FILES = ("morph.json", "result.json", "shapes.npz", "final_shape.csv", "report.html",
          "shapes_plain.png", "shapes_load.png", "shapes_energy.png", "matches.png",
          "energy.png", "morph.gif")


# ------------------------------------------------------------------------ the form


def morph_options() -> list[dict]:
    """The form: one entry per option of :data:`modalmorph.apps.runs.FORM_CLASSES` (matching,
    physics, loads and time integration, stopping), by flat name.

    Generated from the fields' metadata, so that a new option appears in the form by
    itself. Each entry has ``name``, ``group``, ``kind`` ("bool", "choice" or "text"),
    ``default`` (JSON), ``default_text`` (as typed in the form), ``choices`` (or None),
    ``summary`` (the help's first sentence) and ``help``.
    """
    options = []
    for name, cls, f in flat_fields(FORM_CLASSES):
        meta = f.metadata
        choices = list(meta["choices"]) if meta["kind"] == "str" and meta["choices"] \
            else None
        kind = "bool" if meta["kind"] == "bool" else "choice" if choices else "text"
        default = cls().record()[f.name]
        text = default_text(f)
        summary = re.split(r"(?<=\.)\s", meta["help"], maxsplit=1)[0]
        options.append(dict(name=name, group=meta["group"], kind=kind, default=default,
                            default_text=text, choices=choices, summary=summary,
                            help=meta["help"]))
    return options


def parse_options(values: dict) -> Settings:
    """The run's settings from the form's values (text, or booleans for check boxes).

    An empty field takes the default; text is parsed as on the command line
    (:func:`modalmorph.options.parse_value`: ``40``, ``2/3``, ``0.5 1``, ``rubber``,
    ``1e5 0.3 1000``).

    Raises
    ------
    OptionError
        For an unknown option or an invalid value (the message names the option).
    """
    given = {name: value for name, value in values.items()
             if not (isinstance(value, str) and not value.strip())}
    return Settings.from_flat(given, FORM_CLASSES, where="options")


def _examples() -> dict:
    """The bundled pairs, as in ``modalmorph demo``."""
    return {
        "heart": ("heart: left ventricle, end-diastole -> end-systole",
                  lambda: (heart_shape("diastole"), heart_shape("systole"))),
        "hands": ("hands: hand 0 (120 nodes) -> hand 3 (140 nodes)",
                  lambda: (hand_shape(0, 120), hand_shape(3, 140))),
    }


# -------------------------------------------------------------------------- jobs


class _Stopped(Exception):
    """Raised from the progress callback when the user presses Stop."""


class _Job:
    """One run of morph() in a thread, with its progress and, at the end, its files."""

    def __init__(self, source, target, settings: Settings, folder: Path, title: str,
                 images: dict):
        self.source, self.target, self.settings = source, target, settings
        self.folder, self.title, self.images = folder, title, images
        self.state, self.step, self.distance = "running", 0, None
        self.error = self.field = self.result = self.payload = None
        self.stop = threading.Event()
        self.lock = threading.Lock()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _progress(self, step: int, distance: float) -> None:
        self.step, self.distance = step, distance
        if self.stop.is_set():
            raise _Stopped(f"stopped by the user at step {step}")

    def _run(self) -> None:
        try:
            result = compute_morph(self.source, self.target, self.settings,
                                   progress=self._progress)
            self.payload = result_payload(result, title=self.title, images=self.images)
            self.result, self.state = result, "done"
        except (ValueError, ArithmeticError, _Stopped) as exc:  # MorphDivergedError too
            self.error, self.state = str(exc).splitlines()[0], "error"
            self.field = _field_of(self.error)
        except Exception as exc:  # reported to the page, logged in full here
            log.exception("morph failed")
            self.error, self.state = f"internal error: {type(exc).__name__}: {exc}", "error"

    def status(self) -> dict:
        return dict(state=self.state, step=self.step, distance=self.distance,
                    max_steps=self.settings.morph.max_steps, error=self.error,
                    field=self.field, files=list(_FILES) if self.state == "done" else [])

    def file(self, name: str) -> Path:
        """Write (once) and return a download."""
        if name not in _FILES or self.state != "done":
            raise FileNotFoundError(name)
        path = self.folder / name
        with self.lock:
            if not path.exists():
                self._write(name)
        return path

    def _write(self, name: str) -> None:
        r, out = self.result, self.folder
        if name == "morph.json":
            (out / name).write_text(json.dumps(self.payload, allow_nan=False), "utf-8")
        elif name in ("result.json", "shapes.npz", "final_shape.csv"):
            save_result(r, out,
                        options=self.settings.record(FORM_CLASSES))
        elif name == "report.html":
            write_html(r, out / name, title=self.title, images=self.images)
        elif name == "morph.gif":
            figures.animate(r, out / name)
        else:
            figures.save_figures(r, out, formats=("png",), dpi=120)


def _field_of(message: str) -> str | None:
    """The option a message names first (option messages start with the name)."""
    names = [o["name"] for o in morph_options()]
    words = re.findall(r"\w+", message)
    return next((w for w in words[:3] if w in names), None)


# ------------------------------------------------------------------------- server


class _Server(ThreadingHTTPServer):
    daemon_threads = True

    def __init__(self, address):
        super().__init__(address, _Handler)
        self.tmp = tempfile.TemporaryDirectory(prefix="modalmorph-app-")
        self.shapes: dict[str, dict] = {}
        self.jobs: dict[str, _Job] = {}
        self.lock = threading.Lock()

    def keep(self, table: dict, key: str, value) -> None:
        with self.lock:
            table[key] = value
            while len(table) > _KEEP:
                table.pop(next(iter(table)))

    def server_close(self):
        super().server_close()
        self.tmp.cleanup()


class _HTTPError(Exception):
    def __init__(self, status: HTTPStatus, message: str, field: str | None = None):
        super().__init__(message)
        self.status, self.field = status, field


class _Handler(BaseHTTPRequestHandler):
    server: _Server
    protocol_version = "HTTP/1.1"

    def log_message(self, format, *args):  # noqa: A002 (the base class's name)
        log.debug("%s " + format, self.address_string(), *args)

    # --- plumbing
    def _send(self, status, body: bytes, ctype: str, extra: dict | None = None):
        self.send_response(status)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.send_header("X-Content-Type-Options", "nosniff")
        for key, value in (extra or {}).items():
            self.send_header(key, value)
        self.end_headers()
        self.wfile.write(body)

    def _json(self, obj, status=HTTPStatus.OK):
        self._send(status, json.dumps(obj, allow_nan=False).encode(), "application/json")

    def _body(self, limit: int) -> bytes:
        try:
            length = int(self.headers.get("Content-Length", ""))
        except ValueError:
            raise _HTTPError(HTTPStatus.LENGTH_REQUIRED, "the request has no length") from None
        if length > limit:
            self.close_connection = True
            if length <= 8 * limit:  # read it, so the browser gets the message
                while length > 0:
                    length -= len(self.rfile.read(min(length, 2**20)) or b"x" * length)
            raise _HTTPError(HTTPStatus.REQUEST_ENTITY_TOO_LARGE,
                             f"the file is too large: {int(self.headers['Content-Length'])} "
                             f"bytes, the limit is {limit} bytes")
        return self.rfile.read(length)

    def _dispatch(self, method: str):
        try:
            if not _allowed_host(self.headers.get("Host", ""), self.server.server_address):
                raise _HTTPError(HTTPStatus.FORBIDDEN, "unexpected Host header")
            url = urlsplit(self.path)
            parts = [p for p in url.path.split("/") if p]
            api = parts[:1] == ["api"] and len(parts) > 1
            route = getattr(self, f"_{method}_{parts[1] if api else 'page'}", None)
            if route is None or (parts and parts[0] != "api"):
                raise _HTTPError(HTTPStatus.NOT_FOUND, f"no such page: {url.path}")
            route(parts[2:], parse_qs(url.query))
        except _HTTPError as exc:
            self._json({"error": str(exc), "field": exc.field}, exc.status)
        except (ValueError, OSError, ImportError) as exc:  # a bad input: say why
            self._json({"error": str(exc).splitlines()[0]}, HTTPStatus.BAD_REQUEST)
        except Exception as exc:
            log.exception("request failed")
            self._json({"error": f"internal error: {type(exc).__name__}"},
                       HTTPStatus.INTERNAL_SERVER_ERROR)

    def do_GET(self):  # noqa: N802 (the base class's name)
        self._dispatch("get")

    def do_POST(self):  # noqa: N802
        self._dispatch("post")

    def _read_json(self) -> dict:
        try:
            obj = json.loads(self._body(_MAX_JSON) or b"{}")
        except json.JSONDecodeError as exc:
            raise _HTTPError(HTTPStatus.BAD_REQUEST, f"not JSON: {exc}") from None
        if not isinstance(obj, dict):
            raise _HTTPError(HTTPStatus.BAD_REQUEST, "expected a JSON object")
        return obj

    # --- routes
    def _get_page(self, rest, query):
        self._send(HTTPStatus.OK, render_page(None).encode(), "text/html; charset=utf-8")

    def _get_schema(self, rest, query):
        self._json(morph_options())

    def _get_examples(self, rest, query):
        self._json([{"name": k, "label": v[0]} for k, v in _examples().items()])

    def _post_example(self, rest, query):
        name = self._read_json().get("name")
        examples = _examples()
        if name not in examples:
            raise _HTTPError(HTTPStatus.BAD_REQUEST, f"no example {name!r}; "
                             f"choose one of {sorted(examples)}")
        source, target = examples[name][1]()
        self._json({"source": self._store(source, f"{name} source", None),
                    "target": self._store(target, f"{name} target", None)})

    def _post_upload(self, rest, query):
        q = {k: v[0].strip() for k, v in query.items()}
        name = Path(q.get("name", "")).name
        suffix = Path(name).suffix.lower()
        if suffix not in SUPPORTED_EXTENSIONS:
            raise _HTTPError(HTTPStatus.BAD_REQUEST,
                             f"{name or 'the file'}: unsupported file type {suffix!r}; "
                             f"supported: {', '.join(SUPPORTED_EXTENSIONS)}")
        data = self._body(MAX_UPLOAD)
        threshold = float(q["threshold"]) if q.get("threshold") else None
        nodes = int(q["nodes"]) if q.get("nodes") else None
        path = Path(self.server.tmp.name) / f"{uuid.uuid4().hex}{suffix}"
        path.write_bytes(data)
        try:
            image = image_size(path)
            if image is not None and image[0] * image[1] > MAX_PIXELS:
                raise _HTTPError(HTTPStatus.REQUEST_ENTITY_TOO_LARGE,
                                 f"{name}: the image is too large: {image[0]} x {image[1]} "
                                 f"pixels, the limit is {MAX_PIXELS} pixels")
            try:
                shape = read_shape(path, nodes=nodes,
                                   threshold=threshold if image is not None else None)
            except ValueError as exc:  # the reader names the temporary file: use the user's
                raise ValueError(str(exc).replace(str(path), name).replace(path.name, name)) \
                    from None
            try:  # the background is a nicety: a shape without it is still a shape
                picture = image_data(path) if image is not None else None
            except (OSError, ValueError):
                picture = None
        finally:
            path.unlink(missing_ok=True)
        self._json(self._store(shape, name, picture))

    def _store(self, shape, name: str, image) -> dict:
        sid = uuid.uuid4().hex
        self.server.keep(self.server.shapes, sid, dict(shape=shape, name=name, image=image))
        pts = np.asarray(shape.points)
        return {"id": sid, "name": name, "points": pts.tolist(), "dim": int(pts.shape[1]),
                "closed": bool(shape.closed), "image": image,
                "faces": None if shape.faces is None else shape.faces.tolist(),
                "y_up": shape.frame is None or not shape.frame.y_down}

    def _post_run(self, rest, query):
        body = self._read_json()
        shapes = [self.server.shapes.get(str(body.get(side))) for side in ("source", "target")]
        if None in shapes:
            raise _HTTPError(HTTPStatus.BAD_REQUEST,
                             "choose the source and the target shapes first")
        try:
            settings = parse_options(body.get("options") or {})
        except ValueError as exc:
            raise _HTTPError(HTTPStatus.BAD_REQUEST, str(exc),
                             _field_of(str(exc))) from None
        src, tgt = shapes
        images = {k: s["image"] for k, s in zip(("source", "target"), shapes, strict=True)
                  if s["image"]}
        jid = uuid.uuid4().hex
        folder = Path(self.server.tmp.name) / jid
        folder.mkdir()
        job = _Job(src["shape"], tgt["shape"], settings, folder, f"{src['name']} → {tgt['name']}",
                   images)
        self.server.keep(self.server.jobs, jid, job)
        self._json({"job": jid})

    def _job(self, rest) -> _Job:
        job = self.server.jobs.get(rest[0]) if rest else None
        if job is None:
            raise _HTTPError(HTTPStatus.NOT_FOUND, "no such run (the server keeps the last "
                             f"{_KEEP})")
        return job

    def _get_job(self, rest, query):
        job = self._job(rest)
        if rest[1:] == ["result"]:
            if job.payload is None:
                raise _HTTPError(HTTPStatus.CONFLICT, f"the run is {job.state}")
            self._json(job.payload)
        elif len(rest) == 3 and rest[1] == "file":
            try:
                path = job.file(rest[2])
            except FileNotFoundError:
                raise _HTTPError(HTTPStatus.NOT_FOUND, f"no file {rest[2]!r}") from None
            types = {".json": "application/json", ".csv": "text/csv", ".png": "image/png",
                     ".gif": "image/gif", ".html": "text/html; charset=utf-8"}
            self._send(HTTPStatus.OK, path.read_bytes(),
                       types.get(path.suffix, "application/octet-stream"),
                       {"Content-Disposition": f'attachment; filename="{path.name}"'})
        elif len(rest) == 1:
            self._json(job.status())
        else:
            raise _HTTPError(HTTPStatus.NOT_FOUND, f"no such page: {self.path}")

    def _post_job(self, rest, query):
        job = self._job(rest)
        self._read_json()
        if rest[1:] != ["stop"]:
            raise _HTTPError(HTTPStatus.NOT_FOUND, "no such action")
        job.stop.set()
        self._json(job.status())


def _allowed_host(host: str, address) -> bool:
    """A loopback server answers only to loopback names (no DNS rebinding)."""
    if not ipaddress.ip_address(address[0]).is_loopback:
        return True
    name = host.strip("[]") if host.endswith("]") else host.rsplit(":", 1)[0].strip("[]")
    if name == "localhost":
        return True
    try:
        return ipaddress.ip_address(name).is_loopback
    except ValueError:
        return False


def make_server(host: str = "127.0.0.1", port: int = 8765) -> ThreadingHTTPServer:
    """The app's server, bound but not yet serving (``port=0``: any free port)."""
    return _Server((host, port))


def serve(host: str = "127.0.0.1", port: int = 8765, *, open_browser: bool = False) -> None:
    """Serve the app until interrupted (Ctrl-C)."""
    server = make_server(host, port)
    url = f"http://{'localhost' if host == '127.0.0.1' else host}:{server.server_address[1]}/"
    if not ipaddress.ip_address(server.server_address[0]).is_loopback:
        log.warning("the app is reachable from other machines at %s: it has no login", url)
    log.info("modalmorph app at %s (Ctrl-C to stop)", url)
    if open_browser:
        import webbrowser

        webbrowser.open(url)
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        server.server_close()
