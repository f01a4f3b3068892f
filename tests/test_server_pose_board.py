"""The shared pose board: poses quantised once per tick, versions bumped only for changed codes, so idle
soldiers cost a client no encoder work, and every client gets exactly the bytes the per-client float path
(``Connection.send(JointUpdates)``) would have produced."""

from __future__ import annotations

from typing import Any

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from test_server_support import make_server

from protocol.connection import CLIENT, NEED_DATA, PAUSED, SERVER, Connection
from protocol.entity import Appearance, make_entity_requests
from protocol.events import Accept, ConnectionClosed, Error, Hello, JointUpdates, Subscribe, UpdateTableMsg
from protocol.updates import UpdateEncoder, quantise
from server.app import TtesServer
from server.session import Session


class Pair:
    """A session and its client, wired without sockets; ``shadow`` is a server connection fed the same
    client bytes that encodes from the board's floats (the path sessions used before the shared codes)."""

    def __init__(self, server: TtesServer, name: str) -> None:
        self.server = server
        self.session = Session(server.world, server.board_ref, server.config, name)
        server.sessions[self.session.id] = self.session
        cfg = server.config
        self.client = Connection(CLIENT)
        self.shadow = Connection(SERVER, max_frame=cfg.max_frame, max_soldiers=cfg.max_soldiers)
        self.to_server(self.client.send(Hello(name, "observer")))
        self.shadow.send(Accept(cfg.name, cfg.max_frame, cfg.max_soldiers))
        for t in server.world.tables:
            self.shadow.send(UpdateTableMsg(t))
        self.updates: list[JointUpdates] = []
        self.flush()

    def to_server(self, data: bytes) -> None:
        self.session.feed(data)
        self.shadow.receive_data(data)
        while (ev := self.shadow.next_event()) is not NEED_DATA and ev is not PAUSED:
            pass

    def subscribe(self, indices: tuple[int, ...]) -> None:
        self.to_server(self.client.send(Subscribe(indices)))

    def flush(self) -> bytes:
        """The session's output, decoded by the client; returns the joint-update bytes of it."""
        data = self.session.take_output()
        if not data:
            return data  # (b"" would mean EOF to the client)
        self.client.receive_data(data)
        while (ev := self.client.next_event()) is not NEED_DATA and ev is not PAUSED:
            if isinstance(ev, JointUpdates):
                self.updates.append(ev)
            assert not isinstance(ev, (ConnectionClosed, Error)), ev
        return data

    def expected(self) -> bytes:
        """What the float path sends now: every valid subscribed soldier, diffed against this client."""
        board = self.server.board_ref.board
        assert board is not None
        sub = self.shadow.subscribed
        rows = sub[board.valid[sub]]
        return self.shadow.send(
            JointUpdates(
                1, rows, board.dofs[rows], board.positions[rows], board.orientations[rows], board.tick
            )
        )


def spy_encoder(session: Session, table: int = 1) -> list[np.ndarray]:
    """Record the soldier rows every ``encode_codes`` call of this session's encoder is given."""
    enc: UpdateEncoder = session.conn._encoders[table]
    calls: list[np.ndarray] = []
    plain = enc.encode_codes

    def encode_codes(
        indices: np.ndarray, codes: np.ndarray, tick: int, max_payload: int, version: object = None
    ) -> Any:
        calls.append(np.asarray(indices).copy())
        return plain(indices, codes, tick, max_payload, version)

    enc.encode_codes = encode_codes  # type: ignore[method-assign]
    return calls


def walk(server: TtesServer, indices: list[int], speed: float = 1.4) -> None:
    m = server.world.manager
    assert m is not None
    n = len(indices)
    vel = np.tile([0.0, speed, 0.0], (n, 1))
    rows = make_entity_requests(np.array(indices), [int(Appearance.UPRIGHT)] * n, [1] * n, vel, [0.0] * n)
    m.apply_requests(rows, server.request_time())


def test_unchanged_codes_keep_their_version_and_cost_no_encoder_work() -> None:
    server = make_server(throttle=0.0)
    server.start_world()
    ticks: list[Any] = []
    server.on_tick = ticks.append
    a = Pair(server, "a")
    a.subscribe(tuple(range(10)))
    server.tick(1 / 30)
    want = a.expected()
    assert a.flush() == want
    board = server.board_ref.board
    assert board is not None
    assert sorted({int(i) for u in a.updates for i in u.indices}) == list(range(10))
    calls = spy_encoder(a.session)
    version = board.version.copy()
    # the manager hands the same (resting) poses in again: new board ticks, no changed codes
    for _ in range(3):
        assert board.publish(ticks[0], server.world) == 0
    np.testing.assert_array_equal(board.version, version)
    assert a.flush() == b"" and calls == []
    # one soldier walks: only it reaches the encoder, and the bytes are the float path's
    walk(server, [3])
    for k in range(2, 8):
        server.tick(k / 30)
        want = a.expected()
        assert a.flush() == want
    assert calls and all(c.tolist() == [3] for c in calls)
    assert board.rows_changed < board.rows_published


def test_two_clients_get_identical_correct_poses_and_the_float_paths_bytes() -> None:
    server = make_server(throttle=0.0)
    server.start_world()
    a, b = Pair(server, "a"), Pair(server, "b")
    a.subscribe(tuple(range(10)))
    b.subscribe(tuple(range(0, 10, 2)))
    walk(server, [0, 1, 2, 5, 8], 1.4)
    walk(server, [4], 4.0)
    board = server.board_ref.board
    assert board is not None
    for k in range(1, 40):
        server.tick(k / 30)
        if k == 20:
            b.subscribe(tuple(range(10)))  # late: b's first updates of the odd soldiers are full
        want_a = a.expected()
        assert a.flush() == want_a
        if k % 3 == 0:  # b reads every third tick only: deltas span skipped ticks
            want_b = b.expected()
            assert b.flush() == want_b
    want_b = b.expected()
    assert b.flush() == want_b
    idx = np.arange(10)
    table = server.world.sets[0].table
    truth = quantise(table, board.dofs[idx], board.positions[idx], board.orientations[idx])
    np.testing.assert_array_equal(board.codes[idx], truth)
    for p in (a, b):
        dec = p.client.decoder(1)
        assert dec is not None and dec.known(idx).all()
        np.testing.assert_array_equal(dec.codes(idx), truth)
    dofs_a = a.client.decoder(1).current(idx)[0]  # type: ignore[union-attr]
    np.testing.assert_allclose(dofs_a, board.dofs[idx], atol=2 * np.pi / 4096)
    assert len(b.updates) < len(a.updates)


def test_clients_share_encodes_and_each_gets_the_float_paths_bytes() -> None:
    """Issue 18: clients joining at different ticks with different subscriptions each get exactly the
    per-client bytes, while clients in one delta state share one encode (the server's memo hits)."""
    server = make_server(throttle=0.0)
    server.start_world()
    walk(server, [0, 1, 2, 5, 8], 1.4)
    walk(server, [4], 4.0)
    pairs: list[Pair] = []
    subs = [tuple(range(10)), tuple(range(10)), tuple(range(0, 10, 2)), tuple(range(10))]
    for k in range(1, 30):
        if k in (1, 2, 9, 15):  # joins: two together, two late
            p = Pair(server, f"c{k}")
            p.subscribe(subs[len(pairs)])
            pairs.append(p)
        server.tick(k / 30)
        for j, p in enumerate(pairs):
            if j == 2 and k % 4:
                continue  # a lagging reader
            want = p.expected()
            assert p.flush() == want
    encodes = server.board_ref.encodes
    assert encodes.hits > encodes.misses, (encodes.hits, encodes.misses)
    states = [p.session.conn._encoders[1].state for p in pairs]
    assert states[0] == states[1] == states[3] != states[2]  # the late joiner joined after its keyframe


def test_clients_that_watch_their_own_soldiers_never_share_an_encode() -> None:
    """Issue 21's bench: each load client watches the soldiers it made, so no two encoders get the same rows:
    the memo only misses, and the status line's counts (``shared_encodes``) say so, with the rows diffed."""
    server = make_server(throttle=0.0)
    server.start_world()
    walk(server, list(range(10)), 1.4)
    pairs = [Pair(server, "a"), Pair(server, "b")]
    pairs[0].subscribe(tuple(range(0, 10, 2)))
    pairs[1].subscribe(tuple(range(1, 10, 2)))
    rows = 0
    for k in range(1, 10):
        server.tick(k / 30)
        for p in pairs:
            before = len(p.updates)
            p.flush()
            rows += sum(len(u.indices) for u in p.updates[before:])
    encodes = server.board_ref.encodes
    assert encodes.hits == 0 and encodes.misses >= 2 * 9
    assert encodes.rows_encoded >= rows > 0  # (an encode's rows: those sent and the unchanged ones given)
    counts = server._encode_counts()["shared_encodes"]
    assert counts == f"hits:0,own:{encodes.misses},caught_up:0,rows:{encodes.rows_encoded}"


def test_a_fed_publish_labels_its_rows_with_the_tick_it_names() -> None:
    """A front-end's board (``publish_codes``, no tick loop of its own) labels what it sends with the tick
    each publish names, not one more (``PoseBoard.labels``)."""
    from server.pose_board import PoseBoard

    board = PoseBoard(4, 2)
    board.publish_codes(np.array([0, 1]), np.array([1, 1]), np.zeros((2, 3), np.int32), 7)
    assert board.labels(np.array([0, 1])).tolist() == [7, 7]
    board.publish_codes(np.array([1]), np.array([1]), np.ones((1, 3), np.int32), 8)
    assert board.labels(np.array([0, 1])).tolist() == [8, 8]


def test_a_board_fed_16_bit_codes_keeps_them_as_uint16_until_a_wider_code() -> None:
    """A front-end's board keeps its batches' uint16 codes as they came (half the bytes of its merges and
    gathers); codes past 16 bits (no batch carries them) turn it to int32 with every code kept."""
    from server.pose_board import PoseBoard

    board = PoseBoard(4, 2)
    board.publish_codes(np.arange(3), np.ones(3), np.arange(9, dtype=np.uint16).reshape(3, 3), 1)
    assert board.codes.dtype == np.uint16 and board.codes_of(np.array([2])).dtype == np.uint16
    assert (
        board.publish_codes(np.array([0, 1]), np.ones(2), np.array([[0, 1, 2], [3, 4, 6]], np.int32), 2) == 1
    )
    assert board.codes.dtype == np.uint16 and board.version[:3].tolist() == [1, 2, 1]
    board.publish_codes(np.array([2]), np.ones(1), np.full((1, 3), 70_000, np.int32), 3)
    assert board.codes.dtype == np.int32
    assert board.codes[:3].tolist() == [[0, 1, 2], [3, 4, 6], [70_000] * 3]


def test_sessions_asking_for_the_same_rows_share_one_gather_of_the_codes() -> None:
    """``codes_of``: one read-only gather per publish for equal rows (the clients of one group); other rows
    or a new publish gather again."""
    from server.pose_board import PoseBoard

    board = PoseBoard(4, 2)
    board.publish_codes(np.arange(3), np.ones(3), np.arange(9, dtype=np.int32).reshape(3, 3), 1)
    first = board.codes_of(np.array([0, 2]))
    assert board.codes_of(np.array([0, 2])) is first and not first.flags.writeable
    assert first.tolist() == [[0, 1, 2], [6, 7, 8]]
    assert board.codes_of(np.array([1])).tolist() == [[3, 4, 5]]
    board.publish_codes(np.array([0]), np.ones(1), np.full((1, 3), 5, np.int32), 2)
    assert board.codes_of(np.array([0, 2])).tolist() == [[5, 5, 5], [6, 7, 8]]


def assert_decode_the_board(server: TtesServer, *pairs: Pair) -> None:
    """Each client's decoder holds exactly the board's codes for soldiers 0-9."""
    board = server.board_ref.board
    assert board is not None
    idx = np.arange(10)
    for p in pairs:
        dec = p.client.decoder(1)
        assert dec is not None
        np.testing.assert_array_equal(dec.codes(idx), board.codes[idx])


def _two_watching_ten_walkers() -> tuple[TtesServer, Pair, Pair]:
    """A server with soldiers 0-9 walking, and two observers subscribed to all of them."""
    server = make_server(throttle=0.0)
    server.start_world()
    walk(server, list(range(10)), 1.4)
    a, b = Pair(server, "a"), Pair(server, "b")
    a.subscribe(tuple(range(10)))
    b.subscribe(tuple(range(10)))
    return server, a, b


def test_a_late_writer_catches_up_through_its_groups_frames() -> None:
    """Issue 18's spiral: a writer that missed publishes sends the frames its group got for them (from the
    memo, ticks in order) and the newest publish's shared encode, never an encode of its own; a client
    whose throttle skips ticks on purpose is not late: it gets one encode spanning them."""
    server, a, b = _two_watching_ten_walkers()
    encodes = server.board_ref.encodes
    assert encodes is not None
    sent: dict[int, bytes] = {}
    calls = spy_encoder(b.session)
    last = 0
    for k in range(1, 13):
        server.tick(k / 30)
        sent[k] = a.flush()
        if k == 1 or k % 3 == 0:  # b misses one publish, then two at a time
            misses = encodes.misses
            assert b.flush() == b"".join(sent[j] for j in range(last + 1, k + 1))
            assert encodes.misses == misses
            last = k
    assert encodes.caught_up == 1 + 2 * 3 and len(calls) == 1  # b encoded at tick 1 only: then memo frames
    assert_decode_the_board(server, a, b)
    idx = np.arange(10)
    board = server.board_ref.board
    assert board is not None
    b.session.throttle = 0.1  # b asks for 10 updates a second: skipped ticks are its choice
    server.tick(13 / 30)
    a.flush()
    server.tick(14 / 30)
    a.flush()
    caught = encodes.caught_up
    assert b.flush() and encodes.caught_up == caught and len(calls) == 2
    np.testing.assert_array_equal(b.client.decoder(1).codes(idx), board.codes[idx])  # type: ignore[union-attr]


def test_a_late_writer_with_answers_between_ticks_decodes_the_board_in_tick_order() -> None:
    """The catch-up through the memo (issue 18) and the answers between ticks (issue 16, rows labelled with
    the next tick) together: a writer reading every third tick, while soldiers are answered between ticks,
    still decodes exactly the board's codes, and the ticks it receives never go backwards."""
    server, a, b = _two_watching_ten_walkers()
    m = server.world.manager
    assert m is not None
    for k in range(1, 16):
        server.tick(k / 30)
        a.flush()
        if k == 1 or k % 3 == 0:  # b joins a's group at tick 1, then misses publishes
            b.flush()
            assert_decode_the_board(server, a, b)
        if k % 2 == 0:  # between this tick and the next: soldier k % 10 kneels, answered at once
            i = k % 10
            kneel = make_entity_requests(np.array([i]), [int(Appearance.KNEEL)], [1], np.zeros((1, 3)), [0.0])
            m.apply_requests(kneel, server.request_time())
            server.answer_requests()
            a.flush()
    encodes = server.board_ref.encodes
    assert encodes is not None
    assert server.answers > 0 and encodes.caught_up > 0  # both paths were taken
    for p in (a, b):
        ticks = [u.tick for u in p.updates]
        assert ticks == sorted(ticks), ticks


def test_a_codes_only_board_sends_every_client_the_same_bytes() -> None:
    """A shard's board keeps the codes alone (``TtesServer.codes_only``: no float poses written at each
    publish, issue 21): the same ticks give the same codes, versions and client bytes as a board that keeps
    the poses, from before the board exists or switched after."""
    servers = [make_server(throttle=0.0) for _ in range(3)]
    servers[1].codes_only()  # before the world: the board is made without poses
    for s in servers:
        s.start_world()
        walk(s, [0, 1, 2, 5, 8], 1.4)
        walk(s, [4], 4.0)
    servers[2].codes_only()  # after: the board drops its poses
    pairs = [Pair(s, "a") for s in servers]
    for p in pairs:
        p.subscribe(tuple(range(10)))
    for k in range(1, 25):
        for s in servers:
            s.tick(k / 30)
        sent = [p.flush() for p in pairs]
        assert sent[0] and sent[1] == sent[0] and sent[2] == sent[0]
    boards = [s.board_ref.board for s in servers]
    keep, *bare = boards
    assert keep is not None and len(keep.dofs) >= 10
    for b in bare:
        assert b is not None and not b.poses and len(b.dofs) == len(b.positions) == len(b.orientations) == 0
        for name in ("codes", "version", "valid", "table_of"):
            np.testing.assert_array_equal(getattr(b, name)[:10], getattr(keep, name)[:10])


@settings(max_examples=60, deadline=None)
@given(n=st.integers(0, 40), width=st.integers(1, 70), seed=st.integers(0, 2**32 - 1))
def test_rows_differ_is_any_of_the_rows_comparisons(n: int, width: int, seed: int) -> None:
    """``_rows_differ`` (the board's changed-codes test, word by word) is ``(a != b).any(axis=1)``, for any
    field count (a multiple of 8 or not) and rows that differ in one field, several or none."""
    from server.pose_board import _rows_differ

    rng = np.random.default_rng(seed)
    a = rng.integers(0, 4, (n, width)).astype(np.int32)
    b = a.copy()
    hit = rng.random((n, width)) < rng.choice([0.0, 0.02, 0.5])
    b[hit] += 1
    np.testing.assert_array_equal(_rows_differ(a, b), (a != b).any(axis=1))


def test_codes_of_one_table_or_several_are_stored_alike() -> None:
    """``publish_codes``: a batch of one update table (stored whole) and one of two tables (stored table by
    table) take the same codes, tables and versions."""
    from server.pose_board import PoseBoard

    rows = np.array([3, 0, 5, 2])
    codes = np.arange(4 * 9, dtype=np.int32).reshape(4, 9)
    one, two = PoseBoard(4, 2), PoseBoard(4, 2)
    assert one.publish_codes(rows, np.array([1, 1, 1, 1]), codes, 7) == 4
    assert two.publish_codes(rows, np.array([1, 2, 1, 2]), codes, 7) == 4
    np.testing.assert_array_equal(one.codes[rows], codes)
    np.testing.assert_array_equal(two.codes[rows], codes)
    assert two.table_of[rows].tolist() == [1, 2, 1, 2] and one.table_of[rows].tolist() == [1] * 4
    codes[2, 8] += 1  # soldier 5 moved; soldier 2 changes table on ``one``
    assert one.publish_codes(rows, np.array([1, 1, 1, 2]), codes, 8) == 2
    assert two.publish_codes(rows, np.array([1, 2, 1, 2]), codes, 8) == 1
    assert one.version[rows].tolist() == [1, 1, 2, 2] and two.version[rows].tolist() == [1, 1, 2, 1]
