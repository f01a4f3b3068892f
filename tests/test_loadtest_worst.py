"""The load test's account of its worst probes (issue 16: a 2 s latency spike must say what it was)."""

from __future__ import annotations

import numpy as np
import pytest

from client_stub.loadtest.mix import Activity
from client_stub.loadtest.stats import Tracker, summarise
from client_stub.loadtest.worst import change_name, worst_line

RATE = 30.0
STAND_KNEEL = int(Activity.STAND) * 16 + int(Activity.KNEEL)


def _run(*, silent: tuple[float, float] = (0.0, 0.0), superseded_at: float | None = None) -> Tracker:
    """Two soldiers of one connection: slot 0 walks (a row every tick, none while ``silent``), slot 1 rests
    and is probed (stand -> kneel) at 1.0 s, and answered in the frame of tick 60 (2.0 s); the mix driver
    steps at 10 Hz on time."""
    tr = Tracker(RATE, 1)
    tr.grow(2, np.zeros(2, np.int64))
    tr.activity(0.0, np.array([0]), np.array([True]), np.array([False]))
    tr.activity(1.0, np.array([1]), np.array([False]), np.array([True]), np.array([STAND_KNEEL]))
    if superseded_at is not None:
        tr.activity(superseded_at, np.array([1]), np.array([False]), np.array([False]))
    for k in range(1, 30):
        tr.rec.steps.append((k / 10, k / 10, k / 10 + 0.001))
    for tick in range(90):
        t = 0.005 + tick / RATE
        if silent[0] <= t < silent[1] and tick != 60:
            continue
        tr.batch(t, 0, tick, np.array([0, 1] if tick == 60 else [0]), 100)
    return tr


def _worst(tr: Tracker, waits: list[tuple[float, float, float]] | None = None) -> dict:
    tr.rec.waits.extend(waits or [(0.0, 0.0, 0.0), (3.0, 0.05, 0.05)])
    s = summarise(tr.arrays(3.0), RATE, 0.5, 2.9, 1)
    assert s["latency_samples"] == 1 and s["probes_over_1s"] == 1
    worst = s["worst_probes"][0]
    assert s["probes_over_1s_causes"] == {worst["cause"]: 1}
    return worst


def test_a_probe_answered_late_while_the_stream_flowed_is_the_soldiers() -> None:
    p = _worst(_run())
    assert p["latency_ms"] == pytest.approx(1005.0, abs=0.1) and p["sent_s"] == 0.5
    assert p["change"] == "stand->kneel" and not p["superseded"] and p["superseded_after_ms"] is None
    assert p["frames"] == 31 and p["ticks"] == 31 and p["longest_gap_ms"] < 40  # ticks 30 ... 60
    assert p["answer_tick"] == 60 and p["write_ms"] == 1.0 and p["loadgen_late_ms"] == 0.0
    assert p["cause"] == "soldier showed nothing"


def test_a_silence_on_its_connection_is_a_stall_and_a_starved_server_says_so() -> None:
    stalled = _worst(_run(silent=(1.1, 1.95)))
    assert stalled["longest_gap_ms"] > 800 and stalled["cause"] == "stream stalled"
    # the server's main thread runnable but not running for 0.9 s of that second: the machine's load
    waits = [(0.0, 0.0, 0.0), (1.0, 0.01, 0.0), (2.0, 0.91, 0.02), (3.0, 0.92, 0.02)]
    tr = _run(silent=(1.1, 1.95))
    tr.rec.cpu.extend([(0.0, 0.0, 0.0), (3.0, 0.3, 0.03)])  # the server ran 10 % of the time, then
    starved = _worst(tr, waits)
    assert starved["server_cpu_ms"] == pytest.approx(100.5, abs=0.1)
    assert starved["server_wait_ms"] == pytest.approx(900.0, abs=1.0) and starved["loadgen_wait_ms"] == 20.0
    assert starved["cause"] == "server starved"
    assert "server starved" in worst_line([starved]) and "server waited 900.1 ms for a CPU" in worst_line(
        [starved]
    )


def test_a_superseded_probe_says_when_it_was_superseded() -> None:
    p = _worst(_run(superseded_at=1.6))
    assert p["superseded"] and p["superseded_after_ms"] == 600.0 and p["cause"] == "superseded"


def test_change_names() -> None:
    assert change_name(STAND_KNEEL) == "stand->kneel" and change_name(-1) == "?"
    dead_stand = int(Activity.DEAD) * 16 + int(Activity.STAND)
    assert change_name(dead_stand) == "dead->stand"


async def test_the_driver_records_its_steps_and_each_probes_change(autojump_clock: object) -> None:
    """The mix driver keeps (due, ran, written) for every step and hands each probe's change to the tracker,
    so an account can say how late the load generator ran and what the soldier was asked."""
    import trio

    from client_stub.loadtest.session import LoadSession, LoadTestConfig

    n = 300
    session = LoadSession(LoadTestConfig(soldiers=n, clients=2, seed=5))

    async def requests(rows: np.ndarray) -> None:
        await trio.sleep(0.001)  # the socket takes them a moment later

    for c in session.clients:
        c.requests = requests  # type: ignore[method-assign]
    session.t0 = trio.current_time()
    session.index, session.owner = np.arange(n), np.arange(n) % 2
    session.driver.grow(n)
    session.tracker.grow(n, session.owner)
    await session.drive(10.0)
    steps = session.tracker.arrays(10.0)["steps"]
    assert len(steps) >= 95 and (steps[:, 0] <= steps[:, 1]).all() and (steps[:, 1] <= steps[:, 2]).all()
    assert (steps[:, 2] - steps[:, 1] >= 0.001).sum() >= 90  # the steps that sent requests waited for them
    probed = ~np.isnan(session.tracker.probe_at).all(axis=1)
    assert probed.any()
    names = {change_name(int(c)) for c in session.tracker.change[probed]}
    assert "?" not in names and all("->" in x for x in names)
