"""ServerLink: a controller connection to the Jack/TTES server inside the caller's own trio run.

:class:`client_stub.stub.jack.JackProc` runs its network in a thread of its own (the stub's render loop is not
async). Replay drivers and the gateway are trio programs, and their tests run the server in the same trio run
under the autojump clock, so they need the same conversation without a thread: this class. Sending is
synchronous (encode, queue for the writer task); a reader task answers PINGs, keeps the update tables,
STATUS and errors, and puts joint updates into :class:`client_stub.stub.jack.UpdateBuffer` double buffers, so
:meth:`swap` hands them out exactly as ``JackProc.swap`` does.
"""

from __future__ import annotations

import contextlib
import logging

import numpy as np
import trio

from client_stub.stub.jack import STARTUP_JCL, JackError, ServerView, UpdateBatch
from protocol.connection import CLIENT, NEED_DATA, Connection
from protocol.entity import ENTITY_REQUEST_DTYPE
from protocol.errors import LocalProtocolError
from protocol.events import (
    Accept,
    ConnectionClosed,
    CreateSoldier,
    EntityRequests,
    Error,
    Event,
    Goodbye,
    Hello,
    Jcl,
    Ping,
    Pong,
    ProtocolError,
    Ready,
    RemoveSoldier,
    Subscribe,
)

log = logging.getLogger("ttes.replay.link")


class ServerLink(ServerView):
    """One TCP connection to the server; open it with :meth:`open` inside a nursery."""

    def __init__(self, name: str = "ttes-replay", role: str = "controller") -> None:
        super().__init__()
        self.name = name
        self.role = role
        self.bytes_sent = 0
        self._conn = Connection(CLIENT)
        self._next_id = 1
        self._accepted = trio.Event()
        self._ready = trio.Event()
        self._closed = trio.Event()
        self._outbox: trio.MemorySendChannel[bytes] | None = None
        self._cancel: trio.CancelScope | None = None
        self._nonce = 0
        self._pongs: dict[int, trio.Event] = {}
        self._answered: set[int] = set()

    # -- connecting -------------------------------------------------------------------------------
    async def open(
        self,
        nursery: trio.Nursery,
        host: str,
        port: int,
        *,
        soldierprefix: str | None = "soldier_low",
        timeout: float = 30.0,
    ) -> None:
        """Connect, shake hands, send the start-up JCL and wait for READY; JackError on failure."""
        try:
            stream = await trio.open_tcp_stream(host, port)
        except OSError as exc:
            raise JackError(f"cannot connect to {host}:{port}: {exc.strerror or exc}") from None
        send, receive = trio.open_memory_channel[bytes](float("inf"))
        self._outbox = send
        nursery.start_soon(self._run, stream, receive)
        self.send(Hello(self.name, self.role))
        with trio.move_on_after(timeout):
            await self._accepted.wait()
            if soldierprefix is not None:
                self.send(Jcl(STARTUP_JCL.format(prefix=soldierprefix), self._new_id()))
            await self._ready.wait()
        if self.failure or not self._ready.is_set() or self._closed.is_set():
            await self.aclose()
            raise JackError(self.failure or f"server {host}:{port} not ready within {timeout} s")

    @property
    def ready(self) -> bool:
        return self._ready.is_set() and not self._closed.is_set()

    @property
    def max_soldiers(self) -> int:
        return self.accept.max_soldiers if self.accept is not None else 0

    # -- sending (synchronous: encode and queue) --------------------------------------------------
    def send(self, event: Event) -> None:
        if self._outbox is None or self._closed.is_set():
            raise JackError(self.failure or "not connected")
        try:
            data = self._conn.send(event)
        except LocalProtocolError as exc:
            raise JackError(f"cannot send {type(event).__name__}: {exc}") from None
        if data:
            self.bytes_sent += len(data)
            try:
                self._outbox.send_nowait(data)
            except (trio.ClosedResourceError, trio.BrokenResourceError):
                raise JackError(self.failure or "connection closing") from None

    def _new_id(self) -> int:
        rid = self._next_id
        self._next_id += 1
        return rid

    def create(self, index: int, figure: str, weapon: str) -> int:
        """CREATE_SOLDIER at ``index``, pipelined (requests sent after it find him); returns its id."""
        rid = self._new_id()
        self.send(CreateSoldier(rid, figure, weapon, int(index)))
        return rid

    def remove(self, index: int) -> None:
        self.send(RemoveSoldier(int(index)))

    def subscribe(self, indices: list[int] | np.ndarray) -> None:
        if len(indices):
            self.send(Subscribe(tuple(int(i) for i in indices)))

    def send_requests(self, rows: np.ndarray) -> None:
        rows = np.asarray(rows, ENTITY_REQUEST_DTYPE)
        if len(rows):
            self.send(EntityRequests(rows))

    def swap(self) -> list[UpdateBatch]:
        """Every pose that arrived since the last call (as ``JackProc.swap``)."""
        return self._fresh(self._flip())

    async def drain(self) -> None:
        """Wait until everything queued so far has been handed to the socket."""
        if self._outbox is not None and not self._closed.is_set():
            while self._outbox.statistics().current_buffer_used:
                await trio.sleep(0.001)

    async def roundtrip(self, timeout: float = 30.0) -> bool:
        """PING and wait for its PONG: the server has then taken everything sent before (it reads a
        connection's messages in order). False if no answer in ``timeout`` s or the link closed."""
        self._nonce += 1
        nonce = self._nonce
        done = self._pongs[nonce] = trio.Event()
        self.send(Ping(nonce))
        with trio.move_on_after(timeout):
            await done.wait()  # set by the PONG, or by the link closing
        self._pongs.pop(nonce, None)
        return nonce in self._answered

    async def aclose(self, reason: str = "done") -> None:
        """GOODBYE (if still open), then close."""
        if self._outbox is not None and not self._closed.is_set():
            with contextlib.suppress(JackError):
                self.send(Goodbye(reason))
            self._outbox.close()
            with trio.move_on_after(2.0):
                await self._closed.wait()
        if self._cancel is not None:
            self._cancel.cancel()

    # -- the tasks --------------------------------------------------------------------------------
    async def _run(self, stream: trio.SocketStream, receive: trio.MemoryReceiveChannel[bytes]) -> None:
        try:
            with trio.CancelScope() as scope:
                self._cancel = scope
                async with stream, trio.open_nursery() as nursery:
                    nursery.start_soon(self._writer, stream, receive)
                    await self._reader(stream)
                    nursery.cancel_scope.deadline = trio.current_time() + 2.0  # let the writer finish
        finally:
            self._closed.set()
            self._accepted.set()
            self._ready.set()
            for pong in self._pongs.values():
                pong.set()

    async def _writer(self, stream: trio.SocketStream, receive: trio.MemoryReceiveChannel[bytes]) -> None:
        async with receive:
            async for data in receive:
                try:
                    await stream.send_all(data)
                except (trio.BrokenResourceError, trio.ClosedResourceError):
                    self.failure = self.failure or "connection lost while sending"
                    return

    async def _reader(self, stream: trio.SocketStream) -> None:
        conn = self._conn
        while True:
            event = conn.next_event()
            if event is NEED_DATA:
                try:
                    data = await stream.receive_some(1 << 16)
                except (trio.BrokenResourceError, trio.ClosedResourceError):
                    data = b""
                conn.receive_data(bytes(data))
                continue
            if isinstance(event, ConnectionClosed):
                self.failure = self.failure or "server closed the connection"
                return
            if isinstance(event, ProtocolError):
                self.errors.append(event)
                self.failure = f"protocol error {event.code}: {event.location}: {event.message}"
                log.warning("%s", self.failure)
                out = conn.data_to_send()
                if out and self._outbox is not None:
                    with contextlib.suppress(trio.ClosedResourceError, trio.BrokenResourceError):
                        self._outbox.send_nowait(out)
                return
            self._handle(event)

    def _handle(self, event: object) -> None:
        self._absorb(event)
        if isinstance(event, Accept):
            self._accepted.set()
        elif isinstance(event, Ready):
            self._ready.set()
        elif isinstance(event, Ping):
            self.send(Pong(event.nonce))
        elif isinstance(event, Pong):
            pong = self._pongs.get(event.nonce)
            if pong is not None:
                self._answered.add(event.nonce)
                pong.set()
        elif isinstance(event, Error):
            log.debug("server error %d: %s", event.code, event.message)
