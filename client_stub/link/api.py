"""What every form of the link offers a synchronous caller (the DIS sink, the stub apps): the trio-native
:class:`~client_stub.link.client.Client` and the threaded :class:`~client_stub.link.threaded.ThreadedClient`
(and so the stub's ``JackProc``) both satisfy :class:`Link`."""

from __future__ import annotations

from typing import Protocol

import numpy as np

from client_stub.link.buffer import UpdateBatch
from protocol.entity import Reaction
from protocol.update_table import UpdateTable


class Link(Protocol):
    @property
    def tables(self) -> dict[int, UpdateTable]: ...

    @property
    def ready_soldiers(self) -> dict[int, int]: ...

    @property
    def max_soldiers(self) -> int: ...

    def create(self, index: int | None, figure: str, weapon: str) -> int: ...

    def remove(self, index: int) -> None: ...

    def subscribe(self, indices: list[int] | np.ndarray) -> None: ...

    def send_requests(self, rows: np.ndarray) -> None: ...

    def react(self, indices: list[int] | np.ndarray, kind: Reaction) -> None: ...

    def swap(self) -> list[UpdateBatch]: ...
