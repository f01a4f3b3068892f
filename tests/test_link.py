"""The one client link (client_stub/link) against the real server in this trio run: READY, awaited and
refused CREATE_SOLDIER, subscriptions, the double buffer, the update hook (decoding or tapping), PING,
GOODBYE."""

from __future__ import annotations

import numpy as np
import pytest
import trio
from test_server_support import running_server

from client_stub.link.client import Client, LinkError
from protocol.entity import ENTITY_REQUEST_DTYPE, Appearance
from protocol.events import JointUpdates


@pytest.mark.parametrize("decode", [True, False])
async def test_the_link_creates_drives_and_hears_a_soldier(
    autojump_clock: trio.abc.Clock, decode: bool
) -> None:
    heard: list[tuple[int, list[int], int, bool]] = []

    def hook(t: float, tick: int, indices: np.ndarray, nbytes: int, event: JointUpdates | None) -> None:
        heard.append((tick, indices.tolist(), nbytes, event is not None))

    async with running_server(throttle=0.0) as server, trio.open_nursery() as nursery:
        link = Client("test-link", decode_updates=decode, on_updates=hook)
        await link.open(nursery, "127.0.0.1", server.addresses[0][1])
        assert link.ready and len(link.ready_soldiers) == 10 and link.tables
        made = await link.create_soldier("DI.fig", "AK_47.fig", index=20)
        assert made.index == 20 and link.created[20] == made.table
        with pytest.raises(LinkError, match="refused"):
            await link.create_soldier("DI.fig", "NoSuchRifle.fig")
        link.subscribe([20])
        row = np.zeros(1, ENTITY_REQUEST_DTYPE)
        row["index"], row["appearance"] = 20, Appearance.KNEEL
        link.send_requests(row)
        await link.drain()
        assert await link.roundtrip()
        await trio.sleep(2.0)
        assert heard and all(h[1] == [20] and h[2] > 8 and h[3] == decode for h in heard)
        assert link.soldier_updates == len(heard) and link.update_bytes == sum(h[2] for h in heard)
        batches = link.swap()
        if decode:  # the newest pose of soldier 20, once
            assert [b.indices.tolist() for b in batches] == [[20]] and link.swap() == []
        else:
            assert batches == []
        await link.aclose()
        assert link.closed and link.failure is None
        with pytest.raises(LinkError):
            link.send_requests(row)
        nursery.cancel_scope.cancel()
