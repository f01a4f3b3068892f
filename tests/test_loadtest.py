"""`ttes loadtest`: the mix, the bookkeeping arithmetic (hand-made and on a tiny real run), the CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trio
from hypothesis import given
from hypothesis import strategies as st

from client_stub.loadtest.mix import MOVING, SPEED, Activity, MixDriver
from client_stub.loadtest.stats import (
    GRACE_TICKS,
    Tracker,
    grid_ticks,
    in_episodes,
    summarise,
)
from protocol.entity import Appearance, first_bad_row
from protocol.events import ticks_per_update

RATE = 30.0


# -- the mix ------------------------------------------------------------------------------------------------
def test_mix_requests_are_valid_and_dis_rate() -> None:
    d = MixDriver(400, seed=3)
    first = d.initial()
    assert len(first) == 400 and first["immediate"].all()
    assert first_bad_row(first, 65536) is None
    sent = 0
    for k in range(1, 201):  # 20 s at 10 Hz
        step = d.step(k / 10)
        assert first_bad_row(step.rows, 65536) is None
        assert set(step.changed.tolist()) <= set(step.rows["index"].tolist())
        assert not (d.activity[step.changed] == step.previous).any()  # a change is a change
        sent += len(step.rows)
    per_soldier_hz = sent / 400 / 20
    assert 0.2 <= per_soldier_hz <= 1.0  # heartbeat 0.2 Hz + changes and turns: DIS-like, far below 30 Hz
    # the velocity matches each activity's speed along the heading
    v = d.velocity()
    assert np.allclose(np.hypot(v[:, 0], v[:, 1]), SPEED[d.activity])


def test_mix_revives_the_dead_immediately_and_moving_mix_only_moves() -> None:
    d = MixDriver(300, seed=5)
    d.activity[:] = Activity.DEAD
    d.until[:] = 0.5
    step = d.step(1.0)
    assert len(step.changed) == 300
    assert (d.activity == Activity.STAND).all()
    revived = step.rows[np.isin(step.rows["index"], step.changed)]
    assert revived["immediate"].all() and (revived["appearance"] == Appearance.UPRIGHT).all()
    m = MixDriver(300, mix="moving", seed=5)
    for k in range(1, 100):
        m.step(k / 5)
        assert m.moving.all()


# -- arithmetic on hand-made recordings ---------------------------------------------------------------------
def test_grid_ticks_counts_integer_ticks_in_half_open_intervals() -> None:
    a = 0.01
    # grid times 0.01 + T/30
    assert grid_ticks(np.array([0.01]), np.array([0.01 + 1.0]), a, RATE)[0] == 30
    assert grid_ticks(np.array([0.0]), np.array([0.01]), a, RATE)[0] == 0  # hi excluded
    assert grid_ticks(np.array([0.01]), np.array([0.011]), a, RATE)[0] == 1  # lo included
    assert grid_ticks(np.array([2.0]), np.array([1.0]), a, RATE)[0] == 0


@given(
    st.lists(
        st.tuples(st.integers(0, 4), st.integers(0, 1), st.floats(0, 9), st.floats(0.01, 3)), max_size=12
    ),
    st.lists(st.tuples(st.integers(0, 4), st.integers(0, 1), st.floats(0, 12)), max_size=30),
)
def test_in_episodes_matches_a_plain_loop(eps: list, rows: list) -> None:
    # make episodes of one (slot, conn) disjoint, as the tracker does
    ep: dict[tuple[int, int], list[tuple[float, float]]] = {}
    for s, c, start, length in eps:
        spans = ep.setdefault((s, c), [])
        if all(start >= e or start + length <= b for b, e in spans):
            spans.append((start, start + length))
    flat = [(s, c, b, e) for (s, c), spans in ep.items() for b, e in spans]
    arr = {
        "ep_slot": np.array([f[0] for f in flat], np.int64),
        "ep_conn": np.array([f[1] for f in flat], np.int64),
        "ep_start": np.array([f[2] for f in flat], np.float64),
        "ep_end": np.array([f[3] for f in flat], np.float64),
    }
    slot = np.array([r[0] for r in rows], np.int64)
    conn = np.array([r[1] for r in rows], np.int64)
    when = np.array([r[2] for r in rows], np.float64)
    got = in_episodes(slot, conn, when, arr, 2)
    want = [any(s == fs and c == fc and b <= w < e for fs, fc, b, e in flat) for s, c, w in rows]
    assert got.tolist() == want


def _perfect_run(drop_ticks: frozenset[int] = frozenset(), late_s: float = 0.0) -> dict:
    """Two soldiers on one connection: slot 0 moves for the whole run; slot 1 rests, is probed at 1.0 s and
    answers in tick 31. Ticks arrive at 0.005 + T/30 (from tick 60 on ``late_s`` later); 100 bytes a frame."""
    tr = Tracker(RATE, 1)
    tr.grow(2, np.zeros(2, np.int64))
    tr.activity(0.0, np.array([0, 1]), np.array([True, False]), np.array([False, False]))
    assert tr.settled(1.0, np.array([1]))[0]  # never updated: at rest
    tr.activity(1.0, np.array([1]), np.array([False]), np.array([True]))
    assert not tr.settled(1.0, np.array([1]))[0]  # a probe is pending
    for tick in range(90):  # 3 s
        if tick in drop_ticks:
            continue
        t = 0.005 + tick / RATE + (late_s if tick >= 60 else 0.0)
        tr.batch(t, 0, tick, np.array([0, 1] if tick == 31 else [0]), 100)
    return tr.arrays(3.0)


def test_summary_of_a_perfect_run() -> None:
    s = summarise(_perfect_run(), RATE, 1.0, 2.0, 1)
    assert s["expected_updates_per_s"] == 30.0 and s["updates_per_s"] == 30.0
    assert s["delivered_pct"] == 100.0 and s["dropped_updates"] == 0 and s["late_updates"] == 0
    assert s["latency_samples"] == 1
    assert s["latency_ms_p50"] == pytest.approx(1000 * (0.005 + 31 / RATE - 1.0), abs=0.01)
    assert s["bytes_per_update"] == pytest.approx(
        100 * 30 / 31, abs=0.01
    )  # 31 rows (one probe answer) in 30 frames
    assert s["server_tick_hz"] == 30.0


def test_summary_counts_dropped_and_late_updates() -> None:
    s = summarise(_perfect_run(drop_ticks=frozenset({35, 36, 40})), RATE, 1.0, 2.0, 1)
    assert s["expected_updates_per_s"] == 30.0 and s["updates_per_s"] == 27.0
    assert s["dropped_updates"] == 3 and s["delivered_pct"] == 90.0
    late = summarise(_perfect_run(late_s=0.1), RATE, 1.5, 2.5, 1)  # from 2.005 s every row is 100 ms late
    assert late["late_updates"] == 15 and late["delivered_pct"] == 100.0


def test_expected_follows_the_servers_throttle() -> None:
    """READY's tick rate and throttle set "expected": 0.04 s at 30 Hz is every tick, 0.1 s one in three."""
    assert ticks_per_update(30.0, 0.04) == 1 and ticks_per_update(30.0, 1 / 30) == 1
    assert ticks_per_update(30.0, 0.0) == 1 and ticks_per_update(30.0, 0.1) == 3
    assert ticks_per_update(60.0, 0.1) == 6 and ticks_per_update(30.0, 0.06) == 2
    thinned = _perfect_run(drop_ticks=frozenset(t for t in range(90) if t % 3))
    s = summarise(thinned, RATE, 1.0, 2.0, 1, every=ticks_per_update(RATE, 0.1))
    assert s["expected_updates_per_s"] == 10.0 and s["delivered_pct"] == 100.0
    assert s["steady_movers_mean"] == 1.0
    assert summarise(thinned, RATE, 1.0, 2.0, 1)["delivered_pct"] == pytest.approx(100 / 3, abs=0.01)


def test_a_probe_superseded_before_its_answer_is_counted_apart() -> None:
    """Slot 0 is probed (kneel) and asked to stand again 0.1 s later: its next update, 2 s on, may reflect
    either or neither (a server that applies both in one turn shows nothing), so a tail of them is told
    from a slow server (issue 21); slot 1's probe, answered in 40 ms, is not superseded."""
    tr = Tracker(RATE, 1)
    tr.grow(2, np.zeros(2, np.int64))
    tr.activity(1.0, np.array([0, 1]), np.array([False, False]), np.array([True, True]))
    tr.batch(1.04, 0, 31, np.array([1]), 100)
    tr.activity(1.1, np.array([0]), np.array([False]), np.array([False]))  # superseded: no new probe
    tr.batch(3.1, 0, 93, np.array([0]), 100)
    s = summarise(tr.arrays(4.0), RATE, 0.5, 3.5, 1)
    assert s["latency_samples"] == 2 and s["probes_superseded"] == 1
    assert s["probes_over_1s"] == 1 and s["probes_over_1s_superseded"] == 1
    assert s["probes_over_1s_sent_s"] == [0.5]  # sent at 1.0, the window from 0.5
    tr.activity(3.5, np.array([0]), np.array([False]), np.array([True]))  # probed again: not superseded
    tr.batch(3.55, 0, 106, np.array([0]), 100)
    assert summarise(tr.arrays(4.0), RATE, 3.4, 3.9, 1)["probes_superseded"] == 0


def test_steady_movers_start_after_the_grace_ticks() -> None:
    tr = Tracker(RATE, 1)
    tr.grow(1, np.zeros(1, np.int64))
    tr.activity(1.0, np.array([0]), np.array([True]), np.array([False]))
    assert tr.steady_from[0] == pytest.approx(1.0 + GRACE_TICKS / RATE)
    tr.activity(2.0, np.array([0]), np.array([False]), np.array([False]))  # stops: episode closed at 2.0
    arr = tr.arrays(5.0)
    assert arr["ep_start"].tolist() == [pytest.approx(1.0 + GRACE_TICKS / RATE)] and arr[
        "ep_end"
    ].tolist() == [2.0]


# -- the driver's step times (issue 16) ----------------------------------------------------------------------
async def _send_times(monkeypatch: pytest.MonkeyPatch, jitter: bool, n: int = 200) -> np.ndarray:
    """Drive a 10 s mix over 2 (fake) connections; the times each connection's requests went out."""
    from client_stub.loadtest.session import LoadSession, LoadTestConfig

    session = LoadSession(LoadTestConfig(soldiers=n, clients=2, seed=5, step_jitter=jitter))
    sent: list[float] = []

    async def requests(rows: np.ndarray) -> None:
        sent.append(session.now())

    for c in session.clients:
        monkeypatch.setattr(c, "requests", requests)
    session.t0 = trio.current_time()
    session.index, session.owner = np.arange(n), np.arange(n) % 2
    session.driver.grow(n)
    session.tracker.grow(n, session.owner)
    await session.drive(10.0)
    return np.array(sent)


def _thirds(times: np.ndarray) -> np.ndarray:
    """The share of ``times`` in each third of the server's tick period (30 Hz)."""
    phase = np.mod(times * RATE, 1.0)
    return np.bincount(np.minimum((phase * 3).astype(np.int64), 2), minlength=3) / len(times)


async def test_requests_sample_every_phase_of_the_tick(autojump_clock, monkeypatch) -> None:
    """A 10 Hz mix against a 30 Hz tick: fixed steps put every request at one phase (a run measured that
    phase only: p50 8.8-18 ms between runs); jittered steps spread them over the whole period, the same
    way for the same seed."""
    fixed = await _send_times(monkeypatch, jitter=False)
    assert len(fixed) > 150 and max(_thirds(fixed)) > 0.99  # one narrow band
    spread = await _send_times(monkeypatch, jitter=True)
    assert len(spread) > 150 and min(_thirds(spread)) >= 0.2, _thirds(spread)
    again = await _send_times(monkeypatch, jitter=True)
    assert again == pytest.approx(spread, abs=1e-9)


# -- a tiny real run ----------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def server():
    from client_stub.link.spawn import spawn_server
    from client_stub.loadtest.session import server_args

    with spawn_server(server_args(RATE, 0.0)) as srv:
        yield srv


@pytest.fixture(scope="module")
def tiny_run(server) -> dict:
    from client_stub.loadtest.session import LoadTestConfig, run_loadtest

    cfg = LoadTestConfig(
        soldiers=16, clients=2, seconds=1.5, warmup_s=1.0, host=server.host, port=server.port,
        server_pid=server.pid, mix="moving", keep_recording=True,
    )  # fmt: skip
    return run_loadtest(cfg)


def test_tiny_run_arithmetic(tiny_run: dict) -> None:
    r = tiny_run
    arr: dict = r["_recording"]
    t0, t1 = r["window"]
    dur = t1 - t0
    assert r["soldiers"] == 16 and r["clients"] == 2 and r["rate_hz"] == RATE and r["seconds"] == 1.5
    assert r["nominal_updates_per_s"] == 16 * RATE
    # recompute bytes per update and all updates per second from the raw frames, with plain Python
    triples = zip(arr["frame_time"], arr["frame_bytes"], arr["frame_rows"], strict=True)
    frames = [(t, b, n) for t, b, n in triples if t0 <= t < t1]
    assert r["bytes_per_update"] == pytest.approx(
        sum(b for _, b, _ in frames) / sum(n for _, _, n in frames), abs=0.01
    )
    assert r["all_updates_per_s"] == pytest.approx(sum(n for _, _, n in frames) / dur, abs=0.1)
    # with the moving mix every soldier is a steady mover (after its grace ticks)
    assert r["expected_updates_per_s"] == pytest.approx(r["steady_movers_mean"] * RATE, rel=0.01)
    assert r["delivered_pct"] == pytest.approx(
        100.0 * r["updates_per_s"] / r["expected_updates_per_s"],
        abs=0.2,  # the rates are rounded to 0.1
    )
    assert 8 < r["steady_movers_mean"] <= 16
    lost = (r["expected_updates_per_s"] - r["updates_per_s"]) * dur
    assert abs(r["dropped_updates"] - max(0.0, lost)) <= 1  # (the rates are rounded to 0.1)
    # a DI-shaped update costs far less than the 1994 packet (436 bytes) and more than its 8-byte header
    assert 8 < r["bytes_per_update"] < 120
    assert r["server_cpu_pct"] is not None and r["server_cpu_pct"] > 0
    assert not r["server"]["spawned"] and r["mode"] == "tap"
    assert r["server"]["role"] == "server"  # it says it is a single server (STATUS), not a front-end
    assert all(MOVING[a] for a in range(len(MOVING)) if r["activities"][Activity(a).name.lower()])


def test_cli_json_and_plot(server, tmp_path, capsys) -> None:
    from ttes.cli import main

    png = tmp_path / "lt.png"
    rc = main(
        ["loadtest", "--port", str(server.port), "--server-pid", str(server.pid), "--soldiers", "6",
         "--clients", "2", "--seconds", "1.5", "--warmup", "1", "--json", "--plot", str(png)]
    )  # fmt: skip
    assert rc == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    for key in ("soldiers", "clients", "rate_hz", "seconds", "updates_per_s", "expected_updates_per_s",
                "latency_ms_p50", "latency_ms_p99", "bytes_per_update", "server_cpu_pct"):  # fmt: skip
        assert key in out
    assert out["soldiers"] == 6 and out["clients"] == 2 and out["rate_hz"] == 30.0
    assert "_recording" not in out
    data = png.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000


def test_cli_refuses_bad_arguments(capsys) -> None:
    from ttes.cli import main

    assert main(["loadtest", "--soldiers", "2", "--clients", "3"]) == 2
    assert "more clients than soldiers" in capsys.readouterr().err
    assert main(["loadtest", "--soldiers", "1", "--clients", "1", "--port", "1", "--seconds", "1"]) == 1
    assert "ttes loadtest: error:" in capsys.readouterr().err  # nothing listens on port 1


def test_ramp_grows_until_its_bound(server) -> None:
    from client_stub.loadtest.session import LoadTestConfig, run_loadtest

    cfg = LoadTestConfig(
        soldiers=4, clients=2, seconds=0.8, warmup_s=0.3, host=server.host, port=server.port, ramp=True,
        ramp_factor=2.0, ramp_max_soldiers=8, max_p99_ms=10_000.0, min_delivered_pct=0.0, mix="moving",
    )  # fmt: skip
    r = run_loadtest(cfg)
    assert [s["soldiers"] for s in r["stages"]] == [4, 8]
    assert all(s["passed"] for s in r["stages"]) and r["largest_sustained_soldiers"] == 8
    assert not any(s["latency_checked"] for s in r["stages"])  # the moving mix has no probes
    assert r["first_failed_soldiers"] is None and r["series"]["soldiers"] == [4.0, 8.0]


def test_subscribe_all_sees_every_connections_soldiers(server) -> None:
    """Issue 17: a controller sees only its client's soldiers, so the load tester's connections are one
    client (one client id): each connection still gets every soldier's updates."""
    from client_stub.loadtest.session import LoadTestConfig, run_loadtest

    cfg = LoadTestConfig(
        soldiers=8, clients=2, seconds=1.0, warmup_s=0.5, host=server.host, port=server.port,
        mix="moving", subscribe_all=True,
    )  # fmt: skip
    r = run_loadtest(cfg)
    assert r["soldiers_seen_min"] == 8, r  # not a delivered percentage: that depends on the machine's load


def test_each_connection_is_its_own_client_so_the_per_client_cap_counts_per_connection(tmp_path) -> None:
    """Issue 17 regression: with every connection one client id, 5,000 soldiers over 2 clients hit the 4,096
    per-client cap ("owns 4096 soldiers"). Without --subscribe-all each connection creates only its own share
    and is a client of its own; here a cap of 6 per client and 8 soldiers over 2 connections."""
    from client_stub.link.spawn import spawn_server
    from client_stub.loadtest.session import LoadTestConfig, run_loadtest, server_args

    config = tmp_path / "server.toml"
    config.write_text("[server]\nmax_soldiers_per_client = 6\n")
    with spawn_server([*server_args(RATE, 0.0), "--config", str(config)]) as srv:
        cfg = LoadTestConfig(
            soldiers=8, clients=2, seconds=0.8, warmup_s=0.3, host=srv.host, port=srv.port, mix="moving",
        )  # fmt: skip
        r = run_loadtest(cfg)
    assert r["soldiers"] == 8 and r["soldiers_seen_min"] == 4, r  # each connection sees its own 4


def test_ramp_defaults_can_pass(server, capsys) -> None:
    """Issue 19: `ttes loadtest --spawn-server --ramp` failed its first stage with its own defaults ("largest
    sustained N = None"): p99 request latency <= 33 ms, less than a request's wait for the next 30 Hz tick
    plus its first pose (README: p99 49-84 ms on a working server). The default bound is DIS's 100 ms."""
    from client_stub.loadtest.session import _passes
    from ttes.cli import build_parser, main
    from ttes.commands.loadtest import config

    cfg = config(build_parser().parse_args(["loadtest", "--spawn-server", "--ramp"]))
    assert _passes(cfg, {"delivered_pct": 99.5, "latency_ms_p99": 84.0})  # the README's worst measured p99
    assert not _passes(cfg, {"delivered_pct": 99.5, "latency_ms_p99": 150.0})
    # a short ramp with the default criteria on a real server sustains its one stage, and says why not if not
    argv = ["loadtest", "--port", str(server.port), "--ramp", "--soldiers", "8", "--clients", "2",
            "--seconds", "2", "--warmup", "1", "--ramp-max-soldiers", "8"]  # fmt: skip
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "p99 request latency <= 100 ms" in out
    # sustained on a quiet machine; on a busy one the stage may miss a criterion (load, not code: no delivered
    # percentage is asserted here), but then the report must say which, with its numbers
    assert "largest sustained N = 8" in out or "no N sustained: the first stage (N=8) failed (" in out, out


# -- what the server says it is (issue 21) ------------------------------------------------------------------
@given(st.lists(st.tuples(st.booleans(), st.booleans()), min_size=1, max_size=8))
def test_role_reads_every_front_end_status_the_front_end_writes(shards: list[tuple[bool, bool]]) -> None:
    """Round trip through the front-end's own STATUS note (``FrontNode.describe``): each shard home or
    stood in for by the next, present or gone."""
    from types import SimpleNamespace

    from client_stub.loadtest.role import role_line, server_role
    from server.fabric.nodes import FrontNode, Sharding

    n = len(shards)
    route = [k if home else (k + 1) % n for k, (home, _) in enumerate(shards)]
    node = SimpleNamespace(shards=n, route=route, present=[p for _, p in shards], front=Sharding(0, 1))
    text = "3 soldiers, 1 clients, 30.0 Hz, tick 12 us mean; " + FrontNode.describe(node)  # type: ignore[arg-type]
    r = server_role(text)
    assert r["role"] == "front-end" and r["status"] == text
    expected = [{"shard": k, "animated_by": route[k], "present": shards[k][1]} for k in range(n)]
    assert r["shards"] == expected
    assert role_line(r).startswith(f"front-end of {n} shards (0 ")


def test_role_of_a_shard_a_single_server_and_silence() -> None:
    from client_stub.loadtest.role import role_line, server_role

    shard = server_role("5 soldiers, 0 clients, 30.0 Hz, tick 80 us mean; shard 1/2, 340 batches")
    assert (shard["role"], shard["shard"], shard["of"], role_line(shard)) == ("shard", 1, 2, "shard 1/2")
    assert server_role("5 soldiers, 2 clients, 30.0 Hz, tick 80 us mean")["role"] == "server"
    assert server_role(None) == {"role": None, "status": None}
    assert role_line({}) == "unknown (no STATUS)"


@given(st.text(max_size=200))
def test_role_never_raises_on_any_status_text(text: str) -> None:
    from client_stub.loadtest.role import role_line, server_role

    r = server_role(text)
    assert r["role"] in ("front-end", "shard", "server") and isinstance(role_line(r), str)


async def test_generators_in_step_say_ready_then_wait_for_the_gate(autojump_clock, tmp_path) -> None:
    """bench/bench_scaleout.py's generators: each says its soldiers exist, and none warms up before the
    bench opens the gate (once all are ready), so that they all measure the same window."""
    from client_stub.loadtest.session import _gate

    ready, gate = tmp_path / "gen0.ready", tmp_path / "gate"
    passed: list[float] = []

    async def generator() -> None:
        await _gate(str(ready), str(gate))
        passed.append(trio.current_time())

    async with trio.open_nursery() as nursery:
        nursery.start_soon(generator)
        await trio.sleep(5.0)
        assert ready.exists() and not passed
        gate.touch()
    assert passed and passed[0] >= 5.0


def test_a_spawned_server_has_room_for_more_soldiers_than_its_default_indices() -> None:
    """20,000 soldiers: more than the 16,384 indices a server has by default (the run failed with "all
    16384 soldier indices are in use"); the wire's 65,536 at most."""
    import contextlib
    from pathlib import Path

    from client_stub.loadtest.session import owner_limit

    with contextlib.ExitStack() as stack:
        assert owner_limit(1000, stack) == []
        text = Path(owner_limit(20000, stack)[1]).read_text()
        assert "max_soldiers_per_client = 20000" in text and "max_soldiers = 21024" in text
        assert "max_soldiers = 65536" in Path(owner_limit(70000, stack)[1]).read_text()
