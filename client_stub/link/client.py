"""The one client of a Jack/TTES server: a trio-native conversation over a protocol ``Connection``.

Every client application speaks through this class: the stub (through :mod:`client_stub.link.threaded`, its
network in a thread of its own), the DIS replay and gateway (inside their own trio run, where tests run the
server too under the autojump clock), the load generator and the crowd (many of them in one run).

Sending is synchronous: encode with the connection, append to an outgoing buffer that a writer task hands to
the socket in as few writes as it can (:meth:`Client.drain` waits until it has). A reader task answers PINGs,
keeps what the server says (handshake, update tables, READY's soldiers, answers to CREATE_SOLDIER, STATUS,
errors, why the link failed) and hands joint updates on: into per-table double buffers that :meth:`swap`
empties (a renderer's newest pose of each soldier), and/or to an ``on_updates`` hook with their arrival time
and wire size (the load generator's measurements). With ``decode_updates=False`` the connection yields only
the update frames' headers (:class:`~protocol.events.UpdateHeaders`): no pose is decoded. There is no
reconnect policy: a lost link stays lost (``failure`` says why) and each application falls back as it
sees fit.
"""

from __future__ import annotations

import contextlib
import logging
import ssl
import uuid
from collections import deque
from collections.abc import Callable
from contextlib import AbstractContextManager

import numpy as np
import trio

from client_stub.link.buffer import UpdateBatch, UpdateBuffer
from protocol import events as ev
from protocol.connection import CLIENT, NEED_DATA, Connection
from protocol.entity import ENTITY_REQUEST_DTYPE, Reaction
from protocol.errors import LocalProtocolError, is_fatal
from protocol.update_table import UpdateTable

log = logging.getLogger("ttes.link")
STARTUP_JCL = 'read_file("jack-ttes-{prefix}.jcl");'
RECEIVE_BYTES = 1 << 18
MAX_INDICES_PER_MESSAGE = 8192  # soldiers per SUBSCRIBE / UNSUBSCRIBE (keeps each control frame small)

# on_updates(arrival time, tick, server indices, frame bytes, decoded event or None when only tapped)
UpdateHook = Callable[[float, int, np.ndarray, int, ev.JointUpdates | None], None]


class LinkError(RuntimeError):
    """The connection to the server failed, was refused, or cannot send this."""


def _why(exc: OSError) -> str:
    """The operating system's reason (trio wraps each address's error in a group behind its own)."""
    cause = exc.__cause__
    inner = [e for e in getattr(cause, "exceptions", ()) if isinstance(e, OSError) and e.strerror]
    return str((inner[0] if inner else exc).strerror or exc)


class Client:
    """One TCP connection to the server (see the module docstring); open it with :meth:`open` in a nursery.

    ``lock`` guards the double buffers when another thread swaps them (:mod:`client_stub.link.threaded`);
    ``notify`` is called in the reader with every event after it has been taken in."""

    def __init__(
        self,
        name: str = "ttes-client",
        role: str = "controller",
        *,
        buffer_updates: bool = True,
        decode_updates: bool = True,
        on_updates: UpdateHook | None = None,
        lock: AbstractContextManager[object] | None = None,
        notify: Callable[[ev.Event], None] | None = None,
    ) -> None:
        self.name = name
        self.role = role
        # who this link is across reconnects (the server keeps its soldiers for it, issue 17) and the role's
        # token when the server has tokens: set them before open()
        self.client_id = f"{name[:40]}-{uuid.uuid4().hex[:12]}"
        self.token = ""
        self.tls: ssl.SSLContext | None = None  # speak TLS (a server with tls_cert); checks its certificate
        self.buffer_updates = buffer_updates
        self.on_updates = on_updates
        self.conn = Connection(CLIENT, decode_updates=decode_updates)
        self.accept: ev.Accept | None = None
        self.tables: dict[int, UpdateTable] = {}
        self.ready_soldiers: dict[int, int] = {}  # server index -> update table, from READY
        self.ready_event: ev.Ready | None = None  # the READY itself: the server's tick rate and throttle
        self.created: dict[int, int] = {}  # server index -> update table, from SOLDIER_CREATED
        self.answers: dict[int, ev.SoldierCreated | ev.Error] = {}  # awaited CREATE_SOLDIER id -> its answer
        self.refused: dict[int, ev.Error] = {}  # request id -> its error
        self.errors: list[ev.Error | ev.ProtocolError] = []
        self.status: ev.Status | None = None
        self.settings: ev.Settings | None = None  # this connection's throttle and STATUS period
        self.removed: deque[int] = deque(maxlen=1024)  # the latest soldiers the server said are gone
        self.failure: str | None = None
        self.last_tick = 0
        self.bytes_sent = 0
        self.bytes_in = 0
        self.update_bytes = 0
        self.soldier_updates = 0  # soldier rows of all joint updates received
        self._lock = lock if lock is not None else contextlib.nullcontext()
        self._notify = notify
        self._buffers: dict[int, UpdateBuffer] = {}
        self._awaited: set[int] = set()  # CREATE_SOLDIER ids whose answers are kept for answer()
        self._next_id = 1
        self._nonce = 0
        self._pongs: dict[int, trio.Event] = {}
        self._answered_pings: set[int] = set()
        self._accepted = trio.Event()
        self._ready = trio.Event()
        self._closed = trio.Event()
        self._answer = trio.Event()  # set (and replaced) whenever a CREATE_SOLDIER answer arrives
        self._out = bytearray()
        self._wake = trio.Event()
        self._progress = trio.Event()  # set (and replaced) whenever the writer handed bytes to the socket
        self._queued = 0
        self._written = 0
        self._outbox_open = False
        self._leaving = False  # we said GOODBYE: the server closing is no failure
        self._cancel: trio.CancelScope | None = None

    # -- connecting -------------------------------------------------------------------------------
    async def open(
        self,
        nursery: trio.Nursery,
        host: str,
        port: int,
        *,
        soldierprefix: str | None = "soldier_low",
        wait_ready: bool = True,
        timeout: float = 30.0,
    ) -> None:
        """Connect and shake hands; then send the start-up JCL (unless ``soldierprefix`` is None) and wait
        for READY (if ``wait_ready``). LinkError (and the link closed) on failure."""
        with trio.move_on_after(timeout) as cs:
            try:
                stream: trio.abc.Stream = await trio.open_tcp_stream(host, port)
                if self.tls is not None:
                    stream = trio.SSLStream(stream, self.tls, server_hostname=host)
            except OSError as exc:
                raise LinkError(f"cannot connect to {host}:{port}: {_why(exc)}") from None
        if cs.cancelled_caught:
            raise LinkError(f"cannot connect to {host}:{port} within {timeout} s")
        self._outbox_open = True
        nursery.start_soon(self._run, stream)
        self.send(ev.Hello(self.name, self.role, client_id=self.client_id, token=self.token))
        with trio.move_on_after(timeout):
            await self._accepted.wait()
            if soldierprefix is not None and self.accepted:
                self.jcl(STARTUP_JCL.format(prefix=soldierprefix))
            if wait_ready:
                await self._ready.wait()
        if self.failure or not self.accepted or (wait_ready and not self.ready):
            await self.aclose()
            what = "ready" if self.accepted else "answering the handshake"
            raise LinkError(self.failure or f"server {host}:{port} not {what} within {timeout} s")

    @property
    def accepted(self) -> bool:
        """The handshake is done and the link is open."""
        return self.accept is not None and not self._closed.is_set()

    @property
    def ready(self) -> bool:
        """READY has arrived and the link is open."""
        return self._ready.is_set() and not self._closed.is_set()

    @property
    def closed(self) -> bool:
        return self._closed.is_set()

    @property
    def max_soldiers(self) -> int:
        return self.accept.max_soldiers if self.accept is not None else 0

    async def wait_ready(self, timeout: float) -> bool:
        """Wait for READY (or the link closing); True when ready."""
        with trio.move_on_after(timeout):
            await self._ready.wait()
        return self.ready

    async def wait_closed(self) -> None:
        await self._closed.wait()

    # -- sending (synchronous: encode and queue) --------------------------------------------------
    def send(self, event: ev.Event) -> None:
        """Encode ``event`` and queue its bytes for the writer; LinkError if closed or not sendable."""
        if not self._outbox_open or self._closed.is_set():
            raise LinkError(self.failure or "not connected")
        try:
            data = self.conn.send(event)
        except LocalProtocolError as exc:
            raise LinkError(f"cannot send {type(event).__name__}: {exc}") from None
        self._queue(data)

    def _queue(self, data: bytes) -> None:
        if data:
            self.bytes_sent += len(data)
            self._queued += len(data)
            self._out += data
            self._wake.set()

    def new_id(self) -> int:
        """A fresh request id (JCL, CREATE_SOLDIER)."""
        rid = self._next_id
        self._next_id += 1
        return rid

    def jcl(self, text: str) -> int:
        rid = self.new_id()
        self.send(ev.Jcl(text, rid))
        return rid

    def create(self, index: int | None, figure: str, weapon: str, *, await_answer: bool = False) -> int:
        """CREATE_SOLDIER, pipelined (requests sent after it find him); returns its id. With
        ``await_answer`` the answer is kept for :meth:`answer`."""
        rid = self.new_id()
        if await_answer:
            self._awaited.add(rid)
        self.send(ev.CreateSoldier(rid, figure, weapon, None if index is None else int(index)))
        return rid

    async def answer(self, rid: int) -> ev.SoldierCreated | ev.Error | None:
        """Wait for the answer to CREATE_SOLDIER ``rid`` and take it (None if the link closed first)."""
        try:
            while rid not in self.answers and not self._closed.is_set():
                await self._answer.wait()
        finally:
            self._awaited.discard(rid)
        return self.answers.pop(rid, None)

    async def create_soldier(
        self, figure: str, weapon: str, index: int | None = None, timeout: float = 10.0
    ) -> ev.SoldierCreated:
        """CREATE_SOLDIER and wait for the answer; LinkError if the server refuses or stays silent."""
        rid = self.create(index, figure, weapon, await_answer=True)
        result = None
        with trio.move_on_after(timeout):
            result = await self.answer(rid)
        if result is None:
            raise LinkError(self.failure or f"no answer to CREATE_SOLDIER {rid} within {timeout} s")
        if isinstance(result, ev.Error):
            raise LinkError(f"server refused soldier: {result.message}")
        return result

    def remove(self, index: int) -> None:
        self.send(ev.RemoveSoldier(int(index)))

    def _send_indices(
        self, make: Callable[[tuple[int, ...]], ev.Event], indices: list[int] | np.ndarray
    ) -> None:
        """One message per MAX_INDICES_PER_MESSAGE indices (a frame's size limit)."""
        idx = np.asarray(indices, np.int64)
        for k in range(0, len(idx), MAX_INDICES_PER_MESSAGE):
            self.send(make(tuple(idx[k : k + MAX_INDICES_PER_MESSAGE].tolist())))

    def subscribe(self, indices: list[int] | np.ndarray) -> None:
        self._send_indices(ev.Subscribe, indices)

    def unsubscribe(self, indices: list[int] | np.ndarray) -> None:
        self._send_indices(ev.Unsubscribe, indices)

    def react(self, indices: list[int] | np.ndarray, kind: Reaction) -> None:
        """REACT: these soldiers play ``kind`` (recoil, flinch) once, now or when they come to rest."""
        self._send_indices(lambda idx: ev.React(int(kind), idx), indices)

    def request_full_update(self, indices: list[int] | None = None) -> None:
        self.send(ev.RequestFullUpdate(tuple(int(i) for i in indices or ())))

    def send_requests(self, rows: np.ndarray) -> None:
        """ENTITY_REQUESTS rows (``ENTITY_REQUEST_DTYPE``, server indices); the connection splits frames."""
        rows = np.asarray(rows, ENTITY_REQUEST_DTYPE)
        if len(rows):
            self.send(ev.EntityRequests(rows))

    def swap(self) -> list[UpdateBatch]:
        """Every pose that arrived since the last call (the consumer side of the double buffers)."""
        with self._lock:
            batches = [buf.flip() for buf in self._buffers.values()]
        return [b for b in batches if b is not None]

    async def drain(self) -> None:
        """Wait until everything queued so far has been handed to the socket (or the link closed)."""
        target = self._queued
        while self._written < target and not self._closed.is_set():
            await self._progress.wait()

    async def roundtrip(self, timeout: float = 30.0) -> bool:
        """PING and wait for its PONG: the server has then taken everything sent before (it reads a
        connection's messages in order). False if no answer in ``timeout`` s or the link closed."""
        self._nonce += 1
        nonce = self._nonce
        done = self._pongs[nonce] = trio.Event()
        self.send(ev.Ping(nonce))
        with trio.move_on_after(timeout):
            await done.wait()  # set by the PONG, or by the link closing
        self._pongs.pop(nonce, None)
        return nonce in self._answered_pings

    async def aclose(self, reason: str = "done") -> None:
        """GOODBYE (if still open), let the writer finish (2 s at most), then close."""
        if self._outbox_open and not self._closed.is_set():
            with contextlib.suppress(LinkError):
                self.send(ev.Goodbye(reason))
            self._leaving = True
            self._outbox_open = False
            self._wake.set()
            with trio.move_on_after(2.0):
                await self._closed.wait()
        self._outbox_open = False
        if self._cancel is not None:
            self._cancel.cancel()

    # -- the tasks --------------------------------------------------------------------------------
    async def _run(self, stream: trio.abc.Stream) -> None:
        try:
            with trio.CancelScope() as scope:
                self._cancel = scope
                async with stream, trio.open_nursery() as nursery:
                    nursery.start_soon(self._writer, stream)
                    await self._reader(stream)
                    self._outbox_open = False
                    self._wake.set()
                    nursery.cancel_scope.deadline = trio.current_time() + 2.0  # let the writer finish
        finally:
            self._closed.set()
            self._outbox_open = False
            for ev in (self._accepted, self._ready, self._answer, self._progress, *self._pongs.values()):
                ev.set()

    async def _writer(self, stream: trio.abc.Stream) -> None:
        while True:
            if not self._out:
                if not self._outbox_open:
                    return
                await self._wake.wait()
                self._wake = trio.Event()
                continue
            data = bytes(self._out)
            self._out.clear()
            try:
                await stream.send_all(data)
            except (trio.BrokenResourceError, trio.ClosedResourceError):
                self.failure = self.failure or "connection lost while sending"
                return
            self._written += len(data)
            self._progress.set()
            self._progress = trio.Event()

    async def _reader(self, stream: trio.abc.Stream) -> None:
        conn = self.conn
        arrival = 0.0
        while True:
            event = conn.next_event()
            if event is NEED_DATA:
                try:
                    data = await stream.receive_some(RECEIVE_BYTES)
                except (trio.BrokenResourceError, trio.ClosedResourceError):
                    data = b""
                arrival = trio.current_time()
                self.bytes_in += len(data)
                conn.receive_data(bytes(data))
                continue
            assert isinstance(event, ev.Event)
            if not self._take(event, arrival):
                return
            if self._notify is not None:
                self._notify(event)

    def _take(self, event: ev.Event, arrival: float) -> bool:
        """Keep what one event says, answer what needs an answer; False when the link has ended."""
        match event:
            case ev.JointUpdates(table=table, tick=tick, indices=indices):
                self._updates(arrival, table, tick, indices, event)
            case ev.UpdateHeaders(table=table, tick=tick, indices=indices):
                self._updates(arrival, table, tick, indices, None)
            case ev.Accept():
                self.accept = event
                self._accepted.set()
            case ev.UpdateTableMsg(table=table):
                self.tables[table.table_id] = table
                with self._lock:
                    self._buffers[table.table_id] = UpdateBuffer(table)
            case ev.Ready(soldiers=soldiers):
                self.ready_soldiers = dict(soldiers)
                self.ready_event = event
                self._ready.set()
            case ev.SoldierCreated(id=rid, index=index, table=table):
                self.created[index] = table
                self._resolve(rid, event)
            case ev.Ping(nonce=nonce):
                self.send(ev.Pong(nonce))
            case ev.Pong(nonce=nonce) if nonce in self._pongs:
                self._answered_pings.add(nonce)
                self._pongs[nonce].set()
            case ev.Status():
                self.status = event
            case ev.Settings():
                self.settings = event
            case ev.SoldierRemoved(index=index):
                self.removed.append(index)
                self.ready_soldiers.pop(index, None)
                self.created.pop(index, None)
            case ev.Error():
                self._error(event)
            case ev.Goodbye(reason=reason):
                self.failure = self.failure or f"server said goodbye: {reason}"
            case ev.ProtocolError() | ev.ConnectionClosed():
                self._end(event)
                return False
        return True

    def _error(self, event: ev.Error) -> None:
        log.debug("server error %d: %s", event.code, event.message)
        self.errors.append(event)
        if event.ref is not None:
            self.refused[event.ref] = event
            self._resolve(event.ref, event)
        if is_fatal(event.code):
            self.failure = self.failure or f"server error {event.code}: {event.message}"

    def _end(self, event: ev.ProtocolError | ev.ConnectionClosed) -> None:
        """The connection is over: the server broke the protocol (it gets our Error frame) or closed."""
        if isinstance(event, ev.ProtocolError):
            self.errors.append(event)
            self.failure = f"protocol error {event.code}: {event.location}: {event.message}"
            log.warning("%s", self.failure)
            self._queue(self.conn.data_to_send())  # the Error frame for the server
        elif not self._leaving:
            self.failure = self.failure or "server closed the connection"

    def _updates(
        self, arrival: float, table: int, tick: int, indices: np.ndarray, event: ev.JointUpdates | None
    ) -> None:
        self.last_tick = tick
        self.update_bytes += self.conn.frame_bytes
        self.soldier_updates += len(indices)
        if event is not None and self.buffer_updates:
            buf = self._buffers.get(table)
            if buf is not None:
                with self._lock:
                    buf.write(event)
        if self.on_updates is not None:
            self.on_updates(arrival, tick, np.asarray(indices, np.int64), self.conn.frame_bytes, event)

    def _resolve(self, rid: int, answer: ev.SoldierCreated | ev.Error) -> None:
        if rid not in self._awaited:
            return
        self.answers[rid] = answer
        self._answer.set()
        self._answer = trio.Event()
