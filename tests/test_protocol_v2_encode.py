"""The cheaper version-2 encode (issue 18: field-major passes, entry widths in one gather, a tree merge of
the fields into groups) writes exactly the bytes of the encoder it replaced (:mod:`v2_reference`) and leads
to the same prediction state, on random tables and on the DI soldier's table; what it writes decodes back
to the codes sent."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from test_protocol_updates import small_tables
from v2_reference import ReferenceEncoder

from protocol.bitpack import merge_columns, merge_groups
from protocol.update_table import UpdateTable, example_di_table
from protocol.updates import UpdateDecoder, UpdateEncoder

DI = example_di_table()


def _moved(rng: np.random.Generator, codes: np.ndarray, vel: np.ndarray, table: UpdateTable) -> np.ndarray:
    """Smooth motion, now and then a jump (an absolute entry) or a new qidx (a flip), inside each field."""
    lay = table.layout
    vel += rng.integers(-2, 3, vel.shape)
    jump = rng.random(codes.shape) < 0.01
    new = codes + vel + jump * rng.integers(-(1 << 15), 1 << 15, codes.shape)
    flip = rng.random((len(codes), len(lay.qidx_fields))) < 0.02
    new[:, lay.qidx_fields] = np.where(flip, rng.integers(0, 4, flip.shape), codes[:, lay.qidx_fields])
    return np.clip(new, 0, lay.max_code).astype(np.int32)


def _same_stream(table: UpdateTable, n: int, seed: int, steps: list[str], max_payload: int) -> None:
    """Both encoders get the same ticks; every frame, the state after it and the decoded codes agree."""
    rng = np.random.default_rng(seed)
    lay = table.layout
    new, ref = UpdateEncoder(table, n, version=2), ReferenceEncoder(table, n, version=2)
    dec = UpdateDecoder(table, n, version=2)
    codes = rng.integers(0, lay.max_code + 1, (n, lay.nfields)).astype(np.int32)
    vel = rng.integers(-30, 31, codes.shape)
    tick = int(rng.integers(0, 2**32))
    for step in steps:
        if step == "reset":
            forget = rng.choice(n, max(1, n // 8), replace=False)
            new.reset(forget)
            ref.reset(forget)
            continue
        tick = (tick + {"next": 1, "same": 0, "gap": 2}[step]) % 2**32
        codes = _moved(rng, codes, vel, table)
        sent = np.sort(rng.choice(n, int(rng.integers(1, n + 1)), replace=False))
        frames = new.encode_codes(sent, codes[sent], tick, max_payload)
        assert frames == ref.encode_codes(sent, codes[sent], tick, max_payload)
        assert np.array_equal(new._before, ref._before)
        for f in frames:
            dec.decode(f)
        assert np.array_equal(dec.codes(sent), codes[sent])


@settings(max_examples=40, deadline=None)
@given(
    small_tables(),
    st.integers(0, 2**32 - 1),
    st.lists(st.sampled_from(["next", "next", "same", "gap", "reset"]), min_size=1, max_size=12),
    st.sampled_from([1 << 16, 200]),
)
def test_random_tables_encode_to_the_reference_bytes(
    table: UpdateTable, seed: int, steps: list[str], max_payload: int
) -> None:
    try:
        _same_stream(table, 24, seed, steps, max_payload)
    except ValueError as exc:  # max_payload too small for one soldier of a wide table (both encoders)
        assert "cannot hold one soldier update" in str(exc)


@settings(max_examples=8, deadline=None)
@given(st.integers(0, 2**32 - 1), st.sampled_from([1 << 20, 1500]))
def test_the_di_table_encodes_to_the_reference_bytes(seed: int, max_payload: int) -> None:
    """A crowd of DI soldiers over a few ticks (frames split at 1,500 bytes too)."""
    _same_stream(DI, 400, seed, ["next"] * 6 + ["gap", "next", "reset", "next", "same", "next"], max_payload)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 4), st.integers(0, 40), st.integers(0, 12))
def test_merge_columns_is_merge_groups_of_the_transpose(seed: int, g: int, n: int, ngroups: int) -> None:
    rng = np.random.default_rng(seed)
    widths = rng.integers(0, {1: 24, 2: 24, 3: 21, 4: 16}[g] + 1, (n, g * ngroups)).astype(np.uint8)
    values = rng.integers(-(1 << 24), 1 << 24, widths.shape).astype(np.int32)
    want, want_w = (a.copy() for a in merge_groups(values, widths, g))
    got, got_w = merge_columns(np.ascontiguousarray(values.T), np.ascontiguousarray(widths.T), g)
    assert np.array_equal(got, want) and np.array_equal(got_w, want_w)
