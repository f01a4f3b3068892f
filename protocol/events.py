"""Events of the TTES wire protocol: what ``Connection.next_event`` yields and ``Connection.send`` takes.

Every event is a frozen dataclass. The ones carrying numpy arrays (``EntityRequests``, ``JointUpdates``)
compare by identity (``eq=False``): compare their arrays yourself.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from protocol.figure import WireFigure
from protocol.framing import DEFAULT_MAX_FRAME
from protocol.update_table import UpdateTable

PROTOCOL_VERSION = 2  # 2: per-entry widths and predicted deltas in JOINT_UPDATES (docs/PROTOCOL.md §8.5)
SUPPORTED_VERSIONS = (1, 2)
DEFAULT_MAX_SOLDIERS = 16384
ROLES = ("observer", "controller", "operator")  # in order of rights: each may do what the one before may
MAX_CLIENT_ID = 64  # characters of a HELLO client_id


class Event:
    """Base class of all protocol events."""


@dataclass(frozen=True)
class Hello(Event):
    """Client → server, first frame: who I am, the role I ask for and the largest frame I accept.

    ``client_id`` names the client across connections (its soldiers are owned by it and reclaimed when it
    reconnects; "" = anonymous: the server picks a fresh id). ``token`` is the credential of the role when
    the server has tokens configured ("" = none). Both are optional on the wire (older clients omit them)."""

    name: str
    role: str = "controller"
    max_frame: int = DEFAULT_MAX_FRAME
    version: int = PROTOCOL_VERSION
    client_id: str = ""
    token: str = field(default="", repr=False)


@dataclass(frozen=True)
class Accept(Event):
    """Server → client, answer to Hello: the version spoken and the server's limits."""

    name: str
    max_frame: int = DEFAULT_MAX_FRAME
    max_soldiers: int = DEFAULT_MAX_SOLDIERS
    version: int = PROTOCOL_VERSION
    client_id: str = ""  # the id the server knows this client by (the HELLO's, or a fresh anonymous one)
    role: str = ""  # the role granted ("" from servers that grant none)


@dataclass(frozen=True)
class Error(Event):
    """Either direction: ``code`` from :class:`ErrorCode` (< 100 fatal), ``ref`` the request id or None."""

    code: int
    message: str
    ref: int | None = None


@dataclass(frozen=True)
class Goodbye(Event):
    reason: str = ""


@dataclass(frozen=True)
class Ping(Event):
    nonce: int = 0


@dataclass(frozen=True)
class Pong(Event):
    nonce: int = 0


@dataclass(frozen=True)
class Jcl(Event):
    """Client → server: JCL command text, e.g. ``read_file("jack-ttes-soldier_low.jcl");``."""

    text: str
    id: int = 0


@dataclass(frozen=True)
class Ready(Event):
    """Server → client: what ``start_ttes_socket_simulation()`` signals; soldiers as (index, table) pairs.

    ``tick_hz`` and ``throttle`` (seconds) tell a client what update rate to expect: a soldier that keeps
    moving is updated every ``k``-th tick, ``k`` the smallest with ``k / tick_hz >= throttle - 1 / (2
    tick_hz)`` (:func:`ticks_per_update`).
    """

    soldiers: tuple[tuple[int, int], ...] = ()
    tick_hz: float = 30.0
    throttle: float = 1 / 30


@dataclass(frozen=True)
class Status(Event):
    """Server → client, every ``set_ttes_report_interval`` seconds."""

    time: float
    soldiers: int
    update_rate: float
    text: str = ""


@dataclass(frozen=True)
class Settings(Event):
    """Server → client: this connection's own settings, sent after READY and whenever one changes.

    ``throttle`` (seconds, a rate cap as READY's, never below the server's) and ``report_interval`` (the
    STATUS period in seconds) are per connection: ``set_ttes_soldier_throttle`` and
    ``set_ttes_report_interval`` from a client change only its own."""

    throttle: float
    report_interval: float


@dataclass(frozen=True)
class SoldierRemoved(Event):
    """Server → client: soldier ``index`` is gone (removed by its owner or an operator, or its owner left
    and did not come back within the grace period); ``reason`` is free text."""

    index: int
    reason: str = ""


@dataclass(frozen=True)
class CreateSoldier(Event):
    """Client → server: a soldier of ``figure`` carrying ``weapon`` ("" = none) at ``index`` or a free one."""

    id: int
    figure: str = "DI.fig"
    weapon: str = "AK_47.fig"
    index: int | None = None


@dataclass(frozen=True)
class SoldierCreated(Event):
    """Server → client, answer to CreateSoldier ``id``: the soldier's index and its update table."""

    id: int
    index: int
    table: int


@dataclass(frozen=True)
class RemoveSoldier(Event):
    index: int


@dataclass(frozen=True)
class Subscribe(Event):
    """Client → server: send me joint updates for these soldiers (a full update first)."""

    indices: tuple[int, ...]


@dataclass(frozen=True)
class Unsubscribe(Event):
    indices: tuple[int, ...]


@dataclass(frozen=True)
class RequestFullUpdate(Event):
    """Client → server: resend these soldiers in full (empty = every subscribed soldier)."""

    indices: tuple[int, ...] = ()


@dataclass(frozen=True)
class React(Event):
    """Client → server: these soldiers play a reaction once (``protocol.entity.Reaction``)."""

    kind: int
    indices: tuple[int, ...] = ()


@dataclass(frozen=True, eq=False)
class EntityRequests(Event):
    """Client → server: a batch of JackPackIn requests (:data:`protocol.entity.ENTITY_REQUEST_DTYPE` rows)."""

    rows: np.ndarray


@dataclass(frozen=True)
class UpdateTableMsg(Event):
    """Server → client: the update table that JointUpdates with this ``table_id`` are read with."""

    table: UpdateTable


@dataclass(frozen=True)
class RequestFigure(Event):
    """Client → server: send the FIGURE of update table ``table`` (``meshes``: with the segment surfaces)."""

    id: int
    table: int
    meshes: bool = False


@dataclass(frozen=True, eq=False)
class FigureMsg(Event):
    """Server → client: the skeleton of every figure of update table ``table`` (``protocol.figure``), in
    figure-entry order; ``body`` is the msgpack map as sent (encoders take it as it is)."""

    table: int
    figures: tuple[WireFigure, ...]
    body: dict[str, Any] = field(repr=False, default_factory=dict)


@dataclass(frozen=True, eq=False)
class JointUpdates(Event):
    """Server → client: soldier poses for one update table at server tick ``tick``.

    On send: the *current* pose of any soldiers; the connection sends only subscribed soldiers and only the
    entries that changed since that client last received them. On receive: the reconstructed current pose of
    the soldiers in the frame, and ``changed`` (n, entries) saying which entries the frame carried.
    ``dofs`` (n, D) radians/metres in table order; ``positions`` (n, G, 3) metres; ``orientations``
    (n, G, 4) unit quaternions (w, x, y, z); G = figure entries in table order.
    """

    table: int
    indices: np.ndarray
    dofs: np.ndarray
    positions: np.ndarray
    orientations: np.ndarray
    tick: int = 0
    changed: np.ndarray | None = None


@dataclass(frozen=True)
class ProtocolError(Event):
    """Local event: the peer broke the protocol (``code`` < 100). The connection is now ERROR and has queued
    an Error frame for the peer in :meth:`Connection.data_to_send`."""

    code: int
    message: str
    location: str = ""


@dataclass(frozen=True, eq=False)
class UpdateHeaders(Event):
    """Local event of a client ``Connection(decode_updates=False)``: one JOINT_UPDATES frame's table, tick and
    soldier indices, its poses not decoded (a load generator's cheap tap: decoding costs as much as the
    server's encoding)."""

    table: int
    tick: int
    indices: np.ndarray


@dataclass(frozen=True)
class ConnectionClosed(Event):
    """Local event: the stream ended cleanly (EOF on a frame boundary) or the connection is CLOSED/ERROR."""


def ticks_per_update(tick_hz: float, throttle: float) -> int:
    """Ticks between two updates of a soldier that keeps changing: the throttle is a rate cap on the tick
    grid (a soldier is due when its last update is at least ``throttle - tick / 2`` old)."""
    period = 1.0 / tick_hz
    return max(1, math.ceil((throttle - period / 2) / period - 1e-9))
