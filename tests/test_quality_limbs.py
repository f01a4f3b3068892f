"""Limbs pass through no other part of the body (issue 14): ``limb_through_cm`` on constructed clips, a man
lying straight, his thighs crossed through each other, his legs spread through the hands at his sides."""

from __future__ import annotations

import numpy as np
import pytest
from test_quality import FIGURES, _clip, _lying

from authoring.quality import THRESHOLDS, FigureSet, check_clip
from authoring.quality_limbs import LIMB_THROUGH_LIMIT_CM, OUT_OF
from peabody.loader import read_figure


@pytest.fixture(scope="module")
def figset() -> FigureSet:
    return FigureSet(
        {"DI.fig": read_figure(FIGURES / "DI.fig"), "AK_47.fig": read_figure(FIGURES / "AK_47.fig")}
    )


def _hips(figset: FigureSet, deg: float) -> dict:
    """DI lying on his back, both hips turned ``deg`` about their first axis (negative: the thighs cross)."""
    poses, body, rifle = _lying(figset)
    kin = figset.kin["DI.fig"]
    poses = poses.copy()
    for side in ("left", "right"):
        poses[:, kin.dof_slices[f"{side}_hip"].start] = np.radians(deg)
    return check_clip(_clip(f"hips{deg}.chset", figset, poses, body, rifle), figset)


def test_a_body_lying_straight_has_no_limb_through_another(figset: FigureSet) -> None:
    row = _hips(figset, 0.0)
    assert row["limb_through_cm"] == 0.0 and row["limb_through_where"] is None


def test_crossed_thighs_go_through_each_other(figset: FigureSet) -> None:
    """kstow2crawl drew the left knee 5.4 cm up through the left forearm; crossed thighs are the same."""
    row = _hips(figset, -20.0)
    assert row["limb_through_cm"] > LIMB_THROUGH_LIMIT_CM
    assert row["limb_through_where"].split()[0] in ("left_thigh", "right_thigh")
    assert "upper_leg[" in row["limb_through_where"]
    assert "limb_through_cm" in row["failures"] and THRESHOLDS["limb_through_cm"] == LIMB_THROUGH_LIMIT_CM


def test_legs_spread_through_the_hands_at_his_sides(figset: FigureSet) -> None:
    row = _hips(figset, 30.0)
    assert row["limb_through_cm"] > LIMB_THROUGH_LIMIT_CM
    assert row["limb_through_where"].startswith(("left_hand in", "right_hand in"))
    assert "limb_through_cm" in row["failures"]


def test_joined_neighbours_are_not_judged() -> None:
    """An upper arm meets the chest, a thigh the pelvis, a forearm its upper arm: they overlap at joints."""
    assert "left_upper_arm" not in OUT_OF["chest"] and "left_thigh" not in OUT_OF.get("pelvis", ())
    assert "left_forearm" not in OUT_OF["left_upper_arm"] and "left_forearm" in OUT_OF["left_thigh"]
