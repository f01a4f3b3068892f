"""Reading DIS logfiles: pcap / pcapng captures, open-dis ``.dislog`` files and raw PDU streams.

One call turns a whole file into a :class:`DisLog`: the lifeform Entity State PDUs as one decoded batch
(:class:`~protocol.dis.batch.EntityStateBatch`) with their receipt times, the Fire/Detonation events, an
index of every PDU seen (in file order) and counters. Nothing in a file is fatal: non-DIS packets, other
PDU types and non-lifeform entities are counted and skipped; a truncated or corrupt record becomes a
:class:`DisError` in ``issues`` (with its record number and offset) and is skipped.

Formats
-------
* **pcap / pcapng** (read with dpkt): Ethernet (with VLAN tags), Linux cooked (SLL, SLL2), BSD
  loopback/null and raw IPv4/IPv6 link types; UDP to ``port`` (default 3000, ``None`` = any port).
  Time = the capture's receipt time. IP fragments are counted and skipped (no reassembly).
  Issue offsets are byte offsets inside the packet, ``record`` the 1-based packet number.
* **.dislog** (open-dis ``PduRecorder``): text lines, ``#`` starts a comment. Each data line is an
  8-byte big-endian signed nanosecond count (time since the recording started) followed by the PDU bytes,
  either ``ENCODING_PLAINTEXT`` (comma-separated signed byte values, optionally bracketed, optionally
  followed by ``# comment``) or ``ENCODING_BASE64`` (one base64 block of time + PDU, or two blocks
  ``time,pdu``). The encoding comes from the ``# Start, ENCODING_...`` header or is sniffed per line.
  ``record`` is the line number, offsets count from the first PDU byte of the line.
* **raw**: PDUs concatenated back to back. There is no receipt time, so times come from the DIS
  timestamps (seconds past the hour, unwrapped across hour roll-overs). Offsets are file offsets.
"""

from __future__ import annotations

import base64
import binascii
import io
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import NDArray

from protocol.dis.batch import EntityStateBatch
from protocol.dis.decoders import (
    DECODERS,
    Corrupt,
    Decoded,
    EntityStates,
    EntityUpdates,
    Event,
    PduRows,
    PduStatus,
    Skipped,
)
from protocol.dis.entity_update import UpdateBases, resolve_updates
from protocol.dis.errors import DisError
from protocol.dis.pdu import DEFAULT_PORT, PduType, timestamp_seconds, unwrap_timestamps
from protocol.dis.remove_entity import DisEvent
from protocol.dis.scan import scan_segments, scan_stream

FORMATS = ("pcap", "pcapng", "dislog", "raw")
I64 = NDArray[np.int64]
F64 = NDArray[np.float64]
Progress = Callable[[int], None]  # called with the number of records read so far


PDU_INDEX_DTYPE = np.dtype(
    [
        ("t", "f8"),
        ("record", "i8"),
        ("offset", "i8"),
        ("length", "i4"),
        ("pdu_type", "u1"),
        ("version", "u1"),
        ("status", "u1"),
        ("batch_index", "i8"),
    ]
)


@dataclass(slots=True)
class DisLog:
    """Everything read from one log. ``times[i]`` is the receipt time of ``batch.records[i]``."""

    source: str
    format: str
    batch: EntityStateBatch
    times: F64
    events: list[DisEvent]  # Fire, Detonation, Remove Entity, file order
    pdus: NDArray[np.void]  # PDU_INDEX_DTYPE, every DIS PDU in file order
    counters: dict[str, int]
    pdu_types: dict[int, int]
    issues: list[DisError]
    t0: float = 0.0  # receipt time of the first record (packet / line / PDU) of the log
    t_end: float = 0.0
    exercises: dict[int, int] = field(default_factory=dict)  # PDUs seen per exercise ID (every exercise)

    @property
    def duration(self) -> float:
        return max(self.t_end - self.t0, 0.0)

    def not_dis(self) -> str | None:
        """Why this file is not a DIS log at all (None when it holds DIS, or nothing).

        A log is DIS when one PDU of a type TTES decodes (:data:`DECODERS`) decoded. Without
        one, it is DIS only if its PDUs of other types outnumber the problems (corrupt records, non-DIS
        datagrams) ten to one: a radio-only capture is DIS, a text file or an image read as PDUs is not
        (each of its lines or junk headers is a problem, the few "PDUs" it seems to hold are noise).
        """
        st = self.pdus["status"]
        decoded = np.isin(st, (PduStatus.DECODED, PduStatus.NOT_LIFEFORM, PduStatus.EVENT, PduStatus.NO_BASE))
        if decoded.any():
            return None
        problems = len(self.issues) + self.counters.get("non_dis", 0)
        others = int(((st == PduStatus.OTHER_TYPE) | (st == PduStatus.OTHER_EXERCISE)).sum())
        if problems == 0 or others >= 10 * problems:
            return None
        first = f" (first: {self.issues[0]})" if self.issues else ""
        return (
            f"not a DIS log (pcap, pcapng, .dislog or raw PDUs): read as {self.format}, it holds no PDU that "
            f"TTES reads, {problems} problem(s){first} and {others} PDU(s) of other types"
        )

    def summary(self) -> dict[str, object]:
        ids = self.batch.records["entity_id"]
        return {
            "source": self.source,
            "format": self.format,
            **self.counters,
            "pdu_types": {str(k): v for k, v in sorted(self.pdu_types.items())},
            "exercises": {str(k): v for k, v in sorted(self.exercises.items())},
            "entities": int(np.unique(ids).shape[0]) if len(self.batch) else 0,
            "duration_s": round(self.duration, 6),
            "issues": len(self.issues),
        }


@dataclass(slots=True)
class _Segments:
    """Byte segments that each start with a PDU, plus where they came from."""

    data: bytes
    start: I64
    end: I64
    time: F64
    record: I64  # 1-based packet / line number; 0 for raw streams
    base: I64  # buffer offset that is offset 0 of the record (packet start, line PDU start, 0)
    stream: bool = False
    t0: float = 0.0
    t_end: float = 0.0
    counters: dict[str, int] = field(default_factory=dict)
    issues: list[DisError] = field(default_factory=list)


# --- format detection -------------------------------------------------------------------------------------
_PCAP_MAGICS = {b"\xa1\xb2\xc3\xd4", b"\xd4\xc3\xb2\xa1", b"\xa1\xb2\x3c\x4d", b"\x4d\x3c\xb2\xa1"}


def detect_format(head: bytes, name: str = "") -> str:
    """``pcap``, ``pcapng``, ``dislog`` or ``raw`` from the first bytes (and the file name)."""
    if head[:4] in _PCAP_MAGICS:
        return "pcap"
    if head[:4] == b"\x0a\x0d\x0d\x0a":
        return "pcapng"
    if name.lower().endswith(".dislog"):
        return "dislog"
    text = head[:64]
    if text[:1] == b"#" or (
        text and re.fullmatch(rb"[0-9A-Za-z+/=,\-\[\]\s]+", text) and not 1 <= text[0] <= 7
    ):
        return "dislog"
    return "raw"


def read_log(
    path: str | Path,
    *,
    fmt: str = "auto",
    port: int | None = DEFAULT_PORT,
    lifeforms_only: bool = True,
    progress: Progress | None = None,
    exercise: int | None = None,
) -> DisLog:
    """Read a log file (format sniffed unless ``fmt`` says). OSError for unreadable files only.
    ``exercise``: decode only the PDUs of that exercise ID (the others are counted as ``other_exercise``)."""
    p = Path(path)
    data = p.read_bytes()
    return read_bytes(data, fmt=fmt, port=port, lifeforms_only=lifeforms_only, progress=progress, name=str(p),
                      exercise=exercise)  # fmt: skip


def read_bytes(
    data: bytes,
    *,
    fmt: str = "auto",
    port: int | None = DEFAULT_PORT,
    lifeforms_only: bool = True,
    progress: Progress | None = None,
    name: str = "<bytes>",
    exercise: int | None = None,
) -> DisLog:
    """Read a log from memory. Unknown ``fmt`` or an unreadable capture header raise :class:`DisError`."""
    data = bytes(data)
    if fmt == "auto":
        fmt = detect_format(data[:64], name)
    if fmt in ("pcap", "pcapng"):
        seg = _read_capture(data, fmt, port, progress)
    elif fmt == "dislog":
        seg = _read_dislog(data)
    elif fmt == "raw":
        seg = _Segments(
            data,
            np.zeros(1, np.int64),
            np.array([len(data)], np.int64),
            np.zeros(1),
            np.zeros(1, np.int64),
            np.zeros(1, np.int64),
            stream=True,
            counters={"records": 1},
        )
    else:
        raise DisError(f"unknown log format {fmt!r} (one of {', '.join(FORMATS)})", 0)
    return _decode(seg, name, fmt, lifeforms_only, exercise)


def read_datagrams(
    datagrams: Sequence[bytes],
    now: float,
    *,
    lifeforms_only: bool = True,
    name: str = "<udp>",
    exercise: int | None = None,
    bases: UpdateBases | None = None,
) -> DisLog:
    """Decode a burst of UDP payloads received at ``now`` (each one or more PDUs), as a live gateway hears
    them: records are numbered 1.. in arrival order and every PDU is stamped ``now``. ``bases``: the last
    Entity State PDU of each entity from earlier bursts, for this burst's Entity State Updates (updated)."""
    n = len(datagrams)
    sizes = np.fromiter((len(d) for d in datagrams), np.int64, n)
    end = np.cumsum(sizes)
    start = end - sizes
    seg = _Segments(
        b"".join(datagrams),
        start,
        end,
        np.full(n, float(now)),
        np.arange(1, n + 1, dtype=np.int64),
        start,
        counters={"records": n, "datagrams": n},
        t0=float(now),
        t_end=float(now),
    )
    return _decode(seg, name, "udp", lifeforms_only, exercise, bases)


# --- captures ---------------------------------------------------------------------------------------------
_DLT_NULL, _DLT_EN10MB, _DLT_RAW_BSD, _DLT_RAW_OBSD, _DLT_RAW = 0, 1, 12, 14, 101
_DLT_LOOP, _DLT_LINUX_SLL, _DLT_IPV4, _DLT_IPV6, _DLT_LINUX_SLL2 = 108, 113, 228, 229, 276
_ETH_IPV4, _ETH_IPV6 = 0x0800, 0x86DD
_VLAN_TYPES = (0x8100, 0x88A8, 0x9100)


def _read_capture(data: bytes, fmt: str, port: int | None, progress: Progress | None) -> _Segments:
    import dpkt  # only captures need it

    bio = io.BytesIO(data)
    issues: list[DisError] = []
    try:
        reader = dpkt.pcap.Reader(bio) if fmt == "pcap" else dpkt.pcapng.Reader(bio)
        linktype = int(reader.datalink())
    except Exception as exc:  # dpkt reports bad headers with assorted exception types
        raise DisError(f"not a readable {fmt} file: {exc}", 0) from None
    frames: list[bytes] = []
    times: list[float] = []
    try:
        for ts, frame in reader:
            frames.append(frame)
            times.append(float(ts))
            if progress is not None and len(frames) % 4096 == 0:
                progress(len(frames))
    except Exception as exc:  # a damaged trailing record: keep what was read, report the rest
        issues.append(
            DisError(f"capture record damaged or truncated ({type(exc).__name__}: {exc})", 0, len(frames) + 1)
        )
    if progress is not None:
        progress(len(frames))
    lengths = np.fromiter((len(f) for f in frames), np.int64, len(frames))
    f_start = np.zeros(len(frames), np.int64)
    if len(frames) > 1:
        np.cumsum(lengths[:-1], out=f_start[1:])
    buf = b"".join(frames)
    t = np.array(times, np.float64)
    seg_start, seg_end, frame_idx, counters, more = _udp_payloads(
        buf, f_start, f_start + lengths, linktype, port
    )
    issues.extend(more)
    counters = {"records": len(frames), **counters}
    return _Segments(
        buf,
        seg_start,
        seg_end,
        t[frame_idx],
        frame_idx + 1,
        f_start[frame_idx],
        counters=counters,
        issues=issues,
        t0=float(t[0]) if t.size else 0.0,
        t_end=float(t[-1]) if t.size else 0.0,
    )


def _udp_payloads(
    buf: bytes, f_start: I64, f_end: I64, linktype: int, port: int | None
) -> tuple[I64, I64, I64, dict[str, int], list[DisError]]:
    """Vectorised link / IP / UDP header parse: (payload starts, ends, frame index, counters, issues)."""
    u8 = np.frombuffer(buf + bytes(64), dtype=np.uint8)  # tail padding: header reads never index out
    n = f_start.shape[0]
    counters = {"non_ip": 0, "non_udp": 0, "ip_fragments": 0, "other_port": 0}
    issues: list[DisError] = []
    empty = np.zeros(0, np.int64)
    if n == 0:
        return empty, empty, empty, counters, issues

    def b(at: I64) -> I64:
        return u8[np.minimum(at, u8.shape[0] - 1)].astype(np.int64)

    def w(at: I64) -> I64:
        return (b(at) << 8) | b(at + 1)

    ethertype = np.zeros(n, np.int64)
    if linktype == _DLT_EN10MB:
        l3 = f_start + 14
        ethertype = w(f_start + 12)
        for _ in range(2):  # up to two VLAN tags
            tagged = np.isin(ethertype, _VLAN_TYPES)
            ethertype = np.where(tagged, w(l3 + 2), ethertype)
            l3 = np.where(tagged, l3 + 4, l3)
    elif linktype == _DLT_LINUX_SLL:
        l3, ethertype = f_start + 16, w(f_start + 14)
    elif linktype == _DLT_LINUX_SLL2:
        l3, ethertype = f_start + 20, w(f_start)
    elif linktype in (_DLT_NULL, _DLT_LOOP):
        l3 = f_start + 4
        family = np.maximum(b(f_start), b(f_start + 3))  # AF value in either byte order
        ethertype = np.where(
            family == 2, _ETH_IPV4, np.where(np.isin(family, (10, 24, 28, 30)), _ETH_IPV6, 0)
        )
    elif linktype in (_DLT_RAW, _DLT_RAW_BSD, _DLT_RAW_OBSD, _DLT_IPV4, _DLT_IPV6):
        l3 = f_start.copy()
        nibble = b(l3) >> 4
        ethertype = np.where(nibble == 4, _ETH_IPV4, np.where(nibble == 6, _ETH_IPV6, 0))
    else:
        counters["non_ip"] = n
        issues.append(DisError(f"link type {linktype} not supported; {n} packets skipped", 0, 1))
        return empty, empty, empty, counters, issues

    v4 = (ethertype == _ETH_IPV4) & (b(l3) >> 4 == 4) & (l3 + 20 <= f_end)
    v6 = (ethertype == _ETH_IPV6) & (b(l3) >> 4 == 6) & (l3 + 40 <= f_end)
    ihl = (b(l3) & 0xF) * 4
    v4 &= ihl >= 20
    counters["non_ip"] = int((~(v4 | v6)).sum())
    frag = v4 & ((w(l3 + 6) & 0x3FFF) != 0)
    counters["ip_fragments"] = int(frag.sum())
    udp = (v4 & ~frag & (b(l3 + 9) == 17)) | (v6 & (b(l3 + 6) == 17))
    counters["non_udp"] = int(((v4 & ~frag) | v6).sum() - udp.sum())
    l4 = np.where(v6, l3 + 40, l3 + ihl)
    ip_end = np.where(v6, l3 + 40 + w(l3 + 4), l3 + w(l3 + 2))
    if port is not None:
        on_port = udp & (w(l4 + 2) == port)
        counters["other_port"] = int((udp & ~on_port).sum())
        udp = on_port
    ulen = w(l4 + 4)
    p_start = l4 + 8
    p_end = l4 + ulen
    bad_len = udp & ((ulen < 8) | (p_end > ip_end))
    truncated = udp & ~bad_len & (p_end > f_end)
    for i in np.flatnonzero(bad_len | truncated).tolist():
        what = (
            "UDP length field inconsistent with the IP header"
            if bad_len[i]
            else "UDP payload cut short by the capture"
        )
        issues.append(DisError(what, int(l4[i] + 4 - f_start[i]), i + 1))
    keep = np.flatnonzero(udp & ~bad_len & ~truncated)
    counters["datagrams"] = int(keep.shape[0])
    return p_start[keep], p_end[keep], keep.astype(np.int64), counters, issues


# --- .dislog ----------------------------------------------------------------------------------------------
_PLAIN_LINE = re.compile(r"[\s\[\]0-9,+\-]+")
# anything that is not a comma-separated list of optionally signed integers
_PLAIN_BAD = re.compile(r"(?:^|,)(?![+-]?[0-9]{1,4}(?:,|$))")


def _read_dislog(data: bytes) -> _Segments:
    text = data.decode("latin-1")
    lines = text.splitlines()
    encoding = None
    head = text[:4096]
    if "ENCODING_BASE64" in head:
        encoding = "base64"
    elif "ENCODING_PLAINTEXT" in head:
        encoding = "plain"
    chunks: list[bytes] = []
    times: list[int] = []
    records: list[int] = []
    issues: list[DisError] = []
    comments = 0
    for lineno, line in enumerate(lines, start=1):
        s = line.strip()
        if not s:
            continue
        if s.startswith("#"):
            comments += 1
            continue
        enc = encoding or ("plain" if _PLAIN_LINE.fullmatch(s.split("#", 1)[0]) else "base64")
        try:
            raw = _plain_line(s) if enc == "plain" else _base64_line(s)
        except DisError as exc:
            issues.append(DisError(exc.message, exc.offset, lineno))
            continue
        if len(raw) < 8:
            issues.append(DisError(f"line holds {len(raw)} bytes, less than the 8-byte time", 0, lineno))
            continue
        times.append(int.from_bytes(raw[:8], "big", signed=True))
        chunks.append(raw[8:])
        records.append(lineno)
    lengths = np.fromiter((len(c) for c in chunks), np.int64, len(chunks))
    start = np.zeros(len(chunks), np.int64)
    if len(chunks) > 1:
        np.cumsum(lengths[:-1], out=start[1:])
    t = np.array(times, np.float64) * 1e-9
    return _Segments(
        b"".join(chunks),
        start,
        start + lengths,
        t,
        np.array(records, np.int64),
        start.copy(),
        counters={"records": len(chunks), "comment_lines": comments},
        issues=issues,
        t0=float(t[0]) if t.size else 0.0,
        t_end=float(t.max()) if t.size else 0.0,
    )


def _plain_line(s: str) -> bytes:
    body = s.split("#", 1)[0].replace("[", "").replace("]", "").replace(" ", "").strip().rstrip(",")
    bad = _PLAIN_BAD.search(body)
    if bad is not None or not body:
        at = body[: bad.start()].count(",") if bad is not None else 0
        raise DisError("unparsable byte value in a plaintext line", max(at - 8, 0))
    values = np.fromstring(body, dtype=np.int64, sep=",")
    out_of_range = (values < -128) | (values > 255)
    if out_of_range.any():
        k = int(np.argmax(out_of_range))
        raise DisError(f"byte value {int(values[k])} out of range", max(k - 8, 0))
    return (values & 0xFF).astype(np.uint8).tobytes()


def _base64_line(s: str) -> bytes:
    try:
        return b"".join(
            base64.b64decode(part.strip(), validate=True) for part in s.split("#", 1)[0].split(",")
        )
    except (binascii.Error, ValueError) as exc:
        raise DisError(f"bad base64: {exc}", 0) from None


# --- the common decoding step -----------------------------------------------------------------------------


def _decode(
    seg: _Segments,
    name: str,
    fmt: str,
    lifeforms_only: bool,
    exercise: int | None = None,
    bases: UpdateBases | None = None,
) -> DisLog:
    """Scan the segments into a PDU index, run each type's decoder (:data:`DECODERS`) on the PDUs of the
    wanted exercise, put the Entity State Updates on their entities' states, collect the events."""
    issues = list(seg.issues)
    if seg.stream:
        index, scan_issues = scan_stream(seg.data)
        non_dis = np.zeros(0, bool)
    else:
        index, non_dis, scan_issues = scan_segments(seg.data, seg.start, seg.end)
    issues.extend(_relocate(e, seg) for e in scan_issues)
    u8 = np.frombuffer(seg.data, dtype=np.uint8)
    n = len(index)
    ptype = u8[index.offset + 2] if n else np.zeros(0, np.uint8)
    version = u8[index.offset] if n else np.zeros(0, np.uint8)
    exercises = u8[index.offset + 1] if n else np.zeros(0, np.uint8)
    wanted = np.ones(n, bool) if exercise is None else exercises == exercise
    if seg.stream:
        ts = _u32(u8, index.offset + 4) if n else np.zeros(0, np.uint32)
        t = unwrap_timestamps(timestamp_seconds(ts))
        seg.t0, seg.t_end = (float(t[0]), float(t.max())) if n else (0.0, 0.0)
    else:
        t = seg.time[index.segment]
    found = _Found(n)
    found.status[~wanted] = PduStatus.OTHER_EXERCISE
    for pdu_type, decoder in DECODERS.items():
        rows = np.flatnonzero((ptype == pdu_type) & wanted)
        if len(rows):
            at = PduRows(
                seg.data, u8, rows, index.offset[rows], index.length[rows], index.segment[rows],
                version[rows], t[rows], lifeforms_only,
            )  # fmt: skip
            for decoded in decoder(at):
                found.add(decoded)
    found.resolve(bases)
    states, status, batch_index = found.states, found.status, found.batch_index
    events = [w.event for w in sorted(found.events, key=lambda w: w.row)]  # file order
    issues += [_relocate(c.error, seg) for c in sorted(found.corrupt, key=lambda c: c.row)]
    pdus = np.zeros(n, PDU_INDEX_DTYPE)
    pdus["t"] = t
    pdus["record"] = seg.record[index.segment] if not seg.stream else 0
    pdus["offset"] = index.offset - (seg.base[index.segment] if not seg.stream else 0)
    pdus["length"] = index.length
    pdus["pdu_type"] = ptype
    pdus["version"] = version
    pdus["status"] = status
    pdus["batch_index"] = batch_index
    type_counts = np.bincount(ptype[wanted], minlength=256)
    types = np.flatnonzero(type_counts)
    ex_counts = np.bincount(exercises, minlength=256)
    ex_ids = np.flatnonzero(ex_counts)
    counters = {
        **seg.counters,
        "non_dis": int(non_dis.sum()),
        **_counters(ptype, status, states, events, len(issues)),
    }
    return DisLog(
        source=name,
        format=fmt,
        batch=states.batch,
        times=np.asarray(t[states.rows], np.float64),
        events=events,
        pdus=pdus,
        counters=counters,
        pdu_types=dict(zip(types.tolist(), type_counts[types].tolist(), strict=True)),
        issues=issues,
        exercises=dict(zip(ex_ids.tolist(), ex_counts[ex_ids].tolist(), strict=True)),
        t0=seg.t0,
        t_end=seg.t_end,
    )


class _Found:
    """What the decoders of one log yielded, and each PDU's status: the ``match`` over the typed events."""

    def __init__(self, n: int) -> None:
        self.status = np.full(n, PduStatus.OTHER_TYPE, np.uint8)  # a type without a decoder stays OTHER_TYPE
        self.batch_index = np.full(n, -1, np.int64)
        self.states = EntityStates.empty()  # a log without Entity State PDUs
        self.updates: EntityUpdates | None = None
        self.events: list[Event] = []
        self.corrupt: list[Corrupt] = []

    def add(self, decoded: Decoded) -> None:
        match decoded:
            case EntityStates(rows=kept, skipped=skipped):
                self.states = decoded
                self.status[kept] = PduStatus.DECODED
                self.status[skipped] = PduStatus.NOT_LIFEFORM
                self.batch_index[kept] = np.arange(len(kept))
            case EntityUpdates():
                self.updates = decoded
            case Event(row=row):
                self.status[row] = PduStatus.EVENT
                self.events.append(decoded)
            case Skipped(rows=rows, status=why):
                self.status[rows] = why
            case Corrupt(row=row):
                self.status[row] = PduStatus.CORRUPT
                self.corrupt.append(decoded)

    def resolve(self, bases: UpdateBases | None) -> None:
        """Each Entity State Update on its entity's last Entity State PDU before it (or in ``bases``): one
        more state, merged in receipt order; an update with nothing to stand on is ``NO_BASE``. ``bases``
        then learns this log's Entity State PDUs."""
        st, up = self.states, self.updates
        if up is not None and len(up.rows):
            resolved, placed = resolve_updates(st.batch, st.rows, up.batch, up.rows, bases)
            self.status[up.rows[~placed]] = PduStatus.NO_BASE
            rows = np.concatenate([st.rows, up.rows[placed]])
            order = np.argsort(rows, kind="stable")
            merged = EntityStateBatch.concatenate([st.batch, resolved]).select(order)
            self.states = replace(st, batch=merged, rows=rows[order])
            self.status[rows] = PduStatus.DECODED
            self.batch_index[rows[order]] = np.arange(len(rows))
        if bases is not None:
            records = self.states.batch.records
            bases.learn(records[records["pdu_type"] == PduType.ENTITY_STATE])


def _counters(
    ptype: NDArray[np.uint8],
    status: NDArray[np.uint8],
    states: EntityStates,
    events: list[DisEvent],
    corrupt: int,
) -> dict[str, int]:
    """Every counter of a log, derived from the PDU types, their statuses and the decoders' events."""
    mine = status != PduStatus.OTHER_EXERCISE
    return {
        "pdus": len(ptype),
        "entity_states": int(((ptype == PduType.ENTITY_STATE) & mine).sum()),
        "lifeforms": states.lifeforms,
        "non_lifeforms": states.non_lifeforms,
        "decoded": len(states.batch),
        "fire": sum(e.kind == "fire" for e in events),
        "detonation": sum(e.kind == "detonation" for e in events),
        "remove_entity": sum(e.kind == "remove_entity" for e in events),
        "entity_state_updates": int(((ptype == PduType.ENTITY_STATE_UPDATE) & mine).sum()),
        "updates_without_base": int((status == PduStatus.NO_BASE).sum()),
        "other_pdus": int((status == PduStatus.OTHER_TYPE).sum()),
        "other_exercise": int((status == PduStatus.OTHER_EXERCISE).sum()),
        "unsupported_version": int((status == PduStatus.UNSUPPORTED_VERSION).sum()),
        "corrupt": corrupt,
    }


def _u32(u8: NDArray[np.uint8], at: I64) -> NDArray[np.uint32]:
    """Big-endian u32 at each offset: one gather of 4-byte rows."""
    return sliding_window_view(u8, 4)[at].copy().view(">u4").reshape(-1).astype(np.uint32)


def _relocate(err: DisError, seg: _Segments) -> DisError:
    """Scan/decode errors carry buffer offsets and segment numbers; report record-relative ones."""
    if seg.stream or err.record is None:
        return DisError(err.message, err.offset, None)
    s = int(err.record)
    return DisError(err.message, err.offset - int(seg.base[s]), int(seg.record[s]))
