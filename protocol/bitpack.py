"""Vectorised MSB-first bit packing of unsigned fields of 1..24 bits (no per-field Python).

Fields are laid end to end: field ``i`` occupies bits ``[start_i, start_i + width_i)`` of the stream, where
bit 0 is the most significant bit of byte 0. The stream is zero-padded to a whole byte. Internally the stream
is a run of 32-bit big-endian words; a field of at most 24 bits starting in word ``k`` always ends inside
word ``k`` or ``k + 1``, so it sits in the 64-bit window ``(word k, word k+1)``. Fields starting in the same
word are contiguous, so ``bitwise_or.reduceat`` assembles each window in one pass; the windows' halves are
then OR-ed into place (window ``k``'s low half and window ``k + 1``'s high half share word ``k + 1``).
"""

from __future__ import annotations

import math
import threading

import numpy as np

_U64 = np.uint64


def bit_starts(widths: np.ndarray) -> tuple[np.ndarray, int]:
    """Start bit of each field and the total bit count."""
    ends = np.cumsum(widths, dtype=np.int64)
    total = int(ends[-1]) if len(ends) else 0
    return ends - widths, total


def pack_bits(values: np.ndarray, widths: np.ndarray) -> bytes:
    """Pack ``values[i]`` (already ``< 2**widths[i]``) in ``widths[i]`` bits each; the padded bytes."""
    widths = np.asarray(widths, np.int64)
    starts, total = bit_starts(widths)
    nbytes = (total + 7) >> 3
    if nbytes == 0:
        return b""
    word = starts >> 5
    end = (starts & 31) + widths  # <= 31 + 24: inside the 64-bit window of words (word, word + 1)
    x = np.asarray(values).astype(_U64) << (64 - end).view(_U64)
    first = np.flatnonzero(np.concatenate([[True], word[1:] != word[:-1]]))
    windows = np.bitwise_or.reduceat(x, first)
    at = word[first]
    words = np.zeros((total >> 5) + 2, _U64)
    words[at] = windows >> _U64(32)
    words[at + 1] |= windows & _U64(0xFFFFFFFF)
    return words.astype(">u4").tobytes()[:nbytes]


def unpack_bits(data: bytes, starts: np.ndarray, widths: np.ndarray) -> np.ndarray:
    """The unsigned fields at bit offsets ``starts`` with ``widths`` (the caller checks they fit ``data``)."""
    return read_fields(body_words(data), np.asarray(starts, np.int64), np.asarray(widths, np.int64))


def body_words(data: bytes) -> np.ndarray:
    """``data`` as 32-bit big-endian words (uint64), with two zero words of slack for :func:`read_fields`."""
    nwords = (len(data) + 3) // 4 + 2
    return np.frombuffer(bytes(data).ljust(nwords * 4, b"\0"), ">u4").astype(_U64)


def read_fields(words: np.ndarray, starts: np.ndarray, widths: np.ndarray) -> np.ndarray:
    """Like :func:`unpack_bits` on :func:`body_words` output, also allowing width 0 (reads 0)."""
    word = starts >> 5
    window = ((words[word] << _U64(32)) | words[word + 1]) << (starts & 31).view(_U64)
    return ((window >> _U64(1)) >> (63 - widths).view(_U64)).astype(np.int64)


# -- grouped 64-bit packing: the joint-update hot path -------------------------------------------------------
#
# A soldier's fields are handled as a dense (n, C) matrix (absent fields have width 0), C a multiple of the
# group size g. Each run of g neighbouring fields is first merged into one *group* of at most 64 bits held
# top-aligned in a uint64 (bits beyond the group's width are 0), so every later pass touches C / g elements
# instead of C. A group starting at stream bit s lies in the 64-bit words s >> 6 and (s >> 6) + 1; groups are
# in stream order, so those starting in the same word are contiguous and one ``bitwise_or.reduceat`` per half
# assembles the words. numpy defines shifts by 64 or more as 0, which absent (width-0) groups rely on.
# Version 2's encoder works field-major ((C, n): each field a row over the soldiers) and merges with
# :func:`merge_columns`, whose passes run along the soldiers; the groups are the same.


class Scratch:
    """Named work buffers reused from call to call (per thread: see :func:`scratch`).

    A fresh multi-megabyte numpy array costs a page fault per 4 KiB page on first touch, which on a VM costs
    more than the arithmetic done on it; batches of similar size therefore reuse these. Buffers above
    ``limit`` bytes are not kept (memory stays bounded whatever the batch), and a caller must not let a
    buffer escape (return copies) nor ask for one name twice while still using it.
    """

    def __init__(self, limit: int = 64 << 20) -> None:
        self.limit = limit
        self._bufs: dict[str, np.ndarray] = {}

    def get(self, name: str, shape: tuple[int, ...], dtype: type | np.dtype) -> np.ndarray:
        dt = np.dtype(dtype)
        nbytes = math.prod(shape) * dt.itemsize
        buf = self._bufs.get(name)
        if buf is None or buf.nbytes < nbytes:
            buf = np.empty(max(nbytes, 64), np.uint8)
            if nbytes <= self.limit:
                self._bufs[name] = buf
        return buf[:nbytes].view(dt).reshape(shape)


_LOCAL = threading.local()


def scratch() -> Scratch:
    """This thread's :class:`Scratch`."""
    s = getattr(_LOCAL, "scratch", None)
    if s is None:
        s = _LOCAL.scratch = Scratch()
    return s


def group_size(max_width: int) -> int:
    """Fields merged per group: as many as always fit 64 bits."""
    return max(1, 64 // max(1, max_width))


def merge_groups(values: np.ndarray, widths: np.ndarray, g: int) -> tuple[np.ndarray, np.ndarray]:
    """Top-aligned groups (n, C/g) uint64 and their bit widths (n, C/g) int64 of ``values`` (n, C).

    ``values`` may hold bits above ``widths`` (e.g. negative deltas): they are dropped. The results are
    :func:`scratch` buffers (``merge.*``), valid until the next call.
    """
    sc = scratch()
    n, c = values.shape
    shape = (n, c // g)
    w = widths.reshape(n, c // g, g)
    group = sc.get("merge.group", shape, _U64)
    used = sc.get("merge.used", shape, _U64)
    wj = sc.get("merge.wj", shape, _U64)
    group[:] = 0
    used[:] = 0
    top = sc.get("merge.top", (n, c), _U64)  # every field top-aligned in one contiguous pass
    sh = sc.get("merge.sh", (n, c), _U64)
    np.subtract(64, widths, out=sh, dtype=_U64)
    np.copyto(top, values, casting="unsafe")
    np.left_shift(top, sh, out=top)
    t3 = top.reshape(n, c // g, g)
    for j in range(g):  # over the g fields of a group (a table constant), each pass vectorised
        np.right_shift(t3[:, :, j], used, out=wj)
        np.bitwise_or(group, wj, out=group)
        np.add(used, w[:, :, j], out=used, dtype=_U64)
    return group, used.view(np.int64)


def merge_columns(values: np.ndarray, widths: np.ndarray, g: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`merge_groups` of field-major input: ``values`` (C, n) int32 and ``widths`` (C, n) uint8, one
    row per field (C a multiple of ``g``); the same groups and widths, (n, C/g), row-major. Every pass runs
    along the n soldiers (long, contiguous loops) instead of across a soldier's few fields. Fields of at
    most 16 bits with ``g = 4`` (the usual tables) merge as a tree in uint32: fields into 32-bit pairs,
    pairs into 64-bit quads. The results are :func:`scratch` buffers (``cols.*``), valid until the next
    call."""
    c, n = values.shape
    sc = scratch()
    u = values.view(np.uint32) if values.dtype == np.int32 else values.astype(np.uint32)
    out, out_w = sc.get("cols.out", (n, c // g), _U64), sc.get("cols.out_w", (n, c // g), np.int64)
    if g == 4 and c and int(widths.max(initial=0)) <= 16:
        # widths and shifts stay uint8 (a quarter of the memory traffic of uint32 copies of them)
        w = widths if widths.dtype == np.uint8 else widths.astype(np.uint8)
        sh = sc.get("cols.sh", (c, n), np.uint8)
        np.subtract(np.uint8(32), w, out=sh)
        top = sc.get("cols.top", (c, n), np.uint32)
        np.left_shift(u, sh, out=top)  # top-aligned in 32 bits; width 0 shifts by 32: 0
        pair, pw = sc.get("cols.pair", (c // 2, n), np.uint32), sc.get("cols.pw", (c // 2, n), np.uint8)
        np.right_shift(top[1::2], w[0::2], out=pair)
        pair |= top[0::2]
        np.add(w[0::2], w[1::2], out=pw)
        group, low = sc.get("cols.group", (c // 4, n), _U64), sc.get("cols.low", (c // 4, n), _U64)
        np.copyto(group, pair[0::2])
        group <<= _U64(32)
        room = sc.get("cols.room", (c // 4, n), np.uint8)
        np.subtract(np.uint8(32), pw[0::2], out=room)  # the high pair's room, as a shift
        np.copyto(low, pair[1::2])
        low <<= room
        group |= low
        np.add(pw[0::2], pw[1::2], out=room)
        np.copyto(out_w, room.T)
    else:
        group = np.zeros((c // g, n), _U64)
        gw = np.zeros((c // g, n), np.int64)
        for j in range(g):
            wj = widths[j::g].astype(_U64)
            t = u[j::g].astype(_U64) << (_U64(64) - wj)
            group |= t >> gw.view(_U64)
            gw += wj.view(np.int64)
        np.copyto(out_w, gw.T)
    np.copyto(out, group.T)
    return out, out_w


def place_groups(groups: np.ndarray, starts: np.ndarray, nwords: int) -> np.ndarray:
    """Native uint64 words (``nwords`` + 2 of slack) holding top-aligned ``groups`` at bit ``starts``.

    ``starts`` must be non-decreasing in flat order, the groups must not overlap and their bits past their
    widths must be 0 (as :func:`merge_groups` and :func:`merge_columns` leave them). The result is a
    :func:`scratch` buffer (``place.words``), valid until the next call.
    """
    sc = scratch()
    s = starts.reshape(-1)
    gr = groups.reshape(-1)
    m = len(s)
    words = sc.get("place.words", (nwords + 2,), _U64)
    words[:] = 0
    if m == 0:
        return words
    word = sc.get("place.word", (m,), np.int64)
    off = sc.get("place.off", (m,), _U64)
    part = sc.get("place.part", (m,), _U64)
    np.right_shift(s, 6, out=word)
    np.bitwise_and(s, 63, out=off, casting="unsafe")
    edge = sc.get("place.edge", (m,), bool)
    edge[0] = True
    np.not_equal(word[1:], word[:-1], out=edge[1:])
    first = np.flatnonzero(edge)
    at = word[first]
    np.right_shift(gr, off, out=part)
    words[at] = np.bitwise_or.reduceat(part, first)
    # only a run's last group can reach into the next word: the others end where the next one starts, in
    # their word, and their bits past their width are 0 (a gather of one group a word, not a second pass)
    last = np.empty_like(first)
    last[:-1] = first[1:] - 1
    last[-1] = m - 1
    words[at + 1] |= gr[last] << (_U64(64) - off[last])
    return words


def be_words(data: bytes | memoryview) -> np.ndarray:
    """``data`` as native uint64 of its big-endian 64-bit words, zero-padded, with two words of slack."""
    nwords = (len(data) + 7) // 8 + 2
    buf = np.zeros(nwords * 8, np.uint8)
    buf[: len(data)] = np.frombuffer(data, np.uint8)
    return buf.view(">u8").astype(_U64)


def read_groups(words: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """Top-aligned 64-bit windows of :func:`be_words` output at bit ``starts`` (any shape)."""
    word = starts >> 6
    off = (starts & 63).view(_U64)
    return (words[word] << off) | (words[word + 1] >> (_U64(64) - off))


def split_groups(groups: np.ndarray, widths: np.ndarray, g: int) -> np.ndarray:
    """Inverse of :func:`merge_groups`: the unsigned fields (n, C) int32 given their ``widths`` (n, C)."""
    sc = scratch()
    n, c = widths.shape
    shape = (n, c // g)
    w = widths.reshape(n, c // g, g)
    out = np.empty((n, c // g, g), np.int32)
    used = sc.get("split.used", shape, _U64)
    sh = sc.get("split.sh", shape, _U64)
    x = sc.get("split.x", shape, _U64)
    used[:] = 0
    for j in range(g):
        np.subtract(64, w[:, :, j], out=sh, dtype=_U64)
        np.left_shift(groups, used, out=x)
        np.right_shift(x, sh, out=x)
        np.copyto(out[:, :, j], x, casting="unsafe")
        np.add(used, w[:, :, j], out=used, dtype=_U64)
    return out.reshape(n, c)


def set_rows(a: np.ndarray, idx: np.ndarray, rows: np.ndarray) -> None:
    """``a[idx] = rows`` for an (N, F) ``a`` whose rows are contiguous (a column slice of a wider array too)
    and C-contiguous (n, F) ``rows``: each row moved as one element of its F fields' bytes. numpy's fancy
    assignment of rows steps through each row's fields: a third dearer at 64 int32 fields (the encoder's
    state, written for every soldier sent). Into a C-contiguous ``a`` they go by ``np.put`` (a plain loop of
    row copies: about 40 % less than the fancy assignment of the same whole rows, 5,000 rows of 64 int32).
    Pairs of float64 (root offsets, travel) go as one complex128 each, a dtype numpy has ready (a void dtype
    made per call costs ~4 us, the cost of a request path's few rows; 10,000 rows: ~170 us fancy, ~18)."""
    f = a.shape[1]
    if not f or a.dtype != rows.dtype or a.strides[1] != a.itemsize or not rows.flags.c_contiguous:
        a[idx] = rows
        return
    row = np.dtype(np.complex128) if a.dtype == np.float64 and f == 2 else np.dtype((np.void, a.itemsize * f))
    if a.flags.c_contiguous:  # np.put would write through a copy of a strided ``a``
        np.put(a.view(row).reshape(-1), idx, rows.view(row).reshape(-1))
    else:
        a.view(row)[idx] = rows.view(row)


def take_rows(a: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """``a[idx]`` (a new C-contiguous array) for a C-contiguous (N, F) ``a``, each row taken as one element of
    its fields' bytes: about half the CPU of numpy's fancy indexing of rows at 64 int32 fields."""
    f = a.shape[1]
    if not f or not a.flags.c_contiguous:
        return a[idx]
    row = np.dtype((np.void, a.itemsize * f))
    return np.take(a.view(row), idx, axis=0).view(a.dtype).reshape(len(idx), f)
