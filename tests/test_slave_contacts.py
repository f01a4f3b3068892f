"""Kneeling contacts carried over to the DI.fig slave (server/authoring/slave_contacts.py): where the master
kneels on his kneecap, the slave does too, his feet stay where they were and the rifle stays in his hands."""

from __future__ import annotations

import copy

import numpy as np
import pytest

pytest.importorskip("scipy")

from server.authoring.build import BuildContext, slave_pair
from server.authoring.quality_frames import FigureSet, play
from server.authoring.slave_contacts import part_heights, rest_slave_knees
from server.authoring.slaving import reslave_channelset
from server.motion.cache import load_channelset
from ttes.paths import CHANNELSETS, FIGURES


@pytest.fixture(scope="module")
def kneeling():
    ctx = BuildContext.load(FIGURES)
    figs = FigureSet({"soldier.fig": ctx.soldier, "DI.fig": ctx.di, "AK_47.fig": ctx.rifle})
    master = load_channelset(CHANNELSETS / "kstow2kfire.chset.env", use_cache=False)
    slave = reslave_channelset(master, slave_pair(ctx), "kstow2kfire_low.chset")
    return figs, master, slave


def _knees(figs: FigureSet, cs, part: str = "kneecap") -> np.ndarray:
    f = play(cs, figs)
    ptype = max(f.poses, key=lambda k: figs.kin[k].ndof)
    return part_heights(f.poses[ptype], f.locations[ptype], figs, ptype, part)["right"]


def _sites(figs: FigureSet, cs, names: tuple[str, ...]) -> np.ndarray:
    f = play(cs, figs)
    kin = figs.kin["DI.fig"]
    g = kin.site_globals(f.poses["DI.fig"], f.locations["DI.fig"])
    return g[:, [kin.site_names.index(n) for n in names]][..., :3, 3]


def test_the_slave_kneels_on_his_kneecap_where_the_master_does(kneeling) -> None:
    figs, master, slave = kneeling
    lowered = copy.deepcopy(slave)
    drop = rest_slave_knees(master, lowered, figs)
    m, before, after = _knees(figs, master), _knees(figs, slave), _knees(figs, lowered)
    assert np.all(before - m > 1.0)  # DI.fig's kneecap mesh sits higher on the same skeleton
    np.testing.assert_allclose(after, m, atol=0.1)
    np.testing.assert_allclose(drop, before - m, atol=0.1)
    # the toes behind the kneeling knee come down onto the ground with it
    assert np.all(_knees(figs, slave, "foot") - _knees(figs, master, "foot") > 0.5)
    np.testing.assert_allclose(_knees(figs, lowered, "foot"), _knees(figs, master, "foot"), atol=0.1)
    # the front foot stays planted (within 3 mm); the rifle went down with the body: the palms still hold it
    feet = ("left_foot.heel", "left_foot.ball")
    np.testing.assert_allclose(_sites(figs, lowered, feet), _sites(figs, slave, feet), atol=0.3)
    rifle_before = play(slave, figs).locations["AK_47.fig"][:, 1, 3]
    rifle_after = play(lowered, figs).locations["AK_47.fig"][:, 1, 3]
    np.testing.assert_allclose(rifle_before - rifle_after, drop, atol=1e-3)
    palms = ("right_palm.palmcenter", "left_palm.palmcenter")
    moved = _sites(figs, slave, palms) - _sites(figs, lowered, palms)
    assert np.abs(moved[..., 1] - drop[:, None]).max() < 1e-3


def test_a_standing_clip_is_left_alone(kneeling) -> None:
    figs, _, _ = kneeling
    master = load_channelset(CHANNELSETS / "ststow2stfire.chset.env", use_cache=False)
    slave = load_channelset(CHANNELSETS / "ststow2stfire_low.chset.env", use_cache=False)
    data = slave.joint_data.copy()
    assert not rest_slave_knees(master, slave, figs).any()
    np.testing.assert_array_equal(slave.joint_data, data)
