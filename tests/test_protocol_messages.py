"""TTES wire protocol: messages round-trip; handshake and state machine; bad input → ProtocolError."""

from __future__ import annotations

import math
import struct

import msgpack
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from protocol.connection import CLIENT, NEED_DATA, PAUSED, SERVER, Connection, State
from protocol.entity import ENTITY_REQUEST_DTYPE, Reaction, make_entity_requests
from protocol.errors import ErrorCode, LocalProtocolError, WireError
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
    JointUpdates,
    Ping,
    Pong,
    ProtocolError,
    React,
    Ready,
    RemoveSoldier,
    RequestFullUpdate,
    Settings,
    SoldierCreated,
    SoldierRemoved,
    Status,
    Subscribe,
    Unsubscribe,
    UpdateTableMsg,
)
from protocol.framing import HANDSHAKE_MAX_FRAME, MIN_CLIENT_MAX_FRAME, encode_frame
from protocol.messages import CODECS, HANDSHAKE_PREFIX, MAGIC, MessageType
from protocol.update_table import DofRange, FigureEntry, JointEntry, UpdateTable, example_di_table

MAX_SOLDIERS = 64


def drain(conn: Connection) -> list[Event]:
    out: list[Event] = []
    while True:
        ev = conn.next_event()
        if ev is NEED_DATA or ev is PAUSED or isinstance(ev, ConnectionClosed):
            return out
        out.append(ev)


def deliver(dst: Connection, data: bytes) -> list[Event]:
    dst.receive_data(data)
    return drain(dst)


def open_pair(max_soldiers: int = MAX_SOLDIERS) -> tuple[Connection, Connection]:
    client, server = Connection(CLIENT), Connection(SERVER, max_soldiers=max_soldiers)
    assert deliver(server, client.send(Hello("stub"))) == [Hello("stub")]
    assert deliver(client, server.send(Accept("jack", max_soldiers=max_soldiers))) == [
        Accept("jack", max_soldiers=max_soldiers)
    ]
    assert client.state is State.OPEN and server.state is State.OPEN
    return client, server


def expect_protocol_error(conn: Connection, data: bytes, code: ErrorCode) -> ProtocolError:
    events = deliver(conn, data)
    assert events and isinstance(events[-1], ProtocolError), events
    err = events[-1]
    assert err.code == code, err
    assert conn.state is State.ERROR
    # the connection queued an Error frame for the peer, readable by a fresh connection's codec
    out = conn.data_to_send()
    assert out[4] == MessageType.ERROR
    body = msgpack.unpackb(out[5:])
    assert body["code"] == code and body["message"]
    assert isinstance(conn.next_event(), ConnectionClosed)
    return err


# -- strategies ---------------------------------------------------------------------------------------------

names = st.text(min_size=1, max_size=24)
u32 = st.integers(0, 2**32 - 1)
index = st.integers(0, MAX_SOLDIERS - 1)
finite = st.floats(allow_nan=False, allow_infinity=False, width=64)
indices = st.lists(index, max_size=20).map(tuple)

client_events = st.one_of(
    st.builds(Jcl, st.text(max_size=200), u32),
    st.builds(CreateSoldier, u32, names, st.text(max_size=20), st.none() | index),
    st.builds(RemoveSoldier, index),
    st.builds(Subscribe, indices),
    st.builds(Unsubscribe, indices),
    st.builds(RequestFullUpdate, indices),
    st.builds(React, st.sampled_from([int(r) for r in Reaction]), indices),
)
both_events = st.one_of(
    st.builds(Ping, st.integers(0, 2**64 - 1)),
    st.builds(Pong, st.integers(0, 2**64 - 1)),
    st.builds(Error, st.integers(100, 0xFFFF), st.text(max_size=80), st.none() | u32),
)


@st.composite
def tables(draw: st.DrawFn) -> UpdateTable:
    def dof() -> DofRange:
        lo = draw(st.floats(-10, 10))
        hi = lo + draw(st.floats(0.01, 10))
        return DofRange(draw(st.sampled_from(["R", "T"])), lo, hi, draw(st.integers(1, 16)))

    entries = []
    for i in range(draw(st.integers(1, 6))):
        if draw(st.booleans()):
            entries.append(JointEntry(f"j{i}", tuple(dof() for _ in range(draw(st.integers(1, 4))))))
        else:
            lo = draw(st.floats(-100, 0))
            entries.append(
                FigureEntry(
                    f"f{i}",
                    lo,
                    lo + draw(st.floats(0.5, 100)),
                    draw(st.integers(1, 24)),
                    draw(st.integers(2, 16)),
                )
            )
    return UpdateTable(draw(st.integers(0, 0xFFFF)), draw(names), draw(st.text(max_size=12)), tuple(entries))


@st.composite
def entity_rows(draw: st.DrawFn) -> np.ndarray:
    n = draw(st.integers(0, 12))
    f32 = st.floats(-1e6, 1e6, allow_nan=False, width=32)
    return make_entity_requests(
        draw(st.lists(index, min_size=n, max_size=n)) if n else np.zeros(0, int),
        draw(st.lists(st.integers(1, 5), min_size=n, max_size=n)) if n else 2,
        draw(st.lists(st.integers(0, 2), min_size=n, max_size=n)) if n else 1,
        draw(st.lists(st.tuples(f32, f32, f32), min_size=n, max_size=n)) if n else (0, 0, 0),
        draw(st.lists(f32, min_size=n, max_size=n)) if n else 0.0,
        draw(st.lists(st.tuples(f32, f32, f32), min_size=n, max_size=n)) if n else (0, 0, 0),
        draw(st.lists(st.booleans(), min_size=n, max_size=n)) if n else False,
    )


# -- round trips --------------------------------------------------------------------------------------------


@given(st.one_of(client_events, both_events))
def test_client_messages_round_trip(event: Event) -> None:
    client, server = open_pair()
    assert deliver(server, client.send(event)) == [event]
    assert server.state is State.OPEN


@given(
    st.one_of(
        both_events,
        st.builds(Status, finite, st.integers(0, 2**32 - 1), st.floats(0, 1e9), st.text(max_size=50)),
    )
)
def test_server_messages_round_trip(event: Event) -> None:
    client, server = open_pair()
    assert deliver(client, server.send(event)) == [event]
    assert client.state is State.OPEN


@given(tables(), u32, index, st.lists(index, max_size=10))
def test_update_table_round_trips_and_enables_references(
    table: UpdateTable, rid: int, created: int, ready: list[int]
) -> None:
    client, server = open_pair()
    assert deliver(client, server.send(UpdateTableMsg(table))) == [UpdateTableMsg(table)]
    tid = table.table_id
    assert deliver(client, server.send(SoldierCreated(rid, created, tid))) == [
        SoldierCreated(rid, created, tid)
    ]
    pairs = tuple((i, tid) for i in ready)
    assert deliver(client, server.send(Ready(pairs))) == [Ready(pairs)]


@given(
    st.floats(1e-3, 1e3, allow_nan=False, allow_infinity=False),
    st.floats(0.0, 60.0, allow_nan=False, allow_infinity=False),
)
def test_ready_carries_the_tick_rate_and_throttle(tick_hz: float, throttle: float) -> None:
    client, server = open_pair()
    assert deliver(client, server.send(Ready((), tick_hz, throttle))) == [Ready((), tick_hz, throttle)]


_NOT_A_RATE = st.sampled_from([0, 0.0, -1.0, math.nan, math.inf, True, "30", None, [30.0]])


@given(st.sampled_from(["tick_hz", "throttle"]), _NOT_A_RATE | st.floats(max_value=-1e-300) | st.just("gone"))
def test_ready_decoder_rejects_bad_rates_with_a_wire_error(key: str, value: object) -> None:
    """Any bad ``tick_hz``/``throttle`` (missing, wrong type, not finite, out of range) is a WireError (SCHEMA
    or BAD_VALUE), never another exception; zero is a fine throttle but not a tick rate."""
    body = {"soldiers": [[0, 1]], "tick_hz": 30.0, "throttle": 0.04}
    if value == "gone":
        del body[key]
    else:
        body[key] = value
    decode = CODECS[MessageType.READY][2]
    if key == "throttle" and value in (0, 0.0):
        assert decode(msgpack.packb(body), 16).throttle == 0.0
        return
    with pytest.raises(WireError) as info:
        decode(msgpack.packb(body), 16)
    assert info.value.code in (ErrorCode.SCHEMA, ErrorCode.BAD_VALUE)


def test_a_ready_with_no_tick_rate_is_never_sent() -> None:
    _, server = open_pair()
    with pytest.raises(LocalProtocolError):  # the codec table's self-check: encode, then decode our bytes
        server.send(Ready((), 0.0, 0.04))


@given(st.text(max_size=100), st.booleans())
def test_goodbye_round_trips_either_way(reason: str, from_client: bool) -> None:
    client, server = open_pair()
    src, dst = (client, server) if from_client else (server, client)
    assert deliver(dst, src.send(Goodbye(reason))) == [Goodbye(reason)]
    assert src.state is State.CLOSED and dst.state is State.CLOSED


@given(entity_rows())
def test_entity_requests_round_trip(rows: np.ndarray) -> None:
    client, server = open_pair()
    (ev,) = deliver(server, client.send(EntityRequests(rows)))
    assert isinstance(ev, EntityRequests)
    assert ev.rows.dtype == ENTITY_REQUEST_DTYPE
    assert ev.rows.tobytes() == rows.tobytes()


@given(names, st.sampled_from(["controller", "observer"]), st.integers(MIN_CLIENT_MAX_FRAME, 2**32 - 1))
def test_handshake_round_trip(name: str, role: str, max_frame: int) -> None:
    client, server = Connection(CLIENT), Connection(SERVER)
    assert deliver(server, client.send(Hello(name, role, max_frame))) == [Hello(name, role, max_frame)]
    assert server.peer_max_frame == max_frame
    assert server.next_event() is PAUSED  # the server answers before reading on
    assert deliver(client, server.send(Accept("jack", 4096, 10))) == [Accept("jack", 4096, 10)]
    assert client.max_soldiers == 10 and client.peer_max_frame == 4096


@given(st.sampled_from(["", "stub-1", "x" * 64]), st.sampled_from(["", "tok"]), st.sampled_from(ROLES))
def test_handshake_identity_round_trip(client_id: str, token: str, role: str) -> None:
    """Issue 17: HELLO's optional client_id and token, ACCEPT's granted id and role."""
    client, server = Connection(CLIENT), Connection(SERVER)
    hello = Hello("ig", role, client_id=client_id, token=token)
    assert deliver(server, client.send(hello)) == [hello]
    accept = Accept("jack", client_id=client_id or "~anon-1", role=role)
    assert deliver(client, server.send(accept)) == [accept]


def test_hello_without_the_identity_fields_is_anonymous_and_bad_ids_are_refused() -> None:
    old = HANDSHAKE_PREFIX.pack(MAGIC, 1) + msgpack.packb(
        {"name": "1994", "role": "controller", "max_frame": 65536}
    )
    (ev,) = deliver(Connection(SERVER), encode_frame(MessageType.HELLO, old))
    assert ev == Hello("1994", "controller", 65536, version=1)
    for bad in ("~anon-1", "x" * 65, "tab\t"):
        body = {"name": "n", "role": "controller", "max_frame": 65536, "client_id": bad}
        frame = encode_frame(MessageType.HELLO, HANDSHAKE_PREFIX.pack(MAGIC, 1) + msgpack.packb(body))
        (err,) = deliver(Connection(SERVER), frame)
        assert isinstance(err, ProtocolError) and err.code == ErrorCode.BAD_VALUE


def test_settings_and_soldier_removed_round_trip() -> None:
    client, server = open_pair()
    for ev in (Settings(0.04, 0.5), SoldierRemoved(7, "owner gone")):
        assert deliver(client, server.send(ev)) == [ev]


def test_entity_request_batches_split_to_the_peers_frame_limit() -> None:
    client, server = Connection(CLIENT), Connection(SERVER, max_frame=1024)
    deliver(server, client.send(Hello("stub")))
    deliver(client, server.send(Accept("jack", max_frame=1024)))
    rows = make_entity_requests(np.arange(100) % MAX_SOLDIERS, velocity=(1.0, 2.0, 0.0))
    data = client.send(EntityRequests(rows))
    events = deliver(server, data)
    assert len(events) == 4  # 30 rows per 1024-byte frame
    assert np.concatenate([e.rows for e in events]).tobytes() == rows.tobytes()


def test_joint_updates_round_trip_only_for_subscribed_soldiers() -> None:
    client, server = open_pair()
    table = example_di_table()
    deliver(client, server.send(UpdateTableMsg(table)))
    deliver(server, client.send(Subscribe((2, 4))))
    rng = np.random.default_rng(1)
    dofs = rng.uniform(0.0, 0.04, (3, 50))  # inside every DOF's range
    pos = rng.uniform(-1.0, 1.0, (3, 2, 3))
    quat = np.tile([1.0, 0.0, 0.0, 0.0], (3, 2, 1))
    (ev,) = deliver(client, server.send(JointUpdates(1, np.array([4, 3, 2]), dofs, pos, quat, tick=9)))
    assert ev.indices.tolist() == [2, 4] and ev.tick == 9
    assert ev.changed.all()
    np.testing.assert_allclose(ev.dofs, dofs[[2, 0]], atol=table.entries[0].dofs[0].step)
    np.testing.assert_allclose(ev.positions, pos[[2, 0]], atol=0.0006)
    np.testing.assert_allclose(ev.orientations, quat[[2, 0]], atol=1e-3)


# -- handshake and state machine ----------------------------------------------------------------------------


def test_unsupported_version_gets_a_readable_error_frame() -> None:
    server = Connection(SERVER)
    hello = hello_frame(7)
    err = expect_protocol_error(server, hello, ErrorCode.UNSUPPORTED_VERSION)
    assert "version 7" in err.message


def hello_frame(version: int, magic: bytes = MAGIC) -> bytes:
    body = msgpack.packb({"name": "x", "role": "controller", "max_frame": 65536})
    return encode_frame(MessageType.HELLO, magic + struct.pack(">H", version) + body)


def test_client_reads_the_servers_version_error() -> None:
    client, server = Connection(CLIENT), Connection(SERVER)
    client.send(Hello("stub"))
    server.receive_data(hello_frame(9))
    assert isinstance(server.next_event(), ProtocolError)
    (ev,) = deliver(client, server.data_to_send())
    assert isinstance(ev, Error) and ev.code == ErrorCode.UNSUPPORTED_VERSION
    assert client.state is State.ERROR


def test_foreign_bytes_are_rejected() -> None:
    # an HTTP client: "GET " read as a length is far above the handshake limit
    expect_protocol_error(Connection(SERVER), b"GET / HTTP/1.1\r\n\r\n", ErrorCode.FRAME_TOO_LARGE)
    expect_protocol_error(Connection(SERVER), hello_frame(1, b"JACK"), ErrorCode.BAD_MAGIC)


def test_oversize_length_is_rejected_before_the_body_arrives() -> None:
    _, server = open_pair()
    err = expect_protocol_error(
        server, struct.pack(">IB", server.max_frame + 1, MessageType.JCL), ErrorCode.FRAME_TOO_LARGE
    )
    assert str(server.max_frame) in err.message
    assert Connection(SERVER).next_event() is NEED_DATA
    small = Connection(SERVER)
    small.receive_data(struct.pack(">I", HANDSHAKE_MAX_FRAME + 1))
    assert isinstance(small.next_event(), ProtocolError)


def test_truncated_stream_and_clean_eof() -> None:
    client, server = open_pair()
    frame = client.send(Ping(1))
    server.receive_data(frame[:-2])
    assert server.next_event() is NEED_DATA
    server.receive_data(b"")
    ev = server.next_event()
    assert isinstance(ev, ProtocolError) and ev.code == ErrorCode.TRUNCATED
    client2, server2 = open_pair()
    server2.receive_data(client2.send(Ping(2)))
    server2.receive_data(b"")
    assert server2.next_event() == Ping(2)
    assert isinstance(server2.next_event(), ConnectionClosed) and server2.state is State.CLOSED


def test_goodbye_closes_both_sides() -> None:
    client, server = open_pair()
    data = client.send(Goodbye("done"))
    assert client.state is State.CLOSED
    assert deliver(server, data) == [Goodbye("done")]
    assert server.state is State.CLOSED
    with pytest.raises(LocalProtocolError):
        server.send(Ping(1))


def test_goodbye_during_the_handshake() -> None:
    client, server = Connection(CLIENT), Connection(SERVER)
    assert deliver(server, client.send(Goodbye("changed my mind"))) == [Goodbye("changed my mind")]
    assert client.state is State.CLOSED and server.state is State.CLOSED


def test_request_errors_keep_the_connection_open_and_fatal_ones_do_not() -> None:
    client, server = open_pair()
    assert deliver(client, server.send(Error(ErrorCode.UNKNOWN_SOLDIER, "no soldier 5", ref=4))) == [
        Error(100, "no soldier 5", 4)
    ]
    assert client.state is State.OPEN and server.state is State.OPEN
    deliver(client, server.send(Error(ErrorCode.INTERNAL, "bye")))
    assert client.state is State.ERROR and server.state is State.ERROR


@pytest.mark.parametrize(
    ("frame", "code"),
    [
        (encode_frame(0x99, b""), ErrorCode.UNKNOWN_MESSAGE_TYPE),
        (b"\x00\x00\x00\x00", ErrorCode.MALFORMED_FRAME),
        (encode_frame(MessageType.HELLO, b""), ErrorCode.UNEXPECTED_MESSAGE),
        (encode_frame(MessageType.JOINT_UPDATES, b""), ErrorCode.UNEXPECTED_MESSAGE),
        (encode_frame(MessageType.JCL, b"\xc1"), ErrorCode.SCHEMA),
        (encode_frame(MessageType.JCL, msgpack.packb([1, 2])), ErrorCode.SCHEMA),
        (encode_frame(MessageType.JCL, msgpack.packb({"text": 5, "id": 1})), ErrorCode.SCHEMA),
        (encode_frame(MessageType.JCL, msgpack.packb({"text": "x"})), ErrorCode.SCHEMA),
        (encode_frame(MessageType.JCL, msgpack.packb({"text": "x", "id": True})), ErrorCode.SCHEMA),
        (encode_frame(MessageType.JCL, msgpack.packb({"text": "x", "id": -1})), ErrorCode.BAD_VALUE),
        (encode_frame(MessageType.SUBSCRIBE, msgpack.packb({"indices": [1, "2"]})), ErrorCode.SCHEMA),
        (encode_frame(MessageType.SUBSCRIBE, msgpack.packb({"indices": [1, True]})), ErrorCode.SCHEMA),
        (encode_frame(MessageType.SUBSCRIBE, msgpack.packb({"indices": [[1]]})), ErrorCode.SCHEMA),
        (encode_frame(MessageType.SUBSCRIBE, msgpack.packb({"indices": [2**63, -1]})), ErrorCode.SCHEMA),
        (
            encode_frame(MessageType.SUBSCRIBE, msgpack.packb({"indices": [1, MAX_SOLDIERS]})),
            ErrorCode.BAD_VALUE,
        ),
        (encode_frame(MessageType.REMOVE_SOLDIER, msgpack.packb({"index": 1.0})), ErrorCode.SCHEMA),
        (encode_frame(MessageType.PING, msgpack.packb({"nonce": 1}) + b"x"), ErrorCode.SCHEMA),
        (encode_frame(MessageType.ENTITY_REQUESTS, b"\x00"), ErrorCode.MALFORMED_FRAME),
        (encode_frame(MessageType.ENTITY_REQUESTS, b"\x00\x01" + bytes(32)), ErrorCode.MALFORMED_FRAME),
    ],
)
def test_server_rejects_bad_frames(frame: bytes, code: ErrorCode) -> None:
    _, server = open_pair()
    expect_protocol_error(server, frame, code)


def _react_frame(body: object) -> bytes:
    return encode_frame(MessageType.REACT, msgpack.packb(body))


@pytest.mark.parametrize(
    ("body", "code"),
    [
        ({"kind": 3, "indices": [1]}, ErrorCode.BAD_VALUE),
        ({"kind": 0, "indices": [1]}, ErrorCode.BAD_VALUE),
        ({"kind": 1, "indices": [MAX_SOLDIERS]}, ErrorCode.BAD_VALUE),
        ({"kind": 1.0, "indices": [1]}, ErrorCode.SCHEMA),
        ({"kind": True, "indices": [1]}, ErrorCode.SCHEMA),
        ({"kind": 1}, ErrorCode.SCHEMA),
        ({"kind": 2, "indices": 1}, ErrorCode.SCHEMA),
        ([1, [1]], ErrorCode.SCHEMA),
    ],
)
def test_react_decoder_checks_kind_and_indices(body: object, code: ErrorCode) -> None:
    _, server = open_pair()
    expect_protocol_error(server, _react_frame(body), code)


@given(st.integers(-5, 5), st.lists(st.integers(-2, MAX_SOLDIERS + 2), max_size=8), st.booleans())
def test_react_decoder_accepts_exactly_the_documented_bodies(kind: int, idx: list[int], extra: bool) -> None:
    """docs/PROTOCOL.md §5: kind 1 (recoil) or 2 (flinch), indices < max_soldiers, unknown keys ignored."""
    body: dict[str, object] = {"kind": kind, "indices": idx}
    if extra:
        body["later"] = "ignored"
    _, server = open_pair()
    server.receive_data(_react_frame(body))
    got = server.next_event()
    if kind in (1, 2) and all(0 <= i < MAX_SOLDIERS for i in idx):
        assert got == React(kind, tuple(idx))
        assert server.state is State.OPEN
    else:
        assert isinstance(got, ProtocolError)
        assert got.code in (ErrorCode.BAD_VALUE, ErrorCode.SCHEMA)


def _rows_frame(**bad: object) -> bytes:
    rows = make_entity_requests([1, 2, 3], velocity=(1.0, 0.0, 0.0))
    for key, value in bad.items():
        rows[key][2] = value
    return encode_frame(
        MessageType.ENTITY_REQUESTS, CODECS[MessageType.ENTITY_REQUESTS][1](EntityRequests(rows))
    )


@pytest.mark.parametrize(
    "bad",
    [
        {"heading": math.nan},
        {"position": (0.0, math.inf, 0.0)},
        {"appearance": 6},
        {"appearance": 0},
        {"weapon": 3},
        {"immediate": 2},
        {"index": MAX_SOLDIERS},
    ],
)
def test_bad_entity_rows_reject_the_whole_frame_naming_the_row(bad: dict[str, object]) -> None:
    _, server = open_pair()
    err = expect_protocol_error(server, _rows_frame(**bad), ErrorCode.BAD_VALUE)
    assert err.location.endswith("row 2")


def test_client_rejects_updates_for_unknown_tables_and_bad_references() -> None:
    client, server = open_pair()
    deliver(client, server.send(UpdateTableMsg(example_di_table(1))))
    deliver(server, client.send(Subscribe((0,))))
    one = np.zeros((1, 50)), np.zeros((1, 2, 3)), np.tile([1.0, 0, 0, 0], (1, 2, 1))
    frame = server.send(JointUpdates(1, np.array([0]), *one))
    forged = frame[:5] + b"\x00\x07" + frame[7:]  # table 7 was never sent
    expect_protocol_error(client, forged, ErrorCode.UNKNOWN_TABLE)
    client3, server3 = open_pair()
    deliver(client3, server3.send(UpdateTableMsg(example_di_table(1))))
    ready = encode_frame(MessageType.READY, msgpack.packb({"soldiers": [[0, 1], [MAX_SOLDIERS, 1]]}))
    expect_protocol_error(client3, ready, ErrorCode.BAD_VALUE)
    client2, _ = open_pair()
    payload = msgpack.packb({"id": 1, "index": 0, "table": 3})
    expect_protocol_error(
        client2, encode_frame(MessageType.SOLDIER_CREATED, payload), ErrorCode.UNKNOWN_TABLE
    )


def test_out_of_order_messages_are_unexpected() -> None:
    server = Connection(SERVER)
    expect_protocol_error(
        server, encode_frame(MessageType.PING, msgpack.packb({"nonce": 1})), ErrorCode.UNEXPECTED_MESSAGE
    )
    client, server = open_pair()
    with pytest.raises(LocalProtocolError):  # a second Hello is refused locally...
        client.send(Hello("again"))
    expect_protocol_error(server, hello_frame(1), ErrorCode.UNEXPECTED_MESSAGE)  # ...and remotely


def test_local_misuse_raises_and_sends_nothing() -> None:
    client, server = Connection(CLIENT), Connection(SERVER)
    with pytest.raises(LocalProtocolError):
        client.send(Ping(1))  # before Hello/Accept
    with pytest.raises(LocalProtocolError):
        server.send(Accept("jack"))  # no Hello yet
    client, server = open_pair()
    with pytest.raises(LocalProtocolError):
        client.send(Ready())  # wrong direction
    with pytest.raises(LocalProtocolError):
        client.send(Subscribe((MAX_SOLDIERS,)))
    with pytest.raises(LocalProtocolError):
        client.send(EntityRequests(make_entity_requests([1], heading=math.nan)))
    with pytest.raises(LocalProtocolError):
        server.send(
            JointUpdates(5, np.array([0]), np.zeros((1, 1)), np.zeros((1, 0, 3)), np.zeros((1, 0, 4)))
        )
    with pytest.raises(LocalProtocolError):
        client.send(Status(1.0, 1, 1.0))
    assert client.state is State.OPEN and server.state is State.OPEN
    assert deliver(server, client.send(Ping(3))) == [Ping(3)]


def test_connections_share_no_state() -> None:
    c1, s1 = open_pair()
    c2, s2 = open_pair()
    expect_protocol_error(s1, encode_frame(0x7F, b""), ErrorCode.UNKNOWN_MESSAGE_TYPE)
    assert s2.state is State.OPEN
    assert deliver(s2, c2.send(Jcl("ok();", 1))) == [Jcl("ok();", 1)]
    deliver(c2, s2.send(UpdateTableMsg(example_di_table(2))))
    assert 2 in c2.tables and 2 not in c1.tables


def test_every_message_type_has_a_codec() -> None:
    assert set(CODECS) | {MessageType.JOINT_UPDATES} == set(MessageType)
