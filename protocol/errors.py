"""Error codes of the TTES wire protocol and the one exception its decoders raise.

Codes below 100 are *fatal*: the connection that detects one sends an Error frame and stops. Codes from 100
up are *request* errors: the server answers one request with them and the connection stays open.
"""

from __future__ import annotations

from collections.abc import Mapping
from enum import IntEnum
from types import MappingProxyType


class ErrorCode(IntEnum):
    """The error table (docs/PROTOCOL.md §9). Values are frozen across protocol versions."""

    # fatal protocol errors (1..99)
    MALFORMED_FRAME = 1
    FRAME_TOO_LARGE = 2
    UNKNOWN_MESSAGE_TYPE = 3
    UNEXPECTED_MESSAGE = 4
    BAD_MAGIC = 5
    UNSUPPORTED_VERSION = 6
    SCHEMA = 7
    BAD_VALUE = 8
    UNKNOWN_TABLE = 9
    BAD_UPDATE = 10
    TRUNCATED = 11
    INTERNAL = 12
    # request errors (100..): the connection stays open
    UNKNOWN_SOLDIER = 100
    SOLDIER_EXISTS = 101
    NO_FREE_SOLDIER = 102
    UNKNOWN_FIGURE = 103
    UNKNOWN_WEAPON = 104
    JCL_ERROR = 105
    NOT_READY = 106
    NOT_PERMITTED = 107
    FIGURE_TOO_LARGE = 108


ERROR_DESCRIPTIONS: Mapping[ErrorCode, str] = MappingProxyType(
    {
        ErrorCode.MALFORMED_FRAME: "a frame whose payload does not have the layout of its message type",
        ErrorCode.FRAME_TOO_LARGE: "frame length above the receiver's max_frame (checked before buffering)",
        ErrorCode.UNKNOWN_MESSAGE_TYPE: "message type byte not in the message table",
        ErrorCode.UNEXPECTED_MESSAGE: "message not allowed in this state or in this direction",
        ErrorCode.BAD_MAGIC: "handshake payload does not start with the magic bytes 'TTES'",
        ErrorCode.UNSUPPORTED_VERSION: "the peer's protocol version is not spoken here",
        ErrorCode.SCHEMA: "msgpack body undecodable, a required field missing, or a field of the wrong type",
        ErrorCode.BAD_VALUE: "NaN/inf, an out-of-range enum, index or count",
        ErrorCode.UNKNOWN_TABLE: "a message references an update table (or entry) that was never sent",
        ErrorCode.BAD_UPDATE: "joint update at odds with the receiver's state (delta before full, overflow)",
        ErrorCode.TRUNCATED: "the stream ended in the middle of a frame",
        ErrorCode.INTERNAL: "the sender hit an internal fault and is closing",
        ErrorCode.UNKNOWN_SOLDIER: "no soldier with that index",
        ErrorCode.SOLDIER_EXISTS: "the requested soldier index is already in use",
        ErrorCode.NO_FREE_SOLDIER: "no free soldier index left",
        ErrorCode.UNKNOWN_FIGURE: "figure type not available on the server",
        ErrorCode.UNKNOWN_WEAPON: "weapon type not available on the server",
        ErrorCode.JCL_ERROR: "a JCL command failed to parse or run",
        ErrorCode.NOT_READY: "request before the server signalled Ready",
        ErrorCode.NOT_PERMITTED: "the client's role may not make this request",
        ErrorCode.FIGURE_TOO_LARGE: "the FIGURE asked for exceeds the client's max_frame",
    }
)


def is_fatal(code: int) -> bool:
    """Fatal codes (< 100) end the connection; request codes (>= 100) do not."""
    return code < 100


class WireError(ValueError):
    """The one error every decoder in :mod:`protocol` raises on bad input.

    ``code`` is an :class:`ErrorCode`, ``location`` says where (``"frame 3 (0x30) row 7: appearance"``).
    """

    def __init__(self, code: ErrorCode, message: str, location: str = "") -> None:
        self.code = ErrorCode(code)
        self.message = message
        self.location = location
        super().__init__(f"{location}: {message}" if location else message)

    def at(self, prefix: str) -> WireError:
        """The same error with ``prefix`` put in front of its location (keeps the subclass)."""
        loc = f"{prefix} {self.location}".strip() if self.location else prefix
        return type(self)(self.code, self.message, loc)


class LocalProtocolError(WireError):
    """Raised by :meth:`Connection.send` when *our* side would break the protocol (nothing is sent)."""
