"""Entity requests (Figure 11's ``JackPackIn``) as a compact, vectorised binary batch.

A request is the DIS state TTES wants a soldier to show: appearance, weapon state, velocity, heading,
position, in Performer coordinates (metres, +Z up, heading in compass degrees clockwise from +Y). Many
requests travel in one frame; the whole frame is rejected, naming the first bad row, if any row is bad.
"""

from __future__ import annotations

import struct
from enum import IntEnum

import numpy as np

from protocol.errors import ErrorCode, WireError


class Appearance(IntEnum):
    """The TTES posture tokens (Figure 2: standing, kneeling, prone, destroyed; plus crawling), one enum for
    the entity requests, the server and the DIS gateway. 1..4 are the 1994 ``JACKTTES_*`` defines, CRAWL is
    new (1994: PRONE + velocity)."""

    DEAD = 1
    STAND = 2  # the DIS tokens' name (``ttes dis dump``)
    UPRIGHT = 2  # JACKTTES_UPRIGHT: an alias of STAND
    KNEEL = 3
    PRONE = 4
    CRAWL = 5


class WeaponState(IntEnum):
    """The TTES weapon tokens; 0 and 1 are the 1994 ``JACKTTES_WEAPON_*`` defines, FIRING is new. (DIS's own
    weapon field is :class:`protocol.dis.appearance.WeaponState`; DIS 'none' maps to STOWED.)"""

    STOWED = 0
    DEPLOYED = 1
    FIRING = 2


class Reaction(IntEnum):
    """What a REACT message asks a soldier to play once in place (docs/PROTOCOL.md §5): a Fire PDU's
    firing recoil or a near detonation's flinch."""

    RECOIL = 1
    FLINCH = 2


# The API dtype (native byte order) and the wire dtype (big-endian, packed, 33 bytes a row).
ENTITY_REQUEST_DTYPE = np.dtype(
    [
        ("index", np.uint16),
        ("appearance", np.uint8),
        ("weapon", np.uint8),
        ("velocity", np.float32, (3,)),
        ("heading", np.float32),
        ("position", np.float32, (3,)),
        ("immediate", np.uint8),
    ]
)
WIRE_ENTITY_DTYPE = np.dtype(
    [
        ("index", ">u2"),
        ("appearance", "u1"),
        ("weapon", "u1"),
        ("velocity", ">f4", (3,)),
        ("heading", ">f4"),
        ("position", ">f4", (3,)),
        ("immediate", "u1"),
    ]
)
assert WIRE_ENTITY_DTYPE.itemsize == 33
COUNT = struct.Struct(">H")
MAX_ROWS_PER_FRAME = 0xFFFF


def make_entity_requests(
    index: np.ndarray | list[int] | int,
    appearance: np.ndarray | list[int] | int = Appearance.UPRIGHT,
    weapon: np.ndarray | list[int] | int = WeaponState.DEPLOYED,
    velocity: np.ndarray | list | tuple = (0.0, 0.0, 0.0),
    heading: np.ndarray | list[float] | float = 0.0,
    position: np.ndarray | list | tuple = (0.0, 0.0, 0.0),
    immediate: np.ndarray | list[bool] | bool = False,
) -> np.ndarray:
    """Build a request batch (structured array of :data:`ENTITY_REQUEST_DTYPE`), broadcasting the columns."""
    idx = np.atleast_1d(np.asarray(index))
    rows = np.zeros(idx.shape[0], ENTITY_REQUEST_DTYPE)
    rows["index"] = idx
    rows["appearance"] = appearance
    rows["weapon"] = weapon
    rows["velocity"] = velocity
    rows["heading"] = heading
    rows["position"] = position
    rows["immediate"] = np.asarray(immediate).astype(np.uint8)
    return rows


def first_bad_row(rows: np.ndarray, max_soldiers: int) -> tuple[int, str] | None:
    """``(row, reason)`` for the first invalid request, or ``None``; vectorised over the batch."""
    app = rows["appearance"].astype(np.int64)
    wpn = rows["weapon"].astype(np.int64)
    with np.errstate(invalid="ignore"):  # signalling NaNs from the wire are reported below, not warned
        floats = np.concatenate(
            [rows["velocity"].astype(np.float64), rows["heading"][:, None], rows["position"]], axis=1
        )
    checks = [
        (rows["index"].astype(np.int64) >= max_soldiers, f"index >= max_soldiers {max_soldiers}"),
        ((app < Appearance.DEAD) | (app > Appearance.CRAWL), "appearance not in 1..5"),
        (wpn > WeaponState.FIRING, "weapon not in 0..2"),
        (rows["immediate"].astype(np.int64) > 1, "immediate not 0 or 1"),
        (~np.isfinite(floats).all(axis=1), "velocity, heading or position not finite"),
    ]
    bad = np.zeros(len(rows), bool)
    for mask, _ in checks:
        bad |= mask
    if not bad.any():
        return None
    row = int(np.flatnonzero(bad)[0])
    reasons = [why for mask, why in checks if mask[row]]
    return row, "; ".join(reasons)


def encode_entity_requests(rows: np.ndarray) -> bytes:
    """Payload of one ENTITY_REQUESTS frame: ``u16 count`` then ``count`` 33-byte rows."""
    if len(rows) > MAX_ROWS_PER_FRAME:
        raise ValueError(f"at most {MAX_ROWS_PER_FRAME} rows per frame")
    wire = np.empty(len(rows), WIRE_ENTITY_DTYPE)
    for name in ENTITY_REQUEST_DTYPE.names or ():
        wire[name] = rows[name]
    return COUNT.pack(len(rows)) + wire.tobytes()


def decode_entity_requests(payload: bytes, max_soldiers: int) -> np.ndarray:
    """Rows of an ENTITY_REQUESTS payload; :class:`WireError` naming the first bad row if any."""
    if len(payload) < 2:
        raise WireError(ErrorCode.MALFORMED_FRAME, "entity requests: missing row count")
    (count,) = COUNT.unpack_from(payload)
    expected = 2 + count * WIRE_ENTITY_DTYPE.itemsize
    if len(payload) != expected:
        raise WireError(
            ErrorCode.MALFORMED_FRAME,
            f"entity requests: {count} rows need {expected} payload bytes, got {len(payload)}",
        )
    wire = np.frombuffer(payload, WIRE_ENTITY_DTYPE, count=count, offset=2)
    with np.errstate(invalid="ignore"):
        rows = wire.astype(ENTITY_REQUEST_DTYPE)
    bad = first_bad_row(rows, max_soldiers)
    if bad is not None:
        raise WireError(ErrorCode.BAD_VALUE, bad[1], f"row {bad[0]}")
    return rows
