"""The server's clock starts with serve(): a start-up run before it, inside trio (as `ttes replay`, `gateway`
and `cigi --with-server` do), must not freeze the soldiers at trio's absolute time."""

from __future__ import annotations

import trio
from test_server_support import make_server


async def test_start_world_before_serve_keeps_server_time_from_zero(autojump_clock: trio.abc.Clock) -> None:
    await trio.sleep(5000.0)  # trio's clock far from 0, as a real clock is
    server = make_server()
    server.start_world()
    assert server.request_time() == 0.0
    async with trio.open_nursery() as nursery:
        await nursery.start(server.serve)
        await trio.sleep(1.0)
        assert 0.9 < server.request_time() < 1.1  # was 5000: every tick ran at that frozen stamp
        server.shutdown()
