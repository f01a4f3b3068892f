"""The vectorised joint-update codec produces exactly the bytes and values of a plain reference.

The reference below follows docs/PROTOCOL.md §7-8 literally: Python loops over soldiers and fields, a bit
string per frame, and the straightforward quantisation (concatenate, gather, scale). The optimised
:mod:`protocol.updates` (grouped 64-bit packing, reused buffers) must agree with it byte for byte, frame for
frame, and its decoder must reproduce the reference's codes and poses.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol.bitpack import merge_groups, place_groups, read_groups, split_groups
from protocol.errors import WireError
from protocol.events import JointUpdates
from protocol.update_table import DofRange, FigureEntry, JointEntry, UpdateTable, example_di_table
from protocol.updates import UpdateDecoder, UpdateEncoder, dequantise, quantise

_OTHERS = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])


# -- the reference ------------------------------------------------------------------------------------------


def ref_quantise(table: UpdateTable, dofs: np.ndarray, pos: np.ndarray, quat: np.ndarray) -> np.ndarray:
    lay = table.layout
    n, g = dofs.shape[0], len(lay.qidx_fields)
    parts = [dofs]
    if g:
        quat = quat / np.linalg.norm(quat, axis=-1, keepdims=True)
        qidx = np.argmax(np.abs(quat), axis=-1)
        lead = np.take_along_axis(quat, qidx[..., None], -1)
        quat = np.where(lead < 0, -quat, quat)
        comps = np.take_along_axis(quat, _OTHERS[qidx], -1)
        parts += [pos.reshape(n, 3 * g), qidx.astype(np.float64), comps.reshape(n, 3 * g)]
    raw = np.concatenate(parts, axis=1)
    if lay.gather is not None:
        raw = raw[:, lay.gather]
    code = np.rint((raw - lay.lo) * (1.0 / lay.step))
    return np.clip(code, 0.0, ((1 << lay.width) - 1).astype(np.float64)).astype(np.int64)


class RefEncoder:
    """What a client last received, and frames built as bit strings (docs/PROTOCOL.md §8.4)."""

    def __init__(self, table: UpdateTable, nmax: int) -> None:
        self.table = table
        self.last = np.zeros((nmax, table.layout.nfields), np.int64)
        self.known = [False] * nmax

    def encode(self, idx: list[int], codes: np.ndarray, tick: int, max_payload: int) -> list[bytes]:
        lay = self.table.layout
        nent = len(lay.entry_start)
        rows = []  # (index, mode, mask, field bit string)
        for i, s in sorted(enumerate(idx), key=lambda p: p[1]):
            new, old = [int(v) for v in codes[i]], [int(v) for v in self.last[s]]
            mask = [
                not self.known[s] or any(new[f] != old[f] for f in range(len(new)) if lay.entry_of[f] == e)
                for e in range(nent)
            ]
            if not any(mask):
                continue
            present = [f for f in range(len(new)) if mask[lay.entry_of[f]]]
            deltas = [new[f] - old[f] for f in present if not lay.is_qidx[f]]
            k = 1
            while any(not -(1 << (k - 1)) <= d < 1 << (k - 1) for d in deltas):
                k += 1
            qidx_moved = any(new[f] != old[f] for f in lay.qidx_fields)
            abs_bits = sum(int(lay.width[f]) for f in present)
            absolute = not self.known[s] or qidx_moved or k > 15 or k * len(deltas) >= abs_bits
            if absolute:
                bits = "".join(format(new[f], f"0{lay.width[f]}b") for f in present)
            else:
                bits = "".join(format(d & ((1 << k) - 1), f"0{k}b") for d in deltas)
            rows.append((s, 0 if absolute else k, mask, bits))
            self.last[s] = new
            self.known[s] = True
        capacity = (max_payload - 10) * 8
        frames: list[list[tuple[int, int, list[bool], str]]] = []
        used = capacity + 1
        for row in rows:
            cost = 16 + 4 + nent + len(row[3])
            if used + cost > capacity or len(frames[-1]) == 0xFFFF:
                frames.append([])
                used = 0
            frames[-1].append(row)
            used += cost
        out = []
        for fr in frames:
            head = "".join(format(m, "04b") + "".join("01"[b] for b in mask) for _, m, mask, _ in fr)
            body = "".join(bits for *_, bits in fr)
            out.append(
                self.table.table_id.to_bytes(2, "big")
                + (tick & 0xFFFFFFFF).to_bytes(4, "big")
                + len(fr).to_bytes(2, "big")
                + b"".join(s.to_bytes(2, "big") for s, *_ in fr)
                + bitstring_bytes(head)
                + bitstring_bytes(body)
            )
        return out


def bitstring_bytes(bits: str) -> bytes:
    bits += "0" * (-len(bits) % 8)
    return int(bits, 2).to_bytes(len(bits) // 8, "big") if bits else b""


def ref_decode(table: UpdateTable, state: np.ndarray, payload: bytes) -> list[int]:
    """Apply a (valid) frame to ``state`` (nmax, F) in place; the soldiers it carried."""
    lay = table.layout
    nent = len(lay.entry_start)
    count = int.from_bytes(payload[6:8], "big")
    idx = [int.from_bytes(payload[8 + 2 * j : 10 + 2 * j], "big") for j in range(count)]
    rest = payload[8 + 2 * count :]
    bits = "".join(format(b, "08b") for b in rest)
    hbits = count * (4 + nent)
    pos = ((hbits + 7) // 8) * 8
    for j, s in enumerate(idx):
        h = bits[j * (4 + nent) : (j + 1) * (4 + nent)]
        mode, mask = int(h[:4], 2), [c == "1" for c in h[4:]]
        for f in range(lay.nfields):
            if not mask[lay.entry_of[f]] or (mode and lay.is_qidx[f]):
                continue
            w = int(lay.width[f]) if mode == 0 else mode
            v = int(bits[pos : pos + w], 2)
            pos += w
            if mode == 0:
                state[s, f] = v
            else:
                state[s, f] += v - (1 << mode) if v >= 1 << (mode - 1) else v
    return idx


# -- strategies ---------------------------------------------------------------------------------------------


@st.composite
def tables(draw: st.DrawFn) -> UpdateTable:
    entries: list[JointEntry | FigureEntry] = []
    for i in range(draw(st.integers(1, 6))):
        if draw(st.booleans()):
            nd = draw(st.integers(1, 5))
            dofs = tuple(DofRange("R", -1.0, 1.0, draw(st.integers(1, 16))) for _ in range(nd))
            entries.append(JointEntry(f"j{i}", dofs))
        else:
            pos_bits, quat_bits = draw(st.integers(1, 24)), draw(st.integers(2, 16))
            entries.append(FigureEntry(f"f{i}", -2.0, 2.0, pos_bits, quat_bits))
    return UpdateTable(draw(st.integers(0, 0xFFFF)), "x.fig", "", tuple(entries))


def random_codes(table: UpdateTable, base: np.ndarray, rng: np.random.Generator, spread: int) -> np.ndarray:
    """Codes near ``base``: some soldiers idle, some entries still, deltas of assorted sizes, qidx flips."""
    lay = table.layout
    n = base.shape[0]
    maxc = (1 << lay.width) - 1
    step = rng.integers(-spread, spread + 1, base.shape) * (rng.random(base.shape) < 0.6)
    step[rng.random(n) < 0.3] = 0
    step[:, lay.is_qidx] = rng.integers(-1, 2, (n, int(lay.is_qidx.sum()))) * (
        rng.random((n, int(lay.is_qidx.sum()))) < 0.1
    )
    return np.clip(base + step, 0, maxc)


# -- tests --------------------------------------------------------------------------------------------------


@settings(max_examples=120)
@given(tables(), st.integers(1, 40), st.integers(0, 2**32), st.sampled_from([1 << 20, 120, 400]))
def test_encoder_and_decoder_match_the_reference(
    table: UpdateTable, n: int, seed: int, max_payload: int
) -> None:
    lay = table.layout
    rng = np.random.default_rng(seed)
    nmax = 64
    per_soldier = 2 + (4 + len(lay.entry_start) + int(lay.width.sum()) + 7) // 8 + 11
    max_payload = max(max_payload, per_soldier)
    enc, dec, ref = (
        UpdateEncoder(table, nmax, version=1),
        UpdateDecoder(table, nmax, version=1),
        RefEncoder(table, nmax),
    )
    ref_state = np.zeros((nmax, lay.nfields), np.int64)
    idx = rng.choice(nmax, n, replace=False)
    codes = rng.integers(0, (1 << lay.width), (n, lay.nfields))
    for tick, spread in enumerate((0, 1, 7, 300, 40000, 3)):
        if tick:
            codes = random_codes(table, codes, rng, spread)
        if tick == 4:
            enc.reset(idx[: n // 2])
            ref.known = [k and s not in set(idx[: n // 2].tolist()) for s, k in enumerate(ref.known)]
        want = ref.encode(idx.tolist(), codes, tick, max_payload)
        got = enc.encode_codes(idx, codes, tick, max_payload)
        assert got == want
        for p in got:
            assert len(p) <= max_payload
            carried = ref_decode(table, ref_state, p)
            ev = dec.decode(p)
            assert ev.indices.tolist() == carried
        assert np.array_equal(dec.codes(np.arange(nmax)), ref_state)
        assert np.array_equal(enc.codes(idx), codes)


@settings(max_examples=60)
@given(tables(), st.integers(1, 30), st.integers(0, 2**32))
def test_quantise_and_float_encode_match_the_reference(table: UpdateTable, n: int, seed: int) -> None:
    lay = table.layout
    rng = np.random.default_rng(seed)
    g = table.nfigures
    dofs = rng.uniform(-1.2, 1.2, (n, table.ndofs))
    pos = rng.uniform(-3.0, 3.0, (n, g, 3))
    quat = rng.normal(size=(n, g, 4))
    want = ref_quantise(table, dofs, pos, quat)
    assert np.array_equal(quantise(table, dofs, pos, quat), want)
    idx = rng.permutation(n)  # unsorted indices: frames list soldiers in index order
    enc, ref = UpdateEncoder(table, 32, version=1), RefEncoder(table, 32)
    got = enc.encode(JointUpdates(table.table_id, idx, dofs, pos, quat, 9), 1 << 20)
    assert got == ref.encode(idx.tolist(), want, 9, 1 << 20)
    dec = UpdateDecoder(table, 32, version=1)
    ev = dec.decode(got[0])
    order = np.argsort(idx)
    expect = dequantise(table, want[order])
    for a, b in zip((ev.dofs, ev.positions, ev.orientations), expect, strict=True):
        assert np.array_equal(a, b)
    assert lay.nfields == want.shape[1]


def test_di_crowd_batch_matches_the_reference_over_several_ticks() -> None:
    table = example_di_table()
    rng = np.random.default_rng(5)
    n, nmax = 300, 400
    idx = np.sort(rng.choice(nmax, n, replace=False))
    enc, dec, ref = (
        UpdateEncoder(table, nmax, version=1),
        UpdateDecoder(table, nmax, version=1),
        RefEncoder(table, nmax),
    )
    state = np.zeros((nmax, table.layout.nfields), np.int64)
    base = rng.normal(size=(n, table.ndofs)) * 0.5
    for tick in range(4):
        moving = np.where(np.arange(n) % 3 == 0, 0.0, tick / 30)
        dofs = base + 0.3 * np.sin(2 * math.pi * moving)[:, None]
        pos = np.tile([[0.0, 0.0, 1.0], [0.1, 0.3, 1.2]], (n, 1, 1)) + 0.02 * moving[:, None, None]
        yaw = 0.1 * np.sin(2 * math.pi * moving)
        quat = np.zeros((n, 2, 4))
        quat[..., 0], quat[..., 3] = np.cos(yaw / 2)[:, None], np.sin(yaw / 2)[:, None]
        codes = ref_quantise(table, dofs, pos, quat)
        got = enc.encode(JointUpdates(1, idx, dofs, pos, quat, tick), 1 << 20)
        assert got == ref.encode(idx.tolist(), codes, tick, 1 << 20)
        for p in got:
            ref_decode(table, state, p)
            dec.decode(p)
        assert np.array_equal(dec.codes(np.arange(nmax)), state)
    # frames split under a small max_payload: same bytes as the reference's split
    enc.reset()
    ref.known = [False] * nmax
    got = enc.encode(JointUpdates(1, idx, dofs, pos, quat, 9), 2000)
    assert len(got) > 1
    assert got == ref.encode(idx.tolist(), codes, 9, 2000)


@given(st.lists(st.integers(0, 24), min_size=1, max_size=80), st.integers(0, 2**32))
def test_grouped_packing_round_trips_and_matches_a_bit_string(widths: list[int], seed: int) -> None:
    rng = np.random.default_rng(seed)
    g = 2
    w = np.array(widths + [0] * (-len(widths) % g), np.uint8).reshape(1, -1)
    v = rng.integers(-(1 << 30), 1 << 30, w.shape)  # bits above each width must be ignored
    groups, gw = merge_groups(v, w, g)
    starts = np.cumsum(gw, axis=1) - gw + 5  # a 5-bit offset
    words = place_groups(groups, starts, int(starts[0, -1] + gw[0, -1]) // 64 + 1)
    data = words.astype(">u8").tobytes()
    want = "".join(
        format(int(x) & ((1 << int(b)) - 1), f"0{int(b)}b") if b else ""
        for x, b in zip(v[0].tolist(), w[0].tolist(), strict=True)
    )
    assert "".join(format(b, "08b") for b in data)[5 : 5 + len(want)] == want
    back = split_groups(read_groups(np.frombuffer(data + bytes(16), ">u8").astype(np.uint64), starts), w, g)
    assert np.array_equal(back, v & ((1 << w.astype(np.int64)) - 1))


def test_decoder_still_rejects_a_frame_the_reference_would_overflow() -> None:
    table = UpdateTable(1, "x", "", (JointEntry("j", (DofRange("R", -1.0, 1.0, 4),)),))
    enc, dec = UpdateEncoder(table, 4, version=1), UpdateDecoder(table, 4, version=1)
    dec.decode(enc.encode_codes(np.array([0]), np.array([[15]]), 0, 1 << 10)[0])
    frame = bytes([0, 1, 0, 0, 0, 1, 0, 1, 0, 0]) + bitstring_bytes("00011") + bitstring_bytes("01")
    with pytest.raises(WireError):
        dec.decode(frame)  # 15 + 1 leaves the 4-bit range
    assert dec.codes(np.array([0])).tolist() == [[15]]
