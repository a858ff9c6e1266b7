"""The app's server: uvicorn (h11's strict HTTP/1.1 parser) serving the Starlette app of
:mod:`.routes`, with a deadline for each request's head, a real listen backlog, a cap on
open connections, and a graceful shutdown on SIGTERM, SIGINT and SIGHUP that cancels the
runs and removes the session's temporary folder."""

from __future__ import annotations

import signal
import socket
import tempfile
import threading
from contextlib import contextmanager

import h11
import uvicorn
from uvicorn.protocols.http.h11_impl import H11Protocol

from .policy import APP_LIMITS, AppLimits
from .routes import AppState, build_app

__all__ = ["AppServer", "SIGNALS"]

# The signals that stop the app gracefully (Ctrl-C, kill, the terminal closed).
SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
# Longest head of a request (h11's default too): the request line and the headers.
_MAX_HEAD = 16 * 2**10
# Seconds the server waits for open connections at shutdown before closing them.
_GRACE = 5


def _protocol(header_timeout: float):
    """uvicorn's h11 protocol, with a deadline for a request's head: a connection that has
    not sent a whole head ``header_timeout`` s after it opened or after its last answer is
    closed (a slow or idle client holds no slot)."""

    class Protocol(H11Protocol):
        def connection_made(self, transport):
            super().connection_made(transport)
            self._arm()

        def on_response_complete(self):
            super().on_response_complete()
            self._arm()

        def _arm(self):
            self._head_since = self.loop.time()
            self.loop.call_later(header_timeout, self._check_head)

        def _check_head(self):
            waiting = self.conn.their_state is h11.IDLE  # no whole head since _arm
            late = self.loop.time() - self._head_since >= header_timeout * 0.999
            if waiting and late and not self.transport.is_closing():
                self.transport.close()

    return Protocol


def _bind(host: str, port: int, backlog: int) -> socket.socket:
    """A listening TCP socket (OSError, e.g. the port in use, is the caller's)."""
    sock = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((host, port))
        sock.listen(backlog)
    except OSError:
        sock.close()
        raise
    return sock


class _Uvicorn(uvicorn.Server):
    """uvicorn's server, stopping on :data:`SIGNALS` and returning (not re-raising them),
    so that the caller cleans up and exits normally."""

    @contextmanager
    def capture_signals(self):
        if threading.current_thread() is not threading.main_thread():
            yield
            return
        previous = {sig: signal.signal(sig, self._stop) for sig in SIGNALS}
        try:
            yield
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, handler)

    stopped_by: int | None = None  # the signal that stopped it

    def _stop(self, sig, frame) -> None:
        self.force_exit = self.should_exit  # a second signal: do not wait for connections
        self.should_exit = True
        self.stopped_by = sig


class AppServer:
    """One session of the app: a socket bound now, served by :meth:`serve_forever`,
    stopped by :meth:`shutdown` (or a signal in the main thread), cleaned by
    :meth:`server_close`.

    Attributes
    ----------
    server_address : (str, int)
        Host and port bound (``port=0``: a free port).
    url : str
        The page's address.
    token : str
        The session's token (the page holds it; every POST must send it).
    tmp : tempfile.TemporaryDirectory
        Uploads and run files; removed by :meth:`server_close`.
    """

    def __init__(self, host: str = "127.0.0.1", port: int = 8765,
                 limits: AppLimits = APP_LIMITS):
        self.socket = _bind(host, port, limits.backlog)
        self.server_address = self.socket.getsockname()[:2]
        self.tmp = tempfile.TemporaryDirectory(prefix="modalmorph-app-")
        config = uvicorn.Config(
            None, host=host, port=port, http=_protocol(limits.header_timeout),
            lifespan="off", backlog=limits.backlog, timeout_keep_alive=limits.keep_alive,
            limit_concurrency=limits.max_connections, h11_max_incomplete_event_size=_MAX_HEAD,
            timeout_graceful_shutdown=_GRACE, log_config=None, log_level="warning",
            access_log=False, server_header=False)
        self.state = AppState(self.server_address, self.tmp.name, limits)
        config.app = build_app(self.state)
        self.token = self.state.token
        name = "localhost" if host == "127.0.0.1" else host
        self.url = f"http://{name}:{self.server_address[1]}/"
        self._server = _Uvicorn(config)
        self._done = threading.Event()

    def serve_forever(self) -> None:
        """Serve until :meth:`shutdown` or, in the main thread, one of :data:`SIGNALS`."""
        try:
            self._server.run(sockets=[self.socket])
        finally:
            self._done.set()

    @property
    def stopped_by(self) -> int | None:
        """The signal that stopped :meth:`serve_forever` (None: :meth:`shutdown`)."""
        return self._server.stopped_by

    def shutdown(self, timeout: float = 30.0) -> None:
        """Stop serving and wait (at most ``timeout`` s) for :meth:`serve_forever`."""
        self._server.should_exit = True
        self._done.wait(timeout)

    def server_close(self) -> None:
        """Cancel the runs, close the socket, remove the temporary folder."""
        self.state.jobs.close()
        self.socket.close()
        self.tmp.cleanup()
