"""Resting parts do not rise after rest (authoring/quality_rest.py, issue 14): once a dead body's pelvis and
chest are down, no foot, heel or knee lifts more than 3 cm off where it lay; the committed face-down deaths
that authoring/dead_legs.py turns out keep to it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from authoring.quality import check_clip
from authoring.quality_frames import FigureSet, play
from authoring.quality_rest import RISE_LIMIT_CM, _heights, rest_frame, rest_rise, rise_after
from server.motion.cache import load_channelset
from ttes.paths import FIGURES

CHANNELSETS = Path(__file__).resolve().parents[1] / "channelsets"
# the clips whose legs dead_legs turns out: soldier, the DI slaves, the M16 slaves
TURNED = [
    f"{c}2dead{s}"
    for c in ("ststow", "stfire", "crawl", "prstow", "prfire")
    for s in ("", "_low", "_m16_low")
]


def test_a_leg_kicked_up_after_the_body_landed_is_seen() -> None:
    """A constructed fall: the torso lands at frame 4; the foot lies at 1 cm, rises 14 cm and is laid down."""
    torso = np.array([40.0, 30.0, 15.0, 5.0, 1.0, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5])
    foot = np.array([20.0, 15.0, 8.0, 3.0, 1.0, 1.0, 6.0, 15.0, 9.0, 2.0, 0.5])
    h = {"pelvis": torso, "chest": torso + 1.0, "left_foot": foot}
    start = rest_frame(h)
    assert start == 4
    assert rise_after(h, start) == (14.0, "left_foot", 7)
    h["left_foot"] = np.minimum(foot, 1.0)  # laid still: the fall's own drop is no rise
    assert rise_after(h, start) == (0.0, None, None)


@pytest.fixture(scope="module")
def figures() -> FigureSet:
    return FigureSet.from_dir(FIGURES, ["soldier.fig", "DI.fig", "M16.fig", "AK_47.fig"])


# none left: stfire2dead's left knee rebounded 3.9 cm 0.1 s after the torso was down (the physics); its
# legs rolled into their passive range as he lands (authoring.deaths.DeathSpec.legs_roll), 2.5 cm
PHYSICS_REBOUND: set[str] = set()


@pytest.mark.parametrize(
    "clip",
    [
        pytest.param(c, marks=pytest.mark.xfail(strict=True, reason="physics rebound"))
        if c in PHYSICS_REBOUND
        else c
        for c in TURNED
    ],
)
def test_a_dead_body_s_legs_do_not_rise_after_it_has_landed(clip: str, figures: FigureSet) -> None:
    cf = play(load_channelset(CHANNELSETS / f"{clip}.chset.env"), figures)
    row = rest_rise(cf, figures)
    assert row["rest_frame"] is not None
    assert row["rest_rise_cm"] <= RISE_LIMIT_CM, row


def test_the_check_sees_a_dead_hand_raised_after_he_lies_still(figures: FigureSet) -> None:
    """kfire2dead's arm fall once swung the right hand up over the head 1.2 s after the body lay still (the
    contact sheet showed it, side view, 2.60 s; 18.6 cm): a hand lifted so after rest is seen, and only in a
    clip that ends in DEAD. (The arm fall no longer lifts it: tests/test_dead_arms.py.)"""
    cf = play(load_channelset(CHANNELSETS / "kfire2dead.chset.env"), figures)
    h = _heights(cf, figures)
    start = rest_frame(h)
    assert start is not None
    lifted = h["right_hand"].copy()
    lifted[-6:] += 18.0  # raised over the still frames at the end
    assert rise_after({**h, "right_hand": lifted}, start)[:2] == (pytest.approx(18.0, abs=1.0), "right_hand")
    assert "rest_rise_cm" in check_clip(cf, figures, ends_dead=True)
    assert "rest_rise_cm" not in check_clip(cf, figures)  # measured only for a clip that ends in DEAD
