"""What stands between the network and the API: a Host check against DNS rebinding, a cap on
request bodies, and error bodies that never echo what was sent.

The app listens on loopback by default, but any web page the user visits can make their
browser send requests to it. A page that rebinds its own domain name to 127.0.0.1 reaches the
API with its own name in the Host header, so requests whose Host is not one the server was
started for are refused (400). Bodies are capped (413) before they are read in full, and a
validation error says what was wrong, never the 100 MB that was sent.
"""

from __future__ import annotations

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


class BodyLimit:
    """Refuse request bodies larger than `limit` bytes with 413: by Content-Length when given,
    else by reading the chunks (at most `limit` bytes are ever held) before the app sees them."""

    def __init__(self, app, limit: int) -> None:
        self.app, self.limit = app, limit

    async def _refuse(self, scope, receive, send) -> None:
        response = JSONResponse({"detail": f"the request body is larger than the limit of {self.limit:,} bytes"},
                                status_code=413)
        await response(scope, receive, send)

    async def __call__(self, scope, receive, send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        length = dict(scope.get("headers") or []).get(b"content-length")
        if length is not None:
            if not length.isdigit() or int(length) > self.limit:
                await self._refuse(scope, receive, send)
            else:
                await self.app(scope, receive, send)
            return
        chunks, size = [], 0
        while True:  # no Content-Length (chunked): read it here, counting
            message = await receive()
            if message["type"] != "http.request":
                chunks.append(message)
                break
            size += len(message.get("body", b""))
            if size > self.limit:
                await self._refuse(scope, receive, send)
                return
            chunks.append(message)
            if not message.get("more_body", False):
                break
        replay = iter(chunks)

        async def replayed():
            return next(replay, None) or await receive()

        await self.app(scope, replayed, send)


def _short(value: Any) -> Any:
    return clipped(value if isinstance(value, str) else json.dumps(value, default=str), ECHO_LIMIT)


def _trimmed(detail: Any) -> Any:
    """An error detail with every long string cut: messages quote what was sent (an unknown
    domain, an unknown action), and what was sent may be a megabyte."""
    if isinstance(detail, str):
        return clipped(detail)
    if isinstance(detail, dict):
        return {k: _trimmed(v) for k, v in detail.items()}
    if isinstance(detail, list):
        return [_trimmed(v) for v in detail]
    return detail


def install(app: FastAPI, allowed_hosts: tuple[str, ...] | None, max_body: int) -> None:
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

    app.add_middleware(BodyLimit, limit=max_body)
    app.add_middleware(HostGuard, allowed=allowed_hosts)
