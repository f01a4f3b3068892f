"""JackProc and JackSoldier (seed 002, 3.5, Figures 9 and 10): the stub's connection to the Jack/TTES server.

1994: ``jack->launch(...)`` started Jack over ``rsh``, ``initsocketconnection()`` opened the sockets and
``sproc()``'d a reader, ``start("soldier_low")`` sent ``read_file("jack-ttes-soldier_low.jcl")``, the stub
waited for ``jackready``, created ``JackSoldier``\\ s, sent them requests and took joint-angle packets into a
per-soldier double buffer that ``update()`` applied to the Performer tree every frame.

Here one TCP stream speaks :mod:`protocol` (docs/PROTOCOL.md). The network side is a trio task running in its
own thread (``trio.run`` there), so the render loop never blocks on the network: it hands events to the trio
thread with ``trio.from_thread.run_sync`` (a queue push) and takes joint updates with :meth:`JackProc.swap`.
The double buffer is struct-of-arrays per update table: the reader writes the newest pose of each soldier
into the *back* buffer and flags it; ``swap`` flips the buffers under a lock and hands the render thread the
flagged rows of the *front* one, which the reader no longer touches.
"""

from __future__ import annotations

import contextlib
import logging
import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trio

from protocol.connection import CLIENT, NEED_DATA, Connection
from protocol.entity import ENTITY_REQUEST_DTYPE
from protocol.errors import LocalProtocolError, is_fatal
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
    JointUpdates,
    Ping,
    Pong,
    ProtocolError,
    Ready,
    RequestFullUpdate,
    SoldierCreated,
    Status,
    Subscribe,
    Unsubscribe,
    UpdateTableMsg,
)
from protocol.update_table import UpdateTable

log = logging.getLogger("ttes.stub.jack")
STARTUP_JCL = 'read_file("jack-ttes-{prefix}.jcl");'


class JackError(RuntimeError):
    """The connection to the server failed or was refused."""


@dataclass
class UpdateBatch:
    """Fresh poses of one update table since the last swap (server indices, protocol units)."""

    table: int
    indices: np.ndarray
    dofs: np.ndarray
    positions: np.ndarray
    orientations: np.ndarray


class UpdateBuffer:
    """Figure 10's double buffer (``buf[2]``, ``sflag``, ``buffer``) for every soldier of one update table."""

    def __init__(self, table: UpdateTable) -> None:
        self.table = table
        self.capacity = 0
        d, g = table.ndofs, table.nfigures
        self.dofs = np.zeros((2, 0, d))
        self.positions = np.zeros((2, 0, g, 3))
        self.orientations = np.zeros((2, 0, g, 4))
        self.fresh = np.zeros((2, 0), bool)
        self.back = 0

    def _grow(self, needed: int) -> None:
        """Bigger arrays; only the back buffer's flags carry over (the front's rows were handed out)."""
        cap = max(needed, 2 * self.capacity, 16)
        pad = cap - self.capacity
        self.dofs = np.concatenate([self.dofs, np.zeros((2, pad, *self.dofs.shape[2:]))], axis=1)
        self.positions = np.concatenate(
            [self.positions, np.zeros((2, pad, *self.positions.shape[2:]))], axis=1
        )
        self.orientations = np.concatenate(
            [self.orientations, np.zeros((2, pad, *self.orientations.shape[2:]))], axis=1
        )
        fresh = np.zeros((2, cap), bool)
        fresh[self.back, : self.capacity] = self.fresh[self.back]
        self.fresh = fresh
        self.capacity = cap

    def write(self, ev: JointUpdates) -> None:
        """Reader side (call with the lock held): newest pose of each soldier into the back buffer."""
        idx = np.asarray(ev.indices, np.int64)
        if not len(idx):
            return
        if idx.max() >= self.capacity:
            self._grow(int(idx.max()) + 1)
        b = self.back
        self.dofs[b, idx] = ev.dofs
        self.positions[b, idx] = ev.positions
        self.orientations[b, idx] = ev.orientations
        self.fresh[b, idx] = True

    def flip(self) -> tuple[int, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Consumer side (call with the lock held): make the back buffer the front; returns its arrays."""
        front = self.back
        self.back ^= 1
        return front, self.fresh, self.dofs, self.positions, self.orientations


class ServerView:
    """What a client knows of the server, kept from its events: the handshake, update tables and their
    double buffers, READY's soldiers, created and refused soldiers, STATUS, errors, the reason it failed.

    Shared by :class:`JackProc` (its own network thread) and :class:`client_stub.link.client.ServerLink`
    (inside the caller's trio run); each adds only what its concurrency needs (events, locks, replies)."""

    def __init__(self) -> None:
        self.accept: Accept | None = None
        self.tables: dict[int, UpdateTable] = {}
        self.ready_soldiers: dict[int, int] = {}  # server index -> update table, from READY
        self.created: dict[int, int] = {}  # server index -> update table, from SOLDIER_CREATED
        self.refused: dict[int, Error] = {}  # CREATE_SOLDIER id -> its error
        self.errors: list[Error | ProtocolError] = []
        self.status: Status | None = None
        self.failure: str | None = None
        self.last_tick = 0
        self._buffers: dict[int, UpdateBuffer] = {}

    def _absorb(self, event: object) -> None:
        """Keep what ``event`` says (a :class:`JackProc` calls it with its lock held)."""
        if isinstance(event, JointUpdates):
            buf = self._buffers.get(event.table)
            if buf is not None:
                buf.write(event)
            self.last_tick = event.tick
        elif isinstance(event, Accept):
            self.accept = event
        elif isinstance(event, UpdateTableMsg):
            self.tables[event.table.table_id] = event.table
            self._buffers[event.table.table_id] = UpdateBuffer(event.table)
        elif isinstance(event, Ready):
            self.ready_soldiers = dict(event.soldiers)
        elif isinstance(event, SoldierCreated):
            self.created[event.index] = event.table
        elif isinstance(event, Status):
            self.status = event
        elif isinstance(event, Error):
            self.errors.append(event)
            if event.ref is not None:
                self.refused[event.ref] = event
            if is_fatal(event.code):
                self.failure = f"server error {event.code}: {event.message}"
        elif isinstance(event, Goodbye):
            self.failure = self.failure or f"server said goodbye: {event.reason}"

    def _flip(self) -> list[tuple[int, int, np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
        """Flip every table's double buffer (a :class:`JackProc` calls it with its lock held)."""
        return [(tid, *buf.flip()) for tid, buf in self._buffers.items()]

    @staticmethod
    def _fresh(
        flipped: list[tuple[int, int, np.ndarray, np.ndarray, np.ndarray, np.ndarray]],
    ) -> list[UpdateBatch]:
        """The rows of the flipped front buffers that arrived since the last swap, marked taken."""
        out = []
        for tid, front, fresh, dofs, positions, orientations in flipped:
            rows = np.flatnonzero(fresh[front])
            if not len(rows):
                continue
            fresh[front, rows] = False
            out.append(
                UpdateBatch(tid, rows, dofs[front, rows], positions[front, rows], orientations[front, rows])
            )
        return out


@dataclass
class _Pending:
    done: threading.Event = field(default_factory=threading.Event)
    result: SoldierCreated | Error | None = None


class JackProc(ServerView):
    """Figure 9: the connection to Jack (the server), its update tables and its soldiers."""

    def __init__(self, name: str = "ttes-stub", role: str = "controller") -> None:
        super().__init__()
        self.name = name
        self.role = role
        self.connected = False  # handshake done
        self.jackready = False  # READY received
        self.quitting = False
        self.closed = threading.Event()  # the network task has ended
        self.table: dict[int, JackSoldier] = {}  # Figure 9's table of soldiers, by server index
        self._lock = threading.Lock()
        self._pending: dict[int, _Pending] = {}
        self._next_id = 1
        self._connected = threading.Event()
        self._ready = threading.Event()
        self._updated = threading.Event()
        self._thread: threading.Thread | None = None
        self._token: trio.lowlevel.TrioToken | None = None
        self._conn: Connection | None = None
        self._outbox: trio.MemorySendChannel[bytes] | None = None
        self._cancel: trio.CancelScope | None = None

    # -- connecting ----------------------------------------------------------------------------------------

    def initsocketconnection(self, host: str, port: int, timeout: float = 10.0) -> None:
        """Connect and shake hands (the reader runs in its own thread from now on); JackError on failure."""
        if self._thread is not None:
            raise JackError("already connected")
        self._thread = threading.Thread(target=self._run, args=(host, port), name="jack-socket", daemon=True)
        self._thread.start()
        if not self._connected.wait(timeout) or not self.connected:
            self.quit()
            raise JackError(self.failure or f"no handshake with {host}:{port} within {timeout} s")

    def start(self, soldierprefix: str = "soldier_low") -> int:
        """Send the start-up JCL, ``read_file("jack-ttes-<prefix>.jcl");``; returns its request id."""
        return self.jcl(STARTUP_JCL.format(prefix=soldierprefix))

    def jcl(self, text: str) -> int:
        rid = self._new_id()
        self.send(Jcl(text, rid))
        return rid

    def wait_ready(self, timeout: float) -> bool:
        """Wait until Jack is ready (READY received) or the connection ends."""
        self._ready.wait(timeout)  # also set when the connection ends
        return self.jackready

    # -- requests ------------------------------------------------------------------------------------------

    def send(self, event: Event) -> None:
        """Queue an event for the server (runs ``Connection.send`` in the trio thread)."""
        if self._token is None or self.closed.is_set():
            raise JackError(self.failure or "not connected")
        try:
            trio.from_thread.run_sync(self._send_now, event, trio_token=self._token)
        except trio.RunFinishedError:
            raise JackError(self.failure or "connection closed") from None
        except LocalProtocolError as exc:
            raise JackError(f"cannot send {type(event).__name__}: {exc}") from None

    def create_soldier(
        self,
        figure: str = "DI.fig",
        weapon: str = "AK_47.fig",
        index: int | None = None,
        timeout: float = 10.0,
    ) -> JackSoldier:
        """CREATE_SOLDIER and wait for the answer; JackError if the server refuses."""
        rid = self._new_id()
        pending = _Pending()
        with self._lock:
            self._pending[rid] = pending
        self.send(CreateSoldier(rid, figure, weapon, index))
        if not pending.done.wait(timeout):
            raise JackError(f"no answer to CREATE_SOLDIER {rid} within {timeout} s")
        result = pending.result
        if not isinstance(result, SoldierCreated):
            raise JackError(f"server refused soldier: {getattr(result, 'message', result)}")
        return self.soldier(result.index, result.table)

    def soldier(self, index: int, table: int) -> JackSoldier:
        """The JackSoldier of an existing server soldier (from READY or SOLDIER_CREATED)."""
        js = JackSoldier(self, index, table)
        self.table[index] = js
        return js

    def subscribe(self, indices: list[int]) -> None:
        if indices:
            self.send(Subscribe(tuple(int(i) for i in indices)))

    def unsubscribe(self, indices: list[int]) -> None:
        if indices:
            self.send(Unsubscribe(tuple(int(i) for i in indices)))

    def request_full_update(self, indices: list[int] | None = None) -> None:
        self.send(RequestFullUpdate(tuple(indices or ())))

    def send_requests(self, rows: np.ndarray) -> None:
        """One ENTITY_REQUESTS batch (``ENTITY_REQUEST_DTYPE`` rows with server indices)."""
        rows = np.asarray(rows, ENTITY_REQUEST_DTYPE)
        if len(rows):
            self.send(EntityRequests(rows))

    def wait_updates(self, timeout: float) -> bool:
        """Wait until joint updates arrived since the last :meth:`swap` (or the connection ended)."""
        return self._updated.wait(timeout) and not self.closed.is_set()

    def swap(self) -> list[UpdateBatch]:
        """Take every pose that arrived since the last call (the consumer side of the double buffers)."""
        with self._lock:
            self._updated.clear()
            flipped = self._flip()
        return self._fresh(flipped)

    def quit(self, reason: str = "quit", timeout: float = 5.0) -> None:
        """Say goodbye and stop the network thread."""
        self.quitting = True
        if self._token is not None and not self.closed.is_set():
            with contextlib.suppress(trio.RunFinishedError, RuntimeError):
                trio.from_thread.run_sync(self._goodbye, reason, trio_token=self._token)
        if self._thread is not None:
            self._thread.join(timeout)

    # -- the trio side ---------------------------------------------------------------------------------------

    def _new_id(self) -> int:
        with self._lock:
            rid = self._next_id
            self._next_id += 1
        return rid

    def _run(self, host: str, port: int) -> None:
        try:
            trio.run(self._main, host, port)
        except Exception as exc:  # the thread must end cleanly whatever happened
            self.failure = self.failure or f"network task failed: {exc!r}"
            log.warning("%s", self.failure)
        finally:
            self.connected = False
            self.closed.set()
            self._connected.set()
            self._ready.set()
            self._updated.set()
            with self._lock:
                for p in self._pending.values():
                    p.done.set()

    async def _main(self, host: str, port: int) -> None:
        self._token = trio.lowlevel.current_trio_token()
        try:
            stream = await trio.open_tcp_stream(host, port)
        except OSError as exc:
            self.failure = f"cannot connect to {host}:{port}: {exc.strerror or exc}"
            return
        conn = Connection(CLIENT)
        self._conn = conn
        send, receive = trio.open_memory_channel[bytes](float("inf"))
        self._outbox = send
        async with stream, trio.open_nursery() as nursery:
            self._cancel = nursery.cancel_scope
            nursery.start_soon(self._writer, stream, receive)
            self._send_now(Hello(self.name, self.role))
            await self._reader(stream, conn)
            await send.aclose()  # the writer drains what is queued, then ends

    async def _writer(self, stream: trio.SocketStream, receive: trio.MemoryReceiveChannel[bytes]) -> None:
        async with receive:
            async for data in receive:
                try:
                    await stream.send_all(data)
                except (trio.BrokenResourceError, trio.ClosedResourceError):
                    return

    def _send_now(self, event: Event) -> None:
        """In the trio thread: encode with the connection and queue the bytes."""
        if self._conn is None or self._outbox is None:
            raise JackError("not connected")
        data = self._conn.send(event)
        if data:
            try:
                self._outbox.send_nowait(data)
            except trio.ClosedResourceError:
                raise JackError("connection closing") from None

    def _goodbye(self, reason: str) -> None:
        with contextlib.suppress(Exception):  # already closing: nothing more to say
            self._send_now(Goodbye(reason))
        if self._outbox is not None:
            self._outbox.close()
        if self._cancel is not None:  # a server that does not close after GOODBYE is not waited for long
            self._cancel.deadline = min(self._cancel.deadline, trio.current_time() + 2.0)

    async def _reader(self, stream: trio.SocketStream, conn: Connection) -> None:
        while True:
            event = conn.next_event()
            if event is NEED_DATA:
                try:
                    data = await stream.receive_some(1 << 16)
                except (trio.BrokenResourceError, trio.ClosedResourceError):
                    data = b""
                conn.receive_data(data)
                continue
            if isinstance(event, ProtocolError | ConnectionClosed):
                if isinstance(event, ProtocolError):
                    self.errors.append(event)
                    self.failure = f"protocol error {event.code}: {event.location}: {event.message}"
                    log.warning("%s", self.failure)
                    out = conn.data_to_send()
                    if out and self._outbox is not None:
                        self._outbox.send_nowait(out)
                return
            self._handle(event)

    def _handle(self, event: object) -> None:
        with self._lock:
            self._absorb(event)
            if isinstance(event, JointUpdates):
                self._updated.set()
        if isinstance(event, Accept):
            self.connected = True
            self._connected.set()
        elif isinstance(event, Ready):
            self.jackready = True
            self._ready.set()
        elif isinstance(event, SoldierCreated):
            self._resolve(event.id, event)
        elif isinstance(event, Ping):
            self._send_now(Pong(event.nonce))
        elif isinstance(event, Error):
            log.warning("server error %d: %s", event.code, event.message)
            if event.ref is not None:
                self._resolve(event.ref, event)

    def _resolve(self, rid: int, result: SoldierCreated | Error) -> None:
        with self._lock:
            pending = self._pending.pop(rid, None)
        if pending is not None:
            pending.result = result
            pending.done.set()


class JackSoldier:
    """Figure 10: one soldier on the server, its requests, and its update table.

    Figure 10's ``receive`` (fill a buffer) and ``update`` (apply it to the soldier's DCS nodes) are done
    for all soldiers at once: :class:`UpdateBuffer` holds every soldier's ``buf[2]``, :meth:`JackProc.swap`
    hands the fresh rows over, and ``StubApp`` writes them into the soldiers' scene graphs in one batch."""

    def __init__(self, jp: JackProc, soldiernum: int, table: int) -> None:
        self.jp = jp
        self.soldiernum = soldiernum
        self.updatetable = table

    def request(
        self,
        appear: int,
        weapon: int,
        velocity: np.ndarray | tuple[float, float, float],
        heading: float,
        position: np.ndarray | tuple[float, float, float],
        immediate: bool = False,
    ) -> None:
        """Send this soldier's DIS state (Figure 11's JackPackIn)."""
        row = np.zeros(1, ENTITY_REQUEST_DTYPE)
        row["index"] = self.soldiernum
        row["appearance"] = appear
        row["weapon"] = weapon
        row["velocity"] = velocity
        row["heading"] = heading
        row["position"] = position
        row["immediate"] = int(bool(immediate))
        self.jp.send_requests(row)


# -- launching a server (1994: rsh <remotehost> jack-ntsc-g ...) ------------------------------------------


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port free on ``host`` right now (the server binds it a moment later)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


class ServerProcess:
    """``ttes server`` as a child process on a free loopback port; ``stop()`` ends it cleanly."""

    def __init__(
        self, port: int | None = None, host: str = "127.0.0.1", extra: list[str] | None = None
    ) -> None:
        self.host = host
        self.port = port or free_port(host)
        cmd = [
            sys.executable,
            "-m",
            "ttes",
            "server",
            "--host",
            host,
            "--port",
            str(self.port),
            *(extra or []),
        ]
        root = Path(__file__).resolve().parents[2]
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")]))
        # the server's log goes to a file: a pipe nobody reads would fill up and stall the server
        self.log = tempfile.TemporaryFile(mode="w+", encoding="utf-8", errors="replace")  # noqa: SIM115 (closed in stop)
        self.proc = subprocess.Popen(
            cmd, cwd=root, env=env, stdout=subprocess.DEVNULL, stderr=self.log, text=True
        )

    def log_tail(self, chars: int = 2000) -> str:
        """The end of what the server wrote to stderr."""
        self.log.flush()
        self.log.seek(0)
        return self.log.read()[-chars:]

    def wait_listening(self, timeout: float = 30.0) -> None:
        """Poll until the port accepts connections; JackError if the server exits or stays silent."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise JackError(
                    f"ttes server exited with {self.proc.returncode}: {self.log_tail(500).strip()}"
                )
            try:
                with socket.create_connection((self.host, self.port), timeout=0.5):
                    return
            except OSError:
                time.sleep(0.1)
        raise JackError(f"ttes server not listening on {self.host}:{self.port} after {timeout} s")

    def stop(self, timeout: float = 5.0) -> int | None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(timeout)
        self.log.close()
        return self.proc.returncode
