"""The 1994 layouts: golden bytes for JackPackIn and update packets, round trips, rejection of bad packets."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from protocol.entity import Appearance, WeaponState, make_entity_requests
from protocol.errors import ErrorCode, WireError
from protocol.legacy import (
    JACKPACKIN_DTYPE,
    decode_jackpackin,
    decode_update_packet,
    decode_update_stream,
    encode_jackpackin,
    encode_update_packets,
    packet_floats,
)
from protocol.update_table import DofRange, FigureEntry, JointEntry, UpdateTable, example_di_table

# soldier 3, UPRIGHT, DEPLOYED, velocity (1.5, 0, 0) m/s, heading 90, position (10, 20, 0) m, immediate
GOLDEN_JACKPACKIN = bytes.fromhex(
    "00000003"  # soldierindex
    "00000002"  # appearance JACKTTES_UPRIGHT
    "00000001"  # weaponstate JACKTTES_WEAPON_DEPLOYED
    "3fc00000" "00000000" "00000000"  # velocity 1.5, 0, 0
    "42b40000"  # heading 90.0
    "41200000" "41a00000" "00000000"  # position 10, 20, 0
    "00000001"  # immediate
)  # fmt: skip


def test_jackpackin_golden_bytes() -> None:
    assert JACKPACKIN_DTYPE.itemsize == 44
    rows = make_entity_requests(
        [3], Appearance.UPRIGHT, WeaponState.DEPLOYED, (1.5, 0, 0), 90.0, (10, 20, 0), True
    )
    assert encode_jackpackin(rows) == GOLDEN_JACKPACKIN
    back = decode_jackpackin(GOLDEN_JACKPACKIN)
    assert back.tobytes() == rows.tobytes()


def test_jackpackin_batch_crawl_and_c_truth() -> None:
    rows = make_entity_requests(
        [0, 9], [Appearance.CRAWL, Appearance.DEAD], [2, 0], (0, 1, 0), [0, 45], (1, 2, 3)
    )
    data = encode_jackpackin(rows)
    assert len(data) == 88
    back = decode_jackpackin(data)
    assert back["appearance"].tolist() == [Appearance.PRONE, Appearance.DEAD]  # 1994 had no CRAWL
    assert back["weapon"].tolist() == [2, 0]
    raw = bytearray(GOLDEN_JACKPACKIN)
    raw[40:44] = struct.pack(">i", -7)  # any non-zero C int is true
    assert decode_jackpackin(bytes(raw))["immediate"].tolist() == [1]


@pytest.mark.parametrize(
    ("offset", "value", "fmt"),
    [
        (4, 5, ">i"),
        (4, 0, ">i"),
        (8, 3, ">i"),
        (0, -1, ">i"),
        (0, 70000, ">i"),
        (24, math.nan, ">f"),
        (12, math.inf, ">f"),
    ],
)
def test_jackpackin_rejects_bad_fields(offset: int, value: float, fmt: str) -> None:
    raw = bytearray(GOLDEN_JACKPACKIN * 2)
    struct.pack_into(fmt, raw, 44 + offset, value)
    with pytest.raises(WireError) as info:
        decode_jackpackin(bytes(raw))
    assert info.value.code == ErrorCode.BAD_VALUE
    assert info.value.location == "JackPackIn 1"
    with pytest.raises(WireError):
        decode_jackpackin(GOLDEN_JACKPACKIN[:-1])


TINY = UpdateTable(
    1,
    "DI.fig",
    "AK_47.fig",
    (JointEntry("left_knee", (DofRange("R", 0.0, 3.0),)), FigureEntry("soldier")),
)


def test_update_packet_golden_bytes_16_and_7_floats() -> None:
    knee = np.array([[0.5]])
    pos = np.array([[[1.0, 2.0, 0.5]]])
    quat = np.array([[[1.0, 0.0, 0.0, 0.0]]])
    data = encode_update_packets(TINY, [4], knee, pos, quat)
    # entry 0, knee 0.5; entry 1, pfMatrix rows (identity rotation, translation row 1, 2, 0.5)
    floats = [0.0, 0.5, 1.0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 1.0, 2.0, 0.5, 1]
    assert data == struct.pack(">ii19f", 4, 19, *floats)
    data7 = encode_update_packets(TINY, [4], knee, pos, quat, figure_floats=7)
    assert data7 == struct.pack(">ii10f", 4, 10, 0.0, 0.5, 1.0, 1.0, 2.0, 0.5, 0.0, 0.0, 0.0, 1.0)
    for blob, n in ((data, 16), (data7, 7)):
        (update,), used = decode_update_stream(TINY, blob, n)
        assert used == len(blob) and update.index == 4 and update.entries == (0, 1)
        assert np.allclose(update.dofs, [0.5]) and np.allclose(update.positions, pos[0])
        assert np.allclose(update.orientations, quat[0])


def test_full_di_update_is_about_440_bytes_and_round_trips() -> None:
    table = example_di_table()
    assert packet_floats(table) == 23 + 50 + 2 * 17
    rng = np.random.default_rng(0)
    n = 4
    dofs = rng.uniform(-1, 1, (n, 50))
    pos = rng.uniform(-1, 1, (n, 2, 3))
    quat = rng.normal(size=(n, 2, 4))
    quat /= np.linalg.norm(quat, axis=-1, keepdims=True)
    data = encode_update_packets(table, np.arange(n), dofs, pos, quat)
    assert len(data) == n * 436
    updates, used = decode_update_stream(table, data + data[:100])  # a trailing partial packet is left
    assert used == len(data) and [u.index for u in updates] == [0, 1, 2, 3]
    for u, d, p, q in zip(updates, dofs, pos, quat, strict=True):
        assert np.allclose(u.dofs, d, atol=1e-6) and np.allclose(u.positions, p, atol=1e-6)
        assert np.allclose(np.abs((u.orientations * q).sum(-1)), 1.0, atol=1e-6)


def test_partial_packets_and_entry_order() -> None:
    data = encode_update_packets(
        TINY, [2], np.array([[1.0]]), np.zeros((1, 1, 3)), np.tile([1.0, 0, 0, 0], (1, 1, 1)), entries=[1, 0]
    )
    update, end = decode_update_packet(TINY, data)
    assert end == len(data) and update.entries == (1, 0)
    only_knee = encode_update_packets(
        TINY, [2], np.array([[1.0]]), np.zeros((1, 1, 3)), np.ones((1, 1, 4)), entries=[0]
    )
    update, _ = decode_update_packet(TINY, only_knee)
    assert np.isnan(update.positions).all() and update.dofs.tolist() == [1.0]


@pytest.mark.parametrize(
    ("packet", "code"),
    [
        (struct.pack(">ii2f", 1, 2, 5.0, 0.0), ErrorCode.UNKNOWN_TABLE),  # entry 5 does not exist
        (struct.pack(">ii2f", 1, 2, 0.5, 0.0), ErrorCode.UNKNOWN_TABLE),  # not an integral index
        (struct.pack(">ii4f", 1, 4, 0.0, 1.0, 0.0, 1.0), ErrorCode.UNKNOWN_TABLE),  # entry repeated
        (struct.pack(">ii3f", 1, 3, 1.0, 0.0, 0.0), ErrorCode.MALFORMED_FRAME),  # figure cut short
        (struct.pack(">ii2f", 1, 2, 0.0, math.nan), ErrorCode.BAD_VALUE),
        (struct.pack(">ii", 1, 500), ErrorCode.BAD_VALUE),  # size above a full packet
        (struct.pack(">ii", 1, -1), ErrorCode.BAD_VALUE),
        (struct.pack(">ii1f", 1, 2, 0.0), ErrorCode.TRUNCATED),
    ],
)
def test_bad_update_packets(packet: bytes, code: ErrorCode) -> None:
    with pytest.raises(WireError) as info:
        decode_update_packet(TINY, packet)
    assert info.value.code == code
