"""Issue 21: a connection whose own throttle is no stricter than the server's is held by no gate of its own
(the soldier manager caps every soldier already), so a soldier's updates stay evenly spaced on the wire
whenever the connection's throttle changes; a stricter one still holds its writes."""

from __future__ import annotations

import numpy as np
import pytest
import trio
from test_server_support import Client, frames_until, running_server

from protocol.events import Subscribe
from server.app import TtesServer


def _vel(speed: float) -> tuple[float, float, float]:
    return (0.0, speed, 0.0)


async def _walking_and_held(server: TtesServer, own: float) -> Client:
    """A client watching soldier 0 walk under the server's 0.1 s throttle with ``own`` as its own throttle,
    returned one tick after a tick whose update of soldier 0 the connection's gate held back."""
    c = await Client.open(server.addresses[0][1])
    await c.requests(index=0, velocity=_vel(1.4), heading=0.0)
    await c.send(Subscribe((0,)))
    await c.jcl(f"set_ttes_soldier_throttle({own:g});")
    await c.drain(0.5)
    await c.caught_up(server)
    session, manager = c.session(server), server.world.manager
    assert manager is not None
    period = 1.0 / server.config.tick_hz
    for _ in range(60):  # tick by tick until the manager's update is newer than the connection's write
        if manager.table.tick_sent[0] > session.last_updates_at + period / 2:
            break
        await trio.sleep_until(server._t0 + server.next_tick + period / 4)
    else:
        raise AssertionError("the connection's gate held nothing back")
    await trio.sleep_until(server._t0 + server.next_tick + period / 2)  # off the tick: half a tick later
    return c


@pytest.mark.parametrize("own", [0.2, 0.4])
async def test_own_throttle_back_to_the_servers_keeps_updates_evenly_spaced(
    autojump_clock: trio.abc.Clock, own: float
) -> None:
    """``set_ttes_soldier_throttle(0)`` after a held update: every third tick from then on (the server's
    0.1 s at 30 Hz), never a longer gap (the connection's gate once counted from the write of the held
    update, a tick late, and each later update went out 0.75 tick later until one gap of 4+ ticks)."""
    async with running_server(throttle=0.1) as server:
        c = await _walking_and_held(server, own)
        await c.jcl("set_ttes_soldier_throttle(0);")
        await c.caught_up(server)
        first = server.ticks
        frames = await frames_until(c, lambda fs: bool(fs) and fs[-1][0] >= first + 60, 4.0)
        ticks = [t for t, indices, _ in frames if 0 in indices]
        assert set(np.diff(ticks).tolist()) == {3}, ticks


async def test_a_stricter_own_throttle_still_holds_every_other_update(
    autojump_clock: trio.abc.Clock,
) -> None:
    """Own 0.2 s over the server's 0.1 s: every sixth tick, also after a JCL between ticks (its SETTINGS goes
    out at once, the update the gate holds does not): a stricter own throttle keeps its gate."""
    async with running_server(throttle=0.1) as server:
        c = await _walking_and_held(server, 0.2)
        await c.jcl("set_ttes_soldier_throttle(0.19);")  # a write off the tick, 6 ticks as 0.2
        await c.caught_up(server)
        first = server.ticks
        frames = await frames_until(c, lambda fs: bool(fs) and fs[-1][0] >= first + 90, 6.0)
        ticks = [t for t, indices, _ in frames if 0 in indices]
        assert set(np.diff(ticks).tolist()) == {6}, ticks
