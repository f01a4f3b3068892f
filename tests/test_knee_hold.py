"""A fall's knee on the ground stays put, the root following it, the feet kept (authoring.knee_hold)."""

from __future__ import annotations

import numpy as np
import pytest

from authoring.body_parts import contact_runs
from authoring.knee_hold import hold_knees
from authoring.postures import lowest_point
from authoring.quality import CONTACT_HEIGHT_CM, THRESHOLDS
from authoring.quality_frames import FigureSet
from authoring.transitions import ClipFrames
from peabody.loader import read_figure
from ttes.paths import FIGURES

N, DOWN, UP = 50, 10, 40  # frames; the knees skid from DOWN to UP
RELEASE = (DOWN + UP) // 2  # the hands let go of the rifle halfway through the skid
SKID_CM = 6.0  # this far forward (ststow2dead's knee: 10.3 cm, kstow2dead's 5.9)
KNEEL_DEG = 120.0  # knees bent this far, hips straight: kneeling upright, the feet off the ground


@pytest.fixture(scope="module")
def skid() -> tuple[FigureSet, ClipFrames]:
    """soldier.fig kneeling upright on both knees, the whole body skidding SKID_CM forward on them."""
    figs = FigureSet({"body": read_figure(FIGURES / "soldier.fig")})
    kin = figs.kin["body"]
    pose = np.zeros(kin.ndof)
    for side in ("left", "right"):
        pose[kin.dof_slices[f"{side}_knee"]] = np.radians(KNEEL_DEG)
    root = np.eye(4)
    root[1, 3] -= float(lowest_point(kin, pose, root))
    roots = np.repeat(root[None], N, axis=0)
    roots[:, 2, 3] -= SKID_CM * np.clip((np.arange(N) - DOWN) / (UP - DOWN), 0.0, 1.0)
    return figs, ClipFrames(np.repeat(pose[None], N, axis=0), roots, roots.copy(), 60.0)


def _slide(figs: FigureSet, frames: ClipFrames, parts: tuple[str, ...]) -> float:
    kin = figs.kin["body"]
    nodes, segs = figs.nodes("body")
    sel = np.isin(figs.node_parts("body"), parts)
    g = kin.segment_globals(frames.poses, frames.roots)
    points = np.einsum("fkij,kj->fki", g[:, segs[sel], :3, :], nodes[sel])
    return float(contact_runs(points, CONTACT_HEIGHT_CM).slide.max(initial=0.0))


def test_a_skidding_knee_is_held_and_the_body_pivots_over_it(skid: tuple[FigureSet, ClipFrames]) -> None:
    figs, frames = skid
    kin = figs.kin["body"]
    knees = ("left_knee", "left_kneecap", "right_knee", "right_kneecap")
    assert _slide(figs, frames, knees) > SKID_CM - 0.5  # the constructed fall skids on its knees
    held = hold_knees(frames, figs.figures["body"], release=RELEASE)
    assert _slide(figs, held, knees) < THRESHOLDS["contact_slide_cm"]
    assert _slide(figs, held, ("left_foot", "right_foot")) < THRESHOLDS["foot_skate_cm"]
    assert np.all(held.poses >= kin.lower - 1e-9) and np.all(held.poses <= kin.upper + 1e-9)
    assert np.degrees(np.abs(np.diff(held.poses, axis=0))).max() < 20.0  # no joint leaps
    np.testing.assert_allclose(held.poses[0], frames.poses[0], atol=1e-6)  # the start posture is kept
    np.testing.assert_allclose(held.roots[0], frames.roots[0], atol=1e-9)
    # the rifle goes with the root while it is held (after: test_a_let_go_rifle_moves_with_the_body_...)
    moved = held.roots[:, :3, 3] - frames.roots[:, :3, 3]
    rifle_moved = held.rifles[:, :3, 3] - frames.rifles[:, :3, 3]
    assert np.abs(moved[RELEASE]).max() > 1.0  # the root was moved back by then (else this proves nothing)
    np.testing.assert_allclose(rifle_moved[: RELEASE + 1], moved[: RELEASE + 1], atol=1e-9)


FLIGHT = 8  # frames the let-go rifle still flies on after the release


def test_a_let_go_rifle_moves_with_the_body_until_it_lies_still(skid: tuple[FigureSet, ClipFrames]) -> None:
    """The root moved back under a rifle still in flight would carry the body into where it lands
    (ststow2dead: his right toes 1.5 cm inside it): it goes along until it lies still, then stays."""
    figs, frames = skid
    rifles = np.repeat(frames.rifles[:1], N, axis=0)
    rifles[:, 0, 3] += 3.0 * np.minimum(np.arange(N), RELEASE + FLIGHT)  # 1.8 m/s sideways, then still
    flung = ClipFrames(frames.poses, frames.roots, rifles, frames.fps)
    held = hold_knees(flung, figs.figures["body"], release=RELEASE)
    moved = held.roots[:, :3, 3] - frames.roots[:, :3, 3]
    rifle_moved = held.rifles[:, :3, 3] - rifles[:, :3, 3]
    landed = RELEASE + FLIGHT
    assert np.abs(moved[-1] - moved[RELEASE]).max() > 1.0  # the root moves on after the release
    np.testing.assert_allclose(rifle_moved[: landed + 1], moved[: landed + 1], atol=1e-9)
    np.testing.assert_allclose(
        rifle_moved[landed:], np.broadcast_to(moved[landed], (N - landed, 3)), atol=1e-9
    )
