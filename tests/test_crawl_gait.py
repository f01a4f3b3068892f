"""Issue 14 on the crawl's start and stand-to-crawl: each planted limb still while planted, lifted off and set
down cleanly, nothing let go in one frame."""

from __future__ import annotations

from functools import cache
from pathlib import Path

import numpy as np
import pytest

from authoring import crawl, ik, transitions
from authoring.build import BuildContext, lift_off_ground, slave_one, slave_pair
from authoring.quality import THRESHOLDS, FigureSet, check_clip
from authoring.quality_frames import play
from authoring.slave_contacts import rest_slave_knees
from authoring.slaving import reslave_channelset
from authoring.transitions import Step
from peabody.fk import FigureKinematics
from server.motion.cache import load_channelset

ROOT = Path(__file__).resolve().parents[1]
SLIDE_LIMIT = THRESHOLDS["contact_slide_cm"]


@cache
def _context() -> BuildContext:
    return BuildContext.load(ROOT / "figures")


def test_the_forearm_planted_through_the_start_lifts_clear_before_its_arm_turns() -> None:
    """crawl_start: the right forearm stays put while the left one makes its part stride, but its arm must
    turn from the CRAWL posture's into the cycle's (the elbow twists 46 degrees): turned on the ground, its
    underside swept 3.5 cm sideways (DI 4.3). Its elbow goal rises first and the arm blends only then."""
    kin = FigureKinematics(_context().soldier)
    n_start = round(crawl.START * crawl.FPS)
    t = np.arange(n_start + 30) / crawl.FPS
    elbows = {side: np.zeros((len(t), 3)) for side in ("left", "right")}
    for track in elbows.values():  # planted, rising into the cycle's clearance as record_crawl has them
        track[:, 1] = crawl.ELBOW_CLEAR * crawl.smoothstep(t / crawl.START)
    goals = [ik.Goal(f"{side}_upper_arm.distal", elbows[side]) for side in ("left", "right")]
    start_goals, blend = crawl._start_lift(kin, t, elbows, goals, n_start)
    lifted = start_goals[1].target_position[:, 1]
    clear = round(crawl.START_CLEAR * crawl.FPS)
    assert start_goals[0] is goals[0]  # the left elbow makes its part stride as before
    assert lifted[clear] == pytest.approx(crawl.ELBOW_CLEAR + crawl.START_HOP)  # up first ...
    assert np.all(lifted[n_start:] == elbows["right"][n_start:, 1])  # down to the cycle's own track
    right = kin.dof_slices["right_elbow"]
    left = kin.dof_slices["left_elbow"]
    assert np.all(blend[: clear + 1, right] == 0.0)  # the right arm turns only once it is up
    assert blend[clear, left.start] > 0.0 and blend[-1, right.start] == 1.0


def test_a_free_step_lets_its_goal_go_over_the_fade_and_at_once_without_one() -> None:
    """ststow2crawl: the left foot's goal switched off in one frame as its free step began; the solve
    snapped the leg to the interpolated pose and the left kneecap jumped 3.6 cm (pop 1.8 m/s)."""
    times = np.arange(0.0, 1.0, 1.0 / 60.0)
    steps = (Step("left_foot", "CRAWL", 0.5, 0.3, free=True),)
    hard = transitions._goal_weight(steps, times)
    soft = transitions._goal_weight(steps, times, 0.15)
    assert isinstance(hard, np.ndarray) and isinstance(soft, np.ndarray)
    free = (times >= 0.5) & (times < 0.8)
    assert np.all(hard[free] == 0.0) and np.all(hard[~free] == 1.0)
    assert np.abs(np.diff(soft[times < 0.8])).max() < 0.2  # no frame lets go of more than a fifth of it
    assert np.all(soft[~free] == 1.0) and np.all(soft[times >= 0.65] == hard[times >= 0.65])


def test_only_ststow2crawl_fades_its_free_steps() -> None:
    fading = {t.name for t in transitions.TRANSITIONS if t.free_fade}
    assert fading == {"ststow2crawl"}


@cache
def _slaved_cycle_slides() -> tuple[dict[str, float], dict[str, float]]:
    """The DI slave of the shipped soldier crawl_cycle: its forearms' slides as slaved, then once the
    slave is lowered onto its knees (the first contact stage of authoring.build.slave_one)."""
    ctx = _context()
    master = load_channelset(ROOT / "channelsets" / "crawl_cycle.chset.env")
    slave = reslave_channelset(master, slave_pair(ctx), "crawl_cycle_low.chset")
    figures: FigureSet = ctx.figure_set

    def slides() -> dict[str, float]:
        row = check_clip(play(slave, figures), figures, locomotion=True)
        return {p: row["contact_slides"].get(f"{p}_forearm", 0.0) for p in ("left", "right")}

    slaved = slides()
    rest_slave_knees(master, slave, figures)
    lift_off_ground(slave, ctx.di)
    return slaved, slides()


def test_the_slaved_crawl_cycles_forearms_stay_put_as_the_master_has_them() -> None:
    """Where DI's cycle drags its forearms: not in the slaving (the copied arms twist as the master's, whose
    right forearm rolls 2.8 cm on the ground, DI's 2.3)..."""
    slaved, _ = _slaved_cycle_slides()
    assert max(slaved.values()) <= SLIDE_LIMIT


@pytest.mark.xfail(
    strict=True, reason="DI lowered onto its knees drags both forearms 3.5 cm (crawl_cycle_low)"
)
def test_lowering_the_slave_onto_its_knees_keeps_its_forearms_still() -> None:
    """... but in rest_slave_knees: DI's kneecap sits 1.4 cm higher than the master's, the whole slave is
    lowered by it, and its forearms, which hovered while their arms twist with the rifle's yaw, come down
    onto the ground rolling (left 0 -> 3.5 cm, right 2.3 -> 3.5); rest_slave_forearms then holds the elbows
    but not the roll (right 4.5)."""
    _, lowered = _slaved_cycle_slides()
    assert max(lowered.values()) <= SLIDE_LIMIT


@cache
def _slaved_cycle(figure: str) -> dict[str, float]:
    """The shipped soldier crawl_cycle slaved as the build slaves it: its forearms' slides."""
    ctx = _context()
    master = load_channelset(ROOT / "channelsets" / "crawl_cycle.chset.env")
    name = "crawl_cycle_low.chset" if figure == "DI" else "crawl_cycle_m16_low.chset"
    slave = slave_one(master, slave_pair(ctx), ctx, figure, name)
    row = check_clip(play(slave, ctx.figure_set), ctx.figure_set, locomotion=True)
    return {p: row["contact_slides"].get(f"{p}_forearm", 0.0) for p in ("left", "right")}


@pytest.mark.parametrize("figure", ["DI", "M16"])
def test_the_built_cycles_forearms_lie_no_longer_than_the_masters(figure: str) -> None:
    """... so the DI slave's arms are solved once more at the end (authoring.slave_forearm_lift): a forearm
    the master holds up stays up (the left one dipped to 1.2 cm and swept 3.8 cm), and the palms' turn on the
    rifle gives way by a few degrees rather than the planted right forearm rolling (4.5 -> 2.0 cm)."""
    assert max(_slaved_cycle(figure).values()) <= SLIDE_LIMIT


def test_only_the_cycles_di_slave_has_its_forearms_lifted() -> None:
    clips = {clip for _, _, clip, _ in crawl.crawl_arcs()}
    assert {c for c in clips if crawl.lifts_slave_forearms(c)} == {"crawl_cycle"}
    assert not crawl.lifts_slave_forearms("crawlarc_l30")
