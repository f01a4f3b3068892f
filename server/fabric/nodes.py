"""A server's part on the fabric: a shard's (:class:`ShardNode`) or a front-end's (:class:`FrontNode`).

Soldier ``i`` belongs to shard ``i % N`` (:class:`Sharding`): the one client-visible index space stays one,
and the front-end, which allocates indices as a single server does, knows the owner of every index without
asking. Both sides run a :class:`~server.app.TtesServer` over the same data: the start-up script creates
the same soldiers everywhere (a shard then drops the ones that are not its own), and the update tables are
the same, so a client of the front-end gets the handshake, tables and FIGURE of a single server.

* a shard publishes, after each publish of its pose board, the soldiers whose codes changed since its
  previous batch as one batch per block of indices on the block's topic (:mod:`server.fabric.batch`),
  and every soldier it holds in *key* batches every ``key_every`` ticks and when a front-end asks (a
  sync, a ``key`` request after a lost batch or a new subscription): the merge and the wire cost what
  moves, and a lost batch costs at most until the next key; each tick, a pulse (no soldiers) says it
  lives; it takes the requests for its soldiers from ``requests/K`` on the trio loop;
* a front-end hears every shard's pulse and the blocks its clients watch (all of a shard's while it
  learns the shard's soldiers, below; a block it starts to hear asks for a key, and what it kept of the
  block from before is dropped as stale), queues each shard's batches as they arrive and merges them in
  order (from the newest key batch of each block among them) into its board
  (``PoseBoard.publish_codes``, one scatter), and its sessions encode from there as always; only the
  soldiers its clients watch go onto the board, the others' newest codes wait in a plain array until a
  client subscribes to them (:mod:`server.fabric.watch`). Its own manager keeps the books (who lives,
  tables, owners, the requests' checks) and never animates; what its clients ask goes to the owning
  shard (``ServerWorld.relay``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import itertools
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import trio

from protocol.bitpack import take_rows
from protocol.entity import ENTITY_REQUEST_DTYPE
from server.fabric import (
    BLOCK,
    WHOLE,
    Fabric,
    Handler,
    Kind,
    Unsubscribe,
    alive_key,
    books_topic,
    front_alive_key,
    fronts_topic,
    poses_topic,
    requests_topic,
)
from server.fabric import fronts as books
from server.fabric import requests as req
from server.fabric import settings as shared
from server.fabric.backlog import MAX_ROWS, Backlog
from server.fabric.batch import PULSE, Batch, decode_batch, encode_batch
from server.fabric.fronts import Fences, IndexShare, Soldier
from server.fabric.stamps import after
from server.fabric.watch import Watch
from server.logging import get_logger
from server.pose_board import PoseBoard
from server.soldier import REQUEST_OK
from server.stage_cpu import TURN_CPU_S
from server.trace import TRACE
from server.world.owners import ANONYMOUS

if TYPE_CHECKING:
    from server.app import TtesServer
    from server.session import Session

log = get_logger("fabric")
KEY_EVERY = 30  # a shard's tick batches between two key batches (1 s at 30 Hz): a lost batch heals by then
TURN_S = TURN_CPU_S  # a shard's turn of fabric requests before it answers them and lets a tick run
PENDING_MAX = 64  # a front-end's queue of one shard's ticks (a pulse and a batch a block heard); beyond, the
# oldest go (and it asks for a key)
ASK_AGAIN_S = 2.0  # a shard heard that has not answered ``books`` by then is asked again; each wait twice
ASK_AGAIN_MAX_S = 32.0  # the last, up to this (a shard busy with a crowd's creations answers late)
SYNCS_KEPT = 256  # the sync ids a shard remembers taking: one sent again is only an ask for a key


@dataclass(frozen=True)
class Sharding:
    """Shard ``k`` of ``n`` owns the soldiers whose index is ``k`` modulo ``n``."""

    k: int
    n: int

    @classmethod
    def parse(cls, text: str) -> Sharding:
        """``"K/N"``; ValueError unless 0 <= K < N."""
        k, sep, n = text.partition("/")
        if not sep or not (k.strip().isdigit() and n.strip().isdigit()) or not 0 <= int(k) < int(n):
            raise ValueError(f"shard {text!r} is not K/N with 0 <= K < N")
        return cls(int(k), int(n))

    @staticmethod
    def home(indices: np.ndarray | int, n: int) -> np.ndarray:
        """The home shard of each soldier index among ``n`` shards: one rule for shards and front-ends."""
        return np.asarray(indices, np.int64) % n

    def owns(self, indices: np.ndarray) -> np.ndarray:
        return self.home(indices, self.n) == self.k


class ShardNode:
    """A shard's link: its batches out on ``poses/K``, its requests in from ``requests/K``."""

    def __init__(
        self,
        server: TtesServer,
        fabric: Fabric,
        sharding: Sharding,
        *,
        key_every: int = KEY_EVERY,
        block: int = BLOCK,
    ) -> None:
        self.server, self.fabric, self.sharding = server, fabric, sharding
        self._pulse = fabric.publisher(poses_topic(sharding.k), Kind.POSES)
        # the streams some front-end hears (set on the fabric's thread: replaced whole, under the lock), and
        # whether one gained a subscriber since the last publish (it needs a key)
        self._match_lock = threading.Lock()
        self.heard: frozenset[int] = frozenset()
        self._fresh = False
        self._puts: dict[int, Handler] = {}  # per stream: WHOLE now, an index block at its first batch
        self._declare(WHOLE)
        self._answer = fabric.publisher(books_topic(), Kind.REQUESTS)  # its soldiers, to a late front-end
        self.block = block
        self.seq = 0  # ticks published (the pulse's count)
        self.block_seq: dict[int, int] = {}  # per stream (WHOLE or an index block), its batches
        self.key_every = key_every
        self.key_due = True  # the first batch is a key
        self._since_key = 0  # tick batches since the last key
        self._sent_serial = 0  # the board publish the last batch covered
        self.taken = 0  # fabric requests handled
        n = server.config.max_soldiers
        self.last = np.zeros(n, ENTITY_REQUEST_DTYPE)  # each soldier's last request taken, for a books answer
        self.has_last = np.zeros(n, bool)
        self.fences: list[int] = []  # per front-end, the newest fence taken (its batches carry them)
        self.stands_in: set[int] = set()  # the other shards whose soldiers it animates (a fail-over's)
        self.settings_stamp = shared.OWN_STAMP  # of the settings it holds: older ones are not taken
        self.gen = np.zeros(n, np.int64)  # each soldier's generation (requests.sync): 0, the script's; of an
        # index not live, its removal's if that is newer (a sync does not create it again from before)
        self._synced: dict[tuple[int, int], None] = {}  # the ids of the syncs taken, oldest first
        # soldiers created since the last fence, and those whose rows the next batch carries (born before a
        # fence): sets, so creations that no fence follows (a sync's) grow them no further than the soldiers
        self._born: set[int] = set()
        self._again: set[int] = set()
        server.on_publish = self.publish
        # what arrived and is not taken yet: bounded (two rows per soldier), requests coalesced per soldier
        self.backlog = Backlog(max_rows=max(MAX_ROWS, 2 * server.config.max_soldiers))
        server.status_note = lambda: (
            f"shard {sharding.k}/{sharding.n}, {self.seq} ticks, {self.backlog.describe()}"
        )
        self.bytes_out = 0  # the batches' bytes (one copy: the fabric sends one to each front-end)
        server.status_fields = lambda: {"fabric_bytes": self.bytes_out, "mono": round(time.monotonic(), 3)}

    def keep_own(self) -> None:
        """Drop the soldiers of the start-up script that other shards own."""
        m = self.server.world.manager
        if m is None:
            return
        for i in m.table.live[~self.sharding.owns(m.table.live)].tolist():
            self.server.world.remove_soldier(int(i), "another shard's")

    def start(self, token: trio.lowlevel.TrioToken) -> None:
        """Take requests on the trio loop in order of arrival, in turns (:meth:`take_turn`): the tick runs
        between turns when it is due (thousands of creations arrive at once when a client creates a crowd)."""
        self.fabric.announce(alive_key(self.sharding.k))
        send, receive = trio.open_memory_channel[None](1)

        def wake() -> None:
            with contextlib.suppress(trio.WouldBlock):
                send.send_nowait(None)

        def arrived(data: bytes) -> None:
            ops = self._decoded(data)
            if TRACE is not None:
                TRACE.stamp("shard_arrive", _request_indices(ops))
            if self.backlog.put(ops):
                token.run_sync_soon(wake)

        self.fabric.subscribe(requests_topic(self.sharding.k), Kind.REQUESTS, arrived)

        async def take() -> None:
            while True:
                if not self.backlog:
                    await receive.receive()
                if self.backlog:
                    with self.server.cpu("requests"):
                        self.take_turn()
                await trio.lowlevel.checkpoint()

        self.server.spawn(take)

    def take_turn(self) -> int:
        """Handle the backlog's operations in order for up to ``TURN_S`` of CPU (one at least), then answer
        them all at once: one answer batch for every request that arrived together (an answer per operation
        cost a sample, a publish and a batch each, and the later ones waited for the earlier ones'; the
        backlog hands consecutive request rows over as one batch, each soldier's newest).
        Returns how many were handled; the rest wait for the next turn, after the tick if it is due."""
        end = time.thread_time() + TURN_S
        n = 0
        while n == 0 or time.thread_time() < end:
            op = self.backlog.take()
            if op is None:
                break
            if TRACE is not None:
                TRACE.stamp("shard_take", _request_indices([op]))
            self.handle(op)
            n += 1
        self.server.requests_arrived()
        return n

    def publish(self, board: PoseBoard, tick: bool = True) -> None:
        """After each publish of the board: the soldiers whose codes changed since the previous batch (a
        tick's batch goes even when none did: it says the shard lives), or at a tick due for a key, every
        soldier. An answer (between ticks, or a tick's first frames: not ``tick``) sends only what it
        changed, and nothing if that is nothing."""
        tick = tick and board.tick == board.ticks
        if self._fresh:  # a stream gained a subscriber: its still soldiers come in no other batch
            with self._match_lock:
                self._fresh = False
            self.key_due = True
        key = tick and (self.key_due or self._since_key + 1 >= self.key_every)
        if key:
            rows = np.flatnonzero(board.valid)
            self.key_due, self._since_key = False, 0
        else:
            rows = np.flatnonzero(board.valid & (board.version > self._sent_serial))
            self._since_key += tick
        if self._again:  # a batch before the fence carried them: the front-end dropped those rows
            again = np.fromiter(self._again, np.int64, len(self._again))
            rows = np.union1d(rows, again[(again < len(board.valid)) & board.valid[again]])
            self._again.clear()
        self._sent_serial = board.serial
        if not tick and not len(rows):
            return
        if TRACE is not None:
            TRACE.stamp("shard_publish", rows, "tick" if tick else "answer")
        if len(rows) and WHOLE in self.heard:  # a front-end hears every block: one batch for it
            self._publish_block(board, WHOLE, rows, key, not tick)
        blocks = rows // self.block  # (rows ascending: each block's rows are consecutive)
        cuts = [0, *(np.flatnonzero(np.diff(blocks)) + 1).tolist(), len(rows)]
        for a, z in itertools.pairwise(cuts):
            if z > a and self._declare(int(blocks[a])) in self.heard:  # some front-end hears it alone
                self._publish_block(board, int(blocks[a]), rows[a:z], key, not tick)
        if tick:  # it lives, whatever blocks a front-end hears; a key's names every soldier (no codes)
            k, n, who = self.sharding.k, self.sharding.n, rows if key else rows[:0]
            empty = np.zeros((len(who), 0), np.uint16)
            pulse = Batch(
                k,
                n,
                self.seq,
                board.tick,
                time.monotonic(),
                who,
                board.table_of[who],
                empty,
                key,
                PULSE,
                tuple(self.fences),
            )
            self._sent(self._pulse, encode_batch(pulse))
            self.seq += 1

    def _declare(self, stream: int) -> int:
        """The publisher of ``stream`` (WHOLE or an index block), declared at its first use with a matching
        listener: the stream is published while some front-end hears it (:attr:`heard`)."""
        if stream not in self._puts:
            topic = poses_topic(self.sharding.k, stream)
            on_match = functools.partial(self._matched, stream)
            self._puts[stream] = self.fabric.publisher(topic, Kind.POSES, on_match=on_match)
        return stream

    def _matched(self, stream: int, present: bool) -> None:
        """On the fabric's thread: ``stream`` has a subscriber now (its next batch is a key), or none. (At
        its declaration, before its first batch, no key: none of its rows went before, so all go now.)"""
        with self._match_lock:
            self.heard = self.heard | {stream} if present else self.heard - {stream}
            self._fresh = self._fresh or (present and stream in self._puts)

    def _publish_block(self, board: PoseBoard, block: int, rows: np.ndarray, key: bool, answer: bool) -> None:
        seq = self.block_seq.get(block, 0)
        self.block_seq[block] = seq + 1
        k, n = self.sharding.k, self.sharding.n
        codes, tables = take_rows(board.codes, rows), board.table_of[rows]  # (rows whole: 2-3 times cheaper)
        fences = tuple(self.fences)
        batch = Batch(
            k, n, seq, board.tick, time.monotonic(), rows, tables, codes, key, block, fences, answer
        )
        self._sent(self._puts[block], encode_batch(batch))

    def _sent(self, put: Handler, data: bytes) -> None:
        put(data)
        self.bytes_out += len(data)

    def _decoded(self, data: bytes) -> list[req.Op]:
        try:
            return req.decode(data)
        except ValueError as exc:
            log.warning("fabric_message_refused", shard=self.sharding.k, error=str(exc))
            return []

    def handle(self, op: req.Op) -> None:
        """One request from a front-end (already checked there: a failure here is logged, not answered;
        the caller answers: ``TtesServer.requests_arrived``)."""
        try:
            self._apply(op)
        except (ValueError, KeyError, TypeError) as exc:  # a bad operation, or a soldier gone meanwhile
            log.warning("fabric_request_failed", shard=self.sharding.k, op=op.get("op"), error=str(exc))
            return
        self.taken += 1

    def _apply(self, msg: dict[str, object]) -> None:
        world = self.server.world
        op = msg["op"]
        if op == "books":
            self._answer_books(int(msg["front"]))  # type: ignore[call-overload]
            return
        if op == "create":
            owner = msg["owner"]
            index = world.create_soldier(
                str(msg["figure"]),
                str(msg["weapon"]),
                int(msg["index"]),  # type: ignore[call-overload]
                owner=str(owner) if owner is not None else None,
            )
            self.has_last[index] = False
            self.gen[index] = int(msg.get("gen") or 0)  # type: ignore[call-overload]
            self._born.add(index)
        elif op == "remove":
            index, gen = int(msg["index"]), int(msg.get("gen") or 0)  # type: ignore[call-overload]
            if 0 <= index < len(self.gen):  # (a removal of a soldier not here counts too: its sync was lost)
                self.gen[index] = max(int(self.gen[index]), gen)
            world.remove_soldier(index, "removed by a front-end")
            self.has_last[index] = False
        elif op == "requests":
            rows = msg["rows"]
            assert isinstance(rows, np.ndarray)
            self._applied(rows)
        elif op == "react":
            world.react(int(msg["index"]), str(msg["kind"]))  # type: ignore[call-overload]
        elif op == "sync":
            self._homes(msg)
            if self._first_time(msg.get("id")):
                self._sync(msg)
            else:  # sent again (its answer was late, not lost): its replay would snap each figure again
                log.info("fabric_sync_again", shard=self.sharding.k, id=msg.get("id"))
            self.key_due = True  # the front-end that sent it may lack soldiers no batch carried since
        elif op == "key":
            self.key_due = True
        elif op == "homes":
            self._homes(msg)
        elif op == "settings":
            stamp = shared.stamp_of(msg)
            if stamp >= self.settings_stamp:  # (a later front-end's start-up settings are older)
                shared.apply(world, msg["values"])  # type: ignore[arg-type]
                self.settings_stamp = stamp
        elif op == "fence":
            self._fenced(int(msg["front"]), int(msg["serial"]))  # type: ignore[call-overload]

    def _fenced(self, front: int, serial: int) -> None:
        """A front-end's message ends: the batches from now on carry its fence (and the rows of the soldiers
        created since the last fence, which a batch sent between their creation and the fence carried)."""
        self.fences += [0] * (front + 1 - len(self.fences))
        self.fences[front] = max(self.fences[front], serial)
        self._again |= self._born
        self._born.clear()

    def _answer_books(self, front: int) -> None:
        """Every soldier this shard animates, for front-end ``front`` that has just heard it."""
        m = self.server.world.manager
        assert m is not None
        live = m.table.live
        soldiers = _soldiers(self.server, live)
        last = self.last[live[self.has_last[live]]]
        homes, gens = sorted(self.stands_in), self.gen[live].tolist()
        values, stamp = shared.of(self.server.world), self.settings_stamp
        self._answer(books.answer(self.sharding.k, front, soldiers, last, homes, gens, values, stamp))
        log.info("fabric_books_answered", shard=self.sharding.k, front=front, soldiers=len(soldiers))

    def _first_time(self, sync_id: object) -> bool:
        """Whether the sync of id ``sync_id`` (front-end, stamp; None: a sync without one) is new here, and
        remember it: a front-end sends a sync again with the same id until the shard answers ``books``."""
        if not (isinstance(sync_id, list) and len(sync_id) == 2):
            return True
        key = (int(sync_id[0]), int(sync_id[1]))
        if key in self._synced:
            return False
        self._synced[key] = None
        if len(self._synced) > SYNCS_KEPT:
            del self._synced[next(iter(self._synced))]
        return True

    def _homes(self, msg: dict[str, object]) -> None:
        """The shards whose soldiers this one animates from now on, when the message says (a late
        front-end's ``books`` learns them even of a shard failed over with none)."""
        homes = msg.get("homes")
        if isinstance(homes, list):
            self.stands_in = {int(h) for h in homes} - {self.sharding.k}

    def _applied(self, rows: np.ndarray) -> None:
        """Apply requests, and keep those taken as their soldiers' last (what a books answer carries)."""
        taken = rows[self.server.world.apply_requests(rows) == REQUEST_OK]
        self.last[taken["index"]] = taken
        self.has_last[taken["index"]] = True

    def _sync(self, msg: dict[str, object]) -> None:
        """Remove the soldiers gone that are here (a removal sent before this shard listened; start-up
        soldiers its script made again), animate every soldier of the sync that is not here yet, from its
        last request, unless this shard took a removal of its index newer than the sync's soldier (another
        front-end removed it since the sync was made); with ``replay`` (soldiers coming home after a
        stand-in animated them) replay the last request of every one."""
        world, m = self.server.world, self.server.world.manager
        assert m is not None
        soldiers = msg["soldiers"]
        rows = msg["rows"]
        assert isinstance(soldiers, list) and isinstance(rows, np.ndarray)
        told, told_gens = msg.get("gone") or [], msg.get("gone_gens")
        assert isinstance(told, list)
        # a removal removes the soldier created before it, not one created again since (through another
        # front-end that the sender had not heard of)
        after: list[float] = [math.inf] * len(told)  # (a sync without generations: every one)
        if isinstance(told_gens, list) and len(told_gens) == len(told):
            after = [float(g) for g in told_gens]
        gone = [
            int(i) for i, g in zip(told, after, strict=True) if m.table.is_live(int(i)) and self.gen[i] < g
        ]
        for i in gone:
            world.remove_soldier(i, "removed through a front-end while this shard did not hear it")
            self.has_last[i] = False
        new, stale = [], 0
        gens = msg.get("gens")
        gens = gens if isinstance(gens, list) and len(gens) == len(soldiers) else [0] * len(soldiers)
        for (index, figure, weapon, owner), gen in zip(soldiers, gens, strict=True):
            if not m.table.is_live(index) and 0 <= index < len(self.gen) and self.gen[index] > int(gen):
                stale += 1  # removed at a newer generation: the sync's soldier is the one removed
            elif not m.table.is_live(index):
                world.create_soldier(figure, weapon, index, owner=owner)
                self.has_last[index] = False
                self.gen[index] = int(gen)
                new.append(index)
        self._born.update(new)
        log.info(
            "fabric_sync",
            shard=self.sharding.k,
            soldiers=len(soldiers),
            created=len(new),
            removed=len(gone),
            removed_since=stale,
        )
        if len(rows):
            self._applied(rows if msg.get("replay") else rows[np.isin(rows["index"], new)])


@dataclass(frozen=True)
class Asked:
    """A shard asked for its books that has not answered: asked again at its first pulse from ``again``
    (server time) on, after ``wait`` s, with ``sync`` first (the sync that went with the ask: a shard
    heard for the first time, or again after a restart or a fail-over; sent again with the same id, a
    shard that took it already only sends a key). The answer follows the sync (one message, in order):
    it acknowledges both, refused or not. Zenoh drops what a node publishes before it knows of a
    subscriber: a shard's first pulses reached a front-end before its subscription to its requests did,
    the sync and the ask went nowhere, and on main the front-end waited for the answer for ever (the
    soldiers created meanwhile never reached the shard: issue 21's flaky CI test)."""

    again: float
    wait: float
    sync: Callable[[], None] | None


class FrontNode:
    """A front-end's link: every shard's newest batch in, its clients' requests out to the shard that
    animates the soldier (it is the world's :class:`~server.startup.Relay`).

    Shard ``k``'s soldiers are animated by shard ``route[k]``: ``k`` itself, or once ``k`` is down, a
    surviving shard, sent a sync of those soldiers with their last requests. Down means gone from the
    fabric (its process died: the fabric's presence says so at once) or silent for ``hung_s`` (no batch: a
    process that hangs; a busy one is only late). A shard heard for the first time, or again after a
    restart (its batch count went back), gets a sync of its own soldiers: creations sent before it listened
    are not lost. A shard that comes back takes its soldiers back from the one that stood in.

    Front-end ``front`` = K/M of several allots indices from its own share (:mod:`server.fabric.fronts`) and
    tells the others on ``ttes/fronts`` what it creates and removes; it keeps their creations and removals
    in its books as its own (not relayed: the front-end that made them did)."""

    def __init__(
        self,
        server: TtesServer,
        fabric: Fabric,
        shards: int,
        *,
        front: Sharding = Sharding(0, 1),
        hung_s: float = 5.0,
        block: int = BLOCK,
    ) -> None:
        self.server, self.fabric, self.shards = server, fabric, shards
        self.front = front
        self.hung_s = hung_s
        self.block = block
        n = server.config.max_soldiers
        self.share = IndexShare(front.k, front.n, block, n) if front.n > 1 else None
        self._books = fabric.publisher(fronts_topic(), Kind.REQUESTS) if front.n > 1 else None
        self._books_out: list[req.Op] = []  # this front-end's creations and removals, for the others
        # the others' presence and connections of client ids: an id's soldiers wait while it is connected
        self.elsewhere = books.Elsewhere(front.k, front.n, block) if front.n > 1 else None
        if self.elsewhere is not None:
            server.world.owners.on_connections = self._connections
        self.mirrored = 0  # the other front-ends' creations and removals kept in the books here
        self.bytes_in = 0  # the shards' batches' bytes
        server.status_fields = lambda: {
            "fabric_bytes": self.bytes_in,
            "mirrored": self.mirrored,
            "fabric_blocks": len(self._subs),
            "mono": round(time.monotonic(), 3),
        }
        self.present = [False] * shards  # on the fabric now (its presence)
        self._puts = [fabric.publisher(requests_topic(k), Kind.REQUESTS) for k in range(shards)]
        self._out: list[list[req.Op]] = [[] for _ in range(shards)]  # per shard, sent at the loop's next turn
        self._token: trio.lowlevel.TrioToken | None = None
        self._flush_due = False
        # the settings last sent to every shard (server.fabric.settings): sent again when they change, with
        # a newer stamp than those held here
        self._told = (server.world.settings, server.world.report_interval)
        self.settings_stamp = shared.START
        self._pending: dict[int, list[bytes]] = {}  # shard -> its batches not merged yet, in arrival order
        self._pending_lock = threading.Lock()  # appended on the fabric's thread, taken on the loop
        self.key_asked = [False] * shards  # a key batch asked for after a lost batch, not come yet
        self.route = list(range(shards))
        self._own_route = list(range(shards))  # every shard animates its own
        self.heard_at = [-math.inf] * shards  # server time of each shard's last pulse
        self.last_seq = [-1] * shards  # of its pulses (ticks)
        self.blocks = -(-n // block)  # index blocks: a shard's pose topics
        self._subs: dict[tuple[int, int], Unsubscribe] = {}  # (shard, block) heard
        self._block_seq: dict[tuple[int, int], int] = {}  # (shard, block) -> its last batch's seq
        self._key_wanted: set[tuple[int, int]] = set()  # heard since lately, no key of it come yet
        self.rows_decoded = np.zeros(self.blocks, np.int64)  # per block: the rows the fabric brought here
        self.pending_max = PENDING_MAX * (1 + self.blocks)  # messages: PENDING_MAX ticks of every block
        self.last = np.zeros(n, ENTITY_REQUEST_DTYPE)  # each soldier's last request, for a sync
        self.has_last = np.zeros(n, bool)
        self.made = np.zeros(n, bool)  # created here (not the start-up script's, not another front-end's)
        self.gen = np.zeros(n, np.int64)  # each index's creations and removals heard of (requests.sync)
        self._asked: dict[int, Asked] = {}  # shards asked for their books, not answered yet
        self._sync_id = 0  # the stamp of the last sync's id (front-end, stamp): a restart's count past it
        # shards whose last key pulse differed from the books: asked only if the next one differs too (a
        # creation through another front-end is often in a pulse before its message on ttes/fronts is here:
        # each front-end asked each shard about once a second while 6 of them made soldiers, 1,000-1,100
        # whole answers a shard in a 100 s run of 48,000 over 6 shards and 6 front-ends)
        self._differed: set[int] = set()
        self.known = np.zeros(n, bool)  # created or removed here, or told so by a front-end: not learned
        self._unknown: dict[int, set[int]] = {}  # shard asked -> its batches' soldiers not in the books
        self._stood_for: dict[int, set[int]] = {}  # shard failed over -> the other homes it animated
        self._followed: dict[int, int] = {}  # shard failed over by another front-end -> that front-end
        self.batches = 0  # merged
        self.skipped = 0  # lost on the fabric (or dropped from a full queue)
        self.failovers = 0
        self.keys = 0  # key batches heard
        self.watching = Watch(n)  # what its clients subscribe to; the others' codes wait there
        # ticks' batches that arrived with answers, merged after the answers' clients encoded them
        # (:meth:`_answers_first`), and those clients' sessions (ids) until they have
        self._held: list[Batch] = []
        self._answering: set[int] = set()
        server.encoded = self._encoded
        self.fences = Fences(front.k, n, shards)  # indices created or removed here: rows wait for a fence
        server.board_ref.on_watch = self.watch
        server.feed = self.feed
        server.relay_out = self._flush
        server.world.relay = self
        server.status_note = self.describe

    def describe(self) -> str:
        """The shards as STATUS shows them: ``front-end of 2 shards: 0 up, 1 on 0 (gone)``, and which
        front-end this is of several: `` (front-end 1 of 2)``."""
        parts = []
        for k in range(self.shards):
            where = "up" if self.route[k] == k else f"on {self.route[k]}"
            parts.append(f"{k} {where}" + ("" if self.present[k] else " (gone)"))
        several = f" (front-end {self.front.k} of {self.front.n})" if self.front.n > 1 else ""
        return f"front-end of {self.shards} shards: " + ", ".join(parts) + several

    def start(self, token: trio.lowlevel.TrioToken) -> None:
        self._token = token
        if self.share is not None:

            def told(data: bytes) -> None:  # from the fabric's thread to the loop
                token.run_sync_soon(self.mirror, data)

            self.fabric.subscribe(fronts_topic(), Kind.REQUESTS, told)
            self.fabric.announce(front_alive_key(self.front.k))
            for j in range(self.front.n):
                if j != self.front.k:
                    self.fabric.watch(front_alive_key(j), functools.partial(self._front_watched, token, j))

        def answered(data: bytes) -> None:
            token.run_sync_soon(self.learn, data)

        self.fabric.subscribe(books_topic(), Kind.REQUESTS, answered)
        for k in range(self.shards):
            self.fabric.subscribe(poses_topic(k), Kind.POSES, functools.partial(self._arrived, token, k))
            self.fabric.watch(alive_key(k), functools.partial(self._watched, token, k))
        self._resubscribe()

    def _covered(self, k: int, streams: set[tuple[int, int]]) -> np.ndarray:
        """Which indices whose home is shard ``k`` the streams of ``streams`` (shard, block) bring (a
        mask): WHOLE all of them, a block its own."""
        n = len(self.watching.held)
        mine = Sharding.home(np.arange(n), self.shards) == k
        heard = {b for s, b in streams if s == k}
        if WHOLE in heard:
            return mine
        return mine & np.isin(np.arange(n) // self.block, list(heard))

    def _wanted(self, blocks: np.ndarray) -> set[tuple[int, int]]:
        """The (shard, stream) topics to hear: of every shard (a survivor publishes a failed shard's
        soldiers), the blocks its clients watch (and ``blocks``), or WHOLE when they cover every block that
        holds a soldier (the same rows, one batch a shard a tick: each message costs the shard, the fabric
        and this loop); WHOLE for a shard asked for its books (until it answers, its batches say which
        indices it animates: allot)."""
        watched = np.flatnonzero(self.watching.watched) // self.block
        every = np.union1d(watched, blocks)
        every = every[(every >= 0) & (every < self.blocks)]
        m = self.server.world.manager
        occupied = np.unique(m.table.live // self.block) if m is not None else every[:0]
        whole = bool(len(every)) and bool(np.isin(occupied, every).all())
        want = set()
        for k in range(self.shards):
            if whole or k in self._asked:
                want.add((k, WHOLE))
            else:
                want.update((k, int(b)) for b in every)
        return want

    def _resubscribe(self, blocks: np.ndarray | None = None) -> None:
        """Hear the wanted topics (:meth:`_wanted`), no others (the new ones first: a shard publishes a
        stream while someone hears it). A topic heard anew asks its shard for a key (its still soldiers
        come in no other batch; the shard sends one too when a stream gains a subscriber), and the codes
        kept of the soldiers it newly brings are dropped (batches went by unheard: they are stale); the
        soldiers no topic brings any more are left unknown on the board (none is sent to a client that
        subscribes later before the key's)."""
        if self._token is None:
            return
        want = self._wanted(np.zeros(0, np.int64) if blocks is None else blocks)
        old = set(self._subs)
        new, gone = sorted(want - old), sorted(old - want)
        board = self.server.board_ref.board
        for k in sorted({k for k, _ in (*new, *gone)}):
            before, after = self._covered(k, old), self._covered(k, want)
            self.watching.held[after & ~before] = False
            if board is not None:  # no client watches them: their rows would go stale there
                board.unknown(np.flatnonzero(before & ~after))
        for k, b in new:
            arrived = functools.partial(self._arrived, self._token, k)
            self._subs[(k, b)] = self.fabric.subscribe(poses_topic(k, b), Kind.POSES, arrived)
            self._key_wanted.add((k, b))
        for stream in gone:
            self._subs.pop(stream)()
            self._key_wanted.discard(stream)
            self._block_seq.pop(stream, None)  # (heard again later: its seq went on meanwhile)
        for k in sorted({k for k, _ in new}):
            self.key_asked[k] = True
            self._send(k, req.key())

    def _watched(self, token: trio.lowlevel.TrioToken, k: int, present: bool) -> None:
        token.run_sync_soon(self._presence, k, present)  # from the fabric's thread to the loop

    def _presence(self, k: int, present: bool) -> None:
        self.present[k] = present
        log.info("fabric_shard_presence", shard=k, present=present)
        if not present:
            self._fail_over(self.server.now())

    def _arrived(self, token: trio.lowlevel.TrioToken, k: int, data: bytes) -> None:
        """On the fabric's thread: queue the batch; the first one waiting asks the loop to publish."""
        if TRACE is not None:
            TRACE.stamp("fe_arrive", decode_batch(data).indices)
        self.bytes_in += len(data)  # a bench's count: an increment lost between fabric threads is noise
        with self._pending_lock:
            queue = self._pending.setdefault(k, [])
            waiting = bool(queue)
            queue.append(data)
            if len(queue) > self.pending_max:  # the loop is far behind: the seq gap asks for a key
                del queue[0]
        if not waiting:
            token.run_sync_soon(self.server.publish_fed)

    def feed(self, board: PoseBoard, tick: int) -> np.ndarray:
        """Merge the newest batch of every shard that sent one into the board, labelled ``tick`` (as soon as
        one arrives, and on each tick of the front-end's own loop), and fail silent shards over. Returns
        the soldiers whose codes changed."""
        now = self.server.now()
        with self._pending_lock:
            pending, self._pending = self._pending, {}
        batches = [decode_batch(data) for k in sorted(pending) for data in pending[k]]
        for b in batches:
            if b.block < self.blocks:
                self.rows_decoded[b.block] += len(b.indices)
            elif b.block == WHOLE:
                per_block = np.bincount(b.indices // self.block, minlength=self.blocks)
                self.rows_decoded += per_block[: self.blocks]
            self._heard(b, now)
        self._fail_over(now)
        self._settings_told()
        m = self.server.world.manager
        if m is not None and self.watching.stale:
            subscribed = (s.conn.subscribed for s in self.server.sessions.values())
            self.watching.recount(subscribed, board, m.table.alive)
            self._resubscribe()
        batches = [*self._held, *(b for b in batches if b.block != PULSE)]
        self._held = []
        if not batches or m is None:
            self._answering.clear()
            return np.zeros(0, np.int64)
        holding = bool(self._answering)  # (its answers' clients have not encoded: more answers, no ticks)
        if tick > self.server.ticks and self.server.answers_first:  # a publish between its ticks
            first, held = self._answers_first(batches)
            if held and (first or holding):
                batches, self._held = first, held
        if not self._held:
            self._answering.clear()
        if not batches:
            return np.zeros(0, np.int64)
        self.batches += len(batches)
        batches = [self._routed(self.fences.clean(b)) for b in batches]  # (after _heard: a sync moves fences)
        rows = np.concatenate([b.indices for b in batches]).astype(np.int64)
        if merge(board, batches, tick, m.table.alive, self.watching):
            changed = rows[
                (rows < board.capacity)
                & (board.version[np.minimum(rows, board.capacity - 1)] == board.serial)
            ]
        else:
            changed = rows[:0]
        if TRACE is not None:
            note = "first" if self._held else "fed" if tick > self.server.ticks else "tick"
            TRACE.stamp("fe_merge", rows, note)  # (first: answers merged before ticks held)
        if self._held and not holding:  # the clients the answers woke encode them before the ticks merge
            woken = self._woken(changed)
            for s in woken:  # the tick's rows follow at once: not held back by the server's throttle
                s.more_of_tick = True  # (Session.take_output), as a single server's tick's first frames
            self._answering = {s.id for s in woken}
            if not self._answering and self._token is not None:
                self._token.run_sync_soon(self.server.publish_fed)
        return changed

    def _routed(self, b: Batch) -> Batch:
        """``b`` without the rows of soldiers whose home is routed to another shard than ``b``'s: a shard
        failed over that this front-end still hears (a split fabric, a shard that resumes before the
        take-back) animates copies that nobody drives."""
        if self.route == self._own_route or not len(b.indices):
            return b
        ok = np.asarray(self.route)[Sharding.home(b.indices, self.shards)] == b.shard
        if ok.all():
            return b
        return dataclasses.replace(b, indices=b.indices[ok], tables=b.tables[ok], codes=b.codes[ok])

    def _answers_first(self, batches: list[Batch]) -> tuple[list[Batch], list[Batch]]:
        """``(now, held)``: the answers among ``batches`` to merge now, before the ticks' batches that came
        with them (issue 21: a client whose answer was merged with a tick waited for the encode of that
        tick's rows, its own client's and the others'), and the rest: each shard's answers that came before
        its first tick's batch here (a shard's batches merge in order); while a shard stands in for another,
        all now (their rows may overlap)."""
        if self.route != self._own_route:
            return batches, []
        now: list[Batch] = []
        held: list[Batch] = []
        for b in batches:
            (now if b.answer and not any(h.shard == b.shard for h in held) else held).append(b)
        return now, held

    def _woken(self, rows: np.ndarray) -> list[Session]:
        """The sessions whose writers a publish of ``rows`` wakes (``TtesServer._published``)."""
        sessions = self.server.sessions.values()
        return [s for s in sessions if s.tables_sent and len(rows) and s.conn.subscribes_any(rows)]

    def _encoded(self, session: Session) -> None:
        """A writer encoded: once every client the held ticks' answers woke has, the ticks merge (at the
        loop's next turn: the writer sends first)."""
        if self._answering:
            self._answering.discard(session.id)
            if not self._answering and self._held and self._token is not None:
                self._token.run_sync_soon(self.server.publish_fed)

    def watch(self, indices: np.ndarray | None) -> None:
        """A client subscribed to ``indices`` (None: one unsubscribed, or left): the held codes of those
        no client watched go onto the board now, before its writer encodes (:mod:`server.fabric.watch`)."""
        if indices is None:
            self.watching.stale = True
            return
        self._resubscribe(np.unique(np.asarray(indices, np.int64) // self.block))  # before: held codes go
        m = self.server.world.manager
        if m is not None:
            self.watching.watch(indices, self.server.board_ref.board, m.table.alive)

    def _heard(self, b: Batch, now: float) -> None:
        if b.block == PULSE:
            self._pulse(b, now)
            return
        k, stream = b.shard, (b.shard, b.block)
        last = self._block_seq.get(stream, b.seq - 1)
        lost = max(0, b.seq - last - 1)  # (a restarted shard's seq goes back: nothing lost)
        self._block_seq[stream] = b.seq
        self.skipped += lost
        if b.key:
            self.keys += 1
            self.key_asked[k] = False
            self._key_wanted.discard(stream)
        elif (lost or stream in self._key_wanted) and not self.key_asked[k]:
            self.key_asked[k] = True  # the rows that changed in a lost batch are stale until a key
            self._send(self.route[k], req.key())
        if k in self._asked and self.server.world.manager is not None:
            self._not_in_books(k, b.indices)

    def _not_in_books(self, k: int, indices: np.ndarray) -> None:
        """Shard ``k`` asked for its books: its soldiers ``indices`` that the books lack, no index of which is
        allotted here until it answers. Only those of the index space: a shard's batches grow this by no
        more (asked again until it answers, :class:`Asked`, the ask may stand a long time)."""
        m = self.server.world.manager
        assert m is not None
        idx = np.asarray(indices, np.int64)
        idx = idx[(idx >= 0) & (idx < len(self.known))]
        self._unknown.setdefault(k, set()).update(idx[~m.table.live_mask(idx)].tolist())

    def _ask_books(self, k: int, now: float, sync: Callable[[], None] | None = None) -> None:
        """Ask shard ``k`` for its books, and again at its pulses until it answers (:class:`Asked`)."""
        ask = self._asked.get(k)  # asked again: twice the last wait; a new sync (a restart) asks anew
        wait = ASK_AGAIN_S if ask is None or sync is not ask.sync else min(2 * ask.wait, ASK_AGAIN_MAX_S)
        self._asked[k] = Asked(now + wait, wait, sync)
        self._send(k, req.books(self.front.k))
        self._resubscribe()

    def _pulse(self, b: Batch, now: float) -> None:
        """Shard ``b.shard``'s tick: it lives; heard for the first time, or back (a restart: its count went
        back; or it had failed over), it gets a sync and ``books`` (:class:`Asked`); not while another
        front-end's fail-over of it stands (:meth:`follow`)."""
        k = b.shard
        first = self.heard_at[k] == -math.inf
        back = first or b.seq < self.last_seq[k] or self.route[k] != k
        self.last_seq[k], self.heard_at[k] = b.seq, now
        sync = None
        if back and k not in self._followed:
            stood_in = self.route[k]
            self.route[k] = k
            if stood_in != k:  # it stood in for k: k's soldiers go home
                for i in self._homed(k).tolist():
                    self._send(stood_in, req.remove(i, int(self.gen[i])))
                self._send(stood_in, req.homes(self._animated_by(stood_in)))
                self._book(req.back(k))  # a fail-over the others followed stands no more
            log.info("fabric_shard_joined", shard=k, seq=b.seq, took_back_from=stood_in)
            # it stood in for other shards before it went (hung): their soldiers live elsewhere now
            moved = [h for h in self._stood_for.pop(k, set()) if self.route[h] != k]
            drop = np.concatenate([self._homed(h) for h in moved]) if moved else None
            # from a stand-in (perhaps learned from its answer: this front-end started meanwhile), all of them
            sync = functools.partial(
                self._sync,
                k,
                [k],
                replay=stood_in != k,
                made=first and stood_in == k,
                drop=drop,
                sync_id=self._next_sync_id(),  # sent again, the same: a shard takes it once
            )
            sync()
        m = self.server.world.manager
        if m is None:
            return
        # this front-end may be late, or have missed another's message: it learns from the shard (a key
        # pulse names every soldier the shard animates, whatever blocks this front-end hears)
        ask = self._asked.get(k)
        if sync is not None or (ask is None and (first or (b.key and self._differs_again(k, b.indices)))):
            self._ask_books(k, now, sync)  # (with a sync: its answer acknowledges it)
        elif ask is not None and now >= ask.again:  # lost (or the shard is busy): ask again
            log.warning("fabric_books_asked_again", front=self.front.k, shard=k, waited_s=ask.wait)
            if ask.sync is not None and self.route[k] == k:
                ask.sync()
            self._ask_books(k, now, ask.sync)
        if k in self._asked:  # until it answers, no index it animates is allotted here
            self._not_in_books(k, b.indices)

    def _differs_again(self, k: int, indices: np.ndarray) -> bool:
        """Whether shard ``k``'s key pulse differs from the books (:meth:`_differs`), as its last one did."""
        differs = self._differs(k, indices)
        again = differs and k in self._differed
        if differs:
            self._differed.add(k)
        else:
            self._differed.discard(k)
        return again

    def _differs(self, k: int, indices: np.ndarray) -> bool:
        """Whether shard ``k``'s key pulse (every soldier it animates) carries a soldier the books lack, or
        lacks one they hold, of those no front-end told this one of (a message lost before a link came up)."""
        m = self.server.world.manager
        assert m is not None
        known, idx = self.known, np.asarray(indices, np.int64)
        idx = idx[idx < len(known)]  # (not the table's length: it grows, and another front-end's share is
        # beyond it: on main a pulse never differed by a soldier created through front-end 1 of 2)
        if (~m.table.live_mask(idx) & ~known[idx]).any():
            return True
        live = m.table.live
        scope = live[(np.asarray(self.route)[Sharding.home(live, self.shards)] == k) & ~known[live]]
        return not np.isin(scope, idx).all()

    def _fail_over(self, now: float) -> None:
        alive = [k for k in range(self.shards) if self._hears(k, now)]
        heard = [at > -math.inf for at in self.heard_at]
        for k, survivor, homes in books.rerouted(self.route, alive, heard):
            self._failed(k, survivor, homes, now)
            self._book(req.failover(k, survivor, homes))  # the others follow (each decides on its own clock)

    def _failed(self, k: int, survivor: int, homes: list[int], now: float) -> None:
        """Shard ``k``'s soldiers of ``homes`` are routed to ``survivor`` now: it gets them by sync."""
        self.failovers += 1
        silent_s = round(now - self.heard_at[k], 3)
        log.warning("fabric_failover", shard=k, to=survivor, homes=homes, silent_s=silent_s)
        self._stood_for.setdefault(k, set()).update(h for h in homes if h != k)
        self._sync(survivor, homes)

    def follow(self, down: int, to: int, by: int) -> None:
        """Front-end ``by`` failed shard ``down`` over to ``to``: fail it over here too, and keep it failed
        over while that fail-over stands, even if this front-end hears the shard (two front-ends routed a
        hung shard's requests differently for up to the hung limit, each deciding on its own clock; with a
        split fabric, for as long as the split lasted: one that still heard the shard kept routing to it,
        while the other's clients saw the stand-in's soldiers). It stands until a front-end takes the
        shard's soldiers back (:meth:`took_back`) or ``by`` is gone from the fabric."""
        now = self.server.now()
        if not (0 <= down < self.shards and 0 <= to < self.shards) or down == to:
            return
        homes = [h for h, r in enumerate(self.route) if r == down]
        if homes:
            self._followed[down] = by
            for h in homes:
                self.route[h] = to
            self._failed(down, to, homes, now)

    def took_back(self, k: int) -> None:
        """Another front-end heard shard ``k`` again and took its soldiers back from the stand-in: this one
        takes them back at ``k``'s next pulse (its own last requests replayed), or, if it does not hear
        ``k``, fails it over itself (the stand-in has let them go)."""
        self._followed.pop(k, None)
        if 0 <= k < self.shards and self.route[k] != k and not self._hears(k, self.server.now()):
            self.route[k] = k  # (the next _fail_over hands its soldiers to a survivor again)

    def _hears(self, k: int, now: float) -> bool:
        return self.present[k] and now - self.heard_at[k] <= self.hung_s

    def _settings_told(self) -> None:
        """The server-wide settings changed (an operator's JCL): every shard takes them, and every other
        front-end (its syncs carry them too)."""
        world = self.server.world
        if world.settings is not self._told[0] or world.report_interval != self._told[1]:
            self._told = (world.settings, world.report_interval)  # (a new value when one changes)
            self.settings_stamp = shared.stamp(self.settings_stamp, self.front.k)
            op = self._settings_op()
            for k in range(self.shards):
                self._send(k, op)
            self._book(op)

    def _settings_op(self) -> req.Op:
        return req.settings(shared.of(self.server.world), self.settings_stamp)

    def _settings_learned(self, values: dict[str, object], stamp: shared.Stamp) -> None:
        """Settings another front-end told, or a shard's answer carried: taken if newer than those here (the
        shards have them already, or the newer ones from here)."""
        if stamp <= self.settings_stamp:
            return
        try:
            shared.apply(self.server.world, values)
        except (ValueError, TypeError) as exc:
            log.warning("fabric_settings_refused", front=self.front.k, error=str(exc))
            return
        self._told = (self.server.world.settings, self.server.world.report_interval)
        self.settings_stamp = stamp

    def _homed(self, k: int) -> np.ndarray:
        """The live soldiers whose home is shard ``k``."""
        m = self.server.world.manager
        live = m.table.live if m is not None else np.zeros(0, np.int64)
        return live[Sharding.home(live, self.shards) == k]

    def _next_sync_id(self) -> int:
        self._sync_id = after(self._sync_id)  # (past a restart's: the shard remembers the ids it took)
        return self._sync_id

    def _sync(
        self,
        shard: int,
        homes: list[int],
        *,
        replay: bool = False,
        made: bool = False,
        drop: np.ndarray | None = None,
        sync_id: int | None = None,
    ) -> None:
        """``made``: only the soldiers created here (a shard heard for the first time: this front-end's
        creations may have gone before it listened; the start-up script's it has, the others' their makers
        sync, and a late front-end's books are not the truth: it learns them from the answer to ``books``).
        ``drop``: soldiers of other homes the shard is to let go of (it stood in for them, and hung).
        ``sync_id``: the id of a sync sent again (:class:`Asked`); None: a new one."""
        m = self.server.world.manager
        if m is None:
            return
        idx = np.concatenate([self._homed(h) for h in homes])
        if made:
            idx = idx[self.made[idx]]
        soldiers = _soldiers(self.server, idx)
        have = idx[self.has_last[idx]]
        removed = books.gone(self.known, m.table.alive, homes, self.shards)
        elsewhere = np.zeros(0, np.int64) if drop is None else np.asarray(drop, np.int64)
        # (not those whose home is routed to the shard since: a sync asked again after another fail-over)
        elsewhere = elsewhere[np.asarray(self.route)[Sharding.home(elsewhere, self.shards)] != shard]
        gone = [*removed.tolist(), *elsewhere.tolist()]
        gone_gens = [*self.gen[removed].tolist(), *(self.gen[elsewhere] + 1).tolist()]  # (those live on)
        animates = None if made else self._animated_by(shard)  # (a shard heard first: the stand-in knows)
        self._send(shard, self._settings_op())  # (the shard keeps newer ones: a change made elsewhere)
        gens = self.gen[idx].tolist()
        self._send(
            shard,
            req.sync(
                soldiers,
                self.last[have],
                replay=replay,
                gone=gone,
                homes=animates,
                gens=gens,
                gone_gens=gone_gens,
                sync_id=(self.front.k, self._next_sync_id() if sync_id is None else sync_id),
            ),
        )
        self.fences.moved(homes, self.shards, shard)

    def _animated_by(self, shard: int) -> list[int]:
        """The homes routed to ``shard``: its own, and those it stands in for."""
        return [h for h, r in enumerate(self.route) if r == shard]

    def _send(self, shard: int, op: req.Op) -> None:
        """Queue an operation for ``shard``: what one turn of the loop queued goes as one message."""
        self._out[shard].append(op)
        self._flush_soon()

    def _book(self, op: req.Op) -> None:
        """Queue a creation or removal for the other front-ends (with several), sent as ``_send``'s."""
        if self._books is not None:
            self._books_out.append({**op, "front": self.front.k})
            self._flush_soon()

    def _book_fenced(self, op: req.Op, index: int) -> None:
        """A creation or removal sent to its shard now: its rows wait for the fence that ends the message,
        here and, told which, on the other front-ends (they mirror it and have no fence of their own)."""
        shard = self._shard_of(index)
        self.fences.mark([index], shard)
        self._book({**op, "shard": shard, "fence": int(self.fences.serial[index])})

    def _flush_soon(self) -> None:
        if self._token is None:
            self._flush()
        elif not self._flush_due:
            self._flush_due = True
            self._token.run_sync_soon(self._flush)

    def _flush(self) -> None:
        self._flush_due = False
        for k, ops in enumerate(self._out):
            if ops and (serial := self.fences.fence(k)) is not None:
                ops.append(req.fence(self.front.k, serial))
            if ops:
                if TRACE is not None:
                    TRACE.stamp("fe_publish", _request_indices(ops))
                self._puts[k](req.pack(ops))
                ops.clear()
        if self._books is not None and self._books_out:
            self._books(req.pack(self._books_out))
            self._books_out.clear()

    def mirror(self, data: bytes) -> None:
        """On the loop: another front-end's creations and removals, kept in the books here as its own (its
        clients see them; the shards heard of them from that front-end, so nothing is relayed)."""
        try:
            ops = [op for op in req.decode(data) if op.get("front") != self.front.k]
        except ValueError as exc:
            log.warning("fabric_books_refused", front=self.front.k, error=str(exc))
            return
        for op in ops:
            self._mirror_one(op)

    def _mirror_one(self, op: req.Op) -> None:
        try:
            if op["op"] == "clients":  # (an anonymous id is one connection's, never connected here)
                for cid, n in op["counts"].items():
                    if not cid.startswith(ANONYMOUS):
                        self._count(int(op["front"]), cid, n)
                return
            if op["op"] == "failover":
                self.follow(int(op["down"]), int(op["to"]), int(op["front"]))
                return
            if op["op"] == "back":
                self.took_back(int(op["shard"]))
                return
            if op["op"] == "settings":  # the shards have them from that front-end
                self._settings_learned(op["values"], shared.stamp_of(op))
                return
            i = int(op["index"])
            self._touch(i)
            self.gen[i] = max(int(self.gen[i]), int(op.get("gen") or 0))
            if op["op"] == "create":
                self._kept(i, str(op["figure"]), str(op["weapon"]), op["owner"])
            elif op["op"] == "remove":
                self._let_go(i, f"removed through front-end {op['front']}")
            if "fence" in op:  # the shard's batches carry the old soldier's rows until they carry this
                self.fences.wait([i], int(op["front"]), int(op["shard"]), int(op["fence"]))
        except (ValueError, KeyError, TypeError) as exc:
            log.warning("fabric_books_failed", front=self.front.k, op=op.get("op"), error=str(exc))
            return
        self.mirrored += 1

    def _front_watched(self, token: trio.lowlevel.TrioToken, j: int, present: bool) -> None:
        token.run_sync_soon(self._front_presence, j, present)  # from the fabric's thread to the loop

    def _front_presence(self, j: int, present: bool) -> None:
        """Front-end ``j`` came (it may have missed what this one told: its connections go again) or went
        (its clients' connections went with it; the orphans of its share may be this one's to remove)."""
        assert self.elsewhere is not None
        self.elsewhere.present[j] = present
        log.info("fabric_front_presence", front=j, present=present)
        if present:
            if self.elsewhere.told:
                self._book(req.clients(dict(self.elsewhere.told)))
            if self.settings_stamp > shared.START:  # (an operator's change: it may have started since)
                self._book(self._settings_op())
            return
        for cid in list(self.elsewhere.counts[j]):
            self._count(j, cid, 0)
        for k in [k for k, by in self._followed.items() if by == j]:  # its fail-overs stand no more
            del self._followed[k]
        self.server.orphans_check()

    def _connections(self, client_id: str) -> None:
        """The owners' hook: ``client_id``'s connections changed; tell the others this front-end's own."""
        assert self.elsewhere is not None
        if client_id.startswith(ANONYMOUS):  # one connection's, of this server: nothing to the others
            return
        own = self.elsewhere.own(client_id, self.server.world.owners.connected.get(client_id, 0))
        if own is not None:
            self._book(req.clients(own))

    def _count(self, front: int, client_id: str, n: int) -> None:
        """Front-end ``front`` has ``n`` connections of ``client_id``: join or leave it here as many times."""
        assert self.elsewhere is not None
        while step := self.elsewhere.step(front, client_id, n):
            if step > 0:
                self.server.world.owners.join(client_id)
            else:
                self.server.client_left(client_id)

    def orphans(self, indices: list[int]) -> list[int]:
        return indices if self.elsewhere is None else self.elsewhere.removes(indices)

    def _kept(self, index: int, figure: str, weapon: str, owner: str | None) -> None:
        """Keep in the books a soldier a shard or another front-end already has (not relayed again)."""
        self.server.world.create_soldier(figure, weapon, index, owner=owner, relay=False)
        self.has_last[index] = False
        self.watching.forget(index)

    def _let_go(self, index: int, reason: str) -> None:
        """Drop from the books a soldier removed elsewhere (not relayed again); its index is free."""
        self.server.world.remove_soldier(index, reason, relay=False)
        self.made[index] = False
        self.watching.forget(index)
        if self.share is not None:
            self.share.freed(index)

    def _touch(self, index: int) -> None:
        """Soldier ``index`` was created or removed here, or a front-end told so: this front-end knows
        better than a shard's answer (which may predate it, or the shard missed it before it listened)."""
        self.known[index] = True

    def learn(self, data: bytes) -> None:
        """On the loop: a shard's answer to this front-end's ``books`` (sent after a sync of the soldiers
        made here): the shard's soldiers are the truth, kept in the books here (not relayed: the shard has
        them, and the front-end that made them told the others), and those it lacks go."""
        try:
            k, front = books.addressee(data)
        except ValueError as exc:
            log.warning("fabric_books_refused", front=self.front.k, error=str(exc))
            return
        if front != self.front.k or k not in self._asked:  # (another front-end's: its body stays packed)
            return
        self._asked.pop(k, None)  # answered: the sync before it was taken, refused or not (on main a
        self._unknown.pop(k, None)  # refused answer left the ask, and sync and replay went every 32 s)
        self._resubscribe()  # its blocks no client watches: heard no more
        try:
            msg = books.decode_answer(data)
        except ValueError as exc:  # (its key pulses ask again if the books differ from the shard's)
            log.warning("fabric_books_refused", front=self.front.k, shard=k, error=str(exc))
            return
        m = self.server.world.manager
        assert m is not None
        heard = [at > -math.inf for at in self.heard_at]
        learned = books.stand_ins(msg["soldiers"], k, self.shards, heard, msg["homes"])
        for home, stand_in in learned.items():
            self.route[home] = stand_in  # failed over before this front-end started
            log.warning("fabric_stand_in_learned", shard=home, to=stand_in)
        live = m.table.live
        mine = {s[0]: s for s in _soldiers(self.server, live)}
        scope = books.answer_scope(live, self.route, k, list(learned))
        drop, add = books.reconcile(mine, scope, msg["soldiers"], set(np.flatnonzero(self.known).tolist()))
        for i in drop:
            self._let_go(i, f"not in shard {k}")
        for i, figure, weapon, owner in add:
            try:
                self._kept(i, figure, weapon, owner)
            except (ValueError, KeyError) as exc:
                log.warning("fabric_books_failed", front=self.front.k, soldier=i, error=str(exc))
        if len(msg["gens"]) == len(msg["soldiers"]):  # its soldiers' generations, if newer
            idx = np.array([s[0] for s in msg["soldiers"]], np.int64)
            np.maximum.at(self.gen, idx, np.array(msg["gens"], np.int64))
        last = books.learned_last(msg["rows"], m.table.alive, self.has_last)
        self.last[last["index"]] = last  # what a fail-over of this front-end hands on
        self.has_last[last["index"]] = True
        log.info("fabric_books_learned", front=self.front.k, shard=k, dropped=len(drop), learned=len(add))
        if isinstance(msg.get("settings"), dict):  # an operator's change made before it started
            self._settings_learned(msg["settings"], shared.stamp_of(msg))
        if self.elsewhere is not None:  # soldiers of ids gone while it was away: their grace starts now
            self.server.orphans_check()

    def _shard_of(self, index: int) -> int:
        return self.route[int(Sharding.home(index, self.shards))]

    # -- the world's Relay ---------------------------------------------------------------------------------
    def allot(self, index: int | None) -> int | None:
        unknown = set().union(*self._unknown.values())  # live in a shard that has not answered yet
        if unknown and (index in unknown or (index is None and self.share is None)):
            raise ValueError("front-end still learning the soldiers from the shards")
        if self.share is None:
            return index
        m = self.server.world.manager
        live = m.table.is_live if m is not None else lambda i: False
        return self.share.allot(index, lambda i: live(i) or i in unknown)

    def created(self, index: int, figure: str, weapon: str, owner: str | None) -> None:
        self._touch(index)
        self.has_last[index] = False
        self.made[index] = True
        self.watching.forget(index)
        if self.share is not None:
            self.share.taken(index)
        self.gen[index] = after(int(self.gen[index]))
        op = req.create(index, figure, weapon, owner, int(self.gen[index]))
        self._send(self._shard_of(index), op)
        self._book_fenced(op, index)

    def removed(self, index: int) -> None:
        self._touch(index)
        self.has_last[index] = self.made[index] = False
        self.watching.forget(index)
        if self.share is not None:
            self.share.freed(index)
        self.gen[index] = after(int(self.gen[index]))
        op = req.remove(index, int(self.gen[index]))
        self._send(self._shard_of(index), op)
        self._book_fenced(op, index)

    def requests(self, rows: np.ndarray) -> None:
        idx = rows["index"].astype(np.int64)
        if TRACE is not None:
            TRACE.stamp("fe_request", idx)
        self.last[idx] = rows
        self.has_last[idx] = True
        shard = np.asarray(self.route)[Sharding.home(idx, self.shards)]
        for k in np.unique(shard).tolist():
            self._send(k, req.requests(rows[shard == k]))

    def react(self, index: int, kind: str) -> None:
        self._send(self._shard_of(index), req.react(index, kind))


def _soldiers(server: TtesServer, indices: np.ndarray) -> list[Soldier]:
    """(index, figure, weapon, owner) of each of ``indices`` (live soldiers): what a sync or books carries."""
    m = server.world.manager
    assert m is not None
    keys, owners = m.library.set_keys, server.world.owners
    return [(i, *keys[int(m.table.fset[i])], owners.owner_of(i)) for i in np.asarray(indices).tolist()]


def _request_indices(ops: list[req.Op]) -> list[int]:
    """The soldiers the entity requests among ``ops`` are for (a trace's stamps)."""
    rows = [
        np.frombuffer(op["rows"], ENTITY_REQUEST_DTYPE) if isinstance(op["rows"], bytes) else op["rows"]
        for op in ops
        if op["op"] == "requests"
    ]
    return np.concatenate([r["index"] for r in rows]).tolist() if rows else []


def merge(
    board: PoseBoard, batches: list[Batch], tick: int, alive: np.ndarray, watch: Watch | None = None
) -> int:
    """Merge shards' batches (each shard's in the order sent) into ``board`` as one publish labelled
    ``tick``: per shard and block from its newest key batch on (a key holds every soldier it animates
    there), the newest codes of each soldier, of the soldiers still ``alive`` here (not removed meanwhile);
    with ``watch``, only of the soldiers a client watches (``watch`` keeps the others'). Returns the
    soldiers whose codes changed (``PoseBoard.publish_codes``; none without batches: no publish)."""
    if not batches:
        return 0
    start = {(b.shard, b.block): i for i, b in enumerate(batches) if b.key}  # each stream's newest key
    used = [b for i, b in enumerate(batches) if i >= start.get((b.shard, b.block), 0)]  # in arrival order
    streams = {(b.shard, b.block) for b in used}
    # a later batch wins for the rows both carry: a stream's batches, or a shard's WHOLE beside its blocks
    # (a front-end that changed from one to the other)
    whole = {k for k, s in streams if s == WHOLE}
    again = len(used) > len(streams) or any(s != WHOLE and k in whole for k, s in streams)
    if watch is not None:
        used = [watch.split(b) for b in used]
    rows = np.concatenate([b.indices for b in used]).astype(np.int64)
    # one batch (a shard's tick): its tables and uint16 codes as they came, read-only views of its bytes
    tables = used[0].tables if len(used) == 1 else np.concatenate([b.tables for b in used])
    codes = used[0].codes if len(used) == 1 else np.concatenate([b.codes for b in used])
    if again:
        _, first = np.unique(rows[::-1], return_index=True)
        newest = len(rows) - 1 - first
        rows, tables, codes = rows[newest], tables[newest], codes[newest]
    live = (rows < len(alive)) & alive[np.minimum(rows, len(alive) - 1)]
    if not live.all():
        rows, tables, codes = rows[live], tables[live], codes[live]
    return board.publish_codes(rows, tables, codes, tick)
