"""Vectorised MSB-first bit packing of unsigned fields of 1..24 bits (no per-field Python).

Fields are laid end to end: field ``i`` occupies bits ``[start_i, start_i + width_i)`` of the stream, where
bit 0 is the most significant bit of byte 0. The stream is zero-padded to a whole byte. Internally the stream
is a run of 32-bit big-endian words; a field of at most 24 bits starting in word ``k`` always ends inside
word ``k`` or ``k + 1``, so it sits in the 64-bit window ``(word k, word k+1)``. Fields starting in the same
word are contiguous, so ``bitwise_or.reduceat`` assembles each window in one pass; the windows' halves are
then OR-ed into place (window ``k``'s low half and window ``k + 1``'s high half share word ``k + 1``).
"""

from __future__ import annotations

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
