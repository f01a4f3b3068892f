"""A dead arm falls down, never up (authoring/dead_arms.py, issue 14): its way is bent through a control pose
so that no part of it rises, within the joint limits; the kneeling deaths' arms lie down without rising after
the body is still."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from authoring import dead_arms
from authoring.death_specs import KFIRE_ARMS_HEADWARD
from authoring.quality import check_clip
from authoring.quality_frames import FigureSet, play
from authoring.quality_postures import rest_endpoint
from authoring.quality_rest import RISE_LIMIT_CM
from server.motion.cache import load_channelset
from ttes.paths import FIGURES

CHANNELSETS = Path(__file__).resolve().parents[1] / "channelsets"
# the highest arm part's lowest node (cm) at the end: kstow2dead's left forearm stood over the chest at 23.5
# (laid from its pose as he lands, it lies on the chest, 13.9; laid after the physics, by the head, 9.2);
# kfire2dead lies half on his side, the top arm's upper arm on the body (17.5)
REST_ARM_CM = {"kstow2dead": 15.0, "kfire2dead": 18.0}


def test_a_rise_is_measured_above_the_lowest_before() -> None:
    lows = np.array([[10.0, 20.0], [8.0, 21.0], [9.5, 15.0], [4.0, 14.0]])
    assert dead_arms.rises(lows) == pytest.approx(1.5)  # the first part: 8 -> 9.5
    assert dead_arms.rises(np.minimum.accumulate(lows, axis=0)) == 0.0


@given(st.lists(st.floats(-1.0, 1.0), min_size=9, max_size=9), st.integers(0, 2**31 - 1))
def test_a_bent_way_stays_within_the_limits_and_ends_where_asked(c: list[float], seed: int) -> None:
    rng = np.random.default_rng(seed)
    lo, hi = -np.ones(9), np.ones(9)
    x0, x1 = rng.uniform(lo, hi), rng.uniform(lo, hi)
    way = dead_arms.bent(x0, np.array(c), x1, np.linspace(0.0, 1.0, 17))
    assert np.allclose(way[0], x0) and np.allclose(way[-1], x1)
    assert (way >= lo - 1e-12).all() and (way <= hi + 1e-12).all()
    assert np.abs(np.diff(way, axis=0)).max() <= 2.0 * 2.0 / 16 + 1e-9  # smooth: no leap between steps


@pytest.fixture(scope="module")
def figures() -> FigureSet:
    return FigureSet.from_dir(FIGURES, ["soldier.fig", "AK_47.fig"])


@pytest.mark.parametrize("clip", sorted(REST_ARM_CM))
def test_a_kneeling_death_s_arms_lie_down_without_rising(clip: str, figures: FigureSet) -> None:
    """kfire2dead's right hand swung up over the head 1.2 s after he lay still (rest_rise 18.6 cm);
    kstow2dead ended with the left forearm raised over the chest (rest_arm 23.5 cm)."""
    cf = play(load_channelset(CHANNELSETS / f"{clip}.chset.env"), figures)
    row = check_clip(cf, figures, ends_dead=True)
    assert row["rest_rise_cm"] <= RISE_LIMIT_CM, (row["rest_rise_part"], row["rest_rise_cm"])
    assert row["end_speed_m_s"] <= 0.5
    rest = rest_endpoint(cf, cf.channelset.nframes - 1, figures, "DEAD")
    assert rest["rest_arm_cm"] <= REST_ARM_CM[clip], (rest["rest_arm"], rest["rest_arm_cm"])


def test_a_way_into_the_body_is_weighed_against_the_body_alone(figures: FigureSet) -> None:
    """Review finding: path_cost weighed how deep the forearm and hand go into the body against a baseline
    that counted the rifle in the arm too (``_Arm.inside0``), so a rifle lying in the arm let the hand go as
    deep into the chest. A way of KNEEL_FIRE's left arm (the shoulder swung round, 6.8 cm into the body) is
    penalised whatever the rifle did."""
    from authoring import dead_settle

    cf = play(load_channelset(CHANNELSETS / "kfire2dead.chset.env"), figures)
    two = FigureSet({"body": figures.figures["soldier.fig"], "rifle": figures.figures["AK_47.fig"]})
    q, root = cf.poses["soldier.fig"][0], cf.locations["soldier.fig"][0]
    body = dead_settle._Body(two, q.astype(float), root.astype(float), cf.locations["AK_47.fig"][0])
    arm = dead_settle._Arm(body, "left")
    x1 = arm.x0.copy()
    x1[3] = body.kin.upper[arm.idx][3]  # the shoulder's second angle at its limit: the arm across the chest
    mid = (arm.x0 + x1) / 2.0
    honest = dead_arms.path_cost(arm, arm.x0, x1)(mid)
    assert honest >= dead_arms.PENALTY * 5.0
    arm.inside0 = 10.0  # as if the rifle had lain 10 cm deep in the arm where it was
    assert dead_arms.path_cost(arm, arm.x0, x1)(mid) == honest


# degrees: kfire2dead's top (right) arm as the search laid it curled over his head (clavicle 2, shoulder 3,
# elbow 2, wrist 2; issue 14, main before session 15)
OVER_THE_HEAD = (40.0, -25.0, 121.0, -30.0, -60.0, 90.0, -87.0, -30.0, -34.0)


def _kfire_last(figures: FigureSet, right_arm: tuple[float, ...] | None = None):
    """The body of the committed kfire2dead's last frame (its right arm at ``right_arm`` degrees)."""
    from authoring import dead_settle

    cf = play(load_channelset(CHANNELSETS / "kfire2dead.chset.env"), figures)
    two = FigureSet({"body": figures.figures["soldier.fig"], "rifle": figures.figures["AK_47.fig"]})
    q, root = cf.poses["soldier.fig"][-1].astype(float), cf.locations["soldier.fig"][-1].astype(float)
    body = dead_settle._Body(two, q, root, cf.locations["AK_47.fig"][-1])
    if right_arm is not None:
        body.q[dead_settle._Arm(body, "right").idx] = np.radians(right_arm)
    return two, body


def test_an_arm_over_the_head_is_wrong_only_where_the_death_asks(figures: FigureSet) -> None:
    """kfire2dead's top (right) arm lay curled over his head (issue 14): with the death's
    ``arms_headward_cm`` its forearm and hand reaching past the shoulders up the spine count as wrong, and
    the arm-fall search weighs them; without it (every other death) nothing changes."""
    from authoring import dead_settle

    _, body = _kfire_last(figures, OVER_THE_HEAD)
    arm = dead_settle._Arm(body, "right")
    p = arm.into(arm.x0)[0]
    assert arm.overhead(p) == 0.0  # headward_cm None: anywhere
    body.headward_cm = KFIRE_ARMS_HEADWARD
    over = arm.overhead(p)
    assert over > 5.0
    assert arm.terms(arm.x0)[2] >= over


def test_kfire2dead_s_arms_lie_not_over_his_head(figures: FigureSet) -> None:
    """Issue 14: kfire2dead's top arm ended curled over his head, its forearm and hand 47.8 cm past his
    shoulders up the spine; now neither arm's reaches past them by more than 15 (its search keeps them
    within 5 of the shoulders as they were when he came down; the clavicle moves as the arm falls: 10.7)."""
    from authoring import dead_settle

    _, body = _kfire_last(figures)
    body.headward_cm = 0.0  # overhead: the whole reach past the shoulders
    for side in ("left", "right"):
        arm = dead_settle._Arm(body, side)
        assert arm.overhead(arm.into(arm.x0)[0]) <= 15.0, side


def test_only_the_arm_over_the_head_is_laid_anew(figures: FigureSet, monkeypatch: pytest.MonkeyPatch) -> None:
    """The arms fall as every death's do; then an arm that lies over the head is laid again from its pose as
    he came down, against the other where it lies: kfire2dead's bottom arm, laid anew with both, swept his
    upper arm along the ground and the turn after it slid his belly 3.96 cm."""
    from authoring import dead_settle

    two, start = _kfire_last(figures)
    start.headward_cm = KFIRE_ARMS_HEADWARD
    target = start.q.copy()
    right = dead_settle._Arm(start, "right").idx
    target[right] = np.radians(OVER_THE_HEAD)
    laid: list[tuple[str, np.ndarray]] = []

    def fallen_arm(body, side: str) -> np.ndarray:
        laid.append((side, body.q.copy()))
        return start.q[dead_settle._Arm(body, side).idx]

    monkeypatch.setattr(dead_settle, "fallen_arm", fallen_arm)
    out, sides = dead_settle._relaid(two, start, target)
    assert sides == ("right",) and [s for s, _ in laid] == ["right"]
    left = dead_settle._Arm(start, "left").idx
    np.testing.assert_array_equal(laid[0][1][left], target[left])  # against the other arm where it lies
    np.testing.assert_array_equal(laid[0][1][right], start.q[right])  # from its own pose
    np.testing.assert_array_equal(out[left], target[left])
