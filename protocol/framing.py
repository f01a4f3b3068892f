"""Length-prefixed frames: ``u32 length (big-endian) | u8 message type | payload``.

``length`` counts the type byte and the payload (so it is at least 1). A receiver checks ``length`` against
its ``max_frame`` as soon as the four length bytes are in, before buffering the body, so a hostile or foreign
peer cannot make it hold more than ``max_frame + 4`` bytes.
"""

from __future__ import annotations

import struct

from protocol.errors import ErrorCode, WireError

HEADER = struct.Struct(">IB")
LENGTH = struct.Struct(">I")
DEFAULT_MAX_FRAME = 1 << 20  # 1 MiB: largest ``length`` a receiver accepts unless configured otherwise
HANDSHAKE_MAX_FRAME = 4096  # the server's limit for the first frame (Hello), whatever max_frame is
MIN_MAX_FRAME = 256  # smallest max_frame a server may announce (clients send small frames or split them)
# smallest max_frame a client may announce: the server's UPDATE_TABLE (length 1,702 for DI.fig + AK-47) and
# FIGURE without meshes (about 16 kB) each come in one frame (docs/PROTOCOL.md §2)
MIN_CLIENT_MAX_FRAME = 65536


def encode_frame(msg_type: int, payload: bytes | bytearray | memoryview) -> bytes:
    """One frame: the length prefix, the type byte, the payload."""
    return HEADER.pack(len(payload) + 1, msg_type) + bytes(payload)


class FrameReader:
    """Accumulates stream bytes and cuts them into ``(type, payload)`` frames; holds no other state."""

    def __init__(self) -> None:
        self._buf = bytearray()
        self._pos = 0  # start of unconsumed bytes; compacted lazily so many small frames stay O(n)

    def feed(self, data: bytes | bytearray | memoryview) -> None:
        if self._pos and self._pos * 2 >= len(self._buf):
            del self._buf[: self._pos]
            self._pos = 0
        self._buf += data

    @property
    def buffered(self) -> int:
        """Bytes received but not yet returned as frames."""
        return len(self._buf) - self._pos

    def next_frame(self, max_frame: int) -> tuple[int, bytes] | None:
        """The next complete frame, or ``None`` if more bytes are needed.

        Raises :class:`WireError` (FRAME_TOO_LARGE, MALFORMED_FRAME) from the length prefix alone.
        """
        avail = len(self._buf) - self._pos
        if avail < 4:
            return None
        (length,) = LENGTH.unpack_from(self._buf, self._pos)
        if length > max_frame:
            raise WireError(
                ErrorCode.FRAME_TOO_LARGE, f"announced frame length {length} exceeds max_frame {max_frame}"
            )
        if length == 0:
            raise WireError(ErrorCode.MALFORMED_FRAME, "frame length 0 (no message type byte)")
        if avail < 4 + length:
            return None
        start = self._pos + 5
        msg_type = self._buf[self._pos + 4]
        payload = bytes(self._buf[start : self._pos + 4 + length])
        self._pos += 4 + length
        return msg_type, payload
