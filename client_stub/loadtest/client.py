"""One load-test connection: handshake, soldiers, subscriptions, requests, and a frame tap on the updates.

A load generator that shares the machine with the server must not spend more than the server: decoding a
joint update costs about 12 µs per soldier in :class:`protocol.updates.UpdateDecoder`, as much as the
server's encoding. So by default the client *taps* the byte stream: it cuts frames itself
(:class:`protocol.framing.FrameReader`) and reads only the 8-byte header and the soldier indices of each
JOINT_UPDATES frame (docs/PROTOCOL.md 8); every other frame goes to a :class:`protocol.connection.Connection`
as usual, which therefore stays a correct client (it never needs the update frames: they change no protocol
state). With ``decode=True`` every frame goes through the Connection and ``on_updates`` receives the full
:class:`~protocol.events.JointUpdates` with the poses (the crowd renderer).
"""

from __future__ import annotations

import struct
from collections.abc import Callable

import numpy as np
import trio

from protocol.connection import CLIENT, NEED_DATA, Connection, State
from protocol.entity import MAX_ROWS_PER_FRAME
from protocol.errors import WireError, is_fatal
from protocol.events import (
    ConnectionClosed,
    CreateSoldier,
    EntityRequests,
    Error,
    Event,
    Goodbye,
    Hello,
    JointUpdates,
    Ping,
    Pong,
    ProtocolError,
    Ready,
    RemoveSoldier,
    SoldierCreated,
    Status,
    Subscribe,
)
from protocol.framing import FrameReader, encode_frame
from protocol.messages import MessageType

UPDATE_HEADER = struct.Struct(">HIH")  # table, tick, count (docs/PROTOCOL.md 8)
RECEIVE_BYTES = 1 << 18
MAX_INDICES_PER_MESSAGE = 8192  # soldiers per SUBSCRIBE (keeps each control frame small)
CREATE_WINDOW = 64  # CREATE_SOLDIER requests in flight (the server's control queue holds 256 answers)


class LoadError(RuntimeError):
    """The server refused something or the connection failed."""


# on_updates(conn number, arrival time, tick, server indices, frame bytes, decoded event or None)
UpdateHook = Callable[[int, float, int, np.ndarray, int, JointUpdates | None], None]


class LoadClient:
    """One TCP connection of the load generator (a controller: it creates and drives its soldiers)."""

    def __init__(self, number: int, on_updates: UpdateHook, *, decode: bool = False, name: str = "") -> None:
        self.number = number
        self.on_updates = on_updates
        self.decode = decode
        self.name = name or f"ttes-loadtest-{number}"
        self.conn = Connection(CLIENT)
        self.frames = FrameReader()
        self.stream: trio.SocketStream | None = None
        self.send_lock = trio.StrictFIFOLock()
        self.ready = trio.Event()
        self.closed = trio.Event()
        self.tables: dict[int, object] = {}
        self.created: dict[int, SoldierCreated | Error] = {}
        self.created_event = trio.Event()
        self.errors: list[str] = []
        self.failure: str | None = None
        self.status: Status | None = None
        self.bytes_in = 0
        self.update_bytes = 0
        self._next_id = 1

    # -- connecting ----------------------------------------------------------------------------------------
    async def connect(self, host: str, port: int, timeout: float = 30.0) -> None:
        """Open the stream and shake hands; returns once READY has arrived (LoadError otherwise)."""
        with trio.move_on_after(timeout) as cs:
            self.stream = await trio.open_tcp_stream(host, port)
        if cs.cancelled_caught or self.stream is None:
            raise LoadError(f"cannot connect to {host}:{port} within {timeout} s")
        await self.send(Hello(self.name, "controller"))

    async def wait_ready(self, timeout: float) -> None:
        with trio.move_on_after(timeout):
            await self.ready.wait()
        if not self.ready.is_set():
            raise LoadError(self.failure or f"{self.name}: no READY within {timeout} s")

    async def send(self, event: Event) -> None:
        data = self.conn.send(event)
        await self.send_bytes(data)

    async def send_bytes(self, data: bytes) -> None:
        if not data or self.stream is None or self.closed.is_set():
            return
        async with self.send_lock:
            try:
                await self.stream.send_all(data)
            except (trio.BrokenResourceError, trio.ClosedResourceError) as exc:
                self._fail(f"send failed: {exc!r}")

    # -- soldiers ------------------------------------------------------------------------------------------
    async def create_soldiers(
        self, count: int, figure: str, weapon: str, timeout: float = 60.0
    ) -> tuple[np.ndarray, np.ndarray]:
        """CREATE_SOLDIER ``count`` times, pipelined ``CREATE_WINDOW`` at a time (the server queues at most a
        few hundred control answers per client); returns (server indices, update tables)."""
        indices: list[int] = []
        tables: list[int] = []
        with trio.move_on_after(timeout) as cs:
            for k in range(0, count, CREATE_WINDOW):
                got = await self._create_window(min(CREATE_WINDOW, count - k), figure, weapon)
                indices += [a.index for a in got]
                tables += [a.table for a in got]
        if cs.cancelled_caught:
            raise LoadError(
                f"{self.name}: only {len(indices)} of {count} soldiers created within {timeout} s"
            )
        return np.array(indices, np.int64), np.array(tables, np.int64)

    async def _create_window(self, count: int, figure: str, weapon: str) -> list[SoldierCreated]:
        ids = list(range(self._next_id, self._next_id + count))
        self._next_id += count
        data = b"".join(self.conn.send(CreateSoldier(i, figure, weapon, None)) for i in ids)
        await self.send_bytes(data)
        while any(i not in self.created for i in ids) and not self.closed.is_set():
            await self.created_event.wait()
            self.created_event = trio.Event()
        answers = [self.created.pop(i, None) for i in ids]
        bad = [a for a in answers if not isinstance(a, SoldierCreated)]
        if bad:
            first = bad[0]
            why = first.message if isinstance(first, Error) else (self.failure or "no answer")
            raise LoadError(f"{self.name}: {len(bad)} of {count} soldiers not created: {why}")
        return [a for a in answers if isinstance(a, SoldierCreated)]

    async def subscribe(self, indices: np.ndarray) -> None:
        idx = np.asarray(indices, np.int64)
        for k in range(0, len(idx), MAX_INDICES_PER_MESSAGE):
            await self.send(Subscribe(tuple(idx[k : k + MAX_INDICES_PER_MESSAGE].tolist())))

    async def requests(self, rows: np.ndarray) -> None:
        """ENTITY_REQUESTS rows (server indices), split into frames as needed."""
        data = b"".join(
            self.conn.send(EntityRequests(rows[k : k + MAX_ROWS_PER_FRAME]))
            for k in range(0, len(rows), MAX_ROWS_PER_FRAME)
        )
        await self.send_bytes(data)

    async def remove(self, indices: np.ndarray) -> None:
        data = b"".join(self.conn.send(RemoveSoldier(int(i))) for i in np.asarray(indices).tolist())
        await self.send_bytes(data)

    async def goodbye(self, reason: str = "load test done") -> None:
        if self.conn.state is State.OPEN:
            await self.send(Goodbye(reason))
        if self.stream is not None:
            with trio.move_on_after(2.0):
                await self.closed.wait()
            await trio.aclose_forcefully(self.stream)

    # -- reading -------------------------------------------------------------------------------------------
    async def reader(self) -> None:
        """Read until the stream ends; run as a task for the life of the connection."""
        assert self.stream is not None
        try:
            while not self.closed.is_set():
                try:
                    data = await self.stream.receive_some(RECEIVE_BYTES)
                except (trio.BrokenResourceError, trio.ClosedResourceError):
                    data = b""
                t = trio.current_time()
                if not data:
                    self._fail(self.failure or "server closed the connection")
                    return
                self.bytes_in += len(data)
                await self._feed(bytes(data), t)
        finally:
            self.closed.set()
            self.ready.set()
            self.created_event.set()

    async def _feed(self, data: bytes, t: float) -> None:
        """Cut frames ourselves (so each update frame's size is known); tap or decode the update frames,
        hand every other frame to the Connection."""
        self.frames.feed(data)
        while not self.closed.is_set():
            try:
                frame = self.frames.next_frame(self.conn.max_frame)
            except WireError as exc:
                self._fail(f"bad frame from server: {exc}")
                return
            if frame is None:
                return
            msg_type, payload = frame
            if msg_type == MessageType.JOINT_UPDATES and self.conn.state is State.OPEN and not self.decode:
                self._tap(payload, t)
            else:
                self.conn.receive_data(encode_frame(msg_type, payload))
                await self._events(t, len(payload) + 5)

    def _tap(self, payload: bytes, t: float) -> None:
        """Header and indices of one JOINT_UPDATES payload (no pose decoding)."""
        if len(payload) < UPDATE_HEADER.size:
            self._fail("joint updates shorter than their header")
            return
        table, tick, count = UPDATE_HEADER.unpack_from(payload)
        if len(payload) < UPDATE_HEADER.size + 2 * count or table not in self.conn.tables:
            self._fail(f"malformed joint updates (table {table}, {count} soldiers, {len(payload)} bytes)")
            return
        idx = np.frombuffer(payload, ">u2", count, UPDATE_HEADER.size).astype(np.int64)
        nbytes = len(payload) + 5
        self.update_bytes += nbytes
        self.on_updates(self.number, t, tick, idx, nbytes, None)

    async def _events(self, t: float, nbytes: int) -> None:
        while True:
            ev = self.conn.next_event()
            if ev is NEED_DATA:
                return
            if isinstance(ev, JointUpdates):
                self.update_bytes += nbytes
                self.on_updates(self.number, t, ev.tick, np.asarray(ev.indices, np.int64), nbytes, ev)
            elif isinstance(ev, SoldierCreated):
                self.created[ev.id] = ev
                self.created_event.set()
            elif isinstance(ev, Ready):
                self.ready.set()
            elif isinstance(ev, Ping):
                await self.send(Pong(ev.nonce))
            elif isinstance(ev, Status):
                self.status = ev
            elif isinstance(ev, Error):
                self.errors.append(f"{ev.code}: {ev.message}")
                if ev.ref is not None:
                    self.created[ev.ref] = ev
                    self.created_event.set()
                if is_fatal(ev.code):
                    self._fail(f"server error {ev.code}: {ev.message}")
            elif isinstance(ev, ProtocolError):
                self._fail(f"protocol error {ev.code}: {ev.location}: {ev.message}")
                await self.send_bytes(self.conn.data_to_send())
                return
            elif isinstance(ev, Goodbye):
                self._fail(self.failure or f"server said goodbye: {ev.reason}")
            elif isinstance(ev, ConnectionClosed):
                return

    def _fail(self, why: str) -> None:
        if self.failure is None:
            self.failure = why
        self.closed.set()


def split_rows(rows: np.ndarray, owner: np.ndarray, nconn: int) -> list[np.ndarray]:
    """Entity-request rows grouped by the connection that owns each row's slot (``rows['index']``)."""
    own = owner[rows["index"].astype(np.int64)]
    return [rows[own == c] for c in range(nconn)]
