"""One client's session: its protocol connection, subscriptions, limits and bounded output.

Memory per client is bounded whatever the client does:

* **joint updates are latest-wins**: the tick loop never queues poses per client. It writes every soldier's
  newest wire-ready pose once into the shared :class:`~server.pose_board.PoseBoard` and wakes the writers.
  A session's writer, whenever its socket can take bytes, encodes the *current* poses of its subscribed
  soldiers that changed since its last write (the connection's ``UpdateEncoder`` diffs against what this
  client last received, so skipped ticks cost nothing and deltas stay exact). A stalled reader therefore
  holds at most one encoded batch, and never slows the tick or other clients. A writer only a few publishes
  late (its group's encodes of them still in the server's memo) sends those frames instead of an encode of
  its own (:meth:`Session._catch_up`): on a busy server, lateness costs bytes, not CPU;
* **control messages** (errors, READY, STATUS, answers) go through a small bounded queue. While it holds
  ``control_queue`` messages the reader stops reading the socket (TCP backpressure: a client that pipelines
  requests is slowed, never dropped, while it reads); only the server's own pushes can add more, and twice
  ``control_queue`` means the client reads nothing at all: it is dropped (so is a client whose socket takes no
  bytes for ``write_timeout``);
* reading stops (TCP backpressure) while the client exceeds its request rate or its JCL runs, and a frame
  longer than ``max_frame`` is refused before it is buffered (the connection checks the length prefix).

Heading-only changes (the seed's "send the last update packet with heading change",
``TickUpdate.heading_only``) need nothing here: heading and position are the client's and the pose is
unchanged, so the encoder sends 0 bytes for them.

The :class:`Session` is driven by :mod:`server.app` (reader and writer tasks); the per-message handling lives
here so it can be tested without sockets.
"""

from __future__ import annotations

import hmac
import math
import time
from collections import deque
from typing import TYPE_CHECKING

import numpy as np
import trio

from protocol.connection import NEED_DATA, PAUSED, SERVER, Connection, State
from protocol.entity import Reaction
from protocol.errors import ErrorCode, LocalProtocolError
from protocol.events import (
    ROLES,
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
    React,
    Ready,
    RemoveSoldier,
    RequestFigure,
    RequestFullUpdate,
    Settings,
    SoldierCreated,
    SoldierRemoved,
    Status,
    Subscribe,
    Unsubscribe,
    UpdateTableMsg,
    ticks_per_update,
)
from protocol.shared_encode import KEEP
from server.config import ServerConfig
from server.jcl import JclError
from server.logging import get_logger
from server.pose_board import BoardRef, PoseBoard
from server.soldier.manager import REQUEST_BAD_VALUE, REQUEST_UNKNOWN_SOLDIER
from server.trace import TRACE

if TYPE_CHECKING:
    from server.pending_requests import PendingRequests
    from server.startup import ServerWorld

RECEIVE_BYTES = 65536
log = get_logger("session")


class Session:
    """One client connection: protocol state, subscriptions, limits and its two bounded outputs."""

    _ids = 0

    def __init__(self, world: ServerWorld, board_ref: BoardRef, config: ServerConfig, peer: str = "") -> None:
        Session._ids += 1
        self.id = Session._ids
        self.world = world
        self.board_ref = board_ref
        self.config = config
        self.peer = peer
        self.conn = Connection(
            SERVER,
            max_frame=config.max_frame,
            max_soldiers=config.max_soldiers,
            shared_encodes=board_ref.encodes,
        )
        self.name = ""
        self.role = ""  # granted at HELLO (server.world.access, server.world.owners say what it allows)
        self.client_id = ""  # the HELLO's client_id, or a fresh anonymous one: owns this client's soldiers
        self.local = True  # the peer is on this host (with no tokens configured, only local peers may join)
        self.joined = False  # counted in world.owners.connected (left again when the session ends)
        self.throttle: float | None = None  # this connection's own rate cap (None: the server's)
        self.report_interval: float | None = None  # this connection's STATUS period (None: the server's)
        self.settings_changed = trio.Event()  # set when report_interval changes: the status task restarts
        self.last_updates_at = -math.inf  # server time of the last joint updates written (own throttle)
        self.retry_at: float | None = None  # updates held back by the own throttle: write them then
        self.status_window = (0.0, 0)  # (time, published ticks) at the last STATUS: its update_rate
        self.control: deque[bytes] = deque()
        self.wake = trio.Event()
        self.closing = False  # no more reading; the writer flushes the control queue and closes
        self.tables_sent = False
        self.ready_sent = False
        self.flushed_serial = 0  # the board publish this client's last write covered
        self.ticked = False  # woken by a tick's publish since the last write (the trio app's writer)
        self.more_of_tick = False  # woken by a tick's first publish of answered soldiers only (take_output)
        self.early: tuple[int, np.ndarray] | None = None  # (board serial, rows) written ahead of a tick
        self.sending = False  # the writer waits for the socket to take a write (the trio app's writer)
        self.force = np.zeros(config.max_soldiers, bool)  # subscribed soldiers owed a (full) update
        self.tokens = float(config.max_requests_per_s)
        self.tokens_at = 0.0
        self.cost = 0.0  # request tokens used since the last charge
        self.bytes_out = 0
        self.batches_out = 0
        self.drop_reason = ""
        self.dropped = False  # ended by the server (error, stall, overflow), not by the client
        self.lingering = False  # after a fatal error: half-close and drain before closing the socket
        self.full = False  # the server had max_clients already: refuse the HELLO
        self.crowded = 0  # > 0: the peer's address had this many connections (max_clients_per_host): refuse
        self.drained = trio.Event()  # set by the writer each time it takes the control queue
        self.writer_done = trio.Event()
        self.offload_jcl = False  # True under the trio app: a JCL frame waits in pending_jcl for the reader
        self.pending_jcl: Jcl | None = None
        # the trio app's: entity requests wait there, applied with other readers' (issue 16); None: at once
        self.pending: PendingRequests | None = None
        self.more = False  # resume stopped at its turn's end with events still buffered
        self.trace_rows = np.zeros(0, np.int64)  # the traced soldiers of the last encode (server.trace)

    # -- output ------------------------------------------------------------------------------------------
    def notify(self) -> None:
        self.wake.set()

    def queue(self, data: bytes) -> None:
        """Queue control bytes; a full queue means the client reads nothing: drop it."""
        if not data:
            return
        if len(self.control) >= 2 * self.config.control_queue:
            self.drop(f"control queue full ({len(self.control)} messages): client not reading", True)
            return
        self.control.append(data)
        self.wake.set()

    @property
    def output_full(self) -> bool:
        """The control queue is full: stop reading this client until the writer has taken it."""
        return len(self.control) >= self.config.control_queue

    def send(self, event: Event) -> None:
        if self.conn.state in (State.CLOSED, State.ERROR):
            return
        self.queue(self.conn.send(event))

    def fatal(self, code: ErrorCode, message: str) -> None:
        """Send a fatal error and close (the connection goes to ERROR)."""
        if self.conn.state not in (State.CLOSED, State.ERROR):
            self.control.append(self.conn.send(Error(int(code), message)))
        self.lingering = True
        self.drop(message, True)

    def drop(self, reason: str, dropped: bool = False) -> None:
        """End the session: no more reading; the writer flushes the control queue, then the socket closes."""
        if not self.closing:
            self.closing = True
            self.drop_reason = reason
            self.dropped = dropped
        self.wake.set()
        self.drained.set()  # a reader waiting for the writer stops waiting

    def take_output(self, now: float | None = None) -> bytes:
        """Everything to write now: queued control bytes, then the latest joint updates (latest-wins), held
        back while this connection's own throttle says so (``retry_at``: when they are due; ``now`` None:
        never held). A write of ``more_of_tick`` alone (soldiers answered as a tick's first publish,
        ``TtesServer.run_tick``) is neither held nor counted: the rest of that tick follows in a moment, and
        the manager's throttle already applied to those soldiers (not so to a client's own throttle)."""
        out = b"".join(self.control)
        self.control.clear()
        self.retry_at = None
        if self.closing or self.conn.state is not State.OPEN or not self.tables_sent:
            return out
        gate = self.own_gate()
        more, self.more_of_tick = self.more_of_tick and gate is None, False
        if now is not None and not more and gate is not None:
            due = self.last_updates_at + gate - 0.5 / self.config.tick_hz
            if now < due - 1e-9:
                # the tick at which they are due wakes the writer; this is for when no tick publishes:
                # a quarter period after it, so a retry never writes ahead of that tick's poses
                self.retry_at = due + 0.75 / self.config.tick_hz
                return out
        data = self._joint_updates()
        if data and now is not None and not more:
            self.last_updates_at = now
        return out + data

    def own_throttle(self) -> float:
        """This connection's rate cap: its own, never below the server's (a client only lowers its rate)."""
        server = self.world.settings.throttle
        return server if self.throttle is None else max(self.throttle, server)

    def own_gate(self) -> float | None:
        """The throttle this connection's writes are held by: its own where it is stricter than the server's
        on the tick grid (``ticks_per_update``), None otherwise (no own throttle, or one no stricter). The
        soldier manager already caps every soldier at the server's throttle, in each soldier's phase
        (``Ticking._due``); a second gate as strict counted from this connection's last write instead: after
        a write between ticks (a JCL's answer) every update it held went out 0.75 tick late, later each time,
        until one gap of 4 ticks (issue 21)."""
        if self.throttle is None:
            return None
        hz = self.config.tick_hz
        if ticks_per_update(hz, self.throttle) <= ticks_per_update(hz, self.world.settings.throttle):
            return None
        return self.throttle

    def own_report_interval(self) -> float:
        return self.world.report_interval if self.report_interval is None else self.report_interval

    def may_see(self, indices: np.ndarray) -> np.ndarray:
        """The soldiers of ``indices`` whose updates this client may receive (``Owners.visible``)."""
        return self.world.owners.visible(indices, self.client_id, self.role)

    def take_answers(self, after: int) -> bytes:
        """The subscribed soldiers whose codes changed at a publish after ``after`` (and after this client's
        last write): soldiers answered as more of a tick since its publish (``TtesServer._answer_in_tick``),
        encoded on their own so that the writer sends them before it encodes the rest of the tick (issue 16);
        nothing once a publish was labelled with the next tick (its rows follow the tick's).
        The next write does not send them again unless they change again. Not for a connection with a
        throttle of its own stricter than the server's (its one write per period carries them)."""
        board = self.board_ref.board
        if board is None or self.own_gate() is not None or self.closing or self.conn.state is not State.OPEN:
            return b""
        if board.tick != board.ticks:  # answered as the next tick's since: they follow the tick's rows
            return b""
        sub = self.conn.subscribed
        if not self.tables_sent or len(sub) == 0:
            return b""
        sub = self.may_see(sub[sub < board.capacity])
        early = self.early
        since = max(after, self.flushed_serial, 0 if early is None else early[0])
        idx = sub[board.valid[sub] & (board.version[sub] > since) & ~self.force[sub]]
        if len(idx) == 0:
            return b""
        self.early = (board.serial, idx if early is None else np.union1d(early[1], idx))
        return self._encode_rows(board, idx, sub, since, False)

    def _joint_updates(self) -> bytes:
        """The subscribed soldiers whose codes changed since the last write (or that are owed a full update),
        encoded from the board's shared codes: this client only diffs and packs, it never re-quantises.

        A writer that missed publishes (a busy server, a slow socket) first catches up through the encodes
        its group was sent at them (:meth:`_catch_up`), then needs only what changed at the newest."""
        board = self.board_ref.board
        if board is None:
            return b""
        sub = self.conn.subscribed
        since = self.flushed_serial
        self.flushed_serial = board.serial
        early, self.early = self.early, None
        if len(sub) == 0:
            return b""
        sub = self.may_see(sub[sub < board.capacity])
        due = board.valid[sub] & ((board.version[sub] > since) | self.force[sub])
        if early is not None:  # written ahead of the rest of the tick (take_answers), not changed since
            due &= ~(np.isin(sub, early[1]) & (board.version[sub] <= early[0]))
        idx = sub[due]
        if len(idx) == 0:
            return b""
        late = early is None and self._may_catch_up(since, board.serial) and not self.force[idx].any()
        self.force[idx] = False
        return self._encode_rows(board, idx, sub, since, late)

    def _encode_rows(
        self, board: PoseBoard, idx: np.ndarray, sub: np.ndarray, since: int, late: bool
    ) -> bytes:
        """JOINT_UPDATES of soldiers ``idx`` (``sub``: those this client may see; ``late``: catch up through
        the shared memo's encodes of the publishes after ``since``)."""
        tables = board.table_of[idx]
        ticks = board.labels(idx)  # the tick's rows, then the rows answered since (the next tick's), in order
        chunks = []
        labels = _distinct(ticks)
        # catching up through the memo is for a tick's plain publish: rows labelled with the board's tick only
        late = late and labels == [board.tick]
        for tick in labels:
            for t in _distinct(tables):
                sel = (tables == t) & (ticks == tick)
                rows = idx if sel.all() else idx[sel]
                if not len(rows):
                    continue
                caught = self._catch_up(t, rows, sub, since) if late else None
                if caught is None:
                    caught = self.conn.send_update_codes(t, rows, board.codes_of(rows), tick, board.serial)
                chunks.append(caught)
        data = b"".join(chunks)
        if data:
            self.batches_out += 1
        if TRACE is not None:
            TRACE.stamp("encode", idx)
            self.trace_rows = idx
        return data

    def _may_catch_up(self, since: int, serial: int) -> bool:
        """Missed publishes worth catching up: a shared memo that still keeps them, and no throttle of this
        connection's that skips ticks on purpose (a writer held back by it is not late)."""
        return (
            self.board_ref.encodes is not None
            and 0 < since < serial - 1
            and serial - since <= KEEP + 1
            and self.own_throttle() * self.config.tick_hz < 1.5
        )

    def _catch_up(self, table: int, rows: np.ndarray, sub: np.ndarray, since: int) -> bytes | None:
        """The frames of the publishes after ``since``, the newest's last, through the shared memo, or None
        (then this client's own encode covers them). ``rows``: the due soldiers of ``table``, ``sub`` the
        soldiers this client may see: the memo's frames are sent only if every row in them is one of those."""
        board = self.board_ref.board
        assert board is not None
        allowed = np.zeros(self.conn.max_soldiers, bool)
        allowed[sub[board.valid[sub] & (board.table_of[sub] == table)]] = True
        changed = board.version[rows]
        missed = [(v, rows[changed == v]) for v in range(since + 1, board.serial)]
        now = rows[changed == board.serial]
        return self.conn.catch_up_codes(
            table, missed, allowed, now, board.codes[now], board.tick, board.serial
        )

    # -- input -------------------------------------------------------------------------------------------
    def feed(self, data: bytes, now: float | None = None) -> float:
        """Bytes from the socket (``b""`` = EOF): handle complete events while the request budget lasts.

        Returns the seconds to wait before calling :meth:`resume` (0.0: everything buffered was handled). The
        budget is checked between events, so frames that arrived together in one read are throttled too.
        """
        self.conn.receive_data(data)
        return self.resume(now)

    def resume(self, now: float | None = None, turn_s: float | None = None) -> float:
        """Handle buffered events until the buffer is empty (0.0) or the budget is spent (seconds to wait).

        ``turn_s``: stop (0.0, ``more`` True) once this much CPU went into the events handled, so a burst
        (thousands of CREATE_SOLDIER in one read) leaves the loop to the tick and the other clients between
        its turns; the check is between events (one at least)."""
        self.more = False
        end = None if turn_s is None else time.thread_time() + turn_s
        handled = 0
        while not self.closing and self.pending_jcl is None and not self.output_full:
            if now is not None:
                wait = self.charge(now)
                if wait > 0:
                    return wait
            if end is not None and handled and time.thread_time() >= end:
                self.more = True
                return 0.0
            ev = self.conn.next_event()
            if ev is NEED_DATA or ev is PAUSED:
                return 0.0
            self.handle(ev)  # type: ignore[arg-type]
            handled += 1
        return 0.0

    def charge(self, now: float) -> float:
        """Pay for the requests handled since the last call (one token per entity row or other message);
        returns the seconds to wait before reading more (the rate limit is TCP backpressure, not a drop)."""
        rate = self.config.max_requests_per_s
        self.tokens = min(rate, self.tokens + (now - self.tokens_at) * rate)
        self.tokens_at = now
        self.tokens -= self.cost
        self.cost = 0.0
        if self.tokens >= 0:
            return 0.0
        # at least a millisecond: a wait below the clock's float resolution would never refill the bucket
        return max(-self.tokens / rate, 1e-3)

    def handle(self, ev: Event) -> None:
        pending = self.pending
        if pending is not None and (not isinstance(ev, EntityRequests) or not pending.may_join(self)):
            # held requests first: nothing overtakes a request, and one frame's errors (a bad value closes the
            # session) come before this client's next message is handled, as when each was applied at once;
            # its next request frames join the held ones (server.pending_requests: queued frames, one batch)
            pending.apply()
            if self.closing:
                return
        try:
            self._handle(ev)
        except LocalProtocolError as exc:  # we were about to send something invalid: a bug, report it
            log.error("internal_protocol_error", session=self.id, error=str(exc))
            self.fatal(ErrorCode.INTERNAL, f"internal error: {exc.message}")

    def _handle(self, ev: Event) -> None:
        self.cost += len(ev.rows) if isinstance(ev, EntityRequests) else 1
        if isinstance(ev, ProtocolError):
            self.control.append(self.conn.data_to_send())  # the Error frame the connection queued
            log.warning(
                "client_protocol_error",
                session=self.id,
                peer=self.peer,
                code=ev.code,
                error=f"{ev.location}: {ev.message}" if ev.location else ev.message,
            )
            self.lingering = True
            self.drop(f"protocol error {ev.code}", True)
        elif isinstance(ev, ConnectionClosed):
            self.drop("closed")
        elif isinstance(ev, Hello):
            self._hello(ev)
        elif isinstance(ev, Goodbye):
            log.info("client_goodbye", session=self.id, reason=ev.reason)
            self.drop("goodbye")
        elif isinstance(ev, Error):
            if ev.code < 100:
                self.drop(f"client sent fatal error {ev.code}")
            else:
                log.info("client_error", session=self.id, code=ev.code, message=ev.message)
        elif isinstance(ev, Ping):
            self.send(Pong(ev.nonce))
        elif isinstance(ev, Pong):
            pass
        elif isinstance(ev, Jcl):
            self._jcl(ev)
        elif isinstance(ev, CreateSoldier):
            self._create(ev)
        elif isinstance(ev, RemoveSoldier):
            self._remove(ev)
        elif isinstance(ev, Subscribe):
            self._subscribe(np.asarray(ev.indices, np.int64))
        elif isinstance(ev, RequestFullUpdate):
            idx = np.asarray(ev.indices, np.int64) if ev.indices else self.conn.subscribed
            self.force[idx] = True
            self.notify()
        elif isinstance(ev, Unsubscribe):  # the connection forgets them; subscribing again: a full update
            self._watch(None)
        elif isinstance(ev, EntityRequests):
            self._requests(ev)
        elif isinstance(ev, React):
            self._react(ev)
        elif isinstance(ev, RequestFigure):
            self._figure(ev)

    def _figure(self, ev: RequestFigure) -> None:
        """FIGURE for a table this client was sent; ERROR 103 (no such table) or 108 (over its max_frame)."""
        msg = self.world.soldiers.figure_message(ev.table, ev.meshes) if self.tables_sent else None
        if msg is None:
            self.send(Error(int(ErrorCode.UNKNOWN_FIGURE), f"no update table {ev.table} was sent", ev.id))
            return
        try:
            self.send(msg)
        except LocalProtocolError as exc:
            if exc.code is not ErrorCode.FRAME_TOO_LARGE:
                raise
            self.send(Error(int(ErrorCode.FIGURE_TOO_LARGE), exc.message, ev.id))

    def _hello(self, ev: Hello) -> None:
        self.name = ev.name
        refused = self._refusal(ev)
        if refused:
            self.send(Error(int(ErrorCode.NOT_PERMITTED), refused))
            self.goodbye(refused.partition(" (")[0])
            self.dropped = True
            log.info("client_refused", session=self.id, peer=self.peer, name=ev.name, reason=refused)
            return
        self.role = ev.role
        self.client_id = ev.client_id or self.world.owners.anonymous(self.id)
        reclaimed = self.world.owners.join(self.client_id)
        self.joined = True
        c = self.config
        self.send(
            Accept(
                c.name,
                c.max_frame,
                c.max_soldiers,
                version=ev.version,  # the client's: an older client keeps its joint-update format
                client_id=self.client_id,
                role=self.role,
            )
        )
        log.info(
            "client_accepted",
            session=self.id,
            peer=self.peer,
            name=ev.name,
            role=self.role,
            client_id=self.client_id,
            reclaimed=len(reclaimed),
        )
        if self.world.ready:
            self.send_ready()

    def _refusal(self, ev: Hello) -> str:
        """Why this HELLO is refused ("" = accepted): the server is full, the peer's address holds its share
        of the slots (``max_clients_per_host``), or the role is not granted."""
        if self.full:
            return f"server full ({self.config.max_clients} clients)"
        if self.crowded:
            host = self.peer.rpartition(":")[0]
            return f"too many connections: {self.crowded} connections from {host} (max_clients_per_host)"
        return self._grant(ev)

    def _grant(self, ev: Hello) -> str:
        """Why the role asked for is refused ("" = granted). With tokens configured a role comes only from a
        token (its own or a higher role's); with none, any local client may claim any role."""
        tokens = self.config.tokens
        if not tokens:
            return (
                "" if self.local else "this server grants roles to local clients only (no tokens configured)"
            )
        held = [
            ROLES.index(r) for r, t in tokens.items() if hmac.compare_digest(ev.token.encode(), t.encode())
        ]
        if max(held, default=-1) >= ROLES.index(ev.role):
            return ""
        return f"the {ev.role} role needs its token (or a higher role's)"

    def send_tables(self) -> None:
        if not self.tables_sent and self.conn.state is State.OPEN:
            for t in self.world.tables:
                self.send(UpdateTableMsg(t))
            self.tables_sent = True
            self.force[self.conn.subscribed] = True

    def send_ready(self) -> None:
        """Tables (first time) then READY with every soldier and its table."""
        if self.conn.state is not State.OPEN:
            return
        self.send_tables()
        m = self.world.manager
        soldiers: tuple[tuple[int, int], ...] = ()
        if m is not None:
            live = self.may_see(m.table.live)
            fset = m.table.fset[live]
            ids = np.array([s.table.table_id for s in self.world.sets], np.int64)[fset]
            soldiers = tuple(zip(live.tolist(), ids.tolist(), strict=True))
        self.send(Ready(soldiers, self.config.tick_hz, self.world.settings.throttle))
        self.ready_sent = True
        self.send_settings()

    # -- this connection's settings (JCL set_ttes_soldier_throttle / set_ttes_report_interval) ---------------
    def send_settings(self) -> None:
        if self.conn.state is State.OPEN and self.ready_sent:
            self.send(Settings(self.own_throttle(), self.own_report_interval()))

    def set_throttle(self, seconds: float) -> None:
        """This connection's rate cap, at once; below the server's it is the server's (a client may only
        lower its own rate). ValueError for a value out of 0 … 60 s."""
        if not (math.isfinite(seconds) and 0.0 <= seconds <= 60.0):
            raise ValueError(f"throttle {seconds} is not in 0 … 60 s")
        self.throttle = float(seconds)
        self.send_settings()
        self.notify()

    def set_report_interval(self, seconds: float) -> None:
        """This connection's STATUS period, at once; ValueError below the server's floor."""
        floor = self.config.min_report_interval
        if not (math.isfinite(seconds) and floor <= seconds <= 86400.0):
            raise ValueError(f"report interval {seconds} is not in {floor:g} … 86400 s")
        self.report_interval = float(seconds)
        self.settings_changed.set()
        self.send_settings()

    def soldier_removed(self, index: int, reason: str) -> None:
        """Tell this client a soldier it could see is gone."""
        if self.conn.state is State.OPEN and self.ready_sent and len(self.may_see(np.array([index]))):
            self.send(SoldierRemoved(index, reason))

    def _permitted(self, ref: int | None, what: str) -> bool:
        if self.role == "observer":
            self.send(Error(int(ErrorCode.NOT_PERMITTED), f"an observer may not send {what}", ref))
            return False
        return True

    def _is_ready(self, ref: int | None, what: str) -> bool:
        if not self.world.ready:
            self.send(Error(int(ErrorCode.NOT_READY), f"{what} before READY", ref))
            return False
        return True

    def _subscribe(self, indices: np.ndarray) -> None:
        hidden = np.setdiff1d(indices, self.may_see(indices))
        if len(hidden):  # the connection keeps them subscribed, but updates are filtered by may_see
            self.send(
                Error(
                    int(ErrorCode.NOT_PERMITTED),
                    f"soldier {int(hidden[0])} belongs to another client"
                    + (f" ({len(hidden)} soldiers)" if len(hidden) > 1 else "")
                    + ": a controller sees its own and the shared soldiers only",
                )
            )
        self.force[indices] = True
        self._watch(indices)  # a front-end: their current poses onto its board first
        self.notify()

    def _watch(self, indices: np.ndarray | None) -> None:
        if self.board_ref.on_watch is not None:
            self.board_ref.on_watch(indices)

    def _jcl(self, ev: Jcl) -> None:
        if self.offload_jcl:  # the reader runs it off the tick (TtesServer.run_jcl) before reading on
            self.pending_jcl = ev
            return
        self.jcl_done(ev, self.run_jcl(ev))

    def run_jcl(self, ev: Jcl) -> JclError | None:
        """Run a JCL frame (any thread: the world sends what touches soldiers to the trio loop)."""
        try:
            self.world.run_jcl(ev.text, self, f"<jcl {ev.id} from {self.name or self.peer}>")
        except JclError as exc:
            return exc
        return None

    def jcl_done(self, ev: Jcl, error: JclError | None) -> None:
        if error is not None:
            self.send(Error(int(ErrorCode.JCL_ERROR), str(error), ev.id))
            log.info("jcl_error", session=self.id, error=str(error))

    def _create(self, ev: CreateSoldier) -> None:
        if not (self._permitted(ev.id, "CREATE_SOLDIER") and self._is_ready(ev.id, "CREATE_SOLDIER")):
            return
        m = self.world.manager
        assert m is not None
        code, msg = self._create_error(ev)
        if code is None:
            try:
                i = self.world.create_soldier(ev.figure, ev.weapon, ev.index, owner=self.client_id)
            except (ValueError, KeyError) as exc:
                code, msg = ErrorCode.NO_FREE_SOLDIER, str(exc)
            else:
                self.send(SoldierCreated(ev.id, i, self.world.table_of(i)))
                log.info("soldier_created", session=self.id, index=i, figure=ev.figure, weapon=ev.weapon)
                return
        self.send(Error(int(code), msg, ev.id))

    def _create_error(self, ev: CreateSoldier) -> tuple[ErrorCode | None, str]:
        m = self.world.manager
        assert m is not None
        lib = m.library
        try:
            self.world.owners.check_cap(self.client_id)
        except ValueError as exc:
            return ErrorCode.NO_FREE_SOLDIER, str(exc)
        fig = ev.figure.rsplit("/", 1)[-1]
        wpn = ev.weapon.rsplit("/", 1)[-1]
        if not any(f == fig for f, _ in lib.set_keys):
            return (
                ErrorCode.UNKNOWN_FIGURE,
                f"no figure {ev.figure!r} (have {sorted({f for f, _ in lib.set_keys})})",
            )
        if wpn and not any(f == fig and w == wpn for f, w in lib.set_keys):
            return ErrorCode.UNKNOWN_WEAPON, f"no weapon {ev.weapon!r} for {ev.figure!r}"
        if ev.index is not None:
            if m.table.is_live(ev.index):
                return ErrorCode.SOLDIER_EXISTS, f"soldier {ev.index} exists"
        elif m.count >= self.config.max_soldiers:
            return ErrorCode.NO_FREE_SOLDIER, f"all {self.config.max_soldiers} soldier indices are in use"
        return None, ""

    def _remove(self, ev: RemoveSoldier) -> None:
        if not (self._permitted(None, "REMOVE_SOLDIER") and self._is_ready(None, "REMOVE_SOLDIER")):
            return
        live = self.world.manager is not None and self.world.manager.table.is_live(ev.index)
        if live and not self.world.owners.may_remove(ev.index, self.client_id, self.role):
            self.send(
                Error(int(ErrorCode.NOT_PERMITTED), f"soldier {ev.index} is not this client's to remove")
            )
            return
        try:
            self.world.remove_soldier(ev.index, f"removed by {self.client_id}")
        except KeyError:
            self.send(Error(int(ErrorCode.UNKNOWN_SOLDIER), f"no soldier {ev.index}"))
            return
        log.info("soldier_removed", session=self.id, index=ev.index)

    def _requests(self, ev: EntityRequests) -> None:
        if not (self._permitted(None, "ENTITY_REQUESTS") and self._is_ready(None, "ENTITY_REQUESTS")):
            return
        m = self.world.manager
        assert m is not None
        kept = self._own_rows(ev.rows)  # row numbers of the batch, for the errors
        if not len(kept):
            return
        rows = ev.rows if len(kept) == len(ev.rows) else ev.rows[kept]
        if self.pending is not None:
            self.pending.hold(self, kept, rows)
        else:
            self.requests_done(kept, rows, self.world.apply_requests(rows))

    def requests_done(self, kept: np.ndarray, rows: np.ndarray, status: np.ndarray) -> None:
        """The errors of request ``rows`` once applied (``kept``: their row numbers in the client's frame)."""
        bad = kept[status == REQUEST_BAD_VALUE]
        if len(bad):
            self.fatal(
                ErrorCode.BAD_VALUE, f"entity requests row {int(bad[0])}: speed above the server's limit"
            )
            return
        at = np.flatnonzero(status == REQUEST_UNKNOWN_SOLDIER)
        if len(at):
            unknown, row = kept[at], int(kept[at[0]])
            self.send(
                Error(
                    int(ErrorCode.UNKNOWN_SOLDIER),
                    f"entity requests row {row}: no soldier {int(rows['index'][at[0]])}"
                    + (f" ({len(unknown)} rows)" if len(unknown) > 1 else ""),
                )
            )

    def _own_rows(self, rows: np.ndarray) -> np.ndarray:
        """The row numbers of the requests for soldiers this client may drive; the others are refused with
        one ERROR."""
        ok = self.world.owners.drivable(rows["index"], self.client_id, self.role)
        if ok.all():
            return np.arange(len(rows))
        bad = np.flatnonzero(~ok)
        self.send(
            Error(
                int(ErrorCode.NOT_PERMITTED),
                f"entity requests row {int(bad[0])}: soldier {int(rows['index'][bad[0]])} belongs to another "
                "client" + (f" ({len(bad)} rows)" if len(bad) > 1 else ""),
            )
        )
        return np.flatnonzero(ok)

    def _react(self, ev: React) -> None:
        """REACT: each soldier this client may drive plays the reaction now or when it comes to rest
        (``SoldierManager.react``); one that cannot react is skipped silently, one of another client's is
        refused with ERROR 107 and an unknown one answered by ERROR 100 (neither fatal)."""
        if not (self._permitted(None, "REACT") and self._is_ready(None, "REACT")):
            return
        m = self.world.manager
        assert m is not None
        idx = np.asarray(ev.indices, np.int64)
        ok = self.world.owners.drivable(idx, self.client_id, self.role)
        if not ok.all():
            bad = idx[~ok]
            more = f" ({len(bad)} soldiers)" if len(bad) > 1 else ""
            self.send(
                Error(
                    int(ErrorCode.NOT_PERMITTED),
                    f"react: soldier {int(bad[0])} belongs to another client{more}",
                )
            )
        kind = Reaction(ev.kind).name.lower()
        unknown = [i for i in idx[ok].tolist() if not m.table.is_live(i)]
        for i in idx[ok].tolist():
            if m.table.is_live(i):
                self.world.react(i, kind)
        if unknown:
            more = f" ({len(unknown)} soldiers)" if len(unknown) > 1 else ""
            self.send(Error(int(ErrorCode.UNKNOWN_SOLDIER), f"react: no soldier {unknown[0]}{more}"))

    # -- server → client ---------------------------------------------------------------------------------
    def status(self, now: float, soldiers: int, update_rate: float, text: str) -> None:
        if self.conn.state is State.OPEN and self.ready_sent:
            self.send(
                Status(
                    float(now), int(soldiers), float(update_rate) if math.isfinite(update_rate) else 0.0, text
                )
            )

    def report(self, text: str) -> None:
        """A JCL report for this client: a STATUS whose text is the report."""
        if self.conn.state is State.OPEN:
            m = self.world.manager
            self.send(Status(float(self.world.clock()), m.count if m else 0, 0.0, text))

    def goodbye(self, reason: str) -> None:
        if self.conn.state in (State.OPEN, State.HANDSHAKE):
            self.control.append(self.conn.send(Goodbye(reason)))
        self.drop(reason)


def _distinct(values: np.ndarray) -> list[int]:
    """The distinct values, sorted; one comparison pass when they are all equal (every soldier of one tick
    and one table, each client, each tick), not a sort or hash of them."""
    if len(values) and (values == values[0]).all():
        return [int(values[0])]
    return [int(v) for v in np.unique(values)]
