"""What stands between the network and the routes: ASGI middleware that refuses a request before
the application spends anything on it.

- HostAllowList: the Host header must name this server (localhost, 127.0.0.1, [::1], the bound
  host, or an --allowed-host). A web page on another site that re-points its DNS name at
  127.0.0.1 (DNS rebinding) sends its own name as Host and gets a 400.
- BodyGuard: a request body is read here, up to max_bytes of bytes actually received whatever
  Content-Length or Transfer-Encoding claim (413 and the connection closed past that), within
  body_timeout_s from the end of the headers (408 and closed after it: a client trickling a body
  cannot hold a worker). Content-Length together with Transfer-Encoding is refused (400): the pair
  is the request-smuggling pattern, and no honest client sends both. The body is then handed to the
  application from memory.

The header phase has its own deadline in server.py (uvicorn has none for a request's headers).
"""

from __future__ import annotations

import asyncio
import json



def host_name(header: str) -> str:
    """'Example.org:8000' -> 'example.org', '[::1]:8000' -> '::1'."""
    header = header.strip().lower()
    if header.startswith("["):
        return header[1:header.find("]")] if "]" in header else header
    return header.rsplit(":", 1)[0] if header.count(":") == 1 else header


async def _reply(send, status: int, detail: str, close: bool = False) -> None:
    body = json.dumps({"detail": detail}).encode()
    headers = [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode())]
    if close:
        headers.append((b"connection", b"close"))
    await send({"type": "http.response.start", "status": status, "headers": headers})
    await send({"type": "http.response.body", "body": body})


class HostAllowList:
    """400 unless the Host header names one of `allowed` (host names, without port); "*" allows any."""

    def __init__(self, app, allowed):
        self.app, self.allowed = app, {host_name(h) for h in allowed}

    async def __call__(self, scope, receive, send):
        if scope["type"] == "http" and "*" not in self.allowed:
            host = dict(scope["headers"]).get(b"host", b"").decode("latin-1")
            if host_name(host) not in self.allowed:
                return await _reply(send, 400, f"Host {host[:100]!r} is not served here (allowed: "
                                               f"{', '.join(sorted(self.allowed))}; see --allowed-host)", close=True)
        await self.app(scope, receive, send)


class BodyGuard:
    """Reads every request body itself, bounded in bytes and time (module docstring)."""

    def __init__(self, app, max_bytes: int, body_timeout_s: float):
        self.app, self.max_bytes, self.body_timeout_s = app, max_bytes, body_timeout_s

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http" or scope["method"] in ("GET", "HEAD", "OPTIONS"):
            return await self.app(scope, receive, send)
        headers = scope["headers"]
        lengths = [v for k, v in headers if k == b"content-length"]
        if lengths and any(k == b"transfer-encoding" for k, _ in headers):
            return await _reply(send, 400, "body: Content-Length and Transfer-Encoding together", close=True)
        if len(lengths) > 1 or (lengths and not lengths[0].isdigit()):
            return await _reply(send, 400, "body: one Content-Length with a number is expected", close=True)
        if lengths and int(lengths[0]) > self.max_bytes:
            return await _reply(send, 413, f"body: {int(lengths[0])} bytes, at most {self.max_bytes}", close=True)
        body = await self._read(receive, send)
        if body is None:
            return
        replayed = False

        async def replay():
            nonlocal replayed
            if not replayed:
                replayed = True
                return {"type": "http.request", "body": body, "more_body": False}
            return await receive()  # after the body: only http.disconnect comes

        await self.app(scope, replay, send)

    async def _read(self, receive, send) -> bytes | None:
        """The whole body, or None once an error reply was sent (or the client left)."""
        loop = asyncio.get_running_loop()
        deadline = loop.time() + self.body_timeout_s
        chunks, size = [], 0
        while True:
            try:
                message = await asyncio.wait_for(receive(), max(0.0, deadline - loop.time()))
            except TimeoutError:
                await _reply(send, 408, f"body: not received within {self.body_timeout_s:g} s", close=True)
                return None
            if message["type"] == "http.disconnect":
                return None
            chunk = message.get("body", b"")
            size += len(chunk)
            if size > self.max_bytes:
                await _reply(send, 413, f"body: more than {self.max_bytes} bytes", close=True)
                return None
            chunks.append(chunk)
            if not message.get("more_body", False):
                return b"".join(chunks)
