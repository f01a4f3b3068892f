"""One load-test connection: a link :class:`~client_stub.link.client.Client` that creates its soldiers in
windows, subscribes, sends requests and measures the updates.

A load generator that shares the machine with the server must not spend more than the server: decoding a
joint update costs about 12 µs per soldier in :class:`protocol.updates.UpdateDecoder`, as much as the
server's encoding. So by default the link's connection only *taps* the update frames
(``decode_updates=False``: their header and soldier indices, docs/PROTOCOL.md 8). With ``decode=True`` every
update is decoded and ``on_updates`` receives the full :class:`~protocol.events.JointUpdates` with the poses
(the crowd renderer). Sends wait until the socket took the bytes (back-pressure on the mix driver).
"""

from __future__ import annotations

import functools
import threading
from collections.abc import Callable

import numpy as np
import trio

from client_stub.link.client import Client, LinkError
from protocol.events import JointUpdates, SoldierCreated
from protocol.update_table import UpdateTable

CREATE_WINDOW = 64  # CREATE_SOLDIER requests in flight (the server's control queue holds 256 answers)


class LoadError(LinkError):
    """The server refused something or the connection failed."""


# on_updates(conn number, arrival time, tick, server indices, frame bytes, decoded event or None)
UpdateHook = Callable[[int, float, int, np.ndarray, int, JointUpdates | None], None]


class LoadClient:
    """One TCP connection of the load generator (a controller: it creates and drives its soldiers)."""

    def __init__(
        self, number: int, on_updates: UpdateHook, *, decode: bool = False, buffer_updates: bool = False,
        name: str = "",
    ) -> None:  # fmt: skip
        """``buffer_updates`` (with ``decode``): keep the poses in the link's double buffers, swapped from
        another thread (the crowd's render loop)."""
        self.number = number
        self.name = name or f"ttes-loadtest-{number}"
        self.link = Client(
            self.name,
            "controller",
            buffer_updates=buffer_updates,
            decode_updates=decode or buffer_updates,
            on_updates=functools.partial(on_updates, number),
            lock=threading.Lock() if buffer_updates else None,
        )

    @property
    def failure(self) -> str | None:
        return self.link.failure

    @property
    def tables(self) -> dict[int, UpdateTable]:
        return self.link.tables

    async def connect(self, nursery: trio.Nursery, host: str, port: int, timeout: float = 30.0) -> None:
        """Open the link in ``nursery`` and shake hands (READY is waited for by :meth:`wait_ready`)."""
        try:
            await self.link.open(nursery, host, port, soldierprefix=None, wait_ready=False, timeout=timeout)
        except LinkError as exc:
            raise LoadError(str(exc)) from None

    async def wait_ready(self, timeout: float) -> None:
        if not await self.link.wait_ready(timeout):
            raise LoadError(self.failure or f"{self.name}: no READY within {timeout} s")

    # -- soldiers ------------------------------------------------------------------------------------------
    async def create_soldiers(
        self, count: int, figure: str, weapon: str, timeout: float = 60.0
    ) -> tuple[np.ndarray, np.ndarray]:
        """CREATE_SOLDIER ``count`` times, pipelined ``CREATE_WINDOW`` at a time (the server queues at most a
        few hundred control answers per client); returns (server indices, update tables)."""
        indices: list[int] = []
        tables: list[int] = []
        with trio.move_on_after(timeout) as cs:
            for k in range(0, count, CREATE_WINDOW):
                got = await self._create_window(min(CREATE_WINDOW, count - k), figure, weapon)
                indices += [a.index for a in got]
                tables += [a.table for a in got]
        if cs.cancelled_caught:
            raise LoadError(
                f"{self.name}: only {len(indices)} of {count} soldiers created within {timeout} s"
            )
        return np.array(indices, np.int64), np.array(tables, np.int64)

    async def _create_window(self, count: int, figure: str, weapon: str) -> list[SoldierCreated]:
        try:
            ids = [self.link.create(None, figure, weapon, await_answer=True) for _ in range(count)]
        except LinkError as exc:
            raise LoadError(f"{self.name}: {exc}") from None
        answers = [await self.link.answer(i) for i in ids]
        made = [a for a in answers if isinstance(a, SoldierCreated)]
        if len(made) < count:
            first = next(a for a in answers if not isinstance(a, SoldierCreated))
            why = first.message if first is not None else (self.failure or "no answer")
            raise LoadError(f"{self.name}: {count - len(made)} of {count} soldiers not created: {why}")
        return made

    async def subscribe(self, indices: np.ndarray) -> None:
        await self._sent(self.link.subscribe, indices)

    async def requests(self, rows: np.ndarray) -> None:
        """ENTITY_REQUESTS rows (server indices)."""
        await self._sent(self.link.send_requests, rows)

    async def remove(self, indices: np.ndarray) -> None:
        for i in np.asarray(indices).tolist():
            if not await self._sent(self.link.remove, i, drain=False):
                return
        await self.link.drain()

    async def goodbye(self, reason: str = "load test done") -> None:
        await self.link.aclose(reason)

    async def _sent(self, call: Callable[..., None], *args: object, drain: bool = True) -> bool:
        """Queue one call's messages (a closed link is reported by ``failure``), then wait for the socket."""
        try:
            call(*args)
        except LinkError:
            return False
        if drain:
            await self.link.drain()
        return True


def split_rows(rows: np.ndarray, owner: np.ndarray, nconn: int) -> list[np.ndarray]:
    """Entity-request rows grouped by the connection that owns each row's slot (``rows['index']``)."""
    own = owner[rows["index"].astype(np.int64)]
    return [rows[own == c] for c in range(nconn)]
