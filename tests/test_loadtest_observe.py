"""The fan-out measurement's counting observers: soldier-updates counted from each JOINT_UPDATES frame's head
alone are what the full decoder finds in the same bytes, in protocol versions 1 and 2, however the stream is
cut into reads."""

from __future__ import annotations

import functools
import itertools
import selectors
from collections import Counter

import numpy as np
import pytest
import trio
from hypothesis import given
from hypothesis import strategies as st
from test_server_support import make_server, running_server

from client_stub.loadtest.fanout import FanoutConfig, summarise
from client_stub.loadtest.observe import CountingObserver, FrameCounter, window_counts
from protocol.connection import CLIENT, NEED_DATA, PAUSED, Connection
from protocol.entity import Appearance, make_entity_requests
from protocol.events import ConnectionClosed, Hello, JointUpdates, ProtocolError, Ready, Subscribe
from server.session import Session

SOLDIERS = 10


def captured_stream(version: int) -> bytes:
    """Everything a server session sends one observer (handshake included) over 30 ticks: soldiers walking
    and running, a late subscription, reads that skip ticks (frames whose deltas span several ticks)."""
    server = make_server(throttle=0.0)
    server.start_world()
    m = server.world.manager
    assert m is not None
    idx = np.arange(SOLDIERS)
    speed = np.where(idx % 2 == 0, 1.4, 4.0)
    vel = np.column_stack([np.zeros(SOLDIERS), speed, np.zeros(SOLDIERS)])
    up = [int(Appearance.UPRIGHT)] * SOLDIERS
    m.apply_requests(
        make_entity_requests(idx, up, [1] * SOLDIERS, vel, [0.0] * SOLDIERS), server.request_time()
    )
    session = Session(server.world, server.board_ref, server.config, "counted")
    server.sessions[session.id] = session
    client = Connection(CLIENT)
    session.feed(client.send(Hello("counted", "observer", version=version)))
    stream = session.take_output()
    client.receive_data(stream)
    while client.next_event() not in (NEED_DATA, PAUSED):
        pass
    session.feed(client.send(Subscribe(tuple(range(0, SOLDIERS, 2)))))
    for k in range(1, 31):
        server.tick(k / 30)
        if k == 12:
            session.feed(client.send(Subscribe(tuple(range(SOLDIERS)))))
        if k < 20 or k % 3 == 0:
            stream += session.take_output()
    return stream


def decoded_counts(stream: bytes, version: int) -> tuple[Counter[int], bool]:
    """Soldier-updates per tick as the full decoder (``UpdateDecoder``) finds them; and whether READY came."""
    client = Connection(CLIENT)
    client.send(Hello("decoder", "observer", version=version))  # the state machine's side of the handshake
    client.receive_data(stream)
    per_tick: Counter[int] = Counter()
    ready = False
    while (ev := client.next_event()) is not NEED_DATA:
        assert not isinstance(ev, ConnectionClosed | ProtocolError), ev
        if isinstance(ev, JointUpdates):
            assert len(ev.dofs) == len(ev.indices)  # decoded in full
            per_tick[ev.tick] += len(ev.indices)
        ready |= isinstance(ev, Ready)
    return per_tick, ready


def counted(counter: FrameCounter) -> Counter[int]:
    per_tick: Counter[int] = Counter()
    for tick, count in zip(counter.ticks, counter.counts, strict=True):
        per_tick[tick] += count
    return per_tick


@pytest.fixture(scope="module", params=[1, 2], ids=["v1", "v2"])
def stream(request: pytest.FixtureRequest) -> tuple[int, bytes]:
    return request.param, captured_stream(request.param)


def test_head_counts_equal_full_decode_counts(stream: tuple[int, bytes]) -> None:
    version, data = stream
    want, ready = decoded_counts(data, version)
    assert ready and sum(want.values()) > 5 * SOLDIERS  # real traffic: full updates, then deltas
    c = FrameCounter()
    others = c.feed(data, now=1.0)
    assert counted(c) == want
    assert sum(c.sizes) + sum(map(len, others)) == len(data)  # every byte is in one frame or the other
    assert not c.buf
    head = others[0][4:11]
    assert head[0] == 0x02 and int.from_bytes(head[5:7], "big") == version  # ACCEPT of that version


@functools.cache
def stream_v2() -> bytes:
    return captured_stream(2)


@given(cuts=st.lists(st.integers(min_value=0, max_value=1 << 16), max_size=40))
def test_counts_do_not_depend_on_how_the_stream_is_cut(cuts: list[int]) -> None:
    data = stream_v2()
    whole = FrameCounter()
    want_others = whole.feed(data)
    parts = FrameCounter()
    edges = sorted({min(c, len(data)) for c in cuts} | {0, len(data)})
    others = [f for a, b in itertools.pairwise(edges) for f in parts.feed(data[a:b])]
    assert (parts.ticks, parts.counts, parts.sizes) == (whole.ticks, whole.counts, whole.sizes)
    assert others == want_others and not parts.buf


def test_window_and_summary_arithmetic() -> None:
    c = FrameCounter(ticks=[5, 6, 6, 7, 9], counts=[10, 4, 6, 10, 10], sizes=[400, 200, 250, 390, 380],
                     times=[0.9, 1.0, 1.01, 1.5, 2.0])  # fmt: skip
    w = window_counts(c, 1.0, 2.0)
    assert w == {"updates": 20, "frames": 3, "bytes": 840, "ticks": 2, "tick_span": 2}
    cfg = FanoutConfig(soldiers=10, observers=1)
    part = {"window": [1.0, 2.0], "late_start": False, "server_cpu_s": 0.5, "observer_cpu_s": 0.01,
            "server_cpu_pct": 50.0, "server_wait_pct": 5.0, "clients": [{"name": "o", **w}]}  # fmt: skip
    s = summarise(cfg, 10.0, [part])
    assert s["expected_updates_per_client"] == 100
    assert s["clients"][0]["delivered_pct"] == 20.0 and s["clients"][0]["bytes_per_update"] == 42.0
    assert s["server_ms_per_tick"] == 250.0  # 0.5 s of CPU over the 2 server ticks (7 and 8) of the window
    assert s["server_cpu_pct"] == 50.0


def read_first_frames(port: int, indices: range) -> CountingObserver:
    """An observer over a real socket: handshake, subscribe, read until a JOINT_UPDATES frame is counted."""
    o = CountingObserver("counting", version=2)
    o.connect("127.0.0.1", port, timeout=30.0)
    o.subscribe(indices)
    assert o.sock is not None
    with selectors.DefaultSelector() as sel:
        sel.register(o.sock, selectors.EVENT_READ)
        for _ in range(600):  # bounded: at most 600 reads (30 s of selector waits)
            if o.counter.counts or o.closed:
                break
            if sel.select(0.05):
                o.pump(0.0)
    o.close()
    return o


async def test_an_observer_shakes_hands_and_counts_the_first_full_updates() -> None:
    async with running_server(throttle=0.0) as server:
        port = server.addresses[0][1]
        o = await trio.to_thread.run_sync(read_first_frames, port, range(SOLDIERS))
    assert o.ready is not None and o.failure is None
    assert o.counter.counts[0] == SOLDIERS  # every subscribed soldier, in full, in the first frame
