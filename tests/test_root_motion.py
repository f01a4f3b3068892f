"""Root motion that matches the entity (issue 16): the figure's root offset relative to the dead-reckoned
entity keeps every planted foot still in the world at starts, stops, walk <-> run and side-steps.

The measure is independent of the server's own bookkeeping: forward kinematics of the poses it sends (root
placement included), placed at the entity's dead-reckoned position and heading as an image generator would;
a sole point (heel or ball) touching the ground must not move more than 2 cm while it stays down."""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pytest

from peabody.fk import FigureKinematics
from peabody.quaternion import to_matrix
from protocol.entity import Appearance, WeaponState, make_entity_requests
from server.soldier.manager import REQUEST_OK, SoldierManager
from server.soldier.root_motion import FRAME_TURN_DEG, SIDE_TURN_DEG, feet_points, side_turns, step_turns
from tests.test_gait_selection import shipped_library

HZ = 60.0
CONTACT_CM = 1.0  # a sole point this near the ground touches it
SKATE_CM = 2.0


@pytest.fixture(scope="module")
def lib():
    return shipped_library()


def drive(
    lib,
    script: list[tuple[float, ...]],
    heading: float,
    until: float,
    weapon: str = "AK_47.fig",
    appearance: Appearance = Appearance.UPRIGHT,
) -> dict[str, np.ndarray]:
    """Play ``(time, speed m/s, compass degrees of the velocity from the heading[, new heading])`` requests;
    return per tick the world positions of the sole points ``(n, feet, points, 2)`` (Performer X east, Y
    north, cm), their heights ``(n, feet, points)``, the clip each tick shows and what the client got: the
    ``placements`` ``(n, figures, 7)`` (soldier frame) and ``joints`` of the soldier then the weapon."""
    m = SoldierManager(lib, throttle=0.0, record_clips=True)
    i = m.create_soldier(figure="DI.fig", weapon=weapon, now=0.0)
    fset = lib.sets[lib.set_index("DI.fig", weapon)]
    kin = FigureKinematics(fset.prototypes[0])
    sl = fset.figure_slice("DI.fig")
    pos, vel, last = np.zeros(2), np.zeros(2), 0.0  # the entity, dead-reckoned (m, m/s)
    pending = sorted(script)
    joints, figures, entity, clips, headings, placements, poses = [], [], [], [], [], [], []
    for k in range(int(until * HZ) + 1):
        now = k / HZ
        pos = pos + vel * (now - last)
        last = now
        while pending and pending[0][0] <= now + 1e-9:
            _, speed, angle, *turn = pending.pop(0)
            heading = turn[0] if turn else heading
            a = math.radians(heading + angle)
            vel = speed * np.array([math.sin(a), math.cos(a)])
            rows = make_entity_requests(
                i, appearance, WeaponState.DEPLOYED, (*vel, 0.0), heading, (*pos, 0.0)
            )
            assert m.apply_requests(rows, now).tolist() == [REQUEST_OK]
        m.tick(now)
        up = m.snapshot([i])  # what the client shows now (a resting soldier's last update included)
        joints.append(up.joints[0, sl])
        figures.append(up.figures[0, 0])
        placements.append(up.figures[0])
        poses.append(up.joints[0])
        entity.append(pos.copy())
        headings.append(math.radians(heading))
        clips.append(lib.clip_names[int(up.clips[0])])
    local = feet_points(kin, np.array(joints), np.array(figures))  # Jack, soldier frame: X right, -Z ahead
    h = np.array(headings)[:, None]
    forward = np.concatenate([np.sin(h), np.cos(h)], axis=1)[:, None, None, :]
    right = np.concatenate([np.cos(h), -np.sin(h)], axis=1)[:, None, None, :]
    world = in_world(local, np.array(entity), np.array(headings))
    root = np.array(figures)[:, [0, 2]]  # the figure's offset from the entity (soldier frame)
    gap = root[:, 0:1] * right[:, 0, 0] - root[:, 1:2] * forward[:, 0, 0]  # ... in the world
    faces = np.einsum("nij,j->ni", to_matrix(np.array(figures, np.float64)[:, 3:7]), [0.0, 0.0, -1.0])
    ahead = faces[:, 0:1] * right[:, 0, 0] - faces[:, 2:3] * forward[:, 0, 0]  # the figure's forward, world
    yaw = np.degrees(np.arctan2(ahead[:, 0], ahead[:, 1]))  # compass degrees the figure faces
    return {"world": world, "height": local[..., 1], "clips": np.array(clips), "gap": gap, "yaw": yaw,
            "placements": np.array(placements), "joints": np.array(poses), "entity": np.array(entity),
            "heading": np.array(headings)}  # fmt: skip


def in_world(local: np.ndarray, entity: np.ndarray, heading: np.ndarray) -> np.ndarray:
    """World ground positions ``(n, ..., 2)`` (Performer X east, Y north, cm) of points ``local`` ``(n, ...,
    3)`` in the soldier frame (Jack: X right, -Z ahead) of an entity at ``entity`` ``(n, 2)`` m facing
    ``heading`` ``(n,)`` radians, as an image generator places them."""
    extra = (1,) * (local.ndim - 2)
    h = heading.reshape(-1, *extra, 1)
    forward = np.concatenate([np.sin(h), np.cos(h)], axis=-1)
    right = np.concatenate([np.cos(h), -np.sin(h)], axis=-1)
    return entity.reshape(-1, *extra, 2) * 100.0 + local[..., 0:1] * right - local[..., 2:3] * forward


def yaw_steps(run: dict[str, np.ndarray]) -> np.ndarray:
    """Per tick how far (degrees) the figure turned in the world since the tick before."""
    return np.abs((np.diff(run["yaw"]) + 180.0) % 360.0 - 180.0)


def touchdowns(down: np.ndarray) -> Iterator[tuple[int, int, int, int]]:
    """Each touchdown of a sole point in ``down`` ``(frames, feet, points)``: (foot, point, first frame, last
    frame) of a run of frames in which it stays down."""
    for f in range(down.shape[1]):
        for p in range(down.shape[2]):
            k = 0
            while k < len(down):
                if not down[k, f, p]:
                    k += 1
                    continue
                j = k
                while j + 1 < len(down) and down[j + 1, f, p]:
                    j += 1
                yield f, p, k, j
                k = j + 1


def skates(run: dict[str, np.ndarray], t0: float = 0.0, t1: float = math.inf) -> list[tuple[float, str]]:
    """Per touchdown of a sole point beginning between ``t0`` and ``t1`` s: how far it moved (cm) while it
    stayed down, and the clip it began in."""
    world, height = run["world"], run["height"]
    out = []
    for f, p, k, j in touchdowns(height < height.min() + CONTACT_CM):
        track = world[k : j + 1, f, p]
        if t0 <= k / HZ < t1:
            out.append((float(np.linalg.norm(track - track[0], axis=1).max()), str(run["clips"][k])))
    return out


def worst(run: dict[str, np.ndarray], family: str) -> float:
    hits = [s for s, clip in skates(run) if family in clip]
    assert hits, f"no stance in a {family} clip"
    return max(hits)


SCENARIO = [(0.5, 1.4, 0.0), (5.0, 3.0, 0.0), (9.0, 1.4, 0.0), (13.0, 0.0, 0.0)]


@pytest.fixture(scope="module")
def walk_run_walk(lib) -> dict[str, np.ndarray]:
    return drive(lib, SCENARIO, heading=30.0, until=16.0)


@pytest.mark.parametrize(
    "family", ["walk_start", "walk_cycle", "walk2run", "run_cycle", "run2walk", "walk_end", "STAND_STOWED"]
)
def test_planted_feet_stay_still_in_the_world(walk_run_walk, family: str) -> None:
    clips = set(walk_run_walk["clips"].tolist())
    if family == "STAND_STOWED":  # standing before and after: no clip name to match, any static clip
        family = "soldier_low/"
    assert any(family in c for c in clips)
    assert worst(walk_run_walk, family) <= SKATE_CM


@pytest.mark.parametrize("speed", [1.0, 1.9, 2.3, 2.39, 4.0, 5.3])
def test_steady_speeds_within_human_cadence_keep_their_feet(lib, speed: float) -> None:
    """From a slow walk to the fastest walk (a walker keeps walking up to 2.4 m/s) and from a jog to the
    recorded run at its highest cadence (3.37 m/s x 1.6 = 5.4 m/s), playback rate alone matches the speed:
    every stance of the steady cycles stays within 2 cm. (Faster runs need a longer stride than the library
    has: the feet slide by the difference, see docs/CHANNELSETS.md.)"""
    run = drive(lib, [(0.5, speed, 0.0)], heading=30.0, until=7.0)
    hits = [s for s, clip in skates(run, 4.0) if "cycle" in clip]
    assert hits and max(hits) <= SKATE_CM


def test_side_steps_and_backward_steps_keep_their_feet(lib) -> None:
    run = drive(lib, [(0.2, 0.3, 90.0), (4.0, 0.0, 0.0), (6.0, 0.6, 180.0), (9.0, 0.0, 0.0)], 200.0, 12.0)
    for family in ("sidestep_r", "bwalk_start", "bwalk_cycle", "bwalk_end"):
        assert worst(run, family) <= SKATE_CM, family


def test_the_figure_trails_the_entity_and_a_stop_ends_near_it(walk_run_walk) -> None:
    """While moving the figure trails the entity by about what it would still travel on a stop (half a step
    and the end step), so the stop leaves it within half a step of the entity; it never drifts away."""
    gap = np.linalg.norm(walk_run_walk["gap"], axis=1)
    assert gap.max() < 200.0
    t = np.arange(len(gap)) / HZ
    assert 60.0 < gap[(t > 4.0) & (t < 5.0)].mean() < 110.0  # walking: 37 + 53 cm
    assert gap[t > 15.0].max() < 37.0  # standing again: within half a walking step (74 cm)


@pytest.mark.parametrize(("turn", "clip"), [(90.0, "turn_r90"), (-45.0, "turn_l45"), (170.0, "turn_r180")])
def test_a_heading_change_while_standing_turns_in_place_on_planted_feet(lib, turn: float, clip: str) -> None:
    run = drive(lib, [(0.0, 0.0, 0.0), (0.5, 0.0, 0.0, 10.0 + turn)], heading=10.0, until=5.0)
    assert any(clip in c for c in run["clips"].tolist())
    assert worst(run, clip) <= SKATE_CM
    # the figure faced the old heading when the entity turned: no snap in the world
    k = int(0.5 * HZ)
    assert np.abs(run["world"][k] - run["world"][k - 1]).max() < 0.5  # cm, over the tick of the request


def test_small_heading_changes_do_not_turn_and_the_figure_stays_put(lib) -> None:
    run = drive(lib, [(0.0, 0.0, 0.0), (0.5, 0.0, 0.0, 20.0), (1.0, 0.0, 0.0, 0.0)], heading=0.0, until=2.0)
    assert not any("turn_" in c for c in run["clips"].tolist())
    assert np.abs(run["world"] - run["world"][0]).max() < 0.5


def test_a_stepping_figure_may_turn_only_while_one_sole_point_alone_is_down() -> None:
    """Six frames: both feet flat, then the left ball alone down (heel and right foot 5 cm up), then the right
    heel lands. It may turn between frames 2-3 and 3-4 only (FRAME_TURN_DEG each), about the left ball, which
    it keeps as the point to turn about while that ball stays down."""
    points = np.zeros((6, 2, 2, 3))  # (frames, feet, heel/ball, XYZ cm)
    points[..., 2] = [[[10.0, -10.0], [10.0, -10.0]]]
    points[:, 1, :, 0] = 20.0  # the right foot, beside the left
    points[:, 0, 1, 2] = -10.0 - np.arange(6)  # the left ball carries the figure (the treadmill)
    points[2:5, :, :, 1] = 5.0
    points[2:5, 0, 1, 1] = 0.0  # ... alone down in frames 2-4
    points[5, 1, 1, 1] = 5.0  # the right heel lands in frame 5, its ball still up
    points[5, 0, 0, 1] = 5.0
    turn, about = step_turns(points)
    assert turn.tolist() == [0.0, 0.0, 0.0, FRAME_TURN_DEG, 2 * FRAME_TURN_DEG, 2 * FRAME_TURN_DEG]
    assert np.allclose(about, points[:, 0, 1][:, [0, 2]])


def test_a_side_step_may_turn_only_while_one_foot_alone_is_down() -> None:
    """Five frames: both feet flat, then the right foot 5 cm up in frames 2-4. It may turn between frames 2-3
    and 3-4 only (SIDE_TURN_DEG over that stance), about the middle of the left foot."""
    points = np.zeros((5, 2, 2, 3))  # (frames, feet, heel/ball, XYZ cm)
    points[..., 2] = [[[10.0, -10.0], [10.0, -10.0]]]
    points[:, 1, :, 0] = 20.0
    points[2:, 1, :, 1] = 5.0
    turn, about = side_turns(points)
    assert turn.tolist() == [0.0, 0.0, 0.0, SIDE_TURN_DEG / 2, SIDE_TURN_DEG]
    assert np.allclose(about[2:], [0.0, 0.0])


TURNS = [(1.4, a) for a in (30.0, 45.0, 60.0, 90.0, 110.0)] + [(3.5, 45.0), (3.5, 90.0), (3.0, 60.0)]


@pytest.mark.parametrize(("speed", "turn"), [(v, s * a) for v, a in TURNS for s in (1.0, -1.0)])
def test_a_heading_change_while_moving_turns_the_body_over_a_few_steps(
    lib, speed: float, turn: float
) -> None:
    """The entity turns at once (heading and velocity); the figure keeps its orientation in the world and
    turns towards the heading at each footfall (root_motion.step_turns): only while one sole point alone is
    down (the ball at push-off; none in a run's flight), about it, up to 45° a step. Every planted point stays
    within 2 cm (it was 4.4 cm at 30°, 6.1-7.1 at 90°, 7.4-9.1 at 110°: the body turned at 90°/s through
    the flat stance, twisting the foot about its middle). The body never snaps, it steers back to the
    entity's path (the turn is slower than the entity's), and the stop still ends near the entity."""
    script = [(0.0, 0.0, 0.0), (0.5, speed, 0.0), (4.0, speed, 0.0, 40.0 + turn), (8.0, 0.0, 0.0)]
    run = drive(lib, script, heading=40.0, until=11.0)
    k = int(4.0 * HZ)
    assert np.abs(run["world"][k] - run["world"][k - 1]).max() < 12.0  # one tick of stepping, no snap
    assert yaw_steps(run).max() <= 6.0  # degrees a 60 Hz frame (tests/test_reversal.py MAX_YAW_STEP_DEG)
    slides = skates(run, 3.5, 11.0)
    assert slides and max(s for s, _ in slides) <= SKATE_CM, sorted(slides)[-3:]
    assert not any("turn_" in c for c in run["clips"].tolist()[: int(8.0 * HZ)])
    assert abs((run["yaw"][int(7.9 * HZ)] - run["yaw"][int(3.9 * HZ)] - turn + 180.0) % 360.0 - 180.0) < 15.0
    assert np.linalg.norm(run["gap"][-1]) < 37.0 + 10.0


def turned(run: dict[str, np.ndarray], t0: float, t1: float) -> float:
    """Compass degrees the figure turned in the world from ``t0`` to ``t1`` s (-180..180)."""
    return float((run["yaw"][int(t1 * HZ)] - run["yaw"][int(t0 * HZ)] + 180.0) % 360.0 - 180.0)


@pytest.mark.parametrize(("side", "turn"), [(s, a) for s in (90.0, -90.0) for a in (30.0, -45.0, 90.0)])
def test_a_side_stepping_figure_turns_about_the_foot_that_alone_is_down(
    lib, side: float, turn: float
) -> None:
    """A side-step's feet shuffle flat, never on one sole point alone: below 45° it turns while one foot
    alone is down, about that foot's centre, at most 10° a stance (root_motion.side_turns); from 45° it
    stops, pivots (turning.SIDE_REVERSAL_DEG), then side-steps on. Every planted point stays within 2 cm (it
    was 8.9-11.8 cm at 30°, 11.6-17 at 45°, 21-31 at 90°: the body turned at 90°/s about the root, twisting
    both feet), and the stop ends near the entity (20-60 cm; turned 10° a stance at 90°, 1.0-1.2 m)."""
    script = [(0.0, 0.0, 0.0), (0.5, 0.3, side), (3.0, 0.3, side, 40.0 + turn), (7.0, 0.0, 0.0)]
    run = drive(lib, script, heading=40.0, until=10.0)
    assert any("sidestep_" in c for c in run["clips"].tolist())
    assert yaw_steps(run).max() <= 6.0
    slides = skates(run, 2.5, 10.0)
    assert slides and max(s for s, _ in slides) <= SKATE_CM, sorted(slides)[-3:]
    assert abs(turned(run, 2.9, 10.0) - turn) < 5.0
    assert np.linalg.norm(run["gap"][-1]) < 70.0


@pytest.mark.parametrize("turn", [90.0, -90.0])
def test_turn_and_stop_in_one_request_ends_facing_the_heading(lib, turn: float) -> None:
    """Turned 90° and stopped in the same request, the walker turns over the end step, then the turn in place
    that fits turns the rest, more or less than its clip over its stances (it ended 13° off the heading: the
    45° clip for a 58° rest). No planted point slides 2 cm, no snap."""
    script = [(0.0, 0.0, 0.0), (0.5, 1.4, 0.0), (4.0, 0.0, 0.0, 40.0 + turn)]
    run = drive(lib, script, heading=40.0, until=9.0)
    assert yaw_steps(run).max() <= 6.0
    slides = skates(run, 3.5, 9.0)
    assert slides and max(s for s, _ in slides) <= SKATE_CM, sorted(slides)[-3:]
    assert abs(turned(run, 0.4, 9.0) - turn) < 3.0  # standing before and after
