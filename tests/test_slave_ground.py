"""A dying DI.fig slave rests where its master rests (authoring/slave_ground.py): after the hands let go, its
trunk, limbs and feet lie as low as the master's, nothing goes into the ground, and the dropped rifle lies
clear of the slave's body and the ground (issue 14: DEAD@ststow's slave hovered 10 cm up, heels 30 cm)."""

from __future__ import annotations

import copy

import numpy as np
import pytest

pytest.importorskip("scipy")

from authoring import slave_ground
from authoring.body_parts import SegmentHulls
from authoring.build import BuildContext, lift_off_ground, slave_pair
from authoring.postures import lowest_point
from authoring.quality_frames import FigureSet, play
from authoring.slave_body import part_heights
from authoring.slave_contacts import rest_slave_forearms, rest_slave_knees, tilt_onto_knees
from authoring.slave_ground import clear_rifle, rest_limbs
from authoring.slaving import reslave_channelset
from server.motion.cache import load_channelset
from ttes.paths import CHANNELSETS, FIGURES


@pytest.fixture(scope="module")
def fallen():
    """ststow2dead and its DI slave as the build made it before the limbs are laid down."""
    ctx = BuildContext.load(FIGURES)
    figs = FigureSet({"soldier.fig": ctx.soldier, "DI.fig": ctx.di, "AK_47.fig": ctx.rifle})
    master = load_channelset(CHANNELSETS / "ststow2dead.chset.env", use_cache=False)
    slave = reslave_channelset(master, slave_pair(ctx), "ststow2dead_low.chset")
    for rest in (rest_slave_knees, rest_slave_forearms, tilt_onto_knees):
        rest(master, slave, figs)
        lift_off_ground(slave, ctx.di)
    return ctx, figs, master, slave


def _height(figs: FigureSet, cs, part: str, side: str = "") -> np.ndarray:
    f = play(cs, figs)
    ptype = max(f.poses, key=lambda k: figs.kin[k].ndof)
    return part_heights(f.poses[ptype], f.locations[ptype], figs, ptype, part, (side,))[side]


def test_the_dead_slave_lies_as_low_as_his_master(fallen) -> None:
    ctx, figs, master, before = fallen
    slave = copy.deepcopy(before)
    rest_limbs(master, slave, figs)
    lift_off_ground(slave, ctx.di)
    assert _height(figs, before, "pelvis")[-1] > 5.0  # the copied angles put a hand into the ground
    # down from 10.4 cm; the check's 2 cm is not yet met (issue 14): 2.98 on the master of the slave_ground
    # branch, 3.03 on the master with the dead settle (the DI's pelvis sits higher on its belly)
    assert _height(figs, slave, "pelvis")[-1] <= 3.5
    assert min(_height(figs, slave, p)[-1] for p in ("belly", "chest")) <= 2.0
    # the feet come down with the body, about as high as the master's (his legs now lie as the physics
    # rolled them, DeathSpec.legs_settle: the slave's right foot 2.0004 cm above his at this stage, within
    # DI's active range; the finished slave's heels: the check's rest_foot)
    for side in ("left", "right"):
        assert _height(figs, slave, "foot", side)[-1] <= _height(figs, master, "foot", side)[-1] + 2.5
    f = play(slave, figs)
    assert lowest_point(figs.kin["DI.fig"], f.poses["DI.fig"], f.locations["DI.fig"]).min() > -1.0
    # the frames the hands still hold the rifle are left alone
    r = slave.release_frame
    np.testing.assert_array_equal(slave.joint_data[:r], before.joint_data[:r])


def test_the_dropped_rifle_is_put_clear_of_the_body_and_the_ground(fallen) -> None:
    _, figs, _, before = fallen
    slave = copy.deepcopy(before)
    r, n = slave.release_frame, slave.nframes
    f = play(slave, figs)
    rifle = next(c for c in slave.figure_channels() if c.protofiletype == "AK_47.fig")
    # after the release the rifle lies 3 cm into the ground and 4 cm nearer the body than it fell
    toward = f.locations["DI.fig"][r:, :3, 3] - f.locations["AK_47.fig"][r:, :3, 3]
    toward[:, 1] = 0.0
    toward *= 4.0 / np.linalg.norm(toward, axis=1)[:, None]
    slave.fig_pos[r:, rifle.column] += (toward - np.array([0.0, 3.0, 0.0])).astype(np.float32)
    nodes, _ = figs.nodes("AK_47.fig")
    kin = figs.kin["DI.fig"]
    segs = kin.segment_globals(f.poses["DI.fig"], f.locations["DI.fig"])
    dropped = np.einsum("fij,kj->fki", play(slave, figs).locations["AK_47.fig"][:, :3, :], nodes)
    assert figs.hulls("DI.fig").depth(dropped[r + 6 :], segs[r + 6 :])[0] > 1.0
    clear_rifle(slave, figs)
    pts = np.einsum("fij,kj->fki", play(slave, figs).locations["AK_47.fig"][:, :3, :], nodes)
    assert figs.hulls("DI.fig").depth(pts[r + 6 :], segs[r + 6 :])[0] <= 1.0
    assert pts[r + 6 :, :, 1].min() >= 0.0
    np.testing.assert_array_equal(slave.fig_pos[:r], before.fig_pos[:r])  # held: where the hands hold it
    assert n > r + 6


def _lowest(figs: FigureSet, cs) -> np.ndarray:
    f = play(cs, figs)
    return lowest_point(figs.kin["DI.fig"], f.poses["DI.fig"], f.locations["DI.fig"])


def test_lifting_the_body_leaves_a_dropped_rifle_where_it_lies(fallen) -> None:
    ctx, figs, _, before = fallen
    slave = copy.deepcopy(before)
    body = next(c for c in slave.figure_channels() if c.protofiletype == "DI.fig")
    rifle = next(c for c in slave.figure_channels() if c.protofiletype == "AK_47.fig")
    slave.fig_pos[:, body.column, 1] -= 5.0  # the whole body 5 cm into the ground
    lifted = copy.deepcopy(slave)
    lift_off_ground(lifted, ctx.di)
    r = slave.release_frame
    # out of the ground in every frame, and lifted the 5 cm back wherever the body was on the ground (a
    # falling body may be in the air a moment: ststow2dead's slave 1.4 cm up as he pitches off his knees)
    assert _lowest(figs, lifted).min() > -0.1
    rise = lifted.fig_pos[:, body.column, 1] - slave.fig_pos[:, body.column, 1]
    on_ground = _lowest(figs, before) < 1.0
    assert on_ground.mean() > 0.8 and np.all(rise[on_ground] > 4.0)
    np.testing.assert_array_equal(lifted.fig_pos[r:, rifle.column], slave.fig_pos[r:, rifle.column])
    assert np.all(lifted.fig_pos[:r, rifle.column, 1] > slave.fig_pos[:r, rifle.column, 1])


def test_a_hull_says_how_deep_a_point_is_and_which_way_is_out() -> None:
    cube = np.array([[x, y, z, 1.0] for x in (0, 10) for y in (0, 10) for z in (0, 10)], np.float64)
    hulls = SegmentHulls.build(cube, np.zeros(len(cube), int), np.array([0]))
    globals_ = np.broadcast_to(np.eye(4), (2, 1, 4, 4)).copy()
    globals_[1, 0, :3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]  # turned 90 degrees about z
    pts = np.array([[[9.0, 5.0, 5.0], [20.0, 5.0, 5.0]], [[-5.0, 9.5, 5.0], [20.0, 5.0, 5.0]]])
    depth, out = hulls.exits(pts, globals_)
    np.testing.assert_allclose(depth, [1.0, 0.5])
    np.testing.assert_allclose(out, [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], atol=1e-9)
    assert hulls.depth(pts, globals_)[:2] == (pytest.approx(1.0), 0)


def test_a_part_the_master_holds_up_is_not_laid_on_the_ground() -> None:
    """A dead leg lifted clear to turn (authoring/dead_legs.py): the master's foot 12 cm up while DI's thigh
    was laid on the ground with it put DI's foot at 1 cm, and it skidded 9.7 cm as it turned."""
    master, slave = np.array([0.0, 12.0, 12.0]), np.array([0.5, 1.0, 9.0])
    need = slave_ground._need(master, slave)
    assert need[0] == pytest.approx(-0.5)  # on the ground: to the master's height
    assert slave[1] + need[1] >= slave_ground.AIR_SHARE * 12.0 - 1e-9  # up in the air: kept up with his
    assert need[2] == 0.0  # high enough already: left alone


def test_a_part_landing_as_the_trunk_settles_is_held_where_the_solve_has_it() -> None:
    """DI crawl2dead (issue 14): a hand landing once the trunk went down was held where the unsolved slave
    had it, 3-5 cm off; the solve jumped there and the smoothing made the jump a 6.3 cm slide."""
    n, release = 6, 0
    heights = {"right_hand": np.array([5.0, 5.0, 0.0, 0.0, 0.0, 5.0])}  # the master's hand lands at frame 2
    unsolved = {s: np.zeros((n, 3)) for s in slave_ground.PART_SITES["right_hand"]}
    solved = {s: np.tile([4.0, 0.0, -3.0], (n, 1)) for s in unsolved}
    master = {slave_ground.ROOT: np.zeros((n, 3))}
    for settling, start in ((np.zeros(n, bool), [0.0, 0.0]), (np.ones(n, bool), [4.0, -3.0])):
        planted = slave_ground._plants(unsolved, master, heights, release, (solved, settling))
        hold = planted["right_lower_arm.distal"]
        assert np.isnan(hold[:2]).all() and np.isnan(hold[5]).all()
        np.testing.assert_allclose(hold[2:5][:, [0, 2]], [start] * 3)  # held still from where it landed


def test_an_arm_that_follows_is_held_where_the_masters_goes_once_it_lifts() -> None:
    """DI crawl2dead (issue 14): once the master lifted his arm it was held nowhere, and each solve pass put
    it out sideways again from where the last left it (8-10 cm, dragged along the ground as it rose).
    Following (``DeathSpec.slave_arms_follow``), an arm's sites are held from the release to the end where
    the master's go, from where the slave's were; the legs are planted only while the master's are down."""
    n, release = 6, 1
    heights = {"right_hand": np.array([0.0, 0.0, 0.0, 5.0, 5.0, 5.0]), "right_knee": np.zeros(n)}
    heights["right_knee"][3:] = 5.0
    sites = (*slave_ground.PART_SITES["right_hand"], *slave_ground.PART_SITES["right_knee"])
    unsolved = {s: np.tile([1.0, 0.0, 2.0], (n, 1)) for s in sites}
    master = {slave_ground.ROOT: np.outer(np.arange(n), [1.0, 0.0, 0.0])}  # he moves 1 cm a frame in x
    held = slave_ground._plants(unsolved, master, heights, release)["right_lower_arm.distal"]
    assert np.isnan(held[3:]).all()  # unheld once his hand lifts
    follows = slave_ground._plants(unsolved, master, heights, release, follow=True)
    hand = follows["right_lower_arm.distal"]
    assert np.isnan(hand[:release]).all()
    np.testing.assert_allclose(hand[release:, 0], 1.0 + np.arange(n - release))
    np.testing.assert_allclose(hand[release:, 2], 2.0)
    assert np.isnan(follows["right_lower_leg.knee"][3:]).all()
    from authoring import deaths

    assert [d.name for d in deaths.DEATHS if d.slave_arms_follow] == ["crawl2dead"]


def test_an_arm_in_the_ground_goes_out_sideways_from_the_chest() -> None:
    """DI crawl2dead's forearm lay 2-7 cm in the ground under its chest and the arm could not lift it (its
    shoulder is on the chest): it goes out horizontally, away from the chest, as far as it must go up."""
    at = np.array([[10.0, -3.0, 0.0], [0.0, -1.0, -5.0], [3.0, 2.0, 4.0]])
    chest = np.array([[0.0, 10.0, 0.0], [0.0, 10.0, 0.0], [0.0, 10.0, 0.0]])
    out = slave_ground._sideways(at, chest, np.array([3.0, 1.0, -2.0]))
    np.testing.assert_allclose(out, [[3.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 0.0, 0.0]])


def test_only_the_crawlers_and_ststow2dead_slaves_move_their_arms_out_sideways() -> None:
    """The sideways move is the crawl death's own setting and ststow2dead's, there with its trunk laid by the
    root alone and its feet held where they land (alone, DI ststow2dead's feet skated 2.35 cm with it, its
    head rested 6.3 cm up; stfire2dead's trunk and feet too since its legs are laid from 1.0 s, DI/M16 foot
    skate 3.68 cm without them): the other deaths' slaves rebuild unchanged."""
    from authoring import deaths

    assert {d.name for d in deaths.DEATHS if d.slave_arm_out} == {"crawl2dead", "ststow2dead"}
    both = {d.name for d in deaths.DEATHS if d.slave_trunk_rigid or d.slave_feet_landed}
    assert both == {"ststow2dead", "stfire2dead"}


def test_the_trunk_is_down_once_pelvis_and_chest_stay_near_where_they_end() -> None:
    """kfire2dead (issue 14): the master's trunk was down 0.25 s before his root, still rolling him on the
    ground, stopped; judged at his root the DI's trunk, lifted out of the ground by its arm under it, was laid
    only then and hovered, pelvis 6-11 cm up (trunk_rise 5.28 cm). With DeathSpec.slave_settle_down it
    settles from the frame his pelvis and chest both lie within DOWN_CM of where they end."""
    near = slave_ground.DOWN_CM - 0.5
    pelvis = np.array([40.0, 20.0, 3.0, 1.0 + near, 2.0, 1.0 + near, 1.0, 1.0])  # down from frame 2
    chest = np.array([60.0, 40.0, 20.0, 9.0, 0.0, near, 0.0, 0.0])  # down from frame 4
    assert slave_ground._trunk_down({"pelvis": pelvis, "chest": chest}) == 4
    assert slave_ground._trunk_down({"pelvis": np.ones(3), "chest": np.zeros(3)}) == 0


def test_only_kfire2dead_slaves_settle_once_the_trunk_is_down() -> None:
    """The settle from the trunk down is kfire2dead's own setting: the other deaths' slaves rebuild
    unchanged."""
    from authoring import deaths

    assert {d.name for d in deaths.DEATHS if d.slave_settle_down} == {"kfire2dead"}


def test_a_master_rolling_his_pelvis_in_place_lies_still() -> None:
    """A prone death's master rolls his pelvis about a pelvis node on the ground with each leg
    (DeathSpec.prone_legs_roll): his root moves ~10 cm/s, yet his body lies still, and the slave's trunk is
    lowered onto the ground while he does (judged at his root alone, it waited for the last 6 frames: the
    DI's pelvis stayed 1.8 cm up and its belly slid 7.7 cm)."""
    from authoring import prone_roll
    from authoring.dead_settle import _Body
    from peabody.loader import read_figure

    figs = FigureSet(
        {"body": read_figure(FIGURES / "soldier.fig"), "rifle": read_figure(FIGURES / "AK_47.fig")}
    )
    kin = figs.kin["body"]
    root = np.eye(4)
    root[:3, :3] = [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]  # face down
    body = _Body(figs, np.zeros(kin.ndof), root, np.eye(4))
    pivot, axis = prone_roll._pivot(body, "left")
    t = np.linspace(0.0, 1.0, 30)
    roots = prone_roll._rolled_roots(root, pivot, axis, np.radians(8.0) * np.sin(np.pi * t))
    q = np.zeros((len(t), kin.ndof))
    fps = 60.0
    assert (
        np.linalg.norm(np.diff(roots[:, :3, 3], axis=0), axis=1) * fps
    ).max() > slave_ground.SETTLE_SPEED_CM_S
    in_place = slave_ground._rolling_in_place(q, roots, figs, "body")
    assert in_place.all()
    assert slave_ground._settled(roots, fps)[-1] == 0.0  # judged at the root, he never lay still
    assert slave_ground._settled(roots, fps, in_place)[slave_ground.SETTLE_FRAMES :] == pytest.approx(1.0)


def test_a_slave_settles_once_its_masters_arms_lie_still_where_the_death_asks() -> None:
    """prstow2dead's master lowers his chest as he is hit (DeathSpec.lowered_at) and swings his arms in
    beside him while his pelvis lies still: the slave's trunk settled then and swept its right forearm
    4.0 cm along the ground as it swung out. Where the death asks (slave_settle_arms_still) the settle waits
    for the master's arm and head sites to be still; only the two prone deaths ask it."""
    from authoring import deaths

    fps, n = 60.0, 40
    still = np.zeros((n, 3))
    swing = still.copy()
    swing[:25, 0] = np.linspace(0.0, 10.0, 25)  # 25 cm/s over frames 0-24, still from frame 24 on
    swing[25:, 0] = 10.0
    at = {"right_lower_arm.distal": swing, "left_lower_arm.distal": still, "bottom_head.distal": still}
    assert slave_ground._arms_still(at, fps) == 24
    assert slave_ground._arms_still({"right_lower_arm.distal": still}, fps) == 0
    asked = {d.name for d in deaths.DEATHS if d.slave_settle_arms_still}
    assert asked == {"prstow2dead", "prfire2dead"}
