"""Joint updates: quantisation, bit packing, per-client delta state, sizes, atomic rejection of bad frames."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from protocol.bitpack import bit_starts, pack_bits, set_rows, take_rows, unpack_bits
from protocol.errors import ErrorCode, WireError
from protocol.events import JointUpdates
from protocol.update_table import (
    DofRange,
    FigureEntry,
    JointEntry,
    UpdateTable,
    example_di_table,
    table_from_wire,
    table_to_wire,
)
from protocol.updates import UpdateDecoder, UpdateEncoder, dequantise, quantise

BIG = 1 << 20
DI = example_di_table()


def poses(table: UpdateTable, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Random in-range poses: DOFs inside [lo, hi - step], positions within a metre, unit quaternions."""
    rng = np.random.default_rng(seed)
    lay = table.layout
    lo, hi = (
        lay.lo[lay.dof_fields],
        lay.lo[lay.dof_fields] + lay.step[lay.dof_fields] * ((1 << lay.width[lay.dof_fields]) - 1),
    )
    dofs = rng.uniform(lo, hi, (n, len(lo)))
    g = table.nfigures
    pos = rng.uniform(-1.0, 1.0, (n, g, 3))
    quat = rng.normal(size=(n, g, 4))
    quat /= np.linalg.norm(quat, axis=-1, keepdims=True)
    return dofs, pos, quat


def upd(
    table: UpdateTable,
    idx: np.ndarray | list[int],
    d: np.ndarray,
    p: np.ndarray,
    q: np.ndarray,
    tick: int = 0,
):
    return JointUpdates(table.table_id, np.asarray(idx), d, p, q, tick)


def angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.degrees(2 * np.arccos(np.clip(np.abs((a * b).sum(-1)), 0.0, 1.0)))


# -- bit packing --------------------------------------------------------------------------------------------


@given(st.lists(st.integers(1, 24), max_size=200), st.randoms(use_true_random=False))
def test_pack_bits_matches_a_bit_string_reference(widths: list[int], rnd) -> None:
    values = [rnd.randrange(1 << w) for w in widths]
    packed = pack_bits(np.array(values, np.int64), np.array(widths, np.int64))
    ref = "".join(format(v, f"0{w}b") for v, w in zip(values, widths, strict=True))
    ref += "0" * (-len(ref) % 8)
    assert packed == (int(ref, 2).to_bytes(len(ref) // 8, "big") if ref else b"")
    starts, total = bit_starts(np.array(widths, np.int64))
    assert total == sum(widths)
    assert unpack_bits(packed, starts, np.array(widths, np.int64)).tolist() == values


# -- quantisation -------------------------------------------------------------------------------------------


def test_resolution_of_the_default_fields() -> None:
    dof = DofRange("R", -math.pi, math.pi)
    assert math.degrees(dof.step) == pytest.approx(360 / 4096)  # 0.088° step, 0.044° worst error
    d, p, q = poses(DI, 5000)
    d2, p2, q2 = dequantise(DI, quantise(DI, d, p, q))
    lay = DI.layout
    assert (np.abs(d2 - d) <= lay.step[lay.dof_fields] / 2 + 1e-12).all()
    assert np.abs(p2 - p).max() <= 0.0005 + 1e-12  # 1 mm step
    assert angle_deg(q2, q).max() < 0.06  # smallest-three, 12 bits per component


def test_zero_and_identity_are_exact() -> None:
    d, p, q = np.zeros((1, 50)), np.zeros((1, 2, 3)), np.tile([1.0, 0, 0, 0], (1, 2, 1))
    d2, p2, q2 = dequantise(DI, quantise(DI, d, p, q))
    assert (d2 == 0).all() and (p2 == 0).all() and (q2 == q).all()


def test_quaternion_sign_and_largest_component_do_not_matter() -> None:
    t = UpdateTable(1, "f", "", (FigureEntry("f"),))
    q = np.array([[[0.1, -0.9, 0.3, 0.2]], [[-0.1, 0.9, -0.3, -0.2]], [[0.0, 0.0, 0.0, 2.0]]])
    _, _, out = dequantise(t, quantise(t, np.zeros((3, 0)), np.zeros((3, 1, 3)), q))
    assert angle_deg(out[0], q[0] / np.linalg.norm(q[0])).max() < 0.06
    assert np.allclose(out[0], out[1])
    assert np.allclose(out[2], [[0, 0, 0, 1]])


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_non_finite_poses_are_refused(bad: float) -> None:
    d, p, q = poses(DI, 3)
    d[1, 7] = bad
    with pytest.raises(ValueError, match="row 1"):
        quantise(DI, d, p, q)
    with pytest.raises(ValueError, match="zero quaternion"):
        quantise(DI, *poses(DI, 1)[:2], np.zeros((1, 2, 4)))


def test_table_wire_form_round_trips() -> None:
    assert table_from_wire(table_to_wire(DI)) == DI


# -- encoder / decoder --------------------------------------------------------------------------------------


def test_full_di_soldier_update_is_at_most_110_bytes() -> None:
    enc = UpdateEncoder(DI)
    d, p, q = poses(DI, 1000)
    (payload,) = enc.encode(upd(DI, np.arange(1000), d, p, q), BIG)
    per_soldier = (len(payload) - 8) / 1000  # minus the 8-byte batch header
    assert per_soldier <= 110
    assert DI.full_update_bits() == 50 * 12 + 2 * (3 * 16 + 2 + 3 * 12)


def test_idle_soldiers_cost_nothing_and_moving_ones_little() -> None:
    enc, dec = UpdateEncoder(DI), UpdateDecoder(DI)
    n = 200
    d, p, q = poses(DI, n, seed=3)
    for payload in enc.encode(upd(DI, np.arange(n), d, p, q), BIG):
        dec.decode(payload)
    assert enc.encode(upd(DI, np.arange(n), d, p, q), BIG) == []  # nobody moved: no frame at all
    moving = np.arange(n) % 10 < 7
    rng = np.random.default_rng(4)
    d2 = d + moving[:, None] * rng.normal(0, 0.003, d.shape)  # ~0.2° per tick
    d2 = np.clip(d2, DI.layout.lo[DI.layout.dof_fields], None)
    payloads = enc.encode(upd(DI, np.arange(n), d2, p, q, tick=2), BIG)
    ev = dec.decode(payloads[0])
    assert ev.indices.tolist() == np.flatnonzero(moving).tolist()
    assert (len(payloads[0]) - 8) / moving.sum() < 60  # deltas of a few bits instead of 12
    assert np.array_equal(dec.codes(np.arange(n)), quantise(DI, d2, p, q))


@st.composite
def small_tables(draw: st.DrawFn) -> UpdateTable:
    entries = []
    for i in range(draw(st.integers(1, 5))):
        if draw(st.booleans()):
            n = draw(st.integers(1, 3))
            entries.append(
                JointEntry(
                    f"j{i}", tuple(DofRange("R", -1.0, 1.0, draw(st.integers(1, 16))) for _ in range(n))
                )
            )
        else:
            entries.append(
                FigureEntry(f"f{i}", -2.0, 2.0, draw(st.integers(1, 24)), draw(st.integers(2, 16)))
            )
    return UpdateTable(3, "x.fig", "", tuple(entries))


@given(
    small_tables(),
    st.lists(st.tuples(st.integers(0, 15), st.floats(0, 0.3)), min_size=1, max_size=6),
    st.integers(0, 2**31),
    st.sampled_from([1, 2]),
)
def test_decoder_reconstructs_the_encoders_quantised_values_exactly(
    table: UpdateTable, ticks: list[tuple[int, float]], seed: int, version: int
) -> None:
    """Whatever mix of absolute and delta modes the encoder picks, both sides hold identical values."""
    rng = np.random.default_rng(seed)
    enc, dec = UpdateEncoder(table, 16, version=version), UpdateDecoder(table, 16, version=version)
    d, p, q = poses(table, 16, seed)
    for step, (nmove, scale) in enumerate(ticks):
        who = rng.permutation(16)[:nmove]
        d[who] = np.clip(d[who] + rng.normal(0, scale, d[who].shape), -1.0, 0.99)
        p[who] = np.clip(p[who] + rng.normal(0, scale, p[who].shape), -2.0, 1.9)
        q[who] = q[who] + rng.normal(0, scale, q[who].shape)
        sent = rng.permutation(16)[: rng.integers(1, 17)]
        for payload in enc.encode(upd(table, sent, d[sent], p[sent], q[sent], step), max_payload=300):
            assert len(payload) <= 300
            dec.decode(payload)
        known = np.flatnonzero(dec.known(np.arange(16)))
        assert np.array_equal(dec.codes(known), enc.codes(known))
        assert np.array_equal(dec.codes(sent), quantise(table, d[sent], p[sent], q[sent]))


def test_full_update_after_reset_subscription_or_request() -> None:
    enc, dec = UpdateEncoder(DI), UpdateDecoder(DI)
    d, p, q = poses(DI, 4)
    for payload in enc.encode(upd(DI, range(4), d, p, q), BIG):
        dec.decode(payload)
    enc.reset([2])
    (payload,) = enc.encode(upd(DI, range(4), d, p, q), BIG)
    ev = dec.decode(payload)
    assert ev.indices.tolist() == [2] and ev.changed.all()
    # a fresh decoder (a new client) cannot take deltas: the first update of a soldier must be full
    d[1, 0] += 0.01
    (payload,) = enc.encode(upd(DI, range(4), d, p, q), BIG)
    with pytest.raises(WireError) as info:
        UpdateDecoder(DI).decode(payload)
    assert info.value.code == ErrorCode.BAD_UPDATE


def test_batches_split_into_frames_under_max_payload() -> None:
    enc, dec = UpdateEncoder(DI), UpdateDecoder(DI)
    d, p, q = poses(DI, 500)
    payloads = enc.encode(upd(DI, np.arange(500), d, p, q), 4096)
    assert len(payloads) > 10 and all(len(x) <= 4096 for x in payloads)
    got = np.concatenate([dec.decode(x).indices for x in payloads])
    assert got.tolist() == list(range(500))
    with pytest.raises(ValueError, match="cannot hold"):
        UpdateEncoder(DI).encode(upd(DI, [0], d[:1], p[:1], q[:1]), 64)


def test_encoder_refuses_duplicates_and_out_of_range_indices() -> None:
    enc = UpdateEncoder(DI, 8)
    d, p, q = poses(DI, 2)
    with pytest.raises(ValueError, match="duplicate"):
        enc.encode(upd(DI, [3, 3], d, p, q), BIG)
    with pytest.raises(ValueError, match="outside"):
        enc.encode(upd(DI, [3, 8], d, p, q), BIG)


def _one_full(n: int = 3) -> tuple[bytes, UpdateDecoder]:
    """A full update of 3 soldiers: 8-byte header, indices at 8..13, header bits at 14.., 4 padding bits."""
    enc = UpdateEncoder(DI)
    (payload,) = enc.encode(upd(DI, np.arange(n), *poses(DI, n)), BIG)
    return payload, UpdateDecoder(DI)


@pytest.mark.parametrize(
    ("mutate", "code"),
    [
        (lambda b: b[:5], ErrorCode.MALFORMED_FRAME),
        (lambda b: b[:-1], ErrorCode.MALFORMED_FRAME),
        (lambda b: b + b"\x00", ErrorCode.MALFORMED_FRAME),
        (lambda b: b[:8] + b"\x00\x01\x00\x00" + b[12:], ErrorCode.BAD_VALUE),  # indices 1, 0: not increasing
        (lambda b: b[:12] + b"\xff\xff" + b[14:], ErrorCode.BAD_VALUE),  # index 65535 >= max_soldiers
        (lambda b: b[:14] + bytes([b[14] | 0x80]) + b[15:], ErrorCode.BAD_UPDATE),  # delta, unknown soldier
        (lambda b: b[:14] + bytes([b[14] & 0xFE]) + b[15:], ErrorCode.BAD_UPDATE),  # partial first update
        (lambda b: b[:-1] + bytes([b[-1] | 0x01]), ErrorCode.MALFORMED_FRAME),  # padding bit set
        (lambda b: b"\x00\x02" + b[2:], ErrorCode.UNKNOWN_TABLE),
    ],
)
def test_decoder_rejects_bad_payloads_without_touching_state(mutate, code: ErrorCode) -> None:
    payload, dec = _one_full()
    with pytest.raises(WireError) as info:
        dec.decode(mutate(payload))
    assert info.value.code == code
    assert not dec.known(np.arange(4)).any()
    assert not dec.codes(np.arange(4)).any()
    dec.decode(payload)  # and the good frame still applies
    assert dec.known(np.arange(3)).all()


def test_delta_overflow_is_rejected_atomically() -> None:
    t = UpdateTable(1, "x", "", (JointEntry("j", (DofRange("R", -1.0, 1.0, 4),)),))
    enc, dec = UpdateEncoder(t, version=1), UpdateDecoder(t, version=1)  # a version-1 frame
    dec.decode(
        enc.encode(upd(t, [0, 1], np.array([[0.0], [0.9]]), np.zeros((2, 0, 3)), np.zeros((2, 0, 4))), BIG)[0]
    )
    before = dec.codes(np.arange(2))
    assert before.ravel().tolist() == [8, 15]  # 4-bit codes of 0.0 and 0.9 on [-1, 1)
    # hand-made frame: soldiers 0 and 1, each mode 2 (2-bit deltas) and mask 1; deltas 0 and +1: 15 + 1 > 15
    hdr = bytes([0x00, 0x01, 0, 0, 0, 0, 0x00, 0x02, 0x00, 0x00, 0x00, 0x01])
    heads = int("0010" + "1" + "0010" + "1", 2) << 6  # 10 bits, 6 padding
    fields = int("00" + "01", 2) << 4
    frame = hdr + heads.to_bytes(2, "big") + bytes([fields])
    with pytest.raises(WireError) as info:
        dec.decode(frame)
    assert info.value.code == ErrorCode.BAD_UPDATE
    assert np.array_equal(dec.codes(np.arange(2)), before)


def test_connection_sends_full_updates_on_subscribe_and_request_and_nothing_when_idle() -> None:
    from protocol.connection import CLIENT, NEED_DATA, SERVER, Connection
    from protocol.events import Accept, Hello, RequestFullUpdate, Subscribe, Unsubscribe, UpdateTableMsg

    client, server = Connection(CLIENT), Connection(SERVER, max_soldiers=8)

    def to_server(event) -> None:
        server.receive_data(client.send(event))
        assert server.next_event() == event

    def updates(tick: int) -> list[JointUpdates]:
        data = server.send(upd(DI, range(4), d, p, q, tick))
        if data:  # b"" would mean EOF to receive_data
            client.receive_data(data)
        out = []
        while (ev := client.next_event()) is not NEED_DATA:
            assert isinstance(ev, JointUpdates), ev
            out.append(ev)
        return out

    to_server(Hello("ig"))
    client.receive_data(server.send(Accept("jack", max_soldiers=8)))
    client.next_event()
    client.receive_data(server.send(UpdateTableMsg(DI)))
    client.next_event()
    d, p, q = poses(DI, 4)
    assert updates(0) == []  # nobody subscribed
    to_server(Subscribe((1, 3)))
    (ev,) = updates(1)
    assert ev.indices.tolist() == [1, 3] and ev.changed.all()
    assert updates(2) == []  # idle: no frame at all
    to_server(RequestFullUpdate((3,)))
    (ev,) = updates(3)
    assert ev.indices.tolist() == [3] and ev.changed.all()
    d[1, 0] += 0.01
    (ev,) = updates(4)
    assert ev.indices.tolist() == [1] and ev.changed[0].tolist() == [True] + [False] * 24
    to_server(Unsubscribe((1,)))
    d[1, 0] += 0.01
    assert updates(5) == []
    to_server(Subscribe((1,)))
    (ev,) = updates(6)
    assert ev.indices.tolist() == [1] and ev.changed.all()
    np.testing.assert_array_equal(
        client.decoder(1).codes([1, 3]), quantise(DI, d[[1, 3]], p[[1, 3]], q[[1, 3]])
    )


def test_a_client_that_does_not_decode_updates_gets_their_headers_and_frame_sizes() -> None:
    """``Connection(CLIENT, decode_updates=False)``: the load generator's tap, inside the protocol."""
    from protocol.connection import CLIENT, SERVER, Connection
    from protocol.events import Accept, Hello, Subscribe, UpdateHeaders, UpdateTableMsg

    client, server = Connection(CLIENT, decode_updates=False), Connection(SERVER, max_soldiers=8)
    server.receive_data(client.send(Hello("ig")))
    server.next_event()
    for ev in (Accept("jack", max_soldiers=8), UpdateTableMsg(DI)):
        client.receive_data(server.send(ev))
        client.next_event()
    server.receive_data(client.send(Subscribe((1, 3))))
    server.next_event()
    d, p, q = poses(DI, 4)
    data = server.send(upd(DI, range(4), d, p, q, 7))
    client.receive_data(data)
    ev = client.next_event()
    assert isinstance(ev, UpdateHeaders) and (ev.table, ev.tick) == (DI.table_id, 7)
    assert ev.indices.tolist() == [1, 3] and client.frame_bytes == len(data)


def test_set_rows_writes_what_fancy_assignment_writes() -> None:
    """The encoder's state rows moved whole (``set_rows``): into a column slice of a wider array too, and
    from rows that are not contiguous (the plain assignment then)."""
    rng = np.random.default_rng(5)
    idx = np.array([7, 0, 3, 12])
    for cols in (slice(None), slice(0, 5)):
        a = rng.integers(0, 99, (16, 6)).astype(np.int32)
        b = a.copy()
        rows = rng.integers(0, 99, (4, 6)).astype(np.int32)[:, cols]
        for r in (np.ascontiguousarray(rows), rows[:, ::-1]):
            set_rows(a[:, cols], idx, r)
            b[idx, cols] = r
            np.testing.assert_array_equal(a, b)
        for src in (a, a[:, cols]):  # rows taken whole, or (not contiguous) by fancy indexing
            np.testing.assert_array_equal(take_rows(src, idx), src[idx])
