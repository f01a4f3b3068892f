"""Fuzz: mutated PDUs, streams, captures and .dislog lines never raise anything but DisError.

`make fuzz` (HYPOTHESIS_PROFILE=fuzz) runs 100,000 mutated PDUs through the codecs; the stream, capture
and .dislog readers get a fifth of that each. In `make test` (profile ci) every test runs 200 examples.
"""

from __future__ import annotations

import base64
import io
import struct

import dpkt
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol.dis import (
    DetonationPdu,
    DisError,
    EntityId,
    EntityStatePdu,
    EntityStateUpdatePdu,
    EntityType,
    FirePdu,
    RemoveEntityPdu,
    VariableParameter,
    decode_entity_state,
    decode_entity_states,
    decode_pdu,
    encode_appearance,
    encode_detonation,
    encode_entity_state,
    encode_entity_update,
    encode_fire,
    encode_pdu,
    encode_remove_entity,
    read_bytes,
)
from protocol.dis.synth import udp_frame

pytestmark = pytest.mark.fuzz
N = settings().max_examples  # the loaded profile's count: 200 (ci) or 100,000 (fuzz)
READER_N = max(N // 5, 200)


def _seeds() -> list[bytes]:
    out = []
    for version in (5, 6, 7):
        for nparams in (0, 1, 3):
            out.append(
                encode_entity_state(
                    EntityStatePdu(
                        entity_id=EntityId(1, 2, 3 + nparams),
                        entity_type=EntityType(3, 1, 225, 1, 27, 0, 0),
                        velocity=(1.0, 2.0, 3.0),
                        location=(1.1e6, -4.8e6, 3.9e6),
                        orientation=(0.1, -0.2, 0.3),
                        appearance=int(encode_appearance(state=3, weapon1=2)),
                        dr_algorithm=4,
                        variable_parameters=tuple(
                            VariableParameter.articulated(4096 + k, k) for k in range(nparams)
                        ),
                        version=version,
                    )
                )
            )
        out.append(encode_fire(FirePdu(shooter=EntityId(1, 1, 1), range=5.0, version=version)))
        out.append(encode_remove_entity(RemoveEntityPdu(EntityId(1, 1, 0), EntityId(1, 2, 4), 9, version)))
        out.append(
            encode_entity_update(
                EntityStateUpdatePdu(
                    entity_id=EntityId(1, 2, 3),
                    velocity=(1.0, 2.0, 3.0),
                    location=(1.1e6, -4.8e6, 3.9e6),
                    appearance=int(encode_appearance(state=5, weapon1=2)),
                    variable_parameters=(VariableParameter.articulated(4096, 0.5),) * (version - 5),
                    version=version,
                )
            )
        )
        out.append(
            encode_detonation(
                DetonationPdu(
                    target=EntityId(1, 1, 2),
                    variable_parameters=(VariableParameter(1, bytes(15)),),
                    version=version,
                )
            )
        )
    return out


SEEDS = _seeds()

# a mutation: overwrite some bytes (biased to the header and counts), then cut or extend
edits = st.lists(
    st.tuples(st.one_of(st.integers(0, 20), st.integers(0, 300)), st.integers(0, 255)), min_size=0, max_size=6
)


@st.composite
def mutated_pdu(draw: st.DrawFn) -> bytes:
    data = bytearray(draw(st.sampled_from(SEEDS)))
    for pos, value in draw(edits):
        if pos < len(data):
            data[pos] = value
    cut = draw(st.one_of(st.none(), st.integers(0, len(data))))
    if cut is not None:
        data = data[:cut]
    data += draw(st.binary(max_size=40)) if draw(st.booleans()) else b""
    return bytes(data)


@settings(max_examples=N)
@given(mutated_pdu())
def test_fuzz_codecs_only_raise_dis_error_and_round_trip(data: bytes) -> None:
    try:
        pdu = decode_pdu(data)
    except DisError as exc:
        assert 0 <= exc.offset <= max(len(data), 200)
    else:
        assert encode_pdu(pdu) == data  # whatever decodes re-encodes byte-exact
    if len(data) >= 144:
        try:
            batch = decode_entity_states(data, [0])
        except DisError:
            with pytest.raises(DisError):
                decode_entity_state(data[: (data[8] << 8) | data[9]])
        else:
            assert len(batch) == 1


@settings(max_examples=READER_N)
@given(st.lists(mutated_pdu(), min_size=1, max_size=6), st.binary(max_size=20))
def test_fuzz_raw_streams_never_raise(pdus: list[bytes], junk: bytes) -> None:
    data = junk.join(pdus)
    log = read_bytes(data, fmt="raw")
    assert len(log.batch) <= len(pdus)
    assert all(isinstance(e, DisError) and 0 <= e.offset <= len(data) for e in log.issues)
    assert log.times.shape == (len(log.batch),)


def _capture() -> bytes:
    f = io.BytesIO()
    w = dpkt.pcap.Writer(f, linktype=dpkt.pcap.DLT_EN10MB)
    for k, pdu in enumerate(SEEDS[:6]):
        w.writepkt(udp_frame(pdu + (SEEDS[-1] if k == 2 else b""), k), ts=10.0 + k)
    return f.getvalue()


CAPTURE = _capture()


@settings(max_examples=READER_N)
@given(
    st.lists(st.tuples(st.integers(0, len(CAPTURE) - 1), st.integers(0, 255)), max_size=8), st.integers(0, 64)
)
def test_fuzz_captures_only_raise_dis_error(flips: list[tuple[int, int]], cut: int) -> None:
    data = bytearray(CAPTURE)
    for pos, value in flips:
        data[pos] = value
    data = data[: len(data) - cut]
    try:
        log = read_bytes(bytes(data))
    except DisError as exc:
        assert exc.offset == 0  # only an unreadable file header is fatal
    else:
        assert len(log.batch) <= 6
        assert all(isinstance(e, DisError) for e in log.issues)


@settings(max_examples=READER_N)
@given(st.lists(mutated_pdu(), min_size=1, max_size=4), st.booleans(), st.text(max_size=12))
def test_fuzz_dislog_lines_never_raise(pdus: list[bytes], plain: bool, noise: str) -> None:
    lines = []
    for k, pdu in enumerate(pdus):
        raw = struct.pack(">q", k * 1_000_000) + pdu
        if plain:
            lines.append(",".join(str(b - 256 if b > 127 else b) for b in raw) + (noise if k == 0 else ""))
        else:
            lines.append(base64.b64encode(raw).decode() + (noise if k == 0 else ""))
    log = read_bytes("\n".join(lines).encode("utf-8", "replace"), fmt="dislog")
    assert len(log.batch) <= len(pdus)
    assert all(isinstance(e, DisError) for e in log.issues)
