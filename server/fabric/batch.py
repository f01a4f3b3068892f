"""One shard's tick on the fabric: the quantised codes of its soldiers, as one message.

The codes are the pose board's (``PoseBoard.codes``: the update table's field values, each at most 16 bits,
docs/PROTOCOL.md §7), sent as uint16 with the soldiers' indices (uint32) and table ids (uint8). A front-end
merges them into its own board and encodes them for its clients with the shared encoding: nothing is
re-quantised on the way. A *key* batch carries every soldier the shard animates; the others only the
soldiers whose codes changed since the shard's previous batch (the front-end's board keeps the rest).
Its ``fences`` say which of each front-end's requests messages the shard had taken when it sent the batch
(:class:`server.fabric.fronts.Fences`: a front-end drops the rows of an index it removed or created again
from the batches sent before the shard heard of it).

A batch holds the soldiers of one block of indices (``block``; its ``seq`` counts that block's batches,
so a front-end that hears some blocks sees the gaps of those) or a tick's *pulse* (``PULSE``, its ``seq``
counts the shard's ticks; a key tick's names every soldier the shard animates, without codes), which every
front-end hears whatever its clients watch.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

MAGIC = b"TTB5"
PULSE = 0xFFFF  # the block of a shard's tick pulse (no soldiers)
MAX_FRONTS = 255  # front-ends whose fences a batch carries: their count is one byte of the header
FENCE_MAX = 2**32 - 1  # a fence serial travels as uint32
# magic, shard, shards, seq, tick, sent (monotonic s), soldiers, fields, flags (1: key, 2: answer), block,
# fronts (uint32 fences follow)
_HEAD = struct.Struct("<4sHHIIdIIBHB")


@dataclass(frozen=True)
class Batch:
    shard: int
    shards: int
    seq: int  # the shard's batch count: a gap is a lost batch
    tick: int  # the shard's tick number
    sent: float  # time.monotonic() at publish (one host's clock: latency on one machine only)
    indices: np.ndarray  # (n,) soldier indices, the one client-visible index space
    tables: np.ndarray  # (n,) update table ids
    codes: np.ndarray  # (n, F) field codes
    key: bool = True  # every soldier of the shard (else: those changed since its previous batch)
    block: int = 0  # the index block of its soldiers (PULSE: a tick's pulse)
    fences: tuple[int, ...] = ()  # per front-end, the newest fence it sent that the shard had taken (0: none)
    answer: bool = False  # an answer's (between ticks, or a tick's first frames), not a tick's


def encode_batch(batch: Batch) -> bytes:
    n = len(batch.indices)
    nf = batch.codes.shape[1] if batch.codes.ndim == 2 else 0
    if batch.codes.size and (batch.codes.min() < 0 or batch.codes.max() > 0xFFFF):
        raise ValueError("codes beyond 16 bits")
    b = batch
    flags = b.key | b.answer << 1
    head = _HEAD.pack(MAGIC, b.shard, b.shards, b.seq, b.tick, b.sent, n, nf, flags, b.block, len(b.fences))
    return b"".join(
        (
            head,
            np.asarray(batch.fences, "<u4").tobytes(),
            np.ascontiguousarray(batch.indices, "<u4").tobytes(),
            np.ascontiguousarray(batch.tables, "u1").tobytes(),
            np.ascontiguousarray(batch.codes, "<u2").tobytes(),
        )
    )


def decode_batch(data: bytes) -> Batch:
    """The batch of ``data`` (arrays are read-only views of it); ValueError if it is not one."""
    if len(data) < _HEAD.size:
        raise ValueError(f"a batch of {len(data)} bytes")
    magic, shard, shards, seq, tick, sent, n, nf, flags, block, nb = _HEAD.unpack_from(data)
    if magic != MAGIC or len(data) != _HEAD.size + 4 * nb + n * (5 + 2 * nf):
        raise ValueError(f"not a batch (magic {magic!r}, {len(data)} bytes for {n} x {nf})")
    fences = tuple(np.frombuffer(data, "<u4", nb, _HEAD.size).tolist())
    at = _HEAD.size + 4 * nb
    indices = np.frombuffer(data, "<u4", n, at)
    tables = np.frombuffer(data, "u1", n, at + 4 * n)
    codes = np.frombuffer(data, "<u2", n * nf, at + 5 * n).reshape(n, nf)
    key, answer = bool(flags & 1), bool(flags & 2)
    return Batch(shard, shards, seq, tick, sent, indices, tables, codes, key, block, fences, answer)
