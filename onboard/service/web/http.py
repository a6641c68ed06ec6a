"""A small asyncio HTTP/1.1 server: enough for one page and its JSON API.

GET, HEAD and POST; the request line and headers within :data:`MAX_HEAD_BYTES`, a body
of at most :data:`MAX_BODY_BYTES` (``Content-Length``, no chunked uploads); one request
per connection (``Connection: close``), every response with its ``Content-Length`` and
``Cache-Control: no-store``. A client that sends nothing for :data:`READ_TIMEOUT_S` is
dropped, and beyond :data:`MAX_CLIENTS` connections at once a new one is closed
unanswered (idle clients cannot pile up in the service's loop). Handlers are plain
functions of :class:`Request` returning :class:`Response`; one that raises answers 500
(logged), so the page can never stop the process that serves it. No dependency beyond the standard library: the vehicle install stays lean.
"""

from __future__ import annotations

import asyncio
import logging
from dataclasses import dataclass, field
from typing import Callable
from urllib.parse import parse_qs, unquote, urlsplit

log = logging.getLogger(__name__)

MAX_HEAD_BYTES = 16384
MAX_BODY_BYTES = 262144
READ_TIMEOUT_S = 10.0
MAX_CLIENTS = 32
REASONS = {200: "OK", 400: "Bad Request", 404: "Not Found", 405: "Method Not Allowed",
           413: "Payload Too Large", 422: "Unprocessable Content", 500: "Internal Server Error"}


@dataclass
class Request:
    """One request: ``path`` without the query, ``query`` its first values."""

    method: str
    path: str
    query: dict[str, str] = field(default_factory=dict)
    headers: dict[str, str] = field(default_factory=dict)
    body: bytes = b""


@dataclass
class Response:
    """One response."""

    status: int = 200
    body: bytes = b""
    content_type: str = "text/plain; charset=utf-8"


Handler = Callable[[Request], Response]


class HttpError(Exception):
    """A request that cannot be served: answered with ``status`` and the message."""

    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status = status


def parse_head(head: bytes) -> Request:
    """The request line and headers (ending in a blank line) as a Request without body."""
    try:
        lines = head.decode("latin-1").split("\r\n")
        method, target, version = lines[0].split(" ")
    except ValueError:
        raise HttpError(400, "malformed request line") from None
    if not version.startswith("HTTP/1."):
        raise HttpError(400, f"unsupported {version}")
    headers: dict[str, str] = {}
    for line in lines[1:]:
        if line:
            name, sep, value = line.partition(":")
            if not sep:
                raise HttpError(400, "malformed header")
            headers[name.strip().lower()] = value.strip()
    url = urlsplit(target)
    query = {k: v[0] for k, v in parse_qs(url.query).items()}
    return Request(method, unquote(url.path) or "/", query, headers)


def encode_response(resp: Response, head_only: bool = False) -> bytes:
    """The response's bytes (status line, headers, body unless ``head_only``)."""
    head = (f"HTTP/1.1 {resp.status} {REASONS.get(resp.status, 'Error')}\r\n"
            f"Content-Type: {resp.content_type}\r\nContent-Length: {len(resp.body)}\r\n"
            "Cache-Control: no-store\r\nConnection: close\r\n\r\n")
    return head.encode("latin-1") + (b"" if head_only else resp.body)


def parse_listen(listen: str) -> tuple[str, int]:
    """``HOST:PORT`` (``[::1]:8110`` for IPv6) as (host, port); ValueError otherwise."""
    host, sep, port = listen.rpartition(":")
    if not sep or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise ValueError(f"{listen!r}: expected HOST:PORT")
    return host.strip("[]") or "0.0.0.0", int(port)


class HttpServer:
    """Serves ``routes`` (``(method, path) -> handler``; HEAD uses the GET handler).

    Parameters:
        routes: the handlers.
        host, port: where to listen (port 0: any free port, see :attr:`port`).
    """

    def __init__(self, routes: dict[tuple[str, str], Handler], host: str, port: int) -> None:
        self.routes = routes
        self.host = host
        self.port = port
        self.served = 0
        """Requests answered."""
        self.refused = 0
        """Connections closed unanswered because :data:`MAX_CLIENTS` were open."""
        self._active = 0
        self._server: asyncio.AbstractServer | None = None

    async def start(self) -> None:
        """Listen; :attr:`port` is then the port bound."""
        self._server = await asyncio.start_server(self._client, self.host, self.port,
                                                  limit=MAX_HEAD_BYTES)
        self.port = self._server.sockets[0].getsockname()[1]

    async def close(self) -> None:
        """Stop listening and wait for the connections being served."""
        if self._server is not None:
            self._server.close()
            await self._server.wait_closed()
            self._server = None

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        if self._active >= MAX_CLIENTS:
            self.refused += 1
            writer.close()
            return
        self._active += 1
        try:
            await self._serve(reader, writer)
        finally:
            self._active -= 1

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        head_only = False
        try:
            async with asyncio.timeout(READ_TIMEOUT_S):
                req = await self._read(reader)
            head_only = req.method == "HEAD"
            resp = self.dispatch(req)
        except HttpError as err:
            resp = Response(err.status, str(err).encode())
        except (TimeoutError, asyncio.IncompleteReadError, ConnectionError):
            writer.close()
            return
        try:
            writer.write(encode_response(resp, head_only))
            await writer.drain()
            self.served += 1
        except ConnectionError:
            pass
        finally:
            writer.close()

    @staticmethod
    async def _read(reader: asyncio.StreamReader) -> Request:
        try:
            head = await reader.readuntil(b"\r\n\r\n")
        except asyncio.LimitOverrunError:
            raise HttpError(400, "request head too large") from None
        req = parse_head(head[:-4])
        try:
            length = int(req.headers.get("content-length", "0"))
        except ValueError:
            raise HttpError(400, "bad Content-Length") from None
        if length > MAX_BODY_BYTES:
            raise HttpError(413, f"body over {MAX_BODY_BYTES} bytes")
        if length:
            req.body = await reader.readexactly(length)
        return req

    def dispatch(self, req: Request) -> Response:
        """The handler's response to ``req`` (404/405 when none, 500 when it raises)."""
        method = "GET" if req.method == "HEAD" else req.method
        handler = self.routes.get((method, req.path))
        if handler is None:
            known = any(path == req.path for _, path in self.routes)
            return Response(405 if known else 404, b"method not allowed" if known else b"not found")
        try:
            return handler(req)
        except HttpError as err:
            return Response(err.status, str(err).encode())
        except Exception:  # noqa: BLE001 - a page bug must not stop the service
            log.exception("web: %s %s failed", req.method, req.path)
            return Response(500, b"internal error: see the log")
