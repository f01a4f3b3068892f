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

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from protocol import fused
from protocol.bitpack import merge_columns, scratch
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
    groups: np.ndarray  # (n, C/g) the rows' fields merged into top-aligned groups (``protocol.bitpack``)
    gwidth: np.ndarray  # (n, C/g) int64 their bit widths
    restart_rows: np.ndarray  # rows with an entry sent absolute: their prediction restarts
    restart: np.ndarray  # (len(restart_rows), F) their ``before`` codes (every other row's: its old ``cur``)
    # the fused path's (``groups`` empty): the rows' fields ORed into zeroed words from each row's start bit
    pack: Callable[[np.ndarray, np.ndarray], None] | None = None


class Columns:
    """Per-table constants of the version-2 encoder (built once per table, see ``updates._Plan``).

    ``perm`` lists the delta fields (qidx left out) position-major: the first field of every entry, then the
    second field of the entries that have one, and so on, the entries ordered by delta-field count (most
    first). Gathered once into that order, the per-entry maxima are a few passes over a shrinking prefix
    (``spans``) instead of a column gather per field position."""

    def __init__(self, lay: TableLayout, ncols: int, g: int) -> None:
        nd = lay.entry_ndelta.astype(np.int64)
        self.nent, self.nfields, self.ncols, self.g = len(nd), lay.nfields, ncols, g
        order = np.argsort(-nd, kind="stable")
        self.inverse = None if (order == np.arange(self.nent)).all() else np.argsort(order)
        delta = [
            [f for f in range(s, s + c) if not lay.is_qidx[f]]
            for s, c in zip(lay.entry_start.tolist(), lay.entry_nfields.tolist(), strict=True)
        ]
        perm: list[int] = []
        spans: list[tuple[int, int]] = []
        for j in range(int(nd.max(initial=1))):
            es = [e for e in order.tolist() if nd[e] > j]
            if j:
                spans.append((len(perm), len(es)))
            perm += [delta[e][j] for e in es]
        self.perm = np.asarray(perm, np.int64)
        self.spans = tuple(spans)
        self.absbits = lay.entry_absbits.astype(np.int32)
        self.ndelta = nd.astype(np.int32)
        self.absbits_f = lay.entry_absbits.astype(np.float32)
        self.ones_f = np.ones(self.nent, np.float32)
        self.entry_of = lay.entry_of
        self.qidx_fields = lay.qidx_fields
        self.qidx_entry = lay.entry_of[lay.qidx_fields]
        self.width = lay.width.astype(np.uint8)
        # the fused loops' (protocol.fused): every entry has a delta field (entry_widths assumes it too)
        self.fused = fused.AVAILABLE and bool((nd >= 1).all())
        self.field_entry = lay.entry_of.astype(np.int64)
        self.is_qidx = lay.is_qidx.astype(bool)
        self.width64 = lay.width.astype(np.int64)
        self.ndelta64, self.absbits64 = nd, lay.entry_absbits.astype(np.int64)


def _entry_bits(mag: np.ndarray) -> np.ndarray:
    """int32 bit lengths plus one of magnitudes >= 0 (float32: exact below 2^24, where widths stop at 15).

    Read from the float32's biased exponent field (``frexp``'s exponent is that field less 126, and 0 for
    0.0): three integer passes instead of frexp's two outputs and their conversion."""
    bits = mag.astype(np.float32).view(np.int32)
    np.right_shift(bits, 23, out=bits)
    bits -= 125
    return np.maximum(bits, 1, out=bits)


def entry_widths(cols: Columns, resid: np.ndarray) -> np.ndarray:
    """(E, n) int32: per entry the smallest two's-complement width holding its delta fields' residuals,
    from field-major residuals ``resid`` (F', n)."""
    sc = scratch()
    shape = (len(cols.perm), resid.shape[1])
    m = np.take(resid, cols.perm, axis=0, out=sc.get("v2.mag", shape, np.int32), mode="clip")
    np.maximum(m, np.invert(m, out=sc.get("v2.inv", shape, np.int32)), out=m)  # bit length of max(r, -r-1)
    for at, k in cols.spans:  # plus a sign bit holds r
        np.maximum(m[:k], m[at : at + k], out=m[:k])
    return _entry_bits(m[: cols.nent] if cols.inverse is None else m[cols.inverse])


def transpose(a: np.ndarray, out: np.ndarray) -> None:
    """``out[:] = a.T`` for a C-contiguous (n, F) int32 ``a``. numpy's element-wise transposed copy reads
    4-byte elements at a stride of a row; for F a multiple of 4 the rows' 16-byte runs (four fields) are
    transposed as single elements first, then split into their fields by four strided copies: about a
    third cheaper (a (5,500, 64) batch)."""
    n, f = a.shape
    if f % 4 or not a.flags.c_contiguous or n < 64:
        np.copyto(out, a.T)
        return
    quads = scratch().get("v2.quads", (f // 4, n, 4), np.int32)
    rec = np.dtype((np.void, 16))
    np.copyto(quads.view(rec).reshape(f // 4, n), a.view(rec).T)
    for j in range(4):
        np.copyto(out[j::4], quads[:, :, j])


def state_columns(nfields: int) -> int:
    """Columns of the prediction state: ``before``'s codes, then the tick of the last update (as uint32)."""
    return nfields + 1


def state_ticks(state: np.ndarray) -> np.ndarray:
    """(n,) int32 view of a prediction state's tick column: the (n, F + 1) int32 layout's last column, or
    the (n, F + 2) uint16 layout's last two (an encoder keeps codes of at most 16 bits as uint16)."""
    return state[:, state.shape[1] - (4 // state.itemsize) :].view(np.int32)[:, 0]


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


def residuals(
    q: np.ndarray, cur: np.ndarray, state: np.ndarray, tick: int, out: np.ndarray | None = None
) -> np.ndarray:
    """(n, F) int32: ``q`` minus the prediction, ``2 · cur − before`` for soldiers whose last update was at
    ``tick − 1`` (mod 2³²), else ``cur``. ``q``, ``cur`` and ``state`` may be uint16 (:func:`state_ticks`):
    the sums run in int32."""
    nf = q.shape[1]
    resid = np.subtract(q, cur, out=out, dtype=np.int32)
    predicts = state_ticks(state) == tick_code(tick - 1)
    rows = np.flatnonzero(predicts)
    if 2 * len(rows) >= len(q):
        # most rows predict (every mover of a tick): dense passes, then the few that do not put back to
        # ``q − cur`` (a fancy gather of nearly every row costs several dense passes)
        resid -= cur
        resid += state[:, :nf]
        if len(rows) < len(q):
            rest = np.flatnonzero(~predicts)
            resid[rest] = np.subtract(q[rest], cur[rest], dtype=np.int32)
    elif len(rows):
        resid[rows] -= np.subtract(cur[rows], state[rows, :nf], dtype=np.int32)
    return resid


@dataclass(frozen=True)
class _Choice:
    """Per entry and row (field-major, (E, n)): which go absolute, the widths sent, the rows' bit costs."""

    ent_abs: np.ndarray  # (E, n) bool: entries sent absolute (every entry of an absolute row)
    row_abs: np.ndarray  # (n,) bool: mode 0
    w: np.ndarray  # (E, n) uint8: each present delta entry's width, else 0
    cost_abs: np.ndarray  # (n,) float32: the row's field bits in mode 0
    cost_delta: np.ndarray  # (n,) float32: its field and width bits in mode 1
    npresent: np.ndarray  # (n,) float32: its present entries


def _choose(
    cols: Columns, ke: np.ndarray, q: np.ndarray, cur: np.ndarray, known: np.ndarray, present: np.ndarray
) -> _Choice:
    """An entry whose residuals need more than 15 bits, whose qidx changed, or whose residuals cost at least
    its absolute bits goes absolute (width 0); a row whose entries cost no less in delta mode, or that the
    receiver does not know, goes absolute whole. ``ke``, ``present``: (E, n); row sums are float32 matrix
    products (small integers: exact)."""
    cost = ke * cols.ndelta[:, None]
    ent_abs = (ke > MAX_WIDTH) | (cost >= cols.absbits[:, None])
    ent_abs[cols.qidx_entry] |= (q[:, cols.qidx_fields] != cur[:, cols.qidx_fields]).T
    some = bool(ent_abs.any())
    if some:
        np.copyto(cost, cols.absbits[:, None], where=ent_abs)
    pres = present.astype(np.float32)
    costf = cost.astype(np.float32)
    costf += WIDTH_BITS
    costf *= pres
    cost_delta = cols.ones_f @ costf
    cost_abs = cols.absbits_f @ pres
    row_abs = cost_abs <= cost_delta
    row_abs |= ~known
    if row_abs.any():
        ent_abs |= row_abs
        some = True
    w = np.multiply(ke, present, dtype=np.uint8, casting="unsafe")
    if some:
        np.copyto(w, 0, where=ent_abs)
    return _Choice(ent_abs, row_abs, w, cost_abs, cost_delta, cols.ones_f @ pres)


def encode_rows(
    cols: Columns,
    q: np.ndarray,
    cur: np.ndarray,
    state: np.ndarray,
    known: np.ndarray,
    present: np.ndarray,
    tick: int,
) -> Rows:
    """Version-2 rows of soldiers with at least one present entry (``present`` (n, E): changed entries).

    Per entry the smallest width holding every residual, or absolute (:func:`_choose`). The work is
    field-major (one transposed copy of the residuals): every pass runs along the soldiers. The dense passes
    treat every entry as a delta entry; the few rows with an absolute entry (new soldiers, qidx flips,
    jumps) are fixed up on their own. With ``cols.fused``, :func:`fused_rows` does it all in two loops.
    """
    if cols.fused:
        return fused_rows(cols, (q, cur, state), known, present, tick)
    n, nf = q.shape
    sc = scratch()  # big work arrays reused from tick to tick: no page faults for fresh megabytes
    values = sc.get("v2.values", (cols.ncols, n), np.int32)  # field-major; padding fields have width 0
    values[nf:] = 0
    transpose(residuals(q, cur, state, tick, sc.get("v2.resid", (n, nf), np.int32)), values[:nf])
    pres = np.ascontiguousarray(present.T)
    c = _choose(cols, entry_widths(cols, values), q, cur, known, pres)
    widths = sc.get("v2.widths", (cols.ncols, n), np.uint8)
    widths[nf:] = 0
    np.take(c.w, cols.entry_of, axis=0, out=widths[:nf], mode="clip")
    widths[cols.qidx_fields] = 0
    header = np.empty((n, MODE_BITS + cols.nent), np.uint8)
    header[:, 0] = ~c.row_abs
    header[:, MODE_BITS:] = present
    sent = present & ~c.row_abs[:, None] if c.row_abs.any() else present
    nibble_count = np.where(c.row_abs, 0, c.npresent).astype(np.int64)
    rows = np.flatnonzero((c.ent_abs & pres).any(axis=0))  # few: absolute entries send codes
    restart = q[:0]
    if len(rows):
        absf = c.ent_abs[:, rows][cols.entry_of] & pres[:, rows][cols.entry_of]  # (F, m)
        values[:nf, rows] = np.where(absf, q[rows].T, values[:nf, rows])
        widths[:nf, rows] = np.where(absf, cols.width[:, None], widths[:nf, rows])
        restart = np.where(absf.T, q[rows], cur[rows])
    groups, gwidth = merge_columns(values, widths, cols.g)
    return Rows(
        header=header,
        # np.compress, not a boolean index: about 2.4 times cheaper for 65,000 bytes of which 78 % are taken
        nibbles=np.compress(np.ascontiguousarray(sent).reshape(-1), np.ascontiguousarray(c.w.T).reshape(-1)),
        nibble_count=nibble_count,
        row_bits=np.where(c.row_abs, c.cost_abs, c.cost_delta - WIDTH_BITS * nibble_count).astype(np.int64),
        groups=groups,
        gwidth=gwidth,
        restart_rows=rows,
        restart=restart,
    )


def fused_rows(
    cols: Columns,
    rows: tuple[np.ndarray, np.ndarray, np.ndarray],
    known: np.ndarray,
    present: np.ndarray,
    tick: int,
) -> Rows:
    """:func:`encode_rows` through the compiled loops of :mod:`protocol.fused` (``cols.fused``), ``rows``
    its ``(q, cur, state)``: the same rows, whose fields ``Rows.pack`` writes once the frames are cut
    (``groups`` and ``gwidth`` empty)."""
    q, cur, state = rows
    n, ne = len(q), cols.nent
    sc = scratch()
    w = sc.get("fused.w", (n, ne), np.uint8)
    ent_abs = sc.get("fused.abs", (n, ne), np.bool_)
    nibbles = sc.get("fused.nibbles", (n * ne,), np.uint8)
    restarts = sc.get("fused.restarts", (n,), np.bool_)
    header = np.empty((n, MODE_BITS + ne), np.uint8)
    row_bits, nibble_count = np.empty(n, np.int64), np.empty(n, np.int64)
    predicts = state_ticks(state) == tick_code(tick - 1)
    args = (cols.field_entry, cols.is_qidx)
    count = fused.kernel("rows_meta")(
        q, cur, state, predicts, known, present, *args, cols.ndelta64, cols.absbits64, MAX_WIDTH,
        w, ent_abs, header, nibbles, nibble_count, row_bits, restarts,
    )  # fmt: skip
    again = np.flatnonzero(restarts)  # few: absolute entries send codes
    restart = q[:0]
    if len(again):
        absf = np.take(ent_abs[again] & present[again], cols.field_entry, axis=1)  # (m, F)
        restart = np.where(absf, q[again], cur[again])

    def pack(starts: np.ndarray, words: np.ndarray) -> None:
        fused.kernel("pack_fields")(
            q, cur, state, predicts, present, ent_abs, w, *args, cols.width64, starts, words
        )

    return Rows(
        header=header,
        nibbles=nibbles[:count],
        nibble_count=nibble_count,
        row_bits=row_bits,
        groups=np.zeros((n, 0), np.uint64),
        gwidth=np.zeros((n, 0), np.int64),
        restart_rows=again,
        restart=restart,
        pack=pack,
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
