"""A dying slave's hands and forearms on the ground lie still where they come to rest
(authoring/slave_arms.py, issue 14: stfire2dead's DI/M16 left hand rolled under rest_limbs' frame-by-frame
solve as the trunk settled, its nodes sliding 4.0 cm while the master's lay still)."""

from __future__ import annotations

import copy

import numpy as np
import pytest

pytest.importorskip("scipy")

from authoring import deaths, slave_arms
from authoring.body_parts import contact_slides
from authoring.build import BuildContext, slaving_context
from authoring.quality import CONTACT_HEIGHT_CM, check_clip
from authoring.quality_frames import FigureSet
from authoring.slave_body import played_body
from authoring.slave_feet import part_points
from server.motion.binding import bind_channelset
from server.motion.cache import load_channelset
from ttes.paths import CHANNELSETS, FIGURES

ROLL = slice(80, 130)  # frames in which the left hand, on the ground, is made to roll to and fro


@pytest.fixture(scope="module")
def figs() -> FigureSet:
    ctx = BuildContext.load(FIGURES)
    return FigureSet({"soldier.fig": ctx.soldier, "DI.fig": ctx.di, "AK_47.fig": ctx.rifle})


def _hand_slide(cs, figs: FigureSet) -> float:
    """The left hand's largest slide over a run of frames on the ground (the check's measure)."""
    q, loc, stype = played_body(cs, figs)
    slide, _ = contact_slides(part_points(q, loc, figs, stype, ("left_hand",)), CONTACT_HEIGHT_CM)
    return float(slide.max())


def test_a_hand_rolling_on_the_ground_is_held_where_it_comes_to_rest(figs: FigureSet) -> None:
    """The DI stfire2dead slave's left hand lies on the ground from frame 71 on; its wrist is made to roll it
    (16 degrees to and fro, as rest_limbs' solve did): held, its nodes stay put, and the clip's last frame
    (the DEAD rest) is unchanged and the hands stay on the rifle until they let go."""
    master = load_channelset(CHANNELSETS / "stfire2dead.chset.env", use_cache=False)
    before = load_channelset(CHANNELSETS / "stfire2dead_low.chset.env", use_cache=False)
    figs = slaving_context(BuildContext.load(FIGURES), "stfire2dead", master).figure_set  # legs passive
    bf = bind_channelset(before, [figs.figures["DI.fig"]]).figures[0]
    kin = figs.kin["DI.fig"]
    wrist = kin.dof_slices["left_wrist"].start
    col = bf.src[list(bf.dst).index(wrist)]
    rolled = copy.deepcopy(before)
    f = np.arange(ROLL.start, ROLL.stop)
    rolled.joint_data[ROLL, col] += np.radians(16.0) * np.sin((f - ROLL.start) * np.pi / 12.0)
    assert _hand_slide(rolled, figs) > 3.0
    held = copy.deepcopy(rolled)
    assert slave_arms.pin_slave_arms(master, held, figs) > 0.0
    assert _hand_slide(held, figs) < 1.5
    np.testing.assert_array_equal(held.joint_data[-1], rolled.joint_data[-1])
    held_at, rolled_at = (_palms(cs, figs)[: before.release_frame + 1] for cs in (held, rolled))
    assert np.abs(held_at - rolled_at).max() < 0.1  # cm: the hands stay on the rifle until they let go


def _palms(cs, figs: FigureSet) -> np.ndarray:
    """Both palm centres ``(n, 2, 3)`` (cm)."""
    q, loc, stype = played_body(cs, figs)
    kin = figs.kin[stype]
    at = [kin.site_names.index(f"{side}_palm.palmcenter") for side in ("left", "right")]
    return kin.site_globals(q, loc)[..., :3, 3][:, at]


def test_only_stfire2dead_and_the_prone_deaths_slaves_pin_their_arms(figs: FigureSet) -> None:
    """The hold is stfire2dead's, prfire2dead's and prstow2dead's own setting (laid by the spine and no
    longer lifted with the body, prfire2dead's DI right hand slid 3.26 cm, prstow2dead's M16 right forearm
    4.30): another death's slave is left as it is."""
    pinned = {d.name for d in deaths.DEATHS if d.slave_arms_pinned}
    assert pinned == {"stfire2dead", "prfire2dead", "prstow2dead"}
    master = load_channelset(CHANNELSETS / "ststow2dead.chset.env", use_cache=False)
    slave = load_channelset(CHANNELSETS / "ststow2dead_low.chset.env", use_cache=False)
    before = slave.joint_data.copy()
    assert slave_arms.pin_slave_arms(master, slave, figs) == 0.0
    np.testing.assert_array_equal(slave.joint_data, before)


@pytest.mark.parametrize("suffix", ["_low", "_m16_low"])
def test_stfire2dead_slaves_hands_lie_still(figs: FigureSet, suffix: str) -> None:
    """The committed DI/M16 stfire2dead slaves: no hand or forearm slides past the check's 3 cm (4.0 cm
    before)."""
    ctx = BuildContext.load(FIGURES)
    figs = FigureSet(
        {"soldier.fig": ctx.soldier, "DI.fig": ctx.di, "AK_47.fig": ctx.rifle, "M16.fig": ctx.m16}
    )
    slave = load_channelset(CHANNELSETS / f"stfire2dead{suffix}.chset.env", use_cache=False)
    out = check_clip(slave, figs, ends_dead=True)
    arms = {p: v for p, v in out["contact_slides"].items() if p.endswith(("_hand", "_forearm"))}
    assert max(arms.values()) <= 1.5, arms
    assert out["contact_slide_cm"] <= 3.0
