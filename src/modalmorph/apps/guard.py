"""Who may talk to the app, and how much they may send: the Host, Origin and
Sec-Fetch-Site of every request, the session's token on every state-changing one, and
request bodies read against a size and a deadline (Starlette requests)."""

from __future__ import annotations

import hmac
import ipaddress
import json
from dataclasses import replace
from http import HTTPStatus

import anyio
from starlette.requests import Request

from ..io.limits import LimitError, check_json
from .policy import APP_LIMITS, AppLimits, Refused

__all__ = ["TOKEN_HEADER", "allowed_host", "check_request", "read_body", "read_json"]

# The header that carries the session's token: a custom header cannot be sent across
# sites without a CORS preflight, which the app never grants.
TOKEN_HEADER = "X-Modalmorph-Token"
_SAFE = ("GET", "HEAD")
# Sec-Fetch-Site values of a request the app's own page (or the user, typing the address)
# makes; "same-site" is another port of the same host: another origin, refused.
_OWN_FETCH = ("same-origin", "none")


def allowed_host(host: str, address: tuple) -> bool:
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


def check_request(request: Request, address: tuple, token: str) -> None:
    """:class:`Refused`: 400 for a request with both a length and a transfer coding; 403
    for a foreign Host, a foreign Origin, a cross-site fetch, or a
    state-changing request without the session's token."""
    if "content-length" in request.headers and "transfer-encoding" in request.headers:
        raise Refused(HTTPStatus.BAD_REQUEST, "both Content-Length and Transfer-Encoding: "
                      "refused (the two could be read differently on the way)")
    host = request.headers.get("host", "")
    if not allowed_host(host, address):
        raise Refused(HTTPStatus.FORBIDDEN, "unexpected Host header")
    origin = request.headers.get("origin")
    if origin is not None and origin != f"http://{host}":
        raise Refused(HTTPStatus.FORBIDDEN, f"cross-site request refused: Origin {origin!r} "
                      "is not the app's own page")
    site = request.headers.get("sec-fetch-site")
    if site is not None and site not in _OWN_FETCH:
        raise Refused(HTTPStatus.FORBIDDEN, f"cross-site request refused (Sec-Fetch-Site: "
                      f"{site})")
    if request.method not in _SAFE:
        given = request.headers.get(TOKEN_HEADER, "")
        if not hmac.compare_digest(given.encode(), token.encode()):
            raise Refused(HTTPStatus.FORBIDDEN, f"missing or wrong {TOKEN_HEADER}: only the "
                          "app's own page may change its state")


async def read_body(request: Request, limit: int, limits: AppLimits = APP_LIMITS) -> bytes:
    """The body, refused (413, naming ``limit``) before it is read when its announced
    length is too large, and (408) when it is not sent within ``body_timeout``."""
    length = request.headers.get("content-length")
    if length is None or not length.isdigit():  # h11 refuses negative and malformed ones
        raise Refused(HTTPStatus.LENGTH_REQUIRED, "the request has no Content-Length")
    if int(length) > limit:
        raise Refused(HTTPStatus.REQUEST_ENTITY_TOO_LARGE, f"the file is too large: "
                      f"{int(length)} bytes, the limit is {limit} bytes", "max_upload")
    chunks, size = [], 0
    try:
        with anyio.fail_after(limits.body_timeout):
            async for chunk in request.stream():
                size += len(chunk)
                if size > limit:  # cannot happen with a strict parser; kept as a bound
                    raise Refused(HTTPStatus.REQUEST_ENTITY_TOO_LARGE,
                                  f"the body is longer than {limit} bytes", "max_upload")
                chunks.append(chunk)
    except TimeoutError:
        raise Refused(HTTPStatus.REQUEST_TIMEOUT, f"the body was not sent within "
                      f"{limits.body_timeout:g} s (body_timeout limit)") from None
    return b"".join(chunks)


async def read_json(request: Request, limits: AppLimits = APP_LIMITS) -> dict:
    """A JSON object of at most ``max_json`` bytes nested at most ``max_json_depth``."""
    raw = await read_body(request, limits.max_json, limits)
    try:
        check_json(raw, "the request", _json_limits(limits))
        obj = json.loads(raw or b"{}")
    except LimitError as exc:
        raise Refused(HTTPStatus.REQUEST_ENTITY_TOO_LARGE, str(exc), exc.limit) from None
    except (ValueError, RecursionError) as exc:
        raise Refused(HTTPStatus.BAD_REQUEST, f"not JSON: {exc}") from None
    if not isinstance(obj, dict):
        raise Refused(HTTPStatus.BAD_REQUEST, "expected a JSON object")
    return obj


def _json_limits(limits: AppLimits):
    return replace(limits.files, max_file_bytes=limits.max_json,
                   max_json_depth=limits.max_json_depth)
