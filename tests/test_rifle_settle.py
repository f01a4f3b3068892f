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
from authoring.rifle_settle import rifle_parts, settled
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


def test_a_body_coming_down_beside_a_lying_rifle_leaves_it_lying(figset: FigureSet) -> None:
    """The body meets the rifle's pieces, not its convex hull: his shoulder, lowered onto the ground 2.4 cm
    clear of the rifle lying on its side but 1.9 cm into its hull (between barrel and magazine), pushed the
    hull 0.53 cm (prstow2dead's left palm wedged it against the ground and stood it up: overhang 44 cm)."""
    from scipy.spatial import ConvexHull

    lying, body, _ = _lying(figset, n=40)
    body[:20, 1, 3] += np.linspace(8.0, 0.0, 20)  # he comes down from 8 cm up, then lies still
    side = np.eye(4)
    side[:3, 3] = (27.0, 0.0, 170.0)  # by his left shoulder, its magazine toward him
    loc = _on_ground(figset, side @ _rot(1, 180.0) @ _rot(2, 90.0))
    kin, hulls = figset.kin["DI.fig"], figset.hulls("DI.fig", hands=True)
    segg = kin.segment_globals(lying[-1:], body[-1:])[0]
    assert hulls.clearance(_rifle_points(figset, loc), segg).min() > 2.0  # clear of him ...
    nodes, segs = figset.nodes("DI.fig")
    him = np.linalg.solve(loc, np.einsum("kij,kj->ki", segg[segs], nodes).T).T[:, :3]
    hull = ConvexHull(figset.nodes("AK_47.fig")[0][:, :3]).equations
    assert (him @ hull[:, :3].T + hull[:, 3]).max(axis=1).min() < -1.5  # ... but in its hull
    away = body.copy()
    away[:, 0, 3] -= 300.0  # he lies 3 m away: the rifle settles on the ground alone

    def rifle_settled(roots: np.ndarray) -> ClipFrames:
        clip = ClipFrames(lying, roots, np.tile(loc, (len(lying), 1, 1)), 60.0)
        return settled(clip, figset.figures["DI.fig"], figset.figures["AK_47.fig"])

    frames, alone = rifle_settled(body), rifle_settled(away)
    moved = _rifle_points(figset, frames.rifles[-1]) - _rifle_points(figset, alone.rifles[-1])
    assert np.linalg.norm(moved, axis=1).max() < 0.05  # it lies as it would without him
    assert _rest(figset, frames, kin.segment_globals(frames.poses[-1:], frames.roots[-1:])[0]) == 0.0


def test_the_rifle_splits_into_convex_pieces_far_smaller_than_its_hull(figset: FigureSet) -> None:
    from scipy.spatial import ConvexHull

    rifle = figset.figures["AK_47.fig"]
    parts = rifle_parts(rifle)
    nodes = rifle.segments["rifle"].psurf.nodes  # type: ignore[union-attr]
    assert sum(len(p) for p in parts) == len(nodes) and len(parts) > 10  # stock, grip, magazine, barrel...
    for part in parts:  # each convex: every node on its hull
        eq = ConvexHull(part).equations
        assert (part @ eq[:, :3].T + eq[:, 3]).max(axis=1).min() > -0.01
    assert sum(ConvexHull(p).volume for p in parts) < 0.5 * ConvexHull(nodes).volume


def test_a_rifle_let_go_over_him_falls_through_the_parts_it_does_not_meet(figset: FigureSet) -> None:
    """DeathSpec.rifle_refall: the rifle falling again from the hands meets no arm (ststow2dead's flailing
    arms juggled it over his head); here it meets no part at all and falls past his belly to the ground,
    where meeting him it lies on him."""
    poses, body, _ = _lying(figset, n=40)
    kin = figset.kin["DI.fig"]
    belly = kin.segment_globals(poses[:1], body[:1])[0, kin.segment_names.index("lower_torso"), :3, 3]
    loc = _rot(1, 90.0) @ _rot(2, 90.0)  # on its side, across his belly, 50 cm up
    grip = figset.figures["AK_47.fig"].site("rifle.grip").location[:, 3]
    loc[:3, 3] = np.r_[belly[0], 50.0, belly[2]] - (loc @ grip)[:3]
    clip = ClipFrames(poses, body, np.tile(loc, (len(poses), 1, 1)), 60.0)
    soldier, rifle = figset.figures["DI.fig"], figset.figures["AK_47.fig"]
    on_him = settled(clip, soldier, rifle, start=0)
    through = settled(clip, soldier, rifle, start=0, unmet=tuple(kin.segment_names))
    assert (on_him.rifles[-1] @ grip)[1] > 10.0  # its centre on him (cm up)
    assert (through.rifles[-1] @ grip)[1] < 6.0  # ... and on the ground


def test_a_tossed_rifle_is_flung_its_way(figset: FigureSet) -> None:
    """DeathSpec.rifle_refall_toss: the rifle falling again is flung by the toss (N) for TOSS_SECONDS."""
    poses, body, _ = _lying(figset, n=40)
    side = np.eye(4)
    side[:3, 3] = (80.0, 30.0, 0.0)  # beside him, 30 cm up
    clip = ClipFrames(poses, body, np.tile(side, (len(poses), 1, 1)), 60.0)
    soldier, rifle = figset.figures["DI.fig"], figset.figures["AK_47.fig"]
    dropped = settled(clip, soldier, rifle, start=0).rifles[-1, :3, 3]
    tossed = settled(clip, soldier, rifle, start=0, toss=np.array([80.0, 0.0, 0.0])).rifles[-1, :3, 3]
    assert tossed[0] - dropped[0] > 10.0  # cm: away from him, along +X
