"""``modalmorph app``: the method as a local web application.

The user picks two shapes (a bundled example or uploaded files), sets the options
of :func:`modalmorph.match` and :func:`modalmorph.morph` in a form generated from the fields
of their option classes (:data:`modalmorph.apps.runs.FORM_CLASSES`), runs them,
follows its progress and explores the result in the viewer of :mod:`modalmorph.apps.report`.

The server (the ``app`` extra: ``pip install 'modalmorph[app]'``) is uvicorn serving a
Starlette application (:mod:`.server`, :mod:`.routes`): h11's strict HTTP parser,
deadlines for a request's head and body, a listen backlog, a graceful stop on SIGTERM,
SIGINT and SIGHUP that removes the session's temporary folder. It binds to 127.0.0.1 by
default, answers only to loopback names and its own page's origin, and every POST carries
the session's token, which only that page holds (:mod:`.guard`). Every resource is bounded
before it is spent (:mod:`.policy`, :mod:`modalmorph.io.limits`): an upload's size, the
arrays an NPZ inflates to, an image's pixels, JSON depth, nodes, steps, runs at once and
queued; a refusal is a 4xx answer naming the limit.
"""

from __future__ import annotations

import ipaddress
import logging

from .form import morph_options, parse_options
from .policy import APP_LIMITS, AppLimits

__all__ = ["MAX_UPLOAD", "MAX_PIXELS", "MISSING_EXTRA", "make_server", "morph_options",
           "parse_options", "serve"]

log = logging.getLogger(__name__)

# Largest upload and largest image decoded (see AppLimits and modalmorph.io.limits.Limits).
MAX_UPLOAD = APP_LIMITS.files.max_file_bytes
MAX_PIXELS = APP_LIMITS.files.max_pixels
MISSING_EXTRA = ("the web app needs its server (Starlette and uvicorn): "
                 "pip install 'modalmorph[app]'")
_SERVER_PACKAGES = ("starlette", "uvicorn", "h11", "anyio")


def make_server(host: str = "127.0.0.1", port: int = 8765, *,
                limits: AppLimits = APP_LIMITS):
    """The app's server, bound but not yet serving (``port=0``: any free port).

    Returns
    -------
    modalmorph.apps.server.AppServer
        ``serve_forever()``, ``shutdown()``, ``server_close()``, ``server_address``,
        ``url`` and ``token``.

    Raises
    ------
    ImportError
        Without the ``app`` extra (:data:`MISSING_EXTRA`: one line saying what to install).
    OSError
        When the address cannot be bound (the port is in use).
    """
    try:
        from .server import AppServer
    except ImportError as exc:
        if (exc.name or "").split(".")[0] in _SERVER_PACKAGES:
            raise ImportError(MISSING_EXTRA) from None
        raise
    return AppServer(host, port, limits)


def serve(host: str = "127.0.0.1", port: int = 8765, *, open_browser: bool = False
          ) -> int | None:
    """Serve the app until Ctrl-C, SIGTERM or SIGHUP; then cancel the runs and remove
    the temporary folder. Returns the signal that stopped it."""
    server = make_server(host, port)
    if not ipaddress.ip_address(server.server_address[0]).is_loopback:
        log.warning("the app is reachable from other machines at %s: it has no login",
                    server.url)
    log.info("modalmorph app at %s (Ctrl-C to stop)", server.url)
    if open_browser:
        import webbrowser

        webbrowser.open(server.url)
    try:
        server.serve_forever()
    finally:
        server.server_close()
        log.info("modalmorph app stopped")
    return server.stopped_by
