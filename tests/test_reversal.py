"""A soldier walking one way who is asked to walk the other way (issue 16): DIS entities reverse at once
(velocity and heading flip in one PDU); a person stops, pivots and walks away. Measured as an image
generator would see it (tests/test_root_motion.py's ``drive``): every sole point planted in the world while
it is down (≤ 2 cm), the figure's facing never jumps more than MAX_YAW_STEP_DEG between two 60 Hz frames,
and the figure catches up with its entity afterwards."""

from __future__ import annotations

import numpy as np
import pytest

from protocol.entity import Appearance, WeaponState, make_entity_requests
from server.soldier.core import WALK_MAX_RATE
from server.soldier.manager import SoldierManager
from server.soldier.turning import REVERSAL_TURN_SPEEDUP
from tests.test_gait_selection import move, run, shipped_library
from tests.test_root_motion import HZ, SKATE_CM, drive, skates, yaw_steps

MAX_YAW_STEP_DEG = 6.0  # degrees per 60 Hz frame (360°/s): faster reads as a snap
T_REVERSE, T_STOP, T_END = 4.0, 20.0, 23.0


@pytest.fixture(scope="module", params=[180.0, 170.0, -170.0], ids=["180", "170", "-170"])
def reversal(request, lib) -> tuple[float, dict[str, np.ndarray]]:  # type: ignore[no-untyped-def]
    turn = request.param
    script = [(0.0, 0.0, 0.0), (0.5, 1.4, 0.0), (T_REVERSE, 1.4, 0.0, 20.0 + turn), (T_STOP, 0.0, 0.0)]
    return turn, drive(lib, script, heading=20.0, until=T_END)


@pytest.fixture(scope="module")
def lib():  # type: ignore[no-untyped-def]
    return shipped_library()


def test_a_reversal_stops_pivots_on_planted_feet_and_walks_away(reversal) -> None:  # type: ignore[no-untyped-def]
    turn, played = reversal
    clips = [c.rsplit("/", 1)[-1].removesuffix("_low") for c in played["clips"].tolist()]
    after = clips[int(T_REVERSE * HZ) :]
    families = [c[:-2] if c[-2:] in ("_l", "_r") else c for c in after]
    seq = [f for k, f in enumerate(families) if k == 0 or families[k - 1] != f]
    side = "r" if turn > 0 else "l"
    assert seq[:4] == ["walk_cycle", "walk_end", f"turn_{side}180", "walk_start"], seq
    slides = skates(played, T_REVERSE - 0.6, T_END)
    assert slides and max(s for s, _ in slides) <= SKATE_CM, sorted(slides)[-3:]
    assert yaw_steps(played).max() <= MAX_YAW_STEP_DEG
    # facing: the old way until the pivot, the new heading after it
    k = int(T_REVERSE * HZ)
    assert abs((played["yaw"][k + 2] - 20.0 + 180.0) % 360.0 - 180.0) < 10.0
    k = int((T_STOP - 1.0) * HZ)
    assert abs((played["yaw"][k] - 20.0 - turn + 180.0) % 360.0 - 180.0) < 10.0


def test_after_a_reversal_the_figure_catches_up_with_its_entity(reversal) -> None:  # type: ignore[no-untyped-def]
    _, played = reversal
    gap = np.linalg.norm(played["gap"], axis=1)
    t = np.arange(len(gap)) / HZ
    # the entity walked on during the stop and the pivot (~3 s): the figure trails it by up to ~5 m, then
    # catches up with faster cadence (up to ~1 m/s faster) to the usual walking lag; a stop ends within a
    # walking step of it (74 cm: by the phase it falls in, a plain walk's stop ends 1-61 cm from the entity,
    # the shorter end step after a step just ended ~70)
    assert gap.max() < 500.0
    assert gap[(t > T_STOP - 1.0) & (t < T_STOP)].mean() < 110.0  # walking: 37 + 53 cm, as any walk
    assert gap[t > T_END - 0.5].max() < 74.0


def caught_up(played: dict[str, np.ndarray], since: float, steady: tuple[float, float]) -> float:
    """Seconds after ``since`` until the figure's gap to its entity stays within 5 cm of its steady walking
    gap (the mean over the ``steady`` window, s)."""
    gap = np.linalg.norm(played["gap"], axis=1)
    t = np.arange(len(gap)) / HZ
    usual = gap[(t >= steady[0]) & (t < steady[1])].mean()
    off = np.flatnonzero((np.abs(gap - usual) > 5.0) & (t < steady[1]))
    return float(t[off[-1]] - since) if len(off) else 0.0


def test_the_lag_a_reversal_leaves_is_closed_at_a_jog(reversal) -> None:  # type: ignore[no-untyped-def]
    """The stop, the pivot and the walk start take 2.6 s (the end and start steps hurried to the walk's upper
    cadence, stepping.HURRY_RATE: 0.63 + 1.37 + 0.57 s; at their recorded pace 1.13 + 1.37 + 1.02 = 3.5 s)
    while the entity walks on at 1.4 m/s: the figure falls 3.3-3.9 m further behind than a walker's usual
    0.9 m (was 4.6-5.2; no root offset keeps planted feet nearer). More than 2 m behind that, it jogs
    (walk2run, run cycles closing ~1.4 m/s, core.CATCH_UP_RUN_CM) and walks again within 80 cm of the run's
    lag, the walk's faster cadence closing the rest (up to core.WALK_MAX_RATE): back within 5 cm of the
    usual lag 6.1-7.5 s after the reversal (was 8.0-9.4 s; 12.9 s at most 1.5 times the entity's speed)."""
    _, played = reversal
    gap = np.linalg.norm(played["gap"], axis=1)
    assert gap.max() < 140.0 * (0.55 + 2.57) + 93.0  # the entity walks on over the step under way and these
    assert "run_cycle" in [c.rsplit("/", 1)[-1].removesuffix("_low")[:-2] for c in played["clips"].tolist()]
    assert caught_up(played, T_REVERSE, (T_STOP - 2.0, T_STOP)) < 8.0


def paces(lib, script: list[tuple[float, ...]], until: float, since: float) -> dict[str, float]:  # type: ignore[no-untyped-def]
    """Play ``(time, speed m/s, new heading)`` requests; per clip family the seconds its first clip from
    ``since`` s on took."""
    m = SoldierManager(lib, throttle=0.0, record_clips=True)
    i = m.create_soldier(now=0.0)
    for k, (t, speed, heading) in enumerate(script):
        move(m, i, t, speed, 0.0, heading=heading)
        run(m, t, script[k + 1][0] if k + 1 < len(script) else until)
    out: dict[str, float] = {}
    for c in m.clips_of(i):
        name = c.clip.rsplit("/", 1)[-1].removesuffix("_low")
        if c.time >= since - 1e-9:
            out.setdefault(name[:-2] if name[-2:] in ("_l", "_r") else name, c.duration - c.skipped)
    return out


def test_a_reversal_hurries_its_stop_and_its_start(lib) -> None:  # type: ignore[no-untyped-def]
    """A person stopping to turn back, and setting off after the turn, steps at his upper cadence: the end
    step (1.13 s recorded) and the start step after the pivot (1.02 s) play at core.WALK_MAX_RATE; the pivot
    stays at turning.REVERSAL_TURN_SPEEDUP (its in-place steps already ~0.2 s each, a sprinter's cadence).
    Starting from standing facing the heading, and a plain stop, keep their recorded pace (the start less its
    still first frame, skipped as a request's start: lead_in)."""
    took = paces(lib, [(0.5, 1.4, 20.0), (T_REVERSE, 1.4, 200.0)], 8.0, T_REVERSE)
    assert took["walk_end"] == pytest.approx(1.133 / WALK_MAX_RATE, abs=0.01)
    assert took["turn_r180"] == pytest.approx(3.667 / REVERSAL_TURN_SPEEDUP, abs=0.01)
    assert took["walk_start"] == pytest.approx(1.017 / WALK_MAX_RATE, abs=0.01)
    plain = paces(lib, [(0.5, 1.4, 20.0), (T_REVERSE, 0.0, 20.0)], 7.0, 0.0)
    assert (plain["walk_start"], plain["walk_end"]) == pytest.approx((1.017 - 1 / 60, 1.133), abs=0.01)


@pytest.mark.parametrize("turn", [120.0, -120.0, 130.0, -130.0, 135.0, -135.0, 140.0, -140.0, 150.0, -160.0])
def test_a_near_reversal_pivots_too_its_rest_turned_about_the_planted_foot(lib, turn: float) -> None:  # type: ignore[no-untyped-def]
    """135-180°: the 180° pivot alone, what it turns too much turned back over it, about the foot carrying
    the weight while one foot alone is down (its middle while it is flat), at most 9° per such stance
    (turning.PIVOT_REST_PER_STANCE_DEG; each degree twists the heel and ball ~0.2 cm): 135° 1.8 cm, 140°
    1.6-1.7 (was the 180° pivot and a 45° turn back), 150° 1.3, 160° 1.0. 120-134°: the 90° pivot would turn
    10° and more per stance (2.0-2.7 cm), so the 90° and then the 45° (0.7-1.5 cm); these turned over the
    steps while walking (below turning.REVERSAL_DEG, then 135°) and slid 9.4-9.8 cm."""
    script = [(0.0, 0.0, 0.0), (0.5, 1.4, 0.0), (T_REVERSE, 1.4, 0.0, 20.0 + turn), (12.0, 0.0, 0.0)]
    played = drive(lib, script, heading=20.0, until=12.0)
    clips = [c.rsplit("/", 1)[-1].removesuffix("_low") for c in played["clips"].tolist()]
    turns = [c for k, c in enumerate(clips) if c.startswith("turn_") and (k == 0 or clips[k - 1] != c)]
    side = "r" if turn > 0 else "l"
    assert turns == ([f"turn_{side}180"] if abs(turn) >= 135.0 else [f"turn_{side}90", f"turn_{side}45"])
    assert max(s for s, _ in skates(played, T_REVERSE - 0.6, 12.0)) <= SKATE_CM
    assert yaw_steps(played).max() <= MAX_YAW_STEP_DEG
    assert abs((played["yaw"][int(11.5 * HZ)] - 20.0 - turn + 180.0) % 360.0 - 180.0) < 10.0


def test_a_snap_during_the_pivot_ends_it(lib) -> None:  # type: ignore[no-untyped-def]
    """An ``immediate`` request while the figure pivots: it rests at once; the pivot's extra turn stops (a
    standing turn in place may follow, as for any standing figure facing away from its heading, with its own
    rest: what its clip turns too much, -3.3° here, not the pivot's -10°)."""
    m = SoldierManager(lib, throttle=0.0, record_clips=True)
    i = m.create_soldier(now=0.0)
    move(m, i, 0.5, 1.4, 0.0, heading=20.0)
    run(m, 0.5, 4.0)
    move(m, i, 4.0, 1.4, 0.0, heading=190.0)
    run(m, 4.0, 6.0)
    assert "turn_r180" in m.soldier_info(i)["clip"] and m.table.pivot_rest[i] != 0.0
    rows = make_entity_requests(
        i, Appearance.UPRIGHT, WeaponState.DEPLOYED, (0, 0, 0), 190.0, (0, 0, 0), True
    )
    m.apply_requests(rows, 6.0)
    assert not m.table.reversing[i]
    if "turn_r180" in m.soldier_info(i)["clip"]:  # the standing turn: its clip's 180° less where it faces
        rest = (180.0 - float(m.table.root_yaw[i]) + 180.0) % 360.0 - 180.0
        assert m.table.pivot_rest[i] == pytest.approx(rest) and abs(rest) < 10.0
    else:
        assert m.table.pivot_rest[i] == 0.0
