"""A soldier walking one way who is asked to walk the other way (issue 16): DIS entities reverse at once
(velocity and heading flip in one PDU); a person stops, pivots and walks away. Measured as an image
generator would see it (tests/test_root_motion.py's ``drive``): every sole point planted in the world while
it is down (≤ 2 cm), the figure's facing never jumps more than MAX_YAW_STEP_DEG between two 60 Hz frames,
and the figure catches up with its entity afterwards."""

from __future__ import annotations

import numpy as np
import pytest

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
    from tests.test_gait_selection import shipped_library

    return shipped_library()


def test_a_reversal_stops_pivots_on_planted_feet_and_walks_away(reversal) -> None:  # type: ignore[no-untyped-def]
    turn, run = reversal
    played = [c.rsplit("/", 1)[-1].removesuffix("_low") for c in run["clips"].tolist()]
    after = played[int(T_REVERSE * HZ) :]
    families = [c[:-2] if c[-2:] in ("_l", "_r") else c for c in after]
    seq = [f for k, f in enumerate(families) if k == 0 or families[k - 1] != f]
    side = "r" if turn > 0 else "l"
    assert seq[:4] == ["walk_cycle", "walk_end", f"turn_{side}180", "walk_start"], seq
    slides = skates(run, T_REVERSE - 0.6, T_END)
    assert slides and max(s for s, _ in slides) <= SKATE_CM, sorted(slides)[-3:]
    assert yaw_steps(run).max() <= MAX_YAW_STEP_DEG
    # facing: the old way until the pivot, the new heading after it
    k = int(T_REVERSE * HZ)
    assert abs((run["yaw"][k + 2] - 20.0 + 180.0) % 360.0 - 180.0) < 10.0
    k = int((T_STOP - 1.0) * HZ)
    assert abs((run["yaw"][k] - 20.0 - turn + 180.0) % 360.0 - 180.0) < 10.0


def test_after_a_reversal_the_figure_catches_up_with_its_entity(reversal) -> None:  # type: ignore[no-untyped-def]
    _, run = reversal
    gap = np.linalg.norm(run["gap"], axis=1)
    t = np.arange(len(gap)) / HZ
    # the entity walked on during the stop and the pivot (~4 s): the figure trails it by up to ~6 m, then
    # catches up with faster cadence (~0.7 m/s) to the usual walking lag, and a stop ends near the entity
    assert gap.max() < 650.0
    assert gap[(t > T_STOP - 1.0) & (t < T_STOP)].mean() < 110.0  # walking: 37 + 53 cm, as any walk
    assert gap[t > T_END - 0.5].max() < 47.0


@pytest.mark.parametrize("turn", [140.0, -140.0, 160.0, -160.0])
def test_a_near_reversal_pivots_too_its_rest_turned_about_the_planted_foot(lib, turn: float) -> None:  # type: ignore[no-untyped-def]
    """135-160°: the 180° pivot plus the rest (20-45° the other way) spread over it, about the sole point
    carrying the weight: the other end of that foot twists a little (measured 1.8-4.9 cm), far less than
    turning over the steps did (8-10 cm, and the figure drifted 1.7 m off its entity for good)."""
    script = [(0.0, 0.0, 0.0), (0.5, 1.4, 0.0), (T_REVERSE, 1.4, 0.0, 20.0 + turn), (12.0, 0.0, 0.0)]
    run = drive(lib, script, heading=20.0, until=12.0)
    assert any("turn_" in c for c in run["clips"].tolist())
    assert max(s for s, _ in skates(run, T_REVERSE - 0.6, 12.0)) <= 5.0
    assert yaw_steps(run).max() <= MAX_YAW_STEP_DEG
