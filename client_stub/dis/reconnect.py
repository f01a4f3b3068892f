"""Keep a DIS sink linked to its server: when the link closes (the server stopped or restarted), connect again
with backoff and hand the sink the new link (:meth:`~client_stub.dis.sink.ServerSink.rebind` re-creates its
soldiers, subscribes and sends their last requests). Meanwhile the gateway or replay goes on; the sink keeps
its soldiers' state. After ``give_up_after`` seconds without a server, :class:`GaveUp` (the commands exit 1).
"""

from __future__ import annotations

import logging
from collections.abc import Awaitable, Callable, Sequence

import trio

from client_stub.dis.sink import ServerSink
from client_stub.link.auth import Credentials
from client_stub.link.client import Client, LinkError
from client_stub.link.retry import BACKOFF, GIVE_UP_AFTER

log = logging.getLogger("ttes.reconnect")


class GaveUp(LinkError):
    """No server answered for ``give_up_after`` seconds."""


def connector(
    nursery: trio.Nursery,
    host: str,
    port: int,
    name: str = "ttes-client",
    timeout: float = 10.0,
    credentials: Credentials | None = None,
) -> Callable[[], Awaitable[Client]]:
    """What :func:`keep_linked` calls: a new link to ``host:port`` with the command's ``credentials`` (token,
    TLS) and the first link's client id, so a server that kept our soldiers for us hands them back."""
    first: list[Client] = []

    async def connect() -> Client:
        link = (credentials or Credentials()).apply(Client(name))
        if first:
            link.client_id = first[0].client_id
        await link.open(nursery, host, port, timeout=timeout)
        first[:] = first or [link]
        return link

    return connect


async def keep_linked(
    sink: ServerSink,
    connect: Callable[[], Awaitable[Client]],
    backoff: Sequence[float] = BACKOFF,
    give_up_after: float = GIVE_UP_AFTER,
    *,
    task_status: trio.TaskStatus[trio.CancelScope] = trio.TASK_STATUS_IGNORED,
) -> None:
    """Run until cancelled: wait for the sink's link to close, reconnect, rebind; GaveUp when out of time."""
    with trio.CancelScope() as scope:
        task_status.started(scope)
        while True:
            link = sink.link
            assert isinstance(link, Client), "keep_linked needs the trio client"
            await link.wait_closed()
            sink.lost = sink.lost or link.failure or "connection closed"
            log.warning("server lost (%s): reconnecting", sink.lost)
            sink.rebind(await reconnect(connect, backoff, give_up_after))
            log.warning("server back: %d soldiers created again", len(sink.rifle_of))


async def reconnect(
    connect: Callable[[], Awaitable[Client]], backoff: Sequence[float], give_up_after: float
) -> Client:
    """A new link: ``connect`` tried after each backoff delay until one succeeds or time runs out."""
    t0 = trio.current_time()
    why = ""
    for k in range(1_000_000):
        delay = backoff[min(k, len(backoff) - 1)]
        if trio.current_time() - t0 + delay > give_up_after:
            break
        await trio.sleep(delay)
        try:
            return await connect()
        except LinkError as exc:
            why = str(exc)
    raise GaveUp(f"gave up after {trio.current_time() - t0:.0f} s without a server: {why}")


async def keep_linked_or_stop(
    sink: ServerSink,
    connect: Callable[[], Awaitable[Client]],
    stop: trio.CancelScope,
    failures: list[str],
    give_up_after: float = GIVE_UP_AFTER,
) -> None:
    """:func:`keep_linked` for a command: when it gives up, say why in ``failures`` and cancel ``stop`` (the
    command then exits 1). ``give_up_after`` 0: no reconnecting, a lost server stops the command at once."""
    if give_up_after <= 0:
        link = sink.link
        assert isinstance(link, Client)
        await link.wait_closed()
        failures.append(f"server lost: {link.failure or 'connection closed'}")
        stop.cancel()
        return
    try:
        await keep_linked(sink, connect, give_up_after=give_up_after)
    except GaveUp as exc:
        failures.append(str(exc))
        stop.cancel()
