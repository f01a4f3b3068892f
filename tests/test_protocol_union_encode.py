"""Issue 21: a front-end's clients of one shard batch encoded in one pass (``encode_codes_union``) get, each,
the bytes, delta state and memo state their own encodes would give them, whatever their rows (disjoint,
overlapping, idle), histories, payload limits and formats."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_protocol_encode_reference import STEPS, WIDE, _moved
from test_protocol_updates import small_tables

from protocol.shared_encode import SharedEncodes
from protocol.update_table import UpdateTable, example_di_table
from protocol.updates import UpdateDecoder, UpdateEncoder, encode_codes_union

DI = example_di_table()


def _same_state(a: UpdateEncoder, b: UpdateEncoder) -> None:
    assert np.array_equal(a._known, b._known)
    assert np.array_equal(a._last[a._known], b._last[b._known])
    assert np.array_equal(a._sent, b._sent) and a._tick == b._tick
    if a.version >= 2:
        assert np.array_equal(a._before, b._before)


def union_stream(
    table: UpdateTable, n: int, seed: int, steps: list[str], payloads: list[int], version: int, memo: bool
) -> None:
    """Clients with payload limits ``payloads`` (two may be in one state: the memo's case) each watch
    random rows; each step they are encoded in one union and, alongside, one by one: same frames, states."""
    rng = np.random.default_rng(seed)
    lay = table.layout
    memos = (SharedEncodes(), SharedEncodes()) if memo else (None, None)
    union = [UpdateEncoder(table, n, memos[0], version) for _ in payloads]
    alone = [UpdateEncoder(table, n, memos[1], version) for _ in payloads]
    decs = [UpdateDecoder(table, n, version) for _ in payloads]
    codes = rng.integers(0, lay.max_code + 1, (n, lay.nfields)).astype(np.int32)
    vel = rng.integers(-30, 31, codes.shape)
    tick = int(rng.integers(0, 2**32))
    for serial, step in enumerate(steps):
        if step == "reset":
            k = int(rng.integers(len(payloads)))
            forget = rng.choice(n, max(1, n // 8), replace=False)
            union[k].reset(forget)
            alone[k].reset(forget)
            continue
        tick = (tick + {"same": 0, "gap": 2}.get(step, 1)) % 2**32
        codes = _moved(rng, codes, vel, table, 0.9 if step == "idle" else float(rng.random()) * 0.5)
        shared_rows = rng.choice(n, int(rng.integers(0, n + 1)), replace=False)
        subs = [
            shared_rows if rng.random() < 0.3 else rng.choice(n, int(rng.integers(0, n + 1)), replace=False)
            for _ in payloads
        ]
        if rng.random() < 0.5:  # sorted, their codes slices of one gather: the union reads them uncopied
            subs = [np.sort(rows) for rows in subs]
        gathered = codes[np.concatenate(subs)]
        at = np.cumsum([0, *map(len, subs)])
        jobs = [
            (union[k], rows, gathered[at[k] : at[k + 1]], max_payload)
            for k, (rows, max_payload) in enumerate(zip(subs, payloads, strict=True))
        ]
        version_key = serial if memo else None
        try:
            got = encode_codes_union(jobs, tick, version_key)
        except ValueError as exc:  # max_payload too small for one soldier of a wide table
            assert "cannot hold one soldier update" in str(exc)
            return
        for k, (_, rows, q, max_payload) in enumerate(jobs):
            assert got[k] == alone[k].encode_codes(rows, q, tick, max_payload, version_key)
            _same_state(union[k], alone[k])
            assert union[k].state == alone[k].state
            for f in got[k]:
                assert len(f) <= max_payload
                decs[k].decode(f)
            assert np.array_equal(decs[k].codes(rows), q)
        if memo:
            a, b = memos
            assert a is not None and b is not None
            assert (a.hits, a.misses, a.rows_encoded) == (b.hits, b.misses, b.rows_encoded)


@settings(max_examples=40, deadline=None)
@given(
    small_tables(),
    st.integers(0, 2**32 - 1),
    STEPS,
    st.lists(st.sampled_from([1 << 16, 300, 120]), min_size=1, max_size=4),
    st.sampled_from([1, 2]),
    st.booleans(),
)
def test_random_tables_union_encode_to_each_clients_own_bytes(
    table: UpdateTable, seed: int, steps: list[str], payloads: list[int], version: int, memo: bool
) -> None:
    union_stream(table, 24, seed, steps, payloads, version, memo)


@settings(max_examples=8, deadline=None)
@given(st.integers(0, 2**32 - 1), STEPS, st.sampled_from([1, 2]), st.booleans())
def test_a_di_crowd_and_a_wide_table_union_encode_to_each_clients_own_bytes(
    seed: int, steps: list[str], version: int, memo: bool
) -> None:
    """Hundreds of DI soldiers in frames of 1,500 and 65,535 bytes; 97 fields (two diff words a row)."""
    union_stream(DI, 600, seed, ["next", "next", *steps], [1500, 65535, 1500], version, memo)
    union_stream(WIDE, 300, seed, ["next", *steps], [4000, 4000], version, memo)


def test_clients_in_one_state_still_share_one_encode() -> None:
    """Two clients in one state sent the same rows: the union encodes them once (the second: a memo hit)."""
    memo = SharedEncodes()
    a, b = UpdateEncoder(DI, 16, memo), UpdateEncoder(DI, 16, memo)
    codes = np.random.default_rng(3).integers(0, 4000, (16, DI.layout.nfields)).astype(np.int32)
    codes[:, DI.layout.qidx_fields] = 0
    rows = np.arange(16)
    fa, fb = encode_codes_union([(a, rows, codes, 1500), (b, rows, codes, 1500)], 7, 1)
    assert fa == fb and fa
    assert (memo.hits, memo.misses, memo.rows_encoded) == (1, 1, 16)
    assert a.state == b.state


def test_a_union_needs_distinct_encoders_of_one_table() -> None:
    a = UpdateEncoder(DI, 8)
    codes = np.zeros((1, DI.layout.nfields), np.int32)
    with pytest.raises(ValueError, match="one job"):
        encode_codes_union([(a, np.array([0]), codes, 1500), (a, np.array([1]), codes, 1500)], 1)
