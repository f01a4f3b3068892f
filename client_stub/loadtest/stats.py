"""The load tester's bookkeeping and arithmetic: what was expected, what arrived, how late, at what cost.

The server sends a soldier's update only when its quantised pose changed (docs/PROTOCOL.md 8.4: an idle
soldier costs 0 bytes), so "N × rate" is not what a healthy server sends when half the soldiers stand still.
The yardstick is therefore the soldiers that *must* change every tick: those walking, running or crawling
(a *steady mover* from 2 ticks after the request that set them moving until the request that stops them).
A server that keeps up delivers each steady mover in every tick's batch; a server that skips ticks or
coalesces them (its writers are latest-wins) delivers fewer.

Everything is counted on the server's **tick grid**. Every JOINT_UPDATES frame carries the server's tick
``T``; a tick's grid time is ``a + T / rate``, ``a`` being the smallest ``arrival − T / rate`` seen in the
window (the fastest delivery; a tick's arrival is its last row's, see :func:`grid_offset`); ``arrival − grid
time`` is a row's *delivery* time (how long after its tick it arrived, beyond the fastest; negative for an
answer sent before its tick). Expected updates = for every grid tick in the window, the steady movers at
that tick's grid time; received = rows of steady movers whose tick's grid time is in the window. A row
arriving more than one period after its grid time is *late* (the server fell behind real time).

Latency is measured on *probes*: requests to a soldier that was at rest (no update for ``settle`` seconds),
so the first update that arrives for it is the one that reflects the request. A probe whose soldier was
asked to do something else again before that update came is *superseded*: its update may reflect the later
request, or none (asked to kneel, then to stand again: a server that applies both in one turn may show
nothing). Such probes are counted apart (``probes_superseded``, and among those answered over a second,
``probes_over_1s_superseded``) so that a tail of them is told from a slow server (issue 21).

All methods are vectorised per batch; :func:`summarise` and :func:`series` are pure functions of the
recorded arrays, so tests can check the arithmetic on hand-made inputs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from client_stub.loadtest.worst import causes_over, worst_probes

GRACE_TICKS = 2.0  # a soldier set moving counts as a steady mover this many ticks after the request
SETTLE_S = 0.5  # a soldier with no update for this long is at rest: its next update answers a probe
_KEY_SPAN = 1.0e6  # seconds: composite (slot, time) keys need times below this


@dataclass
class Recording:
    """Everything one run recorded (times in seconds on the load generator's monotonic clock)."""

    rate_hz: float
    # one entry per soldier row received
    row_time: list[np.ndarray] = field(default_factory=list)  # arrival
    row_tick: list[np.ndarray] = field(default_factory=list)
    row_slot: list[np.ndarray] = field(default_factory=list)  # global slot (0..N-1), per subscriber
    row_conn: list[np.ndarray] = field(default_factory=list)
    # one entry per JOINT_UPDATES frame
    frame_time: list[float] = field(default_factory=list)
    frame_bytes: list[int] = field(default_factory=list)
    frame_rows: list[int] = field(default_factory=list)
    # steady-mover episodes: [start, end) of slot as seen by connection conn
    ep_slot: list[np.ndarray] = field(default_factory=list)
    ep_conn: list[np.ndarray] = field(default_factory=list)
    ep_start: list[np.ndarray] = field(default_factory=list)
    ep_end: list[np.ndarray] = field(default_factory=list)
    # probes: (send time, latency) of answered probes; sent times of every probe
    probe_sent: list[np.ndarray] = field(default_factory=list)
    latency_time: list[np.ndarray] = field(default_factory=list)
    latency: list[np.ndarray] = field(default_factory=list)
    latency_superseded: list[np.ndarray] = field(default_factory=list)  # the answered probe was superseded
    # and what each answered probe was (for the worst probes' account, :mod:`client_stub.loadtest.worst`):
    # its slot, connection, the tick of the frame that answered it, and its change (from * 16 + to activity)
    latency_slot: list[np.ndarray] = field(default_factory=list)
    latency_conn: list[np.ndarray] = field(default_factory=list)
    latency_tick: list[np.ndarray] = field(default_factory=list)
    latency_change: list[np.ndarray] = field(default_factory=list)
    latency_superseded_at: list[np.ndarray] = field(default_factory=list)  # when (nan: not superseded)
    frame_conn: list[int] = field(default_factory=list)  # the connection and tick of each JOINT_UPDATES frame
    frame_tick: list[int] = field(default_factory=list)
    # the mix driver's steps: (when due, when it ran, when its requests were written): a late step is a load
    # generator that did not run, a slow write a server that did not read
    steps: list[tuple[float, float, float]] = field(default_factory=list)
    # seconds the server's and the load generator's threads waited on a run queue so far (Linux schedstat;
    # nan if unknown), sampled with the CPU: (time, server, load generator)
    waits: list[tuple[float, float, float]] = field(default_factory=list)
    # CPU samples: time, server CPU seconds (nan if unknown), load generator CPU seconds
    cpu: list[tuple[float, float, float]] = field(default_factory=list)
    requests_sent: list[tuple[float, float]] = field(default_factory=list)

    def arrays(self) -> dict[str, np.ndarray]:
        def cat(parts: list[np.ndarray], dtype: type) -> np.ndarray:
            return np.concatenate(parts).astype(dtype) if parts else np.zeros(0, dtype)

        return {
            "row_time": cat(self.row_time, np.float64),
            "row_tick": cat(self.row_tick, np.int64),
            "row_slot": cat(self.row_slot, np.int64),
            "row_conn": cat(self.row_conn, np.int64),
            "frame_time": np.asarray(self.frame_time, np.float64),
            "frame_bytes": np.asarray(self.frame_bytes, np.int64),
            "frame_rows": np.asarray(self.frame_rows, np.int64),
            "frame_conn": np.asarray(self.frame_conn, np.int64),
            "frame_tick": np.asarray(self.frame_tick, np.int64),
            "ep_slot": cat(self.ep_slot, np.int64),
            "ep_conn": cat(self.ep_conn, np.int64),
            "ep_start": cat(self.ep_start, np.float64),
            "ep_end": cat(self.ep_end, np.float64),
            "probe_sent": cat(self.probe_sent, np.float64),
            "latency_time": cat(self.latency_time, np.float64),
            "latency": cat(self.latency, np.float64),
            "latency_superseded": cat(self.latency_superseded, np.bool_),
            "latency_slot": cat(self.latency_slot, np.int64),
            "latency_conn": cat(self.latency_conn, np.int64),
            "latency_tick": cat(self.latency_tick, np.int64),
            "latency_change": cat(self.latency_change, np.int64),
            "latency_superseded_at": cat(self.latency_superseded_at, np.float64),
            "cpu": np.asarray(self.cpu, np.float64).reshape(-1, 3),
            "steps": np.asarray(self.steps, np.float64).reshape(-1, 3),
            "waits": np.asarray(self.waits, np.float64).reshape(-1, 3),
            "requests": np.asarray(self.requests_sent, np.float64).reshape(-1, 2),
        }


class Tracker:
    """Per-soldier state that turns batches and requests into a :class:`Recording` as they happen.

    Slots are the load tester's soldier numbers; each slot belongs to (is subscribed by) one connection, or
    to all of them with ``subscribers > 1`` (rows then carry the connection number)."""

    def __init__(self, rate_hz: float, nconn: int = 1) -> None:
        self.rate = float(rate_hz)
        self.grace = GRACE_TICKS / self.rate
        self.nconn = nconn
        self.rec = Recording(self.rate)
        self.n = 0
        self.steady_from = np.zeros(0)  # start of the open episode (inf: not a steady mover now)
        self.last_rx = np.zeros((0, nconn))  # last arrival of an update, per connection
        self.probe_at = np.zeros((0, nconn))  # pending probe send time (nan: none)
        self.change = np.zeros(0, np.int64)  # the pending probe's change (from * 16 + to; -1: not told)
        # when its soldier's activity changed again since (nan: not: the probe is not superseded)
        self.superseded_at = np.zeros((0, nconn))
        self.owner = np.zeros(0, np.int64)  # subscribing connection, -1 = all

    def grow(self, n: int, owner: np.ndarray) -> None:
        k = n - self.n
        if k <= 0:
            return
        self.steady_from = np.concatenate([self.steady_from, np.full(k, np.inf)])
        self.last_rx = np.concatenate([self.last_rx, np.full((k, self.nconn), -np.inf)])
        self.probe_at = np.concatenate([self.probe_at, np.full((k, self.nconn), np.nan)])
        self.change = np.concatenate([self.change, np.full(k, -1, np.int64)])
        self.superseded_at = np.concatenate([self.superseded_at, np.full((k, self.nconn), np.nan)])
        self.owner = np.concatenate([self.owner, np.asarray(owner, np.int64)])
        self.n = n

    def _close(self, slots: np.ndarray, t: float) -> None:
        """End the open steady episodes of ``slots`` at ``t``."""
        open_ = slots[np.isfinite(self.steady_from[slots])]
        if not len(open_):
            return
        conns = self._subscribers(open_)
        for c, sel in conns:
            self.rec.ep_slot.append(open_[sel])
            self.rec.ep_conn.append(np.full(int(sel.sum()), c, np.int64))
            self.rec.ep_start.append(self.steady_from[open_[sel]])
            self.rec.ep_end.append(np.full(len(open_[sel]), t))
        self.steady_from[open_] = np.inf

    def _subscribers(self, slots: np.ndarray) -> list[tuple[int, np.ndarray]]:
        owner = self.owner[slots]
        out = []
        for c in range(self.nconn):
            sel = (owner == c) | (owner < 0)
            if sel.any():
                out.append((c, sel))
        return out

    def activity(
        self,
        t: float,
        slots: np.ndarray,
        moving: np.ndarray,
        probe: np.ndarray,
        change: np.ndarray | None = None,
    ) -> None:
        """Requests sent at ``t`` that changed the activity of ``slots`` (``moving`` after the change);
        ``probe`` marks those whose request is a latency probe (call :meth:`settled` to pick them);
        ``change``: each one's change (from * 16 + to activity), kept with its probe's answer."""
        slots = np.asarray(slots, np.int64)
        if not len(slots):
            return
        self._close(slots, t)
        self.steady_from[slots[moving]] = t + self.grace
        pending = ~np.isnan(self.probe_at[slots])
        first = pending & np.isnan(self.superseded_at[slots])
        self.superseded_at[slots] = np.where(first, t, self.superseded_at[slots])
        p = slots[probe]
        if len(p):
            self.rec.probe_sent.append(np.full(len(p), t))
            self.change[p] = -1 if change is None else np.asarray(change, np.int64)[probe]
            cols = self.owner[p]
            for c in range(self.nconn):
                sel = (cols == c) | (cols < 0)
                self.probe_at[p[sel], c] = t
                self.superseded_at[p[sel], c] = np.nan

    def settled(self, t: float, slots: np.ndarray) -> np.ndarray:
        """(len(slots),) bool: no update for ``SETTLE_S`` on any subscriber and no probe pending."""
        slots = np.asarray(slots, np.int64)
        quiet = (self.last_rx[slots] <= t - SETTLE_S).all(axis=1)
        return quiet & np.isnan(self.probe_at[slots]).all(axis=1)

    def batch(self, t: float, conn: int, tick: int, slots: np.ndarray, nbytes: int) -> None:
        """One JOINT_UPDATES frame received at ``t`` on ``conn``: ``slots`` are its soldiers' slots."""
        slots = np.asarray(slots, np.int64)
        rec = self.rec
        rec.frame_time.append(t)
        rec.frame_bytes.append(nbytes)
        rec.frame_rows.append(len(slots))
        rec.frame_conn.append(conn)
        rec.frame_tick.append(tick)
        if not len(slots):
            return
        rec.row_time.append(np.full(len(slots), t))
        rec.row_tick.append(np.full(len(slots), tick, np.int64))
        rec.row_slot.append(slots)
        rec.row_conn.append(np.full(len(slots), conn, np.int64))
        self.last_rx[slots, conn] = t
        sent = self.probe_at[slots, conn]
        answered = ~np.isnan(sent)
        if answered.any():
            rec.latency_time.append(np.full(int(answered.sum()), t))
            rec.latency.append(t - sent[answered])
            rec.latency_superseded.append(~np.isnan(self.superseded_at[slots[answered], conn]))
            rec.latency_slot.append(slots[answered])
            rec.latency_conn.append(np.full(int(answered.sum()), conn, np.int64))
            rec.latency_tick.append(np.full(int(answered.sum()), tick, np.int64))
            rec.latency_change.append(self.change[slots[answered]])
            rec.latency_superseded_at.append(self.superseded_at[slots[answered], conn])
            self.probe_at[slots[answered], conn] = np.nan

    def arrays(self, t: float) -> dict[str, np.ndarray]:
        """The recording so far, with the still open episodes ending at ``t`` (the state is unchanged)."""
        arr = self.rec.arrays()
        open_ = np.flatnonzero(np.isfinite(self.steady_from))
        slots, conns = [arr["ep_slot"]], [arr["ep_conn"]]
        starts, ends = [arr["ep_start"]], [arr["ep_end"]]
        for c, sel in self._subscribers(open_):
            slots.append(open_[sel])
            conns.append(np.full(int(sel.sum()), c, np.int64))
            starts.append(self.steady_from[open_[sel]])
            ends.append(np.full(int(sel.sum()), t))
        arr["ep_slot"], arr["ep_conn"] = np.concatenate(slots), np.concatenate(conns)
        arr["ep_start"], arr["ep_end"] = np.concatenate(starts), np.concatenate(ends)
        return arr

    def finish(self, t: float) -> None:
        """Close every open episode at ``t`` (end of the run)."""
        self._close(np.arange(self.n), t)


# -- arithmetic -------------------------------------------------------------------------------------------


def grid_offset(row_time: np.ndarray, row_tick: np.ndarray, rate: float, t0: float, t1: float) -> float:
    """``a`` of the tick grid ``a + T / rate``: the smallest ``arrival(T) − T/rate`` over the ticks whose rows
    arrived in ``[t0, t1)`` (nan if none), ``arrival(T)`` the *last* arrival of a row of tick ``T``: the
    server may send a tick's update of a soldier with a new request before the tick (an answer, labelled
    with the tick it anticipates), so only a tick's last rows say when the tick itself went out."""
    sel = (row_time >= t0) & (row_time < t1)
    if not sel.any():
        return math.nan
    ticks, inv = np.unique(row_tick[sel], return_inverse=True)
    last = np.full(len(ticks), -np.inf)
    np.maximum.at(last, inv, row_time[sel])
    return float(np.min(last - ticks / rate))


def grid_ticks(lo: np.ndarray, hi: np.ndarray, a: float, rate: float) -> np.ndarray:
    """How many grid times ``a + T/rate`` (T integer) lie in ``[lo, hi)``, elementwise (0 if hi <= lo)."""
    lo = np.asarray(lo, np.float64)
    hi = np.asarray(hi, np.float64)
    n = np.ceil((hi - a) * rate - 1e-9) - np.ceil((lo - a) * rate - 1e-9)
    return np.where(hi > lo, np.maximum(n, 0), 0).astype(np.int64)


def in_episodes(
    slot: np.ndarray, conn: np.ndarray, when: np.ndarray, ep: dict[str, np.ndarray], nconn: int
) -> np.ndarray:
    """(n,) bool: does ``(slot, conn)`` have a steady episode containing ``when``? Episodes of one
    (slot, conn) never overlap."""
    if not len(ep["ep_slot"]) or not len(slot):
        return np.zeros(len(slot), bool)
    ekey = (ep["ep_slot"] * nconn + ep["ep_conn"]).astype(np.float64) * _KEY_SPAN
    order = np.argsort(ekey + ep["ep_start"], kind="stable")
    starts = (ekey + ep["ep_start"])[order]
    rkey = (slot * nconn + conn).astype(np.float64) * _KEY_SPAN
    pos = np.searchsorted(starts, rkey + when, side="right") - 1
    ok = pos >= 0
    j = order[np.clip(pos, 0, None)]
    same = (ep["ep_slot"][j] == slot) & (ep["ep_conn"][j] == conn)
    return ok & same & (when >= ep["ep_start"][j]) & (when < ep["ep_end"][j])


def percentile_ms(values_s: np.ndarray, q: float) -> float:
    return float(np.percentile(values_s, q) * 1000.0) if len(values_s) else math.nan


def _cpu_pct(cpu: np.ndarray, col: int, t0: float, t1: float) -> float:
    """Percent of one core used between the samples nearest ``t0`` and ``t1``."""
    if len(cpu) < 2:
        return math.nan
    i0 = int(np.argmin(np.abs(cpu[:, 0] - t0)))
    i1 = int(np.argmin(np.abs(cpu[:, 0] - t1)))
    dt = cpu[i1, 0] - cpu[i0, 0]
    if dt <= 0 or not (np.isfinite(cpu[i0, col]) and np.isfinite(cpu[i1, col])):
        return math.nan
    return float(100.0 * (cpu[i1, col] - cpu[i0, col]) / dt)


def _round(x: float, nd: int = 3) -> float | None:
    return None if x is None or not math.isfinite(x) else round(float(x), nd)


def _soldiers_seen_min(slot: np.ndarray, conn: np.ndarray, nconn: int) -> int:
    """The fewest distinct soldiers any one connection received updates of (over the whole run): with
    --subscribe-all, every connection should see every soldier."""
    return min((len(np.unique(slot[conn == c])) for c in range(nconn)), default=0)


def summarise(
    arr: dict[str, np.ndarray], rate: float, t0: float, t1: float, nconn: int, every: int = 1
) -> dict:
    """The steady-state figures of the window ``[t0, t1)`` (see the module docstring). Counts are per
    subscription: with every connection subscribed to every soldier, a mover counts once per connection.
    ``every``: the server's ticks per update of one soldier (``protocol.events.ticks_per_update`` of READY's
    ``tick_hz`` and ``throttle``): a steady mover is expected in one tick of ``every``."""
    dur = t1 - t0
    a = grid_offset(arr["row_time"], arr["row_tick"], rate, t0, t1)
    if math.isfinite(a):
        when = a + arr["row_tick"] / rate
        sel = (when >= t0) & (when < t1)
        steady = in_episodes(arr["row_slot"][sel], arr["row_conn"][sel], when[sel], arr, nconn)
        received = int(steady.sum())
        lateness = arr["row_time"][sel] - when[sel]
        late = int((lateness > 1.0 / rate).sum())
        late_steady = int((lateness[steady] > 1.0 / rate).sum())
        rows_in = int(sel.sum())
        lo = np.maximum(arr["ep_start"], t0)
        hi = np.minimum(arr["ep_end"], t1)
        expected = round(grid_ticks(lo, hi, a, rate).sum() / every)
        ticks = arr["row_tick"][sel]
        tick_span = int(ticks.max() - ticks.min() + 1) if len(ticks) else 0
    else:
        received = late = late_steady = rows_in = expected = tick_span = 0
        lateness = np.zeros(0)
    fsel = (arr["frame_time"] >= t0) & (arr["frame_time"] < t1)
    fbytes = int(arr["frame_bytes"][fsel].sum())
    frows = int(arr["frame_rows"][fsel].sum())
    lsel = (arr["latency_time"] >= t0) & (arr["latency_time"] < t1)
    lat = arr["latency"][lsel]
    sup = arr["latency_superseded"][lsel] if "latency_superseded" in arr else np.zeros(len(lat), bool)
    sent_at = arr["latency_time"][lsel] - lat
    psel = (arr["probe_sent"] >= t0) & (arr["probe_sent"] < t1 - 2 * SETTLE_S)
    req = arr["requests"]
    rsel = (req[:, 0] >= t0) & (req[:, 0] < t1) if len(req) else np.zeros(0, bool)
    mover_ticks = expected * every / max(1, round(dur * rate))
    return {
        "updates_per_s": _round(received / dur, 1),
        "expected_updates_per_s": _round(expected / dur, 1),
        "delivered_pct": _round(100.0 * received / expected, 2) if expected else None,
        "all_updates_per_s": _round(frows / dur, 1),
        "steady_movers_mean": _round(mover_ticks, 1),
        "dropped_updates": max(0, expected - received),
        "late_updates": late,
        "late_steady_updates": late_steady,
        "late_pct": _round(100.0 * late / rows_in, 2) if rows_in else None,
        "delivery_ms_p50": _round(percentile_ms(lateness, 50), 2),
        "delivery_ms_p99": _round(percentile_ms(lateness, 99), 2),
        "server_ticks_seen": tick_span,
        "soldiers_seen_min": _soldiers_seen_min(arr["row_slot"], arr["row_conn"], nconn),
        "server_tick_hz": _round(tick_span / dur, 2),
        "latency_ms_p50": _round(percentile_ms(lat, 50), 2),
        "latency_ms_p99": _round(percentile_ms(lat, 99), 2),
        "latency_ms_max": _round(float(lat.max() * 1000.0), 2) if len(lat) else None,
        "latency_samples": len(lat),
        "probes_sent": int(psel.sum()),
        "probes_superseded": int(sup.sum()),
        "probes_over_1s": int((lat > 1.0).sum()),
        "probes_over_1s_superseded": int((sup & (lat > 1.0)).sum()),
        # when they were sent (s into the window, the first 50): a burst is a stall, a spread is lost answers
        "probes_over_1s_sent_s": np.round(np.sort(sent_at[lat > 1.0] - t0)[:50], 2).tolist(),
        # the slowest probes, each with what went on while it waited, and what held up those over 1 s
        # (client_stub.loadtest.worst)
        "worst_probes": worst_probes(arr, t0, t1),
        "probes_over_1s_causes": causes_over(arr, t0, t1, 1.0),
        "bytes_per_update": _round(fbytes / frows, 2) if frows else None,
        "bytes_per_s": _round(fbytes / dur, 0),
        "frames_per_s": _round(int(fsel.sum()) / dur, 1),
        "requests_per_s": _round(float(req[rsel, 1].sum()) / dur, 1) if len(req) else 0.0,
        "server_cpu_pct": _round(_cpu_pct(arr["cpu"], 1, t0, t1), 1),
        "client_cpu_pct": _round(_cpu_pct(arr["cpu"], 2, t0, t1), 1),
    }


def series(
    arr: dict[str, np.ndarray],
    rate: float,
    t0: float,
    t1: float,
    nconn: int,
    bin_s: float = 1.0,
    every: int = 1,
) -> dict:
    """Per-bin throughput (received vs expected steady-mover updates per second), probe latency p50/p99 and
    server CPU, for plotting. Times are seconds from ``t0``."""
    edges = np.arange(t0, t1 + 1e-9, bin_s)
    if len(edges) < 2:
        edges = np.array([t0, t1])
    nb = len(edges) - 1
    a = grid_offset(arr["row_time"], arr["row_tick"], rate, t0, t1)
    got = np.zeros(nb)
    exp = np.zeros(nb)
    if math.isfinite(a):
        when = a + arr["row_tick"] / rate
        sel = (when >= t0) & (when < t1)
        steady = in_episodes(arr["row_slot"][sel], arr["row_conn"][sel], when[sel], arr, nconn)
        got = np.histogram(when[sel][steady], edges)[0].astype(np.float64)
        for k in range(nb):
            lo = np.maximum(arr["ep_start"], edges[k])
            hi = np.minimum(arr["ep_end"], edges[k + 1])
            exp[k] = grid_ticks(lo, hi, a, rate).sum() / every
    width = np.diff(edges)
    p50 = np.full(nb, np.nan)
    p99 = np.full(nb, np.nan)
    which = np.digitize(arr["latency_time"], edges) - 1
    for k in range(nb):
        lat = arr["latency"][which == k]
        if len(lat):
            p50[k], p99[k] = np.percentile(lat, [50, 99]) * 1000.0
    cpu = np.full(nb, np.nan)
    for k in range(nb):
        cpu[k] = _cpu_pct(arr["cpu"], 1, edges[k], edges[k + 1])
    return {
        "t": (edges[:-1] + width / 2 - t0).tolist(),
        "updates_per_s": (got / width).tolist(),
        "expected_updates_per_s": (exp / width).tolist(),
        "latency_ms_p50": p50.tolist(),
        "latency_ms_p99": p99.tolist(),
        "server_cpu_pct": cpu.tolist(),
    }
