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
