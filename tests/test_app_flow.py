"""Flow control, not drops (issue 17): heavy JCL runs off the tick, a pipelining client that reads is
slowed by backpressure and answered in full, deadlines close only the clients that stall. Real TCP over
127.0.0.1 with trio's autojump clock."""

from __future__ import annotations

import json
import struct
import threading
from pathlib import Path

import pytest
import trio
from test_server_support import Client, running_server

import server.world.store as store_module
from protocol.errors import ErrorCode
from protocol.events import Error, Goodbye, Hello, Jcl, Ping, Pong, Ready, Status


def port_of(server) -> int:  # type: ignore[no-untyped-def]
    return server.addresses[0][1]


async def test_ticks_keep_coming_while_a_slow_load_runs(
    autojump_clock: trio.abc.Clock, monkeypatch: pytest.MonkeyPatch
) -> None:
    release = threading.Event()
    real = store_module.load_posture_graph

    def slow_load(path: Path, name: str | None = None, **kw: object) -> object:
        release.wait(timeout=3.0)  # never reached in a passing run: the test releases it
        return real(path, name, **kw)  # type: ignore[arg-type]

    monkeypatch.setattr(store_module, "load_posture_graph", slow_load)
    async with running_server(report_interval=1000.0) as server:
        c = await Client.open(port_of(server), "loader", role="operator")
        await c.expect(Ready)
        await c.jcl('load_posture_graph("soldier_low.graph", "slow"); report_ttes_status("s0");')
        before = server.ticks
        with trio.fail_after(2.0):  # ticks at the full 30 Hz while the loader is blocked
            while server.ticks < before + 50:
                await trio.sleep(1 / 30)
        assert "slow" not in server.world.graphs  # the load was still running meanwhile
        release.set()
        # the JCL finished after the load (the load runs in real time in its thread: no virtual deadline)
        status = await c.expect(Status, lambda st: '"s0"' in st.text, timeout=1e9)  # not a periodic one
        assert status.text
        assert "slow" in server.world.graphs
        assert server.tick_overruns == 0
        await c.aclose()


async def test_a_pipelining_client_that_reads_gets_every_answer(autojump_clock: trio.abc.Clock) -> None:
    async with running_server(report_interval=1000.0) as server:
        c = await Client.open(port_of(server), "pipeliner")
        await c.expect(Ready)
        await c.send_raw(b"".join(c.conn.send(Ping(k)) for k in range(1000)))  # 4x the control queue
        nonces = [(await c.expect(Pong)).nonce for _ in range(1000)]
        assert nonces == list(range(1000))
        jcl = b"".join(c.conn.send(Jcl(f'report_ttes_status("s{k % 10}");', k)) for k in range(300))
        await c.send_raw(jcl)
        reports = [await c.expect(Status, lambda s: s.text.startswith("{")) for _ in range(300)]
        assert [json.loads(r.text)["soldiers"][0]["name"] for r in reports] == [
            f"s{k % 10}" for k in range(300)
        ]
        assert server.clients_dropped == 0
        await c.send(Ping(7))
        assert (await c.expect(Pong)).nonce == 7
        await c.aclose()


async def test_a_half_sent_frame_after_hello_is_closed_at_its_deadline(
    autojump_clock: trio.abc.Clock,
) -> None:
    async with running_server(frame_timeout=5.0, report_interval=1000.0) as server:
        c = await Client.open(port_of(server), "half")
        await c.expect(Ready)
        await c.send_raw(struct.pack(">IB", 100, 0x10) + b"\x81")  # a JCL frame cut short, the socket open
        t0 = trio.current_time()
        await c.until_closed()
        assert trio.current_time() - t0 == pytest.approx(5.0, abs=0.1)
        await trio.sleep(0.1)
        assert server.clients_dropped == 1
        idle = await Client.open(port_of(server), "idle")  # idle between whole frames is not a stall
        await idle.expect(Ready)
        await trio.sleep(60.0)
        await idle.send(Ping(1))
        assert (await idle.expect(Pong)).nonce == 1


async def test_one_address_holds_at_most_its_share_of_the_slots(autojump_clock: trio.abc.Clock) -> None:
    async with running_server(max_clients=10, max_clients_per_host=3, report_interval=1000.0) as server:
        held = [await Client.open(port_of(server), f"idle{k}") for k in range(3)]
        extra = await Client.open(port_of(server), "fourth", hello=False)
        await extra.send(Hello("fourth"))
        err = await extra.expect(Error, lambda e: e.code == ErrorCode.NOT_PERMITTED)
        assert "3 connections from 127.0.0.1" in err.message
        await extra.until_closed()
        await held[0].send(Goodbye("bye"))
        await held[0].until_closed()
        await trio.sleep(0.1)
        again = await Client.open(port_of(server), "again")  # a slot of this address is free again
        await again.expect(Ready)
