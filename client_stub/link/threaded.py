"""A :class:`~client_stub.link.client.Client` run by trio in a thread of its own, for a render loop that is
not async (the stub's window and headless renderer).

The render thread never blocks on the network: it hands calls to the trio thread with
``trio.from_thread.run_sync`` (an encode and a buffer append) and takes joint updates with :meth:`swap`, which
flips the client's double buffers under the lock the reader writes them under. Waiting calls
(:meth:`create_soldier`, :meth:`wait_ready`, :meth:`wait_updates`) wait on thread events the reader sets.
"""

from __future__ import annotations

import contextlib
import logging
import threading
from collections.abc import Callable
from typing import ParamSpec, TypeVar

import numpy as np
import trio

from client_stub.link.buffer import UpdateBatch
from client_stub.link.client import STARTUP_JCL, Client, LinkError
from protocol.entity import Reaction
from protocol.events import (
    Accept,
    Error,
    Event,
    JointUpdates,
    ProtocolError,
    Ready,
    SoldierCreated,
    Status,
)
from protocol.update_table import UpdateTable

log = logging.getLogger("ttes.link.threaded")
P = ParamSpec("P")
T = TypeVar("T")


class ThreadedClient:
    """The link's calls from a plain thread (see the module docstring)."""

    def __init__(self, name: str = "ttes-stub", role: str = "controller") -> None:
        self._lock = threading.Lock()
        self.client = Client(name, role, lock=self._lock, notify=self._notify)
        self.closed = threading.Event()  # the network thread has ended
        self._accepted = threading.Event()
        self._ready = threading.Event()
        self._updated = threading.Event()
        self._thread: threading.Thread | None = None
        self._token: trio.lowlevel.TrioToken | None = None
        self._failure: str | None = None

    # -- what the client knows ------------------------------------------------------------------------------
    @property
    def failure(self) -> str | None:
        return self.client.failure or self._failure

    @property
    def connected(self) -> bool:
        """Handshake done and the link still open."""
        return self.client.accepted and not self.closed.is_set()

    @property
    def ready(self) -> bool:
        return self.client.ready and not self.closed.is_set()

    @property
    def accept(self) -> Accept | None:
        return self.client.accept

    @property
    def tables(self) -> dict[int, UpdateTable]:
        return self.client.tables

    @property
    def ready_soldiers(self) -> dict[int, int]:
        return self.client.ready_soldiers

    @property
    def max_soldiers(self) -> int:
        return self.client.max_soldiers

    @property
    def status(self) -> Status | None:
        return self.client.status

    @property
    def errors(self) -> list[Error | ProtocolError]:
        return self.client.errors

    # -- connecting -----------------------------------------------------------------------------------------
    def connect(self, host: str, port: int, timeout: float = 10.0) -> None:
        """Connect and shake hands (the network runs in its own thread from now on); LinkError on failure."""
        if self._thread is not None:
            raise LinkError("already connected")
        self._thread = threading.Thread(
            target=self._run, args=(host, port, timeout), name="ttes-link", daemon=True
        )
        self._thread.start()
        if not self._accepted.wait(timeout) or not self.connected:
            self.quit()
            raise LinkError(self.failure or f"no handshake with {host}:{port} within {timeout} s")

    def start(self, soldierprefix: str = "soldier_low") -> int:
        """Send the start-up JCL, ``read_file("jack-ttes-<prefix>.jcl");``; returns its request id."""
        return self.jcl(STARTUP_JCL.format(prefix=soldierprefix))

    def wait_ready(self, timeout: float) -> bool:
        """Wait until READY arrived or the connection ended; True when ready."""
        self._ready.wait(timeout)
        return self.ready

    # -- calls into the trio thread -------------------------------------------------------------------------
    def call(self, fn: Callable[P, T], *args: P.args, **kwargs: P.kwargs) -> T:
        """Run one of the client's synchronous calls in the trio thread; LinkError once the link is gone."""
        if self._token is None or self.closed.is_set():
            raise LinkError(self.failure or "not connected")
        try:
            return trio.from_thread.run_sync(lambda: fn(*args, **kwargs), trio_token=self._token)
        except trio.RunFinishedError:
            raise LinkError(self.failure or "connection closed") from None

    def send(self, event: Event) -> None:
        self.call(self.client.send, event)

    def jcl(self, text: str) -> int:
        return self.call(self.client.jcl, text)

    def create(self, index: int | None, figure: str, weapon: str) -> int:
        """CREATE_SOLDIER, pipelined (no waiting); returns its id."""
        return self.call(self.client.create, index, figure, weapon)

    def create_soldier(
        self, figure: str, weapon: str, index: int | None = None, timeout: float = 10.0
    ) -> SoldierCreated:
        """CREATE_SOLDIER and wait for the answer; LinkError if the server refuses or stays silent."""
        if self._token is None or self.closed.is_set():
            raise LinkError(self.failure or "not connected")
        try:
            return trio.from_thread.run(
                self.client.create_soldier, figure, weapon, index, timeout, trio_token=self._token
            )
        except trio.RunFinishedError:
            raise LinkError(self.failure or "connection closed") from None

    def remove(self, index: int) -> None:
        self.call(self.client.remove, index)

    def subscribe(self, indices: list[int] | np.ndarray) -> None:
        if len(indices):
            self.call(self.client.subscribe, indices)

    def unsubscribe(self, indices: list[int] | np.ndarray) -> None:
        if len(indices):
            self.call(self.client.unsubscribe, indices)

    def react(self, indices: list[int] | np.ndarray, kind: Reaction) -> None:
        if len(indices):
            self.call(self.client.react, indices, kind)

    def request_full_update(self, indices: list[int] | None = None) -> None:
        self.call(self.client.request_full_update, indices)

    def send_requests(self, rows: np.ndarray) -> None:
        if len(rows):
            self.call(self.client.send_requests, rows)

    # -- updates --------------------------------------------------------------------------------------------
    def wait_updates(self, timeout: float) -> bool:
        """Wait until joint updates arrived since the last :meth:`swap` (or the connection ended)."""
        return self._updated.wait(timeout) and not self.closed.is_set()

    def swap(self) -> list[UpdateBatch]:
        """Take every pose that arrived since the last call (thread-safe: the buffers flip under the lock)."""
        self._updated.clear()
        return self.client.swap()

    def quit(self, reason: str = "quit", timeout: float = 5.0) -> None:
        """Say goodbye and stop the network thread."""
        if self._token is not None and not self.closed.is_set():
            with contextlib.suppress(trio.RunFinishedError, RuntimeError):
                trio.from_thread.run(self.client.aclose, reason, trio_token=self._token)
        if self._thread is not None:
            self._thread.join(timeout)

    # -- the trio thread ------------------------------------------------------------------------------------
    def _run(self, host: str, port: int, timeout: float) -> None:
        try:
            trio.run(self._main, host, port, timeout)
        except Exception as exc:  # the thread must end cleanly whatever happened
            self._failure = self._failure or f"network task failed: {exc!r}"
            log.warning("%s", self._failure)
        finally:
            self.closed.set()
            for ev in (self._accepted, self._ready, self._updated):
                ev.set()

    async def _main(self, host: str, port: int, timeout: float) -> None:
        self._token = trio.lowlevel.current_trio_token()
        async with trio.open_nursery() as nursery:
            try:
                await self.client.open(
                    nursery, host, port, soldierprefix=None, wait_ready=False, timeout=timeout
                )
            except LinkError as exc:
                self._failure = str(exc)
                return
            await self.client.wait_closed()

    def _notify(self, event: Event) -> None:
        """In the trio thread, after the client took ``event`` in: wake whoever waits for it."""
        match event:
            case Accept():
                self._accepted.set()
            case Ready():
                self._ready.set()
            case JointUpdates():
                self._updated.set()
            case Error(code=code, message=message):
                log.warning("server error %d: %s", code, message)
