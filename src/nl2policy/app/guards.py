"""What stands between the network and the API: a Host check against DNS rebinding, a refusal
of state-changing requests from other sites, security headers, a cap and a deadline on request
bodies, text that must be Unicode, and error bodies that never echo what was sent.

The app listens on loopback by default, but any web page the user visits can make their
browser send requests to it. A page that rebinds its own domain name to 127.0.0.1 reaches the
API with its own name in the Host header, so requests whose Host is not one the server was
started for are refused (400). Bodies are capped (413) before they are read in full, and a
validation error says what was wrong, never the 100 MB that was sent.
"""

from __future__ import annotations

import asyncio
import ipaddress
import json
from typing import Any, Iterable

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException

from nl2policy.limits import clipped

LOOPBACK_HOSTS = ("127.0.0.1", "localhost", "::1")
WILDCARD_HOSTS = ("0.0.0.0", "::", "")
ECHO_LIMIT = 80  # characters of a rejected value that an error may quote


def is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def allowed_hosts_for(bind_host: str, extra: Iterable[str] = ()) -> tuple[str, ...] | None:
    """Host header values to accept when listening on `bind_host`; None accepts any (a server
    bound to every interface with no --allow-host: the user chose to publish it)."""
    names = set(LOOPBACK_HOSTS) | set(extra)
    if bind_host in WILDCARD_HOSTS and not extra:
        return None
    if bind_host not in WILDCARD_HOSTS:
        names.add(bind_host)
    return tuple(sorted(names))


def _host_name(header: str) -> str:
    """'example.com:8000' -> 'example.com', '[::1]:8000' -> '::1'."""
    if header.startswith("["):
        return header[1:].split("]", 1)[0]
    return header.rsplit(":", 1)[0] if header.count(":") == 1 else header


class HostGuard:
    """Refuse requests whose Host header names a host this server was not started for."""

    def __init__(self, app, allowed: tuple[str, ...] | None) -> None:
        self.app, self.allowed = app, None if allowed is None else {h.lower() for h in allowed}

    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] in ("http", "websocket") and self.allowed is not None:
            headers = dict(scope.get("headers") or [])
            host = _host_name(headers.get(b"host", b"").decode("latin-1").strip().lower())
            if host not in self.allowed:
                response = JSONResponse({"detail": "this server answers only to its own address (Host header "
                                                   f"{host[:ECHO_LIMIT]!r} refused); start it with --allow-host to add one"},
                                        status_code=400)
                await response(scope, receive, send)
                return
        await self.app(scope, receive, send)


UNSAFE_METHODS = {"POST", "PUT", "PATCH", "DELETE"}
"""Methods that change state: the ones a page on another site must not be able to send."""
BODY_TIMEOUT_S = 30.0
"""Seconds a request's whole body may take to arrive (a body is at most MAX_BODY_BYTES)."""
SECURITY_HEADERS = [(b"x-content-type-options", b"nosniff"), (b"x-frame-options", b"DENY"),
                    (b"content-security-policy", b"frame-ancestors 'none'"), (b"referrer-policy", b"same-origin")]
"""On every response: no MIME sniffing, no framing by another page (clickjacking), no URLs
leaked to other sites."""


async def _refuse(scope, receive, send, status: int, message: str, where: str = "request") -> None:
    await JSONResponse({"detail": {"message": message, "where": where}}, status_code=status)(scope, receive, send)


def _origin_problem(headers: dict) -> str | None:
    """Why a state-changing request comes from another site, or None. Browsers say where a
    request comes from (Sec-Fetch-Site; Origin on every cross-origin POST, even a "simple"
    text/plain one that needs no preflight); a request from our own pages carries our own
    origin. Clients that are not browsers send neither and are not a cross-site risk."""
    site = headers.get(b"sec-fetch-site", b"").decode("latin-1").lower()
    if site and site not in ("same-origin", "none"):
        return f"cross-site request refused (Sec-Fetch-Site: {site[:20]}): only this app's own pages may change its state"
    origin = headers.get(b"origin")
    if origin is None:
        return None
    origin_text = origin.decode("latin-1").strip().lower()
    host = headers.get(b"host", b"").decode("latin-1").strip().lower()
    if origin_text not in (f"http://{host}", f"https://{host}"):
        return (f"cross-origin request refused (Origin {origin_text[:ECHO_LIMIT]!r} is not this server's "
                f"{host[:ECHO_LIMIT]!r}): only this app's own pages may change its state")
    return None


def _not_unicode(value: Any) -> bool:
    """Whether a parsed JSON value holds a string (or key) that is not valid Unicode."""
    stack = [value]
    while stack:
        item = stack.pop()
        if isinstance(item, str):
            try:
                item.encode("utf-8")
            except UnicodeEncodeError:
                return True
        elif isinstance(item, dict):
            stack.extend(item.keys())
            stack.extend(item.values())
        elif isinstance(item, list):
            stack.extend(item)
    return False


class RequestGuard:
    """The request boundary: security headers on every response; state-changing requests from
    another site refused (403) and their bodies only as JSON (415); bodies capped (413) and
    read in full within a deadline (408) before the app sees them; JSON whose text is not
    Unicode (a lone surrogate escape, "\\ud800") refused (422) without being echoed."""

    def __init__(self, app, limit: int, timeout: float = BODY_TIMEOUT_S) -> None:
        self.app, self.limit, self.timeout = app, limit, timeout

    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def send_secured(message) -> None:
            if message["type"] == "http.response.start":
                names = {k.lower() for k, _ in message.get("headers", [])}
                message = {**message, "headers": list(message.get("headers", []))
                           + [(k, v) for k, v in SECURITY_HEADERS if k not in names]}
            await send(message)

        headers = dict(scope.get("headers") or [])
        unsafe = scope.get("method", "GET").upper() in UNSAFE_METHODS
        if unsafe:
            problem = _origin_problem(headers)
            if problem:
                await _refuse(scope, receive, send_secured, 403, problem)
                return
        length = headers.get(b"content-length")
        if length is not None and (not length.isdigit() or int(length) > self.limit):
            await _refuse(scope, receive, send_secured, 413, f"the request body is larger than the limit of {self.limit:,} bytes",
                          "body")
            return
        has_body = (length is not None and int(length) > 0) or b"transfer-encoding" in headers
        if not has_body:
            await self.app(scope, receive, send_secured)
            return
        kind = headers.get(b"content-type", b"").decode("latin-1").split(";")[0].strip().lower()
        if unsafe and kind != "application/json":
            await _refuse(scope, receive, send_secured, 415, f"send the body as JSON (Content-Type: application/json), "
                                                             f"not {kind[:ECHO_LIMIT] or 'without a type'}", "body")
            return
        body = await self._read(receive)
        if isinstance(body, tuple):
            await _refuse(scope, receive, send_secured, *body)
            return
        if kind == "application/json" and _json_not_unicode(body):
            await _refuse(scope, receive, send_secured, 422, "the request's JSON holds text that is not valid Unicode "
                                                             "(a lone surrogate such as \\ud800); send UTF-8 text", "body")
            return
        sent = False

        async def replayed():
            nonlocal sent
            if not sent:
                sent = True
                return {"type": "http.request", "body": body, "more_body": False}
            return await receive()  # after the body: the disconnect, when it comes

        await self.app(scope, replayed, send_secured)

    async def _read(self, receive) -> bytes | tuple[int, str, str]:
        """The whole body, or (status, message, where) to refuse it: too large, too slow, or the
        client went away."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + self.timeout
        chunks, size = [], 0
        while True:
            try:
                message = await asyncio.wait_for(receive(), max(0.0, deadline - loop.time()))
            except asyncio.TimeoutError:
                return 408, f"the request body did not arrive within {self.timeout:g} s", "body"
            if message["type"] != "http.request":
                return 400, "the client disconnected before sending its whole body", "body"
            chunk = message.get("body", b"")
            size += len(chunk)
            if size > self.limit:
                return 413, f"the request body is larger than the limit of {self.limit:,} bytes", "body"
            chunks.append(chunk)
            if not message.get("more_body", False):
                return b"".join(chunks)


def _json_not_unicode(body: bytes) -> bool:
    try:
        return _not_unicode(json.loads(body))
    except (ValueError, RecursionError):  # not JSON, or nested too deeply: the app's own errors say so
        return False


def printable(text: str) -> str:
    """`text` with anything that is not Unicode (lone surrogates) written as escapes, so an
    error can quote it and still be encoded."""
    return text.encode("utf-8", "backslashreplace").decode("utf-8")


def _short(value: Any) -> Any:
    return printable(clipped(value if isinstance(value, str) else json.dumps(value, default=str), ECHO_LIMIT))


def _trimmed(detail: Any) -> Any:
    """An error detail with every long string cut: messages quote what was sent (an unknown
    domain, an unknown action), and what was sent may be a megabyte."""
    if isinstance(detail, str):
        return printable(clipped(detail))
    if isinstance(detail, dict):
        return {k: _trimmed(v) for k, v in detail.items()}
    if isinstance(detail, list):
        return [_trimmed(v) for v in detail]
    return detail


def install(app: FastAPI, allowed_hosts: tuple[str, ...] | None, max_body: int,
            body_timeout: float = BODY_TIMEOUT_S) -> None:
    """Add the guards and the error handlers that keep error bodies small."""

    @app.exception_handler(RequestValidationError)
    async def validation_error(request: Request, exc: RequestValidationError) -> JSONResponse:
        errors = [{"loc": list(e.get("loc", ())), "msg": e.get("msg", ""), "type": e.get("type", "")}
                  | ({"input": _short(e["input"])} if "input" in e and e["input"] is not None else {})
                  for e in exc.errors()[:20]]
        return JSONResponse({"detail": errors}, status_code=422)

    @app.exception_handler(StarletteHTTPException)
    async def http_error(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        return JSONResponse({"detail": _trimmed(exc.detail)}, status_code=exc.status_code,
                            headers=getattr(exc, "headers", None))

    @app.exception_handler(RecursionError)
    async def too_deep(request: Request, exc: RecursionError) -> JSONResponse:
        return JSONResponse({"detail": {"message": "the JSON is nested too deeply (a tree has at most 3 questions "
                                                   "on a path)", "where": "body"}}, status_code=422)

    app.add_middleware(HostGuard, allowed=allowed_hosts)
    app.add_middleware(RequestGuard, limit=max_body, timeout=body_timeout)  # outermost: its headers go on every response
