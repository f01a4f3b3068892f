"""The publish/subscribe fabric between shards and front-ends (issue 21), behind one small interface.

A shard (``ttes server --shard K/N``) publishes each tick's quantised codes as one batch on ``poses/K/all``
while some front-end hears the whole shard, and one batch per block of soldier indices on ``poses/K/B``
(block B: indices ``B * block`` up to the next block, :data:`BLOCK`) for each block some front-end hears
alone (the fabric tells a publisher whether its topic has subscribers: nothing goes where nobody
listens); each tick a header-only *pulse* on ``poses/K`` (it lives, and which tick); it takes the requests
for its soldiers from ``requests/K``. A front-end (``ttes front``) subscribes to every shard's pulse and to
the blocks its clients watch, or to the whole shard when they watch every block that holds a soldier (one
batch a shard a tick: the same rows in the fewest messages), and publishes its clients' requests to the
owning shard. The engine is an existing one, chosen by name:
Eclipse Zenoh (``zenoh``, the default: see docs/SCALING.md for the measurements) or Eclipse Cyclone DDS
(``dds``). Each adapter imports its library when it is opened, never at import time of ``ttes server``
(the ``[fabric]`` extra; an import-linter contract keeps the libraries inside their adapters).

Quality of service by what a topic carries (:class:`Kind`): poses are best-effort and latest-wins (a late
batch is superseded by the next tick's, never queued), requests are reliable and kept until delivered.
"""

from __future__ import annotations

import enum
import random
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

ENGINES = ("zenoh", "dds")
DEFAULT_PORT = 7447
BLOCK = 4096  # soldier indices per pose topic (``--fabric-block``: shards and front-ends must agree)
WHOLE = 0xFFFE  # the stream of a shard's whole batches (``poses/K/all``), beside its blocks 0, 1, ...


class Kind(enum.Enum):
    """What a topic carries, which sets its quality of service."""

    POSES = "poses"  # best-effort, keep-last-1: a newer batch supersedes a lost or late one
    REQUESTS = "requests"  # reliable, keep-all: requests, creations and removals (ownership) all arrive


def poses_topic(shard: int, block: int | None = None) -> str:
    """Shard ``shard``'s batches of soldier index block ``block`` (:data:`WHOLE`: of all its soldiers);
    its pulse without a block."""
    if block is None:
        return f"ttes/poses/{shard}"
    return f"ttes/poses/{shard}/all" if block == WHOLE else f"ttes/poses/{shard}/{block}"


def requests_topic(shard: int) -> str:
    return f"ttes/requests/{shard}"


def fronts_topic() -> str:
    """Where front-ends tell each other the soldiers they create and remove (``ttes front --front K/M``)."""
    return "ttes/fronts"


def books_topic() -> str:
    """Where a shard answers a front-end's ``books`` with the soldiers it animates (a late front-end)."""
    return "ttes/books"


def alive_key(shard: int) -> str:
    return f"ttes/alive/{shard}"


def front_alive_key(front: int) -> str:
    """Front-end ``front`` of several is on the fabric (the others count its clients' connections)."""
    return f"ttes/alive/front/{front}"


Handler = Callable[[bytes], None]  # called on the fabric's own thread, once per message
Presence = Callable[[bool], None]  # called on the fabric's own thread: present (True) or gone (False)
Unsubscribe = Callable[[], None]  # ends a subscription (a message already in flight may still come)


class Changes:
    """Calls ``on_change`` with a state only when it differs from the last one told (an adapter's matching:
    the state at declaration and its listener's changes may come in either order, from two threads)."""

    def __init__(self, on_change: Presence) -> None:
        self.on_change = on_change
        self.state: bool | None = None
        self.lock = threading.Lock()

    def __call__(self, state: bool) -> None:
        with self.lock:  # (told inside: two changes are told in the order they were made)
            if state != self.state:
                self.state = state
                self.on_change(state)


class Fabric(Protocol):
    """One process's node on the fabric."""

    engine: str

    def publisher(self, topic: str, kind: Kind, on_match: Presence | None = None) -> Handler:
        """A function that publishes one message (bytes) on ``topic``. With ``on_match``: called (on the
        fabric's thread, or at once for the state at declaration) with True when the topic has gained a
        subscriber on the fabric, False when its last one has gone (Zenoh's matching status, DDS's
        publication-matched status): a shard publishes no pose stream nobody hears."""
        ...

    def subscribe(self, topic: str, kind: Kind, on_message: Handler) -> Unsubscribe:
        """Call ``on_message`` (on the fabric's thread) with every message published on ``topic``, until
        the returned function is called."""
        ...

    def announce(self, key: str) -> None:
        """Be present under ``key`` while this node lives (gone when its process dies or it closes)."""
        ...

    def watch(self, key: str, on_change: Presence) -> None:
        """Call ``on_change`` when a node announced under ``key`` appears (True) or goes (False)."""
        ...

    def close(self) -> None: ...


DDS_DOMAIN_MAX = 232  # the highest DDS domain id (DDSI-RTPS 2.x port mapping: 7400 + 250 * domain < 65536)


def engine_flags(engine: str) -> list[str]:
    """The ``ttes server`` / ``ttes front`` flags of a run of its own on ``engine``: for DDS a random domain,
    since DDS nodes of another run on this host (the same loopback peers) would join this one (the tests'
    and the benches' clusters: a DDS bench failed 3 of 6 runs with "server closed the connection" while
    another run used domain 0)."""
    if engine != "dds":
        return ["--fabric", engine]
    return ["--fabric", engine, "--fabric-domain", str(random.randrange(1, DDS_DOMAIN_MAX + 1))]


@dataclass(frozen=True)
class FabricConfig:
    """Where this node listens and whom it connects to: unicast endpoints ``host:port``, no multicast.

    Zenoh (peer mode) listens on ``listen`` and connects to ``connect``; Cyclone DDS uses the hosts of
    ``listen`` and ``connect`` as its unicast peers (on a domain of its own, ``domain``)."""

    engine: str = "zenoh"
    listen: str = ""  # "" = no listener (Zenoh); a front-end listens, shards connect to it
    connect: tuple[str, ...] = field(default_factory=tuple)
    domain: int = 0


def open_fabric(config: FabricConfig) -> Fabric:
    """A node on the configured engine (ModuleNotFoundError without the ``[fabric]`` extra). The process
    keeps freed memory from then on (:mod:`server.fabric.heap`: each tick's whole-batch buffers page-faulted
    anew, on either engine)."""
    from server.fabric.heap import keep_freed_memory

    keep_freed_memory()
    if config.engine == "zenoh":
        from server.fabric.zenoh_node import ZenohFabric

        return ZenohFabric(config)
    if config.engine == "dds":
        from server.fabric.dds_node import DdsFabric

        return DdsFabric(config)
    raise ValueError(f"no fabric engine {config.engine!r} (have {', '.join(ENGINES)})")
