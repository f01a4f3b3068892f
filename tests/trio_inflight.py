"""Opt-in pytest plugin (``-p trio_inflight``, with ``tests/`` on ``PYTHONPATH``): a test client's bytes
arrive late while ``autojump_clock`` jumps, as on a loaded machine whose kernel defers loopback delivery.

Each receive on a client-side stream (one that ``trio.open_tcp_stream`` made: the tests' clients) first
waits TTES_INFLIGHT_MS of real time (default 2) in a worker thread, with probability TTES_INFLIGHT_P
(default 1). Meanwhile no task can run and nothing new is readable, so the autojump clock jumps to the next
deadline (a tick, a test's time box). The server's sockets are untouched: only when the client reads
changes. A test that reads by tick numbers or by what the server wrote passes under it; one that reads
within a time box and expects a given frame in it fails (issue 21).
"""

from __future__ import annotations

import os
import random
import time
from typing import Any

import trio

DELAY_S = float(os.environ.get("TTES_INFLIGHT_MS", "2")) / 1000
P = float(os.environ.get("TTES_INFLIGHT_P", "1"))
_open_tcp_stream = trio.open_tcp_stream
_receive_some = trio.SocketStream.receive_some
_clients: set[int] = set()


async def _open(*args: Any, **kwargs: Any) -> trio.SocketStream:
    stream = await _open_tcp_stream(*args, **kwargs)
    _clients.add(id(stream.socket))
    return stream


async def _receive(self: trio.SocketStream, max_bytes: int | None = None) -> bytes:
    if id(self.socket) in _clients and random.random() < P:
        await trio.to_thread.run_sync(time.sleep, DELAY_S)
    return await _receive_some(self, max_bytes)


trio.open_tcp_stream = _open
trio.SocketStream.receive_some = _receive  # type: ignore[method-assign]
