"""Slaving DI.fig to soldier.fig (seed 002, 3.4.4) and re-recording channelsets for the slave."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from authoring.motion import KeyPosture, MotionScript, SiteConstraint
from authoring.slaving import (
    SLAVE_CONSTRAINTS,
    MasterSlavePair,
    SlaveParameters,
    create_channelset_motion,
    create_master_slave_pair,
    low_name,
    reslave_channelset,
    slave_parameters,
    turn_slave_off,
    turn_slave_on,
)
from peabody.loader import read_figure
from server.motion.channelset import channelsets_close, make_channelset

FIGURES = Path(__file__).resolve().parents[1] / "figures"
LEGS = (
    "left_hip",
    "left_knee",
    "left_ankle",
    "left_toes",
    "right_hip",
    "right_knee",
    "right_ankle",
    "right_toes",
)


@pytest.fixture(scope="module")
def pair() -> MasterSlavePair:
    master = read_figure(FIGURES / "soldier.fig", load_psurfs=False)
    slave = read_figure(FIGURES / "DI.fig", load_psurfs=False)
    rifle = read_figure(FIGURES / "AK_47.fig", load_psurfs=False)
    return create_master_slave_pair(master, slave, rifle)


def _ready_pose(pair: MasterSlavePair) -> np.ndarray:
    """A master pose with the forearms raised in front (as when holding a rifle) and a bent torso."""
    mk = pair.master_kin
    q = mk.neutral_pose()
    for side in ("left", "right"):
        q[mk.dof_slices[f"{side}_shoulder"]] = [0.2, 0.5, 0.3]
        q[mk.dof_slices[f"{side}_elbow"]] = [1.3, 0.4]
    for j in ("vl3", "vl2", "vt8", "vt4"):
        q[mk.dof_slices[j]] = [0.03, 0.06, 0.04]
    q[mk.dof_slices["waist"]] = [0.05, 0.2, -0.1]
    q[mk.dof_slices["neck"]] = [0.0, 0.2, 0.1]
    return q


def _poses(pair: MasterSlavePair, n: int, seed: int) -> np.ndarray:
    mk = pair.master_kin
    rng = np.random.default_rng(seed)
    span = np.minimum(mk.upper - mk.lower, 2.0)
    q = _ready_pose(pair) + rng.uniform(-1, 1, (n, mk.ndof)) * 0.12 * span
    return np.clip(q, mk.lower, mk.upper)


def test_slave_parameters_reads_the_seed_call() -> None:
    p = slave_parameters("yes", "yes", "yes", "yes", 0.50, "yes", 0.50, "yes", "yes")
    assert p == SlaveParameters(True, True, True, True, 0.5, True, 0.5, True, True)
    q = slave_parameters("no", "yes", "no", "yes", "0.25", "yes", 2, "no", "no")
    assert (q.copy_angles, q.match_torso, q.torso_weight, q.elbow_weight, q.palm_priority) == (
        False,
        False,
        0.25,
        2.0,
        False,
    )
    with pytest.raises(ValueError, match="9 arguments"):
        slave_parameters("yes", "yes")
    with pytest.raises(ValueError, match="yes"):
        slave_parameters("maybe", "yes", "yes", "yes", 0.5, "yes", 0.5, "yes", "yes")
    with pytest.raises(ValueError, match="positive"):
        slave_parameters("yes", "yes", "yes", "yes", -1, "yes", 0.5, "yes", "yes")


def test_slaved_pose_matches_palms_and_copies_legs(pair: MasterSlavePair) -> None:
    pair.slave_parameters("yes", "yes", "yes", "yes", 0.50, "yes", 0.50, "yes", "yes")
    q = _poses(pair, 40, seed=11)
    loc = np.tile(pair.master.location, (40, 1, 1))
    loc[:, :3, 3] += np.random.default_rng(2).uniform(-50, 50, (40, 3))  # anywhere in the world
    slave, slave_loc = pair.slave_pose(q, loc)
    mk, sk = pair.master_kin, pair.slave_kin
    ms = mk.site_globals(q, loc)
    ss = sk.site_globals(slave, slave_loc)
    for palm in ("left_palm.palmcenter", "right_palm.palmcenter"):
        d = np.linalg.norm(
            ms[:, mk.site_names.index(palm), :3, 3] - ss[:, sk.site_names.index(palm), :3, 3], axis=1
        )
        assert d.max() < 1.0
        assert np.median(d) < 0.05
    for joint in LEGS:
        np.testing.assert_array_equal(slave[:, sk.dof_slices[joint]], q[:, mk.dof_slices[joint]])
    # the root sites coincide, so feet land where the master's do
    np.testing.assert_allclose(slave_loc, loc, atol=1e-9)
    for c in SLAVE_CONSTRAINTS:  # every landmark of the table ends up close
        d = np.linalg.norm(
            ms[:, mk.site_names.index(c.master_site), :3, 3]
            - ss[:, sk.site_names.index(c.slave_site), :3, 3],
            axis=1,
        )
        assert d.max() < 1.0, c.name
    assert np.all(slave >= sk.lower) and np.all(slave <= sk.upper)


def test_spine_blend_gives_the_torso_segments_the_master_orientations(pair: MasterSlavePair) -> None:
    q = _poses(pair, 8, seed=5)
    mk, sk = pair.master_kin, pair.slave_kin
    start = pair.copy_pose(q, mk.segment_globals(q))
    mg, sg = mk.segment_globals(q), sk.segment_globals(start)
    for m_seg, s_seg in (("l3", "lumbar"), ("t12", "middle_torso"), ("upper_torso", "upper_torso")):
        rm = mg[:, mk.segment_names.index(m_seg), :3, :3]
        rs = sg[:, sk.segment_names.index(s_seg), :3, :3]
        np.testing.assert_allclose(rs, rm, atol=1e-9)


def test_turn_slave_on_and_off(pair: MasterSlavePair) -> None:
    mk, sk = pair.master_kin, pair.slave_kin
    q = _ready_pose(pair)
    q[mk.dof_slices["left_knee"]] = 0.7
    mk.set_pose(q)
    sk.set_pose(sk.lower.clip(0.0, None))
    before = sk.neutral_pose().copy()
    try:
        turn_slave_off(pair)
        pair.update()
        np.testing.assert_array_equal(sk.neutral_pose(), before)  # off: the slave is left alone
        turn_slave_on(pair)
        pair.update()  # on: the SimulationFunction sets the slave figure from the master figure
        assert sk.neutral_pose()[sk.dof_slices["left_knee"]][0] == pytest.approx(0.7)
        palm = "right_palm.palmcenter"
        assert np.linalg.norm(mk.site_global(palm)[:3, 3] - sk.site_global(palm)[:3, 3]) < 1.0
    finally:
        mk.set_pose(np.zeros(mk.ndof))
        sk.set_pose(np.zeros(sk.ndof))
        pair.slave.location = pair.master.location.copy()


def _master_clip(pair: MasterSlavePair):
    """A short soldier.fig + AK_47.fig clip with the palms on the rifle, as the authoring pipeline makes."""
    mk = pair.master_kin
    rifle = pair.rifle
    assert rifle is not None
    q0 = _ready_pose(pair)
    g = mk.site_globals(q0)
    grip = g[mk.site_names.index("right_palm.palmcenter"), :3, 3]
    loc = np.eye(4)
    loc[:3, 3] = grip - rifle.site("rifle.grip").location[:3, 3]
    start = KeyPosture("ready", {pair.master.name: q0}, {rifle.name: loc})
    script = MotionScript([pair.master, rifle], start, duration=0.25)
    later = loc.copy()
    later[:3, 3] += [0.0, 6.0, -4.0]
    script.move_to(KeyPosture("up", {}, {rifle.name: later}), 0.0, 0.25)
    script.constrain(
        SiteConstraint(pair.master.name, "right_palm.palmcenter", rifle.name, "rifle.grip", priority=1)
    )
    script.constrain(
        SiteConstraint(pair.master.name, "left_palm.palmcenter", rifle.name, "rifle.handguard", priority=1)
    )
    return script.to_channelset("ready2up.chset", fps=60)


def test_reslave_channelset_records_the_slave_and_keeps_the_rifle(pair: MasterSlavePair) -> None:
    pair.slave_parameters("yes", "yes", "yes", "yes", 0.50, "yes", 0.50, "yes", "yes")
    master_cs = _master_clip(pair)
    low = reslave_channelset(master_cs, pair)
    assert low.name == "ready2up_low.chset" == low_name(master_cs.name)
    assert low.nframes == master_cs.nframes and low.fps == master_cs.fps
    types = {c.protofiletype for c in low.channels}
    assert types == {"DI.fig", "AK_47.fig"}
    assert {c.object for c in low.joint_channels()} == {
        j for j in pair.slave.joints if pair.slave.joints[j].ndofs
    }
    rifle_tracks = lambda cs: [t for t in cs.tracks() if t.protofiletype == "AK_47.fig"]  # noqa: E731
    assert channelsets_close(
        make_channelset("r", 60, rifle_tracks(low)),
        make_channelset("r", 60, rifle_tracks(master_cs)),
        atol=1e-6,
    )
    # the DI's palms hold the rifle wherever the master's did
    rec = create_channelset_motion(low, [pair.slave, pair.rifle])
    sk = pair.slave_kin
    ss = sk.site_globals(np.asarray(rec.poses["DI"], np.float64), np.asarray(rec.locations["DI"]))
    rk_sites = {s.name: s.location for s in pair.rifle.sites()}
    rloc = np.asarray(rec.locations[pair.rifle.name])
    for palm, site in (("right_palm.palmcenter", "grip"), ("left_palm.palmcenter", "handguard")):
        target = (rloc @ rk_sites[site])[:, :3, 3]
        d = np.linalg.norm(ss[:, sk.site_names.index(palm), :3, 3] - target, axis=1)
        assert d.max() < 1.0


def test_reslave_carries_optional_fields(pair: MasterSlavePair) -> None:
    master_cs = _master_clip(pair)
    master_cs.ground_speed = 123.5  # type: ignore[attr-defined]
    master_cs.stride_length = 70.25  # type: ignore[attr-defined]
    low = reslave_channelset(master_cs, pair, name="x_low.chset")
    assert low.name == "x_low.chset"
    assert (low.ground_speed, low.stride_length) == (123.5, 70.25)  # type: ignore[attr-defined]


def test_arms_let_go_in_place_blend_from_their_pose_at_the_release() -> None:
    """DeathSpec.slave_let_go_in_place: after the release the arms blend from the pose they had as the hands
    let go into the copied angles (ststow2dead's M16 slave's right shoulder leapt 22.5 degrees in the first
    frame, its goals tracked on); the other DOFs are left as they are."""
    from authoring.slaving import RELEASE_FADE_FRAMES, _let_go_in_place

    n, release = 40, 10
    poses = np.random.default_rng(0).normal(size=(n, 4))
    copied = np.zeros((n, 4))
    arms = np.array([True, True, False, False])
    out = _let_go_in_place(poses, copied, release, arms)
    np.testing.assert_array_equal(out[:release], poses[:release])
    np.testing.assert_array_equal(out[:, ~arms], poses[:, ~arms])
    step = np.abs(np.diff(out[release - 1 :, arms], axis=0)).max()
    assert step <= np.abs(poses[release - 1, arms]).max() * 0.25  # eased, no leap
    np.testing.assert_allclose(out[release - 1 + RELEASE_FADE_FRAMES :, arms], 0.0)  # the copied angles
