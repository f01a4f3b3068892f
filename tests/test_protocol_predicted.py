"""Version 2 joint updates (docs/PROTOCOL.md §8.5, issue 18): per-entry widths and predicted deltas.

A plain sequential decoder written from §8.5 alone (``SpecDecoder``, bit by bit, no numpy tricks) must agree
with the vectorised one on every frame the encoder writes; hypothesis drives smooth, jumpy, gapped and
repeated-tick motion, resets and frame splits; mutated frames raise only WireError and change nothing.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_protocol_updates import small_tables

from protocol.errors import ErrorCode, WireError
from protocol.update_table import UpdateTable, example_di_table
from protocol.updates import UpdateDecoder, UpdateEncoder

DI = example_di_table()
N = 12


class SpecDecoder:
    """§8.5 read literally: header bits, width nibbles, field bits; cur, before and t per soldier."""

    def __init__(self, table: UpdateTable) -> None:
        self.table = table
        self.cur: dict[int, list[int]] = {}
        self.before: dict[int, list[int]] = {}
        self.t: dict[int, int] = {}

    def decode(self, payload: bytes) -> None:
        lay = self.table.layout
        count = int.from_bytes(payload[6:8], "big")
        tick = int.from_bytes(payload[2:6], "big")
        idx = [int.from_bytes(payload[8 + 2 * j : 10 + 2 * j], "big") for j in range(count)]
        bits = "".join(f"{b:08b}" for b in payload[8 + 2 * count :])
        nent = len(self.table.entries)
        heads = [bits[j * (1 + nent) : (j + 1) * (1 + nent)] for j in range(count)]
        pos = -(-count * (1 + nent) // 8) * 8
        widths = []
        for h in heads:
            row = []
            for e in range(nent):
                if h[0] == "1" and h[1 + e] == "1":
                    row.append(int(bits[pos : pos + 4], 2))
                    pos += 4
                else:
                    row.append(0)
            widths.append(row)
        pos = -(-pos // 8) * 8
        for s, h, row in zip(idx, heads, widths, strict=True):
            cur = self.cur.get(s, [0] * lay.nfields)
            before = self.before.get(s, cur)
            follows = self.t.get(s) == (tick - 1) % 2**32
            new, nbefore = list(cur), list(cur)
            for e in range(nent):
                if h[1 + e] != "1":
                    continue
                a = int(lay.entry_start[e])
                for f in range(a, a + int(lay.entry_nfields[e])):
                    w = row[e]
                    if w == 0:  # absolute entry
                        b = int(lay.width[f])
                        new[f] = nbefore[f] = int(bits[pos : pos + b], 2)
                        pos += b
                    elif not lay.is_qidx[f]:
                        r = int(bits[pos : pos + w], 2)
                        r -= (r >> (w - 1)) << w
                        pos += w
                        new[f] = (2 * cur[f] - before[f] if follows else cur[f]) + r
                        assert 0 <= new[f] <= int(lay.max_code[f])
            self.cur[s], self.before[s], self.t[s] = new, nbefore, tick
        assert len(payload) - (8 + 2 * count) == -(-pos // 8)


def _smooth(rng: np.random.Generator, codes: np.ndarray, vel: np.ndarray, table: UpdateTable) -> np.ndarray:
    """Codes moved on by a slowly changing velocity (and now and then a jump), kept inside each field."""
    lay = table.layout
    vel += rng.integers(-2, 3, vel.shape)
    jump = rng.random(codes.shape) < 0.02
    new = codes + vel + jump * rng.integers(-(1 << 14), 1 << 14, codes.shape)
    return np.clip(new, 0, lay.max_code).astype(np.int32)


@settings(max_examples=60, deadline=None)
@given(
    small_tables(),
    st.integers(0, 2**32 - 1),
    st.lists(st.sampled_from(["next", "same", "gap", "reset"]), min_size=1, max_size=25),
    st.sampled_from([1 << 16, 120]),
)
def test_the_spec_decoder_and_the_fast_one_agree_with_the_encoder(
    table: UpdateTable, seed: int, steps: list[str], max_payload: int
) -> None:
    rng = np.random.default_rng(seed)
    lay = table.layout
    enc, dec, spec = (
        UpdateEncoder(table, N, version=2),
        UpdateDecoder(table, N, version=2),
        SpecDecoder(table),
    )
    codes = rng.integers(0, lay.max_code + 1, (N, lay.nfields)).astype(np.int32)
    vel = rng.integers(-20, 21, codes.shape)
    tick = int(rng.integers(0, 2**32))  # the tick wraps through 2^32 in some examples
    for step in steps:
        if step == "reset":
            enc.reset(rng.choice(N, 2, replace=False))
            continue
        tick = (tick + {"next": 1, "same": 0, "gap": 3}[step]) % 2**32
        codes = _smooth(rng, codes, vel, table)
        sent = np.sort(rng.choice(N, int(rng.integers(1, N + 1)), replace=False))
        try:
            payloads = enc.encode_codes(sent, codes[sent], tick, max_payload)
        except ValueError:
            return  # max_payload too small for one soldier of a wide table
        for p in payloads:
            assert len(p) <= max_payload
            dec.decode(p)
            spec.decode(p)
        assert np.array_equal(dec.codes(sent), codes[sent])
        assert all(spec.cur[s] == codes[s].tolist() for s in sent.tolist())


def test_the_prediction_follows_the_tick_through_its_wrap() -> None:
    """Ticks 2^32 - 1 then 0 are consecutive (§8.5: t = T - 1 mod 2^32): the third update is predicted."""
    lay = DI.layout
    enc, dec = UpdateEncoder(DI, 1, version=2), UpdateDecoder(DI, 1, version=2)
    codes = np.full((1, lay.nfields), 2000, np.int32)
    codes[:, lay.qidx_fields] = 0
    sizes = []
    for k, tick in enumerate((2**32 - 2, 2**32 - 1, 0)):
        (p,) = enc.encode_codes(np.array([0]), codes + 100 * k * (~lay.is_qidx), tick, 1 << 16)
        dec.decode(p)
        sizes.append(len(p))
    assert np.array_equal(dec.codes(np.array([0])), codes + 200 * (~lay.is_qidx))
    assert sizes[2] < sizes[1]  # residuals 0 (1 bit) instead of deltas of 100 (8 bits)


def test_steady_motion_costs_fewer_bytes_than_version_1() -> None:
    """A DI crowd in steady motion (each field at its own constant rate): version 2 predicts it exactly."""
    rng = np.random.default_rng(3)
    lay = DI.layout
    codes = rng.integers(1500, 2500, (64, lay.nfields)).astype(np.int32)
    codes[:, lay.qidx_fields] = 0
    vel = rng.integers(-15, 16, codes.shape)
    vel[:, lay.qidx_fields] = 0
    size = {}
    for version in (1, 2):
        enc, dec = UpdateEncoder(DI, 64, version=version), UpdateDecoder(DI, 64, version=version)
        total = 0
        for tick in range(1, 31):
            (p,) = enc.encode_codes(np.arange(64), codes + tick * vel, tick, 1 << 16)
            dec.decode(p)
            total += len(p) if tick > 2 else 0
        size[version] = total / (28 * 64)
    # per soldier: 1-bit residuals (0) and 25 width nibbles against 5-bit deltas: 25.5 against 44.4 bytes
    assert size[2] < 26
    assert size[1] > 44


def _v2_frames() -> tuple[list[bytes], bytes]:
    """Two good frames (a full update, then a delta of soldier 1) and a third whose widths we mutate."""
    enc = UpdateEncoder(DI, 4, version=2)
    codes = np.full((4, DI.layout.nfields), 1000, np.int32)
    codes[:, DI.layout.qidx_fields] = 0
    first = enc.encode_codes(np.arange(4), codes, 1, 1 << 16)
    codes[1, :3] += 5
    second = enc.encode_codes(np.arange(4), codes, 2, 1 << 16)
    codes[1, :3] += 9
    (third,) = enc.encode_codes(np.arange(4), codes, 3, 1 << 16)
    return first + second, third


@pytest.mark.parametrize(
    ("mutate", "code"),
    [
        # one soldier: index at 8, 26 header bits at 10..13, one width nibble at 14, the fields from 15
        (lambda b: b[:13] + bytes([b[13] | 0x01]) + b[14:], ErrorCode.MALFORMED_FRAME),  # header padding
        (lambda b: b[:-1], ErrorCode.MALFORMED_FRAME),
        (lambda b: b + b"\x00", ErrorCode.MALFORMED_FRAME),
        (lambda b: b[:14] + bytes([b[14] | 0x0F]) + b[15:], ErrorCode.MALFORMED_FRAME),  # width pad nibble
        (lambda b: b[:14] + bytes([0xF0]) + b[15:], ErrorCode.MALFORMED_FRAME),  # width 15: length wrong
    ],
)
def test_bad_version_2_frames_are_refused_and_change_nothing(mutate, code: ErrorCode) -> None:
    good, third = _v2_frames()
    dec = UpdateDecoder(DI, 4, version=2)
    for p in good:
        dec.decode(p)
    held = dec.codes(np.arange(4))
    with pytest.raises(WireError) as info:
        dec.decode(mutate(third))
    assert info.value.code == code
    assert np.array_equal(dec.codes(np.arange(4)), held)
    dec.decode(third)  # the good frame still applies, with the prediction state untouched
    assert dec.codes(np.array([1]))[0, 0] == 1014


def test_a_residual_leaving_its_range_is_bad_update() -> None:
    """A hand-made frame (§8.5): soldier 1, mode 1, entry 0 only, width 1, residuals −1, 0, 0 at code 0."""
    lay = DI.layout
    codes = np.full((4, lay.nfields), 1000, np.int32)
    codes[:, lay.qidx_fields] = 0
    codes[1, 0] = 0  # waist dof 0 at the bottom of its range
    dec = UpdateDecoder(DI, 4, version=2)
    for p in UpdateEncoder(DI, 4, version=2).encode_codes(np.arange(4), codes, 1, 1 << 16):
        dec.decode(p)
    nent = len(DI.entries)
    head = (
        DI.table_id.to_bytes(2, "big")
        + (2).to_bytes(4, "big")
        + (1).to_bytes(2, "big")
        + (1).to_bytes(2, "big")
    )
    hdr = ("1" + "1" + "0" * (nent - 1)).ljust(-(-(1 + nent) // 8) * 8, "0")
    frame = head + int(hdr, 2).to_bytes(len(hdr) // 8, "big") + bytes([0x10, 0b1000_0000])
    with pytest.raises(WireError) as info:
        dec.decode(frame)
    assert info.value.code == ErrorCode.BAD_UPDATE
    assert np.array_equal(dec.codes(np.arange(4)), codes)
    ok = frame[:-2] + bytes([0x20, 0b0001_0000])  # width 2, residuals 0, 1, 0 (before = cur: p = cur)
    dec.decode(ok)
    assert dec.codes(np.array([1]))[0, :3].tolist() == [0, 1001, 1000]
