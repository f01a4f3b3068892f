"""The sans-IO TTES connection: bytes in → events out, events in → bytes out (after h11's design).

No sockets, no clocks, no threads: the caller moves bytes. A ``Connection`` keeps the state one side of one
TCP stream needs: the frame buffer, the handshake state, the peer's limits, the update tables, the per-client
joint-update encoders (server) or decoders (client), and the server's record of what the client subscribed to.
Nothing is shared between connections, so one connection's error never touches another.

Receiving never raises on bad input: a broken frame becomes a :class:`ProtocolError` event, the state becomes
ERROR and an Error frame for the peer waits in :meth:`Connection.data_to_send`. Sending something our side may
not send raises :class:`LocalProtocolError` and sends nothing.
"""

from __future__ import annotations

from collections.abc import Sequence
from enum import Enum

import numpy as np

from protocol.entity import ENTITY_REQUEST_DTYPE, MAX_ROWS_PER_FRAME, WIRE_ENTITY_DTYPE, first_bad_row
from protocol.errors import ErrorCode, LocalProtocolError, WireError, is_fatal
from protocol.events import (
    DEFAULT_MAX_SOLDIERS,
    PROTOCOL_VERSION,
    Accept,
    ConnectionClosed,
    EntityRequests,
    Error,
    Event,
    FigureMsg,
    Goodbye,
    Hello,
    JointUpdates,
    ProtocolError,
    Ready,
    RequestFullUpdate,
    SoldierCreated,
    Subscribe,
    Unsubscribe,
    UpdateHeaders,
    UpdateTableMsg,
)
from protocol.framing import DEFAULT_MAX_FRAME, HANDSHAKE_MAX_FRAME, MIN_MAX_FRAME, FrameReader, encode_frame
from protocol.messages import (
    CLIENT_SENDS,
    CODECS,
    MAX_SOLDIERS_LIMIT,
    SERVER_SENDS,
    TYPE_OF,
    MessageType,
)
from protocol.shared_encode import SharedEncodes
from protocol.updates import UPDATE_HEADER, UpdateDecoder, UpdateEncoder


class Role(Enum):
    CLIENT = "client"
    SERVER = "server"


class State(Enum):
    HANDSHAKE = "HANDSHAKE"
    OPEN = "OPEN"
    CLOSED = "CLOSED"
    ERROR = "ERROR"


class _Sentinel:
    def __init__(self, name: str) -> None:
        self._name = name

    def __repr__(self) -> str:
        return self._name


NEED_DATA = _Sentinel("NEED_DATA")  # next_event: feed more bytes with receive_data
PAUSED = _Sentinel("PAUSED")  # next_event (server): answer the Hello with Accept or Error first

CLIENT, SERVER = Role.CLIENT, Role.SERVER


def _type_name(t: int) -> str:
    try:
        return MessageType(t).name
    except ValueError:
        return f"0x{t:02x}"


class Connection:
    """One side of one TTES stream.

    ``max_frame`` is the largest frame length this side accepts (announced in Hello/Accept; the value in the
    Hello or Accept we send wins). ``max_soldiers`` bounds soldier indices (server: announced in Accept;
    client: taken from the server's Accept). A client made with ``decode_updates=False`` yields
    :class:`UpdateHeaders` instead of decoded :class:`JointUpdates`. ``frame_bytes`` is the size on the wire
    of the frame behind the last event.
    """

    def __init__(
        self,
        role: Role,
        max_frame: int = DEFAULT_MAX_FRAME,
        max_soldiers: int = DEFAULT_MAX_SOLDIERS,
        *,
        decode_updates: bool = True,
        shared_encodes: SharedEncodes | None = None,
    ) -> None:
        if max_frame < MIN_MAX_FRAME:
            raise ValueError(f"max_frame must be >= {MIN_MAX_FRAME}")
        if not 1 <= max_soldiers <= MAX_SOLDIERS_LIMIT:
            raise ValueError(f"max_soldiers must be in 1..{MAX_SOLDIERS_LIMIT}")
        self.role = role
        self.state = State.HANDSHAKE
        self.max_frame = max_frame
        self.max_soldiers = max_soldiers
        self.peer_max_frame = DEFAULT_MAX_FRAME
        self.peer: Hello | Accept | None = None  # the peer's handshake, once received
        self.version: int | None = None
        self.tables: dict[int, UpdateTableMsg] = {}
        self.decode_updates = decode_updates
        self.frame_bytes = 0
        self._reader = FrameReader()
        self._outbox = bytearray()
        self._eof = False
        self._frames_in = 0
        self._hello_sent = False
        self._sent_version: int | None = None
        self._encoders: dict[int, UpdateEncoder] = {}
        self._shared_encodes = shared_encodes  # server: one memo for all its connections (encode once)
        self._decoders: dict[int, UpdateDecoder] = {}
        self._subscribed = np.zeros(0, bool)

    # -- bytes in ------------------------------------------------------------------------------------------

    def receive_data(self, data: bytes) -> None:
        """Feed bytes from the stream; ``b""`` means the peer closed it (EOF)."""
        if not data:
            self._eof = True
        elif not self._eof and self.state not in (State.CLOSED, State.ERROR):
            self._reader.feed(data)

    @property
    def pending_bytes(self) -> int:
        """Bytes of a frame received only in part (0 between whole frames): a server's frame deadline."""
        return self._reader.buffered

    def data_to_send(self) -> bytes:
        """Bytes the connection produced by itself (the Error frame after a ProtocolError); clears them."""
        out = bytes(self._outbox)
        self._outbox.clear()
        return out

    def next_event(self) -> Event | _Sentinel:
        """The next event, NEED_DATA, or PAUSED; ConnectionClosed once the connection is CLOSED or ERROR."""
        if self.state in (State.CLOSED, State.ERROR):
            return ConnectionClosed()
        if self.role is SERVER and self.state is State.HANDSHAKE and self.peer is not None:
            return PAUSED
        handshake = self.role is SERVER and self.state is State.HANDSHAKE
        try:
            frame = self._reader.next_frame(HANDSHAKE_MAX_FRAME if handshake else self.max_frame)
        except WireError as exc:
            return self._fail(exc.at(f"frame {self._frames_in + 1}"))
        if frame is None:
            if not self._eof:
                return NEED_DATA
            if self._reader.buffered:
                return self._fail(
                    WireError(
                        ErrorCode.TRUNCATED, f"stream ended inside a frame ({self._reader.buffered} bytes)"
                    )
                )
            self.state = State.CLOSED
            return ConnectionClosed()
        self._frames_in += 1
        msg_type, payload = frame
        self.frame_bytes = 5 + len(payload)
        name = _type_name(msg_type)
        try:
            return self._receive(msg_type, payload)
        except WireError as exc:
            inner = exc.location.removeprefix(name).strip()  # messages name themselves; say it once
            where = f"frame {self._frames_in} ({name})" + (f" {inner}" if inner else "")
            return self._fail(WireError(exc.code, exc.message, where))
        except Exception as exc:
            # a bug of ours must not escape as a crash either (the fuzz tests assert this never happens)
            where = f"frame {self._frames_in} ({name})"
            return self._fail(WireError(ErrorCode.INTERNAL, f"internal error: {exc!r}", where))

    def _fail(self, exc: WireError) -> ProtocolError:
        self.state = State.ERROR
        text = f"{exc.location}: {exc.message}" if exc.location else exc.message
        self._outbox += encode_frame(
            MessageType.ERROR, CODECS[MessageType.ERROR][1](Error(int(exc.code), text))
        )
        return ProtocolError(int(exc.code), exc.message, exc.location)

    def _receive(self, msg_type: int, payload: bytes) -> Event:
        try:
            mt = MessageType(msg_type)
        except ValueError:
            raise WireError(
                ErrorCode.UNKNOWN_MESSAGE_TYPE, f"unknown message type 0x{msg_type:02x}"
            ) from None
        peer_sends = SERVER_SENDS if self.role is CLIENT else CLIENT_SENDS
        if mt not in peer_sends:
            peer = "server" if self.role is CLIENT else "client"
            raise WireError(ErrorCode.UNEXPECTED_MESSAGE, f"a {peer} may not send {mt.name}")
        if self.state is State.HANDSHAKE:
            first = MessageType.HELLO if self.role is SERVER else MessageType.ACCEPT
            if mt not in (first, MessageType.ERROR, MessageType.GOODBYE):
                raise WireError(ErrorCode.UNEXPECTED_MESSAGE, f"{mt.name} before the handshake completed")
        elif mt in (MessageType.HELLO, MessageType.ACCEPT):
            raise WireError(ErrorCode.UNEXPECTED_MESSAGE, f"second handshake message {mt.name}")

        if mt is MessageType.JOINT_UPDATES:
            return self._receive_updates(payload)
        event = CODECS[mt][2](payload, self.max_soldiers)
        if isinstance(event, Hello):
            self.peer, self.peer_max_frame = event, event.max_frame
        elif isinstance(event, Accept):
            if not self._hello_sent:
                raise WireError(ErrorCode.UNEXPECTED_MESSAGE, "ACCEPT before our HELLO")
            if event.version != self._sent_version:
                raise WireError(
                    ErrorCode.UNSUPPORTED_VERSION,
                    f"asked for version {self._sent_version}, got {event.version}",
                )
            self.peer, self.peer_max_frame, self.version = event, event.max_frame, event.version
            self.max_soldiers = event.max_soldiers
            self.state = State.OPEN
        elif isinstance(event, Error) and is_fatal(event.code):
            self.state = State.ERROR
        elif isinstance(event, Goodbye):
            self.state = State.CLOSED
        elif isinstance(event, UpdateTableMsg):
            self.tables[event.table.table_id] = event
            self._decoders[event.table.table_id] = UpdateDecoder(event.table, self.max_soldiers, self._format)
        elif isinstance(event, SoldierCreated | FigureMsg):
            self._require_tables([event.table])
        elif isinstance(event, Ready):
            self._require_tables([t for _, t in event.soldiers])
        elif isinstance(event, Subscribe | Unsubscribe | RequestFullUpdate):
            self._track_subscription(event)
        return event

    def _require_tables(self, table_ids: list[int]) -> None:
        for tid in table_ids:
            if tid not in self.tables:
                raise WireError(ErrorCode.UNKNOWN_TABLE, f"update table {tid} was never sent")

    def _receive_updates(self, payload: bytes) -> JointUpdates | UpdateHeaders:
        if len(payload) < UPDATE_HEADER.size:
            raise WireError(
                ErrorCode.MALFORMED_FRAME, "joint updates: payload shorter than its 8-byte header"
            )
        tid, tick, count = UPDATE_HEADER.unpack_from(payload)
        decoder = self._decoders.get(tid)
        if decoder is None:
            raise WireError(
                ErrorCode.UNKNOWN_TABLE, f"joint updates reference update table {tid}, never sent"
            )
        if self.decode_updates:
            return decoder.decode(payload)
        if len(payload) < UPDATE_HEADER.size + 2 * count:
            raise WireError(
                ErrorCode.MALFORMED_FRAME,
                f"joint updates: {count} soldier indices need more than {len(payload)} bytes",
            )
        return UpdateHeaders(
            tid, tick, np.frombuffer(payload, ">u2", count, UPDATE_HEADER.size).astype(np.int64)
        )

    def _track_subscription(self, event: Subscribe | Unsubscribe | RequestFullUpdate) -> None:
        idx = np.asarray(event.indices, np.int64)
        if isinstance(event, Subscribe):
            self._subscribed[idx] = True
        elif isinstance(event, Unsubscribe):
            self._subscribed[idx] = False
        elif not len(idx):
            idx = np.flatnonzero(self._subscribed)
        for enc in self._encoders.values():
            enc.reset(idx)

    # -- events in, bytes out -----------------------------------------------------------------------------

    def send(self, event: Event) -> bytes:
        """The bytes of ``event`` (possibly several frames, or b"" for an update with nothing new)."""
        mt = TYPE_OF.get(type(event))
        if mt is None:
            raise LocalProtocolError(
                ErrorCode.UNKNOWN_MESSAGE_TYPE, f"{type(event).__name__} is not sendable"
            )
        mine = CLIENT_SENDS if self.role is CLIENT else SERVER_SENDS
        if mt not in mine:
            raise LocalProtocolError(
                ErrorCode.UNEXPECTED_MESSAGE, f"a {self.role.value} may not send {mt.name}"
            )
        self._check_send_state(mt)
        if isinstance(event, JointUpdates):
            return self._send_updates(event)
        if isinstance(event, EntityRequests):
            return self._send_requests(event)
        payload = self._encode_checked(mt, event)
        if len(payload) + 1 > self.peer_max_frame:
            raise LocalProtocolError(
                ErrorCode.FRAME_TOO_LARGE,
                f"{mt.name} of {len(payload) + 1} bytes exceeds {self.peer_max_frame}",
            )
        self._after_send(event)
        return encode_frame(mt, payload)

    def _check_send_state(self, mt: MessageType) -> None:
        if self.state in (State.CLOSED, State.ERROR):
            raise LocalProtocolError(ErrorCode.UNEXPECTED_MESSAGE, f"connection is {self.state.value}")
        if mt in (MessageType.ERROR, MessageType.GOODBYE):
            return
        if self.state is State.HANDSHAKE:
            if self.role is CLIENT and (mt is not MessageType.HELLO or self._hello_sent):
                raise LocalProtocolError(
                    ErrorCode.UNEXPECTED_MESSAGE, f"{mt.name} before the server's Accept"
                )
            if self.role is SERVER and (mt is not MessageType.ACCEPT or self.peer is None):
                raise LocalProtocolError(ErrorCode.UNEXPECTED_MESSAGE, f"{mt.name} before answering a Hello")
        elif mt in (MessageType.HELLO, MessageType.ACCEPT):
            raise LocalProtocolError(ErrorCode.UNEXPECTED_MESSAGE, f"{mt.name} after the handshake")

    def _encode_checked(self, mt: MessageType, event: Event) -> bytes:
        """Encode, then decode our own bytes: we never send what a correct peer would reject."""
        _, encode, decode = CODECS[mt]
        try:
            payload = encode(event)
            decode(payload, self.max_soldiers)
        except WireError as exc:
            raise LocalProtocolError(exc.code, exc.message, exc.location) from None
        except (TypeError, ValueError, OverflowError, AttributeError) as exc:
            raise LocalProtocolError(ErrorCode.SCHEMA, f"cannot encode {mt.name}: {exc}") from None
        return payload

    def _after_send(self, event: Event) -> None:
        if isinstance(event, Hello):
            self._hello_sent = True
            self.max_frame = event.max_frame
            self._sent_version = event.version
        elif isinstance(event, Accept):
            self.max_frame, self.max_soldiers, self.version = (
                event.max_frame,
                event.max_soldiers,
                event.version,
            )
            self._subscribed = np.zeros(self.max_soldiers, bool)
            self.state = State.OPEN
        elif isinstance(event, Error) and is_fatal(event.code):
            self.state = State.ERROR
        elif isinstance(event, Goodbye):
            self.state = State.CLOSED
        elif isinstance(event, UpdateTableMsg):
            tid = event.table.table_id
            self.tables[tid] = event
            self._encoders[tid] = UpdateEncoder(
                event.table, self.max_soldiers, self._shared_encodes, self._format
            )

    def _send_updates(self, event: JointUpdates) -> bytes:
        encoder = self._encoders.get(event.table)
        if encoder is None:
            raise LocalProtocolError(ErrorCode.UNKNOWN_TABLE, f"send UpdateTableMsg {event.table} first")
        idx = np.asarray(event.indices, np.int64).reshape(-1)
        if len(idx) and (idx.min() < 0 or idx.max() >= self.max_soldiers):
            raise LocalProtocolError(ErrorCode.BAD_VALUE, f"soldier index outside 0..{self.max_soldiers - 1}")
        keep = self._subscribed[idx]
        if not keep.all():
            event = JointUpdates(
                event.table,
                idx[keep],
                np.asarray(event.dofs)[keep],
                np.asarray(event.positions)[keep],
                np.asarray(event.orientations)[keep],
                event.tick,
            )
        try:
            payloads = encoder.encode(event, self.peer_max_frame - 1)
        except ValueError as exc:
            raise LocalProtocolError(ErrorCode.BAD_VALUE, str(exc)) from None
        return b"".join(encode_frame(MessageType.JOINT_UPDATES, p) for p in payloads)

    def send_update_codes(
        self, table: int, indices: np.ndarray, codes: np.ndarray, tick: int, version: object = None
    ) -> bytes:
        """JOINT_UPDATES frames from codes already quantised for ``table`` (server side).

        For servers that quantise every soldier once per tick and share the codes between their clients: the
        same checks, delta state and bytes as ``send(JointUpdates(...))`` with the poses those codes encode.
        ``version`` (equal versions and rows mean equal codes) lets connections made with one
        ``shared_encodes`` memo share the encode (:mod:`protocol.shared_encode`).
        """
        encoder = self._update_encoder(table)
        idx = self._soldier_indices(indices)
        keep = self._subscribed[idx]
        if not keep.all():
            idx, codes = idx[keep], np.asarray(codes)[keep]
        try:
            payloads = encoder.encode_codes(idx, codes, tick & 0xFFFFFFFF, self.peer_max_frame - 1, version)
        except ValueError as exc:
            raise LocalProtocolError(ErrorCode.BAD_VALUE, str(exc)) from None
        return b"".join(encode_frame(MessageType.JOINT_UPDATES, p) for p in payloads)

    def catch_up_codes(
        self,
        table: int,
        missed: Sequence[tuple[object, np.ndarray]],
        allowed: np.ndarray,
        indices: np.ndarray,
        codes: np.ndarray,
        tick: int,
        version: object,
    ) -> bytes | None:
        """:meth:`send_update_codes` for a server connection that missed publishes: the shared memo's frames
        of them, then the newest's (``indices``, ``codes``: what changed at it); None when the memo cannot
        stand in for its own encode (``UpdateEncoder.catch_up``: ``missed`` is, oldest first, each missed
        publish's version and the soldiers it owes; ``allowed``, a bool mask, the soldiers this client may
        be sent besides being subscribed)."""
        encoder = self._update_encoder(table)
        mask = self._subscribed.copy()
        mask[len(allowed) :] = False
        mask[: len(allowed)] &= allowed[: len(mask)]
        idx = self._soldier_indices(indices)
        keep = mask[idx]
        try:
            payloads = encoder.catch_up(
                missed, mask, idx[keep], np.asarray(codes)[keep], tick & 0xFFFFFFFF, self.peer_max_frame - 1,
                version,
            )  # fmt: skip
        except ValueError as exc:
            raise LocalProtocolError(ErrorCode.BAD_VALUE, str(exc)) from None
        if payloads is None:
            return None
        return b"".join(encode_frame(MessageType.JOINT_UPDATES, p) for p in payloads)

    def _soldier_indices(self, indices: np.ndarray) -> np.ndarray:
        """``indices`` as int64, each a soldier this connection can hold (else BAD_VALUE, not IndexError)."""
        idx = np.asarray(indices, np.int64).reshape(-1)
        if len(idx) and (idx.min() < 0 or idx.max() >= self.max_soldiers):
            raise LocalProtocolError(ErrorCode.BAD_VALUE, f"soldier index outside 0..{self.max_soldiers - 1}")
        return idx

    def _update_encoder(self, table: int) -> UpdateEncoder:
        """The server's encoder of ``table``, once JOINT_UPDATES may be sent."""
        if self.role is not SERVER:
            raise LocalProtocolError(ErrorCode.UNEXPECTED_MESSAGE, "a client may not send JOINT_UPDATES")
        self._check_send_state(MessageType.JOINT_UPDATES)
        encoder = self._encoders.get(table)
        if encoder is None:
            raise LocalProtocolError(ErrorCode.UNKNOWN_TABLE, f"send UpdateTableMsg {table} first")
        return encoder

    def _send_requests(self, event: EntityRequests) -> bytes:
        rows = np.asarray(event.rows)
        if rows.dtype.names != ENTITY_REQUEST_DTYPE.names:
            raise LocalProtocolError(ErrorCode.SCHEMA, "rows must have protocol.entity.ENTITY_REQUEST_DTYPE")
        rows = rows.astype(ENTITY_REQUEST_DTYPE).reshape(-1)
        bad = first_bad_row(rows, self.max_soldiers)
        if bad is not None:
            raise LocalProtocolError(ErrorCode.BAD_VALUE, bad[1], f"row {bad[0]}")
        per_frame = min(MAX_ROWS_PER_FRAME, (self.peer_max_frame - 3) // WIRE_ENTITY_DTYPE.itemsize)
        encode = CODECS[MessageType.ENTITY_REQUESTS][1]
        chunks = [rows[i : i + per_frame] for i in range(0, max(len(rows), 1), per_frame)]
        return b"".join(encode_frame(MessageType.ENTITY_REQUESTS, encode(EntityRequests(c))) for c in chunks)

    @property
    def _format(self) -> int:
        """The joint-update format: the version agreed in the handshake (§8 version 1, §8.5 version 2)."""
        return self.version if self.version is not None else PROTOCOL_VERSION

    # -- server helpers -------------------------------------------------------------------------------------

    @property
    def subscribed(self) -> np.ndarray:
        """Server: indices of the soldiers this client subscribed to."""
        return np.flatnonzero(self._subscribed)

    def subscribes_any(self, indices: np.ndarray) -> bool:
        """Server: whether this client subscribed to any of the soldiers ``indices``."""
        idx = indices[indices < len(self._subscribed)]
        return bool(self._subscribed[idx].any())

    def reset_soldiers(self, indices: np.ndarray | list[int] | None = None) -> None:
        """Server: the next update of these soldiers (all if None) is full, e.g. after an index is reused."""
        idx = None if indices is None else np.asarray(indices, np.int64)
        for enc in self._encoders.values():
            enc.reset(idx)

    def decoder(self, table_id: int) -> UpdateDecoder | None:
        """Client: the decoder (current soldier poses) of an update table."""
        return self._decoders.get(table_id)
