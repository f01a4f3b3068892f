"""Fuzz: random and mutated frames into both sides of a Connection; nothing but events may come out.

``HYPOTHESIS_PROFILE=fuzz pytest -m fuzz -s tests/test_protocol_fuzz.py`` runs 100,000 streams per test and
prints how many frames were fed.
"""

from __future__ import annotations

import contextlib
import struct
from collections import Counter
from collections.abc import Iterator

import msgpack
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from protocol.connection import CLIENT, NEED_DATA, PAUSED, SERVER, Connection, State
from protocol.entity import make_entity_requests
from protocol.errors import ErrorCode, WireError
from protocol.events import (
    PROTOCOL_VERSION,
    Accept,
    ConnectionClosed,
    CreateSoldier,
    EntityRequests,
    Error,
    Event,
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
    SoldierCreated,
    Status,
    Subscribe,
    Unsubscribe,
    UpdateTableMsg,
)
from protocol.framing import encode_frame
from protocol.legacy import decode_jackpackin, decode_update_stream, encode_jackpackin, encode_update_packets
from protocol.messages import MessageType
from protocol.update_table import example_di_table

MAX_SOLDIERS = 64
TABLE = example_di_table(1)
FED: Counter[str] = Counter()


def _frames(data: bytes) -> list[bytes]:
    out, at = [], 0
    while at < len(data):
        n = struct.unpack_from(">I", data, at)[0] + 4
        out.append(data[at : at + n])
        at += n
    return out


def _corpus(version: int = PROTOCOL_VERSION) -> tuple[bytes, list[bytes], bytes, list[bytes]]:
    """Valid frames from a real session: (hello, client→server frames, accept, server→client frames)."""
    client, server = Connection(CLIENT), Connection(SERVER, max_soldiers=MAX_SOLDIERS)
    hello = client.send(Hello("fuzz", version=version))
    server.receive_data(hello)
    server.next_event()
    accept = server.send(Accept("jack", max_soldiers=MAX_SOLDIERS, version=version))
    client.receive_data(accept)
    client.next_event()
    rows = make_entity_requests(
        [1, 2], [2, 4], [1, 2], [(1.0, 0, 0), (0, 0, 0)], [90, 0], [(1, 2, 0), (3, 4, 0)]
    )
    to_server = [
        client.send(e)
        for e in (
            Jcl('read_file("jack-ttes-soldier_low.jcl");', 1),
            CreateSoldier(2, "DI.fig", "M16.fig", 3),
            RemoveSoldier(3),
            Subscribe((0, 1, 2)),
            Unsubscribe((2,)),
            RequestFullUpdate(()),
            React(1, (1, 2)),
            React(2, ()),
            EntityRequests(rows),
            Ping(5),
            Pong(6),
            Error(105, "jcl failed", 1),
        )
    ]
    server.receive_data(b"".join(to_server))
    while server.next_event() is not NEED_DATA:
        pass
    rng = np.random.default_rng(0)
    dofs = rng.uniform(0.0, 0.04, (2, 50))
    pos = rng.uniform(-1, 1, (2, 2, 3))
    quat = rng.normal(size=(2, 2, 4))
    idx = np.array([0, 1])
    to_client = [server.send(UpdateTableMsg(TABLE))]
    to_client += [
        server.send(e) for e in (SoldierCreated(2, 3, 1), Ready(((0, 1), (1, 1))), Status(1.0, 2, 30.0, "ok"))
    ]
    to_client.append(server.send(JointUpdates(1, idx, dofs, pos, quat, tick=1)))
    dofs[0, :4] += 0.01
    to_client.append(server.send(JointUpdates(1, idx, dofs, pos, quat, tick=2)))
    to_client += [server.send(e) for e in (Ping(1), Pong(2), Error(100, "no soldier", 4))]
    bye = encode_frame(MessageType.GOODBYE, msgpack.packb({"reason": "x"}))
    return hello, [*to_server, bye], accept, [*to_client, bye]


HELLO, TO_SERVER, ACCEPT, TO_CLIENT = _corpus()
V1 = _corpus(1)  # version 1's joint updates (§8.1-8.3) stay fuzzed too


@st.composite
def mutated(draw: st.DrawFn, frames: list[bytes]) -> bytes:
    frame = draw(st.sampled_from(frames))
    op = draw(st.sampled_from(["keep", "flip", "payload", "truncate", "length", "type", "extend", "random"]))
    if op == "keep":
        return frame
    if op == "flip":  # flip bytes anywhere, framing included
        buf = bytearray(frame)
        for _ in range(draw(st.integers(1, 4))):
            buf[draw(st.integers(0, len(buf) - 1))] ^= draw(st.integers(1, 255))
        return bytes(buf)
    if op == "payload":  # flip payload bits, keep the framing valid: reaches the message decoders
        buf = bytearray(frame)
        if len(buf) > 5:
            for _ in range(draw(st.integers(1, 3))):
                buf[draw(st.integers(5, len(buf) - 1))] ^= 1 << draw(st.integers(0, 7))
        return bytes(buf)
    if op == "truncate":
        return frame[: draw(st.integers(0, len(frame) - 1))]
    if op == "length":
        return struct.pack(">I", draw(st.integers(0, 2**32 - 1))) + frame[4:]
    if op == "type":
        return frame[:4] + bytes([draw(st.integers(0, 255))]) + frame[5:]
    if op == "extend":  # valid framing around a payload with garbage added or cut
        payload = frame[5:] + draw(st.binary(max_size=16))
        payload = payload[: draw(st.integers(0, len(payload)))]
        return encode_frame(frame[4], payload)
    return draw(st.binary(max_size=64))


def _events(conn: Connection, on_pause: bytes | None) -> Iterator[Event]:
    for _ in range(10_000):
        ev = conn.next_event()
        if ev is PAUSED:
            conn.send(Accept("jack", max_soldiers=MAX_SOLDIERS))
            continue
        if ev is NEED_DATA or isinstance(ev, ConnectionClosed):
            return
        yield ev
    raise AssertionError("next_event never asked for data")


def _feed(conn: Connection, chunks: list[bytes], eof: bool) -> None:
    for chunk in chunks:
        conn.receive_data(chunk)
        for ev in _events(conn, None):
            assert isinstance(ev, Event)
            if isinstance(ev, ProtocolError):
                assert ev.code != ErrorCode.INTERNAL, ev  # the catch-all must never fire
                assert conn.state is State.ERROR
                out = conn.data_to_send()
                assert out[4] == MessageType.ERROR and msgpack.unpackb(out[5:])["code"] == ev.code
    if eof:
        conn.receive_data(b"")
        list(_events(conn, None))
    assert isinstance(conn.next_event(), ConnectionClosed) or conn.next_event() is NEED_DATA


@pytest.fixture(scope="module", autouse=True)
def _report() -> Iterator[None]:
    yield
    print(
        f"\nfuzz: fed {FED['frames']} frames ({FED['bytes']} bytes) in {FED['streams']} connection streams; "
        f"{FED['legacy']} legacy blobs"
    )


@pytest.mark.fuzz
@given(
    st.booleans(),
    st.data(),
    st.booleans(),
    st.integers(1, 64),
)
def test_connections_survive_random_and_mutated_frames(
    to_server: bool, data: st.DataObject, eof: bool, chunk: int
) -> None:
    """Either side, after a real handshake, fed 1..8 valid/mutated/random frames split at random points."""
    version = data.draw(st.sampled_from([1, PROTOCOL_VERSION]))
    hello, to_server_frames, accept, to_client = V1 if version == 1 else (HELLO, TO_SERVER, ACCEPT, TO_CLIENT)
    corpus = to_server_frames if to_server else to_client
    frame = st.sampled_from(corpus) | mutated(corpus)  # about half the frames stay valid: errors come late
    frames = data.draw(st.lists(frame, min_size=1, max_size=8))
    if to_server:
        conn = Connection(SERVER, max_soldiers=MAX_SOLDIERS)
        lead = data.draw(st.just(hello) | mutated([hello]))
    else:
        conn = Connection(CLIENT)
        conn.send(Hello("fuzz", version=version))
        lead = data.draw(st.just(accept) | mutated([accept]))
        if data.draw(st.booleans()):  # the update table and a full update first, so deltas can apply
            frames = [to_client[0], to_client[4], *frames]
    stream = lead + b"".join(frames)
    FED["frames"] += len(frames) + 1
    FED["bytes"] += len(stream)
    FED["streams"] += 1
    _feed(conn, [stream[i : i + chunk] for i in range(0, len(stream), chunk)], eof)


msgpack_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(2**64), 2**64)
    | st.floats()
    | st.text(max_size=8)
    | st.binary(max_size=8),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4),
    max_leaves=12,
)
KEYS = [
    "name",
    "role",
    "max_frame",
    "max_soldiers",
    "code",
    "message",
    "ref",
    "reason",
    "nonce",
    "id",
    "text",
    "soldiers",
]
KEYS += ["time", "update_rate", "figure", "weapon", "index", "table", "indices", "entries", "kind"]


@pytest.mark.fuzz
@given(
    st.sampled_from(sorted(set(MessageType) - {MessageType.ENTITY_REQUESTS, MessageType.JOINT_UPDATES})),
    st.dictionaries(st.sampled_from(KEYS), msgpack_values, max_size=8) | msgpack_values,
    st.booleans(),
)
def test_schema_checks_survive_arbitrary_msgpack_bodies(mt: MessageType, body: object, prefix: bool) -> None:
    """Well-framed control messages whose msgpack body has any shape: only events, never exceptions."""
    try:
        payload = msgpack.packb(body, use_bin_type=True)
    except (OverflowError, ValueError, TypeError):
        return
    if mt in (MessageType.HELLO, MessageType.ACCEPT) and prefix:
        payload = b"TTES\x00\x01" + payload
    frame = encode_frame(mt, payload)
    server = Connection(SERVER, max_soldiers=MAX_SOLDIERS)
    client = Connection(CLIENT)
    client.send(Hello("fuzz"))
    if mt is not MessageType.HELLO:
        server.receive_data(HELLO)
        server.next_event()
        server.send(Accept("jack", max_soldiers=MAX_SOLDIERS))
    if mt is not MessageType.ACCEPT:
        client.receive_data(ACCEPT)
        client.next_event()
        client.receive_data(TO_CLIENT[0])
        client.next_event()
    FED["frames"] += 2
    _feed(server, [frame], eof=False)
    _feed(client, [frame], eof=True)


def _legacy_corpus() -> list[bytes]:
    rng = np.random.default_rng(2)
    quat = rng.normal(size=(2, 2, 4))
    args = (TABLE, [0, 1], rng.uniform(-1, 1, (2, 50)), rng.uniform(-1, 1, (2, 2, 3)), quat)
    rows = make_entity_requests([1, 2], [2, 5], [1, 2], (1.0, 0, 0), 90.0, (1, 2, 3), [True, False])
    return [
        encode_update_packets(*args),
        encode_update_packets(*args, figure_floats=7, entries=[24, 0]),
        encode_jackpackin(rows),
    ]


LEGACY = _legacy_corpus()


@pytest.mark.fuzz
@given(st.binary(max_size=200) | mutated(LEGACY), st.sampled_from([16, 7]))
def test_legacy_decoders_raise_only_wire_errors(blob: bytes, figure_floats: int) -> None:
    FED["legacy"] += 1
    for decode in (lambda: decode_jackpackin(blob), lambda: decode_update_stream(TABLE, blob, figure_floats)):
        with contextlib.suppress(WireError):
            decode()
