"""The TTES byte stream over WebSocket (RFC 6455), for browsers: a trio Stream over another one, via wsproto.

A browser cannot open a TCP socket, so ``ttes server --ws-port`` also accepts WebSocket connections, and
:class:`WebSocketStream` makes one look like the TCP stream to the session code (nothing else changes): the
payloads of the client's **binary** messages, concatenated, are the TTES byte stream, and what the server
writes goes out as binary messages (docs/PROTOCOL.md §2.1). wsproto is sans-IO (h11 for the upgrade request),
so this module only moves bytes and decides:

* the upgrade: a request whose ``Origin`` :func:`origin_allowed` refuses gets HTTP 403 (a web page of another
  site must not drive a local server with the role a local client gets); anything but a WebSocket upgrade 400;
* what closes the connection (the end of the stream for the session; :attr:`close_code` says why): a text
  message (1003), a message longer than ``max_message`` (1009), a WebSocket protocol violation (1002), the
  peer's close. Memory stays bounded: a message is passed on as it arrives, never assembled.

The same class is the client side (``client=True``, then :meth:`connect`), for tests and Python clients.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterable
from urllib.parse import urlsplit

import h11
import trio
from wsproto import ConnectionType, WSConnection
from wsproto.connection import ConnectionState
from wsproto.events import (
    AcceptConnection,
    BytesMessage,
    CloseConnection,
    Event,
    Ping,
    RejectConnection,
    Request,
    TextMessage,
)
from wsproto.utilities import LocalProtocolError, RemoteProtocolError

RECEIVE_CHUNK = 65536
CLOSE_TIMEOUT_S = 0.5  # how long aclose may spend sending the close frame
NORMAL, PROTOCOL_ERROR, UNSUPPORTED_DATA, MESSAGE_TOO_BIG = 1000, 1002, 1003, 1009
LOOPBACK_HOSTS = frozenset({"localhost", "127.0.0.1", "::1"})


class WebSocketError(OSError):
    """The WebSocket upgrade failed (client side): refused by the server, or not a WebSocket server."""


def origin_allowed(origin: str | None, allowed: Iterable[str] = ()) -> bool:
    """Whether a WebSocket upgrade from a page of ``origin`` (its ``Origin`` header; None: not a browser)
    is accepted. ``allowed`` lists origins (``"http://host:port"``) or ``"*"``; the default (empty) accepts
    no Origin and the pages served from a loopback host, on any port (``ttes web``)."""
    allowed = tuple(allowed)
    if origin is None or "*" in allowed or origin in allowed:
        return True
    if allowed:
        return False
    try:
        parts = urlsplit(origin)
        return parts.scheme in ("http", "https") and (parts.hostname or "") in LOOPBACK_HOSTS
    except ValueError:
        return False


class WebSocketStream(trio.abc.Stream):
    """The bytes of a TTES connection as binary WebSocket messages over ``transport``."""

    def __init__(
        self,
        transport: trio.abc.Stream,
        *,
        client: bool = False,
        max_message: int = 1 << 20,
        accept_origin: Callable[[str | None], bool] = origin_allowed,
    ) -> None:
        self.transport = transport
        self.ws = WSConnection(ConnectionType.CLIENT if client else ConnectionType.SERVER)
        self.max_message = max_message
        self.accept_origin = accept_origin
        self.open = False  # the upgrade is done
        self.ended = False  # no more bytes will come: closed, refused or broken
        self.close_code: int | None = None  # why it ended: the close code sent or received
        self.origin: str | None = None
        self._buffer = bytearray()
        self._head = bytearray()  # the bytes of the upgrade request until it is answered
        self._message = 0  # bytes of the binary message now arriving
        self._send_lock = trio.Lock()

    # -- the client's upgrade ------------------------------------------------------------------------------
    async def connect(self, host: str, target: str = "/", origin: str | None = None) -> None:
        """Client side: send the upgrade request and wait for the answer (WebSocketError if refused)."""
        headers = [(b"origin", origin.encode())] if origin else []
        await self._send(self.ws.send(Request(host=host, target=target, extra_headers=headers)))
        while not self.open:
            data = await self._read()
            if not data:
                raise WebSocketError("the server closed the connection during the WebSocket upgrade")
            self.ws.receive_data(data)
            for event in self.ws.events():
                if isinstance(event, AcceptConnection):
                    self.open = True
                elif isinstance(event, RejectConnection):
                    raise WebSocketError(f"WebSocket upgrade refused: HTTP {event.status_code}")

    # -- trio.abc.Stream -----------------------------------------------------------------------------------
    async def receive_some(self, max_bytes: int | None = None) -> bytes:
        """The next bytes of the TTES stream; b"" once the WebSocket has ended (for whatever reason)."""
        while not self._buffer and not self.ended:
            data = await self._read()
            await self._feed(data)
        n = len(self._buffer) if max_bytes is None else max_bytes
        out = bytes(self._buffer[:n])
        del self._buffer[:n]
        return out

    async def send_all(self, data: bytes | bytearray | memoryview) -> None:
        """One binary message (BrokenResourceError once the WebSocket is not open)."""
        if not self.open or self.ended or self.ws.state is not ConnectionState.OPEN:
            raise trio.BrokenResourceError("the WebSocket is not open")
        await self._send(self.ws.send(BytesMessage(data=bytes(data))))

    async def wait_send_all_might_not_block(self) -> None:
        await self.transport.wait_send_all_might_not_block()

    async def aclose(self) -> None:
        """Send a normal close when still open (briefly, even when cancelled), then close the transport."""
        try:
            if self.open and self.ws.state is ConnectionState.OPEN:
                with trio.CancelScope(shield=True), trio.move_on_after(CLOSE_TIMEOUT_S):
                    await self._send(self.ws.send(CloseConnection(code=NORMAL)))
                    self.close_code = self.close_code or NORMAL
        except (trio.BrokenResourceError, trio.ClosedResourceError, LocalProtocolError):
            pass
        finally:
            self.ended = True
            await self.transport.aclose()

    # -- inside --------------------------------------------------------------------------------------------
    async def _read(self) -> bytes:
        try:
            return bytes(await self.transport.receive_some(RECEIVE_CHUNK))
        except (trio.BrokenResourceError, trio.ClosedResourceError):
            return b""

    async def _send(self, data: bytes) -> None:
        if data:
            async with self._send_lock:
                await self.transport.send_all(data)

    async def _feed(self, data: bytes) -> None:
        """Hand ``data`` (b"": the transport ended) to wsproto and act on its events."""
        if not data:
            self.ended = True
            return
        if not self.open:
            self._head += data
        try:
            self.ws.receive_data(data)
            more = True
            while more:  # again after the upgrade: bytes that came with the request are the first frames
                more = False
                for event in self.ws.events():
                    more = True
                    await self._on_event(event)
                    if self.ended:
                        return
        except RemoteProtocolError as exc:
            await self._refuse(400, PROTOCOL_ERROR, str(exc))

    async def _on_event(self, event: Event) -> None:
        if isinstance(event, Request):
            await self._upgrade(event)
        elif isinstance(event, BytesMessage):
            self._message += len(event.data)
            if self._message > self.max_message:
                await self._close(MESSAGE_TOO_BIG, f"a message over {self.max_message} bytes")
                return
            self._buffer += event.data
            if event.message_finished:
                self._message = 0
        elif isinstance(event, TextMessage):
            await self._close(UNSUPPORTED_DATA, "binary messages only (the TTES stream)")
        elif isinstance(event, Ping):
            await self._send(self.ws.send(event.response()))
        elif isinstance(event, CloseConnection):
            if self.ws.state is ConnectionState.OPEN:  # wsproto's own verdict on a bad frame: we close
                await self._close(event.code, event.reason or "")
                return
            if self.ws.state is ConnectionState.REMOTE_CLOSING:
                await self._send(self.ws.send(event.response()))
            self.close_code = event.code
            self.ended = True

    async def _upgrade(self, request: Request) -> None:
        origin = next((v.decode("latin-1") for k, v in request.extra_headers if k.lower() == b"origin"), None)
        self.origin = origin
        if not self.accept_origin(origin):
            await self._refuse(403, None, f"origin {origin} not allowed")
            return
        await self._send(self.ws.send(AcceptConnection()))
        self.open = True
        # wsproto's server drops bytes that came after the request (frames sent before the 101 arrived)
        end = self._head.find(b"\r\n\r\n")
        trailing, self._head = bytes(self._head[end + 4 :]) if end >= 0 else b"", bytearray()
        if trailing:
            self.ws.receive_data(trailing)

    async def _refuse(self, status: int, code: int | None, reason: str) -> None:
        """End: an HTTP refusal while upgrading, else a close frame with ``code``."""
        if not self.open:
            with contextlib.suppress(LocalProtocolError, h11.LocalProtocolError):  # no answerable request
                await self._send(self.ws.send(RejectConnection(status_code=status)))
            self.close_code = code
            self.ended = True
        else:
            await self._close(code or PROTOCOL_ERROR, reason)

    async def _close(self, code: int, reason: str) -> None:
        if self.ws.state in (ConnectionState.OPEN, ConnectionState.REMOTE_CLOSING):
            with contextlib.suppress(trio.BrokenResourceError, trio.ClosedResourceError):
                await self._send(self.ws.send(CloseConnection(code=code, reason=reason[:120])))
        self.close_code = code
        self.ended = True


__all__ = ["WebSocketError", "WebSocketStream", "origin_allowed"]
