"""``ttes loadtest``: N soldiers over C connections, a realistic DIS-rate mix, and what the server delivers.

One trio loop runs C :class:`~client_stub.loadtest.client.LoadClient` connections (each creates, subscribes
to and drives its share of the soldiers) and the *driver*, which steps the :class:`MixDriver` at
``step_hz`` (a DIS gateway's granularity; each step at a random point of its period, so the requests
sample every phase of the server's tick), sends the requests it decides, marks latency probes and samples
CPU. :class:`~client_stub.loadtest.stats.Tracker` turns what arrives into a recording; the figures of the
steady-state window (after ``warmup_s``) come from :func:`~client_stub.loadtest.stats.summarise`.

``run_ramp`` keeps the connections and grows N stage by stage (×``ramp_factor``) until a stage misses the
criteria (delivered ≥ ``min_delivered_pct`` of expected and p99 latency ≤ ``max_p99_ms``), and reports the
largest N that met them. Every loop is bounded: stages, seconds, and a wall-clock limit.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import os
import tempfile
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np
import trio

from client_stub.dis.sink import MAX_SOLDIERS_PER_CLIENT
from client_stub.link.auth import Credentials
from client_stub.link.spawn import ServerProcess, cpu_seconds, self_cpu_seconds, spawn_server
from client_stub.loadtest.client import LoadClient, LoadError, split_rows
from client_stub.loadtest.mix import MOVING, MixDriver
from client_stub.loadtest.observe import run_queue_seconds
from client_stub.loadtest.role import STATUS_EVERY_S, STATUS_JCL, server_role
from client_stub.loadtest.stats import GRACE_TICKS, Tracker, series, summarise
from protocol.events import DEFAULT_MAX_SOLDIERS, Ready, ticks_per_update
from protocol.messages import MAX_SOLDIERS_LIMIT

MAX_STAGES = 40
STARTUP_ROOM = 1024  # soldier indices left to the spawned server's start-up script beside the load's
Progress = Callable[[float, float | None, str], None]  # (seconds done, in all: None unknown, stage)
# The ramp's default latency bound: DIS's budget for tightly coupled interactions (IEEE 1278.2: 100 ms from
# one simulator's action to another's display). A request's first update waits up to one server tick (33 ms
# at 30 Hz) before it is even computed, so the bound this was before, 33 ms at p99, failed the first stage of
# any run on a working server ("largest sustained N = None").
DIS_LATENCY_MS = 100.0
JITTER_STREAM = 16  # the step jitter's random stream, apart from the mix's (same --seed, same mix)


@dataclass
class LoadTestConfig:
    soldiers: int = 100
    clients: int = 2
    rate_hz: float = 30.0
    seconds: float = 10.0
    warmup_s: float = 3.0
    host: str = "127.0.0.1"
    port: int = 7000
    spawn_server: bool = False
    server_data: str = "auto"  # auto | synthetic | default (the spawned server's motion library)
    server_pid: int | None = None  # CPU of an external server on this machine
    throttle: float | None = 0.0  # spawned server: --throttle (0: every tick); None: the script's
    mix: str = "realistic"
    seed: int = 1
    figure: str = "DI.fig"
    weapon: str = "AK_47.fig"
    subscribe_all: bool = False
    decode: bool = False
    step_hz: float = 10.0
    step_jitter: bool = True  # each step at a random point of its period (False: every step at one phase)
    timeout_s: float = 60.0
    keep_recording: bool = False  # tests: put the raw recording (numpy arrays) under "_recording"
    # ramp
    ramp: bool = False
    ramp_factor: float = 1.3
    ramp_max_soldiers: int = 8000
    ramp_max_s: float = 600.0
    min_delivered_pct: float = 99.0
    max_p99_ms: float = DIS_LATENCY_MS
    latency_metric: str = "request"  # request: request -> update (p99); delivery: server tick -> arrival
    credentials: Credentials = field(default_factory=Credentials)  # token / TLS for every connection
    # several generators in step (bench/bench_scaleout.py): once the soldiers exist, write ready_file and
    # wait until the file gate exists before the warm-up
    ready_file: str = ""
    gate: str = ""

    def check(self) -> None:
        if self.soldiers < 1 or self.clients < 1:
            raise ValueError("--soldiers and --clients must be at least 1")
        if self.clients > self.soldiers:
            raise ValueError("more clients than soldiers")
        for name in ("rate_hz", "seconds", "step_hz", "timeout_s", "ramp_max_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be > 0")
        if not (math.isfinite(self.warmup_s) and self.warmup_s >= 0):
            raise ValueError("warmup must be >= 0")
        if self.latency_metric not in ("request", "delivery"):
            raise ValueError("latency metric must be request or delivery")
        if self.ramp and not self.ramp_factor > 1.0:
            raise ValueError("--ramp-factor must be > 1")


@dataclass
class LoadTestResult:
    summary: dict[str, Any]
    series: dict[str, list[float]] = field(default_factory=dict)


class LoadSession:
    """The connections, the mix driver and the tracker of one run (or one ramp)."""

    def __init__(
        self,
        cfg: LoadTestConfig,
        server_cpu: Any = None,
        *,
        buffer_updates: bool = False,
        server_pid: int | None = None,
    ) -> None:
        """``buffer_updates``: the clients keep decoded poses for a renderer (see :class:`LoadClient`);
        ``server_pid``: a server on this machine, whose run-queue waits the worst probes' account gives."""
        self.cfg = cfg
        self.clients = [
            LoadClient(k, self._on_updates, decode=cfg.decode, buffer_updates=buffer_updates)
            for k in range(cfg.clients)
        ]
        if cfg.subscribe_all:  # one client over C connections: each may see every soldier it made
            for c in self.clients[1:]:  # (so all of them count against one client's soldier cap)
                c.link.client_id = self.clients[0].link.client_id
        for c in self.clients:
            cfg.credentials.apply(c.link)
        self.driver = MixDriver(0, mix=cfg.mix, seed=cfg.seed, now=0.0)
        self.jitter = np.random.default_rng((cfg.seed, JITTER_STREAM)) if cfg.step_jitter else None
        nsub = cfg.clients
        self.tracker = Tracker(cfg.rate_hz, nsub)
        self.server_cpu = server_cpu or (lambda: math.nan)
        self.server_pid = server_pid
        self.index = np.zeros(0, np.int64)  # slot -> server index
        self.owner = np.zeros(0, np.int64)  # slot -> connection
        self.slot_of = np.full(1 << 16, -1, np.int64)  # server index -> slot
        self.t0 = 0.0
        self.tables: set[int] = set()
        self.rate = cfg.rate_hz  # the server's tick rate, from READY once connected
        self.throttle: float | None = None  # the server's throttle, from READY
        self.every = 1  # server ticks per update of a soldier that keeps moving (its throttle)
        self.progress: Progress | None = None  # progress(done_s, total_s, stage) while driving
        self.stage = ""  # the stage progress names ("N=130" of a ramp)

    def now(self) -> float:
        return trio.current_time() - self.t0

    def _on_updates(self, conn: int, t: float, tick: int, idx: np.ndarray, nbytes: int, ev: object) -> None:
        slots = self.slot_of[idx]
        self.tracker.batch(t - self.t0, conn, tick, slots[slots >= 0], nbytes)

    async def connect(self, nursery: trio.Nursery, host: str, port: int) -> None:
        """Open every connection (their links run in ``nursery``) and wait for READY on each."""
        self.t0 = trio.current_time()
        for c in self.clients:
            await c.connect(nursery, host, port, self.cfg.timeout_s)
        for c in self.clients:
            await c.wait_ready(self.cfg.timeout_s)
        self._server_rate(self.clients[0].link.ready_event)

    def ask_status(self) -> None:
        """STATUS a second on the first connection (its own setting): what the server says it is."""
        self.clients[0].link.jcl(STATUS_JCL)

    async def server_role(self) -> dict[str, Any]:
        """What the server says it is (:func:`~client_stub.loadtest.role.server_role`), from the newest
        STATUS; a run shorter than the STATUS period waits (bounded) for its first."""
        link = self.clients[0].link
        with trio.move_on_after(2 * STATUS_EVERY_S + 1.0):
            while link.status is None and link.failure is None:
                await trio.sleep(STATUS_EVERY_S / 10)
        return server_role(None if link.status is None else link.status.text)

    def _server_rate(self, ready: Ready | None) -> None:
        """Count "expected" on the server's own tick rate and throttle (READY), not on what was asked for."""
        if ready is None:
            return
        self.rate, self.throttle = ready.tick_hz, ready.throttle
        self.every = ticks_per_update(ready.tick_hz, ready.throttle)
        self.tracker.rate = self.rate
        self.tracker.grace = GRACE_TICKS * self.every / self.rate

    async def grow(self, n: int) -> None:
        """Create soldiers up to ``n`` (spread over the connections), subscribe, send the first requests."""
        cfg = self.cfg
        old = self.driver.n
        if n <= old:
            return
        share = np.diff(np.linspace(0, n - old, cfg.clients + 1).round().astype(np.int64))
        results: list[tuple[np.ndarray, np.ndarray] | None] = [None] * cfg.clients

        async def create(k: int) -> None:
            results[k] = await self.clients[k].create_soldiers(
                int(share[k]), cfg.figure, cfg.weapon, cfg.timeout_s
            )

        async with trio.open_nursery() as nursery:
            for k in range(cfg.clients):
                if share[k]:
                    nursery.start_soon(create, k)
        idx: list[np.ndarray] = []
        owner: list[np.ndarray] = []
        for k, r in enumerate(results):
            if r is not None:
                idx.append(r[0])
                owner.append(np.full(len(r[0]), k))
                self.tables.update(int(t) for t in np.unique(r[1]))
        new_idx = np.concatenate(idx)
        new_owner = np.concatenate(owner)
        self.index = np.concatenate([self.index, new_idx])
        self.owner = np.concatenate([self.owner, new_owner])
        slots = np.arange(old, n)
        self.slot_of[new_idx] = slots
        self.driver.time = self.now()
        self.driver.grow(n)
        self.tracker.grow(n, -np.ones(len(slots), np.int64) if cfg.subscribe_all else new_owner)
        for k, c in enumerate(self.clients):
            mine = new_idx if cfg.subscribe_all else new_idx[new_owner == k]
            if len(mine):
                await c.subscribe(mine)
        rows = self.driver.initial(slots)
        t = self.now()
        self.tracker.activity(t, slots, MOVING[self.driver.activity[slots]], np.zeros(len(slots), bool))
        await self._send(rows)

    async def _send(self, rows: np.ndarray) -> None:
        if not len(rows):
            return
        parts = split_rows(rows, self.owner, self.cfg.clients)
        for k, part in enumerate(parts):
            if len(part):
                part = part.copy()
                part["index"] = self.index[part["index"].astype(np.int64)]
                await self.clients[k].requests(part)
        self.tracker.rec.requests_sent.append((self.now(), float(len(rows))))

    def sample_cpu(self) -> None:
        now = self.now()
        self.tracker.rec.cpu.append((now, self.server_cpu(), self_cpu_seconds()))
        self.tracker.rec.waits.append(
            (now, run_queue_seconds(self.server_pid), run_queue_seconds(os.getpid()))
        )

    async def drive(self, until: float) -> None:
        """Step the mix until session time ``until``: requests, probes, CPU samples."""
        times = step_times(trio.current_time(), 1.0 / self.cfg.step_hz, self.jitter)
        begin = self.now()
        due = next(times)
        await trio.sleep_until(due)
        while self.now() < until:
            if self.progress is not None:
                self.progress(self.now() - begin, until - begin, self.stage)
            self.failed()
            t = self.now()
            step = self.driver.step(t)
            ch = step.changed
            if len(ch):
                was_static = ~MOVING[step.previous]
                probe = was_static & self.tracker.settled(t, ch)
                now_doing = self.driver.activity[ch]
                change = step.previous.astype(np.int64) * 16 + now_doing
                self.tracker.activity(t, ch, MOVING[now_doing], probe, change)
            await self._send(step.rows)
            self.tracker.rec.steps.append((due - self.t0, t, self.now()))
            self.sample_cpu()
            due = next(times)
            await trio.sleep_until(due)
        if self.progress is not None:
            self.progress(until - begin, until - begin, self.stage)

    def failed(self) -> None:
        for c in self.clients:
            if c.failure is not None:
                raise LoadError(f"connection {c.number}: {c.failure}")

    async def close(self, remove: bool) -> None:
        for c in self.clients:
            if remove and c.failure is None:
                await c.remove(self.index[self.owner == c.number])
            await c.goodbye()

    def summary(self, t0: float, t1: float) -> dict[str, Any]:
        arr = self.tracker.arrays(self.now())
        out = summarise(arr, self.rate, t0, t1, self.cfg.clients, self.every)
        out.update(ready_tick_hz=self.rate, ready_throttle=self.throttle, ticks_per_update=self.every)
        out["probes_pending"] = int((~np.isnan(self.tracker.probe_at)).sum())
        for p in out["worst_probes"]:  # the server's index too, to find him in its log
            p["soldier"] = int(self.index[p["slot"]])
        return out

    def series(self, t0: float, t1: float) -> dict[str, list[float]]:
        return series(self.tracker.arrays(self.now()), self.rate, t0, t1, self.cfg.clients, every=self.every)


def step_times(start: float, period: float, jitter: np.random.Generator | None) -> Iterator[float]:
    """The mix driver's step times: one in each ``period`` after ``start``, at a uniformly random point of
    it. Steps at a fixed rate that divides the server's tick rate (10 Hz against 30 Hz) would all land at one
    phase of the tick period, and a run's latency would measure that phase only (issue 16); jittered, one
    run samples them all. ``jitter`` None: every step at the start of its period."""
    for k in itertools.count():
        yield start + period * (k + (jitter.uniform() if jitter is not None else 0.0))


def _header(cfg: LoadTestConfig, n: int) -> dict[str, Any]:
    return {
        "soldiers": n,
        "clients": cfg.clients,
        "rate_hz": cfg.rate_hz,
        "seconds": cfg.seconds,
        "nominal_updates_per_s": round(n * cfg.rate_hz * (cfg.clients if cfg.subscribe_all else 1), 1),
    }


def _passes(cfg: LoadTestConfig, s: dict[str, Any]) -> bool:
    """The ramp criteria. Request latency needs probes (soldiers changing from rest: none in the moving
    mix); a stage without any is judged on throughput alone and says so in ``latency_checked``."""
    pct = s.get("delivered_pct")
    p99 = s.get("latency_ms_p99" if cfg.latency_metric == "request" else "delivery_ms_p99")
    s["latency_checked"] = p99 is not None
    return pct is not None and pct >= cfg.min_delivered_pct and (p99 is None or p99 <= cfg.max_p99_ms)


def failed_on(cfg: LoadTestConfig, s: dict[str, Any]) -> str:
    """Which ramp criterion a stage missed, in words with its numbers."""
    why = []
    pct = s.get("delivered_pct")
    if pct is None or pct < cfg.min_delivered_pct:
        why.append(f"delivered {pct}% < {cfg.min_delivered_pct:g}%")
    key = "latency_ms_p99" if cfg.latency_metric == "request" else "delivery_ms_p99"
    p99 = s.get(key)
    if p99 is not None and p99 > cfg.max_p99_ms:
        why.append(f"p99 {cfg.latency_metric} latency {p99} ms > {cfg.max_p99_ms:g} ms")
    return ", ".join(why)


async def _run(
    cfg: LoadTestConfig,
    host: str,
    port: int,
    server_cpu: Any,
    remove: bool,
    progress: Progress | None = None,
    server_pid: int | None = None,
) -> dict[str, Any]:
    session = LoadSession(cfg, server_cpu, server_pid=server_pid)
    session.progress, session.stage = progress, f"N={cfg.soldiers}"
    out: dict[str, Any] = {}
    async with trio.open_nursery() as nursery:
        await session.connect(nursery, host, port)
        session.ask_status()
        try:
            if cfg.ramp:
                out = await _ramp(cfg, session)
            else:
                await session.grow(cfg.soldiers)
                await _gate(cfg.ready_file, cfg.gate)
                start = session.now() + cfg.warmup_s
                await session.drive(start + cfg.seconds)
                end = session.now()
                session.tracker.finish(end)
                t0, t1 = start, min(end, start + cfg.seconds)
                out = {
                    **_header(cfg, cfg.soldiers),
                    **session.summary(t0, t1),
                    "activities": session.driver.counts(),
                    "series": session.series(t0, t1),
                    "window": [t0, t1],
                }
                if cfg.keep_recording:
                    out["_recording"] = session.tracker.rec.arrays()
            out["server"] = await session.server_role()
        finally:
            with trio.CancelScope(shield=True), trio.move_on_after(5.0):
                await session.close(remove)
            nursery.cancel_scope.cancel()
    out["server_tables"] = sorted(session.tables)
    out["mode"] = "decode" if cfg.decode else "tap"
    return out


async def _gate(ready_file: str, gate: str) -> None:
    """With several load generators in processes of their own (``bench/bench_scaleout.py``): say this one's
    soldiers exist (``ready_file``), then wait (its links still reading) until the file ``gate`` exists, so
    that every generator warms up and measures in the same window."""
    if ready_file:
        Path(ready_file).touch()
    while gate and not Path(gate).exists():
        await trio.sleep(0.05)


async def _ramp(cfg: LoadTestConfig, session: LoadSession) -> dict[str, Any]:
    stages: list[dict[str, Any]] = []
    n = cfg.soldiers
    best: int | None = None
    first_fail: int | None = None
    wall0 = time.monotonic()
    for _ in range(MAX_STAGES):
        session.stage = f"N={n}"
        await session.grow(n)
        start = session.now() + cfg.warmup_s
        await session.drive(start + cfg.seconds)
        s = {**_header(cfg, n), **session.summary(start, start + cfg.seconds)}
        s["passed"] = _passes(cfg, s)
        if not s["passed"]:
            s["failed_on"] = failed_on(cfg, s)
        stages.append(s)
        if not s["passed"]:
            first_fail = n
            break
        best = n
        nxt = max(n + cfg.clients, round(n * cfg.ramp_factor))
        if nxt > cfg.ramp_max_soldiers or time.monotonic() - wall0 > cfg.ramp_max_s:
            break
        n = nxt
    session.tracker.finish(session.now())
    last = stages[-1]
    return {
        "ramp": True,
        "largest_sustained_soldiers": best,
        "first_failed_soldiers": first_fail,
        "criteria": {"min_delivered_pct": cfg.min_delivered_pct, "max_p99_ms": cfg.max_p99_ms,
                     "latency_metric": cfg.latency_metric},
        "clients": cfg.clients,
        "rate_hz": cfg.rate_hz,
        "seconds": cfg.seconds,
        "soldiers": last["soldiers"],
        **{k: last.get(k) for k in ("updates_per_s", "expected_updates_per_s", "latency_ms_p50",
                                   "latency_ms_p99", "delivery_ms_p99", "bytes_per_update",
                                   "server_cpu_pct")},
        "stages": stages,
        "series": {
            "t": [float(i) for i in range(len(stages))],
            "soldiers": [float(s["soldiers"]) for s in stages],
            "updates_per_s": [s["updates_per_s"] or 0.0 for s in stages],
            "expected_updates_per_s": [s["expected_updates_per_s"] or 0.0 for s in stages],
            "latency_ms_p50": [s["latency_ms_p50"] or math.nan for s in stages],
            "latency_ms_p99": [s["latency_ms_p99"] or math.nan for s in stages],
            "delivery_ms_p99": [s["delivery_ms_p99"] or math.nan for s in stages],
            "server_cpu_pct": [s["server_cpu_pct"] or math.nan for s in stages],
        },
    }  # fmt: skip


def server_args(tick_hz: float, throttle: float | None) -> list[str]:
    """The spawned server's command line for a load test: its tick rate and throttle."""
    return ["--tick-hz", f"{tick_hz:g}", *(["--throttle", f"{throttle:g}"] if throttle is not None else [])]


def owner_limit(soldiers: int, stack: contextlib.ExitStack) -> list[str]:
    """``--config`` raising the spawned server's soldiers per client id (4096 by default) to ``soldiers``:
    the load generator's first client creates them all; and its soldier indices (16,384 by default, the
    start-up script's soldiers among them) to make room for them, up to the wire's 65,536 (the file lives
    until ``stack`` closes)."""
    lines = []
    if soldiers > MAX_SOLDIERS_PER_CLIENT:
        lines.append(f"max_soldiers_per_client = {soldiers}")
    if soldiers + STARTUP_ROOM > DEFAULT_MAX_SOLDIERS:
        lines.append(f"max_soldiers = {min(MAX_SOLDIERS_LIMIT, soldiers + STARTUP_ROOM)}")
    if not lines:
        return []
    folder = stack.enter_context(tempfile.TemporaryDirectory(prefix="ttes-loadtest-"))
    path = Path(folder) / "server.toml"
    path.write_text("".join(f"{line}\n" for line in lines), encoding="utf-8")
    return ["--config", str(path)]


def run_loadtest(cfg: LoadTestConfig, progress: Progress | None = None) -> dict[str, Any]:
    """Run a load test (or a ramp) as configured; returns the JSON-ready result. ``progress(done_s, total_s,
    stage)`` while each stage runs (warm-up and measurement; a ramp's stages are named ``N=...``)."""
    cfg.check()
    with contextlib.ExitStack() as stack:
        return _run_loadtest(cfg, stack, progress)


def _loading(progress: Progress | None) -> Callable[[float], None] | None:
    """The spawned server's wait as a progress stage of unknown length."""
    if progress is None:
        return None
    return lambda seconds: progress(seconds, None, "server loading")


def _run_loadtest(
    cfg: LoadTestConfig, stack: contextlib.ExitStack, progress: Progress | None
) -> dict[str, Any]:
    server: ServerProcess | None = None
    server_cpu: Callable[[], float] | None
    try:
        if cfg.spawn_server:
            most = max(cfg.soldiers, cfg.ramp_max_soldiers) if cfg.ramp else cfg.soldiers
            args = server_args(cfg.rate_hz, cfg.throttle) + owner_limit(most, stack)
            server = spawn_server(args, data=cfg.server_data, waiting=_loading(progress))
            host, port = server.host, server.port
            server_cpu = server.cpu_seconds
        else:
            host, port = cfg.host, cfg.port
            given = cfg.server_pid
            server_cpu = (lambda: cpu_seconds(given)) if given else None
        try:
            pid = server.pid if server is not None else cfg.server_pid
            out = trio.run(_run, cfg, host, port, server_cpu, server is None, progress, pid)
        except BaseExceptionGroup as group:  # errors inside nurseries arrive grouped
            leaf = first_leaf(group)
            if isinstance(leaf, LoadError | OSError):
                raise LoadError(str(leaf)) from None
            raise
        said = out.pop("server", {})  # what it says it is (role, shards), then how it was reached
        if server is not None:
            out["server"] = {**said, "spawned": True, "synthetic": server.synthetic, "pid": server.pid}
        else:
            out["server"] = {**said, "spawned": False, "address": f"{host}:{port}"}
        # credentials: a secret (and an SSL context), never in a report
        hidden = ("host", "port", "keep_recording", "credentials")
        out["config"] = {f.name: getattr(cfg, f.name) for f in fields(cfg) if f.name not in hidden}
        return out
    finally:
        if server is not None:
            server.close()


def first_leaf(exc: BaseException) -> BaseException:
    while isinstance(exc, BaseExceptionGroup) and exc.exceptions:
        exc = exc.exceptions[0]
    return exc
