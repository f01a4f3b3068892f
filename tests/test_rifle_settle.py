"""A let-go rifle left leaning on nothing falls again among the replayed body (authoring.rifle_settle, issue
14): balanced on its muzzle beside the dead man it tips over and lies on the ground; lying across him it stays
on him, never through him."""

from __future__ import annotations

import numpy as np
import pytest
from test_quality import _lying
from test_quality_rifle_rest import _on_ground, _rifle_points, _rot

from authoring.quality import FigureSet
from authoring.quality_rifle_rest import OVERHANG_LIMIT_CM, rifle_rest
from authoring.rifle_settle import settled
from authoring.transitions import ClipFrames
from peabody.loader import read_figure
from ttes.paths import FIGURES

pytest.importorskip("mujoco")


@pytest.fixture(scope="module")
def figset() -> FigureSet:
    return FigureSet(
        {"DI.fig": read_figure(FIGURES / "DI.fig"), "AK_47.fig": read_figure(FIGURES / "AK_47.fig")}
    )


def _settle(figset: FigureSet, rifle: np.ndarray) -> tuple[ClipFrames, np.ndarray, list[float]]:
    """DI lying on his back (20 frames), the rifle recorded still at ``rifle``, settled again: the frames,
    the last frame's segment globals and each frame's deepest rifle node in the body (cm)."""
    poses, body, _ = _lying(figset, n=20)
    frames = settled(
        ClipFrames(poses, body, np.tile(rifle, (len(poses), 1, 1)), 60.0),
        figset.figures["DI.fig"],
        figset.figures["AK_47.fig"],
    )
    kin, hulls = figset.kin["DI.fig"], figset.hulls("DI.fig")
    segg = kin.segment_globals(frames.poses, frames.roots)
    depth = [
        -hulls.clearance(_rifle_points(figset, r), g).min() for r, g in zip(frames.rifles, segg, strict=True)
    ]
    return frames, segg[-1], depth


def _rest(figset: FigureSet, frames: ClipFrames, segg: np.ndarray) -> float:
    loc = frames.rifles[-1]
    grip = loc @ figset.figures["AK_47.fig"].site("rifle.grip").location
    hulls = figset.hulls("DI.fig", hands=True)
    return rifle_rest(_rifle_points(figset, loc), grip[:3, 3], hulls, segg, len(frames.rifles) - 1)[
        "rifle_rest_overhang_cm"
    ]


def test_a_rifle_balanced_on_its_muzzle_falls_and_lies_on_the_ground(figset: FigureSet) -> None:
    side = np.eye(4)
    side[:3, 3] = (70.0, 0.0, 0.0)  # beside him
    tilted = _on_ground(figset, side @ _rot(0, -25.0) @ _rot(2, 90.0))  # muzzle down, butt up 25 degrees
    frames, segg, _ = _settle(figset, tilted)
    assert _rest(figset, frames, segg) == 0.0
    fallen = _rifle_points(figset, frames.rifles[-1])[:, 1]
    assert fallen.min() > -1.0  # on the ground, not in it
    assert fallen.max() < _rifle_points(figset, tilted)[:, 1].max() - 10.0  # the butt came down
    speed = np.linalg.norm(np.diff(frames.rifles[-3:, :3, 3], axis=0), axis=1) * 60.0 / 100.0
    assert speed.max() < 0.03  # at rest
    assert len(frames.poses) == len(frames.rifles) >= 20  # the body held while it falls


def test_a_rifle_lying_across_him_stays_on_him(figset: FigureSet) -> None:
    poses, body, _ = _lying(figset, n=1)
    kin = figset.kin["DI.fig"]
    segg = kin.segment_globals(poses, body)[0]
    hulls = figset.hulls("DI.fig", hands=True)
    loc = _rot(1, 90.0) @ _rot(2, 90.0)  # on its side, across his belly
    grip = figset.figures["AK_47.fig"].site("rifle.grip").location[:, 3]
    belly = segg[kin.segment_names.index("lower_torso"), :3, 3]
    loc[:3, 3] = np.r_[belly[0], 60.0, belly[2]] - (loc @ grip)[:3]
    for _ in range(60):  # lowered until it touches him
        pts = _rifle_points(figset, loc)
        gap = min(hulls.clearance(pts, segg).min(), pts[:, 1].min())
        if gap <= 0.5:
            break
        loc[1, 3] -= gap - 0.25
    frames, last, depth = _settle(figset, loc)
    assert max(depth) <= 1.0  # never through him
    assert _rest(figset, frames, last) < OVERHANG_LIMIT_CM
