"""The CIGI host's thin I/O: a scene of soldiers on the server, their newest poses, a datagram per message.

The packets are :mod:`protocol.cigi_scene`'s; this module only creates the scene's soldiers over the client
link (a grid, three metres apart, each facing his own way, postures taking turns: stand, kneel, prone),
keeps the newest pose of each from the link's double buffers, and at every frame of ``fps`` hands the
frame's messages to a ``send`` callable (a UDP socket's ``sendto`` in the command, a list in tests).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import trio

from client_stub.link.client import Client, LinkError
from protocol import cigi_scene
from protocol.dis.geo import LocalFrame
from protocol.entity import Appearance, WeaponState, make_entity_requests
from protocol.update_table import JointEntry

FIGURE = "DI.fig"
SPACING = 3.0  # metres between soldiers
POSTURES = (Appearance.UPRIGHT, Appearance.KNEEL, Appearance.PRONE)


@dataclass
class HostConfig:
    soldiers: int = 10
    fps: float = 30.0
    origin: LocalFrame = field(default_factory=lambda: LocalFrame(0.0, 0.0, 0.0))
    max_bytes: int = cigi_scene.MAX_MESSAGE


def scene_requests(indices: np.ndarray) -> np.ndarray:
    """The scene's entity requests: a square grid, headings 0, 37, 74 ... degrees, postures in turn."""
    n = len(indices)
    side = max(1, math.ceil(math.sqrt(n)))
    k = np.arange(n)
    pos = np.stack([(k % side) * SPACING, (k // side) * SPACING, np.zeros(n)], axis=1)
    return make_entity_requests(
        indices,
        appearance=[int(POSTURES[i % len(POSTURES)]) for i in range(n)],
        weapon=WeaponState.DEPLOYED,
        heading=(k * 37.0) % 360.0,
        position=pos,
    )


class CigiHost:
    """The soldiers of one link as CIGI entities: :meth:`populate`, then :meth:`run` (or :meth:`frame`)."""

    def __init__(self, link: Client, cfg: HostConfig, send: Callable[[bytes], object]) -> None:
        self.link = link
        self.cfg = cfg
        self.send = send
        self.requests = np.zeros(0, make_entity_requests(0).dtype)
        self.table_of: dict[int, int] = {}  # server index -> update table
        self.poses: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}  # dofs, figure offsets, quats
        self.stats = {"frames": 0, "datagrams": 0, "bytes": 0, "soldiers_sent": 0}

    async def populate(self, timeout: float = 10.0) -> None:
        """Create the scene's soldiers, subscribe to them and send their requests."""
        tables = sorted(self.link.tables.values(), key=lambda t: (t.figure != FIGURE, t.table_id))
        if not tables:
            raise LinkError("the server has no update tables (no motion library bound)")
        figure, weapon = tables[0].figure, tables[0].weapon
        made = [
            await self.link.create_soldier(figure, weapon, timeout=timeout) for _ in range(self.cfg.soldiers)
        ]
        self.table_of = {a.index: a.table for a in made}
        idx = np.array(sorted(self.table_of), np.int64)
        self.requests = scene_requests(idx)
        self.link.subscribe(idx)
        self.link.send_requests(self.requests)
        await self.link.drain()

    def take_updates(self) -> None:
        for b in self.link.swap():
            for row, i in enumerate(b.indices.tolist()):
                self.poses[i] = (b.dofs[row], b.positions[row], b.orientations[row])

    def groups(self) -> list[cigi_scene.SoldierGroup]:
        """The soldiers with a pose so far, one group per update table, as the scene module takes them."""
        types = cigi_scene.entity_types(self.link.tables)
        rows: dict[int, list[int]] = {}
        for r, req in enumerate(self.requests):
            i = int(req["index"])
            if i in self.poses:
                rows.setdefault(self.table_of[i], []).append(r)
        out = []
        for tid, sel in sorted(rows.items()):
            table, req = self.link.tables[tid], self.requests[sel]
            poses = [self.poses[int(i)] for i in req["index"]]
            out.append(cigi_scene.SoldierGroup(
                req["index"], types[tid], req["position"], req["heading"],
                np.stack([p[1] for p in poses]), np.stack([p[2] for p in poses]),
                tuple(pid for pid, _ in cigi_scene.figure_parts(table)), np.stack([p[0] for p in poses]),
                tuple(d.kind for e in table.entries if isinstance(e, JointEntry) for d in e.dofs),
            ))  # fmt: skip
        return out

    def frame(self, number: int, timestamp: int = 0) -> None:
        """Send frame ``number``'s messages (the newest poses)."""
        self.take_updates()
        groups = self.groups()
        for msg in cigi_scene.frame_messages(number, groups, self.cfg.origin, self.cfg.max_bytes, timestamp):
            self.send(msg)
            self.stats["datagrams"] += 1
            self.stats["bytes"] += len(msg)
        self.stats["frames"] += 1
        self.stats["soldiers_sent"] = sum(len(g.entity_ids) for g in groups)

    async def run(self, frames: int | None = None) -> None:
        """Frames at ``fps`` (on trio's clock) until ``frames`` are sent or the link fails."""
        period = 1.0 / self.cfg.fps
        start = trio.current_time()
        n = 0
        while frames is None or n < frames:
            if self.link.failure:
                raise LinkError(self.link.failure)
            self.frame(n, int((trio.current_time() - start) * 1e5))  # CIGI timestamps: 10 µs ticks
            n += 1
            await trio.sleep_until(start + n * period)
