"""The load test's worst probes, each with what was going on while it waited (issue 16: the latency spike).

A request → update latency of seconds, seen once in a run, says nothing by itself: was the whole stream
stalled (the server, or the load generator, not running), or did frames keep coming and none carried this
soldier (its request showed nothing: the motion, or a later request superseded it)? :func:`worst_probes`
gives each of the slowest probes of a window its own account from the recording:

* ``change``: what its soldier was asked (``stand->kneel``), whether it was ``superseded`` and when
  (``superseded_after_ms``), and ``answer_tick``, the server tick of the frame that answered it;
* ``write_ms``: how long its request took to be handed to the socket (a server that did not read);
* ``frames`` and ``ticks``: the frames and distinct server ticks its connection received while it waited,
  and ``longest_gap_ms``, the longest silence on that connection in that time;
* ``loadgen_late_ms``: how late the mix driver's steps ran meanwhile (the load generator itself not running);
* ``server_wait_ms`` / ``loadgen_wait_ms``: how long the server's and the load generator's main threads
  waited on a run queue meanwhile (runnable, not running: the machine's other load; Linux schedstat), and
  ``server_cpu_ms`` / ``loadgen_cpu_ms`` the CPU each process used meanwhile (what is left of the wait was
  idle: waiting on a socket or a timer);
* ``cause`` (:func:`cause`): ``superseded``, ``request written late``, ``server starved``, ``load generator
  starved``, ``stream stalled`` or ``soldier showed nothing``.

The summary keeps the :data:`WORST` slowest (``worst_probes``) and counts the causes of every probe over a
second (``probes_over_1s_causes``): a run's spike says what it was without a second run.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from client_stub.loadtest.mix import Activity

WORST = 5  # probes in the account
STALL_SHARE = 0.5  # a silence this share of a probe's wait, or more: the stream stalled


def change_name(code: int) -> str:
    """``from * 16 + to`` (activity numbers) as ``stand->kneel``; ``?`` when not told."""
    if code < 0:
        return "?"
    names = {int(a): a.name.lower() for a in Activity}
    return f"{names.get(code // 16, '?')}->{names.get(code % 16, '?')}"


def _waited_ms(samples: np.ndarray, col: int, t0: float, t1: float) -> float | None:
    """Seconds (run-queue or CPU) of column ``col`` between ``t0`` and ``t1`` (interpolated samples), in ms;
    None when a sample is unknown."""
    if len(samples) < 2 or not np.isfinite(samples[:, col]).all():
        return None
    a, b = np.interp([t0, t1], samples[:, 0], samples[:, col])
    return round(1000.0 * float(b - a), 1)


def cause(probe: dict[str, Any]) -> str:
    """The first that holds: ``superseded``; ``request written late`` (its write took most of the wait: the
    server did not read); ``server starved`` / ``load generator starved`` (its main thread waited most of it
    on a run queue: the machine's other load); ``stream stalled`` (the longest silence on its connection was
    most of it, with neither starved: the server held it up); else ``soldier showed nothing`` (frames flowed,
    none for him: the motion)."""
    half = STALL_SHARE * probe["latency_ms"]
    if probe["superseded"]:
        return "superseded"
    if (probe["write_ms"] or 0.0) >= half:
        return "request written late"
    if (probe["server_wait_ms"] or 0.0) >= half:
        return "server starved"
    if (probe["loadgen_wait_ms"] or 0.0) >= half:
        return "load generator starved"
    if probe["longest_gap_ms"] >= half:
        return "stream stalled"
    return "soldier showed nothing"


def worst_probes(arr: dict[str, np.ndarray], t0: float, t1: float, n: int = WORST) -> list[dict[str, Any]]:
    """The ``n`` slowest probes answered in ``[t0, t1)``, slowest first, each with its account (see the
    module); times are seconds into the window."""
    sel = _answered(arr, t0, t1)
    worst = sel[np.argsort(-arr["latency"][sel], kind="stable")[:n]]
    return [account(arr, k, t0) for k in worst.tolist()]


def causes_over(arr: dict[str, np.ndarray], t0: float, t1: float, seconds: float) -> dict[str, int]:
    """How many of the probes answered in ``[t0, t1)`` after more than ``seconds`` had each cause."""
    sel = _answered(arr, t0, t1)
    counts: dict[str, int] = {}
    for k in sel[arr["latency"][sel] > seconds].tolist():
        c = account(arr, k, t0)["cause"]
        counts[c] = counts.get(c, 0) + 1
    return counts


def _answered(arr: dict[str, np.ndarray], t0: float, t1: float) -> np.ndarray:
    """The answered probes of ``[t0, t1)`` (none from a recording without the accounts' arrays)."""
    if "latency_conn" not in arr:
        return np.zeros(0, np.int64)
    lt = arr["latency_time"]
    return np.flatnonzero((lt >= t0) & (lt < t1))


def account(arr: dict[str, np.ndarray], k: int, t0: float) -> dict[str, Any]:
    """Answered probe ``k``'s account (see the module); times are seconds after ``t0``."""
    answered, latency = float(arr["latency_time"][k]), float(arr["latency"][k])
    sent, conn = answered - latency, int(arr["latency_conn"][k])
    on = arr["frame_conn"] == conn
    ft = arr["frame_time"][on]
    inside = (ft > sent) & (ft <= answered)
    gap = float(np.diff(np.concatenate([[sent], ft[inside], [answered]])).max())
    steps, waits = arr["steps"], arr["waits"]
    late = steps[(steps[:, 1] >= sent) & (steps[:, 1] <= answered)]
    own = steps[np.abs(steps[:, 1] - sent) < 1e-6]  # its own step: how long its request took to write
    again = float(arr["latency_superseded_at"][k]) - sent
    probe = {
        "sent_s": round(sent - t0, 3),
        "latency_ms": round(1000.0 * latency, 1),
        "connection": conn,
        "slot": int(arr["latency_slot"][k]),
        "change": change_name(int(arr["latency_change"][k])),
        "superseded": bool(arr["latency_superseded"][k]),
        "superseded_after_ms": round(1000.0 * again, 1) if math.isfinite(again) else None,
        "answer_tick": int(arr["latency_tick"][k]),
        "frames": int(inside.sum()),
        "ticks": len(np.unique(arr["frame_tick"][on][inside])),
        "longest_gap_ms": round(1000.0 * gap, 1),
        "write_ms": round(1000.0 * float(own[0, 2] - sent), 1) if len(own) else None,
        "loadgen_late_ms": round(1000.0 * float((late[:, 1] - late[:, 0]).max()), 1) if len(late) else None,
        "server_wait_ms": _waited_ms(waits, 1, sent, answered),
        "loadgen_wait_ms": _waited_ms(waits, 2, sent, answered),
        "server_cpu_ms": _waited_ms(arr["cpu"], 1, sent, answered),
        "loadgen_cpu_ms": _waited_ms(arr["cpu"], 2, sent, answered),
    }
    probe["cause"] = cause(probe)
    return probe


def worst_line(probes: list[dict[str, Any]], causes: dict[str, int] | None = None) -> str:
    """The slowest probe in words, and the causes of those over 1 s (the summary's line); "" without one."""
    if not probes:
        return ""
    p = probes[0]
    over = ", ".join(f"{c} {k}" for c, k in sorted((causes or {}).items(), key=lambda ck: -ck[1]))
    waits = ", ".join(
        f"{who} waited {p[key]:g} ms for a CPU"
        for who, key in (("server", "server_wait_ms"), ("load generator", "loadgen_wait_ms"))
        if p[key] is not None and math.isfinite(p[key])
    )
    return (
        f"slowest probe {p['latency_ms']:g} ms ({p['change']}, sent at {p['sent_s']:g} s, connection "
        f"{p['connection']}): {p['cause']}; {p['frames']} frames of {p['ticks']} ticks meanwhile, longest "
        f"silence {p['longest_gap_ms']:g} ms"
        + (f"; {waits}" if waits else "")
        + (f"; over 1 s: {over}" if over else "")
    )
