"""Entity State / Fire / Detonation codecs: golden bytes, versions 5/6/7, batch = scalar, bad input."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from protocol.dis import (
    DetonationPdu,
    DisError,
    EntityId,
    EntityStatePdu,
    EntityType,
    FirePdu,
    VariableParameter,
    decode_entity_state,
    decode_entity_states,
    decode_pdu,
    encode_entity_state,
    encode_entity_states,
    encode_pdu,
    make_marking,
)
from protocol.dis.batch import EntityStateBatch, batch_from_pdus, pdu_from_row
from protocol.dis.pdu import encode_timestamp, timestamp_seconds, unwrap_timestamps
from protocol.dis.warfare import MunitionDescriptor

SAMPLES = Path(__file__).resolve().parents[1].parent / "shared" / "dis-samples"


def sample(name: str) -> bytes:
    path = SAMPLES / name
    if not path.exists():
        pytest.skip(f"{path} not present")
    return path.read_bytes()


def golden_pdu(version: int) -> EntityStatePdu:
    return EntityStatePdu(
        entity_id=EntityId(1, 2, 3),
        force_id=1,
        entity_type=EntityType(3, 1, 225, 1, 27, 0, 0),
        alt_entity_type=EntityType(3, 1, 225, 1, 27, 0, 0),
        velocity=(1.0, -2.0, 0.5),
        location=(1.0, 2.0, -1.5),
        orientation=(0.25, 0.0, -0.5),
        appearance=0x02010000,
        dr_algorithm=2,
        acceleration=(0.0, 0.0, 0.0),
        angular_velocity=(0.0, 0.0, 0.25),
        marking=make_marking("ABC"),
        capabilities=0,
        variable_parameters=(VariableParameter.articulated(0x114D, 0.5, change=1, attached_to=0),),
        version=version,
        exercise=3,
        timestamp=0x01020304,
        pdu_status=0x10 if version == 7 else 0,
    )


def golden_bytes(version: int) -> bytes:
    """Hand-assembled: every field written out in hex, independent of the codec's struct formats."""
    status = "1000" if version == 7 else "0000"  # DIS 7: pdu status + padding; DIS 5/6: 16-bit padding
    hexes = [
        f"{version:02x}",
        "03",
        "01",
        "01",
        "01020304",
        "00a0",
        status,  # header: length 160 = 144 + 16
        "0001",
        "0002",
        "0003",
        "01",
        "01",  # entity id, force, one variable parameter
        "03",
        "01",
        "00e1",
        "01",
        "1b",
        "00",
        "00",  # entity type 3.1.225.1.27.0.0
        "03",
        "01",
        "00e1",
        "01",
        "1b",
        "00",
        "00",  # alternative entity type
        "3f800000",
        "c0000000",
        "3f000000",  # velocity 1, -2, 0.5 (f32)
        "3ff0000000000000",
        "4000000000000000",
        "bff8000000000000",  # location 1, 2, -1.5 (f64)
        "3e800000",
        "00000000",
        "bf000000",  # orientation 0.25, 0, -0.5
        "02010000",  # appearance
        "02",
        "00" * 15,  # dead reckoning algorithm 2 + 15 other bytes
        "00000000" * 3,  # linear acceleration
        "00000000",
        "00000000",
        "3e800000",  # angular velocity 0, 0, 0.25
        "01",
        "414243" + "00" * 8,  # marking: ASCII "ABC"
        "00000000",  # capabilities
        "00",
        "01",
        "0000",
        "0000114d",
        "3f000000",
        "00000000",  # articulated part 0x114D = 0.5, changed once
    ]
    return bytes.fromhex("".join(hexes))


@pytest.mark.parametrize("version", [5, 6, 7])
def test_golden_bytes_each_version(version: int) -> None:
    pdu = golden_pdu(version)
    data = encode_entity_state(pdu)
    assert data == golden_bytes(version)
    assert len(data) == 160 == pdu.length
    assert decode_entity_state(data) == pdu
    # bytes 10-11 are where the versions differ
    assert data[10:12] == (b"\x10\x00" if version == 7 else b"\x00\x00")


def test_dis7_pdu_status_and_dis6_padding_survive_round_trip() -> None:
    data = bytearray(golden_bytes(6))
    data[10:12] = b"\xab\xcd"  # odd padding in the wild is kept byte-exact
    pdu = decode_entity_state(bytes(data))
    assert (pdu.pdu_status, pdu.padding) == (0xAB, 0xCD)
    assert encode_entity_state(pdu) == bytes(data)


def test_variable_parameter_fields() -> None:
    vp = decode_entity_state(golden_bytes(7)).variable_parameters[0]
    assert (vp.record_type, vp.change, vp.attached_to, vp.parameter_type, vp.value) == (0, 1, 0, 0x114D, 0.5)


def test_batch_decode_matches_scalar_decode_for_mixed_versions_and_lengths() -> None:
    pdus = [golden_pdu(v) for v in (5, 6, 7)]
    pdus.append(EntityStatePdu(entity_id=EntityId(9, 9, 9), version=7, marking=make_marking("X")))
    pdus.append(
        EntityStatePdu(
            entity_id=EntityId(4, 5, 6),
            variable_parameters=tuple(VariableParameter.articulated(4096 + k, k / 4) for k in range(3)),
        )
    )
    data = b"".join(encode_entity_state(p) for p in pdus)
    offsets = np.cumsum([0] + [p.length for p in pdus[:-1]])
    batch = decode_entity_states(data, offsets)
    assert len(batch) == 5
    assert [pdu_from_row(batch, i) for i in range(5)] == pdus
    assert batch.records["num_params"].tolist() == [1, 1, 1, 0, 3]
    assert batch.params["parameter_type"].tolist() == [0x114D] * 3 + [4096, 4097, 4098]
    assert encode_entity_states(batch) == data
    assert encode_entity_states(batch_from_pdus(pdus)) == data


def test_batch_fast_path_for_back_to_back_fixed_size_pdus() -> None:
    pdus = [EntityStatePdu(entity_id=EntityId(1, 1, i), appearance=i) for i in range(50)]
    data = b"".join(encode_entity_state(p) for p in pdus)
    batch = decode_entity_states(data)  # no offsets: one PDU every 144 bytes
    assert batch.records["entity_id"]["entity"].tolist() == list(range(50))
    assert batch.records["appearance"].tolist() == list(range(50))


def test_batch_select_keeps_variable_parameters_with_their_pdus() -> None:
    pdus = [
        EntityStatePdu(
            entity_id=EntityId(1, 1, i),
            variable_parameters=tuple(VariableParameter.articulated(i, k) for k in range(i)),
        )
        for i in range(5)
    ]
    batch = batch_from_pdus(pdus)
    sub = batch.select(np.array([False, True, False, True, True]))
    assert [pdu_from_row(sub, i) for i in range(3)] == [pdus[1], pdus[3], pdus[4]]
    both = EntityStateBatch.concatenate([sub, batch.select([0, 2])])
    assert [pdu_from_row(both, i).entity_id.entity for i in range(5)] == [1, 3, 4, 0, 2]
    assert both.params_of(4)["parameter_type"].tolist() == [2, 2]


@pytest.mark.parametrize(
    ("mutate", "offset", "words"),
    [
        (lambda d: d[:100], 8, "length field"),  # truncated: length says 160
        (lambda d: d + b"\0" * 16, 8, "length field"),  # extra bytes
        (lambda d: d[:19] + b"\x02" + d[20:], 19, "variable parameters"),  # N disagrees with length
        (lambda d: b"\x04" + d[1:], 0, "version"),
        (lambda d: d[:2] + b"\x02" + d[3:], 2, "not Entity State"),
        (lambda d: d[:8] + b"\x00\x80" + d[10:128], 8, "shorter than 144"),
        (lambda d: d[:5], 5, "truncated header"),
    ],
)
def test_bad_entity_state_raises_dis_error_with_offset(mutate, offset: int, words: str) -> None:
    with pytest.raises(DisError) as info:
        decode_entity_state(mutate(golden_bytes(7)))
    assert info.value.offset == offset
    assert words in str(info.value)
    assert isinstance(info.value, ValueError)


def test_batch_decode_reports_absolute_offset_of_bad_pdu() -> None:
    good = golden_bytes(7)
    bad = bytearray(good)
    bad[19] = 5  # wrong record count
    with pytest.raises(DisError) as info:
        decode_entity_states(good + bytes(bad), [0, 160])
    assert info.value.offset == 160 + 19


@pytest.mark.parametrize(
    "pdu",
    [
        EntityStatePdu(version=4),
        EntityStatePdu(force_id=256),
        EntityStatePdu(marking=b"x" * 12),
        EntityStatePdu(dr_other=b"\0"),
        EntityStatePdu(location=("a", 0.0, 0.0)),  # type: ignore[arg-type]
        EntityStatePdu(entity_id=EntityId(70000, 0, 0)),
    ],
)
def test_unencodable_values_raise_dis_error(pdu: EntityStatePdu) -> None:
    with pytest.raises(DisError):
        encode_entity_state(pdu)


def test_make_marking() -> None:
    assert make_marking("RM/A/SQD4") == b"RM/A/SQD4\0\0"
    assert EntityStatePdu(marking=make_marking("26")).marking_text == "26"
    with pytest.raises(DisError):
        make_marking("twelve chars")
    with pytest.raises(DisError):
        make_marking("€")


def test_fire_and_detonation_golden_round_trip() -> None:
    fire = FirePdu(
        shooter=EntityId(1, 1, 1),
        target=EntityId(1, 2, 2),
        event_id=EntityId(1, 1, 7),
        location=(1.0, 2.0, 3.0),
        descriptor=MunitionDescriptor(EntityType(2, 8, 225, 2, 1, 0, 0), quantity=3, rate=600),
        velocity=(0.0, 900.0, 0.0),
        range=50.0,
        version=6,
    )
    data = encode_pdu(fire)
    assert len(data) == 96 and data[2] == 2 and data[3] == 2 and data[8:10] == b"\x00\x60"
    assert data[12:18] == bytes.fromhex("000100010001") and data[18:24] == bytes.fromhex("000100020002")
    assert data[92:96] == struct.pack(">f", 50.0)
    assert decode_pdu(data) == fire
    det = DetonationPdu(
        shooter=EntityId(1, 1, 1),
        target=EntityId(1, 2, 2),
        location=(4.0, 5.0, 6.0),
        result=1,
        variable_parameters=(VariableParameter.articulated(1, 2.0),),
    )
    data = encode_pdu(det)
    assert len(data) == 120 and data[100] == 1 and data[101] == 1
    assert decode_pdu(data) == det
    with pytest.raises(DisError) as info:
        decode_pdu(data[:110])
    assert info.value.offset == 8


def test_decode_pdu_rejects_other_types() -> None:
    with pytest.raises(DisError) as info:
        decode_pdu(bytes([7, 1, 22, 5]) + bytes(8))
    assert info.value.offset == 2 and "comment" in str(info.value)


def test_timestamps() -> None:
    ts = encode_timestamp(1800.0, absolute=True)
    assert ts & 1 == 1
    assert timestamp_seconds(ts) == pytest.approx(1800.0, abs=1e-5)
    assert encode_timestamp(3600.0 + 12.5) == encode_timestamp(12.5)
    assert unwrap_timestamps([3590.0, 3599.0, 5.0, 10.0]).tolist() == [3590.0, 3599.0, 3605.0, 3610.0]


# --- the real samples (skipped when ../shared/dis-samples is absent) -----------------------------------


def test_sample_dismounted_ak74_decodes_to_readme_values() -> None:
    data = sample("001_entity_state.DI_AK74")
    pdu = decode_entity_state(data)
    assert pdu.version == 7 and len(data) == 192 == pdu.length
    assert pdu.entity_id == (50, 126, 28)
    assert pdu.force_id == 2
    assert pdu.entity_type == (3, 1, 222, 1, 206, 1, 0)
    assert pdu.appearance == 0x02010000
    assert pdu.dr_algorithm == 1
    assert (pdu.marking_charset, pdu.marking_text) == (1, "RM/A/SQD4")
    vps = pdu.variable_parameters
    assert [v.record_type for v in vps] == [0, 0, 30]
    assert [v.parameter_type for v in vps[:2]] == [0x114D, 0x114E]
    assert encode_entity_state(pdu) == data
    batch = decode_entity_states(data, [0])
    assert pdu_from_row(batch, 0) == pdu


def test_sample_m1a2_tank_and_dis6_platform() -> None:
    tank = decode_entity_state(sample("001_entity_state.M1A2"))
    assert tank.entity_type.kind == 1 and len(tank.variable_parameters) == 7
    assert tank.marking_text == "WM/1/M1A2"
    raw26 = sample("EntityStatePdu-26.raw")
    p26 = decode_entity_state(raw26)
    assert (p26.version, p26.dr_algorithm, p26.marking_text, p26.length) == (6, 2, "26", 144)
    assert encode_entity_state(p26) == raw26


def test_sample_fire_and_detonation() -> None:
    fire = decode_pdu(sample("002_fire.M799"))
    det = decode_pdu(sample("003_detonation.M799"))
    assert isinstance(fire, FirePdu) and isinstance(det, DetonationPdu)
    assert fire.shooter == (50, 126, 5) and fire.target == (50, 126, 27)
    assert det.shooter == fire.shooter and det.target == fire.target and det.event_id == fire.event_id
    assert det.result == 1  # entity impact
    assert fire.descriptor.munition.kind == 2
    assert encode_pdu(fire) == sample("002_fire.M799")
    assert encode_pdu(det) == sample("003_detonation.M799")
