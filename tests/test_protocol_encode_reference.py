"""Issue 21: the cheaper joint-update encode writes exactly the bytes of the encoder it replaced (frozen in
:mod:`encode_reference`), for both formats, over random tables, codes, histories (ticks in a row, gaps,
repeats, resets, idle soldiers, partial and unsorted batches) and payload limits, and leaves the same delta
and prediction state."""

from __future__ import annotations

import encode_reference as reference
import numpy as np
import pytest
from encode_reference import ReferenceEncoder
from hypothesis import given, settings
from hypothesis import strategies as st
from test_protocol_updates import small_tables

from protocol import predicted
from protocol.update_table import DofRange, FigureEntry, JointEntry, UpdateTable, example_di_table
from protocol.updates import UpdateDecoder, UpdateEncoder

DI = example_di_table()
STEPS = st.lists(
    st.sampled_from(["next", "next", "next", "same", "gap", "reset", "idle"]), min_size=1, max_size=10
)


def _moved(rng: np.random.Generator, codes: np.ndarray, vel: np.ndarray, table: UpdateTable, still: float):
    """Smooth motion with jumps and qidx flips; a share ``still`` of the soldiers keeps its codes."""
    lay = table.layout
    vel += rng.integers(-2, 3, vel.shape)
    jump = rng.random(codes.shape) < 0.01
    new = codes + vel + jump * rng.integers(-(1 << 15), 1 << 15, codes.shape)
    flip = rng.random((len(codes), len(lay.qidx_fields))) < 0.02
    new[:, lay.qidx_fields] = np.where(flip, rng.integers(0, 4, flip.shape), codes[:, lay.qidx_fields])
    new = np.clip(new, 0, lay.max_code).astype(np.int32)
    keep = rng.random(len(codes)) < still
    new[keep] = codes[keep]
    return new


def same_stream(
    table: UpdateTable,
    n: int,
    seed: int,
    steps: list[str],
    max_payload: int,
    version: int,
    reference: type[ReferenceEncoder] = ReferenceEncoder,
    encoder: type[UpdateEncoder] = UpdateEncoder,
) -> None:
    """The ``encoder`` and ``reference`` get the same ticks: every frame is the same bytes, the states after
    it agree, and what is sent decodes back to the codes."""
    rng = np.random.default_rng(seed)
    lay = table.layout
    new, ref = encoder(table, n, version=version), reference(table, n, version=version)
    dec = UpdateDecoder(table, n, version=version)
    codes = rng.integers(0, lay.max_code + 1, (n, lay.nfields)).astype(np.int32)
    vel = rng.integers(-30, 31, codes.shape)
    tick = int(rng.integers(0, 2**32))
    for step in steps:
        if step == "reset":
            forget = rng.choice(n, max(1, n // 8), replace=False)
            new.reset(forget)
            ref.reset(forget)
            continue
        tick = (tick + {"same": 0, "gap": 2}.get(step, 1)) % 2**32
        codes = _moved(rng, codes, vel, table, 0.9 if step == "idle" else float(rng.random()) * 0.5)
        sent = rng.choice(n, int(rng.integers(1, n + 1)), replace=False)  # unsorted: the encoder sorts
        frames = new.encode_codes(sent, codes[sent], tick, max_payload)
        assert frames == ref.encode_codes(sent, codes[sent], tick, max_payload)
        assert np.array_equal(new._known, ref._known)
        assert np.array_equal(new._last[new._known], ref._last[ref._known])
        if version >= 2:
            nf = lay.nfields  # the same prediction (the encoder keeps it as uint16, the reference int32)
            assert np.array_equal(new._before[:, :nf], ref._before[:, :nf])
            assert np.array_equal(predicted.state_ticks(new._before), predicted.state_ticks(ref._before))
        for f in frames:
            assert len(f) <= max_payload
            dec.decode(f)
        assert np.array_equal(dec.codes(sent), codes[sent])


@settings(max_examples=60, deadline=None)
@given(
    small_tables(),
    st.integers(0, 2**32 - 1),
    STEPS,
    st.sampled_from([1 << 16, 300, 120]),
    st.sampled_from([1, 2]),
)
def test_random_tables_encode_to_the_frozen_bytes(
    table: UpdateTable, seed: int, steps: list[str], max_payload: int, version: int
) -> None:
    try:
        same_stream(table, 24, seed, steps, max_payload, version)
    except ValueError as exc:  # max_payload too small for one soldier of a wide table (both encoders)
        assert "cannot hold one soldier update" in str(exc)


@settings(max_examples=10, deadline=None)
@given(st.integers(0, 2**32 - 1), STEPS, st.sampled_from([1 << 20, 65535, 1500]), st.sampled_from([1, 2]))
def test_a_di_crowd_encodes_to_the_frozen_bytes(
    seed: int, steps: list[str], max_payload: int, version: int
) -> None:
    """Hundreds of DI soldiers, frames split at 1,500 and 65,535 bytes too."""
    same_stream(DI, 600, seed, ["next", "next", *steps], max_payload, version)


_JOINTS = [
    JointEntry(f"j{i}", tuple(DofRange("R", -1.0, 1.0, 10 + i % 7) for _ in range(3))) for i in range(30)
]
WIDE = UpdateTable(4, "wide.fig", "", (*_JOINTS, FigureEntry("f", -2.0, 2.0, 16, 12)))


@settings(max_examples=6, deadline=None)
@given(st.integers(0, 2**32 - 1), STEPS, st.sampled_from([1, 2]))
def test_a_table_wider_than_64_fields_encodes_to_the_frozen_bytes(
    seed: int, steps: list[str], version: int
) -> None:
    """97 fields: the diff spans two 64-bit words per soldier."""
    assert WIDE.layout.nfields > 64
    same_stream(WIDE, 300, seed, ["next", *steps], 4000, version)


@pytest.mark.parametrize("version", [1, 2])
def test_nothing_changed_sends_nothing(version: int) -> None:
    new, ref = UpdateEncoder(DI, 8, version=version), ReferenceEncoder(DI, 8, version=version)
    codes = np.random.default_rng(1).integers(0, 4000, (8, DI.layout.nfields)).astype(np.int32)
    codes[:, DI.layout.qidx_fields] = 0
    idx = np.arange(8)
    assert new.encode_codes(idx, codes, 5, 1 << 16) == ref.encode_codes(idx, codes, 5, 1 << 16)
    assert new.encode_codes(idx, codes, 6, 1 << 16) == ref.encode_codes(idx, codes, 6, 1 << 16) == []


@pytest.mark.parametrize("version", [1, 2])
def test_codes_past_16_bits_widen_the_state_and_keep_the_frozen_bytes(version: int) -> None:
    """The encoder keeps a table of 16-bit fields' codes as uint16; codes no quantiser makes (past 16 bits,
    negative) turn its state to int32 first, so every frame stays the frozen encoder's."""
    rng = np.random.default_rng(7)
    new, ref = UpdateEncoder(DI, 40, version=version), ReferenceEncoder(DI, 40, version=version)
    assert new._last.dtype == np.uint16
    codes = rng.integers(0, 4000, (40, DI.layout.nfields)).astype(np.int32)
    codes[:, DI.layout.qidx_fields] = 0
    idx = np.arange(40)
    for tick in range(5, 10):
        codes += rng.integers(-3, 4, codes.shape).astype(np.int32) * (codes > 8)
        codes[:, DI.layout.qidx_fields] = 0
        if tick == 7:
            codes[3, 5], codes[9, 2] = 70_000, -5
        assert new.encode_codes(idx, codes, tick, 1 << 16) == ref.encode_codes(idx, codes, tick, 1 << 16)
    assert new._last.dtype == np.int32
    assert np.array_equal(new._last, ref._last)
    if version >= 2:
        assert np.array_equal(new._before, ref._before)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(0, 300), st.integers(1, 80))
def test_transpose_is_numpys(seed: int, n: int, f: int) -> None:
    """The residuals' transposed copy (four fields at a time where it can) equals ``a.T``."""
    a = np.random.default_rng(seed).integers(-(1 << 31), 1 << 31, (n, f)).astype(np.int32)
    out = np.empty((f, n), np.int32)
    predicted.transpose(a, out)
    assert np.array_equal(out, a.T)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 300), st.floats(0.0, 1.0))
def test_residuals_are_the_frozen_ones(seed: int, n: int, predicting: float) -> None:
    """Whatever share of the rows predicts (all, most: dense passes and the rest put back; few: by row)."""
    rng = np.random.default_rng(seed)
    nf, tick = DI.layout.nfields, 1000
    q, cur = (rng.integers(-(1 << 31), 1 << 31, (n, nf)).astype(np.int32) for _ in range(2))
    state = rng.integers(-(1 << 31), 1 << 31, (n, nf + 1)).astype(np.int32)
    state[:, nf] = np.where(rng.random(n) < predicting, tick - 1, tick - 2)
    ours = predicted.residuals(q, cur, state, tick, np.empty((n, nf), np.int32))
    assert np.array_equal(ours, reference.residuals(q, cur, state, tick))
