"""Quantising per component column (issue 16's cheaper tick) gives the codes the per-quaternion numpy calls
gave, bit for bit: on random and edge-case poses (ties between components, negative leads, values out of
range, half steps) and on the poses a real crowd ticks (shipped clips, DI soldiers with AK-47s and M16s,
standing and moving)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from client_stub.loadtest.mix import MixDriver
from protocol.update_table import UpdateTable, example_di_table
from protocol.updates import quantise
from server.pose_board import PoseBoard
from tests.test_lead_in import shipped_world

DI = example_di_table()
_OTHERS = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])


def reference(table: UpdateTable, dofs: np.ndarray, pos: np.ndarray, quat: np.ndarray) -> np.ndarray:
    """The codes as quantise computed them before the column form (numpy calls on the last axis)."""
    lay, n = table.layout, len(dofs)
    quat = quat / np.linalg.norm(quat, axis=-1, keepdims=True)
    qidx = np.argmax(np.abs(quat), axis=-1)
    quat = np.where(np.take_along_axis(quat, qidx[..., None], -1) < 0, -quat, quat)
    raw = np.empty((n, lay.nfields))
    raw[:, lay.dof_fields] = dofs
    raw[:, lay.pos_fields.ravel()] = pos.reshape(n, -1)
    raw[:, lay.qidx_fields] = qidx
    raw[:, lay.comp_fields.ravel()] = np.take_along_axis(quat, _OTHERS[qidx], -1).reshape(n, -1)
    raw = np.clip(np.rint((raw - lay.lo) * (1.0 / lay.step)), 0.0, lay.max_code.astype(np.float64))
    return raw.astype(np.int32)


def random_poses(n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """DOFs and positions partly out of range (the clip), quaternions of any scale and sign."""
    rng = np.random.default_rng(seed)
    dofs = rng.uniform(-4.0, 4.0, (n, DI.ndofs))
    pos = rng.uniform(-3.0, 3.0, (n, DI.nfigures, 3))
    quat = rng.normal(size=(n, DI.nfigures, 4)) * rng.uniform(0.01, 100.0, (n, DI.nfigures, 1))
    return dofs, pos, quat


def test_random_poses_give_the_reference_codes() -> None:
    for seed in range(3):
        d, p, q = random_poses(5000, seed)
        np.testing.assert_array_equal(quantise(DI, d, p, q), reference(DI, d, p, q))


def in_range_poses(n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """DOFs and positions within their fields' ranges (nothing to clip), quaternions of any scale and sign."""
    lay, rng = DI.layout, np.random.default_rng(seed)
    hi = lay.lo + lay.step * lay.max_code
    dofs = rng.uniform(lay.lo[lay.dof_fields], hi[lay.dof_fields], (n, DI.ndofs))
    pos = rng.uniform(lay.lo[lay.pos_fields], hi[lay.pos_fields], (n, DI.nfigures, 3))
    quat = rng.normal(size=(n, DI.nfigures, 4)) * rng.uniform(0.01, 100.0, (n, DI.nfigures, 1))
    return dofs, pos, quat


@pytest.mark.parametrize("n", [1, 16, 37])
def test_one_value_out_of_range_is_clipped_in_any_row(n: int) -> None:
    """Most ticks clip nothing and skip the clip (``updates._needs_clip``): one value below or above its
    field's range, in any row (of the blocks of 16 the check reads, or of the rest), still clips."""
    d, p, q = in_range_poses(n, n)
    np.testing.assert_array_equal(quantise(DI, d, p, q), reference(DI, d, p, q))
    for row in sorted({0, n // 2, n - 1}):
        for value in (-1e6, 1e6):
            d2, p2 = d.copy(), p.copy()
            d2[row, (row * 7) % DI.ndofs] = value
            p2[row, 0, row % 3] = value
            for dofs, pos in ((d2, p), (d, p2)):
                np.testing.assert_array_equal(quantise(DI, dofs, pos, q), reference(DI, dofs, pos, q))


def test_ties_signs_and_half_steps_give_the_reference_codes() -> None:
    h = math.sqrt(0.5)
    quats = [
        [0.5, 0.5, 0.5, 0.5],
        [-0.5, 0.5, -0.5, 0.5],
        [0.0, -h, h, 0.0],
        [0.0, 0.0, -h, -h],
        [-0.0, -1.0, 0.0, -0.0],
        [0.0, 0.0, 0.0, -3.0],
        [-1.0, 0.0, 0.0, 0.0],
    ]
    n = len(quats)
    q = np.repeat(np.array(quats)[:, None, :], DI.nfigures, axis=1)
    lay = DI.layout
    d = np.tile(lay.lo[lay.dof_fields] + 0.5 * lay.step[lay.dof_fields], (n, 1))  # exactly half a step
    p = np.zeros((n, DI.nfigures, 3))
    np.testing.assert_array_equal(quantise(DI, d, p, q), reference(DI, d, p, q))


@settings(max_examples=200, deadline=None)
@given(st.lists(st.sampled_from([-1.0, -0.5, -0.0, 0.0, 0.25, 0.5, 1.0]), min_size=8, max_size=8))
def test_quaternions_of_few_values_give_the_reference_codes(values: list[float]) -> None:
    q = np.array(values).reshape(1, 2, 4)
    if (np.linalg.norm(q, axis=-1) < 1e-9).any():
        with pytest.raises(ValueError, match="zero quaternion"):
            quantise(DI, np.zeros((1, DI.ndofs)), np.zeros((1, 2, 3)), q)
        return
    d, p = np.zeros((1, DI.ndofs)), np.zeros((1, 2, 3))
    np.testing.assert_array_equal(quantise(DI, d, p, q), reference(DI, d, p, q))


@pytest.mark.parametrize("component", [0, 1, 3])
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_non_finite_orientation_is_refused(bad: float, component: int) -> None:
    d, p, q = random_poses(3, 0)
    q[2, 1, component] = bad
    with pytest.raises(ValueError, match="row 2"):
        quantise(DI, d, p, q)


@pytest.mark.parametrize("mix", ["realistic", "moving"])
def test_a_real_crowd_ticks_the_reference_codes(mix: str) -> None:
    """Shipped clips, DI soldiers with AK-47s and M16s: every tick's codes are the reference's codes of the
    poses the board holds (the world is test_lead_in's, cached: its soldiers are removed after)."""
    world = shipped_world()
    m = world.manager
    assert m is not None
    table = world.sets[0].table
    board = PoseBoard(table.ndofs, table.nfigures)
    weapons = ["M16.fig" if k % 3 == 0 else "AK_47.fig" for k in range(90)]
    idx = np.array([m.create_soldier(figure="DI.fig", weapon=w, now=0.0) for w in weapons])
    try:
        for i in idx:
            board.add(int(i), world.table_of(int(i)))
        rows = MixDriver(len(idx), mix=mix, seed=1).initial()
        rows["index"] = idx[rows["index"]]
        m.apply_requests(rows, 0.0)
        tables = {s.table.table_id: s.table for s in world.sets}
        for k in range(1, 46):
            board.publish(m.tick(k / 30), world)
            for tid, t in tables.items():
                r = idx[board.table_of[idx] == tid]
                assert len(r) and board.valid[r].all()
                want = reference(t, board.dofs[r], board.positions[r], board.orientations[r])
                np.testing.assert_array_equal(board.codes[r], want)
    finally:
        for i in idx:
            m.remove_soldier(int(i))


def test_work_buffers_never_reach_what_a_caller_keeps() -> None:
    """The tick reuses its big work arrays (protocol.bitpack.scratch); what a caller keeps is its own: two
    samples, two conversions and two quantisations share no memory, and ``out=`` gives the same codes."""
    world = shipped_world()
    m = world.manager
    assert m is not None
    idx = np.array([m.create_soldier(figure="DI.fig", weapon="AK_47.fig", now=0.0) for _ in range(4)])
    try:
        first, second = m.snapshot(idx), m.snapshot(idx)
        assert len(first) == len(second) == len(idx)
        assert not np.shares_memory(first.joints, second.joints)
        assert not np.shares_memory(first.figures, second.figures)
        conv = world.sets[0].converter
        a, b = conv.convert(first), conv.convert(second)
        for x, y in ((a.dofs, b.dofs), (a.positions, b.positions), (a.orientations, b.orientations)):
            assert not np.shares_memory(x, y)
        table = world.sets[0].table
        qa = quantise(table, a.dofs, a.positions, a.orientations)
        qb = quantise(table, b.dofs, b.positions, b.orientations)
        assert not np.shares_memory(qa, qb)
        out = np.empty_like(qa)
        assert quantise(table, a.dofs, a.positions, a.orientations, out) is out
        np.testing.assert_array_equal(out, qa)
        reused = conv.convert(first, reuse=True)
        np.testing.assert_array_equal(reused.dofs, a.dofs)
        np.testing.assert_array_equal(reused.orientations, a.orientations)
    finally:
        for i in idx:
            m.remove_soldier(int(i))
