"""The web app's limits: what one request, one run and one connection may cost.

Every refusal is a 4xx answer that names the limit (:class:`Refused`); the file limits
(sizes, array shapes, pixels, JSON depth) are :class:`modalmorph.io.limits.Limits`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from http import HTTPStatus

from ..io.limits import Limits

__all__ = ["AppLimits", "APP_LIMITS", "Refused"]


@dataclass(frozen=True)
class AppLimits:
    """The app's bounds, each checked before the resource is spent.

    Attributes
    ----------
    files : Limits
        Uploads: 16 MiB stored, 64 MiB of arrays inflated, 25 Mpixel, JSON 32 deep.
    max_json : int
        Bytes of a JSON request (the options form is under 2 KB).
    max_json_depth : int
        Nesting of a JSON request (the form nests 2 deep).
    max_nodes : int
        Nodes of one shape (the matching is quadratic in them: 5000 x 5000 distances
        are 200 MB).
    max_model_nodes : int
        ``model_nodes`` (the physical model is dense: 1000 2D nodes, four 2000 x 2000
        matrices, 128 MB).
    max_steps : int
        ``max_steps`` of one run.
    max_node_steps : int
        Nodes x ``max_steps`` of one run: the history and the viewer's JSON hold about
        160 bytes per node and step, 40 MB at this bound.
    max_running, max_queued : int
        Runs computed at once (the machine's cores go to BLAS) and runs waiting; beyond
        them a run is refused (429).
    keep : int
        Runs kept, the oldest forgotten (a forgotten run is cancelled).
    keep_shapes : int
        Shapes kept, the oldest forgotten (two per user: 50 users at once; a shape is at
        most 5000 nodes, 80 KB, plus the PNG of an uploaded image).
    job_ttl : float
        Seconds a finished run and its files are kept.
    header_timeout, body_timeout : float
        Seconds for a request's head, and for its body (16 MiB at 1 MB/s is 16 s).
    keep_alive : int
        Seconds an idle kept-alive connection is held.
    backlog, max_connections : int
        Connections waiting to be accepted, and open at once (beyond: 503).
    """

    files: Limits = field(default_factory=Limits)
    max_json: int = 64 * 2**10
    max_json_depth: int = 8
    max_nodes: int = 5000
    max_model_nodes: int = 1000
    max_steps: int = 5000
    max_node_steps: int = 250_000
    max_running: int = 2
    max_queued: int = 8
    keep: int = 16
    keep_shapes: int = 128
    job_ttl: float = 1800.0
    header_timeout: float = 10.0
    body_timeout: float = 60.0
    keep_alive: int = 5
    backlog: int = 512
    max_connections: int = 256


APP_LIMITS = AppLimits()


class Refused(Exception):
    """A request the app will not serve: the status, the message, and the form field or
    limit it names (None: neither)."""

    def __init__(self, status: HTTPStatus, message: str, field: str | None = None):
        super().__init__(message)
        self.status, self.field = status, field
