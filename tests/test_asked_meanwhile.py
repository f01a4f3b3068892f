"""A soldier asked for another posture while a posture change's path plays re-plans it from the arc now
playing (issue 16, ``server.soldier.replanning``): that arc to its end or, where the graph has it the other
way and that is quicker, back from the frame it shows, then the quickest path to the new goal. Before, he
played the whole path first: asked to crawl while he went down from standing to prone (through CRAWL:
``ststow2crawl`` then ``crawl2prstow``), he lay down and came up again before he crawled, 3.2 s."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trio

from protocol.entity import Appearance
from protocol.events import JointUpdates
from tests.soldier_script import driven
from tests.test_gait_selection import shipped_library
from tests.test_prone_turn import served

HZ = 30.0  # the stub's update rate
HEADING = 40.0
JUMP_DEG = (
    20.0  # a re-plan turns no joint further than this between two updates (or than the clip already did)
)


@pytest.fixture(scope="module")
def lib():
    return shipped_library()


def ahead(speed: float) -> np.ndarray:
    return speed * np.array([math.sin(math.radians(HEADING)), math.cos(math.radians(HEADING))])


def played(
    lib, script: list[tuple[float, Appearance, float]], until: float
) -> list[tuple[float, str, str, np.ndarray]]:
    """Play ``(time, posture, speed m/s along HEADING)`` requests to a standing DI soldier at HZ; per update
    the time, the clip shown, where he is (``CRAWLING``/``WALKING`` while he steps, else his posture) and his
    joints (radians)."""
    out = []
    for now, m, i, _, _ in driven(lib, [(t, app, v, HEADING) for t, app, v in script], until, HZ):
        up, info = m.snapshot([i]), m.soldier_info(i)
        where = {"CRAWL": "CRAWLING", "LOCO": "WALKING"}.get(info["mode"], info["posture"])
        where = where if info["mode"] in ("IDLE", "CRAWL", "LOCO") else "PATH"
        clip = lib.clip_names[int(up.clips[0])].split("/")[-1]
        out.append((now, clip, where, np.asarray(up.joints[0], np.float64).copy()))
    return out


def shown(lib, script: list[tuple[float, Appearance, float]], until: float) -> list[tuple[float, str]]:
    """The clips :func:`played` shows, each with the time it began."""
    out: list[tuple[float, str]] = []
    for now, clip, _, _ in played(lib, script, until):
        if not out or out[-1][1] != clip:
            out.append((now, clip))
    return out


def reached(rows: list, asked: float, where: str) -> float:
    """Seconds from ``asked`` until he is ``where`` (inf: never)."""
    return next((now - asked for now, _, w, _ in rows if now >= asked - 1e-9 and w == where), math.inf)


def jumps(rows: list, asked: float) -> float:
    """Degrees the joints turn at most between two of the updates around ``asked``."""
    joints = np.array([r[3] for r in rows])
    step = np.degrees(np.abs(np.diff(joints, axis=0)).max(axis=1))  # step[k]: update k to k + 1
    k = round(asked * HZ)
    return float(step[k - 2 : k + 3].max())


def no_jump(lib, script: list[tuple[float, Appearance, float]], rows: list) -> None:
    """The re-plan at the script's last request turns no joint between two updates further than JUMP_DEG, or
    than the clip turned it there anyway (the run without that request: the recordings' own swings reach
    40° an update at 30 Hz; an arc that turns back turns as fast as it came)."""
    asked = script[-1][0]
    now, anyway = jumps(rows, asked), jumps(played(lib, script[:-1], asked + 0.5), asked)
    assert now <= max(JUMP_DEG, anyway) + 1e-6, (now, anyway)


def test_asked_to_crawl_on_his_way_down_to_prone_he_crawls_from_crawl(lib) -> None:
    """PRONE at 0.5 s, CRAWL at 0.3 m/s at 1 s (``ststow2crawl`` plays until 2.47 s): he crawls once he is
    on forearms and knees, without lying down first (before: ``crawl2prstow`` down and up, crawling at 5.67
    s: 4.67 s after he was asked; now 1.47)."""
    script = [(0.0, Appearance.UPRIGHT, 0.0), (0.5, Appearance.PRONE, 0.0), (1.0, Appearance.CRAWL, 0.3)]
    rows = played(lib, script, 4.0)
    assert "crawl2prstow_low" not in {r[1] for r in rows}
    assert reached(rows, 1.0, "CRAWLING") < 1.6  # ststow2crawl's rest: 1.47 s
    no_jump(lib, script, rows)


def test_asked_to_stand_half_way_down_he_gets_up_from_there(lib) -> None:
    """STAND asked 1 s into ``ststow2crawl`` (1.97 s): the arc turns back from the frame it shows and he
    stands 1.03 s later (before: down to prone and all the way up again, 6.17 s), no joint turning faster
    at the turn than the arc already did."""
    script = [(0.0, Appearance.UPRIGHT, 0.0), (0.5, Appearance.PRONE, 0.0), (1.5, Appearance.UPRIGHT, 0.0)]
    rows = played(lib, script, 4.0)
    assert "crawl2prstow_low" not in {r[1] for r in rows}
    assert reached(rows, 1.5, "STAND_STOWED") < 1.2
    no_jump(lib, script, rows)


def test_asked_to_crawl_as_he_lies_down_he_comes_back_up_from_there(lib) -> None:
    """CRAWL asked 0.7 s into ``crawl2prstow`` (from CRAWL, on his way from standing to prone): that arc
    turns back and he crawls 0.77 s later (before: lying down first, 2.47 s)."""
    script = [(0.0, Appearance.UPRIGHT, 0.0), (0.5, Appearance.PRONE, 0.0), (3.2, Appearance.CRAWL, 0.3)]
    rows = played(lib, script, 5.0)
    assert reached(rows, 3.2, "CRAWLING") < 1.0
    assert "PRONE_STOWED" not in {r[2] for r in rows}
    no_jump(lib, script, rows)


def test_a_request_for_the_posture_his_path_reaches_changes_nothing(lib) -> None:
    """Getting up from prone, asked to walk (from STAND_STOWED, the path's end): the path plays exactly as
    it would have, then he walks."""
    up = [(0.0, Appearance.PRONE, 0.0), (6.0, Appearance.UPRIGHT, 0.0)]
    alone = played(lib, up, 10.5)
    walks = played(lib, [*up, (7.0, Appearance.UPRIGHT, 1.0)], 10.5)
    k = next(n for n, r in enumerate(alone) if r[0] >= 6.0 and r[2] == "STAND_STOWED")
    assert [r[1] for r in walks[:k]] == [r[1] for r in alone[:k]]
    assert np.array_equal(np.array([r[3] for r in walks[:k]]), np.array([r[3] for r in alone[:k]]))
    assert walks[k][2] in ("STAND_STOWED", "WALKING") and walks[-1][2] == "WALKING"


def test_killed_on_his_way_down_he_dies_from_where_he_is(lib) -> None:
    """DEAD asked 1 s after PRONE (the replayed exercise's victim, killed 1.05 s after he was told to go
    prone): he dies from forearms and knees, not lying down first."""
    script = [(0.0, Appearance.UPRIGHT, 0.0), (0.5, Appearance.PRONE, 0.0), (1.5, Appearance.DEAD, 0.0)]
    clips = [c for _, c in shown(lib, script, 8.0)]
    assert "crawl2prstow_low" not in clips and clips[-1].endswith("2dead_low"), clips


def test_a_man_asked_to_stand_while_he_falls_dead_falls_first(lib) -> None:
    """UPRIGHT asked 0.5 s into his death: the fall is never turned back half-way (the graph has it the other
    way, DEAD -> STAND_STOWED, for a dead man asked to stand); he falls exactly as if not asked, lies dead,
    then gets up the same way."""
    dies = [(0.0, Appearance.UPRIGHT, 0.0), (0.5, Appearance.DEAD, 0.0)]
    asked = played(lib, [*dies, (1.0, Appearance.UPRIGHT, 0.0)], 15.0)
    unasked = played(lib, dies, 15.0)
    lies = next(n for n, r in enumerate(unasked) if r[2].startswith("DEAD"))  # his death clip has ended
    fall = [n for n, r in enumerate(unasked[:lies]) if r[1].endswith("2dead_low")]
    assert len(fall) > 2.0 * HZ, len(fall)
    assert np.array_equal(np.array([asked[n][3] for n in fall]), np.array([unasked[n][3] for n in fall])), (
        "the fall was changed by a request made while he fell"
    )
    assert asked[-1][2] == "STAND_STOWED", asked[-1][2]


async def wire_stand(asked: bool) -> tuple[float, float, list[str]]:
    """Soldier 0 of a served world told to go prone, and (``asked``) 1 s later to stand: how soon he stands
    (inf: not in 3 s), the most a joint the image generator receives turns between two updates meanwhile,
    the clips he played."""
    async with served() as (_, world, c):
        await c.requests(index=0, appearance=Appearance.PRONE, heading=HEADING)
        await c.drain(1.0)
        if asked:
            await c.requests(index=0, appearance=Appearance.UPRIGHT, heading=HEADING)
        t0, poses, stood = trio.current_time(), [], math.inf
        while trio.current_time() - t0 < 3.0:
            for ev in await c.drain(0.05):
                if isinstance(ev, JointUpdates) and 0 in ev.indices.tolist():
                    poses.append(ev.dofs[ev.indices.tolist().index(0)].copy())
            info = world.manager.soldier_info(0)
            if info["posture"] == "STAND_STOWED" and info["mode"] == "IDLE":
                stood = min(stood, trio.current_time() - t0)
        turn = float(np.degrees(np.abs(np.diff(np.array(poses), axis=0)).max()))
        return stood, turn, [s.clip.split("/")[-1] for s in world.manager.clip_log if s.index == 0]


async def test_over_the_wire_asked_to_stand_half_way_down_he_gets_up_from_there(
    autojump_clock: trio.abc.Clock,
) -> None:
    """Asked to stand 1 s into his way down through a served world (real TCP, trio's autojump clock): he
    stands again within 1.5 s (before: not within 3 s), and no joint the image generator receives turns
    further between two updates than JUMP_DEG or than on his way down unasked."""
    stood, turn, log = await wire_stand(True)
    _, anyway, _ = await wire_stand(False)
    assert "crawl2prstow_low" not in log and stood < 1.5, (stood, log)
    assert turn <= max(JUMP_DEG, anyway) + 1e-6, (turn, anyway)


async def test_over_the_wire_asked_to_crawl_on_his_way_down_he_crawls_from_crawl(
    autojump_clock: trio.abc.Clock,
) -> None:
    """The CRAWL request on his way down through a served world."""
    async with served() as (_, world, c):
        await c.requests(index=0, appearance=Appearance.PRONE, heading=HEADING)
        await c.drain(0.5)
        await c.requests(index=0, appearance=Appearance.CRAWL, heading=HEADING, velocity=(*ahead(0.3), 0.0))
        await c.drain(3.0)
        log = [s.clip.split("/")[-1] for s in world.manager.clip_log if s.index == 0]
        assert "crawl2prstow_low" not in log and "crawl_cycle_low" in log, log
