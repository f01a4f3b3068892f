"""Message types and the codec of the stateless messages (handshake and msgpack control messages).

Each control message body is one msgpack map with string keys, checked field by field on receipt: a missing
field or a field of the wrong type is a SCHEMA error, a value out of range (or NaN/inf) a BAD_VALUE error.
Unknown keys are ignored, so later minor versions can add optional fields.
"""

from __future__ import annotations

import builtins  # Body names methods str/int/float: its later annotations spell the types out
import math
import struct
from collections.abc import Callable, Mapping
from enum import IntEnum
from types import MappingProxyType
from typing import Any

import msgpack
import numpy as np

from protocol.entity import Reaction, decode_entity_requests, encode_entity_requests
from protocol.errors import ErrorCode, WireError
from protocol.events import (
    MAX_CLIENT_ID,
    ROLES,
    SUPPORTED_VERSIONS,
    Accept,
    CreateSoldier,
    EntityRequests,
    Error,
    Event,
    FigureMsg,
    Goodbye,
    Hello,
    Jcl,
    JointUpdates,
    Ping,
    Pong,
    React,
    Ready,
    RemoveSoldier,
    RequestFigure,
    RequestFullUpdate,
    Settings,
    SoldierCreated,
    SoldierRemoved,
    Status,
    Subscribe,
    Unsubscribe,
    UpdateTableMsg,
)
from protocol.figure import figure_from_wire
from protocol.framing import MIN_CLIENT_MAX_FRAME, MIN_MAX_FRAME
from protocol.update_table import table_from_wire, table_to_wire

MAGIC = b"TTES"
HANDSHAKE_PREFIX = struct.Struct(">4sH")  # magic, version
U32 = 0xFFFFFFFF
U64 = 0xFFFFFFFFFFFFFFFF
MAX_SOLDIERS_LIMIT = 0x10000  # soldier indices are u16 on the wire


class MessageType(IntEnum):
    """The type byte of a frame. HELLO, ACCEPT and ERROR keep their numbers and layouts in every version."""

    HELLO = 0x01
    ACCEPT = 0x02
    ERROR = 0x03
    GOODBYE = 0x04
    PING = 0x05
    PONG = 0x06
    JCL = 0x10
    READY = 0x11
    STATUS = 0x12
    SETTINGS = 0x13
    CREATE_SOLDIER = 0x20
    SOLDIER_CREATED = 0x21
    REMOVE_SOLDIER = 0x22
    SUBSCRIBE = 0x23
    UNSUBSCRIBE = 0x24
    REQUEST_FULL_UPDATE = 0x25
    SOLDIER_REMOVED = 0x26
    REACT = 0x27
    REQUEST_FIGURE = 0x28
    ENTITY_REQUESTS = 0x30
    UPDATE_TABLE = 0x31
    JOINT_UPDATES = 0x32
    FIGURE = 0x33


BOTH = frozenset({MessageType.ERROR, MessageType.GOODBYE, MessageType.PING, MessageType.PONG})
CLIENT_SENDS = BOTH | {
    MessageType.HELLO,
    MessageType.JCL,
    MessageType.CREATE_SOLDIER,
    MessageType.REMOVE_SOLDIER,
    MessageType.SUBSCRIBE,
    MessageType.UNSUBSCRIBE,
    MessageType.REQUEST_FULL_UPDATE,
    MessageType.REACT,
    MessageType.REQUEST_FIGURE,
    MessageType.ENTITY_REQUESTS,
}
SERVER_SENDS = BOTH | {
    MessageType.ACCEPT,
    MessageType.READY,
    MessageType.STATUS,
    MessageType.SETTINGS,
    MessageType.SOLDIER_CREATED,
    MessageType.SOLDIER_REMOVED,
    MessageType.UPDATE_TABLE,
    MessageType.JOINT_UPDATES,
    MessageType.FIGURE,
}


# -- field-by-field schema checks ---------------------------------------------------------------------------


class Body:
    """A received msgpack map, read one typed field at a time."""

    def __init__(self, raw: Any, what: str) -> None:
        if not isinstance(raw, dict):
            raise WireError(ErrorCode.SCHEMA, f"body is {type(raw).__name__}, not a map", what)
        self.raw = raw
        self.what = what

    def _get(self, key: str) -> Any:
        if key not in self.raw:
            raise WireError(ErrorCode.SCHEMA, f"missing field {key!r}", self.what)
        return self.raw[key]

    def _type(self, key: str, value: Any, want: str) -> WireError:
        return WireError(
            ErrorCode.SCHEMA, f"field {key!r} must be {want}, got {type(value).__name__}", self.what
        )

    def _range(self, key: str, msg: str) -> WireError:
        return WireError(ErrorCode.BAD_VALUE, f"field {key!r} {msg}", self.what)

    def str(self, key: str, *, nonempty: bool = False) -> str:
        v = self._get(key)
        if not isinstance(v, str):
            raise self._type(key, v, "a string")
        if nonempty and not v:
            raise self._range(key, "must not be empty")
        return v

    def optional_str(self, key: builtins.str, max_len: builtins.int) -> builtins.str:
        """A string field a later minor version added: "" when absent, at most ``max_len`` characters."""
        if key not in self.raw:
            return ""
        v = self.str(key)
        if len(v) > max_len:
            raise self._range(key, f"is longer than {max_len} characters")
        return v

    def int(self, key: builtins.str, lo: int, hi: int, *, nullable: bool = False) -> Any:
        v = self._get(key)
        if v is None and nullable:
            return None
        if not isinstance(v, int) or isinstance(v, bool):
            raise self._type(key, v, "an int" + (" or nil" if nullable else ""))
        if not lo <= v <= hi:
            raise self._range(key, f"= {v} not in {lo}..{hi}")
        return v

    def float(self, key: builtins.str, lo: builtins.float = -math.inf) -> builtins.float:
        v = self._get(key)
        if not isinstance(v, int | float) or isinstance(v, bool):
            raise self._type(key, v, "a number")
        v = float(v)
        if not math.isfinite(v) or v < lo:
            raise self._range(key, f"= {v} must be finite and >= {lo}")
        return v

    def ints(
        self, key: builtins.str, lo: builtins.int, hi: builtins.int, *, width: builtins.int = 0
    ) -> np.ndarray:
        """A list of ints (``width`` > 0: a list of ``width``-int lists), checked in one numpy pass."""
        v = self._get(key)
        if not isinstance(v, list):
            raise self._type(key, v, "a list")
        shape = (len(v), width) if width else (len(v),)
        if not v:
            return np.zeros(shape, np.int64)
        try:
            arr = np.asarray(v)
        except (ValueError, TypeError):
            arr = np.zeros(0, object)
        flat = (x for row in v for x in row) if width and arr.shape == shape else v
        if arr.dtype.kind not in "iu" or arr.shape != shape or any(isinstance(x, bool) for x in flat):
            want = f"a list of [{width} ints]" if width else "a list of ints"
            raise WireError(ErrorCode.SCHEMA, f"field {key!r} must be {want}", self.what)
        bad = (arr < lo) | (arr > hi)
        if bad.any():
            at = int(np.flatnonzero(bad.reshape(len(v), -1).any(axis=1))[0])
            raise self._range(key, f"item {at} not in {lo}..{hi}")
        return arr.astype(np.int64)


def unpack_body(payload: bytes, what: str) -> Body:
    try:
        raw = msgpack.unpackb(payload, raw=False, strict_map_key=True, use_list=True)
    except Exception as exc:  # any msgpack failure on untrusted bytes is one SCHEMA error
        raise WireError(
            ErrorCode.SCHEMA, f"undecodable msgpack ({type(exc).__name__}: {exc})", what
        ) from None
    return Body(raw, what)


def pack_body(body: dict[str, Any], *, single_float: bool = False) -> bytes:
    return msgpack.packb(body, use_bin_type=True, use_single_float=single_float)


# -- per message ------------------------------------------------------------------------------------------


def _handshake(payload: bytes, what: str) -> tuple[int, bytes]:
    if len(payload) < HANDSHAKE_PREFIX.size:
        raise WireError(ErrorCode.MALFORMED_FRAME, "shorter than magic + version", what)
    magic, version = HANDSHAKE_PREFIX.unpack_from(payload)
    if magic != MAGIC:
        raise WireError(ErrorCode.BAD_MAGIC, f"magic {magic!r} is not {MAGIC!r}", what)
    if version not in SUPPORTED_VERSIONS:
        raise WireError(
            ErrorCode.UNSUPPORTED_VERSION,
            f"protocol version {version} is not supported; supported: {list(SUPPORTED_VERSIONS)}",
            what,
        )
    return version, payload[HANDSHAKE_PREFIX.size :]


def handshake_version(payload: bytes) -> int | None:
    """The version field of a HELLO/ACCEPT payload, if it has one (for error messages)."""
    if len(payload) < HANDSHAKE_PREFIX.size:
        return None
    return int(HANDSHAKE_PREFIX.unpack_from(payload)[1])


def _dec_hello(payload: bytes, ctx: int) -> Hello:
    version, rest = _handshake(payload, "HELLO")
    b = unpack_body(rest, "HELLO")
    role = b.str("role")
    if role not in ROLES:
        raise WireError(ErrorCode.BAD_VALUE, f"role {role!r} not in {ROLES}", "HELLO")
    client_id = b.optional_str("client_id", MAX_CLIENT_ID)
    if client_id.startswith("~") or not client_id.isprintable():
        raise WireError(
            ErrorCode.BAD_VALUE, "field 'client_id' must be printable, not start with '~'", "HELLO"
        )
    name, max_frame = b.str("name", nonempty=True), b.int("max_frame", 0, U32)
    if max_frame < MIN_CLIENT_MAX_FRAME:
        raise WireError(
            ErrorCode.BAD_VALUE,
            f"max_frame {max_frame} is below {MIN_CLIENT_MAX_FRAME}, the least a client may announce: "
            "UPDATE_TABLE and FIGURE (without meshes) must each fit in one frame",
            "HELLO",
        )
    return Hello(name, role, max_frame, version, client_id, b.optional_str("token", 1024))


def _dec_accept(payload: bytes, ctx: int) -> Accept:
    version, rest = _handshake(payload, "ACCEPT")
    b = unpack_body(rest, "ACCEPT")
    return Accept(
        b.str("name", nonempty=True),
        b.int("max_frame", MIN_MAX_FRAME, U32),
        b.int("max_soldiers", 1, MAX_SOLDIERS_LIMIT),
        version,
        b.optional_str("client_id", MAX_CLIENT_ID + 16),
        b.optional_str("role", 16),
    )


def _enc_handshake(version: int, body: dict[str, Any], optional: Mapping[str, str] | None = None) -> bytes:
    """Prefix + body; the ``optional`` string fields go in only when not empty (older peers omit them)."""
    body = body | {k: v for k, v in (optional or {}).items() if v}
    return HANDSHAKE_PREFIX.pack(MAGIC, version) + pack_body(body)


def _indices(b: Body, key: str, max_soldiers: int) -> tuple[int, ...]:
    return tuple(b.ints(key, 0, max_soldiers - 1).tolist())


def _dec_error(p: bytes, n: int) -> Error:
    b = unpack_body(p, "ERROR")
    return Error(b.int("code", 0, 0xFFFF), b.str("message"), b.int("ref", 0, U32, nullable=True))


def _dec_jcl(p: bytes, n: int) -> Jcl:
    b = unpack_body(p, "JCL")
    return Jcl(b.str("text"), b.int("id", 0, U32))


def _dec_ready(p: bytes, n: int) -> Ready:
    b = unpack_body(p, "READY")
    pairs = b.ints("soldiers", 0, 0xFFFF, width=2)
    if (pairs[:, 0] >= n).any():
        raise WireError(ErrorCode.BAD_VALUE, f"field 'soldiers': index >= max_soldiers {n}", "READY")
    tick_hz = b.float("tick_hz", 0.0)
    if tick_hz <= 0.0:
        raise WireError(ErrorCode.BAD_VALUE, f"field 'tick_hz' = {tick_hz} must be > 0", "READY")
    return Ready(tuple((int(i), int(t)) for i, t in pairs.tolist()), tick_hz, b.float("throttle", 0.0))


def _enc_ready(e: Ready) -> bytes:
    soldiers = [list(s) for s in e.soldiers]
    return pack_body({"soldiers": soldiers, "tick_hz": float(e.tick_hz), "throttle": float(e.throttle)})


def _dec_status(p: bytes, n: int) -> Status:
    b = unpack_body(p, "STATUS")
    return Status(b.float("time"), b.int("soldiers", 0, U32), b.float("update_rate", 0.0), b.str("text"))


def _dec_create(p: bytes, n: int) -> CreateSoldier:
    b = unpack_body(p, "CREATE_SOLDIER")
    return CreateSoldier(
        b.int("id", 0, U32),
        b.str("figure", nonempty=True),
        b.str("weapon"),
        b.int("index", 0, n - 1, nullable=True),
    )


def _dec_created(p: bytes, n: int) -> SoldierCreated:
    b = unpack_body(p, "SOLDIER_CREATED")
    return SoldierCreated(b.int("id", 0, U32), b.int("index", 0, n - 1), b.int("table", 0, 0xFFFF))


def _dec_react(p: bytes, n: int) -> React:
    b = unpack_body(p, "REACT")
    return React(b.int("kind", min(Reaction), max(Reaction)), _indices(b, "indices", n))


def _enc_status(e: Status) -> bytes:
    return pack_body(
        {"time": float(e.time), "soldiers": e.soldiers, "update_rate": float(e.update_rate), "text": e.text}
    )


def _dec_settings(p: bytes, n: int) -> Settings:
    b = unpack_body(p, "SETTINGS")
    return Settings(b.float("throttle", 0.0), b.float("report_interval", 0.0))


def _dec_request_figure(p: bytes, n: int) -> RequestFigure:
    b = unpack_body(p, "REQUEST_FIGURE")
    meshes = b.raw.get("meshes", False)
    if not isinstance(meshes, bool):
        raise WireError(ErrorCode.SCHEMA, "field 'meshes' must be a bool", "REQUEST_FIGURE")
    return RequestFigure(b.int("id", 0, U32), b.int("table", 0, 0xFFFF), meshes)


def _dec_figure(p: bytes, n: int) -> FigureMsg:
    raw = unpack_body(p, "FIGURE").raw
    table, figures = figure_from_wire(raw)
    return FigureMsg(table, figures, raw)


def _dec_removed(p: bytes, n: int) -> SoldierRemoved:
    b = unpack_body(p, "SOLDIER_REMOVED")
    return SoldierRemoved(b.int("index", 0, n - 1), b.str("reason"))


Encoder = Callable[[Any], bytes]
Decoder = Callable[[bytes, int], Event]

# type -> (event class, encode(event) -> payload, decode(payload, max_soldiers) -> event)
_CODECS: dict[MessageType, tuple[type[Event], Encoder, Decoder]] = {
    MessageType.HELLO: (
        Hello,
        lambda e: _enc_handshake(
            e.version,
            {"name": e.name, "role": e.role, "max_frame": e.max_frame},
            {"client_id": e.client_id, "token": e.token},
        ),
        _dec_hello,
    ),
    MessageType.ACCEPT: (
        Accept,
        lambda e: _enc_handshake(
            e.version,
            {"name": e.name, "max_frame": e.max_frame, "max_soldiers": e.max_soldiers},
            {"client_id": e.client_id, "role": e.role},
        ),
        _dec_accept,
    ),
    MessageType.ERROR: (
        Error,
        lambda e: pack_body({"code": e.code, "message": e.message, "ref": e.ref}),
        _dec_error,
    ),
    MessageType.GOODBYE: (
        Goodbye,
        lambda e: pack_body({"reason": e.reason}),
        lambda p, n: Goodbye(unpack_body(p, "GOODBYE").str("reason")),
    ),
    MessageType.PING: (
        Ping,
        lambda e: pack_body({"nonce": e.nonce}),
        lambda p, n: Ping(unpack_body(p, "PING").int("nonce", 0, U64)),
    ),
    MessageType.PONG: (
        Pong,
        lambda e: pack_body({"nonce": e.nonce}),
        lambda p, n: Pong(unpack_body(p, "PONG").int("nonce", 0, U64)),
    ),
    MessageType.JCL: (Jcl, lambda e: pack_body({"id": e.id, "text": e.text}), _dec_jcl),
    MessageType.READY: (Ready, _enc_ready, _dec_ready),
    MessageType.STATUS: (Status, _enc_status, _dec_status),
    MessageType.SETTINGS: (
        Settings,
        lambda e: pack_body({"throttle": float(e.throttle), "report_interval": float(e.report_interval)}),
        _dec_settings,
    ),
    MessageType.CREATE_SOLDIER: (
        CreateSoldier,
        lambda e: pack_body({"id": e.id, "figure": e.figure, "weapon": e.weapon, "index": e.index}),
        _dec_create,
    ),
    MessageType.SOLDIER_CREATED: (
        SoldierCreated,
        lambda e: pack_body({"id": e.id, "index": e.index, "table": e.table}),
        _dec_created,
    ),
    MessageType.REMOVE_SOLDIER: (
        RemoveSoldier,
        lambda e: pack_body({"index": e.index}),
        lambda p, n: RemoveSoldier(unpack_body(p, "REMOVE_SOLDIER").int("index", 0, n - 1)),
    ),
    MessageType.SUBSCRIBE: (
        Subscribe,
        lambda e: pack_body({"indices": list(e.indices)}),
        lambda p, n: Subscribe(_indices(unpack_body(p, "SUBSCRIBE"), "indices", n)),
    ),
    MessageType.SOLDIER_REMOVED: (
        SoldierRemoved,
        lambda e: pack_body({"index": e.index, "reason": e.reason}),
        _dec_removed,
    ),
    MessageType.UNSUBSCRIBE: (
        Unsubscribe,
        lambda e: pack_body({"indices": list(e.indices)}),
        lambda p, n: Unsubscribe(_indices(unpack_body(p, "UNSUBSCRIBE"), "indices", n)),
    ),
    MessageType.REQUEST_FULL_UPDATE: (
        RequestFullUpdate,
        lambda e: pack_body({"indices": list(e.indices)}),
        lambda p, n: RequestFullUpdate(_indices(unpack_body(p, "REQUEST_FULL_UPDATE"), "indices", n)),
    ),
    MessageType.REACT: (
        React,
        lambda e: pack_body({"kind": int(e.kind), "indices": list(e.indices)}),
        _dec_react,
    ),
    MessageType.REQUEST_FIGURE: (
        RequestFigure,
        lambda e: pack_body({"id": e.id, "table": e.table, "meshes": bool(e.meshes)}),
        _dec_request_figure,
    ),
    MessageType.FIGURE: (FigureMsg, lambda e: pack_body(e.body, single_float=True), _dec_figure),
    MessageType.ENTITY_REQUESTS: (
        EntityRequests,
        lambda e: encode_entity_requests(e.rows),
        lambda p, n: EntityRequests(decode_entity_requests(p, n)),
    ),
    MessageType.UPDATE_TABLE: (
        UpdateTableMsg,
        lambda e: pack_body(table_to_wire(e.table)),
        lambda p, n: UpdateTableMsg(table_from_wire(unpack_body(p, "UPDATE_TABLE").raw)),
    ),
}

# read-only views: no module-level state any connection could change
CODECS: Mapping[MessageType, tuple[type[Event], Encoder, Decoder]] = MappingProxyType(_CODECS)
TYPE_OF: Mapping[type[Event], MessageType] = MappingProxyType(
    {**{cls: t for t, (cls, _, _) in _CODECS.items()}, JointUpdates: MessageType.JOINT_UPDATES}
)
