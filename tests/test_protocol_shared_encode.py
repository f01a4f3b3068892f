"""Encode once, send to many: what each client receives through the shared memo is byte-identical to what a
private per-client encoder sends, whatever the subscription mixes, resets and join times (issue 18)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol.shared_encode import SharedEncodes
from protocol.update_table import example_di_table
from protocol.updates import UpdateDecoder, UpdateEncoder

DI = example_di_table()
NMAX = 48


class Client:
    """One client: a shared encoder, the private reference it must match, and a decoder of what it got."""

    def __init__(self, shared: SharedEncodes, rows: np.ndarray, protocol: int = 2) -> None:
        self.enc = UpdateEncoder(DI, NMAX, shared, protocol)
        self.ref = UpdateEncoder(DI, NMAX, version=protocol)
        self.dec = UpdateDecoder(DI, NMAX, protocol)
        self.rows = rows
        self.protocol = protocol

    def reset(self, idx: np.ndarray | None) -> None:
        self.enc.reset(idx)
        self.ref.reset(idx)


def _codes(rng: np.random.Generator, codes: np.ndarray, moving: float) -> np.ndarray:
    lay = DI.layout
    move = rng.random(NMAX) < moving
    step = rng.integers(-40, 41, codes.shape) * move[:, None]
    return np.clip(codes + step, 0, lay.max_code).astype(np.int32)


def _step(
    rng: np.random.Generator, clients: list[Client], shared: SharedEncodes, groups: list[np.ndarray]
) -> None:
    """One random event between publishes: a join, a (re)subscription, a reused index, a new row set."""
    ev = int(rng.integers(0, 8))
    if ev == 0:
        clients.append(Client(shared, groups[int(rng.integers(len(groups)))], clients[0].protocol))
    elif ev == 1 and clients:
        clients[int(rng.integers(len(clients)))].reset(rng.choice(NMAX, 3, replace=False))
    elif ev == 2:
        reused = rng.choice(NMAX, 1)
        for c in clients:  # a soldier index reused: every client resets it (server.app._on_created)
            c.reset(reused)
    elif ev == 3 and clients:
        clients[int(rng.integers(len(clients)))].rows = groups[int(rng.integers(len(groups)))]
    elif ev == 4 and clients:
        clients[int(rng.integers(len(clients)))].reset(None)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 2**32), st.integers(1, 5), st.sampled_from([1 << 16, 300]), st.sampled_from([1, 2, 0]))
def test_shared_encoding_is_byte_identical_to_per_client(
    seed: int, nclients: int, max_payload: int, protocol: int
) -> None:
    rng = np.random.default_rng(seed)
    shared = SharedEncodes()
    # visibility / subscription mixes: everything, one owner's soldiers, the others', a random subset
    groups = [
        np.arange(NMAX),
        np.arange(0, NMAX, 2),
        np.arange(1, NMAX, 2),
        np.sort(rng.choice(NMAX, 20, False)),
    ]
    # protocol 0: version 1 and version 2 clients mixed in one memo (a server's old and new clients)
    clients = [
        Client(shared, groups[int(rng.integers(len(groups)))], protocol or int(rng.integers(1, 3)))
        for _ in range(nclients)
    ]
    codes = rng.integers(0, DI.layout.max_code + 1, (NMAX, DI.layout.nfields)).astype(np.int32)
    for version in range(1, 40):
        codes = _codes(rng, codes, float(rng.choice([0.0, 0.3, 1.0])))
        for c in clients:
            if rng.random() < 0.2:
                continue  # a lagging client skips this publish
            sel = c.rows[rng.random(len(c.rows)) < 0.9] if rng.random() < 0.3 else c.rows
            got = c.enc.encode_codes(sel, codes[sel], version, max_payload, version)
            want = c.ref.encode_codes(sel, codes[sel], version, max_payload)
            assert got == want
            for p in got:
                c.dec.decode(p)
            assert np.array_equal(c.dec.codes(sel), codes[sel])  # what the client decodes is the pose
        _step(rng, clients, shared, groups)
    everyone = np.arange(NMAX)
    for c in clients:  # the same delta state (codes of soldiers not known are stale and never used)
        known = c.ref.known(everyone)
        assert np.array_equal(c.enc.known(everyone), known)
        assert np.array_equal(c.enc.codes(everyone[known]), c.ref.codes(everyone[known]))


@pytest.mark.parametrize("protocol", [1, 2])
def test_clients_in_one_state_share_one_encode_and_a_late_joiner_joins_them(protocol: int) -> None:
    shared = SharedEncodes()
    rng = np.random.default_rng(1)
    rows = np.arange(NMAX)
    codes = rng.integers(0, DI.layout.max_code + 1, (NMAX, DI.layout.nfields)).astype(np.int32)
    early = [UpdateEncoder(DI, NMAX, shared, protocol) for _ in range(3)]
    late = UpdateEncoder(DI, NMAX, shared, protocol)
    for version in range(1, 7):
        codes = _codes(rng, codes, 0.5)
        for enc in early + ([late] if version >= 3 else []):
            enc.encode_codes(rows, codes, version, 1 << 16, version)
    # versions 1-2: one encode for three clients; 3: the late joiner's keyframe (its own) joins the group;
    # protocol 2: its keyframe restarted its prediction, so it joins after one more encode of its own
    assert len({e.state for e in [*early, late]}) == 1
    assert shared.misses == 6 + 1 + (protocol - 1)


def test_visibility_groups_never_share_rows() -> None:
    """Two owners' clients see disjoint soldiers: each decodes only its own rows (issue 17 holds)."""
    shared = SharedEncodes()
    codes = np.zeros((NMAX, DI.layout.nfields), np.int32)
    mine, theirs = np.arange(0, NMAX, 2), np.arange(1, NMAX, 2)
    a, b = UpdateEncoder(DI, NMAX, shared), UpdateEncoder(DI, NMAX, shared)
    da, db = UpdateDecoder(DI, NMAX), UpdateDecoder(DI, NMAX)
    for version in (1, 2):
        codes = codes + 1
        for enc, dec, rows in ((a, da, mine), (b, db, theirs)):
            for p in enc.encode_codes(rows, codes[rows], version, 1 << 16, version):
                assert set(dec.decode(p).indices.tolist()) <= set(rows.tolist())
    assert not da.known(theirs).any() and not db.known(mine).any()


class Writer:
    """A server session's writer over a shared encoder: owes the soldiers of ``rows`` whose codes changed
    since its last write and, when it missed publishes, catches up through its group's memoised frames
    (the logic of ``server.session.Session._joint_updates``)."""

    def __init__(self, shared: SharedEncodes, rows: np.ndarray, protocol: int) -> None:
        self.enc = UpdateEncoder(DI, NMAX, shared, protocol)
        self.dec = UpdateDecoder(DI, NMAX, protocol)
        self.rows = rows
        self.since = 0
        self.caught = 0

    def write(self, serial: int, codes: np.ndarray, changed_at: np.ndarray, max_payload: int) -> list[bytes]:
        due = self.rows[changed_at[self.rows] > self.since]
        since, self.since = self.since, serial
        got = None
        if 0 < since < serial - 1 and len(due):
            allowed = np.zeros(NMAX, bool)
            allowed[self.rows] = True
            missed = [(v, due[changed_at[due] == v]) for v in range(since + 1, serial)]
            now = due[changed_at[due] == serial]
            got = self.enc.catch_up(missed, allowed, now, codes[now], serial, max_payload, serial)
            self.caught += got is not None
        if got is None:
            got = self.enc.encode_codes(due, codes[due], serial, max_payload, serial)
        for p in got:
            ju = self.dec.decode(p)
            assert set(ju.indices.tolist()) <= set(self.rows.tolist())  # never a soldier it may not see
        return got


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32), st.sampled_from([1 << 16, 300]), st.sampled_from([1, 2, 0]))
def test_late_writers_catch_up_through_the_memo_and_decode_every_pose(
    seed: int, max_payload: int, protocol: int
) -> None:
    """Writers that skip one to five publishes, alone or together, in groups of equal and of different
    subscriptions, v1 and v2 mixed: what each decodes after every write is every subscribed soldier's
    current code, and those whose write took the memo's frames rejoin their group's state."""
    rng = np.random.default_rng(seed)
    shared = SharedEncodes()
    groups = [np.arange(NMAX), np.arange(0, NMAX, 2), np.sort(rng.choice(NMAX, 20, False))]
    writers = [
        Writer(shared, groups[int(rng.integers(len(groups)))], protocol or int(rng.integers(1, 3)))
        for _ in range(int(rng.integers(2, 6)))
    ]
    codes = rng.integers(0, DI.layout.max_code + 1, (NMAX, DI.layout.nfields)).astype(np.int32)
    changed_at = np.ones(NMAX, np.int64)  # every soldier is new at the first publish
    skip_until = [0] * len(writers)
    for serial in range(1, 40):
        new = _codes(rng, codes, float(rng.choice([0.0, 0.3, 1.0])))
        changed_at[(new != codes).any(axis=1)] = serial
        codes = new
        for j, w in enumerate(writers):
            if serial < skip_until[j]:
                continue
            if rng.random() < 0.25:  # falls behind for one to five publishes
                skip_until[j] = serial + int(rng.integers(1, 6))
                continue
            w.write(serial, codes, changed_at, max_payload)
            assert np.array_equal(w.dec.codes(w.rows), codes[w.rows])
            assert w.dec.known(w.rows).all()
        if rng.random() < 0.1:
            reused = rng.choice(NMAX, 1)
            changed_at[reused] = serial
            for w in writers:  # a reused index: every writer resets it (server.app._on_created)
                w.enc.reset(reused)


@pytest.mark.parametrize("protocol", [1, 2])
def test_a_writer_one_publish_late_sends_its_groups_frames_and_stays_in_the_group(protocol: int) -> None:
    """The spiral of issue 18: a writer that misses a publish takes the memo's frames for it (byte for byte
    what its group got, ticks in order) and the newest publish's shared encode, with no encode of its own."""
    shared = SharedEncodes()
    rng = np.random.default_rng(2)
    rows = np.arange(NMAX)
    codes = rng.integers(0, DI.layout.max_code + 1, (NMAX, DI.layout.nfields)).astype(np.int32)
    changed_at = np.zeros(NMAX, np.int64)
    on_time, late = Writer(shared, rows, protocol), Writer(shared, rows, protocol)
    sent: dict[int, list[bytes]] = {}
    for serial in range(1, 9):
        codes = _codes(rng, codes, 1.0)
        changed_at[:] = serial
        sent[serial] = on_time.write(serial, codes, changed_at, 1 << 16)
        if serial not in (4, 6, 7):
            misses = shared.misses
            got = late.write(serial, codes, changed_at, 1 << 16)
            assert shared.misses == misses  # every frame from the memo
            if serial == 5:
                assert got == sent[4] + sent[5]
            if serial == 8:
                assert got == sent[6] + sent[7] + sent[8]
            assert late.enc.state == on_time.enc.state
    assert late.caught == 2 and shared.caught_up == 3


def test_a_late_writer_never_takes_frames_with_a_soldier_it_may_no_longer_see() -> None:
    """Visibility changes without a reset (a soldier's owner changes): the group's frames for the missed
    publish hold soldiers this writer may not see now, so it encodes on its own, and only what it may see."""
    shared = SharedEncodes()
    rng = np.random.default_rng(3)
    everyone, even = np.arange(NMAX), np.arange(0, NMAX, 2)
    codes = rng.integers(0, DI.layout.max_code + 1, (NMAX, DI.layout.nfields)).astype(np.int32)
    changed_at = np.ones(NMAX, np.int64)
    a, b = Writer(shared, everyone, 2), Writer(shared, everyone, 2)
    for serial in (1, 2, 3):
        if serial > 1:
            codes = _codes(rng, codes, 1.0)
            changed_at[:] = serial
        if serial == 3:
            b.rows = even  # b may see only the even soldiers now; its encoder was not reset
        if serial != 2:  # b first: the group's state of publish 2 is still intact, a chain could end there
            assert b.write(serial, codes, changed_at, 1 << 16)  # (asserts every decoded soldier is b's)
        a.write(serial, codes, changed_at, 1 << 16)
    assert b.caught == 0
    assert np.array_equal(b.dec.codes(even), codes[even])


def test_encoders_of_different_max_soldiers_never_share_arrays() -> None:
    """Clients may negotiate different max_soldiers: equal rows from FRESH must not hand one the other's
    (smaller) state arrays."""
    shared = SharedEncodes()
    small, large = UpdateEncoder(DI, NMAX, shared), UpdateEncoder(DI, 2 * NMAX, shared)
    codes = np.zeros((2 * NMAX, DI.layout.nfields), np.int32)
    rows = np.arange(4)
    for enc in (small, large):
        enc.encode_codes(rows, codes[rows], 1, 1 << 16, 1)
    far = np.arange(NMAX, NMAX + 4)
    assert large.encode_codes(far, codes[far] + 1, 2, 1 << 16, 2)
