"""A leg part that would skid on the ground lifts off instead, and lands once where it comes to rest
(authoring.leg_lift)."""

from __future__ import annotations

import numpy as np
import pytest

from authoring.body_parts import contact_runs
from authoring.leg_lift import SLIDE_BUDGET_CM, eased_legs, lift_windows, lifted
from authoring.postures import lowest_point
from authoring.quality import CONTACT_HEIGHT_CM, THRESHOLDS, frame_flicks
from authoring.quality_frames import FigureSet
from authoring.slave_feet import part_points
from authoring.transitions import ClipFrames
from peabody.loader import read_figure
from ttes.paths import FIGURES

N, SKID_FROM, SKID_TO = 60, 15, 35  # frames; the body skids between these
SKID_CM = 6.0  # this far sideways (kfire2dead's tucked toes: 7 cm in 4 frames, kstow2dead's knee 5.9)
FEET = ("left_foot", "right_foot")
SLOW_STEP_DEG = 2.0  # degrees a frame: a slower lift than this skid's default one


def test_the_window_runs_from_the_slide_to_where_the_node_comes_to_rest() -> None:
    x = np.r_[np.zeros(10), np.linspace(0.0, 5.0, 11), np.full(9, 5.0)]  # still, slides 5 cm, still
    points = np.zeros((30, 1, 3))
    points[:, 0, 0] = x
    points[:3, 0, 1] = 10.0  # touches down at frame 3
    window = lift_windows(points)
    first, last = np.flatnonzero(window)[[0, -1]]
    assert x[first] > SLIDE_BUDGET_CM >= x[first - 1]  # lifts once it has slid the budget ...
    assert x[last] < 5.0 - SLIDE_BUDGET_CM <= x[last + 1]  # ... and lands within it of its rest
    assert window[first : last + 1].all()
    assert not lift_windows(points[:12]).any()  # a node that slides less stays down


@pytest.fixture(scope="module")
def skid() -> tuple[FigureSet, ClipFrames]:
    """soldier.fig standing, his feet flat on the ground, the whole body skidding SKID_CM sideways."""
    figs = FigureSet({"body": read_figure(FIGURES / "soldier.fig")})
    kin = figs.kin["body"]
    pose = np.zeros(kin.ndof)
    root = np.eye(4)
    root[1, 3] -= float(lowest_point(kin, pose, root))
    roots = np.repeat(root[None], N, axis=0)
    roots[:, 0, 3] += SKID_CM * np.clip((np.arange(N) - SKID_FROM) / (SKID_TO - SKID_FROM), 0.0, 1.0)
    return figs, ClipFrames(np.repeat(pose[None], N, axis=0), roots, roots.copy(), 60.0)


def _slide(figs: FigureSet, frames: ClipFrames, parts: tuple[str, ...]) -> float:
    points = part_points(frames.poses, frames.roots, figs, "body", parts)
    return float(contact_runs(points, CONTACT_HEIGHT_CM).slide.max(initial=0.0))


def test_skidding_feet_lift_off_and_land_once_where_they_rest(skid: tuple[FigureSet, ClipFrames]) -> None:
    figs, frames = skid
    kin = figs.kin["body"]
    assert _slide(figs, frames, FEET) > SKID_CM - 0.5  # the constructed fall drags its feet
    out = lifted(frames, figs.figures["body"])
    assert _slide(figs, out, FEET) < THRESHOLDS["foot_skate_cm"]
    for foot in FEET:
        low = part_points(out.poses, out.roots, figs, "body", (foot,))[..., 1].min(axis=1)
        down = low <= CONTACT_HEIGHT_CM
        assert (~down[SKID_FROM + 5 : SKID_TO - 5]).all()  # off the ground while the body skids ...
        assert down[-1] and (np.diff(down.astype(int)) > 0).sum() == 1  # ... lands once and stays
        assert low.min() > -THRESHOLDS["ground_penetration_cm"]
    assert np.all(out.poses >= kin.lower - 1e-9) and np.all(out.poses <= kin.upper + 1e-9)
    assert np.degrees(np.abs(np.diff(out.poses, axis=0))).max() < THRESHOLDS["max_frame_jump_deg"]
    np.testing.assert_allclose(out.poses[[0, -1]], frames.poses[[0, -1]], atol=1e-6)  # start and rest kept
    np.testing.assert_array_equal(out.roots, frames.roots)  # the body goes as it fell: legs only


def test_a_leg_let_go_in_one_frame_turns_over_a_few(skid: tuple[FigureSet, ClipFrames]) -> None:
    """Issue 14 (kstow2dead): a pin that stretched the right knee and gave it back 19 degrees in one frame,
    and a lift that turned an ankle 10 degrees for a single frame, flicked; eased, the legs' change from
    the fall turns over a few frames, everything else (and the first and last frames) as held."""
    figs, fall = skid
    kin = figs.kin["body"]
    knee, ankle = kin.dof_slices["right_knee"].start, kin.dof_slices["left_ankle"].start
    held = np.array(fall.poses)
    held[20:40, knee] += np.radians(np.linspace(0.0, 20.0, 20))  # stretched slowly, let go at once
    held[30, ankle] += np.radians(10.0)  # one frame's twitch
    held[:, kin.dof_slices["waist"]] += np.radians(5.0)  # not a leg: left as held
    rot = np.ones(kin.ndof, dtype=bool)
    flicks = frame_flicks(np.asarray(held), rot, kin.dof_slices)
    assert flicks["max_frame_flick_deg"] > THRESHOLDS["max_frame_flick_deg"]
    assert flicks["ankle_flick_deg"] > THRESHOLDS["ankle_flick_deg"]
    pinned = ClipFrames(held, fall.roots, fall.rifles, fall.fps)
    out = eased_legs(fall, pinned, figs.figures["body"], 2.0)
    flicks = frame_flicks(np.asarray(out.poses), rot, kin.dof_slices)
    assert flicks["max_frame_flick_deg"] < THRESHOLDS["max_frame_flick_deg"] / 2
    assert flicks["ankle_flick_deg"] < THRESHOLDS["ankle_flick_deg"] / 2
    np.testing.assert_allclose(out.poses[[0, -1]], held[[0, -1]], atol=1e-12)
    waist = kin.dof_slices["waist"]
    np.testing.assert_array_equal(out.poses[:, waist], held[:, waist])
    assert abs(np.degrees(out.poses[32, knee] - held[32, knee])) < 0.5  # away from the jumps: as held


def test_a_death_may_lift_its_legs_more_slowly(skid: tuple[FigureSet, ClipFrames]) -> None:
    """Issue 14 (kfire-s21): lifting kfire2dead's tucked rear foot turned the right knee 9.8 degrees in one
    frame and the foot popped 4.33 m/s; a death's own step (``DeathSpec.legs_lift_step_deg``) lets the lift
    turn a leg's joints at most that much a frame, the feet still lifting off as the body skids."""
    figs, frames = skid
    kin = figs.kin["body"]
    right = np.zeros(kin.ndof, dtype=bool)
    for joint, sl in kin.dof_slices.items():
        right[sl] = joint.startswith("right_")
    for steps in ((("right_", SLOW_STEP_DEG),), ()):
        out = lifted(frames, figs.figures["body"], steps)
        turn = np.degrees(np.abs(np.diff(out.poses, axis=0))).max(axis=0)
        if not steps:
            assert turn[right].max() > SLOW_STEP_DEG + 0.25  # the default (leg_lift.STEP_DEG) is faster here
            continue
        assert turn[right].max() <= SLOW_STEP_DEG + 1e-6
        assert turn[~right].max() > SLOW_STEP_DEG + 0.25  # the left leg lifts as fast as before
        assert _slide(figs, out, FEET) < THRESHOLDS["foot_skate_cm"]
        np.testing.assert_allclose(out.poses[[0, -1]], frames.poses[[0, -1]], atol=1e-6)


def test_eased_together_a_leg_turns_as_one_where_one_joint_stutters(
    skid: tuple[FigureSet, ClipFrames],
) -> None:
    """Issue 14 (ststow2dead): the knee hold stuttered the left knee (6.4, 0.6, 5.0 degrees a frame) while
    the hip turned on smoothly. Eased one DOF at a time only the knee is smoothed, out of step with the hip
    (the foot jumped 3.9 m/s); ``together``, every leg DOF is smoothed there as one, elsewhere as held."""
    figs, fall = skid
    kin = figs.kin["body"]
    knee, hip = kin.dof_slices["left_knee"].start, kin.dof_slices["left_hip"].start
    held = np.array(fall.poses)
    stutter = np.radians(np.cumsum([0.0, 6.4, 0.6, 5.0, 0.4] + [0.0] * 5))
    held[25:35, knee] += stutter
    held[25:35, hip] += np.radians(np.linspace(0.0, 9.0, 10))  # a smooth turn of the change: no flick
    held[35:, knee] += stutter[-1]
    held[35:, hip] += np.radians(9.0)
    pinned = ClipFrames(held, fall.roots, fall.rifles, fall.fps)
    alone = eased_legs(fall, pinned, figs.figures["body"], 1.0)
    together = eased_legs(fall, pinned, figs.figures["body"], 1.0, together=True)
    np.testing.assert_array_equal(alone.poses[:, hip], held[:, hip])  # the hip did not flick: as held
    assert np.abs(together.poses[22:38, hip] - held[22:38, hip]).max() > 0.0  # smoothed with the knee
    rot = np.ones(kin.ndof, dtype=bool)
    assert frame_flicks(np.asarray(together.poses), rot, kin.dof_slices)["max_frame_flick_deg"] < 3.0
    np.testing.assert_array_equal(together.poses[:15], held[:15])  # away from the stutter: as held
