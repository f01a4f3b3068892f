"""Turns in place and side-steps (committed soldier.fig and DI.fig clips): each reaches its yaw or its
sideways displacement, ends in STAND_STOWED moved by its ``end_offset``, pivots on the inside foot's ball
with the heel up, and never slides a foot that touches the ground."""

from __future__ import annotations

import math

import numpy as np
import pytest

from server.authoring import turns
from server.authoring.gait import BaseStance
from server.authoring.quality import FigureSet, play
from server.motion.cache import load_channelset
from server.motion.posture_change import load_posture_graph
from ttes.paths import CHANNELSETS, FIGURES, POSTURE_GRAPHS

CONTACT = 2.5  # cm: a foot point this low is touching the ground, whatever its speed
SUFFIXES = {"": "soldier.fig", "_low": "DI.fig"}
TURNS = [(f"turn_{d[0]}{a}", d, a) for d in ("left", "right") for a in turns.TURN_ANGLES]
FOOT_POINTS = ("foot.heel", "foot.ball", "toes.distal")


@pytest.fixture(scope="module")
def figures() -> FigureSet:
    return FigureSet.from_dir(FIGURES, ["soldier.fig", "DI.fig", "AK_47.fig"])


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
def test_turn_graph_lists_every_clip_as_a_stand_stowed_self_loop(suffix: str):
    name = "soldier_turn.graph" if suffix else "soldier_turn_hi.graph"
    loaded = load_posture_graph(POSTURE_GRAPHS / name)
    assert loaded.graph.postures == ["STAND_STOWED"]
    stems = [f.rsplit("/", 1)[-1].removesuffix(f"{suffix}.chset.env") for f in loaded.graph.files]
    assert stems == list(turns.TURN_CLIPS)
    loops = {(a.start, a.end, a.forward) for a in loaded.graph.arcs}
    assert loops == {("STAND_STOWED", "STAND_STOWED", True)}
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
    _, _, _, kin, sites = _played(name, suffix, figures)
    for side in ("left", "right"):
        for p in FOOT_POINTS:
            pts = _point(kin, sites, side, p)
            assert pts[:, 1].min() > -1.0, f"{side}_{p} in the ground"
            touching = np.r_[False, pts[:, 1] <= CONTACT, False]
            starts = np.flatnonzero(~touching[:-1] & touching[1:])
            stops = np.flatnonzero(touching[:-1] & ~touching[1:])
            for a, b in zip(starts, stops, strict=True):
                xz = pts[a:b][:, [0, 2]]
                slide = np.sqrt(((xz[:, None] - xz[None]) ** 2).sum(-1)).max()
                assert slide <= 2.0, f"{name}{suffix} {side}_{p} slides {slide:.2f} cm in frames {a}..{b}"


@pytest.mark.parametrize("suffix", SUFFIXES)
@pytest.mark.parametrize(("name", "side", "angle"), TURNS)
def test_turn_pivots_on_the_inside_ball_heel_up_while_the_other_foot_steps(
    name: str, side: str, angle: int, suffix: str, figures: FigureSet
):
    _, cf, body, kin, sites = _played(name, suffix, figures)
    other = "right" if side == "left" else "left"
    ball = _point(kin, sites, side, "foot.ball")
    assert np.linalg.norm((ball - ball[0])[:, [0, 2]], axis=1).max() < 1.5
    yaw = np.array([_yaw(m) for m in cf.locations[body]]) - _yaw(cf.locations[body][0])
    yaw = (yaw + 180.0) % 360.0 - 180.0 if angle < 180 else np.unwrap(yaw * math.pi / 180) * 180 / math.pi
    turning = np.abs(np.gradient(yaw)) > 0.5  # degrees per frame
    assert turning.any()
    for p in ("foot.heel", "toes.distal"):  # only the ball of the pivot foot is on the ground while it turns
        assert _point(kin, sites, side, p)[turning, 1].min() > CONTACT, p
    # the outer foot is in the air while it travels round the pivot
    for p in FOOT_POINTS:
        pts = _point(kin, sites, other, p)
        moving = np.linalg.norm(np.gradient(pts[:, [0, 2]], axis=0), axis=1) * cf.channelset.fps > 10.0
        assert pts[moving, 1].min() > CONTACT, p


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


def test_turn_plan_moves_the_stance_about_the_pivot_ball():
    base = BaseStance(
        {"left": (-15.0, -12.0), "right": (2.0, 14.0)},
        {"left": -10.0, "right": -25.0},
        {"left": np.array([-0.7, 0.0, -21.5]), "right": np.array([0.7, 0.0, -21.5])},
        np.zeros(2),
    )
    for side in ("left", "right"):
        for angle in turns.TURN_ANGLES:
            plan = turns.plan_turn(base, side, angle)
            assert plan.end_move[2] == (angle if side == "left" else -angle)
            bx, bz = base.ball_at(side)
            ball = np.array([bx, 0.0, bz, 1.0])
            np.testing.assert_allclose(turns.ground_move(*plan.end_move) @ ball, ball, atol=1e-9)
