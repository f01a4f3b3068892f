"""Version 2 joint updates: per-entry delta widths and predicted deltas (docs/PROTOCOL.md §8.5).

Version 1 sends every changed field of a soldier as a delta from its last code, all in one width ``k`` (the
widest delta of the soldier). Animation is smooth, so version 2 sends the *residual* from a linear prediction
``2 · cur − before`` (``before``: the code before the soldier's last update), each entry in its own width: a
walking soldier's pelvis travel, nearly constant per tick, then costs a few bits, not the widest joint's.
Both sides keep ``before`` and the tick of the last update next to ``cur``. The prediction holds only for a
soldier updated at the tick just before (else it is ``cur``: a plain delta), and an entry sent absolute
restarts it (``before = cur``): two receivers that got different histories of an idle soldier predict alike,
so a server's late joiner can share its group's encode (:mod:`protocol.shared_encode`).

Frame layout after the indices (all MSB-first, each section zero-padded to a byte)::

    header: count × (1-bit mode, E-bit mask)        mode 0 = every present entry absolute, 1 = delta
    widths: a 4-bit width w per present entry of every mode-1 soldier (0 = this entry absolute)
    fields: per present entry, its absolute fields or its w-bit two's-complement residuals (qidx not sent)

Everything is vectorised over the batch, as in :mod:`protocol.updates` (which holds the version-1 path and the
shared frame splitting).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np

from protocol.update_table import TableLayout

MODE_BITS = 1
WIDTH_BITS = 4
MAX_WIDTH = (1 << WIDTH_BITS) - 1


@dataclass(frozen=True)
class Rows:
    """What the packer needs of n soldier rows (one format), and the prediction state they lead to."""

    header: np.ndarray  # (n, H) uint8 header bits: mode, then the E mask bits
    nibbles: np.ndarray  # flat uint8 widths, row after row (the width section's nibbles)
    nibble_count: np.ndarray  # (n,) nibbles of each row
    row_bits: np.ndarray  # (n,) field bits of each row
    values: np.ndarray  # (n, F) field values (absolute codes or signed residuals)
    widths: np.ndarray  # (n, C) uint8 field widths (C: the plan's padded columns; 0 = absent)
    state: np.ndarray  # (n, F + 1) the prediction state after these rows (see :func:`state_columns`)


def _entry_bits(mag: np.ndarray) -> np.ndarray:
    """int32 bit lengths plus one of magnitudes >= 0 (float32: exact below 2^24, where widths stop at 15)."""
    return np.frexp(mag.astype(np.float32))[1].astype(np.int32) + 1


@cache
def _entry_passes(
    starts: tuple[int, ...], counts: tuple[int, ...]
) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
    """Per ``j`` >= 1: the entries with more than ``j`` fields and their ``j``-th field's column."""
    st, ct = np.array(starts, np.int64), np.array(counts, np.int64)
    out = []
    for j in range(1, int(ct.max(initial=1))):
        es = np.flatnonzero(ct > j)
        out.append((es, st[es] + j))
    return tuple(out)


def entry_max(lay: TableLayout, values: np.ndarray) -> np.ndarray:
    """(n, E): each entry's largest field value of ``values`` (n, F). A column pass per field position in
    an entry (at most 7) instead of ``np.maximum.reduceat`` along rows, which runs an inner loop per
    (soldier, entry) pair and costs about twice as much for a server's batch."""
    out = values[:, lay.entry_start]
    for es, cols in _entry_passes(tuple(lay.entry_start.tolist()), tuple(lay.entry_nfields.tolist())):
        if len(es) == out.shape[1]:
            np.maximum(out, values[:, cols], out=out)
        else:
            out[:, es] = np.maximum(out[:, es], values[:, cols])
    return out


def state_columns(nfields: int) -> int:
    """Columns of the prediction state: ``before``'s codes, then the tick of the last update (as uint32)."""
    return nfields + 1


def tick_code(tick: int) -> np.int32:
    """A u32 tick as stored in the state's int32 tick column."""
    return np.uint32(tick & 0xFFFFFFFF).view(np.int32)


def field_widths(
    lay: TableLayout, ncols: int, present: np.ndarray, absolute: np.ndarray, w: np.ndarray
) -> np.ndarray:
    """(n, ncols) uint8: each present field's width, absolute entries at their own, delta entries ``w``."""
    n, nf = present.shape[0], lay.nfields
    out = np.zeros((n, ncols), np.uint8)
    wd = np.where(absolute | ~present, 0, w).astype(np.uint8)
    np.multiply(np.take(wd, lay.entry_of, axis=1), ~lay.is_qidx, out=out[:, :nf], casting="unsafe")
    rows = np.flatnonzero((absolute & present).any(axis=1))  # few: new soldiers, qidx flips, jumps
    if len(rows):
        absf = np.take(absolute[rows] & present[rows], lay.entry_of, axis=1)
        out[rows, :nf] = np.where(absf, lay.width, out[rows, :nf])
    return out


def residuals(q: np.ndarray, cur: np.ndarray, state: np.ndarray, tick: int) -> np.ndarray:
    """(n, F) int32: ``q`` minus the prediction, ``2 · cur − before`` for soldiers whose last update was at
    ``tick − 1`` (mod 2³²), else ``cur``."""
    nf = q.shape[1]
    resid = q - cur
    rows = np.flatnonzero(state[:, nf] == tick_code(tick - 1))
    if len(rows) == len(q):
        resid -= cur
        resid += state[:, :nf]
    elif len(rows):
        resid[rows] -= cur[rows] - state[rows, :nf]
    return resid


def encode_rows(
    lay: TableLayout,
    ncols: int,
    q: np.ndarray,
    cur: np.ndarray,
    state: np.ndarray,
    known: np.ndarray,
    present: np.ndarray,
    tick: int,
) -> Rows:
    """Version-2 rows of soldiers with at least one present entry (``present`` (n, E): changed entries).

    Per entry the smallest width holding every residual; an entry whose residuals need more than 15 bits,
    whose qidx changed, or whose residuals cost at least its absolute bits goes absolute (width 0); a row
    whose entries cost no less in delta mode, or that the receiver does not know, goes absolute whole.
    """
    resid = residuals(q, cur, state, tick)
    mag = np.maximum(resid, ~resid)  # the bit length of max(r, -r - 1), plus a sign bit, holds r
    mag[:, lay.qidx_fields] = 0
    ke = _entry_bits(entry_max(lay, mag))  # (n, E): one width per entry
    qflip = np.zeros(present.shape, bool)
    qflip[:, lay.entry_of[lay.qidx_fields]] = q[:, lay.qidx_fields] != cur[:, lay.qidx_fields]
    absbits = lay.entry_absbits.astype(np.int32)
    delta_bits = ke * lay.entry_ndelta.astype(np.int32)
    ent_abs = qflip | (ke > MAX_WIDTH) | (delta_bits >= absbits)
    cost = np.where(ent_abs, absbits, delta_bits)
    cost += WIDTH_BITS
    cost *= present
    cost_delta = cost.sum(axis=1)
    cost_abs = (present * absbits).sum(axis=1)
    row_abs = ~known | (cost_abs <= cost_delta)
    ent_abs |= row_abs[:, None]
    w = np.where(ent_abs, 0, ke)
    nibble_count = np.where(row_abs, 0, present.sum(axis=1))
    header = np.empty((len(q), MODE_BITS + present.shape[1]), np.uint8)
    header[:, 0] = ~row_abs
    header[:, MODE_BITS:] = present
    sent_abs = ent_abs & present
    values, after = resid, np.empty((len(q), q.shape[1] + 1), np.int32)
    after[:, :-1] = cur
    after[:, -1] = tick_code(tick)
    rows = np.flatnonzero(sent_abs.any(axis=1))  # few: the absolute entries send codes, restart predictions
    if len(rows):
        absf = np.take(sent_abs[rows], lay.entry_of, axis=1)
        values[rows] = np.where(absf, q[rows], resid[rows])
        after[rows, :-1] = np.where(absf, q[rows], cur[rows])
    return Rows(
        header=header,
        nibbles=w[present & ~row_abs[:, None]].astype(np.uint8),
        nibble_count=nibble_count,
        row_bits=np.where(row_abs, cost_abs, cost_delta - WIDTH_BITS * nibble_count),
        values=values,
        widths=field_widths(lay, ncols, present, ent_abs, w),
        state=after,
    )


def pack_nibbles(nibbles: np.ndarray) -> bytes:
    """4-bit values, first in the high half of a byte; an odd count ends in a zero nibble."""
    nib = np.asarray(nibbles, np.uint8)
    if len(nib) & 1:
        nib = np.append(nib, np.uint8(0))
    return ((nib[0::2] << 4) | nib[1::2]).astype(np.uint8).tobytes()


def unpack_nibbles(data: bytes, count: int) -> tuple[np.ndarray, bool]:
    """``count`` 4-bit values of ``data`` (``(count + 1) // 2`` bytes) and whether the pad nibble is zero."""
    b = np.frombuffer(data, np.uint8, (count + 1) // 2)
    nib = np.empty(2 * len(b), np.uint8)
    nib[0::2] = b >> 4
    nib[1::2] = b & 15
    return nib[:count], not (count & 1) or nib[count] == 0


@dataclass(frozen=True)
class Header:
    """A version-2 frame's per-soldier reading: mode, mask, widths, and where each row's fields are."""

    delta: np.ndarray  # (n,) bool: mode 1
    mask: np.ndarray  # (n, E) bool
    absolute: np.ndarray  # (n, E) bool: present entries sent absolute (mode 0 or width 0)
    w: np.ndarray  # (n, E) int64 widths (0 where absolute or absent)
    widths: np.ndarray  # (n, C) uint8 field widths


def read_header(lay: TableLayout, ncols: int, bits: np.ndarray, nibbles: np.ndarray) -> Header:
    """The rows' header from their (n, 1 + E) header bits and the width section's nibbles."""
    delta = bits[:, 0].astype(bool)
    mask = bits[:, MODE_BITS:].astype(bool)
    w = np.zeros(mask.shape, np.int64)
    w[mask & delta[:, None]] = nibbles
    absolute = mask & ((w == 0) | ~delta[:, None])
    return Header(delta, mask, absolute, w, field_widths(lay, ncols, mask, absolute, w))


def apply_rows(
    lay: TableLayout, hdr: Header, vals: np.ndarray, cur: np.ndarray, state: np.ndarray, tick: int
) -> tuple[np.ndarray, np.ndarray]:
    """The rows' new ``(cur, state)`` from their unsigned field values ``vals`` (n, F) as read at ``tick``.

    Dense int32 passes over (n, F): a field of width 0 (absent, or a delta entry's qidx) reads 0 and keeps its
    code; the few rows with an absolute entry are fixed up on their own.
    """
    nf = lay.nfields
    width = hdr.widths[:, :nf]
    sign = np.right_shift(np.left_shift(np.int32(1), width, dtype=np.int32), 1)  # 2^(w-1); 0 for w = 0
    new = vals.astype(np.int32)
    new ^= sign  # w-bit two's complement: (v ^ 2^(w-1)) - 2^(w-1)
    new -= sign
    new += cur
    follows = np.flatnonzero(state[:, nf] == tick_code(tick - 1))
    if len(follows):  # predicted: add the velocity cur - before to the fields sent as residuals
        moved = cur[follows] - state[follows, :nf]
        moved *= width[follows] != 0
        new[follows] += moved
    after = np.empty((len(cur), nf + 1), np.int32)
    after[:, :nf] = cur
    after[:, nf] = tick_code(tick)
    rows = np.flatnonzero((hdr.absolute & hdr.mask).any(axis=1))
    if len(rows):
        absf = np.take(hdr.absolute[rows], lay.entry_of, axis=1)
        new[rows] = np.where(absf, vals[rows], new[rows])
        after[rows, :nf] = np.where(absf, new[rows], cur[rows])
    return new, after
