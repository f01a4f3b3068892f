"""Gait selection on the shipped library (issue 16): the velocity's angle to the heading picks forward walk,
backward walk or side-step; speed picks walk or run with hysteresis; playback stays within human cadence.

Scenario tests through the core: DIS-like entity requests at explicit times (``now`` passed in), no clocks."""

from __future__ import annotations

import functools
import math
from pathlib import Path

import pytest

from protocol.entity import Appearance, WeaponState, make_entity_requests
from server.soldier.library import MotionLibrary
from server.soldier.manager import MAX_RATE, REQUEST_OK, WALK_MAX_RATE, SoldierManager
from server.startup import ServerWorld

REPO = Path(__file__).resolve().parent.parent


@functools.cache
def shipped_library() -> MotionLibrary:
    """The library a plain server builds from this checkout (``posture_graphs/``, ``channelsets/``)."""
    world = ServerWorld(REPO)
    world.run_startup("jack-ttes-soldier_low.jcl")
    assert world.library is not None
    return world.library


@pytest.fixture(scope="module")
def lib() -> MotionLibrary:
    return shipped_library()


def soldier(lib) -> tuple[SoldierManager, int]:
    m = SoldierManager(lib, record_clips=True, throttle=0.0)
    return m, m.create_soldier(figure="DI.fig", weapon="AK_47.fig", now=0.0)


def move(
    m: SoldierManager, i: int, now: float, speed: float, angle: float = 0.0, heading: float = 0.0
) -> None:
    """A request: ``speed`` m/s at ``angle`` compass degrees from the ``heading`` (90: to the right)."""
    a = math.radians(heading + angle)
    vel = (speed * math.sin(a), speed * math.cos(a), 0.0)
    rows = make_entity_requests(i, Appearance.UPRIGHT, WeaponState.DEPLOYED, vel, heading, (0, 0, 0))
    assert m.apply_requests(rows, now).tolist() == [REQUEST_OK]


def run(m: SoldierManager, t0: float, t1: float, hz: float = 30.0) -> None:
    for k in range(math.ceil(t0 * hz - 1e-9), math.floor(t1 * hz + 1e-9) + 1):
        m.tick(k / hz)


def gaits(m: SoldierManager, i: int, since: float = 0.0) -> list[str]:
    """The clip families played since ``since``, repeats collapsed (``walk_cycle_l`` → ``walk_cycle``)."""
    out: list[str] = []
    for c in m.clips_of(i):
        if c.time < since - 1e-9:
            continue
        name = c.clip.rsplit("/", 1)[-1].removesuffix("_low")
        name = name[:-2] if name[-2:] in ("_l", "_r") and "sidestep" not in name else name
        if not out or out[-1] != name:
            out.append(name)
    return out


def test_the_server_library_has_turns_side_steps_and_reactions(lib) -> None:
    assert lib.can_walk and lib.can_run and lib.can_side and lib.turn is not None and lib.react is not None
    for stem in ("turn_l90", "turn_r180", "sidestep_l", "stfire_recoil", "ststow_flinch"):
        lib.clip_id(stem + "_low")


@pytest.mark.parametrize(
    ("angle", "clip"), [(-90.0, "sidestep_l"), (90.0, "sidestep_r"), (-70.0, "sidestep_l")]
)
def test_sideways_velocity_side_steps_and_stopping_rests(lib, angle: float, clip: str) -> None:
    m, i = soldier(lib)
    move(m, i, 0.0, 0.3, angle, heading=40.0)
    run(m, 0.0, 4.0)
    assert gaits(m, i) == [clip]
    assert len(m.clips_of(i)) >= 2  # it repeats while the velocity stays sideways
    move(m, i, 4.0, 0.0, heading=40.0)
    run(m, 4.0, 7.0)
    assert m.soldier_info(i)["mode"] == "IDLE"
    move(m, i, 7.0, 1.2, 20.0, heading=40.0)  # mostly ahead: a forward walk
    run(m, 7.0, 9.0)
    assert gaits(m, i, 7.0)[:2] == ["walk_start", "walk_cycle"]


def test_turning_the_velocity_sideways_while_walking_ends_the_walk_then_side_steps(lib) -> None:
    m, i = soldier(lib)
    move(m, i, 0.0, 1.2)
    run(m, 0.0, 2.0)
    move(m, i, 2.0, 0.4, 90.0)
    run(m, 2.0, 6.0)
    assert gaits(m, i) == ["walk_start", "walk_cycle", "walk_end", "sidestep_r"]


def test_walk_run_switch_near_two_metres_per_second_with_hysteresis(lib) -> None:
    m, i = soldier(lib)
    move(m, i, 0.0, 1.8)
    run(m, 0.0, 3.0)
    assert "run_cycle" not in gaits(m, i)  # 1.8 m/s walks
    move(m, i, 3.0, 2.6)
    run(m, 3.0, 6.0)
    assert gaits(m, i, 3.0)[-2:] == ["walk2run", "run_cycle"]  # 2.6 m/s runs
    move(m, i, 6.0, 2.2)  # inside the hysteresis band: a runner keeps running
    run(m, 6.0, 8.0)
    assert gaits(m, i, 6.0) == ["run_cycle"]
    move(m, i, 8.0, 1.8)
    run(m, 8.0, 10.0)
    assert gaits(m, i, 8.0)[-2:] == ["run2walk", "walk_cycle"]
    move(m, i, 10.0, 2.2)  # and a walker keeps walking
    run(m, 10.0, 12.0)
    assert gaits(m, i, 10.0) == ["walk_cycle"]


def test_a_run_from_rest_at_2_6_and_a_walk_from_rest_at_1_8(lib) -> None:
    for speed, first in ((2.6, "run_start"), (1.8, "walk_start")):
        m, i = soldier(lib)
        move(m, i, 0.0, speed)
        run(m, 0.0, 1.5)
        assert gaits(m, i)[0] == first


def test_cadence_stays_human_and_the_stride_takes_the_rest(lib) -> None:
    m, i = soldier(lib)
    move(m, i, 0.0, 7.0)  # a sprint: 7 m/s on a 3.37 m/s recording
    run(m, 0.0, 4.0)
    cycles = [c for c in m.clips_of(i) if "run_cycle" in c.clip]
    stored = lib.clip_duration[lib.clip_id(cycles[-1].clip)]
    steps_per_s = 1.0 / cycles[-1].duration
    assert cycles[-1].duration == pytest.approx(stored / MAX_RATE)
    assert 1.7 <= steps_per_s <= 4.6


def test_a_fast_walk_steps_at_race_walking_cadence(lib) -> None:
    """A walker keeps walking up to the walk->run switch (2.4 m/s): up to 3.3 steps/s, no stride scaling."""
    m, i = soldier(lib)
    move(m, i, 0.0, 2.0)
    run(m, 0.0, 3.0)
    move(m, i, 3.0, 2.35)
    run(m, 3.0, 7.0)
    cycles = [c for c in m.clips_of(i) if "walk_cycle" in c.clip]
    stored = lib.clip_duration[lib.clip_id(cycles[-1].clip)]
    assert "run_cycle" not in gaits(m, i)
    assert cycles[-1].duration == pytest.approx(
        stored / (2.35 / lib.clip_ground_speed[lib.clip_id(cycles[-1].clip)]), rel=0.03
    )
    assert 1.0 / cycles[-1].duration <= 1.0 / (stored / WALK_MAX_RATE) <= 3.3


def rest(m: SoldierManager, i: int, now: float, app: int, weapon: int) -> None:
    rows = make_entity_requests(i, app, weapon, (0.0, 0.0, 0.0), 0.0, (0, 0, 0))
    assert m.apply_requests(rows, now).tolist() == [REQUEST_OK]


@pytest.mark.parametrize(
    ("app", "weapon", "recoil", "flinch"),
    [
        (Appearance.UPRIGHT, WeaponState.FIRING, "stfire_recoil", "stfire_flinch"),
        (Appearance.KNEEL, WeaponState.FIRING, "kfire_recoil", "kfire_flinch"),
        (Appearance.PRONE, WeaponState.FIRING, "prfire_recoil", "prfire_flinch"),
        (Appearance.UPRIGHT, WeaponState.DEPLOYED, None, "ststow_flinch"),
        (Appearance.CRAWL, WeaponState.DEPLOYED, None, "crawl_flinch"),
    ],
)
def test_fire_recoils_and_a_near_detonation_flinches_in_the_posture_held(
    lib, app: int, weapon: int, recoil: str | None, flinch: str
) -> None:
    m, i = soldier(lib)
    rest(m, i, 0.0, app, weapon)
    run(m, 0.0, 8.0)  # there
    posture = m.soldier_info(i)["posture"]
    got = m.react(i, "recoil", 8.0)
    assert (got.rsplit("/", 1)[-1].removesuffix("_low") if got else None) == recoil
    if got:
        run(m, 8.0, 8.0 + lib.clip_duration[lib.clip_id(got)] + 0.1)
        assert m.soldier_info(i)["posture"] == posture and m.soldier_info(i)["mode"] == "IDLE"
    t = 12.0
    run(m, 8.0, t)
    got = m.react(i, "flinch", t)
    assert got is not None and got.rsplit("/", 1)[-1].removesuffix("_low") == flinch
    run(m, t, t + 3.0)
    assert m.soldier_info(i)["posture"] == posture


def test_a_stepping_soldier_does_not_react(lib) -> None:
    m, i = soldier(lib)
    move(m, i, 0.0, 1.4)
    run(m, 0.0, 2.0)
    assert m.react(i, "flinch", 2.0) is None and m.soldier_info(i)["mode"] == "LOCO"


def test_a_shot_asked_with_the_firing_posture_recoils_once_the_rifle_is_up(lib) -> None:
    """A Fire PDU turns into weapon FIRING and RECOIL at one instant: the soldier raises his rifle (a posture
    change) and the recoil he kept plays when that ends, in the firing posture."""
    m, i = soldier(lib)
    rest(m, i, 0.0, Appearance.UPRIGHT, WeaponState.FIRING)
    assert m.soldier_info(i)["mode"] == "TRANSITION"
    assert m.react(i, "recoil", 0.0) is None  # kept, not refused
    run(m, 0.0, 4.0)
    assert gaits(m, i)[-1] == "stfire_recoil"
    assert m.soldier_info(i)["posture"] == "STAND_FIRE" and m.soldier_info(i)["mode"] == "IDLE"


def test_a_burst_recoils_shot_after_shot_and_a_stale_reaction_is_dropped(lib) -> None:
    m, i = soldier(lib)
    rest(m, i, 0.0, Appearance.UPRIGHT, WeaponState.FIRING)
    run(m, 0.0, 5.0)
    for k in range(3):  # three shots 0.1 s apart: one plays, one waits, the third replaces the waiting one
        m.react(i, "recoil", 5.0 + 0.1 * k)
    run(m, 5.0, 7.0)
    starts = [c for c in m.clips_of(i) if c.clip.endswith("stfire_recoil_low")]
    # the shot's recoil starts at its first moving frame (a request's start), the kept one at its end
    assert len(starts) == 2 and starts[0].skipped > 0.0 and starts[1].skipped == 0.0
    assert starts[1].time == pytest.approx(starts[0].time + starts[0].duration - starts[0].skipped)
    # a flinch kept through a long posture change (stand -> prone) is too old when it ends
    rest(m, i, 7.0, Appearance.PRONE, WeaponState.DEPLOYED)
    m.react(i, "flinch", 7.0)
    run(m, 7.0, 15.0)
    assert "prstow_flinch" not in gaits(m, i, since=7.0) and m.soldier_info(i)["posture"] == "PRONE_STOWED"
