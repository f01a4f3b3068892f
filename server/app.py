"""The trio server: listener, per-client reader/writer tasks, the tick loop, status reports, shutdown.

Structure (one trio nursery):

* the **tick loop** advances every soldier at ``tick_hz`` on trio's clock (``SoldierManager.tick``: one
  vectorised advance + sample), writes the poses once into the shared :class:`~server.pose_board.PoseBoard`
  and wakes the writers — it never waits for a client;
* per client a **reader** (bytes → protocol events → the world) and a **writer** (control queue + the
  latest poses, encoded against what that client last received) — see :mod:`server.session` for why memory
  stays bounded and a stalled client cannot slow anyone else;
* soldiers with new requests get an out-of-cycle update as soon as their reader has handled them
  (:meth:`TtesServer.answer_requests`, ``SoldierManager.answer``), so the update that reflects a request does
  not wait for the next tick (issue 16: one-tick latency). A session holds its requests and its reader lets
  the other readers in first (:meth:`TtesServer.take_requests`): the requests of every client that sent at
  that moment are applied and answered as one batch (:mod:`server.pending_requests`: a batch's cost is mostly
  fixed). The tick and the writers of a tick's frames **let the readers in** first
  (:meth:`TtesServer.let_readers_in`) and apply what they hold: a request that arrived just before a tick is
  answered (and written) before the tick samples; one that arrived while it sampled is answered by that tick
  first (:meth:`TtesServer.run_tick`: those soldiers sampled again, published and written as the tick's
  first frames, before the rest of the tick is quantised and encoded); one that
  arrived during the publish or the writers' encodes is answered as more of the tick before the next writer
  encodes (:meth:`TtesServer._answer_in_tick`: the writers of a tick encode it one at a time, each after
  letting the readers in), and each writer writes its client's answered soldiers before it encodes the rest
  of the tick (:meth:`TtesServer._tick_output`). A writer woken by answers alone writes them at once;
* a **status loop** sends STATUS every report interval (``set_ttes_report_interval``) and logs it;
* **shutdown** (SIGINT/SIGTERM via ``trio.open_signal_receiver`` in :func:`run_server`, or
  :meth:`TtesServer.shutdown`): stop accepting, send GOODBYE to every client, let the writers flush briefly,
  then cancel everything.

The manager reads no clock: ``now`` is trio's clock minus the server's start time, so tests drive it with
``autojump_clock`` and real TCP sockets.

Debugging over the wire: the JCL commands ``report_ttes_status("s0", ...)`` and ``report_ttes_clips("s0")``
answer the calling client with a STATUS whose ``text`` is JSON — each soldier's mode, posture, current clip,
its start and duration (``SoldierManager.soldier_info``), or the clips it started (``set_ttes_clip_recording
("yes")`` or ``record_clips = true`` in the config).
"""

from __future__ import annotations

import contextlib
import errno
import ipaddress
import math
import os
import signal
import threading
import time
from collections.abc import Awaitable, Callable
from typing import Any

import numpy as np
import trio

from protocol.connection import State
from server.config import ConfigError, ServerConfig
from server.gc_freeze import freeze_loaded
from server.listen import bind_tcp
from server.logging import get_logger
from server.pending_requests import PendingRequests
from server.pose_board import BoardRef, PoseBoard
from server.session import Session
from server.soldier.manager import TickUpdate
from server.stage_cpu import TURN_CPU_S, DeafSpans, StageCpu
from server.startup import ServerWorld
from server.tls import server_context
from server.trace import TRACE
from server.websocket import WebSocketStream, origin_allowed
from server.world.commands import needs_worker

# a front-end reader's CPU per turn of its client's buffered events (a burst yields between); a single
# server's reader answers what it handled after each turn, so it keeps handling all that is buffered
READ_TURN_S = TURN_CPU_S
FLUSH_ON_CLOSE_S = 2.0  # how long a closing session's writer may take to flush its last bytes
SHUTDOWN_GRACE_S = 1.0
# TTES_FRONT_TURNS=0: a front-end's woken writers encode back to back, as before (_encode; a bench's A/B)
FRONT_TURNS = os.environ.get("TTES_FRONT_TURNS") != "0"
# clip ends a shard's tick handles between two looks at its CPU (each piece's passes cost a fixed part)
ADVANCE_ROWS = 500
# TTES_ANSWERS_FIRST=0: a shard's tick carries the requests it took while it sampled in its own batch, and a
# front-end merges the answers and the ticks that arrived together in one publish, as before (a bench's A/B)
ANSWERS_FIRST = os.environ.get("TTES_ANSWERS_FIRST") != "0"
MAX_TICK_BACKLOG = 5  # ticks: a server that falls further behind skips ahead instead of bursting
log = get_logger("app")


class TtesServer:
    """``ttes server``: the world (JCL, manager, library) behind a TCP listener."""

    def __init__(self, config: ServerConfig, world: ServerWorld | None = None) -> None:
        self.config = config
        self._t0 = 0.0
        self._clock_started = False  # serve() starts the clock: until then server time is 0
        self.world = world or ServerWorld(
            config.data_dir,
            max_soldiers=config.max_soldiers,
            record_clips=config.record_clips,
            cache_dir=config.cache_dir,
        )
        self.world.clock = self.request_time
        self.world.owners.per_owner = config.max_soldiers_per_client
        self.world.soldiers.configure(tick_period=1.0 / config.tick_hz)  # the throttle caps a rate on it
        self._last_stamp = 0.0
        self.world.events.ready = self._on_ready
        self.world.events.soldier_created = self._on_created
        self.world.events.soldier_removed = self._on_removed
        self.world.events.report = self._on_report
        self.board_ref = BoardRef()
        self.sessions: dict[int, Session] = {}
        self.addresses: list[tuple[str, int]] = []
        self.ws_addresses: list[tuple[str, int]] = []  # the WebSocket listeners (``ws_port``), if any
        self.ticks = 0
        self.tick_overruns = 0
        self.ticks_skipped = 0
        self.clients_total = 0
        self.clients_dropped = 0
        self._batches_window = (0.0, 0)  # (time, ticks that published poses) at the last status report
        self._published_ticks = 0
        self._counted_tick = -1  # the wire tick last counted in _published_ticks
        self._shutdown = trio.Event()
        self._requests_seen = 0  # the manager's request and reaction count at the last answer
        self.pending = PendingRequests(self.world)  # requests the readers hold: applied as one batch
        self.answers = 0  # out-of-cycle publishes
        self.next_tick = 0.0  # server time of the next scheduled tick (what an answer samples at)
        self._ticking = False  # between a tick's sampling and its publish: requests are folded into it
        self._requests_at_tick = 0  # the request count when the tick sampled
        self._answer_after_tick = False  # soldiers taken up by the tick that it could not show yet
        self._tick_serial = 0  # the board's serial after the last tick's publish (its encodes follow)
        self._tick_now = 0.0  # the last tick's time
        self._encode_turn = trio.Lock()  # writers encode one at a time (_tick_output; a front-end's: _encode)
        self.last_tick_seconds = 0.0  # the last tick's own time (sampling and publish, not the pause)
        self.stopped = trio.Event()
        self.started = False
        self._cancel: trio.CancelScope | None = None
        self._nursery: trio.Nursery | None = None
        self._tls = server_context(config)  # None: plain TCP
        self._bound: list[Any] | None = None  # listening sockets bound by bind(), before serve()
        self._bound_ws: list[Any] = []  # and the WebSocket port's
        self.on_tick: Callable[[Any], None] | None = None  # test hook: called with each TickUpdate
        self.cpu = StageCpu()  # the loop's CPU per stage, in the status log line
        # a server process's (the CLI's): the loaded library frozen out of the GC's full collections
        self.freeze_gc = False
        self._frozen_library: object | None = None
        self.deaf = DeafSpans() if os.environ.get("TTES_DEAF") == "1" else None  # a bench's: loop_deaf_ms
        # a shard's: called after each publish with the board (server.fabric: the batch for the front-ends)
        self.on_publish: Callable[[PoseBoard, bool], None] | None = None
        self._asked_in_tick = np.zeros(0, np.int64)  # a shard's: soldiers with requests when its tick sampled
        # answers go before the ticks they came with: a shard's tick's first frames (_shard_first), a
        # front-end's merge (server.fabric.nodes.FrontNode.feed)
        self.answers_first = ANSWERS_FIRST
        self.encoded: Callable[[Session], None] | None = None  # a front-end's: after a writer's encode
        self.board_poses = True  # the board keeps the Jack-unit poses beside the codes (:meth:`codes_only`)
        # a front-end's: fills the board from elsewhere (the shards' batches) instead of the manager, which
        # then only keeps the books; called with the wire tick to label them, returns the soldiers changed
        self.feed: Callable[[PoseBoard, int], np.ndarray] | None = None
        self.relay_out: Callable[[], None] | None = None  # a front-end's: send what was relayed, now
        self.status_note: Callable[[], str] | None = (
            None  # appended to STATUS (a shard's or front-end's role)
        )
        self.status_fields: Callable[[], dict[str, object]] | None = None  # added to the log's status line
        self._jcl_lock = trio.Lock()  # one JCL frame at a time (its loads run in a worker thread)
        self._loop_thread = threading.get_ident()
        self._trio_token: trio.lowlevel.TrioToken | None = None
        self.world.in_loop = self._in_loop

    # -- clock -------------------------------------------------------------------------------------------
    def now(self) -> float:
        """Server time in seconds since :meth:`serve` started (trio's clock); 0 before. A start-up run inside
        trio before serve (``ttes replay/gateway/cigi --with-server``) must not stamp trio's absolute time on
        the world: every later tick would run at that frozen stamp and no soldier would move."""
        if not self._clock_started:
            return 0.0
        try:
            return trio.current_time() - self._t0
        except RuntimeError:  # outside trio (start-up before the run loop)
            return 0.0

    def request_time(self) -> float:
        """The time stamped on a request (and on soldiers created): now, remembered so that no tick runs
        the manager at an earlier time than a request it has already taken."""
        self._last_stamp = max(self._last_stamp, self.now())
        return self._last_stamp

    # -- world events ------------------------------------------------------------------------------------
    def _board(self) -> PoseBoard | None:
        if self.board_ref.board is None and self.world.library is not None:
            table = self.world.sets[0].table
            self.board_ref.board = PoseBoard(table.ndofs, table.nfigures, poses=self.board_poses)
        return self.board_ref.board

    def codes_only(self) -> None:
        """The board keeps the codes alone (a shard's: its batches carry codes and nothing reads the poses;
        ``PoseBoard.drop_poses``); what clients receive is the same."""
        self.board_poses = False
        if self.board_ref.board is not None:
            self.board_ref.board.drop_poses()

    def _on_ready(self, caller: object | None) -> None:
        self._board()
        self._freeze_library()
        for s in self.sessions.values():
            if s is caller or not s.ready_sent:
                s.send_ready()

    def _on_created(self, index: int) -> None:
        board = self._board()
        if board is not None:
            board.add(index, self.world.table_of(index))
        for s in self.sessions.values():
            s.conn.reset_soldiers([index])  # a reused index starts with a full update
            s.force[index] = True

    def _on_removed(self, index: int, reason: str) -> None:
        if self.board_ref.board is not None:
            self.board_ref.board.remove(index)
        for s in self.sessions.values():
            s.soldier_removed(index, reason)

    def _on_report(self, caller: object | None, text: str) -> None:
        if isinstance(caller, Session):
            caller.report(text)

    def _in_loop(self, func: Callable[[], object]) -> object:
        """Run a JCL command that touches soldiers, settings or clients on the trio loop (called from the
        worker thread that runs a client's JCL; called on the loop, it just runs)."""
        if self._trio_token is None or threading.get_ident() == self._loop_thread:
            return func()
        return trio.from_thread.run_sync(func, trio_token=self._trio_token)

    async def run_jcl(self, session: Session) -> None:
        """A client's JCL frame. One that may load files runs in a worker thread: the loads run there, beside
        the tick; every other command hops back to the loop between ticks (``ServerWorld.in_loop``). Any
        other frame runs here at once (``needs_worker``). One frame at a time."""
        ev, session.pending_jcl = session.pending_jcl, None
        if ev is None:
            return
        async with self._jcl_lock:
            if needs_worker(ev.text, self.world.is_startup_script):
                error = await trio.to_thread.run_sync(session.run_jcl, ev)
            else:
                error = session.run_jcl(ev)
        session.jcl_done(ev, error)

    # -- running -----------------------------------------------------------------------------------------
    def start_world(self) -> None:
        """Run the start-up script (JclError if it fails) and apply the config's overrides; once."""
        if self.started:
            return
        self.started = True
        t = time.perf_counter()
        if self.config.startup_script:
            self.world.run_startup(self.config.startup_script)
        if self.config.throttle is not None:
            self.world.set_throttle(self.config.throttle)
        if self.config.report_interval is not None:
            self.world.set_report_interval(self.config.report_interval)
        self._board()
        self._freeze_library()
        m = self.world.manager
        log.info(
            "startup_done",
            seconds=round(time.perf_counter() - t, 3),
            ready=self.world.ready,
            soldiers=m.count if m else 0,
            data_dir=str(self.world.data_dir),
        )

    def _freeze_library(self) -> None:
        """With ``freeze_gc``: once a library is loaded (by the start-up script, or later for the first
        READY), keep what the loading made out of the GC's full collections (:mod:`server.gc_freeze`)."""
        library = self.world.soldiers.library
        if self.freeze_gc and library is not None and library is not self._frozen_library:
            self._frozen_library = library
            freeze_loaded()

    def bind(self) -> None:
        """Bind the listening sockets now, before :meth:`start_world` loads anything: a port in use fails at
        once with a ListenError naming host:port (OSError). :meth:`serve` binds when this was not called."""
        if self._bound is None:
            self._bound = bind_tcp(self.config.host, self.config.port)
            if self.config.ws_port is not None:
                try:
                    self._bound_ws = bind_tcp(self.config.host, self.config.ws_port)
                except OSError:
                    for s in self._bound:
                        s.close()
                    self._bound = None
                    raise

    async def serve(self, *, task_status: Any = trio.TASK_STATUS_IGNORED) -> None:
        """Start up, listen, and run until :meth:`shutdown`; ``task_status.started(addresses)``."""
        self._t0 = trio.current_time()
        self._clock_started = True
        self._loop_thread = threading.get_ident()
        self._trio_token = trio.lowlevel.current_trio_token()
        if self.deaf is not None:
            trio.lowlevel.add_instrument(self.deaf)
        check_exposure(self.config)
        self.start_world()
        self.bind()
        bound, self._bound = self._bound or [], []
        bound_ws, self._bound_ws = self._bound_ws, []
        listeners = [trio.SocketListener(trio.socket.from_stdlib_socket(s)) for s in bound]
        ws_listeners = [trio.SocketListener(trio.socket.from_stdlib_socket(s)) for s in bound_ws]
        self.addresses = [tuple(ln.socket.getsockname()[:2]) for ln in listeners]
        self.ws_addresses = [tuple(ln.socket.getsockname()[:2]) for ln in ws_listeners]
        async with trio.open_nursery() as nursery:
            self._cancel = nursery.cancel_scope
            self._nursery = nursery
            nursery.start_soon(self._tick_loop)
            nursery.start_soon(self._status_loop)
            nursery.start_soon(
                self._accept_all,
                [(ln, False) for ln in listeners] + [(ln, True) for ln in ws_listeners],
                nursery,
            )
            log.info(
                "listening",
                addresses=[f"{h}:{p}" for h, p in self.addresses],
                websocket=[f"{h}:{p}" for h, p in self.ws_addresses],
                ready=self.world.ready,
            )
            task_status.started(self.addresses)
            await self._shutdown.wait()
            for ln in listeners + ws_listeners:
                await ln.aclose()
            for s in list(self.sessions.values()):
                s.goodbye("server shutting down")
            with trio.move_on_after(SHUTDOWN_GRACE_S):
                while self.sessions:
                    await trio.sleep(0.01)
            nursery.cancel_scope.cancel()
        self.stopped.set()
        log.info("stopped", ticks=self.ticks, clients=self.clients_total)

    def shutdown(self) -> None:
        self._shutdown.set()

    def spawn(self, task: Callable[[], Awaitable[None]]) -> None:
        """Run ``task`` beside the server's own tasks (a fabric node's), cancelled with them; once serving."""
        assert self._nursery is not None, "spawn() before serve() started"
        self._nursery.start_soon(task)

    async def _accept_all(
        self, listeners: list[tuple[trio.SocketListener, bool]], nursery: trio.Nursery
    ) -> None:
        """Accept on every listener; ``(listener, True)`` is a WebSocket port (:mod:`server.websocket`)."""

        async def one(listener: trio.SocketListener, websocket: bool) -> None:
            while True:
                try:
                    stream = await listener.accept()
                except trio.ClosedResourceError:
                    return
                except OSError as exc:  # EMFILE and friends: back off, keep serving the others
                    log.warning(
                        "accept_failed", error=str(exc), errno=errno.errorcode.get(exc.errno or 0, "")
                    )
                    await trio.sleep(0.1)
                    continue
                nursery.start_soon(self._client, stream, websocket)

        async with trio.open_nursery() as inner:
            for ln, websocket in listeners:
                inner.start_soon(one, ln, websocket)

    # -- one client --------------------------------------------------------------------------------------
    def _wrap(self, socket: trio.SocketStream, websocket: bool) -> trio.abc.Stream:
        """The session's byte stream over the accepted socket: TLS when configured, then WebSocket (whose
        messages may hold a frame and its 5-byte head at the most)."""
        stream: trio.abc.Stream = (
            socket if self._tls is None else trio.SSLStream(socket, self._tls, server_side=True)
        )
        if websocket:
            origins = self.config.ws_origins
            stream = WebSocketStream(
                stream,
                max_message=self.config.max_frame + 5,
                accept_origin=lambda o: origin_allowed(o, origins),
            )
        return stream

    async def _client(self, socket: trio.SocketStream, websocket: bool = False) -> None:
        try:
            host, port = socket.socket.getpeername()[:2]
            peer = f"{host}:{port}"
        except OSError:
            peer = "?"
        self.clients_total += 1
        session = Session(self.world, self.board_ref, self.config, peer)
        session.offload_jcl = True
        session.pending = self.pending
        session.local = _is_loopback(socket)
        session.full = len(self.sessions) >= self.config.max_clients
        same_host = (
            sum(s.peer.rpartition(":")[0] == host for s in self.sessions.values()) if peer != "?" else 0
        )
        session.crowded = same_host if same_host >= self.config.max_clients_per_host else 0
        self.sessions[session.id] = session
        stream = self._wrap(socket, websocket)
        try:
            async with trio.open_nursery() as n:
                n.start_soon(self._writer, session, stream, n.cancel_scope)
                n.start_soon(self._status_task, session)
                await self._reader(session, stream)
                session.drop(session.drop_reason or "closed")
                with trio.move_on_after(FLUSH_ON_CLOSE_S):
                    await session.writer_done.wait()
                    if session.lingering:
                        await _linger(stream)
                n.cancel_scope.cancel()
        finally:
            self.sessions.pop(session.id, None)
            if self.board_ref.on_watch is not None:  # a front-end: what it watched may be watched no more
                self.board_ref.on_watch(None)
            self._left(session)
            with trio.CancelScope(shield=True):
                await trio.aclose_forcefully(stream)
            if session.dropped:
                self.clients_dropped += 1
            log.info(
                "client_closed",
                session=session.id,
                peer=peer,
                websocket=websocket,
                name=session.name,
                reason=session.drop_reason,
                bytes_out=session.bytes_out,
            )

    async def _reader(self, session: Session, stream: trio.abc.Stream) -> None:
        with trio.move_on_after(self.config.handshake_timeout):
            while session.conn.state is State.HANDSHAKE and not session.closing:
                data = await _receive(stream)
                session.feed(data)
                if not data:
                    session.drop(session.drop_reason or "closed")
        if session.conn.state is State.HANDSHAKE and not session.closing:
            session.drop("no HELLO in time", dropped=True)
        if self.pending.holds(session):  # requests in the HELLO's packet: answered now, not at the next tick
            await self.take_requests()
        frame_started: float | None = None  # when the frame now received in part began arriving
        while not session.closing:
            deadline = math.inf if frame_started is None else frame_started + self.config.frame_timeout
            data = b""
            with trio.move_on_at(deadline) as cs:
                data = await _receive(stream)
            if cs.cancelled_caught:
                session.drop(f"a frame not completed in {self.config.frame_timeout:g} s", dropped=True)
                return
            session.conn.receive_data(data)
            await self._handle_buffered(session)
            if not data:
                session.drop(session.drop_reason or "closed")
                return
            if not session.conn.pending_bytes:
                frame_started = None
            elif frame_started is None:
                frame_started = trio.current_time()

    async def _handle_buffered(self, session: Session) -> None:
        """Handle what the client sent; the socket is not read meanwhile (TCP backpressure): while it is over
        its request rate, and while its JCL runs."""
        while not session.closing:
            with self.cpu("requests"):
                wait = session.resume(self.now(), READ_TURN_S if self.feed is not None else None)
            await self.take_requests()
            if session.more:  # a burst: the tick and the other clients run before its next turn
                await trio.lowlevel.checkpoint()
            elif session.pending_jcl is not None:
                await self.run_jcl(session)
            elif session.output_full:  # the client's answers wait: read on once the writer took them
                session.drained = trio.Event()
                session.notify()
                await session.drained.wait()
            elif wait > 0:  # over the request rate
                await trio.sleep(wait)
            else:
                return

    async def _writer(self, session: Session, stream: trio.abc.Stream, scope: trio.CancelScope) -> None:
        """Write control bytes and the latest poses whenever woken; exits (cancelling the session) when the
        session is closing and flushed, the peer is gone, or one write stalls for ``write_timeout``."""
        try:
            while True:
                if session.retry_at is None:
                    await session.wake.wait()
                else:  # updates held back by the connection's own throttle: write them when due
                    with trio.move_on_at(self._t0 + session.retry_at):
                        await session.wake.wait()
                if session.ticked and self.feed is None:  # a tick's frames: the readers' answers go with them
                    tick_data = await self._tick_output(session, stream)
                    if tick_data is None:
                        return
                    data = tick_data
                else:  # woken by answers alone (written at once, not after the next reader's answer), or a
                    # front-end's tick (its readers answer nothing, its shards do: at once, in turns: _encode)
                    if session.ticked:  # (a front-end's more_of_tick: answers merged before a tick's rows)
                        session.ticked = False
                        self.apply_held()
                    data = await self._encode(session)
                session.drained.set()
                if not await self._send(session, stream, data):
                    return
                if session.closing and not session.control:
                    return
        except (trio.BrokenResourceError, trio.ClosedResourceError):
            session.drop(session.drop_reason or "connection lost")
            session.lingering = False
        finally:
            session.writer_done.set()
            if not session.lingering:
                scope.cancel()

    async def _encode(self, session: Session) -> bytes:
        """What ``session``'s writer writes now. A front-end's writers take turns, each letting the readers
        and the shards' batches in before its encode and sending the requests they relay: a request or an
        answer that arrives during one client's encode waits for that encode only, not for every woken
        client's (issue 21: a shard's batch woke both clients' writers, and their ~3.5 ms encodes ran back
        to back before any socket was read, the relayed requests sent after both)."""
        if self.feed is None or not FRONT_TURNS:
            return self._encode_now(session)
        async with self._encode_turn:
            await self.let_readers_in()
            self.apply_held()  # the requests they hold go to their shards before this encode, not after
            if self.relay_out is not None:
                self.relay_out()
            return self._encode_now(session)

    def _encode_now(self, session: Session) -> bytes:
        session.wake = trio.Event()  # a publish from here on wakes it again
        with self.cpu("encode"):
            data = session.take_output(self.now())
        if self.encoded is not None:
            self.encoded(session)
        return data

    async def _tick_output(self, session: Session, stream: trio.abc.Stream) -> bytes | None:
        """A single server's writer woken by a tick: its client's frames of the tick (None: a write stalled).

        The writers of a tick encode it one at a time (``_encode_turn``), each after letting the readers in:
        a request that landed during another writer's encode is then applied and answered as more of the
        tick (:meth:`_answer_in_tick`) before this one encodes, and this client's answered soldiers are
        written first, on their own (outside the turn: a stalled client holds no other writer up), before
        it encodes the tick's other rows (issue 16: such a request waited for every encode of the tick and
        then for its own)."""
        while True:
            async with self._encode_turn:
                session.more_of_tick = False
                await self.let_readers_in()
                self.apply_held()  # (while this writer owes the tick: answered as more of it)
                with self.cpu("encode"):
                    early = session.take_answers(self._tick_serial)
                    if not early:
                        session.ticked = False
                        session.wake = trio.Event()
                        return session.take_output(self.now())
            if not await self._send(session, stream, early):
                return None

    async def _send(self, session: Session, stream: trio.abc.Stream, data: bytes) -> bool:
        """Write ``data`` (nothing: nothing to do); False: the write stalled and the session is dropped."""
        if not data:
            return True
        timeout = self.config.write_timeout
        session.sending = True
        try:
            with trio.move_on_after(timeout) as cs:
                await stream.send_all(data)
        finally:
            session.sending = False
        if cs.cancelled_caught:
            log.warning("client_stalled", session=session.id, name=session.name, seconds=timeout)
            session.drop(f"write stalled for {timeout:g} s", dropped=True)
            session.lingering = False
            return False
        session.bytes_out += len(data)
        if TRACE is not None:
            TRACE.stamp("sent", session.trace_rows)
            session.trace_rows = session.trace_rows[:0]
        return True

    # -- ticks and reports -------------------------------------------------------------------------------
    async def _tick_loop(self) -> None:
        period = 1.0 / self.config.tick_hz
        next_t = trio.current_time()
        while True:
            self.next_tick = next_t - self._t0
            await trio.sleep_until(next_t)
            await self.let_readers_in()  # answers to requests just before the tick go out before it samples
            answers = self.answers
            self.apply_held()
            if self.answers != answers:  # their writers write them before the tick samples, not after
                await self.let_readers_in()
                self.apply_held()
            await self.run_tick(next_t - self._t0)
            next_t += period
            if self._answer_after_tick:
                self._answer_after_tick = False
                self.next_tick = next_t - self._t0
                self.answer_requests()
            now = trio.current_time()
            if now - next_t > MAX_TICK_BACKLOG * period:  # fell far behind: skip, do not burst
                skipped = math.floor((now - next_t) / period)
                self.ticks_skipped += skipped
                next_t += skipped * period
                self.tick_overruns += 1

    @staticmethod
    async def let_readers_in() -> None:
        """Two passes of the scheduler. Trio polls the sockets between its batches of runnable tasks and runs
        a batch in either order: after the first pass the readers with bytes waiting (and the writers woken)
        are in this task's batch, after the second they have run. So what arrived during a long step is
        handled, and answered, before the next long step starts."""
        await trio.lowlevel.checkpoint()
        await trio.lowlevel.checkpoint()

    def tick(self, scheduled: float | None = None) -> None:
        """One server tick at once: advance + sample every soldier, publish the poses, wake the writers."""
        update = self.sample_tick(scheduled)
        if update is not None:
            self.publish_tick(update)

    async def run_tick(self, scheduled: float | None = None) -> None:
        """The tick loop's tick: the readers are let in between the sampling and the publish, and the
        soldiers whose requests they applied meanwhile are sampled again at the tick's time and published
        first, as the tick's first frames (:meth:`_answer_first`): their writers send them before the rest of
        the tick is quantised and encoded, so a request that lands while the tick samples waits for the
        sampling only (issue 16). Requests taken after that are folded into the tick's publish
        (:meth:`publish_tick`)."""
        first = False
        if self.on_publish is not None:  # a shard's
            update = await self._shard_sample(scheduled)
            if update is not None and self.answers_first:
                first = self._shard_first(update)
        else:
            update = self.sample_tick(scheduled)
        if update is None:
            return
        spent = self.last_tick_seconds
        self._ticking = True  # the readers' answers wait: this tick takes them up
        try:
            await self.let_readers_in()
            with self.cpu("requests"):
                self.pending.apply()
            if self.on_publish is None:  # a shard's batches count a tick's publishes: no first publish
                first = await self._answer_first(update)
                spent += self.last_tick_seconds
        finally:
            self._ticking = False
        self.publish_tick(update, first)
        self.last_tick_seconds += spent

    async def _shard_sample(self, scheduled: float | None) -> TickUpdate | None:
        """A shard's sampling in stretches of about ``TURN_CPU_S`` (issue 21: its loop was deaf for the whole
        of it, 15-20 ms of CPU at 10,000 soldiers when many clips end together): the soldiers are advanced
        to the tick's time a piece at a time, the fabric's requests let in between (applied, their answers
        held: a request brings its soldier up to date itself), then the due ones are sampled, so the tick's
        own batch carries what those requests asked for. None: not ready (:meth:`sample_tick` says why)."""
        m, board = self.world.manager, self._board()
        if m is None or board is None or not self.world.ready:
            return None
        t0 = time.perf_counter()
        self.ticks += 1
        now = self.now() if scheduled is None else max(scheduled, self._last_stamp)
        with self.cpu("animate"):
            ending = m.tick_start(now)
        self._requests_at_tick = self._request_count()
        spent = time.perf_counter() - t0
        end = time.thread_time() + TURN_CPU_S
        for rows in np.array_split(ending, max(1, len(ending) // ADVANCE_ROWS)):
            t0 = time.perf_counter()
            with self.cpu("animate"):
                m.tick_advance_rows(rows)
            spent += time.perf_counter() - t0
            if time.thread_time() >= end:
                await self._let_fabric_in()
                end = time.thread_time() + TURN_CPU_S
        await self._let_fabric_in()
        t0 = time.perf_counter()
        if self.answers_first:  # (tick_emit clears the flags it samples)
            self._asked_in_tick = np.flatnonzero(m.table.requested)
        with self.cpu("animate"):
            update = m.tick_emit(now)
        self.last_tick_seconds = spent + time.perf_counter() - t0
        return update

    def _shard_first(self, update: TickUpdate) -> bool:
        """A shard's tick's first publish: the soldiers whose requests it took while it sampled (their poses
        are in ``update``), as an answer batch of their own before the tick's (issue 21: they waited for
        the quantising and the batch of every soldier, and at the front-end for the encode of the whole
        tick). The tick's publish (``again``) then finds their codes unchanged and sends them no second
        time. False: none of them is in the tick (nothing published)."""
        asked, self._asked_in_tick = self._asked_in_tick, np.zeros(0, np.int64)
        board = self._board()
        if not len(asked) or board is None:
            return False
        sel = np.flatnonzero(np.isin(update.indices, asked))
        if not len(sel):
            return False
        part = update.select(sel)
        t0 = time.perf_counter()
        if self.on_tick is not None:
            self.on_tick(part)
        with self.cpu("quantise"):
            changed = board.publish(part, self.world)
        self._published(board, changed, part.indices, tick=False, more=True)
        self.last_tick_seconds += time.perf_counter() - t0
        return True

    async def _let_fabric_in(self) -> None:
        """Within a shard's tick: the requests that reached the fabric are taken (their answers held for the
        tick). One pass more than :meth:`let_readers_in`: the fabric's thread wakes the loop by
        ``run_sync_soon``."""
        self._ticking = True
        try:
            await self.let_readers_in()
            await trio.lowlevel.checkpoint()
        finally:
            self._ticking = False

    async def _answer_first(self, update: TickUpdate) -> bool:
        """The soldiers whose requests were applied while the tick sampled: sampled again at the tick's time
        and published as the tick's first frames (under its number; False: nothing to publish). ``update``
        then carries their new poses, so the tick's publish finds them unchanged and sends them no second
        time; their writers write them now, each before it encodes the rest of the tick."""
        self.last_tick_seconds = 0.0
        seen = self._request_count()
        if seen == self._requests_at_tick:
            return False
        self._requests_at_tick = self._requests_seen = seen
        m, board = self.world.manager, self._board()
        assert m is not None and board is not None
        t0 = time.perf_counter()
        with self.cpu("animate"):
            again = m.answer(update.now, update.now)  # at the tick's time: its due rule
        if not len(again):
            return False
        if self.on_tick is not None:
            self.on_tick(again)
        with self.cpu("quantise"):
            changed = board.publish(again, self.world)
            update.take(again)
        self._answer_still(again)
        self.last_tick_seconds = time.perf_counter() - t0
        if changed:
            self._published(board, changed, again.indices, tick=False, more=True)
            await self.let_readers_in()  # their writers write them (the readers hold what they take)
        return True

    def sample_tick(self, scheduled: float | None = None) -> TickUpdate | None:
        """A tick's sampling (None: nothing to publish, or a front-end's feed published already).

        The manager runs at the tick's *scheduled* time, not the time the loop woke up: wake-up jitter would
        otherwise make a soldier throttled to one update per tick period miss every other tick, and frame
        choice would wobble. (A request taken after the scheduled time moves the tick's time up to it.)"""
        m, board = self.world.manager, self._board()
        if m is None or board is None or not self.world.ready:
            return None
        t0 = time.perf_counter()
        self.ticks += 1
        if self.feed is not None:
            with self.cpu("merge"):
                rows = self.feed(board, self.ticks)
            self._published(board, len(rows), rows)
            return None
        now = self.now() if scheduled is None else max(scheduled, self._last_stamp)
        with self.cpu("animate"):
            update = m.tick(now)
        self._requests_at_tick = self._request_count()
        self.last_tick_seconds = time.perf_counter() - t0
        return update

    def publish_tick(self, update: TickUpdate, again: bool = False) -> None:
        """Publish a tick's poses and wake the writers; soldiers with requests taken since it sampled are
        sampled again at the tick's time (their request's, if later) and published as more of that tick,
        under its number (a second publish: merging them into the tick's arrays costs more). ``again``: the
        tick published its first frames already (:meth:`_answer_first`)."""
        m, board = self.world.manager, self._board()
        assert m is not None and board is not None
        t0 = time.perf_counter()
        if self.on_tick is not None:
            self.on_tick(update)
        with self.cpu("quantise"):
            changed = board.publish(update, self.world, again=again)
        self._published(board, changed)
        seen = self._request_count()
        if seen != self._requests_at_tick:
            self._requests_seen = seen
            if self.on_publish is None:
                self._take_up(update.now)
            else:  # a shard's batches count a tick's publishes: its answer after the tick, as before
                self._answer_after_tick = True
        self._tick_serial, self._tick_now = board.serial, update.now
        self.last_tick_seconds = time.perf_counter() - t0

    def _take_up(self, now: float) -> None:
        """The soldiers whose requests were applied while the tick sampled: sampled again at the tick's time
        ``now`` (their clock: the request's, if later) and published as more of that tick."""
        m, board = self.world.manager, self._board()
        assert m is not None and board is not None
        with self.cpu("animate"):
            again = m.answer(now, now)  # at the tick's time: its due rule
        if not len(again):
            return
        if self.on_tick is not None:
            self.on_tick(again)
        with self.cpu("quantise"):
            changed = board.publish(again, self.world, again=True)
        self._published(board, changed)
        self._answer_still(again)

    def _answer_still(self, again: TickUpdate) -> None:
        """After a publish of ``again``: a start whose first frames are still (a walk off a rest) shows
        nothing yet at the tick's time: those soldiers get the answer after the tick, at the next tick's
        time, as before."""
        m, board = self.world.manager, self._board()
        assert m is not None and board is not None
        still = again.indices[board.version[again.indices] != board.serial]
        m.table.requested[still] = True
        self._answer_after_tick |= len(still) > 0

    def _request_count(self) -> int:
        m = self.world.manager
        return int(m.stats["requests"] + m.stats["reactions"]) if m is not None else self._requests_seen

    def publish_fed(self) -> None:
        """A front-end's publish as soon as a shard's batch arrives (``feed`` takes it), between its ticks:
        labelled with the next tick, as an answer is, so the wire's tick keeps the tick loop's rate."""
        board = self._board()
        if self.feed is None or board is None or not self.world.ready:
            return
        with self.cpu("merge"):
            rows = self.feed(board, self.ticks + 1)
        self._published(board, len(rows), rows)  # the shards' frames count as a tick's

    def _published(
        self,
        board: PoseBoard,
        changed: int,
        rows: np.ndarray | None = None,
        tick: bool = True,
        more: bool = False,
    ) -> None:
        """After a publish: the shard's hook, then wake the writers (with the ``rows`` changed: only those of
        clients subscribed to one of them, so a shard's answer goes out at once, not behind the encodes of
        clients it does not concern); a tick whose poses changed counts once for the update rate, however
        many publishes carried it (answers, a front-end's shards). A writer woken by a ``tick``'s publish lets
        the readers in before it writes (a single server's); one woken by answers alone does not. ``more``:
        a tick's first frames, the rest to follow (``Session.more_of_tick``: not held by the throttle)."""
        if self.on_publish is not None:
            with self.cpu("fabric"):
                self.on_publish(board, tick)
        if changed:
            if board.tick != self._counted_tick:
                self._counted_tick = board.tick
                self._published_ticks += 1
            for s in self.sessions.values():
                if s.tables_sent and (rows is None or s.conn.subscribes_any(rows)):
                    s.ticked |= tick
                    s.more_of_tick |= more
                    s.notify()

    async def take_requests(self) -> None:
        """A reader's requests (held by its session): the other readers with bytes now are let in first, so
        that the first back applies what they all hold in one batch and answers it once (the cost of a batch
        is mostly fixed: :mod:`server.pending_requests`)."""
        if self.pending:
            await self.let_readers_in()
        self.apply_held()

    def apply_held(self) -> None:
        """Apply the requests the sessions hold (one batch) and answer what arrived."""
        with self.cpu("requests"):
            self.pending.apply()
            self.requests_arrived()

    def requests_arrived(self) -> None:
        """Requests were taken (from a client, or a shard's from the fabric): answer them as more of the tick
        whose encodes are under way (:meth:`_answer_in_tick`), else between ticks."""
        seen = self._request_count()
        if seen != self._requests_seen and not self._ticking:
            self._requests_seen = seen
            if not self._answer_in_tick():
                self.answer_requests()  # by the reader that handled them, before anything else runs

    def _answer_in_tick(self) -> bool:
        """While writers still owe the last tick's frames (its encodes, after its publish; not one that waits
        for its socket) and nothing was answered as the next tick's since: the soldiers whose requests changed
        what they show are sampled at once (at their request's time, the tick's due rule) and published as
        more of that tick, under its number, so a writer that owes the tick writes them before it encodes the
        tick (:meth:`_tick_output`) and one that wrote it writes them at once (issue 16: they waited for every
        encode of the tick). A start whose first frames are still is answered between ticks, at the next
        tick's time. False: not in that phase (the caller answers between ticks)."""
        m, board = self.world.manager, self._board()
        if m is None or board is None or self.feed is not None or self.on_publish is not None:
            return False
        if board.tick != board.ticks or not any(s.ticked and not s.sending for s in self.sessions.values()):
            return False  # (a writer stuck on its socket owes the tick too long to hold answers in it)
        with self.cpu("animate"):
            again = m.answer(self._tick_now, self._tick_now)  # at the tick's time: its due rule
        if len(again):
            if self.on_tick is not None:
                self.on_tick(again)
            with self.cpu("quantise"):
                changed = board.publish(again, self.world, again=True)
            self._published(board, changed, again.indices, tick=False, more=True)
            self._answer_still(again)
            if self._answer_after_tick:  # shows nothing yet: the next tick's time will
                self._answer_after_tick = False
                self.answer_requests()
        return True

    def answer_requests(self) -> None:
        """Between ticks: publish the next tick's update early for the soldiers whose requests changed what
        they show (``SoldierManager.answer``: sampled at the next tick's time, throttled as that tick) and
        wake the writers. Its frames carry the next tick's number (``PoseBoard.publish(between=True)``)."""
        m, board = self.world.manager, self._board()
        if m is None or board is None or not self.world.ready or self.feed is not None:
            return
        now = self.request_time()
        update = m.answer(now, max(now, self.next_tick))
        if not len(update):
            return
        self.answers += 1
        if self.on_tick is not None:
            self.on_tick(update)
        self._published(board, board.publish(update, self.world, between=True), tick=False)

    # -- owners that left ----------------------------------------------------------------------------------
    def _left(self, session: Session) -> None:
        """A session ended: when it was its client id's last, that id's soldiers wait ``orphan_grace``."""
        if not session.joined:
            return
        session.joined = False
        self.client_left(session.client_id)

    def client_left(self, client_id: str) -> None:
        """A connection of ``client_id`` closed (here, or on another front-end: ``server.fabric``)."""
        self._orphans_wait(
            client_id, self.world.owners.leave(client_id, self.now(), self.config.orphan_grace)
        )

    def orphans_check(self) -> None:
        """Start the grace of every id that owns soldiers and has no connection and none yet (a front-end
        that held its connections is gone, or handed the removal of its share's orphans to this one)."""
        owners, now, grace = self.world.owners, self.now(), self.config.orphan_grace
        for cid in owners.owning():
            self._orphans_wait(cid, owners.orphaned(cid, now, grace))

    def _orphans_wait(self, client_id: str, deadline: float | None) -> None:
        if deadline is None or self._nursery is None or self._shutdown.is_set():
            return
        log.info("owner_gone", client_id=client_id, grace=self.config.orphan_grace)
        with contextlib.suppress(RuntimeError):  # stopped: its nursery is closed (a front-end told late)
            self._nursery.start_soon(self._expire_orphans, deadline)

    async def _expire_orphans(self, deadline: float) -> None:
        await trio.sleep_until(self._t0 + deadline)
        self.remove_orphans()

    def remove_orphans(self) -> None:
        """Remove the soldiers of every client id whose grace is over (others get SOLDIER_REMOVED)."""
        owners = self.world.owners
        for cid in owners.expired(self.now()):
            gone = owners.soldiers_of(cid)
            if self.world.relay is not None:  # a front-end of several removes its own share's
                gone = self.world.relay.orphans(gone)
            for i in gone:
                self.world.remove_soldier(i, f"owner {cid} gone for {self.config.orphan_grace:g} s")
            log.info("orphans_removed", client_id=cid, soldiers=len(gone))

    # -- status ------------------------------------------------------------------------------------------
    async def _status_loop(self) -> None:
        while True:
            await trio.sleep(self.world.report_interval)
            self.report_status()

    async def _status_task(self, session: Session) -> None:
        """STATUS to one client every its own report interval; a new interval takes effect at once."""
        session.status_window = (self.now(), self._published_ticks)
        while True:
            changed = session.settings_changed
            with trio.move_on_after(session.own_report_interval()):
                await changed.wait()
            if changed.is_set():
                session.settings_changed = trio.Event()
                continue
            now, soldiers, text = self.status_text()
            t_prev, n_prev = session.status_window
            rate = (self._published_ticks - n_prev) / (now - t_prev) if now > t_prev else 0.0
            session.status_window = (now, self._published_ticks)
            session.status(now, soldiers, rate, text.format(rate=rate))

    def status_text(self) -> tuple[float, int, str]:
        """(now, soldiers, STATUS text with a ``{rate:.1f}`` field left to fill)."""
        m = self.world.manager
        st = m.status() if m is not None else {}
        soldiers = int(st.get("soldiers", 0))
        # a front-end animates nothing itself (its shards do): its manager's tick time would read 0 us
        work = (
            "animated by its shards"
            if self.feed is not None
            else f"tick {st.get('mean_tick_us', 0.0):.0f} us mean"
        )
        text = f"{soldiers} soldiers, {len(self.sessions)} clients, {{rate:.1f}} Hz, {work}"
        if self.status_note is not None:
            text += "; " + self.status_note().replace("{", "{{").replace("}", "}}")
        return self.now(), soldiers, text

    def report_status(self) -> None:
        """The server's own status line in the log, every server report interval."""
        now = self.now()
        t_prev, n_prev = self._batches_window
        rate = (self._published_ticks - n_prev) / (now - t_prev) if now > t_prev else 0.0
        self._batches_window = (now, self._published_ticks)
        m = self.world.manager
        st = m.status() if m is not None else {}
        soldiers = int(st.get("soldiers", 0))
        log.info(
            "status",
            time=round(now, 3),
            soldiers=soldiers,
            clients=len(self.sessions),
            update_rate=round(rate, 2),
            ticks=self.ticks,
            overruns=self.tick_overruns,
            mean_tick_us=round(st.get("mean_tick_us", 0.0), 1),
            modes=st.get("modes", {}),
            cpu_ms_per_tick=self.cpu.report(self.ticks),
            **self._encode_counts(),
            **({} if self.deaf is None else {"loop_deaf_ms": self.deaf.report()}),
            **({} if self.status_fields is None else self.status_fields()),
        )

    def _encode_counts(self) -> dict[str, str]:
        """The shared memo's counts since start (``shared_encodes=hits:H,own:M,caught_up:C,rows:R``):
        encodes taken from a client in the same delta state, a writer's own encodes and the rows they diffed,
        frames sent to late writers; none without a memo."""
        memo = self.board_ref.encodes
        if memo is None:
            return {}
        counts = (memo.hits, memo.misses, memo.caught_up, memo.rows_encoded)
        return {"shared_encodes": "hits:{},own:{},caught_up:{},rows:{}".format(*counts)}


def check_exposure(config: ServerConfig) -> None:
    """ConfigError when the server would listen beyond loopback with no role tokens: anyone on the network
    could then claim any role."""
    if config.tokens:
        return
    host = config.host
    try:
        loopback = host == "localhost" or ipaddress.ip_address(host).is_loopback
    except ValueError:  # a host name other than localhost
        loopback = False
    if not loopback:
        raise ConfigError(
            f"{host!r} is not a loopback address and no role tokens are configured (observer_token, "
            "controller_token, operator_token): set them, or listen on 127.0.0.1",
            "host",
        )


def _is_loopback(stream: trio.SocketStream) -> bool:
    try:
        ip = ipaddress.ip_address(stream.socket.getpeername()[0].split("%")[0])
        if isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped is not None:
            return ip.ipv4_mapped.is_loopback
        return ip.is_loopback
    except (OSError, ValueError, IndexError):
        return False


async def _linger(stream: trio.abc.Stream, limit: int = 1 << 20) -> None:
    """After a fatal error: half-close and discard what the peer still sends, so closing the socket does not
    reset the connection (and destroy our ERROR frame) while unread bytes wait in the receive buffer."""
    if not isinstance(stream, trio.abc.HalfCloseableStream):  # TLS: no half-close; just close
        return
    try:
        await stream.send_eof()
        got = 0
        while got < limit:
            chunk = await stream.receive_some(65536)
            if not chunk:
                return
            got += len(chunk)
    except (trio.BrokenResourceError, trio.ClosedResourceError, OSError):
        return


async def _receive(stream: trio.abc.Stream) -> bytes:
    try:
        return bytes(await stream.receive_some(65536))
    except (trio.BrokenResourceError, trio.ClosedResourceError):
        return b""


async def run_server(
    server: TtesServer,
    *,
    on_listening: Callable[[TtesServer], None] | None = None,
    handle_signals: bool = True,
) -> None:
    """Serve until SIGINT/SIGTERM (or :meth:`TtesServer.shutdown`), then shut down gracefully: stop
    accepting, GOODBYE to every client, a short flush, cancel."""
    async with trio.open_nursery() as nursery:
        await nursery.start(server.serve)
        if on_listening is not None:
            on_listening(server)
        if handle_signals:
            with trio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
                async with trio.open_nursery() as waiter:

                    async def stop_on_signal() -> None:
                        async for sig in signals:
                            log.info("signal", signal=signal.Signals(sig).name)
                            server.shutdown()
                            return

                    waiter.start_soon(stop_on_signal)
                    await server.stopped.wait()
                    waiter.cancel_scope.cancel()


__all__ = ["TtesServer", "run_server"]
