"""Issue 21: what travels on the fabric between shards and front-ends, and the front-end's board merge."""

from __future__ import annotations

import contextlib
import dataclasses

import msgpack
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from protocol.entity import make_entity_requests
from server.fabric import requests as req
from server.fabric.batch import Batch, decode_batch, encode_batch
from server.fabric.fronts import addressee, answer, decode_answer
from server.fabric.nodes import FrontNode, Sharding
from server.pose_board import PoseBoard


def _batch(n: int = 3, nf: int = 64) -> Batch:
    codes = (np.arange(n * nf).reshape(n, nf) * 97) % 65536
    return Batch(1, 2, 7, 9, 12.5, np.arange(n) * 2 + 1, np.full(n, 2), codes)


def test_a_batch_survives_the_fabric() -> None:
    b = decode_batch(encode_batch(_batch()))
    assert (b.shard, b.shards, b.seq, b.tick, b.sent) == (1, 2, 7, 9, 12.5)
    assert b.indices.tolist() == [1, 3, 5] and b.tables.tolist() == [2, 2, 2]
    assert np.array_equal(b.codes, _batch().codes)
    assert b.fences == ()


def test_a_batch_carries_each_front_ends_fence() -> None:
    fenced = decode_batch(encode_batch(dataclasses.replace(_batch(), fences=(0, 7, 2**32 - 1))))
    assert fenced.fences == (0, 7, 2**32 - 1) and fenced.indices.tolist() == [1, 3, 5]
    assert np.array_equal(fenced.codes, _batch().codes)


@pytest.mark.parametrize(
    ("front", "serial"), [(255, 1), (-1, 1), (10**9, 1), ("0", 1), (0, 2**32), (0, -1), (0, 1.5), (0, None)]
)
def test_a_fence_a_batch_cannot_carry_is_refused_when_it_arrives(front: object, serial: object) -> None:
    """A fence's front-end sizes the shard's list of fences and is counted in a byte of every batch, its
    serial travels as uint32: out of range, the shard would grow the list or fail to publish at all."""
    with pytest.raises(ValueError, match="fence"):
        req.decode(req.pack([{"op": "fence", "front": front, "serial": serial}]))
    assert req.decode(req.pack([req.fence(254, 2**32 - 1)])) == [req.fence(254, 2**32 - 1)]


def test_codes_beyond_16_bits_are_refused() -> None:
    b = _batch()
    with pytest.raises(ValueError, match="16 bits"):
        encode_batch(Batch(0, 1, 0, 0, 0.0, b.indices, b.tables, b.codes + 65536))


@given(st.binary(max_size=200))
def test_any_bytes_decode_to_a_batch_or_a_value_error(data: bytes) -> None:
    try:
        b = decode_batch(data)
    except ValueError:
        return
    assert len(b.indices) == len(b.tables) == len(b.codes)


@given(st.binary(max_size=200))
def test_any_bytes_decode_to_requests_or_a_value_error(data: bytes) -> None:
    try:
        ops = req.decode(data)
    except ValueError:
        return
    assert all(op["op"] in req.OPS for op in ops)


@given(
    st.binary(max_size=200)
    | st.builds(
        msgpack.packb,
        st.dictionaries(
            st.sampled_from(["shard", "front", "body"]),
            st.integers(-(2**63), 2**63 - 1) | st.binary(max_size=40) | st.none(),
        ),
    )
)
def test_any_bytes_decode_to_a_books_answer_or_a_value_error(data: bytes) -> None:
    for decode in (addressee, decode_answer):
        with contextlib.suppress(ValueError):
            decode(data)


def test_a_books_answer_names_its_shard_and_front_end_without_its_body() -> None:
    """Every front-end hears every answer; only the one it is for unpacks the soldiers (addressee)."""
    data = answer(1, 4, [(7, "DI.fig", "AK_47.fig", "alpha")], gens=[2])
    assert addressee(data) == (1, 4)
    assert isinstance(msgpack.unpackb(data)["body"], bytes)  # packed apart
    msg = decode_answer(data)
    assert (msg["shard"], msg["front"], msg["soldiers"], msg["gens"]) == (
        1,
        4,
        [(7, "DI.fig", "AK_47.fig", "alpha")],
        [2],
    )


def test_requests_and_syncs_survive_the_fabric() -> None:
    rows = make_entity_requests([4, 6], velocity=(0.0, 1.4, 0.0))
    sync = req.sync([(4, "DI.fig", "M16.fig", "alpha"), (6, "DI.fig", "", None)], rows[:1])
    got = req.decode(req.pack([req.requests(rows), sync, req.create(3, "DI.fig", "AK_47.fig", None)]))
    assert [op["op"] for op in got] == ["requests", "sync", "create"]
    assert np.array_equal(got[0]["rows"], rows)
    assert got[1]["soldiers"] == [[4, "DI.fig", "M16.fig", "alpha"], [6, "DI.fig", "", None]]
    assert got[1]["rows"]["index"].tolist() == [4]
    assert got[2]["owner"] is None


def test_sharding_is_k_of_n() -> None:
    s = Sharding.parse("1/3")
    assert s.owns(np.arange(7)).tolist() == [False, True, False, False, True, False, False]
    for bad in ("3/3", "1", "-1/2", "a/b"):
        with pytest.raises(ValueError):
            Sharding.parse(bad)


def test_merged_codes_bump_the_version_of_changed_soldiers_only() -> None:
    board = PoseBoard(50, 2)
    codes = np.ones((3, 64), np.int32)
    assert board.publish_codes(np.array([0, 1, 2]), np.array([1, 1, 1]), codes, 1) == 3
    codes[1, 5] = 9
    assert board.publish_codes(np.array([0, 1, 2]), np.array([1, 1, 1]), codes, 2) == 1
    assert board.version[:3].tolist() == [1, 2, 1] and board.tick == 2
    assert board.publish_codes(np.zeros(0, np.int64), np.zeros(0, np.int32), np.zeros((0, 0)), 2) == 0


def test_a_request_without_its_rows_is_a_value_error() -> None:
    with pytest.raises(ValueError, match="without rows"):
        req.decode(msgpack.packb([{"op": "requests", "rows": 5}]))


def test_a_front_end_asks_a_shard_for_its_books_when_two_key_pulses_in_a_row_differ() -> None:
    """A creation through another front-end is often in a shard's key pulse before its message on ttes/fronts
    reaches this front-end: asking at once, each front-end asked each shard about once a second while they
    made soldiers (1,000-1,100 whole answers a shard in 100 s, 48,000 over 6 shards and 6 front-ends)."""
    node = FrontNode.__new__(FrontNode)  # (the pulse-by-pulse verdict alone: _differs is the books' check)
    node._differed = set()
    verdicts = iter([True, False, True, True, True, False])
    node._differs = lambda k, indices: next(verdicts)  # type: ignore[method-assign]
    asks = [node._differs_again(0, np.zeros(0, np.int64)) for _ in range(6)]
    assert asks == [False, False, False, True, True, False]
