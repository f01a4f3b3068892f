"""Lying on the ground, his feet are not held up (``lying_feet_raised_s``, issue 14: crawl2prstow held both
feet 8-15 cm up for 0.9 s as he turned over on his belly, a "superman" pose): constructed clips, and every
shipped clip."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from authoring.postures import lowest_point
from authoring.quality import THRESHOLDS, FigureSet, check_clip
from authoring.quality_lying import FEET_RAISED_CM, LYING_PELVIS_CM, RAISED_LIMIT_S, lying_feet_raised
from peabody.loader import read_figure
from server.motion.channelset import Channelset
from server.motion.recording import Recording, recording_to_channelset
from tests.test_quality_support import CLIPS, shipped_heights

ROOT = Path(__file__).resolve().parents[1]
N = 61  # frames: 1 s at 60 fps
PARTS = np.array(["pelvis", "left_foot", "right_foot"], dtype=object)


def _lying(bend: np.ndarray) -> Channelset:
    """DI lying face down on the ground, both knees bent by ``bend`` (rad, per frame): his feet rise."""
    di = read_figure(ROOT / "figures/DI.fig")
    figset = FigureSet({"DI.fig": di})
    kin = figset.kin["DI.fig"]
    face_down = np.eye(4)
    face_down[1:3, 1:3] = [[0.0, 1.0], [-1.0, 0.0]]  # about +X by -90 degrees: the front (-Z) points down
    rec = Recording([di])
    for b in bend:
        q = kin.neutral_pose()
        for side in ("left", "right"):
            q[kin.dof_slices[f"{side}_knee"]] = b
        loc = face_down.copy()
        loc[1, 3] = -float(lowest_point(kin, q[None], loc[None])[0])  # the lowest node on the ground
        rec.append("DI", q, "lower_torso.proximal", loc)
    return recording_to_channelset("prone.chset", rec, 0, len(bend) - 1, 60.0)


@pytest.fixture(scope="module")
def figset() -> FigureSet:
    return FigureSet({"DI.fig": read_figure(ROOT / "figures/DI.fig")})


def test_a_body_lying_with_both_feet_held_up_fails(figset: FigureSet) -> None:
    t = np.arange(N) / 60.0
    held = np.radians(25.0) * np.clip(np.minimum(t - 0.1, 0.9 - t) / 0.1, 0.0, 1.0)  # up 0.1-0.9 s
    row = check_clip(_lying(held), figset)
    assert row["lying_feet_raised_s"] > RAISED_LIMIT_S and "lying_feet_raised_s" in row["failures"], row
    assert THRESHOLDS["lying_feet_raised_s"] == RAISED_LIMIT_S
    kick = np.radians(25.0) * np.clip(np.minimum(t - 0.1, 0.4 - t) / 0.1, 0.0, 1.0)  # a kick, 0.1-0.4 s
    row = check_clip(_lying(kick), figset)
    assert 0.0 < row["lying_feet_raised_s"] <= RAISED_LIMIT_S and "lying_feet_raised_s" not in row["failures"]
    row = check_clip(_lying(np.zeros(N)), figset)  # lying flat
    assert row["lying_feet_raised_s"] == 0.0 and row["lying_feet_raised_where"] is None


def test_only_both_feet_up_while_the_pelvis_lies_count() -> None:
    up, low = FEET_RAISED_CM + 4.0, FEET_RAISED_CM - 1.0
    lying = np.tile([LYING_PELVIS_CM - 1.0, up, up], (N, 1))
    row = lying_feet_raised(lying, PARTS, 60.0)
    assert row["lying_feet_raised_s"] == pytest.approx(N / 60.0, abs=1e-4)
    assert row["lying_feet_raised_where"] == f"frames 0-{N - 1}"
    one_foot = lying.copy()
    one_foot[:, 2] = low  # one leg raised, the other foot on the ground: a leg moving, not a pose
    assert lying_feet_raised(one_foot, PARTS, 60.0)["lying_feet_raised_s"] == 0.0
    kneeling = lying.copy()
    kneeling[:, 0] = LYING_PELVIS_CM + 10.0  # the pelvis up (crawling, kneeling): the feet are not judged
    assert lying_feet_raised(kneeling, PARTS, 60.0)["lying_feet_raised_s"] == 0.0


@pytest.mark.parametrize("clip", CLIPS)
def test_the_shipped_clips_lie_with_their_feet_down(clip: str) -> None:
    """crawl2prstow (all three sets) held both feet 8-15 cm up for 0.9 s; every other clip <= 0.27 s."""
    row = lying_feet_raised(*shipped_heights(clip))
    assert row["lying_feet_raised_s"] <= RAISED_LIMIT_S, row
