"""What a front-end sends a shard on ``requests/K``: its clients' requests for that shard's soldiers.

A message is a msgpack list of operations (a front-end sends what one turn of its loop produced as one
message: a client creating a crowd makes thousands), each a map with ``op`` first: ``create`` (index,
figure, weapon, owner: the front-end allocates indices, so the one client-visible index space stays one),
``remove`` (index), ``requests`` (rows of ``protocol.entity.ENTITY_REQUEST_DTYPE`` as bytes, checked already
by the front-end), ``react`` (index, kind) and ``sync``: every soldier the shard is to animate (index,
figure, weapon, owner) with the last request of each that had one, and the soldiers gone (removed through a
front-end, perhaps before the shard listened: the shard removes those it has): what a shard that joined
late, restarted or takes over another's soldiers (failover) needs to animate them (``replay``: the shard's
own soldiers come home from a stand-in, replay every last request; ``id``: (front-end, stamp), the same
when sent again: a shard takes it once) and ``key``: send a key batch (every soldier, not only the changed
ones) at the next tick, for a front-end that lost a batch; a sync asks for one too; ``homes`` (shards): the
homes it animates now (a fail-over's stand-in, told again when one goes
home; a sync carries them too); ``settings`` (values, stamp): the front-end's server-wide settings (when
they change, and before each sync; the newest stamp wins); ``books`` (front): answer on ``ttes/books``
with every soldier the shard animates, for front-end ``front`` that has just heard the shard first
(:mod:`server.fabric.fronts`); ``fence`` (front, serial): the end of a message that created or removed
soldiers, echoed in the batches (:class:`~server.fabric.fronts.Fences`); on ``ttes/fronts`` only,
``clients`` (counts): a front-end's connections of client ids, ``failover`` (down, to, homes), ``back``
(shard): a fail-over ended. The topic is reliable: ownership and requests are never lost once a shard
listens, and a sync covers the time before.
"""

from __future__ import annotations

from typing import Any

import msgpack
import numpy as np

from protocol.entity import ENTITY_REQUEST_DTYPE
from server.fabric.batch import FENCE_MAX, MAX_FRONTS

OPS = (
    "create",
    "remove",
    "requests",
    "react",
    "sync",
    "key",
    "books",
    "fence",
    "clients",
    "homes",
    "settings",
    "failover",
    "back",
)
Op = dict[str, Any]


def create(index: int, figure: str, weapon: str, owner: str | None, gen: int = 0) -> Op:
    """``gen``: the index's generation (:func:`sync`)."""
    return {"op": "create", "index": index, "figure": figure, "weapon": weapon, "owner": owner, "gen": gen}


def remove(index: int, gen: int = 0) -> Op:
    return {"op": "remove", "index": index, "gen": gen}


def requests(rows: np.ndarray) -> Op:
    return {"op": "requests", "rows": np.ascontiguousarray(rows, ENTITY_REQUEST_DTYPE).tobytes()}


def react(index: int, kind: str) -> Op:
    return {"op": "react", "index": index, "kind": kind}


def sync(
    soldiers: list[tuple[int, str, str, str | None]],
    last: np.ndarray,
    *,
    replay: bool = False,
    gone: list[int] | None = None,
    homes: list[int] | None = None,
    gens: list[int] | None = None,
    gone_gens: list[int] | None = None,
    sync_id: tuple[int, int] | None = None,
) -> Op:
    """``soldiers``: (index, figure, weapon, owner) each; ``last``: the last requests of those with one;
    ``replay``: apply them to the soldiers the shard has too (they come home from a stand-in); ``gone``:
    soldiers removed, which the shard removes if it has them; ``homes``: as :func:`homes` (None: kept);
    ``gens`` and ``gone_gens``: the generation of each soldier and of each removal (an index's creations and
    removals count up, through every front-end and past a front-end's restart: :mod:`server.fabric.stamps`;
    a removal removes only a soldier created before it, not one created again through another front-end
    that the sender has not heard of yet; a shard creates no soldier whose index it saw removed at a newer
    generation); ``sync_id``: (front-end, stamp), the same when the front-end sends the sync again
    (``FrontNode``'s ask for ``books``): a shard that took it already only sends a key (no replay)."""
    rows = np.ascontiguousarray(last, ENTITY_REQUEST_DTYPE).tobytes()
    op = {
        "op": "sync",
        "soldiers": [list(s) for s in soldiers],
        "rows": rows,
        "replay": replay,
        "gone": list(gone or []),
    }
    if gens is not None:
        op["gens"] = list(gens)
    if gone_gens is not None:
        op["gone_gens"] = list(gone_gens)
    if sync_id is not None:
        op["id"] = list(sync_id)
    return op if homes is None else {**op, "homes": list(homes)}


def settings(values: dict[str, Any], stamp: tuple[int, int] = (0, -1)) -> Op:
    """The front-end's server-wide settings (:func:`server.fabric.settings.of`): the shards animate, so an
    operator's JCL and the front-end's own ``--throttle`` apply there; taken where they are at least as new
    (``stamp``: :data:`server.fabric.settings.Stamp`) as those held."""
    return {"op": "settings", "values": values, "stamp": list(stamp)}


def failover(down: int, to: int, homes: list[int]) -> Op:
    """On ``ttes/fronts``: a front-end failed shard ``down`` over to ``to`` (``homes``: the shards whose
    soldiers went): the others follow unless they heard ``down`` lately (``FrontNode.follow``)."""
    return {"op": "failover", "down": down, "to": to, "homes": list(homes)}


def back(shard: int) -> Op:
    """On ``ttes/fronts``: a front-end heard shard ``shard`` again and took its soldiers back from the
    stand-in: the others' following of its fail-over ends (``FrontNode.took_back``)."""
    return {"op": "back", "shard": shard}


def homes(shards: list[int]) -> Op:
    """The shards whose soldiers the shard animates from now on (its own, and those it stands in for): its
    answer to a late front-end's ``books`` names them, soldiers or none."""
    return {"op": "homes", "homes": list(shards)}


def key() -> Op:
    return {"op": "key"}


def fence(front: int, serial: int) -> Op:
    """The end of front-end ``front``'s message that created or removed soldiers: the shard's batches
    carry the newest serial taken (:class:`server.fabric.fronts.Fences`)."""
    return {"op": "fence", "front": front, "serial": serial}


def books(front: int) -> Op:
    return {"op": "books", "front": front}


def clients(counts: dict[str, int]) -> Op:
    """A front-end's open connections of each client id named (0: none now), for the other front-ends on
    ``ttes/fronts``: an id's soldiers wait for it while it is connected to any of them."""
    return {"op": "clients", "counts": counts}


def pack(ops: list[Op]) -> bytes:
    return bytes(msgpack.packb(ops))


def decode(data: bytes) -> list[Op]:
    """The message's operations (``rows`` as ENTITY_REQUEST_DTYPE arrays); ValueError if it is not one."""
    try:
        ops = msgpack.unpackb(data)
    except (ValueError, msgpack.UnpackException) as exc:
        raise ValueError(f"not a fabric request: {exc}") from exc
    if not isinstance(ops, list):
        raise ValueError(f"not a list of fabric requests: {ops!r:.80}")
    return [_checked(op) for op in ops]


def _checked(op: object) -> Op:
    if not isinstance(op, dict) or op.get("op") not in OPS:
        raise ValueError(f"not a fabric request: {op!r:.80}")
    if op["op"] in ("requests", "sync"):
        try:
            op["rows"] = np.frombuffer(op["rows"], ENTITY_REQUEST_DTYPE)
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"fabric {op['op']} without rows: {exc}") from exc
    if op["op"] == "clients":
        counts = op.get("counts")
        if not isinstance(counts, dict) or not all(
            isinstance(c, str) and isinstance(n, int) and n >= 0 for c, n in counts.items()
        ):
            raise ValueError(f"fabric clients without counts: {counts!r:.80}")
    if op["op"] == "fence":  # its numbers size the shard's list of fences and travel in every batch
        front, serial = op.get("front"), op.get("serial")
        if not (isinstance(front, int) and 0 <= front < MAX_FRONTS):
            raise ValueError(f"fabric fence of front-end {front!r:.20} (0 to {MAX_FRONTS - 1})")
        if not (isinstance(serial, int) and 0 <= serial <= FENCE_MAX):
            raise ValueError(f"fabric fence serial {serial!r:.20} (0 to {FENCE_MAX})")
    return op
