"""JackProc and JackSoldier (seed 002, 3.5, Figures 9 and 10): the stub's connection to the Jack/TTES server.

1994: ``jack->launch(...)`` started Jack over ``rsh``, ``initsocketconnection()`` opened the sockets and
``sproc()``'d a reader, ``start("soldier_low")`` sent ``read_file("jack-ttes-soldier_low.jcl")``, the stub
waited for ``jackready``, created ``JackSoldier``\\ s, sent them requests and took joint-angle packets into a
per-soldier double buffer that ``update()`` applied to the Performer tree every frame.

Here the connection is the link's (:class:`~client_stub.link.threaded.ThreadedClient`: one TCP stream
speaking :mod:`protocol`, its reader in a thread of its own, the double buffers flipped by ``swap``);
JackProc only adds Figure 9's vocabulary and its table of soldiers. Launching a server is
:mod:`client_stub.link.spawn`'s.
"""

from __future__ import annotations

import numpy as np

from client_stub.link.threaded import ThreadedClient
from protocol.entity import ENTITY_REQUEST_DTYPE


class JackProc(ThreadedClient):
    """Figure 9: the connection to Jack (the server), its update tables and its soldiers."""

    def __init__(self, name: str = "ttes-stub", role: str = "controller") -> None:
        super().__init__(name, role)
        self.table: dict[int, JackSoldier] = {}  # Figure 9's table of soldiers, by server index

    def initsocketconnection(self, host: str, port: int, timeout: float = 10.0) -> None:
        """Connect and shake hands; LinkError on failure."""
        self.connect(host, port, timeout)

    @property
    def jackready(self) -> bool:
        """READY received (and the link still open)."""
        return self.ready

    def new_soldier(
        self,
        figure: str = "DI.fig",
        weapon: str = "AK_47.fig",
        index: int | None = None,
        timeout: float = 10.0,
    ) -> JackSoldier:
        """CREATE_SOLDIER and wait for the answer; LinkError if the server refuses."""
        made = self.create_soldier(figure, weapon, index, timeout)
        return self.soldier(made.index, made.table)

    def soldier(self, index: int, table: int) -> JackSoldier:
        """The JackSoldier of an existing server soldier (from READY or SOLDIER_CREATED)."""
        js = JackSoldier(self, index, table)
        self.table[index] = js
        return js


class JackSoldier:
    """Figure 10: one soldier on the server, its requests, and its update table.

    Figure 10's ``receive`` (fill a buffer) and ``update`` (apply it to the soldier's DCS nodes) are done
    for all soldiers at once: the link's double buffers hold every soldier's ``buf[2]``,
    :meth:`JackProc.swap` hands the fresh rows over, and ``StubApp`` writes them into the soldiers' scene
    graphs in one batch."""

    def __init__(self, jp: JackProc, soldiernum: int, table: int) -> None:
        self.jp = jp
        self.soldiernum = soldiernum
        self.updatetable = table

    def request(
        self,
        appear: int,
        weapon: int,
        velocity: np.ndarray | tuple[float, float, float],
        heading: float,
        position: np.ndarray | tuple[float, float, float],
        immediate: bool = False,
    ) -> None:
        """Send this soldier's DIS state (Figure 11's JackPackIn)."""
        row = np.zeros(1, ENTITY_REQUEST_DTYPE)
        row["index"] = self.soldiernum
        row["appearance"] = appear
        row["weapon"] = weapon
        row["velocity"] = velocity
        row["heading"] = heading
        row["position"] = position
        row["immediate"] = int(bool(immediate))
        self.jp.send_requests(row)
