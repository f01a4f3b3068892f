"""The cheaper version-2 encode (issue 18: field-major passes, entry widths in one gather, a tree merge of
the fields into groups) writes exactly the bytes of the encoder it replaced (:mod:`v2_reference`) and leads
to the same prediction state, on random tables and on the DI soldier's table; what it writes decodes back
to the codes sent."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from test_protocol_encode_reference import same_stream
from test_protocol_updates import small_tables
from v2_reference import ReferenceEncoder

from protocol.bitpack import merge_columns, merge_groups
from protocol.update_table import UpdateTable, example_di_table

DI = example_di_table()


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
        same_stream(table, 24, seed, steps, max_payload, 2, ReferenceEncoder)
    except ValueError as exc:  # max_payload too small for one soldier of a wide table (both encoders)
        assert "cannot hold one soldier update" in str(exc)


@settings(max_examples=8, deadline=None)
@given(st.integers(0, 2**32 - 1), st.sampled_from([1 << 20, 1500]))
def test_the_di_table_encodes_to_the_reference_bytes(seed: int, max_payload: int) -> None:
    """A crowd of DI soldiers over a few ticks (frames split at 1,500 bytes too)."""
    steps = ["next"] * 6 + ["gap", "next", "reset", "next", "same", "next"]
    same_stream(DI, 400, seed, steps, max_payload, 2, ReferenceEncoder)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32 - 1), st.integers(1, 4), st.integers(0, 40), st.integers(0, 12))
def test_merge_columns_is_merge_groups_of_the_transpose(seed: int, g: int, n: int, ngroups: int) -> None:
    rng = np.random.default_rng(seed)
    widths = rng.integers(0, {1: 24, 2: 24, 3: 21, 4: 16}[g] + 1, (n, g * ngroups)).astype(np.uint8)
    values = rng.integers(-(1 << 24), 1 << 24, widths.shape).astype(np.int32)
    want, want_w = (a.copy() for a in merge_groups(values, widths, g))
    got, got_w = merge_columns(np.ascontiguousarray(values.T), np.ascontiguousarray(widths.T), g)
    assert np.array_equal(got, want) and np.array_equal(got_w, want_w)
