"""Finding PDU boundaries in byte buffers: datagrams (one segment each) and raw PDU streams.

A *segment* is a run of bytes that starts with a PDU: a UDP payload, a ``.dislog`` line, or a whole raw
file. Datagrams usually hold one PDU whose length field equals the payload size; that case is decided for
all segments at once with numpy. Bundled datagrams (several PDUs, optionally padded to 8 bytes) and raw
streams are walked by their length fields; a raw stream of equal-length PDUs is walked in vectorised runs
(one numpy comparison per few thousand PDUs) and only falls back to a plain loop over lengths where
lengths change. A corrupt length in a raw stream is reported and the scan resynchronises on the next
plausible header.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from protocol.dis.errors import DisError
from protocol.dis.pdu import HEADER_SIZE

I64 = NDArray[np.int64]
_MAX_KNOWN_TYPE = 72
_MAX_FAMILY = 13


@dataclass(slots=True)
class PduIndex:
    """Where each PDU is: absolute ``offset`` and ``length`` in the buffer, and its ``segment``."""

    offset: I64
    length: I64
    segment: I64

    def __len__(self) -> int:
        return int(self.offset.shape[0])


def _u16(u8: NDArray[np.uint8], at: I64) -> I64:
    return (u8[at].astype(np.int64) << 8) | u8[at + 1]


def _plausible(version: int, pdu_type: int, length: int) -> bool:
    return 1 <= version <= 7 and pdu_type != 0 and length >= HEADER_SIZE


def scan_segments(
    data: bytes, seg_start: I64, seg_end: I64
) -> tuple[PduIndex, NDArray[np.bool_], list[DisError]]:
    """PDUs of datagram-like segments. Returns (index, non-DIS mask per segment, issues).

    A segment whose first 12 bytes are not a plausible DIS header is *non-DIS* (counted, not an error).
    Issues carry absolute offsets and ``record`` = segment number (the caller maps it to a record).
    """
    u8 = np.frombuffer(data, dtype=np.uint8)
    seg_start = np.asarray(seg_start, dtype=np.int64)
    seg_end = np.asarray(seg_end, dtype=np.int64)
    nseg = seg_start.shape[0]
    size = seg_end - seg_start
    has_header = size >= HEADER_SIZE
    at = np.where(has_header, seg_start, 0)
    if u8.shape[0] < HEADER_SIZE:
        at = np.zeros(nseg, np.int64)
        u8 = np.zeros(HEADER_SIZE, np.uint8)
    version, ptype, length = u8[at], u8[at + 2], _u16(u8, at + 8)
    plausible = has_header & (version >= 1) & (version <= 7) & (ptype != 0) & (length >= HEADER_SIZE)
    single = plausible & (length == size)
    offs = [seg_start[single]]
    lens = [length[single]]
    segs = [np.flatnonzero(single)]
    issues: list[DisError] = []
    for s in np.flatnonzero(plausible & ~single).tolist():
        o, lo, sg = _walk_bundle(data, int(seg_start[s]), int(seg_end[s]), s, issues)
        offs.append(o)
        lens.append(lo)
        segs.append(sg)
    index = PduIndex(np.concatenate(offs), np.concatenate(lens), np.concatenate(segs))
    order = np.argsort(index.offset, kind="stable")
    return PduIndex(index.offset[order], index.length[order], index.segment[order]), ~plausible, issues


def _walk_bundle(data: bytes, p: int, end: int, seg: int, issues: list[DisError]) -> tuple[I64, I64, I64]:
    """PDUs of one multi-PDU (or damaged) datagram, walking length fields."""
    start = p
    offs: list[int] = []
    lens: list[int] = []
    while p < end:
        remaining = end - p
        if remaining < HEADER_SIZE or not _plausible(data[p], data[p + 2], (data[p + 8] << 8) | data[p + 9]):
            if offs:
                if not any(data[p:end]):
                    break  # zero padding after the last bundled PDU
                aligned = p + (-(p - start)) % 8
                if aligned != p and aligned + HEADER_SIZE <= end and not any(data[p:aligned]):
                    p = aligned
                    if _plausible(data[p], data[p + 2], (data[p + 8] << 8) | data[p + 9]):
                        continue
            issues.append(DisError(f"{remaining} bytes that are not a DIS PDU", p, seg))
            break
        length = (data[p + 8] << 8) | data[p + 9]
        if length > remaining:
            issues.append(
                DisError(f"PDU length {length} but only {remaining} bytes left (truncated)", p + 8, seg)
            )
            break
        offs.append(p)
        lens.append(length)
        p += length
    o = np.array(offs, np.int64)
    return o, np.array(lens, np.int64), np.full(o.shape[0], seg, np.int64)


def scan_stream(data: bytes, start: int = 0, end: int | None = None) -> tuple[PduIndex, list[DisError]]:
    """PDUs of a raw stream of concatenated PDUs (segment 0), resynchronising after corrupt records."""
    end = len(data) if end is None else end
    u8 = np.frombuffer(data, dtype=np.uint8)
    offs: list[I64] = []
    issues: list[DisError] = []
    window = 64
    p = start

    def resync(after: int) -> int:
        """The next plausible header at or after ``after``, searched in growing vectorised windows."""
        lo, width = after, 4096
        while lo < end:
            hi = min(lo + width, end)
            found = _resync_candidates(u8, lo, hi, end)
            if found.shape[0]:
                return int(found[0])
            lo, width = hi, width * 2
        return end

    while p < end:
        remaining = end - p
        if remaining < HEADER_SIZE:
            issues.append(DisError(f"{remaining} trailing bytes, too short for a PDU header", p))
            break
        version, ptype, length = data[p], data[p + 2], (data[p + 8] << 8) | data[p + 9]
        if not _plausible(version, ptype, length):
            nxt = resync(p + 1)
            issues.append(DisError(f"not a DIS PDU header; skipped {nxt - p} bytes", p))
            p = nxt
            continue
        if length > remaining:
            nxt = resync(p + 1)
            issues.append(
                DisError(f"PDU length {length} but only {remaining} bytes left; skipped {nxt - p}", p + 8)
            )
            p = nxt
            continue
        # a vectorised run of PDUs with the same version, type and length
        kmax = min(remaining // length, window)
        if kmax >= 8:
            cand = p + length * np.arange(kmax, dtype=np.int64)
            ok = (_u16(u8, cand + 8) == length) & (u8[cand] == version) & (u8[cand + 2] == ptype)
            m = kmax if bool(ok.all()) else int(np.argmin(ok))
            offs.append(cand[:m])
            p += m * length
            window = window * 2 if m == kmax else 64
            if m >= 4:
                continue
        # a plain loop over lengths where they vary (offsets only: lengths are re-read vectorised)
        lo: list[int] = []
        add = lo.append
        last = end - HEADER_SIZE
        for _ in range(4096):
            if p > last:
                break
            length = (data[p + 8] << 8) | data[p + 9]
            if not 0 < data[p] < 8 or not data[p + 2] or length < HEADER_SIZE or p + length > end:
                break
            add(p)
            p += length
        offs.append(np.array(lo, np.int64))
    o = np.concatenate(offs) if offs else np.zeros(0, np.int64)
    ln = _u16(u8, o + 8) if o.shape[0] else np.zeros(0, np.int64)
    return PduIndex(o, ln, np.zeros(o.shape[0], np.int64)), issues


def _resync_candidates(u8: NDArray[np.uint8], lo: int, hi: int, end: int) -> I64:
    """Positions in [lo, hi) that look like a PDU header whose PDU fits before ``end`` and is followed by
    another plausible header (or ends exactly at ``end``), vectorised."""
    hi = min(hi, end - HEADER_SIZE + 1)
    if hi <= lo:
        return np.zeros(0, np.int64)
    pos = np.arange(lo, hi, dtype=np.int64)
    v, t, f = u8[pos], u8[pos + 2], u8[pos + 3]
    length = _u16(u8, pos + 8)
    ok = (
        (v >= 1) & (v <= 7) & (t >= 1) & (t <= _MAX_KNOWN_TYPE) & (f <= _MAX_FAMILY) & (length >= HEADER_SIZE)
    )
    ok &= pos + length <= end
    nxt = pos + length
    at_end = nxt == end
    inner = ok & ~at_end & (nxt <= end - HEADER_SIZE)
    follow = np.zeros(pos.shape[0], bool)
    j = nxt[inner]
    follow[inner] = (u8[j] >= 1) & (u8[j] <= 7) & (u8[j + 2] >= 1) & (_u16(u8, j + 8) >= HEADER_SIZE)
    return pos[ok & (at_end | follow)]
