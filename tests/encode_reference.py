"""The joint-update encode path as it was on main at 4fe50ef (before issue 21's cheaper rewrite), frozen here
as the reference the live encoder must match byte for byte: the change detection, the version-1 and version-2
rows, the field-major merge, the frame split and the word placement. Only the encoder's bookkeeping (delta
state, shared memo) is inherited from :class:`protocol.updates.UpdateEncoder`."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from protocol import predicted
from protocol.bitpack import merge_groups
from protocol.predicted import MAX_WIDTH, MODE_BITS, WIDTH_BITS, Columns, Rows, tick_code
from protocol.updates import MAX_COUNT, UPDATE_HEADER, UpdateEncoder, _Plan

_U64 = np.uint64


def changed(plan: _Plan, diff: np.ndarray) -> np.ndarray:
    n = diff.shape[0]
    packed = np.zeros((n, plan.nwords * 8), np.uint8)
    packed[:, : (diff.shape[1] + 7) >> 3] = np.packbits(diff, axis=1)
    rows = packed.view(">u8").astype(np.uint64)
    if plan.nwords == 1:
        return (rows & plan.member[:, 0]) != 0
    return ((rows[:, None, :] & plan.member) != 0).any(axis=2)


def entry_widths(cols: Columns, resid: np.ndarray) -> np.ndarray:
    m = np.take(resid, cols.perm, axis=0)
    np.maximum(m, np.invert(m), out=m)
    for at, k in cols.spans:
        np.maximum(m[:k], m[at : at + k], out=m[:k])
    mag = m[: cols.nent] if cols.inverse is None else m[cols.inverse]
    return np.frexp(mag.astype(np.float32))[1].astype(np.int32) + 1


def residuals(q: np.ndarray, cur: np.ndarray, state: np.ndarray, tick: int) -> np.ndarray:
    nf = q.shape[1]
    resid = q - cur
    rows = np.flatnonzero(state[:, nf] == tick_code(tick - 1))
    if len(rows) == len(q):
        resid -= cur
        resid += state[:, :nf]
    elif len(rows):
        resid[rows] -= cur[rows] - state[rows, :nf]
    return resid


def choose(
    cols: Columns, ke: np.ndarray, q: np.ndarray, cur: np.ndarray, known: np.ndarray, present: np.ndarray
) -> tuple[np.ndarray, ...]:
    cost = ke * cols.ndelta[:, None]
    ent_abs = (ke > MAX_WIDTH) | (cost >= cols.absbits[:, None])
    ent_abs[cols.qidx_entry] |= (q[:, cols.qidx_fields] != cur[:, cols.qidx_fields]).T
    some = bool(ent_abs.any())
    if some:
        cost = np.where(ent_abs, cols.absbits[:, None], cost)
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
        w[ent_abs] = 0
    return ent_abs, row_abs, w, cost_abs, cost_delta, cols.ones_f @ pres


def merge_columns(values: np.ndarray, widths: np.ndarray, g: int) -> tuple[np.ndarray, np.ndarray]:
    c, n = values.shape
    u = values.view(np.uint32) if values.dtype == np.int32 else values.astype(np.uint32)
    group = np.zeros((c // g, n), _U64)
    gw = np.zeros((c // g, n), np.int64)
    for j in range(g):
        wj = widths[j::g].astype(_U64)
        t = u[j::g].astype(_U64) << (_U64(64) - wj)
        group |= t >> gw.view(_U64)
        gw += wj.view(np.int64)
    return np.ascontiguousarray(group.T), np.ascontiguousarray(gw.T)


def encode_rows_v2(
    cols: Columns, q: np.ndarray, cur: np.ndarray, state: np.ndarray, known: np.ndarray, present: np.ndarray,
    tick: int,
) -> Rows:  # fmt: skip
    n, nf = q.shape
    values = np.zeros((cols.ncols, n), np.int32)
    values[:nf] = residuals(q, cur, state, tick).T
    pres = np.ascontiguousarray(present.T)
    ent_abs, row_abs, w, cost_abs, cost_delta, npresent = choose(
        cols, entry_widths(cols, values), q, cur, known, pres
    )
    widths = np.zeros((cols.ncols, n), np.uint8)
    widths[:nf] = w[cols.entry_of]
    widths[cols.qidx_fields] = 0
    header = np.empty((n, MODE_BITS + cols.nent), np.uint8)
    header[:, 0] = ~row_abs
    header[:, MODE_BITS:] = present
    sent = present & ~row_abs[:, None] if row_abs.any() else present
    nibble_count = np.where(row_abs, 0, npresent).astype(np.int64)
    rows = np.flatnonzero((ent_abs & pres).any(axis=0))
    restart = q[:0]
    if len(rows):
        absf = ent_abs[:, rows][cols.entry_of] & pres[:, rows][cols.entry_of]
        values[:nf, rows] = np.where(absf, q[rows].T, values[:nf, rows])
        widths[:nf, rows] = np.where(absf, cols.width[:, None], widths[:nf, rows])
        restart = np.where(absf.T, q[rows], cur[rows])
    groups, gwidth = merge_columns(values, widths, cols.g)
    return Rows(
        header=header,
        nibbles=np.compress(sent.reshape(-1), np.ascontiguousarray(w.T).reshape(-1)),
        nibble_count=nibble_count,
        row_bits=np.where(row_abs, cost_abs, cost_delta - WIDTH_BITS * nibble_count).astype(np.int64),
        groups=groups,
        gwidth=gwidth,
        restart_rows=rows,
        restart=restart,
    )


def place_groups(groups: np.ndarray, starts: np.ndarray, nwords: int) -> np.ndarray:
    s = starts.reshape(-1)
    gr = groups.reshape(-1)
    words = np.zeros(nwords + 2, _U64)
    if len(s) == 0:
        return words
    word = s >> 6
    off = (s & 63).astype(_U64)
    edge = np.concatenate([[True], word[1:] != word[:-1]])
    first = np.flatnonzero(edge)
    at = word[first]
    words[at] = np.bitwise_or.reduceat(gr >> off, first)
    words[at + 1] |= np.bitwise_or.reduceat(gr << (_U64(64) - off), first)
    return words


def pack_nibbles(nibbles: np.ndarray) -> bytes:
    nib = np.asarray(nibbles, np.uint8)
    if len(nib) & 1:
        nib = np.append(nib, np.uint8(0))
    return ((nib[0::2] << 4) | nib[1::2]).astype(np.uint8).tobytes()


_RowsV2 = Callable[..., Rows]


class ReferenceEncoder(UpdateEncoder):
    """An :class:`UpdateEncoder` whose diff, rows and frames are the frozen code above; ``rows_v2`` may
    stand in another frozen version-2 row encoder (``v2_reference``: the one before issue 18's rewrite)."""

    rows_v2: _RowsV2 | None = None

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._widen()  # the frozen code's int32 state (the encoder keeps 16-bit codes as uint16)

    def _encode_sorted(self, idx: np.ndarray, q: np.ndarray, tick: int, max_payload: int) -> list[bytes]:
        plan = self._plan
        self._tick = tick
        known = self._known[idx]
        last = self._last[idx]
        chg = changed(plan, q != last)
        if not known.all():
            chg[~known] = True
        send = chg.any(axis=1)
        if not send.all():
            if not send.any():
                self._sent = idx[:0]
                return []
            idx, q, last, chg, known = (a[send] for a in (idx, q, last, chg, known))
        if self.version >= 2:
            before = self._before[idx]
            if self.rows_v2 is not None:
                rows = self.rows_v2(self.table.layout, plan.cols, plan.g, q, last, before, known, chg, tick)
            else:
                rows = encode_rows_v2(plan.v2, q, last, before, known, chg, tick)
        else:
            rows = self._rows_v1(q, last, chg, known)
        payloads = self._ref_chunks(idx, rows, tick, max_payload)
        self._hlast, self._hknown = self._hlast.writable(), self._hknown.writable()
        self._last[idx] = q
        self._known[idx] = True
        if self.version >= 2:
            self._hbefore = self._hbefore.writable()
            nf = last.shape[1]
            self._before[idx, :nf] = last
            self._before[idx, nf] = tick_code(tick)
            if len(rows.restart_rows):
                self._before[idx[rows.restart_rows], :nf] = rows.restart
        self._sent = idx
        return payloads

    def _rows_v1(self, q: np.ndarray, last: np.ndarray, chg: np.ndarray, known: np.ndarray) -> Rows:
        plan, lay = self._plan, self.table.layout
        delta = q - last
        mag = np.maximum(delta.max(axis=1), ~delta.min(axis=1))
        k = np.frexp(mag.astype(np.float64))[1] + 1
        qidx_moved = (delta[:, lay.qidx_fields] != 0).any(axis=1)
        changed_i = chg.view(np.uint8)
        delta_bits = k * (changed_i @ plan.ndelta)
        abs_bits = changed_i @ plan.absbits
        absolute = ~known | qidx_moved | (k > 15) | (delta_bits >= abs_bits)
        mode = np.where(absolute, 0, k)
        header = np.empty((len(q), 4 + chg.shape[1]), np.uint8)
        np.bitwise_and(mode.astype(np.uint8)[:, None] >> plan.mode_shift, 1, out=header[:, :4])
        header[:, 4:] = changed_i
        values = np.where(absolute[:, None], q, delta)
        widths = plan.widths(absolute, k, np.take(changed_i, plan.entry_of, axis=1))
        groups, gwidth = merge_groups(plan.padded(values), widths, plan.g)
        return Rows(
            header=header,
            nibbles=np.zeros(0, np.uint8),
            nibble_count=np.zeros(len(q), np.int64),
            row_bits=np.where(absolute, abs_bits, delta_bits),
            groups=groups.copy(),
            gwidth=gwidth.copy(),
            restart_rows=np.zeros(0, np.int64),
            restart=last[:0],
        )

    def _ref_chunks(self, idx: np.ndarray, rows: Rows, tick: int, max_payload: int) -> list[bytes]:
        row_bits = rows.row_bits
        per_row = 16 + rows.header.shape[1] + predicted.WIDTH_BITS * rows.nibble_count + row_bits
        slack = 3 if self.version >= 2 else 2
        capacity = (max_payload - UPDATE_HEADER.size - slack) * 8
        if capacity < int(per_row.max()):
            raise ValueError(f"max_payload {max_payload} cannot hold one soldier update")
        cum = np.concatenate([[0], np.cumsum(per_row)])
        bounds = [0]
        while bounds[-1] < len(idx):
            a = bounds[-1]
            b = int(np.searchsorted(cum, cum[a] + capacity, side="right")) - 1
            bounds.append(min(max(b, a + 1), a + MAX_COUNT, len(idx)))
        fbits = np.concatenate([[0], np.cumsum(row_bits)])
        frame_bits = np.diff(fbits[bounds])
        frame_word = np.concatenate([[0], np.cumsum((frame_bits + 63) >> 6)])
        gwidth = rows.gwidth
        starts = np.cumsum(gwidth.reshape(-1)).reshape(gwidth.shape)
        starts -= gwidth
        for f in range(1, len(bounds) - 1):
            a, b = bounds[f], bounds[f + 1]
            starts[a:b] += frame_word[f] * 64 - fbits[a]
        body = place_groups(rows.groups, starts, int(frame_word[-1])).astype(">u8").tobytes()
        index = idx.astype(">u2").tobytes()
        nib_at = np.concatenate([[0], np.cumsum(rows.nibble_count)])
        out: list[bytes] = []
        for f in range(len(bounds) - 1):
            a, b = bounds[f], bounds[f + 1]
            at = int(frame_word[f]) * 8
            widths = b""
            if self.version >= 2:
                widths = pack_nibbles(rows.nibbles[nib_at[a] : nib_at[b]])
            out.append(
                UPDATE_HEADER.pack(self.table.table_id, tick & 0xFFFFFFFF, b - a)
                + index[2 * a : 2 * b]
                + np.packbits(rows.header[a:b].reshape(-1)).tobytes()
                + widths
                + body[at : at + ((int(frame_bits[f]) + 7) >> 3)]
            )
        return out
