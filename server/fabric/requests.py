"""What a front-end sends a shard on ``requests/K``: its clients' requests for that shard's soldiers.

One msgpack map per message, ``op`` first: ``create`` (index, figure, weapon, owner: the front-end allocates
indices, so the one client-visible index space stays one), ``remove`` (index), ``requests`` (rows of
``protocol.entity.ENTITY_REQUEST_DTYPE`` as bytes, checked already by the front-end), ``react`` (index,
kind) and ``sync``: every soldier the shard is to animate (index, figure, weapon, owner) with the last
request of each that had one: what a shard that joined late, restarted or takes over another's soldiers
(failover) needs to animate them. The topic is reliable: ownership and requests are never lost once a
shard listens, and a sync covers the time before.
"""

from __future__ import annotations

from typing import Any

import msgpack
import numpy as np

from protocol.entity import ENTITY_REQUEST_DTYPE

OPS = ("create", "remove", "requests", "react", "sync")


def create(index: int, figure: str, weapon: str, owner: str | None) -> bytes:
    return _pack({"op": "create", "index": index, "figure": figure, "weapon": weapon, "owner": owner})


def remove(index: int) -> bytes:
    return _pack({"op": "remove", "index": index})


def requests(rows: np.ndarray) -> bytes:
    return _pack({"op": "requests", "rows": np.ascontiguousarray(rows, ENTITY_REQUEST_DTYPE).tobytes()})


def react(index: int, kind: str) -> bytes:
    return _pack({"op": "react", "index": index, "kind": kind})


def sync(soldiers: list[tuple[int, str, str, str | None]], last: np.ndarray) -> bytes:
    """``soldiers``: (index, figure, weapon, owner) each; ``last``: the last requests of those with one."""
    rows = np.ascontiguousarray(last, ENTITY_REQUEST_DTYPE).tobytes()
    return _pack({"op": "sync", "soldiers": [list(s) for s in soldiers], "rows": rows})


def decode(data: bytes) -> dict[str, Any]:
    """The message's map (``rows`` as an ENTITY_REQUEST_DTYPE array); ValueError if it is not one."""
    try:
        msg = msgpack.unpackb(data)
    except (ValueError, msgpack.UnpackException) as exc:
        raise ValueError(f"not a fabric request: {exc}") from exc
    if not isinstance(msg, dict) or msg.get("op") not in OPS:
        raise ValueError(f"not a fabric request: {msg!r:.80}")
    if msg["op"] in ("requests", "sync"):
        try:
            msg["rows"] = np.frombuffer(msg["rows"], ENTITY_REQUEST_DTYPE)
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"fabric {msg['op']} without rows: {exc}") from exc
    return msg


def _pack(msg: dict[str, Any]) -> bytes:
    return bytes(msgpack.packb(msg))
