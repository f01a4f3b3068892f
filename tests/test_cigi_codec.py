"""CIGI 3.3 packets: the standard's sizes and offsets, round trips in both byte orders, a fuzzed decoder."""

from __future__ import annotations

import contextlib
import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol import cigi
from protocol.cigi import (
    ArticulatedPart,
    CigiError,
    DofSelect,
    EntityControl,
    IgControl,
    PacketId,
    ShortArticulatedPart,
    decode_message,
    encode,
)

u8, u16, u32 = (st.integers(0, (1 << n) - 1) for n in (8, 16, 32))
f32 = st.floats(width=32, allow_nan=False)
f64 = st.floats(allow_nan=False)
ig = st.builds(
    IgControl, u32, u32, st.booleans(), st.integers(-128, 127), st.integers(0, 2), st.booleans(), u32
)
entity = st.builds(
    EntityControl, u16, u16, f64, f64, f64, f32, f32, f32, st.integers(0, 2), st.booleans(), st.booleans(),
    st.booleans(), st.integers(0, 2), u8, u16,
)  # fmt: skip
part = st.builds(ArticulatedPart, u16, u8, st.booleans(), *[st.none() | f32] * 6)
selects = st.sampled_from(list(DofSelect))
short = st.builds(ShortArticulatedPart, u16, u8, u8, selects, selects, f32, f32, st.booleans(), st.booleans())
orders = st.sampled_from([">", "<"])


def test_sizes_are_the_standards() -> None:
    assert cigi.SIZES == {PacketId.IG_CONTROL: 24, PacketId.ENTITY_CONTROL: 48, PacketId.ARTICULATED_PART: 32,
                          PacketId.SHORT_ARTICULATED_PART: 16}  # fmt: skip


def test_field_offsets_of_docs_cigi() -> None:
    """A few offsets docs/CIGI.md quotes from the standard, read back from the bytes."""
    head = encode(IgControl(0x01020304, 0x0A0B0C0D, True, 5, 1, False, 7))
    assert head[:4] == bytes([1, 24, 3, 5]) and head[4] == 0x35 and head[6:8] == b"\x80\x00"
    assert struct.unpack_from(">III", head, 8) == (0x01020304, 0x0A0B0C0D, 7)
    ent = encode(EntityControl(300, 1001, 1.5, -2.5, 3.5, 1.0, 2.0, 3.0))
    assert struct.unpack_from(">H", ent, 2) == (300,) and ent[4] == 1 and ent[6] == 255
    assert struct.unpack_from(">HH3f3d", ent, 8) == (1001, 0, 1.0, 2.0, 3.0, 1.5, -2.5, 3.5)
    art = encode(ArticulatedPart(9, 4, True, z=0.5, yaw=-90.0))
    assert art[4] == 4 and art[5] == 0b1001001 and struct.unpack_from(">6f", art, 8)[2::3] == (0.5, -90.0)
    sh = encode(ShortArticulatedPart(9, 1, 2, DofSelect.ROLL, DofSelect.X_OFFSET, 0.25, 2.0))
    assert sh[4:7] == bytes([1, 2, 6 | 1 << 3 | 0xC0]) and struct.unpack_from(">2f", sh, 8) == (0.25, 2.0)


@given(ig, st.lists(entity | part | short, max_size=20), orders)
def test_round_trip(head: IgControl, packets: list[cigi.Packet], order: cigi.Order) -> None:
    message = b"".join(encode(p, order) for p in [head, *packets])
    assert cigi.byte_order(message) == order
    assert decode_message(message) == ([head, *packets], 0)


def test_unknown_packets_are_skipped_by_size() -> None:
    message = encode(IgControl(1)) + bytes([200, 8]) + bytes(6) + encode(ShortArticulatedPart(
        1, 1, 2, DofSelect.ROLL, DofSelect.ROLL, 0.0, 0.0))  # fmt: skip
    packets, skipped = decode_message(message)
    assert skipped == 1 and len(packets) == 2


@pytest.mark.parametrize(
    "message, why",
    [
        (b"", "starts with"),
        (encode(EntityControl(1, 1, 0, 0, 0)), "starts with"),
        (encode(IgControl(1))[:6] + b"\x12\x34" + bytes(16), "magic"),
        (encode(IgControl(1)) + b"\x02", "cut"),
        (encode(IgControl(1)) + encode(EntityControl(1, 1, 0, 0, 0))[:40], "size 48"),
        (encode(IgControl(1)) + b"\x07\x00", "size 0"),
        (encode(IgControl(1)) + b"\x07\x18" + bytes(22), "not 16"),
    ],
)
def test_malformed_messages_say_why(message: bytes, why: str) -> None:
    with pytest.raises(CigiError, match=why):
        decode_message(message)


def test_out_of_range_fields_are_refused() -> None:
    with pytest.raises(CigiError, match="ArticulatedPart"):
        encode(ArticulatedPart(1, 256))


@pytest.mark.fuzz
@settings(max_examples=max(settings().max_examples, 200))
@given(ig, st.lists(entity | part | short, max_size=6), st.data())
def test_fuzzed_messages_decode_or_say_why(
    head: IgControl, packets: list[cigi.Packet], data: st.DataObject
) -> None:
    """Mutated messages (bytes flipped, cut, grown) give packets or CigiError, nothing else."""
    message = bytearray(b"".join(encode(p) for p in [head, *packets]))
    for _ in range(data.draw(st.integers(1, 4))):
        at = data.draw(st.integers(0, len(message) - 1))
        message[at] = data.draw(u8)
    cut = data.draw(st.integers(0, len(message)))
    tail = data.draw(st.binary(max_size=40))
    try:
        got, _ = decode_message(bytes(message[:cut]) + tail)
    except CigiError:
        return
    assert all(isinstance(p, IgControl | EntityControl | ArticulatedPart | ShortArticulatedPart) for p in got)


@pytest.mark.fuzz
@given(st.binary(max_size=200), orders)
def test_any_bytes_after_an_ig_control_decode_or_say_why(tail: bytes, order: cigi.Order) -> None:
    with contextlib.suppress(CigiError):
        decode_message(encode(IgControl(1), order) + tail)


def test_part_ids_stop_at_255() -> None:
    from protocol.cigi_scene import part_dofs
    from protocol.update_table import DofRange, FigureEntry, JointEntry, UpdateTable

    def table(njoints: int) -> UpdateTable:
        dofs = (DofRange("R", -3.2, 3.2),) * 16
        joints = tuple(JointEntry(f"j{k}", dofs) for k in range(njoints))
        return UpdateTable(1, "X.fig", "Y.fig", (FigureEntry("soldier"), *joints))

    assert [p.part_id for p in part_dofs(table(15))] == list(range(1, 241))
    with pytest.raises(ValueError, match="part IDs stop at 255"):
        part_dofs(table(16))
