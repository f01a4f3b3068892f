"""A dying man does not get up (``dying_rise_cm``, issue 14): a physics variant of kstow2dead straightened
the kneeling man up off his knee until he nearly stood (pelvis 44 -> 59 cm) before he fell back, and no limit
failed. Constructed clips, the variant's heights and every shipped death."""

from __future__ import annotations

import numpy as np
import pytest
from test_quality import N, _clip, _lying, figset  # noqa: F401  (the module's figure fixture)

from authoring.quality import THRESHOLDS, FigureSet, check_clip
from authoring.quality_rising import DYING_RISE_LIMIT_CM, dying_rise
from tests.test_quality_support import CLIPS, shipped_heights

PARTS = np.array(["pelvis", "chest", "left_foot"], dtype=object)
# the kstow-s21 variant's DI slave (kstow2dead_low, /tmp/kstow-s21/vA), every 6th frame of 171 at 60 fps:
# the lowest node of the pelvis and of the chest (cm)
VARIANT_PELVIS = [43.4, 43.0, 42.5, 42.5, 42.1, 42.4, 39.7, 36.6, 42.6, 54.8, 58.6, 54.9, 45.2, 26.8, 7.9]
VARIANT_PELVIS += [8.4, 8.5, 8.6, 8.6, 8.9, 9.7, 14.6, 16.7, 9.0, 2.1, 0.5, 0.1, 0.3, 0.2]
VARIANT_CHEST = [67.2, 66.7, 64.8, 61.7, 59.2, 59.5, 56.5, 53.0, 57.9, 70.5, 75.7, 70.0, 58.4, 37.8, 7.8]
VARIANT_CHEST += [3.2, 2.3, 2.3, 2.7, 3.2, 4.2, 9.2, 10.5, 5.2, 3.2, 0.5, 0.2, 0.3, 0.2]
DEATHS = [c for c in CLIPS if "2dead" in c]


def _heights(pelvis: list[float] | np.ndarray, chest: list[float] | np.ndarray) -> np.ndarray:
    """Node heights ``(n, 3)`` of :data:`PARTS`: the pelvis, the chest, a foot on the ground."""
    return np.stack([np.asarray(pelvis), np.asarray(chest), np.zeros(len(pelvis))], axis=1)


def test_a_dying_man_rising_off_his_knee_fails() -> None:
    row = dying_rise(_heights(VARIANT_PELVIS, VARIANT_CHEST), PARTS)
    assert row["dying_rise_cm"] == pytest.approx(58.6 - 43.4) and row["dying_rise_part"] == "pelvis"
    assert row["dying_rise_cm"] > DYING_RISE_LIMIT_CM and row["dying_rise_where"].startswith(
        "pelvis at frame 10"
    )
    chest_only = dying_rise(_heights(np.linspace(43.0, 0.0, 29), VARIANT_CHEST), PARTS)
    assert chest_only["dying_rise_part"] == "chest" and chest_only["dying_rise_cm"] > DYING_RISE_LIMIT_CM


def test_a_fall_passes() -> None:
    """Knelt, he sags, bounces 2 cm as his knee gives and falls to the ground: nothing above the start."""
    t = np.linspace(0.0, 1.0, 60)
    pelvis = 44.0 * (1.0 - t**2) + 2.0 * np.sin(np.pi * t) ** 8
    row = dying_rise(_heights(pelvis, pelvis + 24.0), PARTS)
    assert row == {"dying_rise_cm": 0.0, "dying_rise_part": None, "dying_rise_where": None}
    assert dying_rise(np.zeros((5, 1)), np.array(["left_foot"], dtype=object))["dying_rise_cm"] is None


def test_the_check_fails_a_dead_body_rising(figset: FigureSet) -> None:  # noqa: F811
    """DI lying on his back 30 cm up falls to the ground (a death) and passes; lifted 20 cm as he falls (12
    above the start), fails; a clip that does not end in DEAD is not judged."""
    poses, body, rifle = _lying(figset)
    fall = np.linspace(30.0, 0.0, N)
    body[:, 1, 3] += fall
    rifle[:, 1, 3] += fall
    row = check_clip(_clip("falls.chset", figset, poses, body, rifle), figset, ends_dead=True)
    assert row["dying_rise_cm"] == 0.0 and "dying_rise_cm" not in row["failures"]
    assert THRESHOLDS["dying_rise_cm"] == DYING_RISE_LIMIT_CM
    frames = np.arange(N)
    lift = np.where(frames < N // 2, 20.0 * np.sin(np.pi * frames / (N // 2)) ** 2, 0.0)  # up ~12 cm
    body[:, 1, 3] += lift
    rifle[:, 1, 3] += lift
    row = check_clip(_clip("rises.chset", figset, poses, body, rifle), figset, ends_dead=True)
    assert row["dying_rise_cm"] > DYING_RISE_LIMIT_CM and "dying_rise_cm" in row["failures"], row
    assert row["dying_rise_part"] in ("pelvis", "chest")
    assert "dying_rise_cm" not in check_clip(_clip("rises.chset", figset, poses, body, rifle), figset)


@pytest.mark.parametrize("clip", DEATHS)
def test_no_shipped_death_rises(clip: str) -> None:
    heights, parts, _ = shipped_heights(clip)
    assert dying_rise(heights, parts)["dying_rise_cm"] <= DYING_RISE_LIMIT_CM
