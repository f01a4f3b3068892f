"""The version-2 row encoder as it was before its cheaper rewrite (issue 18, main at ded06c4): soldier-major
passes, a column gather per field position for the entry widths, :func:`protocol.bitpack.merge_groups`.
Kept as the reference that :func:`protocol.predicted.encode_rows` must match byte for byte."""

from __future__ import annotations

import numpy as np
from encode_reference import ReferenceEncoder as FrozenEncoder

from protocol import predicted
from protocol.bitpack import merge_groups
from protocol.update_table import TableLayout


def entry_max(lay: TableLayout, values: np.ndarray) -> np.ndarray:
    """(n, E): each entry's largest field value of ``values`` (n, F), one column pass per field position."""
    out = values[:, lay.entry_start]
    for j in range(1, int(lay.entry_nfields.max(initial=1))):
        es = np.flatnonzero(lay.entry_nfields > j)
        out[:, es] = np.maximum(out[:, es], values[:, lay.entry_start[es] + j])
    return out


def encode_rows(
    lay: TableLayout, ncols: int, g: int, q: np.ndarray, cur: np.ndarray, state: np.ndarray,
    known: np.ndarray, present: np.ndarray, tick: int,
) -> predicted.Rows:  # fmt: skip
    resid = predicted.residuals(q, cur, state, tick)
    mag = np.maximum(resid, ~resid)
    mag[:, lay.qidx_fields] = 0
    ke = np.frexp(entry_max(lay, mag).astype(np.float32))[1].astype(np.int32) + 1
    qflip = np.zeros(present.shape, bool)
    qflip[:, lay.entry_of[lay.qidx_fields]] = q[:, lay.qidx_fields] != cur[:, lay.qidx_fields]
    absbits = lay.entry_absbits.astype(np.int32)
    delta_bits = ke * lay.entry_ndelta.astype(np.int32)
    ent_abs = qflip | (ke > predicted.MAX_WIDTH) | (delta_bits >= absbits)
    cost = np.where(ent_abs, absbits, delta_bits) + predicted.WIDTH_BITS
    cost *= present
    cost_delta = cost.sum(axis=1)
    cost_abs = (present * absbits).sum(axis=1)
    row_abs = ~known | (cost_abs <= cost_delta)
    ent_abs |= row_abs[:, None]
    w = np.where(ent_abs, 0, ke)
    nibble_count = np.where(row_abs, 0, present.sum(axis=1))
    header = np.empty((len(q), predicted.MODE_BITS + present.shape[1]), np.uint8)
    header[:, 0] = ~row_abs
    header[:, predicted.MODE_BITS :] = present
    sent_abs = ent_abs & present
    values, restart = resid, q[:0]
    rows = np.flatnonzero(sent_abs.any(axis=1))
    if len(rows):
        absf = np.take(sent_abs[rows], lay.entry_of, axis=1)
        values[rows] = np.where(absf, q[rows], resid[rows])
        restart = np.where(absf, q[rows], cur[rows])
    padded = np.zeros((len(q), ncols), np.int32)
    padded[:, : lay.nfields] = values
    groups, gwidth = merge_groups(padded, predicted.field_widths(lay, ncols, present, ent_abs, w), g)
    return predicted.Rows(
        header=header,
        nibbles=w[present & ~row_abs[:, None]].astype(np.uint8),
        nibble_count=nibble_count,
        row_bits=np.where(row_abs, cost_abs, cost_delta - predicted.WIDTH_BITS * nibble_count),
        groups=groups.copy(),
        gwidth=gwidth.copy(),
        restart_rows=rows,
        restart=restart,
    )


class ReferenceEncoder(FrozenEncoder):
    """The frozen encoder of :mod:`encode_reference` with its version-2 rows from the older reference above
    (before, its ``_rows_v2`` override was no longer called: the test compared the encoder with itself)."""

    rows_v2 = staticmethod(encode_rows)
