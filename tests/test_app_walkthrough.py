"""Seed 002's walkthrough (section 4.3) as a scripted scenario over TCP, frame choice, throttle and blending.

The client drives soldier 0 exactly as the 1994 keyboard demo did (walk, turn, run above 3 m/s, stop, walk
backwards, kneel, prone, fire, die, resuscitate, prone and crawl); the server records every clip start and
the test reads them back with the ``report_ttes_clips`` JCL command (a STATUS whose text is JSON)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
import trio
from test_server_support import Client, frames_until, running_server

from protocol.entity import Appearance as A
from protocol.entity import WeaponState as W
from protocol.events import JointUpdates, Ready, Subscribe
from server.soldier.manager import MAX_RATE, MIN_RATE, TickUpdate

STEP = 2 * math.pi / 4096  # one code of a 12-bit rotational DOF


def port_of(server) -> int:  # type: ignore[no-untyped-def]
    return server.addresses[0][1]


def vel(speed: float, heading: float) -> tuple[float, float, float]:
    """Velocity along a compass heading (negative speed: backwards), Performer axes."""
    h = math.radians(heading)
    return (speed * math.sin(h), speed * math.cos(h), 0.0)


# (server time, appearance, weapon, speed m/s, compass heading) — the 4.3 walkthrough, key by key
WALKTHROUGH = [
    (1.0, A.UPRIGHT, W.DEPLOYED, 0.5, 0.0),  # [Up]: walk slowly
    (3.0, A.UPRIGHT, W.DEPLOYED, 0.5, 350.0),  # [Left]: turn towards the fields (heading only)
    (4.0, A.UPRIGHT, W.DEPLOYED, 1.5, 350.0),  # [Up] [Up]: faster
    (6.0, A.UPRIGHT, W.DEPLOYED, 3.5, 350.0),  # above 2.4 m/s: he runs
    (9.0, A.UPRIGHT, W.DEPLOYED, 2.0, 350.0),  # [Down] ...: back below the threshold
    (10.5, A.UPRIGHT, W.DEPLOYED, 0.0, 350.0),  # ... to zero
    (13.0, A.UPRIGHT, W.DEPLOYED, -0.5, 350.0),  # [Down] again: walks backwards
    (16.0, A.UPRIGHT, W.DEPLOYED, 0.0, 350.0),  # stop
    (18.0, A.KNEEL, W.DEPLOYED, 0.0, 350.0),  # [3]
    (21.0, A.PRONE, W.DEPLOYED, 0.0, 350.0),  # [4]
    (25.0, A.PRONE, W.FIRING, 0.0, 350.0),  # [6]: fire
    (27.0, A.PRONE, W.DEPLOYED, 0.0, 350.0),  # [5]
    (29.0, A.DEAD, W.DEPLOYED, 0.0, 350.0),  # [1]: he dies
    (32.0, A.UPRIGHT, W.DEPLOYED, 0.0, 350.0),  # [2]: resuscitate
    (44.0, A.PRONE, W.DEPLOYED, 0.0, 350.0),  # [4]: prone
    (48.0, A.PRONE, W.DEPLOYED, 0.4, 350.0),  # a little forward velocity: he crawls
    (53.0, A.PRONE, W.DEPLOYED, 0.0, 350.0),  # stop crawling
]


async def drive(c: Client, server, script, index: int = 0) -> None:  # type: ignore[no-untyped-def]
    for t, app, wpn, speed, heading in script:
        await trio.sleep_until(server._t0 + t)
        await c.requests(
            index=index, appearance=app, weapon=wpn, velocity=vel(speed, heading), heading=heading
        )


def short(clip: str) -> str:
    return clip.rsplit("/", 1)[-1].removesuffix("_low")


async def test_walkthrough_4_3_clip_sequence_and_timings(autojump_clock: trio.abc.Clock) -> None:
    async with running_server(throttle=0.0, record_clips=True) as server:
        c = await Client.open(port_of(server))
        await c.expect(Ready)
        await c.send(Subscribe((0,)))
        await drive(c, server, WALKTHROUGH)
        await trio.sleep_until(server._t0 + 58.0)
        clips = (await c.report('report_ttes_clips("s0");'))["clips"]
        state = await c.report('report_ttes_status("s0");')
    seq = [(short(x["clip"]), x["forward"]) for x in clips]
    names = [n for n, _ in seq]
    t = {k: [x["time"] for x in clips if short(x["clip"]) == k] for k in set(names)}

    def collapse(xs: list[str]) -> list[str]:  # a cycle repeated on alternating feet counts once
        out: list[str] = []
        for x in xs:
            base = x.removesuffix("_l").removesuffix("_r")
            if not out or out[-1] != base or "cycle" not in base:
                out.append(base)
        return out

    assert collapse(names) == [
        "walk_start", "walk_cycle", "walk2run", "run_cycle", "run2walk", "walk_cycle", "walk_end",
        "bwalk_start", "bwalk_cycle", "bwalk_end",
        "ststow2kstow",                      # stand → kneel
        "kstow2crawl", "crawl2prstow",       # kneel → prone: the quickest path goes through CRAWL
        "prstow2prfire", "prstow2prfire",    # fire, and back (the same clip played backwards)
        "prstow2dead",                       # dies
        "ststow2dead",                       # resuscitation: DEAD → STAND_STOWED, the dying clip backwards
        "ststow2crawl", "crawl2prstow",      # stand → prone
        "crawl2prstow", "crawl_start", "crawl_cycle", "crawl_start",  # to CRAWL, crawl, end = start backwards
        "crawl2prstow",                      # rest prone again
    ]  # fmt: skip
    fwd = dict(zip(range(len(seq)), [f for _, f in seq], strict=True))
    # directions: firing back, resuscitation, prone→crawl and the crawl's end step play backwards
    backwards = [short(clips[k]["clip"]) for k in range(len(seq)) if not fwd[k]]
    assert backwards == ["prstow2prfire", "ststow2dead", "crawl2prstow", "crawl_start"]
    # feet alternate: every walking/running step uses the other foot (walk2run / run2walk count as steps)
    steps = [n for n in names if n.startswith(("walk", "run", "bwalk"))]
    for a, b in itertools.pairwise(steps):
        if a[-2:] in ("_l", "_r") and b[-2:] in ("_l", "_r"):
            assert a[-1] != b[-1], (a, b)
    assert names[names.index("walk2run") - 1][-1] == names[names.index("walk2run") + 1][-1]
    # posture changes start when requested, and each arc of a path starts when the previous one ends (a
    # request's first arc from its first moving frame: it ends as much sooner as it skipped)
    skip = {k: [x["skipped"] for x in clips if short(x["clip"]) == k] for k in set(names)}
    assert t["ststow2kstow"] == [pytest.approx(18.0)]
    assert t["kstow2crawl"] == [pytest.approx(21.0)]
    assert t["crawl2prstow"][0] == pytest.approx(21.0 + 1.4 - skip["kstow2crawl"][0])
    assert t["prstow2prfire"] == [pytest.approx(25.0), pytest.approx(27.0)]
    assert t["prstow2dead"] == [pytest.approx(29.0)]
    assert t["ststow2dead"] == [pytest.approx(32.0)]
    dead = clips[names.index("ststow2dead")]
    assert dead["duration"] == pytest.approx(10.0)  # the seed's 10 s resuscitation arc
    assert t["ststow2crawl"] == [pytest.approx(44.0)]
    assert t["crawl2prstow"][1] == pytest.approx(46.0 - skip["ststow2crawl"][0])  # 44 + 2.0
    assert t["crawl2prstow"][2] == pytest.approx(48.0)  # prone → CRAWL base posture when moving
    assert t["crawl_start"][0] == pytest.approx(48.8 - skip["crawl2prstow"][2])
    # locomotion: the first step starts at the request; then the clips chain exactly end to start (a step
    # under way when the speed changes keeps its phase and changes its rate, so it ends earlier or later)
    assert t["walk_start_l"] == [pytest.approx(1.0)]
    assert t["bwalk_start_l"] + t.get("bwalk_start_r", []) == [pytest.approx(13.0)]
    loco = [x for x in clips if x["mode"] in ("LOCO", "CRAWL")]
    chained = 0
    for a, b in itertools.pairwise(loco):
        rescaled = any(a["time"] <= r[0] < b["time"] for r in WALKTHROUGH)
        if b["state"] not in ("WALK_START", "BWALK_START", "RUN_START", "CRAWL_START") and not rescaled:
            assert b["time"] == pytest.approx(a["time"] + a["duration"], abs=1e-6), (a, b)
            chained += 1
    assert chained >= 15
    # the turn at t=3 is heading-only: no clip starts then
    assert not any(abs(x["time"] - 3.0) < 1e-6 for x in clips)
    # the run starts at the first step end after 6 s, and stops being a run at the first end after 9 s
    w2r = clips[names.index("walk2run")]["time"]
    r2w = clips[names.index("run2walk")]["time"]
    assert 6.0 < w2r < 6.0 + 1.0 and 9.0 < r2w < 9.0 + 1.2  # up to two run strides at the slowest cadence
    # playback rate follows ground speed within human cadence: at 0.5 m/s the 1.4 m/s walk cycle would play
    # at 0.36 of its rate, below the slowest cadence, so it plays at MIN_RATE and the stride shortens; at
    # 1.5 m/s it plays faster (near 1.5/1.4, give or take the root offset's catch-up), never beyond MAX_RATE
    cyc = [x for x in clips if short(x["clip"]).startswith("walk_cycle")]
    slow = [x["duration"] for x in cyc if 2.0 <= x["time"] < 3.5]
    fast = [x["duration"] for x in cyc if 4.3 <= x["time"] < 6.0]
    stored = 0.5
    assert slow and fast and slow[0] == pytest.approx(stored / MIN_RATE, rel=1e-3)
    assert all(stored / MAX_RATE - 1e-9 <= d < slow[0] for d in fast)
    # he ends resting prone
    (s0,) = state["soldiers"]
    assert (s0["mode"], s0["posture"]) == ("IDLE", "PRONE_STOWED")


def expected_pose(server, clip: str, frames: np.ndarray) -> np.ndarray:  # type: ignore[no-untyped-def]
    """The wire DOFs of stored ``frames`` of ``clip`` (sampled exactly on the frames)."""
    lib = server.world.library
    cid = lib.clip_id(clip)
    n = len(frames)
    fps = lib.clips[cid].fps
    s = lib.sets[0].sample(np.full(n, cid), np.zeros(n), np.ones(n, np.int8), np.zeros(n), frames / fps)
    tu = TickUpdate(np.arange(n), s.joints.copy(), s.figures.copy(), np.zeros(n, bool))
    return server.world.sets[0].converter.convert(tu).dofs


async def watching(server) -> Client:  # type: ignore[no-untyped-def]
    """A client subscribed to soldier 0 that has its first (full) update."""
    c = await Client.open(port_of(server))
    await c.expect(Ready)
    await c.send(Subscribe((0,)))
    await c.expect(JointUpdates)
    return c


async def kneel_frames(
    tick_hz: float, throttle: float
) -> tuple[list[float], list[np.ndarray], float, object]:
    """Kneel at t = 1 s (a tick's time); the (time, pose) of every update the client gets in the next 2 s,
    and the seconds of still lead-in the clip skipped (its start before the request). The time is the
    frame's tick's (tick n at (n - 1) / tick_hz), not when its bytes arrived: under ``autojump_clock`` the
    clock jumps while they are on their way."""
    async with running_server(tick_hz=tick_hz, throttle=throttle) as server:
        c = await watching(server)
        await trio.sleep_until(server._t0 + 1.0)
        await c.requests(index=0, appearance=A.KNEEL, weapon=W.DEPLOYED)
        times: list[float] = []
        poses: list[np.ndarray] = []
        skipped = math.nan
        with trio.move_on_after(2.0):
            while True:
                ev = await c.next_event()
                if isinstance(ev, JointUpdates):
                    times.append((ev.tick - 1) / tick_hz)
                    poses.append(ev.dofs[0].copy())
                    if len(times) == 1:
                        skipped = 1.0 - server.world.manager.soldier_info(0)["clip_start"]
        return times, poses, skipped, server


@pytest.mark.parametrize(("tick_hz", "throttle"), [(20.0, 0.0), (60.0, 0.05)])
async def test_frame_choice_under_a_20hz_client(
    autojump_clock: trio.abc.Clock, tick_hz: float, throttle: float
) -> None:
    """Seed 3.4.2: a 60 fps transition sampled by a 20 Hz image generator plays frames 0, 3, 6, … (from its
    first moving frame: the request's answer at once shows it, issue 16)."""
    times, poses, skipped, server = await kneel_frames(tick_hz, throttle)
    lead = round(skipped * 60.0)  # whole still frames skipped
    assert skipped * 60.0 == pytest.approx(lead) and 0 < lead < 6
    # answered at the request, then 20 updates a second, whatever the tick rate
    assert times[0] == pytest.approx(1.0)
    assert np.diff(times) == pytest.approx(np.full(len(times) - 1, 0.05), abs=1e-6)
    k = np.round((np.array(times) - 1.0) / 0.05).astype(int)
    frames = np.minimum(lead + 3 * k, 96)  # ststow2kstow: 1.6 s = 96 frames + 1, held at its last
    got = np.array(poses)
    assert frames[:4].tolist() == [lead, lead + 3, lead + 6, lead + 9] and frames[-1] == 96
    want = expected_pose(server, "ststow2kstow_low", frames.astype(float))
    assert np.abs(got - want).max() <= 1.01 * STEP  # exactly those stored frames (12-bit codes)
    # and not the neighbouring frames: in the middle of the clip they differ by several codes
    mid = (frames > 30) & (frames < 66)
    for off in (-1, 1):
        other = expected_pose(server, "ststow2kstow_low", frames[mid].astype(float) + off)
        assert np.abs(got[mid] - other).max(axis=1).min() > 2 * STEP


async def test_throttle_limits_each_soldiers_update_rate(autojump_clock: trio.abc.Clock) -> None:
    async with running_server(throttle=0.1) as server:
        c = await Client.open(port_of(server))
        await c.expect(Ready)
        await c.requests(index=[0, 1], velocity=[vel(1.4, 0.0), vel(4.0, 90.0)], heading=[0.0, 90.0])
        await c.send(Subscribe((0, 1)))
        await c.drain(0.5)

        async def stamps(seconds: float) -> dict[int, list[int]]:
            """The ticks of each soldier's updates written from now on (none left over from before)."""
            await c.caught_up(server)
            out: dict[int, list[int]] = {0: [], 1: []}
            with trio.move_on_after(seconds):
                while True:
                    ev = await c.next_event()
                    if isinstance(ev, JointUpdates):
                        for i in ev.indices.tolist():
                            out[i].append(ev.tick)
            return out

        got = await stamps(3.0)
        for i in (0, 1):  # 30 Hz ticks, at most one update per 0.1 s = every third tick
            assert set(np.diff(got[i]).tolist()) == {3}, got[i]
        await c.jcl("set_ttes_soldier_throttle(0.2);")
        await c.drain(0.5)
        got = await stamps(3.0)
        for i in (0, 1):
            assert set(np.diff(got[i]).tolist()) == {6}
        # the throttle is this connection's (issue 17): 0 gives back the server's rate, never more
        await c.jcl("set_ttes_soldier_throttle(0);")
        await c.drain(0.5)
        got = await stamps(1.0)
        assert set(np.diff(got[0]).tolist()) == {3}, got[0]


async def test_throttle_004_gives_30_updates_a_second_and_ready_says_so(
    autojump_clock: trio.abc.Clock,
) -> None:
    """Issue 16: the shipped ``set_ttes_soldier_throttle(0.04)`` is a rate cap of 30/s, not two ticks."""
    async with running_server(throttle=0.04) as server:
        c = await Client.open(port_of(server))
        ready = await c.expect(Ready)
        assert (ready.tick_hz, ready.throttle) == (30.0, 0.04)
        await c.requests(index=0, velocity=vel(1.4, 0.0), heading=0.0)
        await c.send(Subscribe((0,)))
        await c.drain(0.5)
        await c.caught_up(server)
        first = server.ticks
        frames = await frames_until(c, lambda fs: bool(fs) and fs[-1][0] >= first + 60, 4.0)  # 2 s
        ticks = [t for t, indices, _ in frames for _ in indices]
        assert ticks[0] <= first + 1 and set(np.diff(ticks).tolist()) == {1}


async def test_a_request_between_ticks_is_reflected_before_the_next_tick(
    autojump_clock: trio.abc.Clock,
) -> None:
    """Issue 16, one-tick latency: the server answers at once with the pose the next tick would send."""
    async with running_server(throttle=0.04) as server:
        c = await watching(server)
        await trio.sleep_until(server._t0 + 1.01)
        rest = c.pose(1, 0)[0].copy()
        nxt = server.next_tick
        assert 1.01 < nxt <= 1.01 + 1 / 30
        written = c.writes(server)
        await c.requests(index=0, appearance=A.KNEEL, weapon=W.DEPLOYED)
        ev = await c.expect(JointUpdates)
        (at, ticks), *_ = written
        assert at < nxt and ev.indices.tolist() == [0]  # written before the tick...
        assert np.abs(ev.dofs[0] - rest).max() > STEP  # ...already kneeling
        assert server.answers == 1 and ev.tick == ticks + 1  # labelled with the tick it anticipates
        await trio.sleep_until(server._t0 + nxt + 0.001)
        assert server.world.manager.stats["answers"] == 1


async def test_a_start_asked_just_before_a_tick_is_reflected_in_its_answer(
    autojump_clock: trio.abc.Clock,
) -> None:
    """Issue 16: kneel -> stand asked 1 ms before a tick. The answer samples the clip 1 ms in; its eased,
    still first frames used to send the kneeling pose again (nothing new on the wire until a later tick).
    The start now begins at its first moving frame: the first update already stands up."""
    async with running_server(throttle=0.0) as server:
        c = await watching(server)
        await c.requests(index=0, appearance=A.KNEEL, weapon=W.DEPLOYED)
        with trio.move_on_at(server._t0 + 3.0):  # kneels (1.6 s), then rests
            while True:
                await c.next_event()
        kneeling = c.pose(1, 0)[0].copy()
        await trio.sleep_until(server._t0 + 3.01)
        nxt = server.next_tick
        assert 3.01 < nxt <= 3.01 + 1 / 30
        await trio.sleep_until(server._t0 + nxt - 0.001)
        written = c.writes(server)
        await c.requests(index=0, appearance=A.UPRIGHT, weapon=W.DEPLOYED)
        ev = await c.expect(JointUpdates)
        assert written[0][0] < nxt and ev.indices.tolist() == [0]  # the answer, written before the tick
        assert np.abs(ev.dofs[0] - kneeling).max() >= STEP  # already moving


async def largest_jump_on_interrupt(blend_time: float) -> float:
    """Walk, then kneel mid-step: the largest per-tick change of any DOF the client sees (radians)."""
    async with running_server(throttle=0.0) as server:
        c = await Client.open(port_of(server), role="operator")  # a server-wide setting: the operator's
        await c.expect(Ready)
        await c.jcl(f"set_ttes_blend_time({blend_time});")
        await c.send(Subscribe((0,)))
        await c.requests(index=0, velocity=vel(1.4, 0.0))
        with trio.move_on_at(server._t0 + 2.0):
            while True:
                await c.next_event()
        step = server.world.manager.soldier_info(0)
        assert step["clip"].endswith(("walk_cycle_l", "walk_cycle_r"))
        mid = step["clip_start"] + 0.5 * step["clip_duration"]
        if mid < 2.0:  # past this step's middle: the next step's (same speed, same duration)
            mid += step["clip_duration"]
        with trio.move_on_at(server._t0 + mid):  # walk on until the middle of a step's swing
            while True:
                await c.next_event()
        before = c.pose(1, 0)[0].copy()
        await c.requests(index=0, appearance=A.KNEEL, velocity=(0.0, 0.0, 0.0))
        prev, jumps = before, []
        with trio.move_on_after(0.6):
            while True:
                ev = await c.next_event()
                if isinstance(ev, JointUpdates):
                    cur = ev.dofs[0]
                    d = np.abs((cur - prev + np.pi) % (2 * np.pi) - np.pi)
                    jumps.append(float(d.max()))
                    prev = cur.copy()
        info = await c.report('report_ttes_status("s0");')
        assert info["soldiers"][0]["mode"] == "TRANSITION"
        return max(jumps)


async def test_interrupting_a_step_cross_fades_without_a_pop(autojump_clock: trio.abc.Clock) -> None:
    blended = await largest_jump_on_interrupt(0.2)
    popped = await largest_jump_on_interrupt(0.0)
    print(
        f"largest per-tick jump: {math.degrees(blended):.2f} deg blended, {math.degrees(popped):.2f} deg not"
    )
    assert math.degrees(blended) < 5.0  # < 5 degrees per 30 Hz tick while the step is cancelled
    assert popped > 2 * blended  # without the cross-fade the same interrupt jumps
