"""Issue 21: the fused version-2 encode (:mod:`protocol.fused`, numba) writes exactly the numpy path's bytes
and leaves the same delta and prediction state, on random tables and a DI crowd (jumps past 15 bits, qidx
flips, resets, frames split), from a front-end board's uint16 codes against int32 ones. (The frozen
reference tests run on the fused path too where numba is installed.)"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_protocol_encode_reference import STEPS, same_stream
from test_protocol_updates import small_tables

from protocol import fused
from protocol.update_table import UpdateTable, example_di_table
from protocol.updates import UpdateEncoder

pytestmark = pytest.mark.skipif(not fused.AVAILABLE, reason="numba is not installed (the fast extra)")
DI = example_di_table()


class NumpyPath(UpdateEncoder):
    """The encoder with the fused loops off (``Columns.fused``): the reference here."""

    def __init__(self, *args: object, **kw: object) -> None:
        super().__init__(*args, **kw)  # type: ignore[arg-type]
        self._plan.v2.fused = False


class FromBoard(UpdateEncoder):
    """The fused encoder given its codes as a front-end's board holds them: uint16 (int32 past 16 bits)."""

    def encode_codes(
        self, indices: np.ndarray, codes: np.ndarray, tick: int, max_payload: int, version: object = None
    ) -> list[bytes]:
        assert self._plan.v2.fused or not (self.table.layout.entry_ndelta >= 1).all()
        if int(codes.max(initial=0)) <= 0xFFFF:
            codes = codes.astype(np.uint16)
        return super().encode_codes(indices, codes, tick, max_payload, version)


@settings(max_examples=60, deadline=None)
@given(small_tables(), st.integers(0, 2**32 - 1), STEPS, st.sampled_from([1 << 16, 300, 120]))
def test_random_tables_encode_as_the_numpy_path(
    table: UpdateTable, seed: int, steps: list[str], max_payload: int
) -> None:
    try:
        same_stream(table, 24, seed, steps, max_payload, 2, NumpyPath, FromBoard)  # type: ignore[arg-type]
    except ValueError as exc:  # max_payload too small for one soldier of a wide table (both encoders)
        assert "cannot hold one soldier update" in str(exc)


@settings(max_examples=10, deadline=None)
@given(st.integers(0, 2**32 - 1), STEPS, st.sampled_from([1 << 20, 65535, 1500]))
def test_a_di_crowd_encodes_as_the_numpy_path(seed: int, steps: list[str], max_payload: int) -> None:
    """Hundreds of DI soldiers, frames split at 1,500 and 65,535 bytes too (each frame's body a new word)."""
    same_stream(DI, 600, seed, ["next", "next", *steps], max_payload, 2, NumpyPath, FromBoard)  # type: ignore[arg-type]


def test_warm_compiles_what_an_encode_then_uses() -> None:
    fused.warm()
    enc = UpdateEncoder(DI, 4, version=2)
    assert enc._plan.v2.fused
    codes = np.zeros((4, DI.layout.nfields), np.uint16)
    assert len(enc.encode_codes(np.arange(4), codes, 1, 1 << 16)) == 1
