"""Kneeling and prone contacts carried over to the DI.fig slave (authoring/slave_contacts.py): where
the master kneels on his kneecap, the slave does too, his feet stay where they were and the rifle stays in his
hands; where the master's prone forearms lie on the ground, so do the slave's."""

from __future__ import annotations

import copy

import numpy as np
import pytest

pytest.importorskip("scipy")

from authoring.build import SNAP_FADE_FRAMES, BuildContext, _snap_end, lift_off_ground, slave_pair
from authoring.quality_frames import FigureSet, play
from authoring.slave_contacts import part_heights, rest_slave_forearms, rest_slave_knees
from authoring.slaving import reslave_channelset
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


@pytest.fixture(scope="module")
def prone():
    ctx = BuildContext.load(FIGURES)
    figs = FigureSet({"soldier.fig": ctx.soldier, "DI.fig": ctx.di, "AK_47.fig": ctx.rifle})
    master = load_channelset(CHANNELSETS / "prfire_recoil.chset.env", use_cache=False)
    slave = reslave_channelset(master, slave_pair(ctx), "prfire_recoil_low.chset")
    lift_off_ground(slave, ctx.di)
    return figs, master, slave


def test_the_prone_slave_lays_his_forearms_on_the_ground_with_the_rifle_in_his_hands(prone) -> None:
    figs, master, slave = prone
    rested = copy.deepcopy(slave)
    rest_slave_forearms(master, rested, figs)
    before = _knees(figs, slave, "forearm")
    after, m = _knees(figs, rested, "forearm"), _knees(figs, master, "forearm")
    assert np.all(before - m > 2.0)  # DI.fig's prone shoulders sit higher: its forearm floats
    assert np.all(after < 2.0)  # resting (the quality check's 2 cm)
    palms, eye = ("right_palm.palmcenter", "left_palm.palmcenter"), ("bottom_head.sight",)
    np.testing.assert_allclose(_sites(figs, rested, palms), _sites(figs, slave, palms), atol=0.1)
    assert np.linalg.norm(_sites(figs, rested, eye) - _sites(figs, slave, eye), axis=-1).max() < 2.1
    q = play(rested, figs).poses["DI.fig"]
    assert np.degrees(np.abs(np.diff(q, axis=0))).max() < 10.0  # smooth over the clip


def test_a_snapped_endpoint_fades_into_the_clip() -> None:
    data = np.zeros((30, 2), np.float32)
    _snap_end(data, -1, np.array([1.0, -2.0]))
    np.testing.assert_allclose(data[-1], [1.0, -2.0])
    assert np.abs(np.diff(data, axis=0)).max() < 0.25  # no jump at the end: spread over SNAP_FADE_FRAMES
    assert not data[: 30 - SNAP_FADE_FRAMES].any()
