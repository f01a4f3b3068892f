"""Version 2's per-row encode as two compiled loops (numba, optional: the ``fast`` extra).

The numpy path (:func:`protocol.predicted.encode_rows`, :func:`protocol.bitpack.merge_columns`,
:func:`protocol.bitpack.place_groups`) makes some fifteen passes over (n, F) arrays of the rows sent, each
a trip through memory (docs/SCALING.md: a front-end's encode is memory-bound, and it is most of its CPU).
Here one loop reads each row's codes once and chooses its widths (:func:`rows_meta`), and a second writes
its fields' bits straight into the frame words (:func:`pack_fields`) once the frames are cut: the same
choices and the same bits, so the same bytes (``tests/test_protocol_fused_encode.py``, and the frozen
reference tests run on whichever path is installed).

Without numba (or with ``TTES_FUSED=0``) :data:`AVAILABLE` is False and the encoder keeps the numpy path.
numba is imported, and the loops compiled (a few seconds) or loaded from its cache beside this module,
at the first encode, or at a server's start (:func:`warm`): a client that imports :mod:`protocol` never
pays for it.
"""

from __future__ import annotations

import importlib.util
import os
from collections.abc import Callable
from typing import Any

import numpy as np

AVAILABLE = importlib.util.find_spec("numba") is not None and os.environ.get("TTES_FUSED", "1") != "0"
_compiled: dict[str, Callable[..., Any]] = {}


def kernel(name: str) -> Callable[..., Any]:
    """The compiled loop of that name below (``AVAILABLE`` only)."""
    hit = _compiled.get(name)
    if hit is None:
        for func in (rows_meta, pack_fields, jack_codes, store_rows):
            _compiled[func.__name__] = compiled(func)
        hit = _compiled[name]
    return hit


def compiled(func: Callable[..., Any]) -> Callable[..., Any]:
    """``func`` compiled by numba (``AVAILABLE`` only), cached beside its module where numba may write."""
    import numba  # here: its import costs 0.3 s of CPU, paid only where something encodes

    try:
        return numba.njit(cache=True, nogil=True)(func)
    except RuntimeError:  # no cache directory it may write (numba's "no locator"): compile each start
        return numba.njit(nogil=True)(func)


def warm() -> None:
    """Compile (or load) the loops for the codes a server encodes (int32 from its own board, uint16 from a
    front-end's; read-only as the board lends them, or a copy of some of their rows), and those of its
    board's quantise and store, so that no client's first update (nor a shard's first tick) waits for it."""
    if not AVAILABLE:
        return
    from protocol.predicted import fused_rows  # (predicted imports this module)
    from protocol.update_table import example_di_table
    from protocol.updates import _Plan

    cols = _Plan(example_di_table()).v2
    state = np.zeros((2, cols.nfields + 2), np.uint16)
    for dtype in (np.int32, np.uint16):
        for lent in (False, True):
            q = np.ones((2, cols.nfields), dtype)
            q.setflags(write=not lent)
            rows = fused_rows(
                cols, (q, state[:, :-2].copy(), state), np.ones(2, bool), np.ones((2, cols.nent), bool), 1
            )
            assert rows.pack is not None
            rows.pack(
                np.cumsum(rows.row_bits) - rows.row_bits,
                np.zeros(int(rows.row_bits.sum()) // 64 + 3, np.uint64),
            )
    for dtype in (np.int32, np.uint16):  # a shard's board (its own codes), a front-end's (the batches')
        kernel("store_rows")(np.zeros((4, 2), dtype), np.arange(2), np.ones((2, 2), dtype), np.zeros(2, bool))
    lay = example_di_table().layout
    g, nd = len(lay.qidx_fields), len(lay.dof_fields)
    figures = np.zeros((2, g, 7), np.float32)
    figures[..., 3] = 1.0
    kernel("jack_codes")(
        np.zeros((2, nd), np.float32),
        figures,
        np.zeros(nd, bool),
        lay.lo,
        1.0 / lay.step,
        lay.max_code.astype(np.float64),
        *(np.ascontiguousarray(a, np.int64) for a in (lay.dof_fields, lay.pos_fields, lay.qidx_fields)),
        np.ascontiguousarray(lay.comp_fields, np.int64),
        np.zeros((2, lay.nfields), np.int32),
    )


def rows_meta(
    q: np.ndarray,
    cur: np.ndarray,
    before: np.ndarray,
    predicts: np.ndarray,
    known: np.ndarray,
    present: np.ndarray,
    entry_of: np.ndarray,
    is_qidx: np.ndarray,
    ndelta: np.ndarray,
    absbits: np.ndarray,
    max_width: int,
    w: np.ndarray,
    ent_abs: np.ndarray,
    header: np.ndarray,
    nibbles: np.ndarray,
    nibble_count: np.ndarray,
    row_bits: np.ndarray,
    restart: np.ndarray,
) -> int:
    """Per row, what ``predicted._choose`` decides: each entry's width ``w`` (n, E) (0: absent or sent
    absolute) and the entries sent absolute ``ent_abs`` (n, E); and what the frame carries: the header bits
    (n, 1 + E), the width nibbles one row after another (returns their count) and each row's count, its
    field bits, and whether an entry of it goes absolute (``restart``: its prediction restarts). The
    residual is ``q − cur`` less ``cur − before`` where ``predicts``; an entry's width is the bit length of
    its delta fields' largest ``max(r, −r−1)`` plus a sign bit; an entry whose qidx changed goes absolute.
    One flat loop over a row's fields (a loop per entry, of one to six fields, mispredicts its exits: half
    as fast again)."""
    n, nf = q.shape
    ne = len(ndelta)
    top = np.zeros(ne, np.int64)
    flip = np.zeros(ne, np.bool_)
    nib = 0
    for i in range(n):
        top[:] = 0
        flip[:] = False
        p = predicts[i]
        for f in range(nf):
            e = entry_of[f]
            c = np.int64(cur[i, f])
            if is_qidx[f]:
                flip[e] |= np.int64(q[i, f]) != c
                continue
            r = np.int64(q[i, f]) - c
            if p:
                r = r - c + np.int64(before[i, f])
            top[e] = max(top[e], r ^ (r >> 63))  # max(r, -r - 1), without a branch on the sign
        delta_bits = 0
        abs_bits = 0
        count = 0
        restarts = False
        for e in range(ne):
            x = top[e]  # its bit length, by halving without branches (a loop's exit mispredicts)
            k = 1
            for half in (16, 8, 4, 2, 1):
                t = (x >> half != 0) * half
                x >>= t
                k += t
            k += x
            cost = k * ndelta[e]
            a = k > max_width or cost >= absbits[e] or flip[e]
            if a:
                cost = absbits[e]
            ent_abs[i, e] = a
            w[i, e] = 0 if a or not present[i, e] else k
            if present[i, e]:
                delta_bits += cost + 4
                abs_bits += absbits[e]
                count += 1
                restarts |= a
        mode0 = abs_bits <= delta_bits or not known[i]
        if mode0:
            ent_abs[i, :] = True
            w[i, :] = 0
            restarts = count > 0
        header[i, 0] = not mode0
        for e in range(ne):
            header[i, 1 + e] = present[i, e]
            if present[i, e] and not mode0:
                nibbles[nib] = w[i, e]
                nib += 1
        nibble_count[i] = 0 if mode0 else count
        restart[i] = restarts
        row_bits[i] = abs_bits if mode0 else delta_bits - 4 * count
    return nib


def pack_fields(
    q: np.ndarray,
    cur: np.ndarray,
    before: np.ndarray,
    predicts: np.ndarray,
    present: np.ndarray,
    ent_abs: np.ndarray,
    w: np.ndarray,
    entry_of: np.ndarray,
    is_qidx: np.ndarray,
    width: np.ndarray,
    starts: np.ndarray,
    words: np.ndarray,
) -> None:
    """OR each row's field bits into ``words`` (native uint64 holding the stream's 64-bit words, MSB first,
    zeroed, with a word of slack) from bit ``starts[i]``: a present entry's fields in order, absolute (its
    codes at their widths, qidx too) or its delta fields' residuals in ``w`` bits. Absent fields go in as
    0 bits of value 0 (no branch on them)."""
    n, nf = q.shape
    at = np.int64(0)  # the word being filled, ``acc`` its bits so far, ``off`` how many
    acc = np.uint64(0)
    off = np.int64(0)
    for i in range(n):
        start = np.int64(starts[i])
        if start != at * 64 + off:  # a frame's first row: its body starts a word
            words[at] |= acc
            at, acc, off = start >> 6, np.uint64(0), start & 63
        p = predicts[i]
        for f in range(nf):
            e = entry_of[f]
            x = np.int64(q[i, f])
            c = np.int64(cur[i, f])
            r = x - c
            if p:
                r = r - c + np.int64(before[i, f])
            if ent_abs[i, e]:
                wd, r = np.int64(width[f]), x
            else:
                wd = np.int64(0) if is_qidx[f] else np.int64(w[i, e])
            wd = wd if present[i, e] else np.int64(0)
            v = np.uint64(r & ((np.int64(1) << wd) - 1))
            end = off + wd
            if end < 64:
                acc |= v << np.uint64((64 - end) & 63)  # (wd 0: v is 0 whatever the shift)
                off = end
            else:  # the word is full: the bits past it begin the next
                spill = end - 64
                words[at] |= acc | (v >> np.uint64(spill))
                at += 1
                acc = (v << np.uint64(63 - spill)) << np.uint64(1)  # (a shift by 64 is undefined)
                off = spill
    words[at] |= acc


def jack_codes(
    joints: np.ndarray,
    figures: np.ndarray,
    translational: np.ndarray,
    lo: np.ndarray,
    inv_step: np.ndarray,
    top: np.ndarray,
    dof_fields: np.ndarray,
    pos_fields: np.ndarray,
    qidx_fields: np.ndarray,
    comp_fields: np.ndarray,
    out: np.ndarray,
) -> int:
    """A shard's poses straight to their codes, a row at a time: ``joints`` (n, D) and ``figures``
    (n, G, 7) float32 in Jack's units (radians, cm; x, y, z, w, x, y, z) into ``out`` (n, F) int32, as
    ``WireConverter.convert`` then :func:`protocol.updates.quantise` compute them, value for value: a DOF
    widened (a translational one / 100; a rotation outside [-pi, pi] wrapped), the axis change (x, -z, y)
    / 100 and (w, x, -z, y), each quaternion normalised (its squares summed in order), its first largest
    ``|component|``'s index and the other three signed so that the largest is positive, then
    ``clip(rint((v - lo) * inv_step), 0, top)``. Those passes read and write ten (n, F) float64 arrays;
    this reads the float32 rows once. Returns -1, or the first row with a non-finite value or a zero
    quaternion (``out`` then undefined: the caller takes the numpy path, which says why)."""
    n, nd = joints.shape
    g = figures.shape[1]
    pi = np.pi
    two_pi = 2 * np.pi
    comps = np.empty(4, np.float64)
    for i in range(n):
        acc = 0.0  # a row's values summed: finite unless one of them is not (or the sum overflows)
        for c in range(nd):
            v = np.float64(joints[i, c])
            if translational[c]:
                v = v / 100.0
            elif v > pi or v < -pi:
                v = v - two_pi * np.floor((v + pi) / two_pi)
            acc += v
            f = dof_fields[c]
            out[i, f] = np.int32(min(max(np.rint((v - lo[f]) * inv_step[f]), 0.0), top[f]))
        for k in range(g):
            for c in range(3):
                x = figures[i, k, 0] if c == 0 else (-figures[i, k, 2] if c == 1 else figures[i, k, 1])
                v = np.float64(x) / 100.0
                acc += v
                f = pos_fields[k, c]
                out[i, f] = np.int32(min(max(np.rint((v - lo[f]) * inv_step[f]), 0.0), top[f]))
            comps[0] = np.float64(figures[i, k, 3])
            comps[1] = np.float64(figures[i, k, 4])
            comps[2] = np.float64(-figures[i, k, 6])
            comps[3] = np.float64(figures[i, k, 5])
            norm = comps[0] * comps[0]
            for c in range(1, 4):
                norm += comps[c] * comps[c]
            norm = np.sqrt(norm)
            if not (norm >= 1e-9 and norm - norm == 0.0):
                return i
            best = 0
            for c in range(4):
                comps[c] = comps[c] / norm
                if abs(comps[c]) > abs(comps[best]):
                    best = c
            flip = comps[best] < 0
            f = qidx_fields[k]
            out[i, f] = np.int32(min(max(np.rint((best - lo[f]) * inv_step[f]), 0.0), top[f]))
            for j in range(3):
                v = comps[j + 1] if best <= j else comps[j]
                if flip:
                    v = -v
                f = comp_fields[k, j]
                out[i, f] = np.int32(min(max(np.rint((v - lo[f]) * inv_step[f]), 0.0), top[f]))
        if acc - acc != 0.0:  # (an inf or a NaN: NaN)
            return i
    return -1


def store_rows(codes: np.ndarray, rows: np.ndarray, q: np.ndarray, changed: np.ndarray) -> None:
    """``changed[i] = (codes[rows[i]] != q[i]).any()``, then ``codes[rows[i]] = q[i]``: a board's store of
    scattered rows (a shard's every N-th soldier) as one pass, not a gather, a compare and a scatter."""
    n, nf = q.shape
    for i in range(n):
        r = rows[i]
        d = False
        for f in range(nf):
            v = q[i, f]
            d |= codes[r, f] != v
            codes[r, f] = v
        changed[i] = d
