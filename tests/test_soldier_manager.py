"""SoldierManager: Figure 12's checks and Figure 5's locomotion on the core, at explicit times (no clocks)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from protocol.entity import ENTITY_REQUEST_DTYPE, Appearance, WeaponState, make_entity_requests
from server.motion.sampling import ClipLibrary
from server.soldier.manager import (
    MIN_RATE,
    REQUEST_BAD_VALUE,
    REQUEST_OK,
    REQUEST_UNKNOWN_SOLDIER,
    WALK_MAX_RATE,
    SoldierManager,
    TickUpdate,
)
from server.soldier.synthetic import synthetic_motion_library

UP, KNEEL, PRONE, DEAD = Appearance.UPRIGHT, Appearance.KNEEL, Appearance.PRONE, Appearance.DEAD
DEPLOYED, FIRING = WeaponState.DEPLOYED, WeaponState.FIRING


@pytest.fixture(scope="module")
def lib():
    return synthetic_motion_library()


def manager(lib, **kw) -> tuple[SoldierManager, int]:
    kw.setdefault("record_clips", True)
    m = SoldierManager(lib, **kw)
    return m, m.create_soldier(now=0.0)


def request(
    m: SoldierManager,
    i: int,
    now: float,
    app: int = UP,
    weapon: int = DEPLOYED,
    speed: float = 0.0,
    heading: float = 0.0,
    backward: bool = False,
    immediate: bool = False,
) -> None:
    h = math.radians(heading)
    s = -speed if backward else speed
    rows = make_entity_requests(
        i, app, weapon, (s * math.sin(h), s * math.cos(h), 0.0), heading, (5, 6, 0), immediate
    )
    assert m.apply_requests(rows, now).tolist() == [REQUEST_OK]


def run(m: SoldierManager, t0: float, t1: float, hz: float = 30.0) -> list[TickUpdate]:
    k0, k1 = math.ceil(t0 * hz - 1e-9), math.floor(t1 * hz + 1e-9)
    return [m.tick(k / hz) for k in range(k0, k1 + 1)]


def seq(m: SoldierManager, i: int) -> list[tuple[str, bool]]:
    return [(c.clip.rsplit("/", 1)[-1].removesuffix("_low"), c.forward) for c in m.clips_of(i)]


def starts(m: SoldierManager, i: int) -> list[tuple[str, float]]:
    return [(c.clip.rsplit("/", 1)[-1].removesuffix("_low"), round(c.time, 9)) for c in m.clips_of(i)]


def skipped(m: SoldierManager, i: int, k: int = 0) -> float:
    """The still lead-in (s) the ``k``-th clip soldier ``i`` started skipped (a request's start skips it:
    server.soldier.lead_in; the synthetic clips ease in, 1-3 frames under one wire step)."""
    s = m.clips_of(i)[k].skipped
    assert 0.0 < s < 0.06
    return s


def names(m: SoldierManager, i: int) -> list[str]:
    return [s for s, _ in seq(m, i)]


# -- posture changes (static graph) ----------------------------------------------------------------------


def test_prone_fire_from_standing_takes_the_quickest_path_and_chains_exactly(lib) -> None:
    m, i = manager(lib)
    request(m, i, 0.0, PRONE, FIRING)
    run(m, 0.0, 4.0)
    s = round(skipped(m, i), 9)  # the first arc, a request's start, skips its lead-in; the others chain
    assert starts(m, i) == [
        ("ststow2crawl", 0.0),
        ("crawl2prstow", round(2.0 - s, 9)),
        ("prstow2prfire", round(2.8 - s, 9)),
    ]
    info = m.soldier_info(i)
    assert info["mode"] == "IDLE" and info["posture"] == "PRONE_FIRE"


def test_transition_arc_continues_and_the_path_goes_on_to_the_new_posture(lib) -> None:
    m, i = manager(lib)
    request(m, i, 0.0, KNEEL)
    run(m, 0.0, 0.5)
    # a path re-plans from the arc playing (server.soldier.replanning); Figure 12's soldier took only the new
    # heading and went on to his first goal. Here the arc's end is on the quickest way
    request(m, i, 0.5, PRONE)
    assert m.soldier_info(i)["path"] == ["KNEEL_STOWED", "CRAWL", "PRONE_STOWED"]
    run(m, 0.5, 4.0)
    s = round(skipped(m, i), 9)
    assert starts(m, i) == [
        ("ststow2kstow", 0.0),
        ("kstow2crawl", round(1.6 - s, 9)),
        ("crawl2prstow", round(3.0 - s, 9)),
    ]
    assert m.soldier_info(i)["posture"] == "PRONE_STOWED"


def test_weapon_change_alone_changes_posture(lib) -> None:
    m, i = manager(lib)
    request(m, i, 0.0, UP, FIRING)
    run(m, 0.0, 1.0)
    request(m, i, 1.0, UP, WeaponState.STOWED)
    run(m, 1.0, 2.0)
    assert seq(m, i) == [("ststow2stfire", True), ("ststow2stfire", False)]


def test_dead_and_resuscitation(lib) -> None:
    m, i = manager(lib)
    request(m, i, 0.0, DEAD)
    run(m, 0.0, 2.0)
    request(m, i, 2.0, DEAD, speed=2.0)  # the dead do not walk
    run(m, 2.0, 3.0)
    assert m.soldier_info(i)["mode"] == "IDLE"
    request(m, i, 3.0, UP)
    run(m, 3.0, 13.5)
    log = m.clips_of(i)
    assert [(c.clip.rsplit("/")[-1], c.forward, c.duration, c.time) for c in log] == [
        ("ststow2dead_low", True, 1.5, 0.0),
        ("ststow2dead_low", False, 10.0, 3.0),
    ]
    assert m.soldier_info(i)["posture"] == "STAND_STOWED"


def test_immediate_snaps_to_the_goal_posture(lib) -> None:
    m, i = manager(lib)
    m.tick(0.0)
    request(m, i, 0.1, KNEEL, FIRING, immediate=True)
    info = m.soldier_info(i)
    assert info["mode"] == "IDLE" and info["posture"] == "KNEEL_FIRE"
    u = m.tick(0.1)
    node = lib.node("KNEEL_FIRE")
    clip = int(lib.rest_clip[node])
    dur = lib.clip_duration[clip]
    ref = lib.sets[0].sample(
        np.array([clip]), np.array([0.1 - dur]), np.array([lib.rest_dir[node]]), np.array([-1.0]), 0.1
    )
    assert u.indices.tolist() == [i]
    np.testing.assert_allclose(u.joints, ref.joints, atol=1e-6)
    assert m.clips_of(i) == []  # no transition played


# -- locomotion (Figure 5) -------------------------------------------------------------------------------


def test_start_steps_alternate_feet_and_steps_alternate(lib) -> None:
    m, i = manager(lib)
    request(m, i, 0.0, speed=1.4)
    run(m, 0.0, 1.5)
    request(m, i, 1.5, speed=0.0)
    run(m, 1.5, 3.0)
    request(m, i, 3.0, speed=1.4)
    run(m, 3.0, 3.7)
    request(m, i, 3.7, speed=0.0)
    run(m, 3.7, 6.0)
    n = names(m, i)
    assert n[:3] == ["walk_start_l", "walk_cycle_r", "walk_cycle_l"]
    first_end = n.index(next(x for x in n if x.startswith("walk_end")))
    feet = [x[-1] for x in n]
    assert all(a != b for a, b in itertools.pairwise(feet))  # every step uses the other foot
    assert n[first_end + 1] == f"walk_start_{'l' if n[first_end].endswith('r') else 'r'}"
    assert n[-1].startswith("walk_end") and m.soldier_info(i)["mode"] == "IDLE"


def test_walk_to_run_and_back_over_the_threshold(lib) -> None:
    m, i = manager(lib)
    request(m, i, 0.0, speed=1.4)
    run(m, 0.0, 1.0)
    request(m, i, 1.0, speed=4.0)
    run(m, 1.0, 3.0)
    request(m, i, 3.0, speed=2.0)
    run(m, 3.0, 5.5)
    request(m, i, 5.5, speed=0.0)
    run(m, 5.5, 7.5)
    n = [x.rstrip("_lr") if x[-2] == "_" else x for x in names(m, i)]
    collapsed = [x for k, x in enumerate(n) if k == 0 or x != n[k - 1]]
    assert collapsed == [
        "walk_start",
        "walk_cycle",
        "walk2run",
        "run_cycle",
        "run2walk",
        "walk_cycle",
        "walk_end",
    ]


def test_run_from_rest_and_stop_from_a_run(lib) -> None:
    m, i = manager(lib)
    request(m, i, 0.0, speed=4.5)
    run(m, 0.0, 1.5)
    request(m, i, 1.5, speed=0.0)
    run(m, 1.5, 3.0)
    n = names(m, i)
    assert n[0] == "run_start_l" and n[1] == "run_cycle_r" and n[-1].startswith("run_end")


def test_backward_walking_never_runs_and_reversing_ends_the_gait(lib) -> None:
    m, i = manager(lib)
    request(m, i, 0.0, speed=5.0, heading=30.0, backward=True)
    run(m, 0.0, 2.0)
    assert set(names(m, i)) == {"bwalk_start_l", "bwalk_cycle_r", "bwalk_cycle_l"}
    request(m, i, 2.0, speed=1.4, heading=30.0)  # now forwards
    run(m, 2.0, 4.0)
    n = names(m, i)
    k = next(j for j, x in enumerate(n) if x.startswith("bwalk_end"))
    assert n[k + 1].startswith("walk_start") and "walk2run" not in n


def test_crawl_start_cycle_and_end_as_start_backwards(lib) -> None:
    m, i = manager(lib)
    request(m, i, 0.0, PRONE)
    run(m, 0.0, 3.0)
    request(m, i, 3.0, PRONE, speed=0.4)
    run(m, 3.0, 7.0)
    request(m, i, 7.0, PRONE, speed=0.0)
    run(m, 7.0, 10.0)
    s = seq(m, i)
    assert s[:4] == [
        ("ststow2crawl", True),
        ("crawl2prstow", True),
        ("crawl2prstow", False),
        ("crawl_start", True),
    ]
    assert ("crawl_cycle", True) in s
    assert s[-2:] == [("crawl_start", False), ("crawl2prstow", True)]
    assert m.soldier_info(i)["posture"] == "PRONE_STOWED"


def test_standing_fire_walks_from_the_base_posture_then_returns(lib) -> None:
    m, i = manager(lib)
    request(m, i, 0.0, UP, FIRING)
    run(m, 0.0, 1.0)
    request(m, i, 1.0, UP, FIRING, speed=1.4)
    run(m, 1.0, 3.0)
    request(m, i, 3.0, UP, FIRING, speed=0.0)
    run(m, 3.0, 5.0)
    s = seq(m, i)
    assert s[:3] == [("ststow2stfire", True), ("ststow2stfire", False), ("walk_start_l", True)]
    assert s[-1] == ("ststow2stfire", True) and s[-2][0].startswith("walk_end")


def test_posture_change_cancels_a_step(lib) -> None:
    m, i = manager(lib)
    request(m, i, 0.0, speed=1.4)
    run(m, 0.0, 0.9)
    request(m, i, 0.9, KNEEL, speed=1.4)  # kneeling soldiers do not walk: cancel the step now
    log = m.clips_of(i)
    assert [(c.clip, round(c.time, 9)) for c in log[-2:]] == [
        ("cancel", 0.9),
        ("soldier_low/ststow2kstow_low", 0.9),
    ]
    assert m.soldier_info(i)["blending"]


def test_playback_rate_follows_ground_speed_and_keeps_the_phase(lib) -> None:
    m, i = manager(lib)
    cycle = lib.clip_id("walk_cycle_r")
    stored, gs = lib.clip_duration[cycle], lib.clip_ground_speed[cycle]
    assert gs == pytest.approx(1.4)  # 70 cm stride / 0.5 s, measured from the clip's travel
    request(m, i, 0.0, speed=1.1)
    run(m, 0.0, 8.0)  # the start step plays at its recorded rate; the cycles then catch the entity up
    cyc = [c for c in m.clips_of(i) if "cycle" in c.clip]
    assert cyc[-1].duration == pytest.approx(stored * gs / 1.1, rel=0.03)
    tb = m.table
    if tb.end[i] - 8.0 < 0.1:  # too near its end: take the next step
        run(m, 8.0, tb.end[i] + 0.01)
    t0 = float(tb.clock[i])
    t = math.ceil((t0 + 0.3 * (tb.end[i] - t0)) * 30) / 30  # a tick time within that step
    run(m, t0, t)
    before = m.snapshot([i])
    request(m, i, t, speed=1.8)
    after = m.snapshot([i])
    assert after.frames[0] == pytest.approx(before.frames[0])  # same phase, faster rate
    np.testing.assert_allclose(after.joints, before.joints, atol=1e-5)
    assert m.soldier_info(i)["clip_duration"] == pytest.approx(stored * gs / 1.8, rel=0.03)
    # human cadence limits: beyond them the stride length takes the rest
    request(m, i, t, speed=0.05)
    assert m.soldier_info(i)["clip_duration"] == pytest.approx(stored / MIN_RATE)
    request(m, i, t, speed=2.3)  # a fast walk: race-walking cadence, no stride scaling (a run's: below)
    assert m.soldier_info(i)["clip_duration"] == pytest.approx(stored * gs / 2.3, rel=0.03)
    assert stored / m.soldier_info(i)["clip_duration"] <= WALK_MAX_RATE and m.table.stride[i] == 1.0
    request(m, i, t, speed=2.39)  # the fastest walk (a walker switches to a run at 2.4)
    assert m.table.stride[i] == 1.0


# -- output: frame choice, throttle, heading-only, blending --------------------------------------------------


def test_real_time_frame_choice_at_20_hz(lib) -> None:
    m, i = manager(lib, throttle=0.0, interpolate=False)
    request(m, i, 0.0, KNEEL)  # ststow2kstow: 1.6 s at 60 fps
    ups = [u for u in run(m, 0.0, 1.6, hz=20.0) if len(u)]  # (it ends a lead-in sooner: then at rest)
    clip = lib.clip_id("ststow2kstow_low")
    frames = [u.frames[0] for u in ups]
    lead = skipped(m, i) * 60.0  # whole frames: the first that moves by a wire step
    assert lead == pytest.approx(round(lead))
    np.testing.assert_allclose(frames, np.minimum(round(lead) + 3.0 * np.arange(len(ups)), 96), atol=1e-6)
    rows = lib.sets[0].clip_start[clip] + np.minimum(round(lead) + 3 * np.arange(len(ups)), 96)
    np.testing.assert_array_equal(np.concatenate([u.joints for u in ups]), lib.sets[0].joint_data[rows])


def test_every_frame_mode_shows_each_frame_once(lib) -> None:
    m, i = manager(lib, throttle=0.0, every_frame=True)
    request(m, i, 0.0, KNEEL)
    ups = [m.tick(k * 0.25) for k in range(1, 11)]  # the tick rate does not matter
    np.testing.assert_allclose([u.frames[0] for u in ups], np.arange(1, 11), atol=1e-6)


def test_throttle_limits_updates_per_soldier(lib) -> None:
    m, i = manager(lib, throttle=0.1, tick_period=1 / 60)
    j = m.create_soldier(now=0.0)
    request(m, i, 0.0, speed=1.4)
    request(m, j, 0.05, KNEEL)
    sent: dict[int, list[float]] = {i: [], j: []}
    for u in run(m, 0.0, 2.0, hz=60.0):
        for s in u.indices.tolist():
            sent[s].append(u.now)
    for s in (i, j):
        gaps = np.diff(sent[s])
        assert len(gaps) > 10 and gaps.min() >= 0.1 - 1e-9 and gaps.max() <= 0.1 + 1 / 60 + 1e-9


@pytest.mark.parametrize(("throttle", "every"), [(0.04, 1), (1 / 30, 1), (0.0, 1), (0.06, 2), (0.1, 3)])
def test_throttle_is_a_rate_cap_on_the_tick_grid(lib, throttle: float, every: int) -> None:
    """Seed 002 3.6: 0.04 s means "at most 30 updates/s", so a 30 Hz server updates a walker every tick."""
    m, i = manager(lib, throttle=throttle, tick_period=1 / 30)
    request(m, i, 0.0, speed=1.4)
    n = 90
    counts = [len(u) for u in run(m, 0.0, (n - 1) / 30)]
    assert len(counts) == n
    assert counts == [1 if k % every == 0 else 0 for k in range(n)]


def test_a_request_between_ticks_is_answered_by_the_next_ticks_update_at_once(lib) -> None:
    """Issue 16: the first update after a request reflects it, and it need not wait for the tick."""
    m, i = manager(lib, throttle=0.04, tick_period=1 / 30)
    j = m.create_soldier(now=0.0)
    run(m, 0.0, 1.0)  # both at rest, sent
    assert len(m.answer(1.01, 1 + 1 / 30)) == 0  # nothing asked: nothing to answer
    request(m, i, 1.01, KNEEL)
    request(m, j, 1.01)  # the same request again: nothing changes, nothing to answer
    a = m.answer(1.01, 1 + 1 / 30)
    assert a.indices.tolist() == [i] and a.now == pytest.approx(1 + 1 / 30)
    assert lib.clip_names[int(a.clips[0])].endswith("ststow2kstow_low")  # the new clip...
    lead = skipped(m, i, -1) * 60  # ...from its first moving frame, as the next tick shows it
    assert a.frames[0] == pytest.approx(lead + (1 / 30 - 0.01) * 60, abs=1e-6)
    t = m.tick(1 + 1 / 30)  # the tick samples the same pose again (the board sends nothing new)
    np.testing.assert_array_equal(t.joints[t.indices.tolist().index(i)], a.joints[0])
    assert len(m.answer(1.04, 1 + 2 / 30)) == 0  # answered once per request


def test_an_answer_is_throttled_as_the_tick_it_anticipates(lib) -> None:
    m, i = manager(lib, throttle=0.1, tick_period=1 / 30)
    request(m, i, 0.0, speed=1.4)
    run(m, 0.0, 0.1)  # updates at ticks 0 and 3 (0.1 s)
    request(m, i, 0.11, speed=2.0)
    assert len(m.answer(0.11, 4 / 30)) == 0  # tick 4 is not due (0.033 s after tick 3)
    assert [len(m.tick(k / 30)) for k in (4, 5)] == [0, 0]
    request(m, i, 0.17, KNEEL)  # an event (a speed change in a start step changes no pose: nothing to answer)
    assert m.answer(0.17, 6 / 30).indices.tolist() == [i]  # tick 6 is due: released at once
    assert m.tick(6 / 30).indices.tolist() == [i] and len(m.tick(7 / 30)) == 0


def test_every_frame_mode_never_answers(lib) -> None:
    m, i = manager(lib, throttle=0.0, every_frame=True)
    request(m, i, 0.01, KNEEL)
    assert len(m.answer(0.01, 1 / 30)) == 0 and m.tick(1 / 30).indices.tolist() == [i]


def test_idle_soldiers_are_omitted_and_heading_only_resends_the_pose(lib) -> None:
    m, i = manager(lib)
    first = m.tick(0.0)
    assert first.indices.tolist() == [i] and not first.heading_only.any()
    assert len(m.tick(1 / 30)) == 0
    request(m, i, 0.05, heading=90.0)
    u = m.tick(2 / 30)
    assert u.indices.tolist() == [i] and u.heading_only.tolist() == [True] and u.headings[0] == 90.0
    np.testing.assert_array_equal(u.joints, first.joints)
    assert len(m.tick(3 / 30)) == 0


def _max_jump_deg(m: SoldierManager, phase: float, app: int) -> float:
    """Walk, cancel the step at ``phase`` of a walk cycle with a posture change; the largest per-tick joint
    change (degrees) around the interrupt, ticking at 30 Hz."""
    i = m.create_soldier(now=0.0)
    request(m, i, 0.0, speed=1.4)
    ups = run(m, 0.0, 1.0)
    info = m.soldier_info(i)
    assert "walk_cycle" in info["clip"]
    cut = round((info["clip_start"] + (1 + phase) * info["clip_duration"]) * 30) / 30  # in the next cycle
    ups += run(m, 1.0 + 1 / 30, cut - 1 / 30)
    request(m, i, cut, app, speed=1.4)
    ups += run(m, cut, cut + 1.0)
    poses = np.stack([u.joints[0] for u in ups[-45:] if len(u)])
    assert len(poses) >= 40
    return float(np.degrees(np.abs(np.diff(poses, axis=0)).max()))


@pytest.mark.parametrize("phase", [0.2, 0.5, 0.8])
def test_cancelled_step_cross_fades_without_a_pop(lib, phase: float) -> None:
    blended = _max_jump_deg(SoldierManager(lib, throttle=0.0), phase, KNEEL)
    assert blended < 5.0, blended
    if phase == 0.5:  # mid-step the swing is largest: without the fade the pose jumps
        popped = _max_jump_deg(SoldierManager(lib, throttle=0.0, blend_time=0.0), phase, KNEEL)
        assert popped > 8.0, popped


def test_one_library_sample_per_tick(lib, monkeypatch) -> None:
    calls = []
    real = ClipLibrary.sample

    def spy(self, *a, **kw):
        calls.append(len(a[0]))
        return real(self, *a, **kw)

    m = SoldierManager(lib)
    for _ in range(20):
        m.create_soldier()
    rows = make_entity_requests(np.arange(20), UP, DEPLOYED, [(0, 1.4 * (k % 3), 0) for k in range(20)], 0.0)
    m.apply_requests(rows, 0.0)
    monkeypatch.setattr(ClipLibrary, "sample", spy)
    for k in range(1, 31):
        m.tick(k / 30)
    assert len(calls) == 30 and max(calls) <= 20


# -- requests: statuses, robustness ---------------------------------------------------------------------


def test_request_statuses_and_last_row_wins(lib) -> None:
    m, i = manager(lib)
    rows = make_entity_requests([i, 99, i, i, i, i, i], UP, DEPLOYED, (0, 0, 0), 0.0)
    rows["appearance"][2] = 9
    rows["weapon"][3] = 7
    rows["velocity"][4] = (np.nan, 0, 0)
    rows["velocity"][5] = (1000.0, 0, 0)
    rows["appearance"][6] = KNEEL
    status = m.apply_requests(rows, 0.0)
    assert status.tolist() == [REQUEST_OK, REQUEST_UNKNOWN_SOLDIER] + [REQUEST_BAD_VALUE] * 4 + [REQUEST_OK]
    assert m.soldier_info(i)["goal"] == "KNEEL_STOWED"
    last = make_entity_requests([i, i], [KNEEL, PRONE], DEPLOYED, (0, 0, 0), 0.0)
    m2, j = manager(lib)
    m2.apply_requests(last, 0.0)
    assert m2.soldier_info(j)["goal"] == "PRONE_STOWED"
    assert m.status()["requests_bad"] == 4 and m.status()["requests_unknown"] == 1


def test_garbage_requests_never_raise(lib) -> None:
    m, _ = manager(lib, record_clips=False)
    for _ in range(5):
        m.create_soldier()
    rng = np.random.default_rng(3)
    for k in range(40):
        raw = rng.integers(0, 256, ENTITY_REQUEST_DTYPE.itemsize * 16, dtype=np.uint8).tobytes()
        rows = np.frombuffer(raw, ENTITY_REQUEST_DTYPE).copy()
        rows["index"] %= 8
        status = m.apply_requests(rows, k / 30)
        assert set(status.tolist()) <= {REQUEST_OK, REQUEST_UNKNOWN_SOLDIER, REQUEST_BAD_VALUE}
        u = m.tick(k / 30)
        assert np.isfinite(u.joints).all() and np.isfinite(u.figures).all()


def test_create_remove_reuse_and_status(lib) -> None:
    m = SoldierManager(lib)
    a, b, c = (m.create_soldier(f"s{k}", now=0.0) for k in range(3))
    with pytest.raises(ValueError, match="in use"):
        m.create_soldier("s1")
    with pytest.raises(ValueError, match="figure set"):
        m.create_soldier(figure="M16.fig", weapon="M16.fig")
    m.remove_soldier(b)
    assert m.create_soldier("new") == b and m.index_of("new") == b
    assert m.create_soldier(index=40) == 40
    u = m.tick(0.0)
    assert u.indices.tolist() == [a, b, c, 40]
    m.remove_soldier(40)
    with pytest.raises(KeyError):
        m.remove_soldier(40)
    st = m.status()
    assert st["soldiers"] == 3 and st["modes"]["idle"] == 3 and st["postures"] == {"STAND_STOWED": 3}
    assert st["ticks"] == 1


def test_heading_offsets_turn_each_graphs_placements(lib) -> None:
    ref, i = manager(lib, throttle=0.0)
    off, _ = manager(lib, throttle=0.0, heading_offsets=(0.0, 90.0, 0.0))
    for m in (ref, off):
        request(m, i, 0.0, speed=1.4)
    a, b = ref.tick(0.2), off.tick(0.2)
    np.testing.assert_array_equal(a.joints, b.joints)
    # compass 90 deg = Jack yaw -90 deg about +Y: (x, z) -> (-z, x)
    np.testing.assert_allclose(b.figures[0, :, 0], -a.figures[0, :, 2], atol=1e-4)
    np.testing.assert_allclose(b.figures[0, :, 2], a.figures[0, :, 0], atol=1e-4)
    for m in (ref, off):
        request(m, i, 0.3, KNEEL)
    a, b = ref.tick(0.9), off.tick(0.9)  # a static clip: offset 0
    np.testing.assert_allclose(a.figures, b.figures, atol=1e-6)


def test_scalar_and_vector_state_entry_agree(lib) -> None:
    from server.soldier.state import LocoState

    for speed, backward in [(0.0, False), (0.7, False), (4.0, True), (20.0, False)]:
        a, i = manager(lib, record_clips=False)
        b, j = manager(lib, record_clips=False)
        for m, s in ((a, i), (b, j)):
            m.table.speed[s] = speed
            m.table.backward[s] = backward
        for state in LocoState:
            if state == LocoState.NONE:
                continue
            a._enter_one(i, int(state), 1.25)
            b._enter_states(np.array([j]), np.array([state], np.int8), np.array([1.25]))
            for col in ("loco", "foot", "clip", "direc", "start", "dur", "end"):
                assert getattr(a.table, col)[i] == pytest.approx(getattr(b.table, col)[j]), (state, col)


def test_moving_during_a_transition_turns_it_back_then_walks_and_immediate_overrides(lib) -> None:
    m, i = manager(lib)
    request(m, i, 0.0, UP, FIRING)  # ststow2stfire, 0.8 s
    request(m, i, 0.2, UP, WeaponState.DEPLOYED, speed=1.4)  # the arc back is quicker than on and back
    assert m.soldier_info(i)["mode"] == "TRANSITION" and m.soldier_info(i)["path"] == ["STAND_STOWED"]
    run(m, 0.0, 2.0)
    s = round(skipped(m, i), 9)
    assert starts(m, i)[:3] == [
        ("ststow2stfire", 0.0),
        ("ststow2stfire", 0.2),  # backwards from the frame shown: as long as it played (the lead-in skipped)
        ("walk_start_l", round(0.4 + s, 9)),
    ]
    assert [f for _, f in seq(m, i)[:2]] == [True, False]
    request(m, i, 2.0, KNEEL)  # cancel the step: a posture change starts
    assert m.soldier_info(i)["mode"] == "TRANSITION"
    request(m, i, 2.1, PRONE, immediate=True)
    info = m.soldier_info(i)
    assert (info["mode"], info["posture"], info["path"], info["blending"]) == (
        "IDLE",
        "PRONE_STOWED",
        [],
        False,
    )


@pytest.mark.parametrize("fast_at", [0.9, 1.3, 1.7, 2.1])
def test_one_footed_gait_transitions_wait_for_their_foot(lib, fast_at: float) -> None:
    # walk2run / run2walk are recorded once, swinging the right foot after the left one lands: whenever the
    # speed crosses the threshold they follow a left step (one more stride first if needed), never a right one
    m, i = manager(lib)
    request(m, i, 0.0, speed=1.4)
    run(m, 0.0, fast_at)
    request(m, i, fast_at, speed=4.0)
    run(m, fast_at, fast_at + 2.0)
    request(m, i, fast_at + 2.0, speed=1.4)
    run(m, fast_at + 2.0, fast_at + 4.0)
    n = names(m, i)
    for transition in ("walk2run", "run2walk"):
        k = n.index(transition)
        assert n[k - 1].endswith("_l"), n
        assert n[k + 1].endswith("_l"), n  # the right foot swung in the transition: the left one is next
