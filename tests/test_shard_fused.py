"""Issue 21: a shard's tick through the compiled loops (numba, the optional fast extra) publishes what the
numpy path publishes: a pose's codes (``protocol.fused.jack_codes``: the wire conversion and the quantise in
one pass), the board's store of scattered rows (``store_rows``) and a sample's blend of two frames
(``server.motion.blend_loop``), bit for bit; a pose the loop cannot quantise goes the numpy path's way."""

from __future__ import annotations

import math

import numpy as np
import pytest

from client_stub.loadtest.mix import MixDriver
from protocol import fused
from protocol.updates import quantise
from server.pose_board import PoseBoard
from server.soldier.core import TickUpdate
from tests.test_lead_in import shipped_world

pytestmark = pytest.mark.skipif(not fused.AVAILABLE, reason="numba is not installed (the fast extra)")


def jack_poses(n: int, ndof: int, nfig: int, seed: int) -> TickUpdate:
    """float32 poses in Jack's units: DOFs past ±pi (wrapped) and past their ranges, positions in and out of
    theirs, quaternions of any scale and sign, and rows of tied components."""
    rng = np.random.default_rng(seed)
    joints = rng.uniform(-7.0, 7.0, (n, ndof)).astype(np.float32)
    joints[::5] *= 100.0  # translational DOFs of metres, far out of range
    figures = np.empty((n, nfig, 7), np.float32)
    figures[..., :3] = rng.uniform(-400.0, 400.0, (n, nfig, 3))
    figures[..., 3:] = rng.normal(size=(n, nfig, 4)) * rng.uniform(0.01, 100.0, (n, nfig, 1))
    h = math.sqrt(0.5)
    ties: list[list[float]] = [
        [0.5, 0.5, 0.5, 0.5],
        [-0.5, 0.5, -0.5, 0.5],
        [0.0, -h, h, 0.0],
        [-0.0, -1.0, 0.0, -0.0],
        [0, 0, 0, -3],
    ]
    for k, q in enumerate(ties):
        figures[k, :, 3:] = q
    idx = np.arange(n, dtype=np.int64)
    return TickUpdate(idx, joints, figures, np.zeros(n, bool))


def numpy_codes(world: object, k: int, update: TickUpdate) -> np.ndarray:
    ju = world.sets[k].converter.convert(update)  # type: ignore[attr-defined]
    return quantise(world.sets[k].table, ju.dofs, ju.positions, ju.orientations)  # type: ignore[attr-defined]


def test_jack_codes_are_the_conversion_and_quantise_codes() -> None:
    world = shipped_world()
    for k, s in enumerate(world.sets):
        for seed in range(3):
            update = jack_poses(3000, s.table.ndofs, s.table.nfigures, seed)
            codes = s.converter.codes(update)
            assert codes is not None
            np.testing.assert_array_equal(codes, numpy_codes(world, k, update))


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, 0.0])
def test_a_pose_it_cannot_quantise_goes_the_numpy_way(bad: float) -> None:
    world = shipped_world()
    s = world.sets[0]
    for where in ("joint", "position", "quaternion"):
        update = jack_poses(40, s.table.ndofs, s.table.nfigures, 7)
        if where == "joint":
            update.joints[31, 3] = bad if bad else math.nan
        elif where == "position":
            update.figures[31, 1, 2] = bad if bad else math.inf
        else:
            update.figures[31, 1, 3:] = bad
        assert s.converter.codes(update) is None
        with pytest.raises(ValueError, match="row 31"):
            numpy_codes(world, 0, update)


def test_store_rows_compares_and_writes_as_numpy() -> None:
    rng = np.random.default_rng(3)
    dtypes: tuple[type, ...] = (np.int32, np.uint16)
    for dtype in dtypes:
        codes: np.ndarray = rng.integers(0, 50, (500, 9)).astype(dtype)
        rows = rng.permutation(500)[:200].astype(np.int64)
        q = codes[rows].copy()
        q[::3, rng.integers(0, 9)] += 1
        want = codes.copy()
        want[rows] = q
        changed = np.empty(len(rows), bool)
        fused.kernel("store_rows")(codes, rows, q, changed)
        np.testing.assert_array_equal(codes, want)
        np.testing.assert_array_equal(changed, np.arange(len(rows)) % 3 == 0)


def test_a_sample_blends_as_the_numpy_path(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every clip of the shipped library at random times (before its start, past its end), its own
    duration or a stretched one, forwards and backwards: the same float32 bits of joints and figures, the
    same frames, roots and ends."""
    lib = shipped_world().manager.library  # type: ignore[union-attr]
    rng = np.random.default_rng(5)
    for s in lib.sets:
        n = 4000
        clip = rng.integers(0, len(s.clip_nframes), n)
        start = rng.uniform(-1.0, 0.0, n)
        direc = np.where(rng.random(n) < 0.5, 1, -1)
        dur = np.where(rng.random(n) < 0.3, 0.0, rng.uniform(0.2, 3.0, n))
        for now in (rng.uniform(0.0, 3.0, n), 1.25):  # each soldier's clock, or one time for all
            got = s.sample(clip, start, direc, dur, now)
            monkeypatch.setattr(fused, "AVAILABLE", False)
            want = s.sample(clip, start, direc, dur, now)
            monkeypatch.setattr(fused, "AVAILABLE", True)
            for a, b in ((got.joints, want.joints), (got.figures, want.figures)):
                np.testing.assert_array_equal(a.view(np.uint32), b.view(np.uint32))
            np.testing.assert_array_equal(got.position.view(np.uint64), want.position.view(np.uint64))
            np.testing.assert_array_equal(got.roots, want.roots)
            np.testing.assert_array_equal(got.ended, want.ended)


def test_a_shards_board_publishes_the_numpy_paths_codes(monkeypatch: pytest.MonkeyPatch) -> None:
    """A moving crowd of DI soldiers (AK-47s and M16s) on every other index, as a shard's: each tick
    published to two boards without poses, one by the loops, one by numpy: the same codes and versions."""
    world = shipped_world()
    m = world.manager
    assert m is not None
    table = world.sets[0].table
    boards = [PoseBoard(table.ndofs, table.nfigures, poses=False) for _ in range(2)]
    weapons = ["M16.fig" if k % 3 == 0 else "AK_47.fig" for k in range(120)]
    idx = np.array([m.create_soldier(figure="DI.fig", weapon=w, now=0.0) for w in weapons])
    try:
        for b in boards:
            for i in idx:
                b.add(int(i), world.table_of(int(i)))
        rows = MixDriver(len(idx), mix="moving", seed=2).initial()
        rows["index"] = idx[rows["index"]]
        m.apply_requests(rows, 0.0)
        mine = idx[::2]
        for k in range(1, 31):
            update = m.tick(k / 30)
            update = update.select(np.flatnonzero(np.isin(update.indices, mine)))
            for b, on in zip(boards, (True, False), strict=True):
                monkeypatch.setattr(fused, "AVAILABLE", on)
                b.publish(update, world)
            monkeypatch.setattr(fused, "AVAILABLE", True)
            np.testing.assert_array_equal(boards[0].codes[idx], boards[1].codes[idx])
            np.testing.assert_array_equal(boards[0].version[idx], boards[1].version[idx])
    finally:
        for i in idx:
            m.remove_soldier(int(i))
