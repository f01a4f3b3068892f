"""Logfile readers: pcap, pcapng (written here with dpkt), .dislog (written by hand) and raw PDU streams."""

from __future__ import annotations

import base64
import io
import struct
from pathlib import Path

import dpkt
import numpy as np
import pytest

from protocol.dis import (
    DetonationPdu,
    DisError,
    EntityId,
    EntityStatePdu,
    EntityType,
    FirePdu,
    PduStatus,
    encode_appearance,
    encode_detonation,
    encode_entity_state,
    encode_fire,
    read_bytes,
    read_datagrams,
    read_log,
)
from protocol.dis.logfile import detect_format
from protocol.dis.synth import udp_frame

SOLDIER = EntityType(3, 1, 225, 1, 27, 0, 0)
TANK = EntityType(1, 1, 225, 1, 1, 3, 0)


def espdu(entity: int, etype: EntityType = SOLDIER, version: int = 7, state: int = 1) -> bytes:
    return encode_entity_state(
        EntityStatePdu(
            entity_id=EntityId(1, 1, entity),
            entity_type=etype,
            appearance=int(encode_appearance(state=state, weapon1=2)),
            location=(1.0e6, -4.8e6, 4.0e6),
            version=version,
        )
    )


FIRE = encode_fire(FirePdu(shooter=EntityId(1, 1, 1), target=EntityId(1, 1, 2), range=12.5))
DETONATION = encode_detonation(DetonationPdu(shooter=EntityId(1, 1, 1), target=EntityId(1, 1, 2), result=1))
COMMENT_PDU = bytes([7, 1, 22, 5]) + struct.pack(">IH", 0, 20) + bytes(10)  # a 20-byte "comment" PDU


def ip_udp(payload: bytes, dport: int = 3000, *, frag: bool = False) -> dpkt.ip.IP:
    udp = dpkt.udp.UDP(sport=3000, dport=dport, data=payload)
    udp.ulen = len(udp)
    ip = dpkt.ip.IP(src=b"\x0a\x00\x00\x01", dst=b"\xff\xff\xff\xff", p=17, data=udp)
    if frag:
        ip.mf = 1
    ip.len = len(ip)
    return ip


def eth(ip: dpkt.Packet, ethertype: int = dpkt.ethernet.ETH_TYPE_IP) -> bytes:
    return bytes(dpkt.ethernet.Ethernet(src=b"\x02" * 6, dst=b"\xff" * 6, type=ethertype, data=ip))


def capture_frames() -> list[tuple[float, bytes]]:
    """A little of everything a DIS capture meets, with the expected outcome in comments."""
    tcp_ip = dpkt.ip.IP(src=b"\x0a\0\0\1", dst=b"\x0a\0\0\2", p=6, data=dpkt.tcp.TCP(sport=1, dport=2))
    tcp_ip.len = len(tcp_ip)
    vlan = eth(ip_udp(espdu(5)))
    vlan = vlan[:12] + b"\x81\x00\x00\x05" + vlan[12:]  # one 802.1Q tag
    bundle = espdu(6) + FIRE + bytes(4)  # two PDUs and 8-byte-alignment padding in one datagram
    return [
        (100.0, udp_frame(espdu(1), 0)),  # 1: soldier
        (100.5, udp_frame(espdu(2, TANK), 1)),  # 2: tank: counted, skipped
        (101.0, eth(tcp_ip)),  # 3: TCP
        (101.1, bytes(dpkt.ethernet.Ethernet(type=dpkt.ethernet.ETH_TYPE_ARP, data=b"\0" * 28))),  # 4: ARP
        (101.2, eth(ip_udp(espdu(3), dport=3001))),  # 5: another port
        (101.3, udp_frame(b"hello, not DIS at all", 0)),  # 6: non-DIS datagram
        (101.4, eth(ip_udp(espdu(4), frag=True))),  # 7: an IP fragment
        (101.5, udp_frame(espdu(7)[:100], 0)),  # 8: DIS header, length field says 144: truncated
        (101.6, vlan),  # 9: soldier 5 behind a VLAN tag
        (101.7, udp_frame(bundle, 0)),  # 10: soldier 6 + a fire PDU
        (101.8, udp_frame(DETONATION, 0)),  # 11
        (101.9, udp_frame(COMMENT_PDU, 0)),  # 12: other PDU type
        (102.0, udp_frame(b"\x04" + espdu(8)[1:], 0)),  # 13: DIS 4 entity state: unsupported version
        (102.5, udp_frame(espdu(9, state=5), 0)),  # 14: soldier, prone
    ]


def write_pcap(frames: list[tuple[float, bytes]], nano: bool = False) -> bytes:
    f = io.BytesIO()
    w = dpkt.pcap.Writer(f, linktype=dpkt.pcap.DLT_EN10MB, nano=nano)
    for ts, frame in frames:
        w.writepkt(frame, ts=ts)
    return f.getvalue()


def write_pcapng(frames: list[tuple[float, bytes]]) -> bytes:
    f = io.BytesIO()
    w = dpkt.pcapng.Writer(f, linktype=dpkt.pcap.DLT_EN10MB)
    for ts, frame in frames:
        w.writepkt(frame, ts=ts)
    return f.getvalue()


def check_capture_log(log) -> None:
    c = log.counters
    assert c["records"] == 14
    assert c["non_ip"] == 1 and c["non_udp"] == 1 and c["other_port"] == 1 and c["ip_fragments"] == 1
    assert c["non_dis"] == 1
    assert log.batch.records["entity_id"]["entity"].tolist() == [1, 5, 6, 9]  # lifeforms, file order
    np.testing.assert_allclose(log.times, [100.0, 101.6, 101.7, 102.5])
    assert (c["lifeforms"], c["non_lifeforms"], c["fire"], c["detonation"]) == (4, 1, 1, 1)
    assert c["unsupported_version"] == 1 and c["other_pdus"] == 1
    assert log.pdu_types == {1: 6, 2: 1, 3: 1, 22: 1}  # the truncated one is an issue, not a PDU
    assert [e.kind for e in log.events] == ["fire", "detonation"]
    assert log.events[0].shooter == (1, 1, 1) and log.events[0].target == (1, 1, 2)
    assert log.events[0].t == pytest.approx(101.7) and log.events[0].range == 12.5
    assert len(log.issues) == 1
    err = log.issues[0]
    assert err.record == 8 and err.offset == 42 + 8  # packet 8: Ethernet 14 + IP 20 + UDP 8, length field
    assert "truncated" in str(err)
    assert log.t0 == pytest.approx(100.0) and log.duration == pytest.approx(2.5)
    statuses = log.pdus["status"].tolist()
    assert statuses.count(PduStatus.DECODED) == 4 and statuses.count(PduStatus.NOT_LIFEFORM) == 1
    # the index says where each PDU sits in its packet: the bundled fire PDU starts 144 bytes in
    fire_row = log.pdus[log.pdus["pdu_type"] == 2][0]
    assert (fire_row["record"], fire_row["offset"]) == (10, 42 + 144)


def test_pcap_counts_skips_and_decodes() -> None:
    data = write_pcap(capture_frames())
    assert detect_format(data[:64]) == "pcap"
    check_capture_log(read_bytes(data))


def test_nanosecond_pcap() -> None:
    log = read_bytes(write_pcap(capture_frames(), nano=True))
    check_capture_log(log)


def test_pcapng_same_result(tmp_path: Path) -> None:
    path = tmp_path / "capture.pcapng"
    path.write_bytes(write_pcapng(capture_frames()))
    log = read_log(path)
    assert log.format == "pcapng"
    check_capture_log(log)


def test_any_port_and_other_port() -> None:
    data = write_pcap(capture_frames())
    assert read_bytes(data, port=None).batch.records["entity_id"]["entity"].tolist() == [1, 3, 5, 6, 9]
    log = read_bytes(data, port=3001)
    assert log.batch.records["entity_id"]["entity"].tolist() == [3]
    assert read_bytes(data, lifeforms_only=False).batch.records["entity_id"]["entity"].tolist() == [
        1,
        2,
        5,
        6,
        9,
    ]


def test_other_link_types() -> None:
    pdu = espdu(11)
    raw_ip = bytes(ip_udp(pdu))
    sll = struct.pack(">HHH8sH", 0, 1, 6, b"\x02" * 8, 0x0800) + raw_ip
    null = struct.pack("<I", 2) + raw_ip
    ip6 = dpkt.ip6.IP6(src=b"\0" * 16, dst=b"\xff" * 16, nxt=17, hlim=1)
    udp = dpkt.udp.UDP(sport=3000, dport=3000, data=pdu)
    udp.ulen = len(udp)
    ip6.data, ip6.plen = udp, len(udp)
    for linktype, frame in ((101, raw_ip), (113, sll), (0, null), (101, bytes(ip6))):
        f = io.BytesIO()
        w = dpkt.pcap.Writer(f, linktype=linktype)
        w.writepkt(frame, ts=5.0)
        log = read_bytes(f.getvalue())
        assert log.batch.records["entity_id"]["entity"].tolist() == [11], linktype
    f = io.BytesIO()
    dpkt.pcap.Writer(f, linktype=147).writepkt(b"whatever", ts=1.0)  # a user link type: skipped with a note
    log = read_bytes(f.getvalue())
    assert len(log.batch) == 0 and log.counters["non_ip"] == 1 and "link type" in str(log.issues[0])


def test_damaged_captures_are_reported_not_raised() -> None:
    data = write_pcap(capture_frames())
    cut = read_bytes(data[:-30])  # the last record is cut short
    assert cut.batch.records["entity_id"]["entity"].tolist()[:3] == [1, 5, 6]
    assert cut.counters["records"] == 14  # dpkt hands over the short record
    assert any(e.record == 14 for e in cut.issues)
    header_only = read_bytes(data[:30])  # a record header cut in two
    assert len(header_only.batch) == 0 and header_only.issues and header_only.issues[0].record == 1
    with pytest.raises(DisError) as info:
        read_bytes(b"\xa1\xb2\xc3\xd4" + bytes(4), fmt="pcap")
    assert info.value.offset == 0
    with pytest.raises(DisError):
        read_bytes(b"x", fmt="nonsense")


# --- .dislog ----------------------------------------------------------------------------------------------


def signed(data: bytes) -> str:
    return ",".join(str(b - 256 if b > 127 else b) for b in data)


def dislog_pdus() -> list[tuple[int, bytes]]:
    return [
        (0, espdu(1)),
        (1_500_000_000, FIRE),
        (2_000_000_000, espdu(2, TANK)),
        (3_250_000_000, espdu(3, state=4)),
    ]


def test_dislog_plaintext(tmp_path: Path) -> None:
    lines = ["# Start, ENCODING_PLAINTEXT, [PduRecorder] 20220620_093604, DIS capture file, x.dislog"]
    lines.append("# DisPduType,ReceiptDate,ReceiptTime")
    for ns, pdu in dislog_pdus():
        lines.append(f"{signed(struct.pack('>q', ns))},{signed(pdu)} # DisPduType {pdu[2]:02d}")
    lines.append("[0,0,0,0,-1,0,0,0],[" + signed(espdu(4)) + "]")  # the older bracketed form
    lines.append("0,0,0,0,0,0,0,0,7,1,nonsense")  # a damaged line
    lines.append("# Finish, ENCODING_PLAINTEXT, 20220620_093613")
    path = tmp_path / "capture.dislog"
    path.write_text("\n".join(lines) + "\n")
    log = read_log(path)
    assert log.format == "dislog"
    assert log.batch.records["entity_id"]["entity"].tolist() == [1, 3, 4]
    np.testing.assert_allclose(log.times, [0.0, 3.25, 0x00000000FF000000 * 1e-9])
    assert log.counters["non_lifeforms"] == 1 and len(log.events) == 1 and log.events[0].t == 1.5
    assert len(log.issues) == 1 and log.issues[0].record == 8
    assert log.counters["comment_lines"] == 3


def test_dislog_base64_one_and_two_blocks() -> None:
    lines = ["# Start, ENCODING_BASE64, x"]
    for k, (ns, pdu) in enumerate(dislog_pdus()):
        t = struct.pack(">q", ns)
        if k % 2:
            lines.append(base64.b64encode(t).decode() + "," + base64.b64encode(pdu).decode())
        else:
            lines.append(base64.b64encode(t + pdu).decode())
    lines.append("!!!not base64!!!")
    log = read_bytes("\n".join(lines).encode(), name="x.dislog")
    assert log.batch.records["entity_id"]["entity"].tolist() == [1, 3]
    np.testing.assert_allclose(log.times, [0.0, 3.25])
    assert [e.t for e in log.events] == [1.5]
    assert len(log.issues) == 1 and log.issues[0].record == 6
    # without a header the encoding is sniffed per line, and the format from the content
    sniffed = read_bytes("\n".join(lines[1:]).encode())
    assert sniffed.format == "dislog" and len(sniffed.batch) == 2


def test_dislog_corrupt_pdu_offsets_are_line_relative() -> None:
    bad = bytearray(espdu(1))
    bad[19] = 3  # claims three variable parameters
    text = base64.b64encode(struct.pack(">q", 5) + bytes(bad)).decode()
    log = read_bytes(("# ENCODING_BASE64\n" + text + "\n").encode())
    assert len(log.batch) == 0
    assert (log.issues[0].record, log.issues[0].offset) == (2, 19)


# --- raw streams ------------------------------------------------------------------------------------------


def test_raw_stream_resyncs_after_corruption() -> None:
    a, b, c = espdu(1), FIRE, espdu(2, state=6)
    garbage = b"\x00\xff\x13\x37\x42"
    data = a + b + garbage + c + a[:60]
    log = read_bytes(data, fmt="raw")
    assert log.batch.records["entity_id"]["entity"].tolist() == [1, 2]
    assert len(log.events) == 1
    offsets = [e.offset for e in log.issues]
    assert offsets[0] == len(a) + len(b)  # where the garbage starts
    assert len(log.issues) == 2 and "60" in str(log.issues[1])  # the trailing half PDU
    assert log.pdus["offset"].tolist() == [0, len(a), len(a) + len(b) + len(garbage)]


def test_raw_stream_of_many_equal_pdus_and_mixed_lengths() -> None:
    pdus = [espdu(i % 50) for i in range(3000)]
    pdus[1000:1000] = [FIRE, DETONATION, COMMENT_PDU] * 5
    log = read_bytes(b"".join(pdus), fmt="raw")
    assert len(log.batch) == 3000 and len(log.events) == 10 and log.counters["other_pdus"] == 5
    assert log.issues == []
    ids = log.batch.records["entity_id"]["entity"]
    assert ids.tolist() == [i % 50 for i in range(3000)]


def test_raw_times_come_from_dis_timestamps() -> None:
    pdus = []
    for k, past_hour in enumerate((3590.0, 3599.5, 2.0)):
        pdus.append(
            encode_entity_state(
                EntityStatePdu(
                    entity_id=EntityId(1, 1, k),
                    entity_type=SOLDIER,
                    timestamp=int(past_hour / 3600 * 2**31) << 1,
                )
            )
        )
    log = read_bytes(b"".join(pdus), fmt="raw")
    np.testing.assert_allclose(log.times, [3590.0, 3599.5, 3602.0], atol=1e-5)


def test_a_live_burst_of_datagrams() -> None:
    burst = [espdu(1), espdu(2, TANK), espdu(3) + FIRE, b"not DIS", espdu(4)[:90]]
    log = read_datagrams(burst, 42.0)
    assert log.batch.records["entity_id"]["entity"].tolist() == [1, 3]  # lifeforms, arrival order
    np.testing.assert_allclose(log.times, [42.0, 42.0])
    assert [e.kind for e in log.events] == ["fire"] and log.events[0].t == 42.0
    assert log.counters["non_lifeforms"] == 1 and log.counters["non_dis"] == 1
    assert len(log.issues) == 1 and log.issues[0].record == 5  # datagrams are numbered from 1
    assert len(read_datagrams([], 0.0).batch) == 0


def test_empty_inputs() -> None:
    for fmt in ("raw", "dislog"):
        log = read_bytes(b"", fmt=fmt)
        assert len(log.batch) == 0 and log.issues == [] and log.duration == 0.0
    log = read_bytes(write_pcap([]))
    assert len(log.batch) == 0 and log.counters["records"] == 0


def test_real_samples_as_a_raw_stream_and_a_capture() -> None:
    shared = Path(__file__).resolve().parents[1].parent / "shared" / "dis-samples"
    names = ["001_entity_state.DI_AK74", "001_entity_state.M1A2", "002_fire.M799", "003_detonation.M799",
             "EntityStatePdu-26.raw"]  # fmt: skip
    if not all((shared / n).exists() for n in names):
        pytest.skip(f"{shared} not present")
    pdus = [(shared / n).read_bytes() for n in names]
    for log in (
        read_bytes(b"".join(pdus), fmt="raw"),
        read_bytes(write_pcap([(1.0 + k, udp_frame(p, k)) for k, p in enumerate(pdus)])),
    ):
        assert log.batch.records["entity_id"].tolist() == [(50, 126, 28)]  # only the dismounted soldier
        assert log.counters["non_lifeforms"] == 2 and log.issues == []
        assert [(e.kind, tuple(e.shooter), tuple(e.target)) for e in log.events] == [
            ("fire", (50, 126, 5), (50, 126, 27)),
            ("detonation", (50, 126, 5), (50, 126, 27)),
        ]
        assert log.batch.params["parameter_type"].tolist()[:2] == [0x114D, 0x114E]


def test_pdu_decoders_are_a_read_only_registry_yielding_typed_events() -> None:
    from protocol.dis.decoders import DECODERS, Corrupt, EntityStates, Event, PduRows
    from protocol.dis.pdu import PduType

    assert set(DECODERS) == {
        PduType.ENTITY_STATE,
        PduType.FIRE,
        PduType.DETONATION,
        PduType.REMOVE_ENTITY,
        PduType.ENTITY_STATE_UPDATE,
    }
    with pytest.raises(TypeError):
        DECODERS[99] = DECODERS[PduType.FIRE]  # type: ignore[index]
    data = espdu(1) + espdu(2, TANK) + espdu(3)[:100]
    u8 = np.frombuffer(data, np.uint8)
    offsets = np.array([0, 144, 288], np.int64)
    rows = PduRows(
        data, u8, np.arange(3), offsets, np.array([144, 144, 100]), np.zeros(3, np.int64),
        u8[offsets], np.zeros(3), True,
    )  # fmt: skip
    out = list(DECODERS[PduType.ENTITY_STATE](rows))
    corrupt = [e for e in out if isinstance(e, Corrupt)]
    (states,) = [e for e in out if isinstance(e, EntityStates)]
    assert [c.row for c in corrupt] == [2]
    assert states.rows.tolist() == [0] and states.skipped.tolist() == [1]
    assert (states.lifeforms, states.non_lifeforms, len(states.batch)) == (1, 1, 1)
    one = np.zeros(1, np.int64)
    fire = DECODERS[PduType.FIRE](
        PduRows(FIRE, np.frombuffer(FIRE, np.uint8), np.array([7]), one, np.array([len(FIRE)]), one,
                np.array([FIRE[0]], np.uint8), np.array([3.0]), True)
    )  # fmt: skip
    (event,) = fire
    assert isinstance(event, Event) and event.row == 7
    assert event.event.kind == "fire" and event.event.t == 3.0
