"""``ttes loadtest --plot FILE.png``: throughput and latency over time (over N for a ramp); matplotlib Agg."""

from __future__ import annotations

import math
import os
from typing import Any


def plot_result(result: dict[str, Any], path: str | os.PathLike[str]) -> None:
    """Two panels: steady-mover updates per second (received vs expected) and probe latency p50/p99."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    s = result.get("series") or {}
    ramp = bool(result.get("ramp"))
    x = s.get("soldiers" if ramp else "t", [])
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(9, 6.5), sharex=True, constrained_layout=True)
    marker = "o" if ramp else None
    top.plot(x, s.get("expected_updates_per_s", []), "--", color="0.45", marker=marker, label="expected")
    top.plot(x, s.get("updates_per_s", []), color="tab:blue", marker=marker, label="received")
    top.set_ylabel("steady-mover updates / s")
    top.set_ylim(bottom=0)
    top.grid(alpha=0.3)
    top.legend(loc="lower right")
    bottom.plot(x, s.get("latency_ms_p50", []), color="tab:green", marker=marker, label="request→update p50")
    bottom.plot(x, s.get("latency_ms_p99", []), color="tab:red", marker=marker, label="request→update p99")
    if ramp and "delivery_ms_p99" in s:
        bottom.plot(x, s["delivery_ms_p99"], color="tab:purple", marker=marker, label="tick→arrival p99")
    rate = float(result.get("rate_hz") or 30.0)
    bottom.axhline(1000.0 / rate, color="0.6", lw=0.8, ls=":", label=f"one tick ({1000.0 / rate:.1f} ms)")
    bottom.set_ylabel("latency (ms)")
    bottom.set_ylim(bottom=0)
    bottom.set_xlabel("soldiers" if ramp else "seconds into the steady state")
    bottom.grid(alpha=0.3)
    bottom.legend(loc="upper left", fontsize="small")
    cpu = s.get("server_cpu_pct")
    if cpu and not all(math.isnan(c) for c in cpu):
        twin = top.twinx()
        twin.plot(x, cpu, color="tab:orange", alpha=0.6, lw=1, marker=marker)
        twin.set_ylabel("server CPU % (orange)", color="tab:orange")
    n = result.get("largest_sustained_soldiers") if ramp else result.get("soldiers")
    what = f"largest sustained N = {n}" if ramp else f"{n} soldiers"
    fig.suptitle(
        f"ttes loadtest: {what}, {result.get('clients')} clients, {rate:g} Hz"
        + ("" if ramp else f", {result.get('bytes_per_update')} bytes/update")
    )
    fig.savefig(path, dpi=100)
    plt.close(fig)
