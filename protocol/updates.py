"""Joint updates: quantisation, per-client delta state and the batched bit-packed frame body.

``UpdateEncoder`` (server side, one per client and update table) remembers the quantised values it last sent
for every soldier; ``UpdateDecoder`` (client side) holds the same values, so deltas reconstruct them exactly.
Everything is vectorised over the batch: no Python loop per soldier or per DOF.

JOINT_UPDATES payload (docs/PROTOCOL.md §8)::

    u16 table | u32 tick | u16 count | count × u16 index (strictly increasing)
    | header bits: count × (4-bit mode, E-bit entry mask), zero-padded to a byte
    | field bits: the changed entries' fields, soldier by soldier, zero-padded to a byte

mode 0 = absolute quantised values; mode k in 1..15 = every field is a k-bit two's-complement delta from the
receiver's current value (qidx fields are not sent and stay as they were). That is protocol version 1;
version 2 (per-entry widths, predicted deltas) is :mod:`protocol.predicted`, chosen by ``version``.
"""

from __future__ import annotations

import struct
import sys
from collections.abc import Sequence

import numpy as np

from protocol import predicted
from protocol.bitpack import (
    be_words,
    group_size,
    merge_groups,
    place_groups,
    read_groups,
    scratch,
    set_rows,
    split_groups,
)
from protocol.errors import ErrorCode, WireError
from protocol.events import DEFAULT_MAX_SOLDIERS, PROTOCOL_VERSION, SUPPORTED_VERSIONS, JointUpdates
from protocol.shared_encode import FRESH, JOIN_RETRY, Encoded, Held, SharedEncodes, digest
from protocol.update_table import TableLayout, UpdateTable

UPDATE_HEADER = struct.Struct(">HIH")  # table, tick, count
MODE_BITS = 4
MAX_DELTA_BITS = 15
MAX_COUNT = 0xFFFF
DECODE_CHUNK = 1 << 20  # field cells decoded per numpy pass
_OTHERS = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]], np.int64)  # components kept per qidx
_OTHERS.setflags(write=False)


def _cols(fields: np.ndarray) -> slice | np.ndarray:
    """``fields`` as a slice when they are a contiguous run (a cheaper column assignment)."""
    f = np.asarray(fields, np.int64).reshape(-1)
    if len(f) and (len(f) == 1 or (np.diff(f) == 1).all()):
        return slice(int(f[0]), int(f[-1]) + 1)
    return f


_Columns = tuple[slice | np.ndarray, ...]
_COLUMNS: dict[int, tuple[TableLayout, _Columns]] = {}  # id(layout) -> (layout, kept alive; its columns)


def _columns(lay: TableLayout) -> _Columns:
    """The layout's dof, position, qidx and three component columns as :func:`_cols` selectors, worked out
    once per layout (a tick quantises with the same few layouts every time)."""
    hit = _COLUMNS.get(id(lay))
    if hit is None or hit[0] is not lay:
        comps = tuple(_cols(lay.comp_fields[:, j]) for j in range(3))
        hit = _COLUMNS[id(lay)] = (
            lay,
            (_cols(lay.dof_fields), _cols(lay.pos_fields), _cols(lay.qidx_fields), *comps),
        )
    return hit[1]


def quantise(
    table: UpdateTable,
    dofs: np.ndarray,
    positions: np.ndarray,
    orientations: np.ndarray,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """Quantised field values (n, F) int32 of n poses (into ``out`` if given); ValueError on non-finite
    input or zero quaternions."""
    lay = table.layout
    dofs = np.asarray(dofs, np.float64)
    positions = np.asarray(positions, np.float64)
    orientations = np.asarray(orientations, np.float64)
    n = dofs.shape[0]
    g = len(lay.qidx_fields)
    if (
        dofs.shape != (n, len(lay.dof_fields))
        or positions.shape != (n, g, 3)
        or orientations.shape != (n, g, 4)
    ):
        raise ValueError(
            f"shapes dofs {dofs.shape}, positions {positions.shape}, orientations {orientations.shape} "
            f"do not match table {table.table_id}: (n, {len(lay.dof_fields)}), (n, {g}, 3), (n, {g}, 4)"
        )
    # written column block by column block (no concatenate + gather) into a reused buffer: a fresh one of
    # 10,000 soldiers is 5 MB that page-faults in on some ticks (the codes returned are a new array)
    raw = scratch().get("quantise.raw", (n, lay.nfields), np.float64)
    cols = _columns(lay)
    if len(lay.dof_fields):
        raw[:, cols[0]] = dofs
    if g:
        raw[:, cols[1]] = positions.reshape(n, 3 * g)
        _quaternion_fields(orientations, raw, cols)
    return _codes(lay, raw, out)


def _codes(lay: TableLayout, raw: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """The fields ``raw`` (n, F) float64, in place, as codes: ``clip(rint((raw - lo) / step), 0, max_code)``
    int32 (ValueError on a non-finite value)."""
    # one summing pass proves finiteness; only an inf/NaN sum (or a finite overflow) pays the exact check
    if not np.isfinite(np.add.reduce(raw, axis=None)) and not np.isfinite(raw).all():
        row = int(np.flatnonzero(~np.isfinite(raw).all(axis=1))[0])
        raise ValueError(f"row {row}: dofs, positions or orientations not finite")
    np.subtract(raw, lay.lo, out=raw)
    np.multiply(raw, 1.0 / lay.step, out=raw)
    np.rint(raw, out=raw)
    if _needs_clip(raw, lay.max_code):  # rare: most ticks clip nothing, and these two passes cost the most
        np.maximum(raw, 0.0, out=raw)  # the clip as maximum then minimum: np.clip's values for finite ones,
        np.minimum(raw, lay.max_code.astype(np.float64), out=raw)  # at a third of its cost on array bounds
    if out is None:
        return raw.astype(np.int32)
    np.copyto(out, raw, casting="unsafe")
    return out


def _needs_clip(raw: np.ndarray, max_code: np.ndarray) -> bool:
    """Whether finite codes ``raw`` (n, F) hold a value below 0 or above its column's ``max_code``: the
    smallest over all, then each column's largest, read through rows of 16 soldiers (numpy's maximum along
    the first axis of an (n, F) array is slow for a short F; along (n/16, 16F) it is not). The clip's
    ``maximum`` and ``minimum`` cost about 0.3 ms each per 10,000 soldiers (float64 maximum has no fast
    loop); these reductions a third of that."""
    n, f = raw.shape
    if not n or float(np.minimum.reduce(raw, axis=None)) < 0.0:
        return bool(n)
    bulk = n - n % 16
    top = raw[bulk:].max(axis=0, initial=0.0)
    if bulk:
        tops = raw[:bulk].reshape(bulk // 16, 16 * f).max(axis=0).reshape(16, f)
        top = np.maximum(top, tops.max(axis=0))
    return bool((top > max_code).any())


def _quaternion_fields(orientations: np.ndarray, raw: np.ndarray, cols: _Columns) -> None:
    """Into ``raw``: each figure's largest-component index and its other three components, the quaternion
    normalised and signed so the largest is positive (ValueError on a zero or non-finite quaternion).

    Worked on contiguous ``(n, G)`` arrays, one per component: numpy's calls on a last axis of 4 (norm,
    argmax, take_along_axis, where) cost four times as much. The values are those calls': the norm sums the
    squares in order, as ``np.linalg.norm``'s reduction over that axis does, and the index is the first
    largest ``|component|`` (tests/test_quantise_columns.py holds both to the calls)."""
    o = [np.ascontiguousarray(orientations[..., k]) for k in range(4)]
    norm = o[0] * o[0]
    for k in (1, 2, 3):
        norm += o[k] * o[k]
    np.sqrt(norm, out=norm)
    if not ((norm >= 1e-9).all() and np.isfinite(norm).all()):  # a zero, NaN or infinite norm
        zero = (norm < 1e-9).any(axis=1)
        if zero.any():
            raise ValueError(f"row {int(np.flatnonzero(zero)[0])}: zero quaternion")
        row = int(np.flatnonzero(~np.isfinite(norm).all(axis=1))[0])
        raise ValueError(f"row {row}: orientations not finite")
    q = [np.divide(c, norm, out=c) for c in o]
    lead = q[0].copy()
    best = np.abs(lead)
    qidx = np.zeros(norm.shape, np.int64)
    for k in (1, 2, 3):
        mag = np.abs(q[k])
        larger = mag > best
        qidx[larger] = k
        np.copyto(best, mag, where=larger)
        np.copyto(lead, q[k], where=larger)
    flip = lead < 0
    raw[:, cols[2]] = qidx
    for j in range(3):  # the components after the largest keep their order: (w, x, y, z) less one
        comp = np.where(qidx <= j, q[j + 1], q[j])
        np.negative(comp, out=comp, where=flip)
        raw[:, cols[3 + j]] = comp


def dequantise(table: UpdateTable, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Field values (n, F) back to ``(dofs, positions, orientations)``; quaternions are unit, (w, x, y, z)."""
    lay = table.layout
    n = q.shape[0]
    g = len(lay.qidx_fields)
    v = lay.lo + q * lay.step
    dofs = np.take(v, lay.dof_fields, axis=1)
    positions = np.take(v, lay.pos_fields.ravel(), axis=1).reshape(n, g, 3)
    comps = np.take(v, lay.comp_fields.ravel(), axis=1).reshape(n, g, 3)
    qidx = np.take(q, lay.qidx_fields, axis=1)
    lead = np.sqrt(np.clip(1.0 - (comps**2).sum(-1), 0.0, None))
    quat = np.empty((n, g, 4))
    np.put_along_axis(quat, qidx[..., None], lead[..., None], -1)
    np.put_along_axis(quat, _OTHERS[qidx], comps, -1)
    quat /= np.linalg.norm(quat, axis=-1, keepdims=True)
    return dofs, positions, quat


class _Plan:
    """Per-table constants of the packer: fields padded to whole groups (see :mod:`protocol.bitpack`)."""

    def __init__(self, table: UpdateTable) -> None:
        lay = table.layout
        nf = lay.nfields
        self.nent = len(lay.entry_start)
        self.g = group_size(max(int(lay.width.max()), MAX_DELTA_BITS))
        self.cols = -(-nf // self.g) * self.g
        pad = self.cols - nf
        self.width = np.concatenate([lay.width, np.zeros(pad, np.int64)]).astype(np.uint8)
        self.notq = np.concatenate([~lay.is_qidx, np.zeros(pad, bool)]).astype(np.uint8)
        self.entry_of = np.concatenate([lay.entry_of, np.zeros(pad, np.int64)])  # pad: width 0 anyway
        self.absbits = lay.entry_absbits
        self.ndelta = lay.entry_ndelta
        self.mode_shift = np.arange(MODE_BITS - 1, -1, -1, dtype=np.uint8)
        # field -> entry membership as bit masks over the row's packed diff bits (no per-entry loop, no BLAS)
        self.nwords = -(-nf // 64)
        member = np.zeros((self.nent, self.nwords * 64), bool)
        member[lay.entry_of, np.arange(nf)] = True
        self.member = np.packbits(member, axis=1).view(">u8").astype(np.uint64)  # (E, nwords)
        self.v2 = predicted.Columns(lay, self.cols, self.g)

    def diff_words(self, diff: np.ndarray) -> np.ndarray:
        """(n, nwords) uint64: the (n, F) bool ``diff`` packed, a row's changed fields as bits."""
        n = diff.shape[0]
        nbytes = (diff.shape[1] + 7) >> 3
        if nbytes == self.nwords * 8:
            return np.packbits(diff, axis=1).view(">u8").astype(np.uint64)
        packed = np.zeros((n, self.nwords * 8), np.uint8)
        packed[:, :nbytes] = np.packbits(diff, axis=1)
        return packed.view(">u8").astype(np.uint64)

    def changed(self, words: np.ndarray) -> np.ndarray:
        """(n, E) bool: entries with at least one changed field, from :meth:`diff_words`."""
        if self.nwords == 1:
            return (words & self.member[:, 0]) != 0
        return ((words[:, None, :] & self.member) != 0).any(axis=2)

    def widths(self, absolute: np.ndarray, k: np.ndarray, incl: np.ndarray) -> np.ndarray:
        """(n, cols) uint8 field widths: the field's width (mode 0) or k (delta, not qidx); 0 if absent."""
        w = np.where(absolute[:, None], self.width, k.astype(np.uint8)[:, None] * self.notq)
        w *= incl
        return w

    def padded(self, values: np.ndarray) -> np.ndarray:
        if values.shape[1] == self.cols:
            return values
        out = np.zeros((values.shape[0], self.cols), values.dtype)
        out[:, : values.shape[1]] = values
        return out


class UpdateEncoder:
    """Server side, one per client and update table: what this client last received, and the packer."""

    def __init__(
        self,
        table: UpdateTable,
        max_soldiers: int = DEFAULT_MAX_SOLDIERS,
        shared: SharedEncodes | None = None,
        version: int = PROTOCOL_VERSION,
    ) -> None:
        self.table = table
        self.max_soldiers = max_soldiers
        self.version = _checked(version)
        nf = table.layout.nfields
        # codes of at most 16 bits (the usual tables) are kept as uint16: the state's rows, gathered and
        # written for every soldier sent from arrays far larger than the caches, move half the bytes
        narrow = int(table.layout.width.max(initial=0)) <= 16
        dtype = np.uint16 if narrow else np.int32
        self._hlast = Held(np.zeros((max_soldiers, nf), dtype))
        self._hknown = Held(np.zeros(max_soldiers, bool))
        ncols = (nf + 2 if narrow else predicted.state_columns(nf)) if version >= 2 else 0
        self._hbefore = Held(np.zeros((max_soldiers if version >= 2 else 0, ncols), dtype))  # prediction
        self._tick = 0  # the tick of the last encode (version 2's join compares the state it predicts from)
        self._plan = _Plan(table)
        self.shared = shared  # the server's memo: encoders in one state share one encode per version
        self.state = FRESH  # this encoder's state id in ``shared`` (equal ids: equal content)
        self._join_after = 0  # encodes before trying to join a group whose content may equal this one's
        self._quick_retry = True  # version 2: may compare again at the next encode (see _try_join)
        self._sent = np.zeros(0, np.int64)  # the rows the last encode sent

    @property
    def _last(self) -> np.ndarray:
        """(max_soldiers, F) the codes this client last received (rows not ``_known``: stale, unused)."""
        return self._hlast.array

    @property
    def _known(self) -> np.ndarray:
        return self._hknown.array

    @property
    def _before(self) -> np.ndarray:
        """Version 2: the prediction state, ``before``'s F codes then the tick (``predicted.state_columns``:
        (max_soldiers, F + 1) int32, or (max_soldiers, F + 2) uint16 with the tick in the last two)."""
        return self._hbefore.array

    def _widen(self) -> None:
        """Codes past 16 bits (not a quantiser's) for a uint16 state: int32 arrays from now on (the layout
        is read off the arrays, so an encoder may adopt either)."""
        nf = self.table.layout.nfields
        ncols = predicted.state_columns(nf) if self._before.shape[1] else 0
        before = np.zeros((len(self._before), ncols), np.int32)
        if ncols:
            before[:, :nf] = self._before[:, :nf]
            before[:, nf] = predicted.state_ticks(self._before)
        for h in (self._hlast, self._hbefore):
            h.drop()
        self._hlast, self._hbefore = Held(self._last.astype(np.int32)), Held(before)

    def reset(self, indices: np.ndarray | list[int] | None = None) -> None:
        """Forget what these soldiers (all if None) last sent: their next update is full."""
        self._hknown = self._hknown.writable()
        if indices is None:
            self._known[:] = False
        else:
            self._known[np.asarray(indices, np.int64)] = False
        if self.shared is not None:
            self.state = self.shared.reset(self.state, None if indices is None else np.asarray(indices))

    def known(self, indices: np.ndarray) -> np.ndarray:
        return self._known[np.asarray(indices, np.int64)]

    def codes(self, indices: np.ndarray) -> np.ndarray:
        """The quantised field values (n, F) this client last received for these soldiers."""
        return self._last[np.asarray(indices, np.int64)].astype(np.int32)

    def encode(self, updates: JointUpdates, max_payload: int) -> list[bytes]:
        """JOINT_UPDATES payloads (each <= ``max_payload`` bytes) carrying what changed; [] if nothing did.

        Raises ValueError on bad input (shapes, non-finite values, duplicate or out-of-range indices).
        """
        idx = np.asarray(updates.indices, np.int64).reshape(-1)
        if len(idx) and (idx.min() < 0 or idx.max() >= self.max_soldiers):
            raise ValueError(f"soldier index outside 0..{self.max_soldiers - 1}")
        q_all = quantise(self.table, updates.dofs, updates.positions, updates.orientations)
        if len(idx) != q_all.shape[0]:
            raise ValueError(f"{len(idx)} indices for {q_all.shape[0]} poses")
        return self.encode_codes(idx, q_all, updates.tick, max_payload)

    def encode_codes(
        self, indices: np.ndarray, codes: np.ndarray, tick: int, max_payload: int, version: object = None
    ) -> list[bytes]:
        """Like :meth:`encode` for poses already quantised (:func:`quantise`, rows matching ``indices``).

        Lets a server quantise a tick's poses once and share the codes between every client's encoder. With
        a ``version`` (the caller's promise: equal versions and rows mean equal codes) and a ``shared`` memo,
        an encoder in the same state as one that already encoded these rows at this version takes its bytes.
        """
        lay = self.table.layout
        idx: np.ndarray = np.asarray(indices, np.int64).reshape(-1)
        q: np.ndarray = np.asarray(codes)
        if q.dtype != np.uint16 or self.version < 2:  # uint16 (a front-end's board): no int32 copy
            q = q.astype(np.int32, copy=False)
        if q.shape != (len(idx), lay.nfields):
            raise ValueError(f"codes of shape {q.shape} for {len(idx)} indices and {lay.nfields} fields")
        if len(idx) and (idx.min() < 0 or idx.max() >= self.max_soldiers):
            raise ValueError(f"soldier index outside 0..{self.max_soldiers - 1}")
        if len(idx) > 1 and (np.diff(idx) <= 0).any():
            order = np.argsort(idx, kind="stable")
            idx, q = idx[order], q[order]
            if (np.diff(idx) == 0).any():
                raise ValueError("duplicate soldier index in one JointUpdates")
        if len(idx) == 0:
            return []
        if self.shared is not None and version is not None:
            return self._shared_encode(idx, q, tick, max_payload, version)
        payloads = self._encode_sorted(idx, q, tick, max_payload)
        if self.shared is not None and len(self._sent):  # a state no other encoder is known to share
            self.state = self.shared.new_id()
        return payloads

    def _shared_encode(
        self, idx: np.ndarray, q: np.ndarray, tick: int, max_payload: int, version: object
    ) -> list[bytes]:
        """:meth:`_encode_sorted` through the shared memo (same bytes, one diff-and-pack per state)."""
        shared = self.shared
        assert shared is not None
        rows = (id(self.table), self.version, self.max_soldiers, digest(idx), tick, max_payload)
        hit = shared.lookup(self.state, rows, version)
        if hit is not None and hit.held is not None:  # same state, rows, codes: same bytes; adopt its state
            self._adopt(*hit.held)
            self._tick = tick
            self.state = hit.state
            return list(hit.payloads)
        payloads = self._encode_sorted(idx, q, tick, max_payload)
        shared.rows_encoded += len(idx)
        new = shared.new_id()
        held = (self._hlast, self._hknown, self._hbefore)
        shared.store(self.state, rows, Encoded(tuple(payloads), new, held, idx, tick))
        self.state = new
        self._try_join(rows)
        return payloads

    def catch_up(
        self,
        missed: Sequence[tuple[object, np.ndarray]],
        allowed: np.ndarray,
        indices: np.ndarray,
        codes: np.ndarray,
        tick: int,
        max_payload: int,
        version: object,
    ) -> list[bytes] | None:
        """:meth:`encode_codes` for a writer that missed publishes, through the shared memo: the frames its
        group was sent at them, then the newest publish's; None (nothing changed) when the memo cannot.

        ``missed``: per missed publish, oldest first, its ``version`` and the soldiers it owes this client
        (whose codes last changed then); ``allowed`` (max_soldiers,) bool: the soldiers this client may be
        sent now; ``indices``/``codes``: what changed at the newest publish, ``version``. From its state, at
        each missed version, it takes an encode memoised from that state whose rows are all allowed (a
        version with none is passed over: its soldiers are owed on) and moves to the state it led to. It
        takes them only if every owed soldier was in one at or after the publish that owes it, so the client
        then holds every soldier's code as of the last missed publish (what an encode of its own would
        bring), and if it can go on from there: a memo hit at the newest version, or that state's arrays
        unwritten since (:meth:`Encoded.intact`).
        """
        shared = self.shared
        taken = self._chain(missed, allowed, max_payload) if shared is not None else None
        if shared is None or taken is None:
            return None
        end = taken[-1]
        idx = np.asarray(indices, np.int64).reshape(-1)
        q = np.asarray(codes, np.int32)
        order = np.argsort(idx, kind="stable")
        idx, q = idx[order], q[order]
        rows = (id(self.table), self.version, self.max_soldiers, digest(idx), tick, max_payload)
        hit = shared.peek(end.state, rows, version) if len(idx) else None
        held = hit.held if hit is not None else end.intact()
        if held is None:
            return None
        frames = [p for e in taken for p in e.payloads]
        shared.caught_up += len(taken)
        self._adopt(*held)
        self._tick, self._sent = end.tick, end.rows
        if hit is not None:
            shared.hits += 1
            self.state, self._tick = hit.state, tick
            return frames + list(hit.payloads)
        self.state = end.state
        return frames + self.encode_codes(idx, q, tick, max_payload, version)

    def _chain(
        self, missed: Sequence[tuple[object, np.ndarray]], allowed: np.ndarray, max_payload: int
    ) -> list[Encoded] | None:
        """The memo's encodes that take this encoder's state through the missed publishes (see
        :meth:`catch_up`), or None."""
        shared = self.shared
        assert shared is not None
        stream = (id(self.table), self.version, self.max_soldiers, max_payload)
        owed = np.zeros(self.max_soldiers, bool)
        state, taken = self.state, []
        for version, due in missed:
            owed[due] = True
            fits = [e for e in shared.kept(version, state, stream) if allowed[e.rows].all()]
            if fits:
                owed[fits[0].rows] = False
                taken.append(fits[0])
                state = fits[0].state
        return taken if taken and not owed.any() else None

    def _try_join(self, rows: tuple[object, ...]) -> None:
        """Adopt the state id of the first encoder that sent these rows at this version if our content is
        equal to its (a late joiner after its first full update, a client after a resubscription)."""
        shared = self.shared
        assert shared is not None
        first_state, first = shared.group(rows, self.state, self)
        if first is self or not isinstance(first, UpdateEncoder) or first.state != first_state:
            return
        if self._join_after > 0:
            self._join_after -= 1
            return
        same = np.array_equal(self._known, first._known) and np.array_equal(
            self._last[self._known], first._last[first._known]
        )
        if same and (self.version < 2 or self._predicts_as(first)):
            self.state = first_state
            self._adopt(first._hlast, first._hknown, first._hbefore)
            self._quick_retry = True
        elif same and self._quick_retry:
            # version 2: a keyframe restarts the joiner's prediction (before = cur), so its ``before`` equals
            # the group's only after one more encode: compare again then, once
            self._quick_retry = False
        else:
            self._join_after = JOIN_RETRY

    def _predicts_as(self, first: UpdateEncoder) -> bool:
        """Version 2: both predict alike from now on. Only soldiers updated at this tick may predict from
        ``before`` at the next; every other soldier's ``before`` is never used again."""
        now = predicted.tick_code(self._tick)
        nf = self.table.layout.nfields
        mine = self._known & (predicted.state_ticks(self._before) == now)
        theirs = first._known & (predicted.state_ticks(first._before) == now)
        return np.array_equal(mine, theirs) and np.array_equal(
            self._before[mine, :nf], first._before[theirs, :nf]
        )

    def _adopt(self, last: Held, known: Held, before: Held) -> None:
        """Share another encoder's state arrays (equal content) instead of keeping our own."""
        self._hlast.drop()
        self._hknown.drop()
        self._hbefore.drop()
        self._hlast, self._hknown, self._hbefore = last.take(), known.take(), before.take()

    def _encode_sorted(self, idx: np.ndarray, q: np.ndarray, tick: int, max_payload: int) -> list[bytes]:
        """The frames for sorted, distinct, non-empty ``idx``; records what was sent in ``_sent``."""
        plan = self._plan
        self._tick = tick
        known = self._known[idx]
        sc = scratch()  # gathers into reused buffers (idx is checked: clip gathers unbuffered)
        stored = self._last.dtype  # uint16, or int32 (wide tables, or widened)
        last = np.take(self._last, idx, axis=0, out=sc.get("enc.last", q.shape, stored), mode="clip")
        words = plan.diff_words(q != last)
        send = (words[:, 0] != 0) if plan.nwords == 1 else (words != 0).any(axis=1)
        send |= ~known
        if not send.all():  # idle soldiers: gather the rest by index (cheaper than boolean masks of rows)
            sel = np.flatnonzero(send)
            if not len(sel):
                self._sent = idx[:0]
                return []
            shape = (len(sel), q.shape[1])
            q = np.take(q, sel, axis=0, out=sc.get("enc.q", shape, q.dtype), mode="clip")
            last = np.take(last, sel, axis=0, out=sc.get("enc.sent_last", shape, stored), mode="clip")
            idx, known, words = idx[sel], known[sel], words[sel]
        changed = plan.changed(words)
        if not known.all():
            changed[~known] = True
        if self.version >= 2:
            before = sc.get("enc.before", (len(idx), self._before.shape[1]), stored)
            np.take(self._before, idx, axis=0, out=before, mode="clip")
            rows = predicted.encode_rows(self._plan.v2, q, last, before, known, changed, tick)
        else:
            rows = self._rows_v1(q, last, changed, known)
        payloads = self._chunks(idx, rows, tick, max_payload)
        if stored == np.uint16 and q.dtype != np.uint16:  # as stored (one pass), or int32 past 16 bits
            if int(np.bitwise_or.reduce(q, axis=None)) >> 16:
                self._widen()
            else:
                q16 = sc.get("enc.q16", q.shape, np.uint16)
                np.copyto(q16, q, casting="unsafe")
                q = q16
        self._hlast, self._hknown = self._hlast.writable(), self._hknown.writable()
        set_rows(self._last, idx, q)
        self._known[idx] = True
        if self.version >= 2:
            self._hbefore = self._hbefore.writable()
            self._restart(idx, last, rows, tick)
        self._sent = idx
        return payloads

    def _restart(self, idx: np.ndarray, last: np.ndarray, rows: predicted.Rows, tick: int) -> None:
        """Version 2: the prediction state after sending ``rows``: ``before`` is the code each soldier held
        until now (or, for an entry sent absolute, the code sent), at ``tick``."""
        nf = last.shape[1]
        before = self._before
        set_rows(before[:, :nf], idx, last.astype(before.dtype, copy=False))
        predicted.state_ticks(before)[idx] = predicted.tick_code(tick)
        if len(rows.restart_rows):
            set_rows(before[:, :nf], idx[rows.restart_rows], rows.restart)

    def _rows_v1(
        self, q: np.ndarray, last: np.ndarray, changed: np.ndarray, known: np.ndarray
    ) -> predicted.Rows:
        """Version 1: one width ``k`` per soldier (its widest delta), or absolute."""
        plan, lay = self._plan, self.table.layout
        delta = q - last
        # smallest k holding every delta: bit length of max(d, -d - 1) plus a sign (unchanged fields are 0)
        mag = np.maximum(delta.max(axis=1), ~delta.min(axis=1))
        k = np.frexp(mag.astype(np.float64))[1] + 1
        qidx_moved = (delta[:, lay.qidx_fields] != 0).any(axis=1)
        changed_i = changed.view(np.uint8)
        delta_bits = k * (changed_i @ plan.ndelta)
        abs_bits = changed_i @ plan.absbits
        absolute = ~known | qidx_moved | (k > MAX_DELTA_BITS) | (delta_bits >= abs_bits)
        mode = np.where(absolute, 0, k)
        header = np.empty((len(q), MODE_BITS + changed.shape[1]), np.uint8)
        np.bitwise_and(mode.astype(np.uint8)[:, None] >> plan.mode_shift, 1, out=header[:, :MODE_BITS])
        header[:, MODE_BITS:] = changed_i
        values = np.where(absolute[:, None], q, delta)  # deltas keep their sign bits: the packer drops
        widths = plan.widths(absolute, k, np.take(changed_i, plan.entry_of, axis=1))
        groups, gwidth = merge_groups(plan.padded(values), widths, plan.g)
        return predicted.Rows(
            header=header,
            nibbles=np.zeros(0, np.uint8),
            nibble_count=np.zeros(len(q), np.int64),
            row_bits=np.where(absolute, abs_bits, delta_bits),
            groups=groups.copy(),
            gwidth=gwidth.copy(),
            restart_rows=np.zeros(0, np.int64),
            restart=last[:0],
        )

    def _chunks(self, idx: np.ndarray, rows: predicted.Rows, tick: int, max_payload: int) -> list[bytes]:
        """Split rows into frames; pack all frames' fields in one pass (each frame's body word-aligned)."""
        row_bits = rows.row_bits
        per_row = 16 + rows.header.shape[1] + predicted.WIDTH_BITS * rows.nibble_count + row_bits
        slack = 3 if self.version >= 2 else 2  # bytes for the paddings of the header, widths, fields
        capacity = (max_payload - UPDATE_HEADER.size - slack) * 8
        if capacity < int(per_row.max()):
            raise ValueError(f"max_payload {max_payload} cannot hold one soldier update")
        cum = np.concatenate([[0], np.cumsum(per_row)])
        bounds = [0]
        while bounds[-1] < len(idx):  # one iteration per frame, not per soldier
            a = bounds[-1]
            b = int(np.searchsorted(cum, cum[a] + capacity, side="right")) - 1
            bounds.append(min(max(b, a + 1), a + MAX_COUNT, len(idx)))
        fbits = np.concatenate([[0], np.cumsum(row_bits)])
        frame_bits = np.diff(fbits[bounds])
        frame_word = np.concatenate([[0], np.cumsum((frame_bits + 63) >> 6)])  # each body starts a word
        if rows.pack is None:
            gwidth = rows.gwidth
            starts = np.cumsum(gwidth.reshape(-1)).reshape(gwidth.shape)  # rows are consecutive in the stream
            starts -= gwidth
        else:  # the fused path: each row's start bit
            starts = fbits[:-1].copy()
        for f in range(1, len(bounds) - 1):  # each frame's body starts a word
            a, b = bounds[f], bounds[f + 1]
            starts[a:b] += frame_word[f] * 64 - fbits[a]
        if rows.pack is None:
            words = place_groups(rows.groups, starts, int(frame_word[-1]))
        else:
            words = scratch().get("place.words", (int(frame_word[-1]) + 2,), np.uint64)
            words[:] = 0
            rows.pack(starts, words)
        if sys.byteorder == "little":  # the wire's words are big-endian: swapped in place, sliced uncopied
            words.byteswap(inplace=True)
        body = words.view(np.uint8).data
        index = idx.astype(">u2").tobytes()
        nib_at = np.concatenate([[0], np.cumsum(rows.nibble_count)])
        out: list[bytes] = []
        for f in range(len(bounds) - 1):
            a, b = bounds[f], bounds[f + 1]
            at = int(frame_word[f]) * 8
            widths = b""
            if self.version >= 2:
                widths = predicted.pack_nibbles(rows.nibbles[nib_at[a] : nib_at[b]])
            out.append(
                b"".join(
                    (
                        UPDATE_HEADER.pack(self.table.table_id, tick & 0xFFFFFFFF, b - a),
                        index[2 * a : 2 * b],
                        np.packbits(rows.header[a:b].reshape(-1)).tobytes(),
                        widths,
                        body[at : at + ((int(frame_bits[f]) + 7) >> 3)],
                    )
                )
            )
        return out


def _checked(version: int) -> int:
    if version not in SUPPORTED_VERSIONS:
        raise ValueError(f"protocol version {version} not in {SUPPORTED_VERSIONS}")
    return version


class UpdateDecoder:
    """Client side, one per update table: the current quantised pose of every soldier, updated atomically."""

    def __init__(
        self, table: UpdateTable, max_soldiers: int = DEFAULT_MAX_SOLDIERS, version: int = PROTOCOL_VERSION
    ) -> None:
        self.table = table
        self.max_soldiers = max_soldiers
        self.version = _checked(version)
        nf = table.layout.nfields
        self._state = np.zeros((max_soldiers, nf), np.int32)
        ncols = predicted.state_columns(nf) if version >= 2 else 0
        self._before = np.zeros((max_soldiers if version >= 2 else 0, ncols), np.int32)
        self._known = np.zeros(max_soldiers, bool)
        self._plan = _Plan(table)

    def known(self, indices: np.ndarray) -> np.ndarray:
        return self._known[np.asarray(indices, np.int64)]

    def codes(self, indices: np.ndarray) -> np.ndarray:
        """The quantised field values (n, F) held for these soldiers (equal to the encoder's)."""
        return self._state[np.asarray(indices, np.int64)].copy()

    def current(self, indices: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Current ``(dofs, positions, orientations)`` of these soldiers (zeros-derived if never received)."""
        return dequantise(self.table, self._state[np.asarray(indices, np.int64)].astype(np.int64))

    def _apply(
        self, q: np.ndarray, words: np.ndarray, bit0: int, mode: np.ndarray, mask: np.ndarray
    ) -> int | None:
        """Read the fields of soldiers ``q`` (m, F) starting at ``bit0`` and apply them to ``q`` in place.

        Dense over (m, F): absent fields read as width 0 and leave their value alone. Returns the row of the
        first soldier whose new value leaves its field's range (``q`` is then left half-updated).
        """
        plan, lay = self._plan, self.table.layout
        nf = lay.nfields
        absolute = mode == 0
        widths = plan.widths(absolute, mode, np.take(mask.view(np.uint8), plan.entry_of, axis=1))
        vals = _read_fields(plan, words, bit0, widths)[:, :nf]
        sign = np.where(absolute, 0, np.left_shift(1, np.maximum(mode, 1) - 1)).astype(np.int32)[:, None]
        vals ^= sign  # k-bit two's complement: (v ^ 2^(k-1)) - 2^(k-1); absent fields (v = 0) stay 0
        vals -= sign
        # delta rows read sign-extended deltas (0 where absent); absolute rows replace their present fields
        if absolute.any():
            keep = ~(absolute[:, None] & (widths[:, :nf] != 0))
            new = np.where(keep, q, 0)
            new += vals
        else:
            new = vals
            new += q
        bad = (new.view(np.uint32) > lay.max_code).any(axis=1)  # negative codes wrap to huge
        q[:] = new
        return int(np.flatnonzero(bad)[0]) if bad.any() else None

    def decode(self, payload: bytes) -> JointUpdates:
        """Apply one JOINT_UPDATES payload; :class:`WireError` (state untouched) if it is bad in any way."""
        nent = len(self.table.layout.entry_start)
        if len(payload) < UPDATE_HEADER.size:
            raise WireError(
                ErrorCode.MALFORMED_FRAME, "joint updates: payload shorter than its 8-byte header"
            )
        table_id, tick, count = UPDATE_HEADER.unpack_from(payload)
        if table_id != self.table.table_id:
            raise WireError(
                ErrorCode.UNKNOWN_TABLE, f"update for table {table_id} given to table {self.table.table_id}"
            )
        hwidth = (predicted.MODE_BITS if self.version >= 2 else MODE_BITS) + nent
        hbits = count * hwidth
        hbytes = (hbits + 7) >> 3
        body_at = UPDATE_HEADER.size + 2 * count + hbytes
        if len(payload) < body_at:
            raise WireError(
                ErrorCode.MALFORMED_FRAME,
                f"joint updates: {count} soldiers need >= {body_at} bytes, got {len(payload)}",
            )
        indices = self._indices(payload, count)
        bits = np.unpackbits(np.frombuffer(payload, np.uint8, hbytes, UPDATE_HEADER.size + 2 * count))
        if bits[hbits:].any():
            raise WireError(ErrorCode.MALFORMED_FRAME, "joint updates: header padding bits not zero")
        hdr = bits[:hbits].reshape(count, hwidth)
        if self.version >= 2:
            q, mask = self._decode_v2(payload, body_at, indices, hdr, tick)
        else:
            q, mask = self._decode_v1(payload[body_at:], indices, hdr)
        self._state[indices] = q
        self._known[indices] = True
        dofs, positions, orientations = dequantise(self.table, q)
        return JointUpdates(self.table.table_id, indices, dofs, positions, orientations, tick, mask)

    def _indices(self, payload: bytes, count: int) -> np.ndarray:
        indices = np.frombuffer(payload, ">u2", count, UPDATE_HEADER.size).astype(np.int64)
        if count > 1 and (np.diff(indices) <= 0).any():
            row = int(np.flatnonzero(np.diff(indices) <= 0)[0]) + 1
            raise WireError(
                ErrorCode.BAD_VALUE, "soldier indices not strictly increasing", f"soldier row {row}"
            )
        if count and indices[-1] >= self.max_soldiers:
            row = int(np.flatnonzero(indices >= self.max_soldiers)[0])
            raise WireError(
                ErrorCode.BAD_VALUE, f"index >= max_soldiers {self.max_soldiers}", f"soldier row {row}"
            )
        return indices

    def _check_first(self, indices: np.ndarray, absolute: np.ndarray, mask: np.ndarray) -> None:
        """A soldier the receiver holds nothing for must come absolute with every entry."""
        bad = ~self._known[indices] & (~absolute | ~mask.all(axis=1))
        if bad.any():
            row = int(np.flatnonzero(bad)[0])
            raise WireError(
                ErrorCode.BAD_UPDATE,
                f"soldier {indices[row]}: first update must be absolute (mode 0) with every entry",
                f"soldier row {row}",
            )

    def _decode_v1(self, body: bytes, indices: np.ndarray, hdr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        lay = self.table.layout
        count = len(indices)
        mode = hdr[:, :MODE_BITS].astype(np.int64) @ (1 << np.arange(MODE_BITS - 1, -1, -1))
        mask = hdr[:, MODE_BITS:].astype(bool)
        self._check_first(indices, mode == 0, mask)
        mask_i = mask.astype(np.int64)
        row_bits = np.where(mode == 0, mask_i @ lay.entry_absbits, mode * (mask_i @ lay.entry_ndelta))
        words = _field_words(body, int(row_bits.sum()))
        q = self._state[indices]
        row_start = np.concatenate([[0], np.cumsum(row_bits)])
        step = max(1, DECODE_CHUNK // lay.nfields)  # soldiers per pass: bounded memory for any frame
        for a in range(0, count, step):
            b = min(count, a + step)
            over = self._apply(q[a:b], words, int(row_start[a]), mode[a:b], mask[a:b])
            if over is not None:
                _out_of_range(indices, a + over)
        return q, mask

    def _decode_v2(
        self, payload: bytes, at: int, indices: np.ndarray, bits: np.ndarray, tick: int
    ) -> tuple[np.ndarray, np.ndarray]:
        plan, lay = self._plan, self.table.layout
        mask = bits[:, predicted.MODE_BITS :].astype(bool)
        if not len(indices):
            _field_words(payload[at:], 0)  # a count-0 frame is its head alone (§8.2)
            return self._state[:0], mask
        delta = bits[:, 0].astype(bool)
        self._check_first(indices, ~delta, mask)
        nnib = int(mask[delta].sum())
        fields_at = at + ((nnib + 1) >> 1)
        if len(payload) < fields_at:
            raise WireError(
                ErrorCode.MALFORMED_FRAME,
                f"joint updates: {nnib} entry widths need >= {fields_at} bytes, got {len(payload)}",
            )
        nibbles, pad_ok = predicted.unpack_nibbles(payload[at:], nnib)
        if not pad_ok:
            raise WireError(ErrorCode.MALFORMED_FRAME, "joint updates: width padding bits not zero")
        hdr = predicted.read_header(lay, plan.cols, bits, nibbles)
        row_bits = hdr.widths.sum(axis=1, dtype=np.int64)
        words = _field_words(payload[fields_at:], int(row_bits.sum()))
        vals = _read_fields(plan, words, 0, hdr.widths)[:, : lay.nfields]
        new, state = predicted.apply_rows(lay, hdr, vals, self._state[indices], self._before[indices], tick)
        bad = ((new < 0) | (new > lay.max_code)).any(axis=1)
        if bad.any():
            _out_of_range(indices, int(np.flatnonzero(bad)[0]))
        self._before[indices] = state
        return new.astype(np.int32), mask


def _field_words(body: bytes, total: int) -> np.ndarray:
    """The field section as :func:`be_words`, after checking its length and padding."""
    if len(body) != (total + 7) >> 3:
        raise WireError(
            ErrorCode.MALFORMED_FRAME,
            f"joint updates: field bits need {(total + 7) >> 3} bytes, got {len(body)}",
        )
    if total & 7 and body[-1] & ((1 << (8 - (total & 7))) - 1):
        raise WireError(ErrorCode.MALFORMED_FRAME, "joint updates: field padding bits not zero")
    return be_words(body)


def _read_fields(plan: _Plan, words: np.ndarray, bit0: int, widths: np.ndarray) -> np.ndarray:
    """The unsigned fields (m, C) of consecutive rows of these ``widths``, the first at bit ``bit0``."""
    gwidth = widths.reshape(len(widths), -1, plan.g).sum(axis=2, dtype=np.int64)
    starts = np.cumsum(gwidth.reshape(-1)).reshape(gwidth.shape)  # rows are consecutive in the stream
    starts -= gwidth
    starts += bit0
    return split_groups(read_groups(words, starts), widths, plan.g)


def _out_of_range(indices: np.ndarray, row: int) -> None:
    raise WireError(
        ErrorCode.BAD_UPDATE, f"soldier {indices[row]}: value outside its field range", f"soldier row {row}"
    )
