"""Joint updates: quantisation, per-client delta state and the batched bit-packed frame body.

``UpdateEncoder`` (server side, one per client and update table) remembers the quantised values it last sent
for every soldier; ``UpdateDecoder`` (client side) holds the same values, so deltas reconstruct them exactly.
Everything is vectorised over the batch: no Python loop per soldier or per DOF.

JOINT_UPDATES payload (docs/PROTOCOL.md §8)::

    u16 table | u32 tick | u16 count | count × u16 index (strictly increasing)
    | header bits: count × (4-bit mode, E-bit entry mask), zero-padded to a byte
    | field bits: the changed entries' fields, soldier by soldier, zero-padded to a byte

mode 0 = absolute quantised values; mode k in 1..15 = every field is a k-bit two's-complement delta from the
receiver's current value (qidx fields are not sent and stay as they were).
"""

from __future__ import annotations

import struct

import numpy as np

from protocol.bitpack import body_words, pack_bits, read_fields
from protocol.errors import ErrorCode, WireError
from protocol.events import DEFAULT_MAX_SOLDIERS, JointUpdates
from protocol.update_table import UpdateTable

UPDATE_HEADER = struct.Struct(">HIH")  # table, tick, count
MODE_BITS = 4
MAX_DELTA_BITS = 15
MAX_COUNT = 0xFFFF
DECODE_CHUNK = 1 << 20  # field cells decoded per numpy pass
_OTHERS = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]], np.int64)  # components kept per qidx
_OTHERS.setflags(write=False)


def quantise(
    table: UpdateTable, dofs: np.ndarray, positions: np.ndarray, orientations: np.ndarray
) -> np.ndarray:
    """Quantised field values (n, F) int32 of n poses; ValueError on non-finite input or zero quaternions."""
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
    parts = [dofs]
    if g:
        norm = np.linalg.norm(orientations, axis=-1, keepdims=True)
        if (norm < 1e-9).any():  # NaN norms pass here and are caught with the other non-finite values
            bad = np.flatnonzero((norm[..., 0] < 1e-9).any(axis=1))[0]
            raise ValueError(f"row {int(bad)}: zero quaternion")
        quat = orientations / norm
        qidx = np.argmax(np.abs(quat), axis=-1)
        lead = np.take_along_axis(quat, qidx[..., None], -1)
        quat = np.where(lead < 0, -quat, quat)
        comps = np.take_along_axis(quat, _OTHERS[qidx], -1)
        parts += [positions.reshape(n, 3 * g), qidx.astype(np.float64), comps.reshape(n, 3 * g)]
    raw = np.concatenate(parts, axis=1)
    if lay.gather is not None:
        raw = np.take(raw, lay.gather, axis=1)
    if not np.isfinite(raw).all():
        row = int(np.flatnonzero(~np.isfinite(raw).all(axis=1))[0])
        raise ValueError(f"row {row}: dofs, positions or orientations not finite")
    np.subtract(raw, lay.lo, out=raw)
    np.multiply(raw, 1.0 / lay.step, out=raw)
    np.rint(raw, out=raw)
    np.clip(raw, 0.0, ((np.int64(1) << lay.width) - 1).astype(np.float64), out=raw)
    return raw.astype(np.int32)


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


class UpdateEncoder:
    """Server side, one per client and update table: what this client last received, and the packer."""

    def __init__(self, table: UpdateTable, max_soldiers: int = DEFAULT_MAX_SOLDIERS) -> None:
        self.table = table
        self.max_soldiers = max_soldiers
        self._last = np.zeros((max_soldiers, table.layout.nfields), np.int32)
        self._known = np.zeros(max_soldiers, bool)

    def reset(self, indices: np.ndarray | list[int] | None = None) -> None:
        """Forget what these soldiers (all if None) last sent: their next update is full."""
        if indices is None:
            self._known[:] = False
        else:
            self._known[np.asarray(indices, np.int64)] = False

    def known(self, indices: np.ndarray) -> np.ndarray:
        return self._known[np.asarray(indices, np.int64)]

    def codes(self, indices: np.ndarray) -> np.ndarray:
        """The quantised field values (n, F) this client last received for these soldiers."""
        return self._last[np.asarray(indices, np.int64)].copy()

    def encode(self, updates: JointUpdates, max_payload: int) -> list[bytes]:
        """JOINT_UPDATES payloads (each <= ``max_payload`` bytes) carrying what changed; [] if nothing did.

        Raises ValueError on bad input (shapes, non-finite values, duplicate or out-of-range indices).
        """
        table, lay = self.table, self.table.layout
        idx = np.asarray(updates.indices, np.int64).reshape(-1)
        if len(idx) and (idx.min() < 0 or idx.max() >= self.max_soldiers):
            raise ValueError(f"soldier index outside 0..{self.max_soldiers - 1}")
        q_all = quantise(table, updates.dofs, updates.positions, updates.orientations)
        if len(idx) != q_all.shape[0]:
            raise ValueError(f"{len(idx)} indices for {q_all.shape[0]} poses")
        order = np.argsort(idx, kind="stable")
        idx = idx[order]
        if len(idx) > 1 and (np.diff(idx) == 0).any():
            raise ValueError("duplicate soldier index in one JointUpdates")
        q_new = q_all[order]
        known = self._known[idx]
        q_old = self._last[idx]
        diff = q_new != q_old
        changed = np.logical_or.reduceat(diff, lay.entry_start, axis=1) if len(idx) else diff[:, :0]
        changed[~known] = True
        send = changed.any(axis=1)
        if not send.any():
            return []
        idx, q_new, q_old, diff, changed, known = (a[send] for a in (idx, q_new, q_old, diff, changed, known))
        incl = np.take(changed, lay.entry_of, axis=1)
        dmask = incl & ~lay.is_qidx
        delta = q_new - q_old
        mag = ((delta ^ (delta >> 31)) * dmask).max(axis=1)  # x ^ (x >> 31) is -x - 1 for negative x
        k = np.frexp(mag.astype(np.float64))[1] + 1
        qidx_moved = (diff & lay.is_qidx).any(axis=1)
        delta_bits = k * dmask.sum(axis=1)
        abs_w = incl * lay.width
        abs_bits = abs_w.sum(axis=1)
        absolute = ~known | qidx_moved | (k > MAX_DELTA_BITS) | (delta_bits >= abs_bits)
        mode = np.where(absolute, 0, k)
        widths = np.where(absolute[:, None], abs_w, dmask * mode[:, None])
        values = np.where(absolute[:, None], q_new, delta & ((1 << mode) - 1).astype(np.int32)[:, None])
        sel = widths > 0
        flat_w = widths[sel]
        flat_v = values[sel]
        row_fields = np.concatenate([[0], np.cumsum(sel.sum(axis=1))])
        row_bits = widths.sum(axis=1)
        payloads = self._chunks(
            idx, mode, changed, row_bits, row_fields, flat_v, flat_w, updates.tick, max_payload
        )
        self._last[idx] = q_new
        self._known[idx] = True
        return payloads

    def _chunks(
        self,
        idx: np.ndarray,
        mode: np.ndarray,
        changed: np.ndarray,
        row_bits: np.ndarray,
        row_fields: np.ndarray,
        flat_v: np.ndarray,
        flat_w: np.ndarray,
        tick: int,
        max_payload: int,
    ) -> list[bytes]:
        nent = changed.shape[1]
        per_row = 16 + MODE_BITS + nent + row_bits  # index + header + fields
        capacity = (max_payload - UPDATE_HEADER.size - 2) * 8  # 2 bytes slack for the two paddings
        if capacity < int(per_row.max()):
            raise ValueError(f"max_payload {max_payload} cannot hold one soldier update")
        cum = np.concatenate([[0], np.cumsum(per_row)])
        out: list[bytes] = []
        a = 0
        while a < len(idx):
            b = int(np.searchsorted(cum, cum[a] + capacity, side="right")) - 1
            b = min(max(b, a + 1), a + MAX_COUNT, len(idx))
            hdr = np.zeros((b - a, MODE_BITS + nent), np.uint8)
            hdr[:, :MODE_BITS] = (mode[a:b, None] >> np.arange(MODE_BITS - 1, -1, -1)) & 1
            hdr[:, MODE_BITS:] = changed[a:b]
            fa, fb = row_fields[a], row_fields[b]
            out.append(
                UPDATE_HEADER.pack(self.table.table_id, tick & 0xFFFFFFFF, b - a)
                + idx[a:b].astype(">u2").tobytes()
                + np.packbits(hdr.ravel()).tobytes()
                + pack_bits(flat_v[fa:fb], flat_w[fa:fb])
            )
            a = b
        return out


class UpdateDecoder:
    """Client side, one per update table: the current quantised pose of every soldier, updated atomically."""

    def __init__(self, table: UpdateTable, max_soldiers: int = DEFAULT_MAX_SOLDIERS) -> None:
        self.table = table
        self.max_soldiers = max_soldiers
        self._state = np.zeros((max_soldiers, table.layout.nfields), np.int32)
        self._known = np.zeros(max_soldiers, bool)

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
        lay = self.table.layout
        k = mode[:, None]
        sel = np.take(mask, lay.entry_of, axis=1) & ~(lay.is_qidx & (k != 0))
        width = np.where(sel, np.where(k == 0, lay.width, k), 0)
        flat_w = width.reshape(-1)
        starts = bit0 + np.cumsum(flat_w) - flat_w
        vals = read_fields(words, starts, flat_w).reshape(q.shape)
        delta = vals - ((vals >> np.maximum(k - 1, 0)) << k)  # k-bit two's complement; 0 where k == 0
        new = np.where(sel & (k == 0), vals, q + delta)
        bad = ((new < 0) | (new > lay.max_code)).any(axis=1)
        q[:] = new
        return int(np.flatnonzero(bad)[0]) if bad.any() else None

    def decode(self, payload: bytes) -> JointUpdates:
        """Apply one JOINT_UPDATES payload; :class:`WireError` (state untouched) if it is bad in any way."""
        lay = self.table.layout
        nent = len(lay.entry_start)
        if len(payload) < UPDATE_HEADER.size:
            raise WireError(
                ErrorCode.MALFORMED_FRAME, "joint updates: payload shorter than its 8-byte header"
            )
        table_id, tick, count = UPDATE_HEADER.unpack_from(payload)
        if table_id != self.table.table_id:
            raise WireError(
                ErrorCode.UNKNOWN_TABLE, f"update for table {table_id} given to table {self.table.table_id}"
            )
        hbits = count * (MODE_BITS + nent)
        hbytes = (hbits + 7) >> 3
        body_at = UPDATE_HEADER.size + 2 * count + hbytes
        if len(payload) < body_at:
            raise WireError(
                ErrorCode.MALFORMED_FRAME,
                f"joint updates: {count} soldiers need >= {body_at} bytes, got {len(payload)}",
            )
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
        bits = np.unpackbits(np.frombuffer(payload, np.uint8, hbytes, UPDATE_HEADER.size + 2 * count))
        if bits[hbits:].any():
            raise WireError(ErrorCode.MALFORMED_FRAME, "joint updates: header padding bits not zero")
        hdr = bits[:hbits].reshape(count, MODE_BITS + nent)
        mode = hdr[:, :MODE_BITS].astype(np.int64) @ (1 << np.arange(MODE_BITS - 1, -1, -1))
        mask = hdr[:, MODE_BITS:].astype(bool)
        known = self._known[indices]
        bad = ~known & ((mode != 0) | ~mask.all(axis=1))
        if bad.any():
            row = int(np.flatnonzero(bad)[0])
            raise WireError(
                ErrorCode.BAD_UPDATE,
                f"soldier {indices[row]}: first update must be absolute (mode 0) with every entry",
                f"soldier row {row}",
            )
        mask_i = mask.astype(np.int64)
        row_bits = np.where(mode == 0, mask_i @ lay.entry_absbits, mode * (mask_i @ lay.entry_ndelta))
        total = int(row_bits.sum())
        body = payload[body_at:]
        if len(body) != (total + 7) >> 3:
            raise WireError(
                ErrorCode.MALFORMED_FRAME,
                f"joint updates: field bits need {(total + 7) >> 3} bytes, got {len(body)}",
            )
        if total & 7 and body[-1] & ((1 << (8 - (total & 7))) - 1):
            raise WireError(ErrorCode.MALFORMED_FRAME, "joint updates: field padding bits not zero")
        q = self._state[indices].astype(np.int64)
        words = body_words(body)
        row_start = np.concatenate([[0], np.cumsum(row_bits)])
        step = max(1, DECODE_CHUNK // lay.nfields)  # soldiers per pass: bounded memory for any frame
        for a in range(0, count, step):
            b = min(count, a + step)
            over = self._apply(q[a:b], words, int(row_start[a]), mode[a:b], mask[a:b])
            if over is not None:
                row = a + over
                raise WireError(
                    ErrorCode.BAD_UPDATE,
                    f"soldier {indices[row]}: value outside its field range",
                    f"soldier row {row}",
                )
        self._state[indices] = q
        self._known[indices] = True
        dofs, positions, orientations = dequantise(self.table, q)
        return JointUpdates(self.table.table_id, indices, dofs, positions, orientations, tick, mask)
