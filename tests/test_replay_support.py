"""Helpers shared by the replay and gateway tests: a synthetic exercise, what its PDUs ask each soldier to do,
and a monitor that records what the server's soldiers actually do (posture nodes, walking, running,
crawling), so a test can check one against the other, in order.

``from test_replay_support import ...`` (tests/ is on the path, as for test_server_support).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trio

from protocol.dis import DisLog, read_log
from protocol.dis.synth import Exercise, synthesize, write_pcap
from protocol.dis.tokens import translate
from server.soldier.state import goal_posture

WALK_RUN = 3.0  # m/s: the server's walk/run threshold
MOVING = 0.1  # m/s
BASE_POSTURE = {"WALK": "STAND_STOWED", "RUN": "STAND_STOWED", "CRAWLING": "CRAWL"}  # locomotion starts there
MAX_LAG = 6.0  # s from a request to the posture (the longest synthetic path is ~3.4 s, plus a step's end)


@functools.cache
def exercise(soldiers: int = 4, seconds: float = 40.0, seed: int = 3) -> Exercise:
    return synthesize(soldiers=soldiers, seconds=seconds, seed=seed)


def exercise_pcap(tmp: Path, soldiers: int = 4, seconds: float = 40.0, seed: int = 3) -> tuple[Path, DisLog]:
    """The exercise written by ``ttes dis synth``'s library call, and read back."""
    path = tmp / f"squad-{soldiers}-{seconds:g}-{seed}.pcap"
    write_pcap(path, exercise(soldiers, seconds, seed))
    return path, read_log(path)


def pcap_of(payloads: list[tuple[float, bytes]]) -> bytes:
    """A pcap (bytes) of UDP broadcasts to port 3000: one datagram per (receipt time, DIS payload)."""
    import io

    import dpkt

    from protocol.dis.synth import udp_frame

    f = io.BytesIO()
    w = dpkt.pcap.Writer(f, linktype=dpkt.pcap.DLT_EN10MB)
    for ts, payload in payloads:
        w.writepkt(udp_frame(payload, 0), ts=ts)
    return f.getvalue()


def activity(posture: int, weapon: int, speed: float) -> str:
    """What a request asks for: WALK / RUN / CRAWLING when moving, else the goal posture node."""
    if speed > MOVING and posture == 2:
        return "RUN" if speed >= WALK_RUN else "WALK"
    if speed > MOVING and posture in (4, 5):
        return "CRAWLING"
    return goal_posture(posture, weapon)


def expected_activities(log: DisLog) -> dict[tuple[int, int, int], list[tuple[float, str]]]:
    """Per entity: (log time, activity) each time the PDUs ask for a different one."""
    tokens, _ = translate(log.batch, log.times)
    out: dict[tuple[int, int, int], list[tuple[float, str]]] = {}
    for tok in tokens:
        key = tuple(int(v) for v in tok["entity"].item())
        seq = out.setdefault(key, [])  # type: ignore[arg-type]
        a = activity(int(tok["posture"]), int(tok["weapon"]), float(tok["speed"]))
        if not seq or seq[-1][1] != a:
            seq.append((float(tok["t"]), a))
    return out  # type: ignore[return-value]


def observed_activity(info: dict) -> str:
    if info["mode"] == "LOCO":
        return "RUN" if info["state"].startswith(("RUN", "WALK2RUN")) else "WALK"
    if info["mode"] == "CRAWL":
        return "CRAWLING"
    return info["posture"]


@dataclass
class Monitor:
    """Samples every soldier of the server each ``period`` (trio time): index -> [(start, end, activity)]."""

    server: object
    period: float = 1 / 30
    seen: dict[int, list[list]] = field(default_factory=dict)

    async def run(self) -> None:
        m = self.server.world.manager  # type: ignore[attr-defined]
        while True:
            now = trio.current_time()
            for i in m.table.live.tolist():
                a = observed_activity(m.soldier_info(i))
                seq = self.seen.setdefault(i, [])
                if seq and seq[-1][2] == a and seq[-1][1] >= now - 2 * self.period:
                    seq[-1][1] = now
                else:
                    seq.append([now, now, a])
            await trio.sleep(self.period)


def match_in_order(
    expected: list[tuple[float, str]], observed: list[list], lag: float = MAX_LAG
) -> list[str]:
    """Problems (empty = fine): each expected activity, in order, must be observed at or after the time it was
    asked for, starting within ``lag`` seconds, after the previous one was. One the next request asked
    something else of less than ``lag`` later, before it was seen, may go unseen: the server re-plans a
    posture change under way toward the latest request (``server.soldier.replanning``; killed 1.05 s after he
    was told to go prone from kneeling, he dies from forearms and knees)."""
    problems = []
    k = 0
    for n, (t_req, want) in enumerate(expected):
        t_next = expected[n + 1][0] if n + 1 < len(expected) else np.inf
        j = k
        while j < len(observed) and not (
            want in (observed[j][2], BASE_POSTURE.get(observed[j][2])) and observed[j][1] >= t_req - 1e-6
        ):
            j += 1
        if t_next - t_req < lag and (j == len(observed) or observed[j][0] > t_next + 1e-6):
            continue  # superseded before it was reached
        if j == len(observed):
            problems.append(f"{want} asked at {t_req:.2f} never seen after the previous activities")
            return problems
        k = j
        if observed[k][0] > t_req + lag:
            problems.append(f"{want} asked at {t_req:.2f} only seen at {observed[k][0]:.2f}")
        if observed[k][2] == want:
            k += 1  # reached through a base posture: the locomotion itself may be the next activity
    return problems


def server_times(
    expected: list[tuple[float, str]], log_t0: float, trio_t0: float, speed: float = 1.0
) -> list:
    return [(trio_t0 + (t - log_t0) / speed, a) for t, a in expected]


def entity_key(entity: tuple[int, int, int]) -> np.uint64:
    return np.uint64((entity[0] << 32) | (entity[1] << 16) | entity[2])
