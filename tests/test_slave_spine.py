"""A prone dead slave's belly comes out of the ground by its spine, not by lifting the body
(authoring/slave_spine.py; issue 14: prfire2dead's DI belly lay 2.8 cm in the ground as the hit pressed the
master flat, and the build's lift raised the whole body, pelvis 0.1 -> 3.0 cm, trunk_rise 5.75)."""

from __future__ import annotations

import copy

import numpy as np
import pytest

pytest.importorskip("scipy")

from authoring.build import BuildContext, slaving_context
from authoring.slave_body import played_body, write_pose
from authoring.slave_rest import part_lows
from authoring.slave_spine import FADE_FRAMES, SPINE_DOFS, lay_slave_spine
from server.motion.cache import load_channelset
from ttes.paths import CHANNELSETS, FIGURES


def test_a_belly_pushed_into_the_ground_comes_out_by_the_spine_alone() -> None:
    """Constructed: the committed DI prfire2dead slave sunk into the ground from the release on until its
    belly lies 2 cm in it, where the master's lies on the ground (as the hit pressing the master flat did)."""
    master = load_channelset(CHANNELSETS / "prfire2dead.chset.env", use_cache=False)
    figs = slaving_context(BuildContext.load(FIGURES), "prfire2dead", master).figure_set  # as the build
    slave = load_channelset(CHANNELSETS / "prfire2dead_low.chset.env", use_cache=False)
    q, loc, stype = played_body(slave, figs)
    kin = figs.kin[stype]
    assert slave.release_frame is not None
    n, release = len(q), slave.release_frame
    sunk = np.tile(np.eye(4), (n, 1, 1))
    after = np.clip((np.arange(n) - release + 6) / 6.0, 0.0, 1.0)
    sunk[:, 1, 3] = -(part_lows(figs, stype, q, loc)["belly"] + 2.0) * after
    write_pose(slave, figs, stype, q, sunk)
    q, loc, _ = played_body(slave, figs)
    before = copy.deepcopy(slave)
    assert part_lows(figs, stype, q, loc)["belly"][release:].max() < -1.9

    bend = lay_slave_spine(master, slave, figs)
    q1, loc1, _ = played_body(slave, figs)
    mq, mloc, mtype = played_body(master, figs)
    m_belly = np.maximum(part_lows(figs, mtype, mq, mloc)["belly"], 0.0)
    belly = part_lows(figs, stype, q1, loc1)["belly"]
    assert bend.max() > 2.0
    full = release + FADE_FRAMES  # faded in from the release (the hands hold the rifle until then) ...
    assert (np.diff(belly[release:full]) > 0).all()
    assert (belly[full:] >= m_belly[full:] - 0.5).all()  # ... out, as high as his (to 5 mm)
    np.testing.assert_array_equal(slave.fig_pos, before.fig_pos)  # the body (its pelvis) where it was
    cols = [kin.dof_slices[j].start + k for j, k in SPINE_DOFS]
    rest = np.setdiff1d(np.arange(kin.ndof), cols)
    np.testing.assert_allclose(q1[:, rest], q[:, rest], atol=1e-6)  # the spine's pitch alone turned
    # eased in: no one-frame bend (7.7 degrees a frame here, 2 cm deep; the rebuilt clip 4.8, main 5.7)
    assert np.degrees(np.abs(np.diff(q1[:, cols], axis=0)).max()) < 8.0


def test_only_the_prone_deaths_slaves_lay_their_trunk_by_the_spine() -> None:
    """prfire2dead's and prstow2dead's own setting: every other death's slaves rebuild unchanged
    (prstow2dead's, laid so, also leave their start from rest: their head 0.59 m/s in the first frames; and
    prfire2dead's, whose arms leave it late, slave_arms_late: the held rifle's muzzle 0.55 m/s)."""
    from authoring import deaths

    assert {d.name for d in deaths.DEATHS if d.slave_spine_laid} == {"prfire2dead", "prstow2dead"}
    assert {d.name for d in deaths.DEATHS if d.slave_start_ease} == {"prstow2dead", "prfire2dead"}
