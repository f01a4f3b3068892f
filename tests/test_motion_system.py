"""The motion system (seed 000, chapter 5): velocity controls, weight functions, key postures, hooks."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from authoring.motion import (
    VC_ACCELERATE,
    VC_CONSTANT,
    VC_DECELERATE,
    VC_EASEIN_EASEOUT,
    WF_CONSTANT,
    WF_DECAY,
    WF_EASEIN_EASEOUT,
    Attach,
    JointTarget,
    KeyPosture,
    LocationTarget,
    Motion,
    MotionScript,
    PinSite,
    SiteConstraint,
    SiteTarget,
    VelocityControl,
    velocity_control,
    weight_function,
)
from peabody.fk import FigureKinematics
from peabody.loader import read_figure
from server.motion.cache import load_channelset
from server.motion.channelset import channelsets_close
from server.motion.channelset_file import save_channelset

FIGURES = Path(__file__).resolve().parents[1] / "figures"


@pytest.fixture(scope="module")
def figs():
    return (
        read_figure(FIGURES / "DI.fig", load_psurfs=False),
        read_figure(FIGURES / "AK_47.fig", load_psurfs=False),
    )


def _translation(x: float, y: float, z: float) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def test_velocity_controls_known_values() -> None:
    t = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
    np.testing.assert_allclose(velocity_control(VC_CONSTANT, t), t)
    np.testing.assert_allclose(velocity_control(VC_ACCELERATE, t), [0, 0.0625, 0.25, 0.5625, 1])
    np.testing.assert_allclose(velocity_control(VC_DECELERATE, t), [0, 0.4375, 0.75, 0.9375, 1])
    ease = (1 - np.cos(np.pi * t)) / 2
    np.testing.assert_allclose(VC_EASEIN_EASEOUT(t), ease)
    np.testing.assert_allclose(ease[[1, 2]], [0.14644660940672624, 0.5])
    # clamped outside [0, 1]; names accepted as strings
    np.testing.assert_allclose(velocity_control("accelerate", [-1.0, 2.0]), [0.0, 1.0])
    # ease-in/out starts and stops at zero speed, so chained motions meet without a kink
    h = 1e-6
    assert VelocityControl.EASE_IN_OUT(h) / h < 1e-4
    assert (1 - VelocityControl.EASE_IN_OUT(1 - h)) / h < 1e-4


def test_weight_functions_known_values() -> None:
    t = np.array([0.0, 0.5, 1.0])
    np.testing.assert_allclose(weight_function(WF_CONSTANT, 2.0, t), [2.0, 2.0, 2.0])
    np.testing.assert_allclose(weight_function(WF_DECAY, 2.0, t), [2.0, 1.0, 0.0])
    np.testing.assert_allclose(weight_function(WF_EASEIN_EASEOUT, 2.0, t), [0.0, 1.0, 2.0])
    np.testing.assert_allclose(weight_function(WF_EASEIN_EASEOUT, 1.0, 0.25), 0.14644660940672624)
    with pytest.raises(ValueError):
        weight_function("sometimes", 1.0, 0.5)


def test_interpolation_hits_key_postures_at_key_times(figs) -> None:
    di, rifle = figs
    kin = FigureKinematics(di)
    a = kin.neutral_pose()
    b = a.copy()
    b[kin.dof_slices["left_knee"]] = 1.0
    b[kin.dof_slices["neck"]] = [0.1, 0.2, 0.3]
    c = a.copy()
    c[kin.dof_slices["left_knee"]] = 0.4
    ra, rb, rc = _translation(0, 100, -30), _translation(10, 120, -40), _translation(-5, 90, -20)
    start = KeyPosture("A", {"DI": a}, {"AK_47": ra})
    script = MotionScript([di, rifle], start)
    script.move_to(KeyPosture("B", {"DI": b}, {"AK_47": rb}), 0.5, 1.0)  # 0.5 .. 1.5 s
    script.move_to(KeyPosture("C", {"DI": c}, {"AK_47": rc}), 2.0, 1.0, VC_CONSTANT)  # 2 .. 3 s
    frames = script.evaluate(fps=60)
    assert frames.nframes == 181 and frames.times[-1] == pytest.approx(3.0)
    p, loc = frames.poses["DI"], frames.locations["AK_47"]
    np.testing.assert_allclose(p[0], a)
    np.testing.assert_allclose(p[30], a)  # the motion starts from where the figure is
    np.testing.assert_allclose(p[90], b, atol=1e-12)  # key time 1.5 s
    np.testing.assert_allclose(p[90:121], np.tile(b, (31, 1)), atol=1e-12)  # held until the next motion
    np.testing.assert_allclose(p[180], c, atol=1e-12)  # key time 3 s
    np.testing.assert_allclose(p[60], (a + b) / 2, atol=1e-12)  # ease-in/out midpoint at 1.0 s
    np.testing.assert_allclose(p[150], (b + c) / 2, atol=1e-12)  # constant velocity midpoint at 2.5 s
    np.testing.assert_allclose(loc[90], rb, atol=1e-9)
    np.testing.assert_allclose(loc[180], rc, atol=1e-9)
    np.testing.assert_allclose(frames.locations["DI"], np.tile(di.location, (181, 1, 1)), atol=1e-12)
    rec = script.interpolate(fps=60)
    assert rec.nframes == 181
    assert rec.roots["DI"][0] == "lower_torso.proximal"
    np.testing.assert_allclose(rec.poses["DI"][90], b.astype(np.float32))


def test_location_slerp_and_joint_subsets(figs) -> None:
    di, rifle = figs
    kin = FigureKinematics(di)
    script = MotionScript([di, rifle], duration=1.0)
    turn = np.eye(4)
    turn[:3, :3] = [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]  # 90 degrees about +Y
    turn[:3, 3] = (20, 0, 0)
    script.add(Motion("AK_47", 0.0, 1.0, LocationTarget(turn), VC_CONSTANT))
    script.add(Motion("DI", 0.0, 0.5, JointTarget({"right_elbow": [1.0, 0.2]}), VC_CONSTANT))
    frames = script.evaluate(fps=10)
    half = frames.locations["AK_47"][5]
    assert np.degrees(np.arccos((np.trace(half[:3, :3]) - 1) / 2)) == pytest.approx(45.0)
    np.testing.assert_allclose(half[:3, 3], (10, 0, 0))
    p = frames.poses["DI"]
    el = kin.dof_slices["right_elbow"]
    np.testing.assert_allclose(p[5, el], [1.0, 0.2])
    others = np.ones(kin.ndof, dtype=bool)
    others[el] = False
    np.testing.assert_array_equal(p[:, others], np.tile(kin.neutral_pose()[others], (11, 1)))


def test_overlapping_motions_later_start_wins_then_the_longer_one_resumes(figs) -> None:
    di, _ = figs
    kin = FigureKinematics(di)
    knee = kin.dof_slices["left_knee"]
    script = MotionScript([di])
    script.add(Motion("DI", 0.0, 1.0, JointTarget({"left_knee": 1.0}), VC_CONSTANT))
    script.add(Motion("DI", 0.2, 0.2, JointTarget({"left_knee": 0.1}), VC_CONSTANT))
    p = script.evaluate(fps=10).poses["DI"][:, knee][:, 0]
    np.testing.assert_allclose(p[:2], [0.0, 0.1])
    np.testing.assert_allclose(p[2], 0.2)  # the second motion starts from the first's value at 0.2 s
    np.testing.assert_allclose(p[4], 0.1)  # and reaches its target at its end
    np.testing.assert_allclose(p[5:], [0.5, 0.6, 0.7, 0.8, 0.9, 1.0])  # the first motion is still active


def test_hooks_keep_palms_on_the_rifle_and_feet_planted(figs) -> None:
    di, rifle = figs
    kin = FigureKinematics(di)
    q0 = kin.neutral_pose()
    squat = q0.copy()
    for side in ("left", "right"):
        squat[kin.dof_slices[f"{side}_hip"]] = [0.0, 0.6, 0.0]
        squat[kin.dof_slices[f"{side}_knee"]] = 1.0
    low = di.location.copy()
    low[1, 3] -= 6.0
    script = MotionScript(
        [di, rifle], KeyPosture("stand", {"DI": q0}, {"AK_47": _translation(5, 105, -30)}), duration=1.2
    )
    script.move_to(
        KeyPosture("squat", {"DI": squat}, {"DI": low, "AK_47": _translation(5, 92, -35)}), 0.1, 1.0
    )
    heel = ("left_foot.heel", "right_foot.heel")
    for site in heel:
        script.constrain(PinSite("DI", site, 0.0, 1.2, orientation=True, joints=_leg(site)))
    script.constrain(SiteConstraint("DI", "right_palm.palmcenter", "AK_47", "rifle.grip", priority=1))
    script.constrain(SiteConstraint("DI", "left_palm.palmcenter", "AK_47", "rifle.handguard", priority=1))
    frames = script.evaluate(fps=30)
    assert len(frames.reports) == 1  # one batched solve for all frames of the figure
    g = kin.site_globals(frames.poses["DI"], frames.locations["DI"])
    rk = FigureKinematics(rifle)
    rg = rk.site_globals(np.zeros((frames.nframes, 0)), frames.locations["AK_47"])
    for palm, site in (("right_palm.palmcenter", "rifle.grip"), ("left_palm.palmcenter", "rifle.handguard")):
        d = g[:, kin.site_names.index(palm), :3, 3] - rg[:, rk.site_names.index(site), :3, 3]
        assert np.linalg.norm(d, axis=1).max() < 0.1
    for site in heel:
        track = g[:, kin.site_names.index(site), :3, 3]
        assert np.abs(track - track[0]).max() < 0.1
    assert np.all(frames.poses["DI"] >= kin.lower) and np.all(frames.poses["DI"] <= kin.upper)


def _leg(site: str) -> list[str]:
    side = site.split("_")[0]
    return [f"{side}_hip", f"{side}_knee", f"{side}_ankle"]


def test_attach_and_site_target_motion(figs, tmp_path: Path) -> None:
    di, rifle = figs
    kin = FigureKinematics(di)
    script = MotionScript([di, rifle], duration=1.0)
    palm = "right_palm.palmcenter"
    start = kin.site_global(palm)[:3, 3]
    goal = start + np.array([5.0, 20.0, -25.0])
    script.add(Motion("DI", 0.0, 0.8, SiteTarget(palm, goal), VC_EASEIN_EASEOUT))
    script.constrain(Attach("AK_47", "DI", palm))
    frames = script.evaluate(fps=10)
    g = kin.site_globals(frames.poses["DI"], frames.locations["DI"])[:, kin.site_names.index(palm)]
    assert np.linalg.norm(g[8, :3, 3] - goal) < 0.1  # reached at the motion's end
    assert np.linalg.norm(g[10, :3, 3] - goal) < 0.1  # and held afterwards
    np.testing.assert_allclose(g[0, :3, 3], start, atol=1e-6)
    # the rifle rode along: its placement relative to the palm never changes
    rel = np.linalg.inv(g) @ frames.locations["AK_47"]
    np.testing.assert_allclose(rel, np.tile(rel[0], (11, 1, 1)), atol=1e-9)
    # recorded into a channelset that survives the file round trip
    cs = script.to_channelset("reach.chset", fps=10)
    assert cs.nframes == 11 and cs.fps == 10
    path = tmp_path / "reach.chset.env"
    save_channelset(cs, path)
    assert channelsets_close(load_channelset(path, use_cache=False), cs, atol=1e-5)


def test_bad_scripts_raise(figs) -> None:
    di, rifle = figs
    script = MotionScript([di, rifle])
    with pytest.raises(KeyError):
        script.add(Motion("nobody", 0.0, 1.0, JointTarget({})))
    with pytest.raises(ValueError):
        Motion("DI", -1.0, 1.0, JointTarget({}))
    with pytest.raises(KeyError):
        script.add(Motion("DI", 0.0, 1.0, KeyPosture("empty")))
    script.add(Motion("DI", 0.0, 1.0, JointTarget({"left_knee": [0.1, 0.2]})))
    with pytest.raises(ValueError, match="takes 1 values"):
        script.evaluate(10)
    with pytest.raises(KeyError):
        script.constrain(Attach("AK_47", "ghost", "x.y"))


def test_fade_slides_a_constraint_in_and_out_without_a_jump(figs) -> None:
    di, _ = figs
    kin = FigureKinematics(di)
    heel = "left_foot.heel"
    hard, soft = MotionScript([di]), MotionScript([di])
    for script, fade in ((hard, 0.0), (soft, 0.2)):
        script.add(Motion("DI", 0.0, 1.0, JointTarget({"left_knee": 1.2}), VC_CONSTANT))
        script.constrain(PinSite("DI", heel, 0.3, 0.7, fade=fade, joints=["left_hip", "left_knee"]))
    fps = 60
    kinematic = MotionScript([di])
    kinematic.add(Motion("DI", 0.0, 1.0, JointTarget({"left_knee": 1.2}), VC_CONSTANT))
    free = kin.site_globals(kinematic.evaluate(fps).poses["DI"])[:, kin.site_names.index(heel), :3, 3]
    jumps = {}
    for name, script in (("hard", hard), ("soft", soft)):
        p = script.evaluate(fps).poses["DI"]
        track = kin.site_globals(p)[:, kin.site_names.index(heel), :3, 3]
        jumps[name] = np.linalg.norm(np.diff(track, axis=0), axis=1).max()
        if name == "soft":
            np.testing.assert_allclose(track[18], free[18], atol=1e-6)  # window start: nothing to do yet
            np.testing.assert_allclose(track[42], free[42], atol=1e-6)  # window end: let go again
            assert np.abs(track[30] - free[18]).max() < 0.1  # fully pinned once faded in (0.5 s)
    assert jumps["soft"] < jumps["hard"] / 2  # releasing a hard pin snaps the foot back
