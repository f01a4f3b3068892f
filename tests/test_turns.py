"""Turns in place and side-steps (committed soldier.fig and DI.fig clips, the M16 ones too): each
reaches its yaw or its sideways displacement, ends in STAND_STOWED moved by its ``end_offset`` (a turn: where
it started, turned about the pelvis), turns a foot on the ground only by pivoting on its ball (the inside
foot first, while the outer one steps round), and never slides a foot that touches the ground."""

from __future__ import annotations

import math

import numpy as np
import pytest

from authoring import crawl_turn, turns
from authoring.gait import BaseStance
from authoring.quality import FigureSet, play
from server.motion.cache import load_channelset
from server.motion.posture_change import load_posture_graph
from ttes.paths import CHANNELSETS, FIGURES, POSTURE_GRAPHS

CONTACT = 2.5  # cm: a foot point this low is touching the ground, whatever its speed (the check: 1.25)
SUFFIXES = {"": "soldier.fig", "_low": "DI.fig", "_m16_low": "DI.fig"}
GRAPHS = {"": "soldier_turn_hi.graph", "_low": "soldier_turn.graph", "_m16_low": "soldier_turn_m16.graph"}
TURNS = [(f"turn_{d[0]}{a}", d, a) for d in ("left", "right") for a in turns.TURN_ANGLES]
FOOT_POINTS = ("foot.heel", "foot.ball", "toes.distal")


@pytest.fixture(scope="module")
def figures() -> FigureSet:
    return FigureSet.from_dir(FIGURES, ["soldier.fig", "DI.fig", "AK_47.fig", "M16.fig"])


def _played(name: str, suffix: str, figures: FigureSet):
    cs = load_channelset(CHANNELSETS / f"{name}{suffix}.chset.env")
    cf = play(cs, figures)
    body = SUFFIXES[suffix]
    kin = figures.kin[body]
    sites = kin.site_globals(cf.poses[body], cf.locations[body])
    return cs, cf, body, kin, sites


def _point(kin, sites, side: str, point: str) -> np.ndarray:
    return sites[:, kin.site_names.index(f"{side}_{point}"), :3, 3]


def _yaw(m: np.ndarray) -> float:
    """Degrees about +Y that turn -Z (the facing direction) to ``m``'s -Z (+ = to the left)."""
    f = -m[:3, 2]
    return math.degrees(math.atan2(-f[0], -f[2]))


@pytest.mark.parametrize("suffix", SUFFIXES)
def test_turn_graph_lists_every_clip_as_a_self_loop_on_its_posture(suffix: str):
    """The standing turns and side-steps loop on STAND_STOWED, the turns on the ground on CRAWL."""
    loaded = load_posture_graph(POSTURE_GRAPHS / GRAPHS[suffix])
    assert loaded.graph.postures == ["STAND_STOWED", "CRAWL"]
    stems = [f.rsplit("/", 1)[-1].removesuffix(f"{suffix}.chset.env") for f in loaded.graph.files]
    assert stems == [*turns.TURN_CLIPS, *crawl_turn.CRAWL_TURN_CLIPS]
    loops = {(stems[a.channelset], a.start, a.end, a.forward) for a in loaded.graph.arcs}
    node = {name: "STAND_STOWED" for name in turns.TURN_CLIPS} | {
        n: "CRAWL" for n in crawl_turn.CRAWL_TURN_CLIPS
    }
    assert loops == {(name, p, p, True) for name, p in node.items()}
    assert sorted(a.channelset for a in loaded.graph.arcs) == list(range(len(stems)))


@pytest.mark.parametrize("suffix", SUFFIXES)
@pytest.mark.parametrize("name", turns.TURN_CLIPS)
def test_clip_ends_in_stand_stowed_moved_by_its_end_offset(name: str, suffix: str, figures: FigureSet):
    cs, cf, body, kin, sites = _played(name, suffix, figures)
    assert cs.end_offset is not None
    x, z, yaw = cs.end_offset
    if name.startswith("turn_"):
        angle = float(name[6:]) * (1.0 if name[5] == "l" else -1.0)
        assert yaw == angle
    else:
        assert (abs(x), z, yaw) == (turns.SIDESTEP, 0.0, 0.0)
        assert x < 0 if name.endswith("_l") else x > 0  # left is -x
    np.testing.assert_allclose(cs.joint_data[-1], cs.joint_data[0], atol=1e-5)
    move = turns.ground_move(x, z, yaw)
    for ptype in cf.locations:
        a, b = cf.locations[ptype][0], cf.locations[ptype][-1]
        np.testing.assert_allclose(b[:3, 3], (move @ a)[:3, 3], atol=0.02, err_msg=ptype)
        np.testing.assert_allclose(b[:3, :3], (move @ a)[:3, :3], atol=1e-4, err_msg=ptype)
    turned = _yaw(cf.locations[body][-1]) - _yaw(cf.locations[body][0]) - yaw
    assert (turned + 180.0) % 360.0 - 180.0 == pytest.approx(0.0, abs=0.01)
    for side in ("left", "right"):  # both feet end flat on the ground in the moved stance
        for p in FOOT_POINTS:
            pts = _point(kin, sites, side, p)
            end = move[:3, :3] @ pts[0] + move[:3, 3]
            np.testing.assert_allclose(pts[-1], end, atol=0.05, err_msg=f"{side}_{p}")


@pytest.mark.parametrize("suffix", SUFFIXES)
@pytest.mark.parametrize("name", turns.TURN_CLIPS)
def test_feet_never_slide_on_or_sink_into_the_ground(name: str, suffix: str, figures: FigureSet):
    """Each foot point, while it touches the ground, keeps its place about the ball: a foot pivoting on its
    ball swings its heel and toes round it (the foot's turn is taken out about the ball), the ball stays."""
    _, _, _, kin, sites = _played(name, suffix, figures)
    for side in ("left", "right"):
        ball = _point(kin, sites, side, "foot.ball")
        yaw = np.radians(_foot_yaw(kin, sites, side))
        for p in FOOT_POINTS:
            pts = _point(kin, sites, side, p)
            assert pts[:, 1].min() > -1.0, f"{side}_{p} in the ground"
            touching = np.r_[False, pts[:, 1] <= CONTACT, False]
            starts = np.flatnonzero(~touching[:-1] & touching[1:])
            stops = np.flatnonzero(touching[:-1] & ~touching[1:])
            for a, b in zip(starts, stops, strict=True):
                turn = yaw[a:b] - yaw[a]
                arm = (pts[a:b] - ball[a:b])[:, [0, 2]]
                c, s_ = np.cos(turn), np.sin(turn)
                back = np.stack([arm[:, 0] * c - arm[:, 1] * s_, arm[:, 0] * s_ + arm[:, 1] * c], axis=1)
                xz = ball[a:b][:, [0, 2]] + back
                slide = np.sqrt(((xz[:, None] - xz[None]) ** 2).sum(-1)).max()
                assert slide <= 2.0, f"{name}{suffix} {side}_{p} slides {slide:.2f} cm in frames {a}..{b}"


def _foot_yaw(kin, sites, side: str) -> np.ndarray:
    """Degrees about +Y of the heel-to-ball direction of a foot, per frame (unwrapped)."""
    d = _point(kin, sites, side, "foot.ball") - _point(kin, sites, side, "foot.heel")
    return np.degrees(np.unwrap(np.arctan2(-d[:, 0], -d[:, 2])))


def test_turn_steps_alternate_feet_never_more_than_45_degrees_apart():
    assert turns.turn_steps(45) == [("outer", 45.0), ("inside", 45.0)]
    assert turns.turn_steps(90) == [("outer", 45.0), ("inside", 90.0), ("outer", 90.0)]
    assert [y for _, y in turns.turn_steps(180)] == [45.0, 90.0, 135.0, 180.0, 180.0]


@pytest.mark.parametrize("suffix", SUFFIXES)
@pytest.mark.parametrize(("name", "side", "angle"), TURNS)
def test_a_turn_pivots_on_the_inside_ball_and_ends_where_it_started(
    name: str, side: str, angle: int, suffix: str, figures: FigureSet
):
    """Issue 14: the inside foot pivots on its ball (heel up, 15 degrees or more) while the outer foot steps
    round; every foot turning on the ground turns on its ball (above); the pelvis ends where it began."""
    cs, cf, body, kin, sites = _played(name, suffix, figures)
    assert cs.end_offset is not None and math.hypot(cs.end_offset[0], cs.end_offset[1]) < 0.01
    root = cf.locations[body][:, :3, 3]
    assert math.hypot(*(root[-1] - root[0])[[0, 2]]) < 0.05
    sign = 1.0 if side == "left" else -1.0
    down = {}
    for s in ("left", "right"):
        low = np.min([_point(kin, sites, s, p)[:, 1] for p in FOOT_POINTS], axis=0) <= CONTACT
        down[s] = low
        edges = np.flatnonzero(np.diff(np.r_[0, low.astype(int), 0]))
        lifts = len(edges) // 2 - 1
        want = sum(1 for role, _ in turns.turn_steps(angle) if (role == "inside") == (s == side))
        assert lifts == want, s
        if s == side:  # the inside foot stands while the outer one steps first, and pivots on its ball
            yaw = _foot_yaw(kin, sites, s)
            first = slice(edges[0], edges[1])
            assert sign * (yaw[first][-1] - yaw[first][0]) >= 15.0
    assert (down["left"] | down["right"]).all()  # a step, never a hop
    body_yaw = np.array([_yaw(m) for m in cf.locations[body]])
    progress = sign * np.degrees(np.unwrap(np.radians(body_yaw - body_yaw[0])))
    assert progress.min() > -0.5 and progress.max() < angle + 0.5
    assert np.diff(progress).min() > -0.2  # the body never turns back


@pytest.mark.parametrize("suffix", SUFFIXES)
@pytest.mark.parametrize("name", turns.TURN_CLIPS)
def test_clips_ease_in_and_out(name: str, suffix: str, figures: FigureSet):
    cs, _, _, _, sites = _played(name, suffix, figures)
    speed = np.linalg.norm(np.diff(sites[:, :, :3, 3], axis=0), axis=-1) * cs.fps  # cm/s per site
    assert speed[0].max() <= 50.0 and speed[-1].max() <= 50.0


@pytest.mark.parametrize("direction", ["left", "right"])
def test_sidestep_leads_with_the_foot_on_its_side_and_never_crosses_the_feet(direction: str, figures):
    _, _, _, kin, sites = _played(f"sidestep_{direction[0]}", "", figures)
    trail = "right" if direction == "left" else "left"
    lead_up = np.flatnonzero(_point(kin, sites, direction, "foot.ball")[:, 1] > CONTACT)
    trail_up = np.flatnonzero(_point(kin, sites, trail, "foot.ball")[:, 1] > CONTACT)
    assert lead_up.max() < trail_up.min()  # the leading foot has landed before the trailing foot lifts
    gap = _point(kin, sites, "right", "foot.heel")[:, 0] - _point(kin, sites, "left", "foot.heel")[:, 0]
    assert gap.min() > 10.0  # the left heel stays well to the left (-x) of the right one


def test_turn_plan_turns_the_stance_about_the_pelvis():
    base = BaseStance(
        {"left": (-15.0, -12.0), "right": (2.0, 14.0)},
        {"left": -10.0, "right": -25.0},
        {"left": np.array([-0.7, 0.0, -21.5]), "right": np.array([0.7, 0.0, -21.5])},
        np.zeros(2),
    )
    for side in ("left", "right"):
        for angle in turns.TURN_ANGLES:
            plan = turns.plan_turn(base, side, angle)
            assert plan.end_move == (0.0, 0.0, angle if side == "left" else -angle)
            assert plan.pivot == (0.0, 0.0)  # the pelvis' ground point


def test_rebuilding_a_turn_reproduces_the_committed_bytes(tmp_path):
    from authoring import build as B

    B.build(tmp_path, FIGURES, only="turn_r45", figure="soldier", progress=False)
    rel = "channelsets/turn_r45.chset.env"
    assert (tmp_path / rel).read_bytes() == (CHANNELSETS / "turn_r45.chset.env").read_bytes()
    graph = "posture_graphs/soldier_turn_hi.graph"
    assert (tmp_path / graph).read_bytes() == (POSTURE_GRAPHS / "soldier_turn_hi.graph").read_bytes()
