"""The live DIS gateway: the synthetic exercise's PDUs sent over loopback UDP (trio sockets, autojump clock)
reach the real server as they do in a replay, and malformed datagrams, unknown PDU types and bursts are
counted, never fatal."""

from __future__ import annotations

import socket

import numpy as np
import pytest
import trio
from hypothesis import given
from hypothesis import strategies as st
from test_replay_support import MAX_LAG, Monitor, entity_key, exercise, expected_activities, match_in_order
from test_server_support import running_server

from client_stub.dis.cursor import EntityFilter
from client_stub.dis.gateway import DisGateway, GatewayConfig
from client_stub.dis.sink import ServerSink
from client_stub.link.client import Client
from protocol.dis import read_bytes
from protocol.dis.pdu import HEADER
from protocol.dis.synth import write_pcap


def unknown_pdu() -> bytes:
    """A well-formed DIS 7 header of PDU type 26 (Signal, a type TTES does not read) with a small body."""
    return HEADER.pack(7, 1, 26, 4, 0, 24, 0, 0) + bytes(12)


async def test_gateway_over_loopback_udp_drives_the_server_like_a_replay(
    autojump_clock: trio.abc.Clock, tmp_path: pytest.TempPathFactory
) -> None:
    ex = exercise()
    path = tmp_path / "squad.pcap"  # type: ignore[operator]
    write_pcap(path, ex)
    expected = expected_activities(read_bytes(path.read_bytes()))
    heartbeat = next(p.payload for p in ex.packets if p.src >= 4)  # the parked vehicle's Entity State PDU
    async with running_server(throttle=0.0) as server, trio.open_nursery() as nursery:
        monitor = Monitor(server)
        nursery.start_soon(monitor.run)
        link = Client("ttes-gateway")
        await link.open(nursery, "127.0.0.1", server.addresses[0][1])
        sink = ServerSink(link)
        gateway = DisGateway(GatewayConfig(port=0, interface="127.0.0.1"))
        gw_nursery = await nursery.start(_gateway_task, gateway, sink)
        port = gateway.address[1]
        sender = trio.socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        t0, p0 = trio.current_time(), ex.packets[0].t
        junk_at = {
            10: b"GET / HTTP/1.0\r\n\r\n",
            20: ex.packets[3].payload[:100],
            30: unknown_pdu(),
            40: b"\x07",
        }
        for k, p in enumerate(ex.packets):
            await trio.sleep_until(t0 + p.t - p0)
            await sender.sendto(p.payload, ("127.0.0.1", port))
            if k in junk_at:  # malformed, truncated, unknown and tiny datagrams between the real ones
                await sender.sendto(junk_at[k], ("127.0.0.1", port))
            if k == 50:  # a burst: 300 datagrams at once (a non-lifeform's heartbeat, over and over)
                for _ in range(300):
                    await sender.sendto(heartbeat, ("127.0.0.1", port))
        await trio.sleep(MAX_LAG)
        for entity, seq in expected.items():
            slot = int(gateway.translator.slots_of(np.array([entity_key(entity)]))[0])
            seen = monitor.seen[sink.base + slot]
            shifted = [(t0 + t - p0, a) for t, a in seq]
            problems = match_in_order(shifted, seen, lag=MAX_LAG + 0.2)
            assert not problems, (entity, problems, [s[2] for s in seen])
        counts = gateway.snapshot()
        assert counts["alive"] == 4 and counts["translator_created"] == 4
        assert counts["datagrams"] == len(ex.packets) + len(junk_at) + 300
        assert counts["non_dis"] >= 2 and counts["corrupt"] >= 1 and counts["other_pdus"] >= 1  # junk counted
        assert counts["max_burst"] > 1 and counts["non_lifeforms"] >= 300
        assert counts["fire"] == ex.counts["fire"] and counts["detonation"] == 1
        assert counts["decode_failures"] == 0 and not link.errors
        gw_nursery.cancel_scope.cancel()  # the gateway stops; its soldiers leave the server
        sink.apply(gateway.stop())
        await link.aclose()
        assert [i for i in server.world.manager.table.live.tolist() if i >= sink.base] == []
        nursery.cancel_scope.cancel()


async def _gateway_task(gateway: DisGateway, sink: ServerSink, task_status: trio.TaskStatus) -> None:
    async with trio.open_nursery() as n:
        await n.start(gateway.serve, sink)
        task_status.started(n)


async def test_entity_filter_and_timeout_in_the_gateway(autojump_clock: trio.abc.Clock) -> None:
    ex = exercise()
    cfg = GatewayConfig(port=0, timeout=2.0, entity_filter=EntityFilter.parse("opposing"))
    gw = DisGateway(cfg)
    t0 = ex.packets[0].t
    tr = gw.handle([p.payload for p in ex.packets if p.t - t0 < 1.0], 0.0)
    assert sorted(tuple(e) for e in tr.created["entity"].tolist()) == [(1, 2, 2), (1, 2, 4)]
    assert gw.status["filtered"] > 0
    assert gw.handle([], 10.0).removed.size == 2  # silent for longer than the timeout


@pytest.mark.fuzz
@given(st.lists(st.binary(max_size=300), min_size=1, max_size=8), st.integers(0, 3))
def test_any_datagrams_are_counted_never_raised(datagrams: list[bytes], n_good: int) -> None:
    """Arbitrary bytes, alone or mixed with good PDUs (some cut short), never escape as exceptions."""
    ex = exercise()
    good = [p.payload for p in ex.packets[:n_good]]
    mixed = good + datagrams + [g[: len(g) // 2] for g in good]
    gw = DisGateway(GatewayConfig(port=0))
    gw.handle(mixed, 1.0)
    assert gw.status["datagrams"] == len(mixed) and gw.status["decode_failures"] == 0


def test_socket_binds_the_interface_asked_for() -> None:
    from client_stub.dis.gateway import open_dis_socket

    s = open_dis_socket(GatewayConfig(port=0, interface="127.0.0.1"))
    try:
        host, port = s.getsockname()[:2]
        assert host == "127.0.0.1" and port > 0 and not s.getblocking()
        assert s.getsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST) == 1
    finally:
        s.close()
    with pytest.raises(OSError):
        open_dis_socket(GatewayConfig(port=0, interface="192.0.2.1"))  # not ours: refused, clearly
