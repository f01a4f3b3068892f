"""The IG's Start of Frame (CIGI 3.3, packet 101): its offsets, round trips, a fuzzed decoder, and the host's
listener counting what a fake IG (a UDP socket in the test) sends it."""

from __future__ import annotations

import contextlib
import shutil
import struct
import subprocess
from pathlib import Path

import dpkt
import pytest
import trio
from hypothesis import given
from hypothesis import strategies as st

from client_stub.cigi import listen
from protocol import cigi
from protocol.cigi import CigiError, StartOfFrame, decode_start_of_frame, encode_start_of_frame
from protocol.dis.synth import udp_frame

u8, u32 = (st.integers(0, (1 << n) - 1) for n in (8, 32))
sofs = st.builds(
    StartOfFrame, u32, u32, u32, st.booleans(), st.integers(-128, 127), u8, st.integers(0, 3),
    st.booleans(), st.integers(0, 15),
)  # fmt: skip
orders = st.sampled_from([">", "<"])


def test_field_offsets_of_docs_cigi() -> None:
    sof = StartOfFrame(0x01020304, 0x0A0B0C0D, 0x11223344, True, -2, 9, 2, True)
    b = encode_start_of_frame(sof)
    assert len(b) == cigi.SOF_SIZE == 24 and b[:2] == bytes([101, 24])
    assert b[2] == 3 and struct.unpack_from(">b", b, 3)[0] == -2 and b[4] == 9
    assert b[5] == 2 | 4 | 8 | 3 << 4 and b[6:8] == b"\x80\x00"
    assert b[8:12] == bytes([1, 2, 3, 4]) and b[12:16] == bytes.fromhex("11223344")
    assert b[16:20] == bytes.fromhex("0a0b0c0d") and b[20:24] == bytes(4)
    assert encode_start_of_frame(sof, "<")[6:8] == b"\x00\x80"


@given(sofs, orders, st.binary(max_size=40))
def test_round_trip_in_both_byte_orders(sof: StartOfFrame, order: cigi.Order, tail: bytes) -> None:
    assert decode_start_of_frame(encode_start_of_frame(sof, order) + tail) == sof  # later packets unread


@pytest.mark.parametrize(
    "message",
    [
        b"",
        encode_start_of_frame(StartOfFrame(1))[:23],
        cigi.encode(cigi.IgControl(1)),  # a host message, not the IG's
        bytes([101, 16]) + encode_start_of_frame(StartOfFrame(1))[2:],  # CIGI 3.0's 16-byte size
        encode_start_of_frame(StartOfFrame(1))[:6] + b"\x12\x34" + bytes(16),  # no magic number
        bytes([101, 24, 2]) + encode_start_of_frame(StartOfFrame(1))[3:],  # CIGI 2's major version
    ],
)
def test_malformed_start_of_frame_raises_cigi_error(message: bytes) -> None:
    with pytest.raises(CigiError):
        decode_start_of_frame(message)


def test_out_of_range_fields_are_refused() -> None:
    with pytest.raises(CigiError):
        encode_start_of_frame(StartOfFrame(1 << 32))


@pytest.mark.fuzz
@given(st.binary(max_size=64) | sofs.map(encode_start_of_frame), st.data())
def test_any_bytes_decode_or_raise_cigi_error(message: bytes, data: st.DataObject) -> None:
    if message:
        at = data.draw(st.integers(0, len(message) - 1))
        message = message[:at] + bytes([data.draw(u8)]) + message[at + 1 :]
    with contextlib.suppress(CigiError):
        decode_start_of_frame(message)


def test_counter_keeps_the_newest_frame_and_counts_malformed() -> None:
    counter = listen.SofCounter()
    counter.feed(encode_start_of_frame(StartOfFrame(7, 5)))
    counter.feed(b"junk")
    counter.feed(encode_start_of_frame(StartOfFrame(8, 6, ig_status=3), "<"))
    assert counter.stats() == {
        "sof_received": 2, "sof_malformed": 1, "ig_frame": 8, "ig_last_host_frame": 6, "ig_status": 3,
    }  # fmt: skip


async def test_a_fake_ig_s_start_of_frames_are_counted() -> None:
    counter = listen.SofCounter()
    with (
        trio.socket.socket(type=trio.socket.SOCK_DGRAM) as ear,
        trio.socket.socket(type=trio.socket.SOCK_DGRAM) as ig,
    ):
        await ear.bind(("127.0.0.1", 0))
        async with trio.open_nursery() as nursery:
            nursery.start_soon(listen.receive, ear, counter)
            for frame in range(10):
                await ig.sendto(encode_start_of_frame(StartOfFrame(100 + frame, frame)), ear.getsockname())
            await ig.sendto(b"\x65\x18 not a start of frame", ear.getsockname())
            with trio.fail_after(10):
                while counter.received + counter.malformed < 11:
                    await trio.sleep(0)  # loopback delivery: a few scheduler turns, no wall-clock wait
            nursery.cancel_scope.cancel()
    assert (counter.received, counter.malformed) == (10, 1)
    assert (counter.ig_frame, counter.last_host_frame) == (109, 9)


TSHARK_FIELDS = {  # tshark field -> our attribute
    "cigi.sof.db_number": "database",
    "cigi.sof.ig_status": "ig_status",
    "cigi.sof.ig_mode": "ig_mode",
    "cigi.sof.timestamp_valid": "timestamp_valid",
    "cigi.sof.earth_reference_model": "earth_reference_model",
    "cigi.sof.minor_version": "minor_version",
    "cigi.sof.ig_frame_number": "ig_frame",
    "cigi.sof.timestamp": "timestamp",
    "cigi.sof.last_host_frame_number": "last_host_frame",
}


@pytest.mark.skipif(shutil.which("tshark") is None, reason="tshark (Wireshark) is not installed")
@pytest.mark.parametrize("order", [">", "<"])
def test_wireshark_dissects_our_start_of_frame_field_for_field(order: cigi.Order, tmp_path: Path) -> None:
    sofs = [StartOfFrame(70000 + k, 65000 + k, 123456 * k, k % 2 == 0, k - 2, 3 * k, k % 4, k % 3 == 0)
            for k in range(5)]  # fmt: skip
    pcap = tmp_path / "sof.pcap"
    with pcap.open("wb") as f:
        w = dpkt.pcap.Writer(f, linktype=dpkt.pcap.DLT_EN10MB)
        for k, sof in enumerate(sofs):
            w.writepkt(udp_frame(encode_start_of_frame(sof, order), 0, cigi.HOST_PORT), ts=k / 30.0)
    cmd = ["tshark", "-n", "-r", str(pcap), "-d", f"udp.port=={cigi.HOST_PORT},cigi", "-T", "fields"]
    for name in TSHARK_FIELDS:
        cmd += ["-e", name]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=60, check=True)
    lines = run.stdout.splitlines()
    assert len(lines) == len(sofs)
    for line, sof in zip(lines, sofs, strict=True):
        theirs = [int(v == "True") if v in ("True", "False") else int(v) for v in line.split("\t")]
        assert theirs == [int(getattr(sof, a)) for a in TSHARK_FIELDS.values()]
