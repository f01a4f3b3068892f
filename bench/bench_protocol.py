"""Joint-update codec benchmark: one 10,000-soldier batch per tick, DI.fig-shaped update table.

Table: 23 joints / 50 DOFs (12-bit codes) + 2 figures (soldier, rifle: 16-bit mm position, smallest-three
quaternion). Motion: 70% of soldiers move (every DOF a 1 Hz sine of amplitude 0.02..0.5 rad sampled at 30 Hz,
the root bobbing ±2 cm and yawing ±5°), 30% stand idle. Reports µs per batch for encode and decode
(UpdateEncoder / UpdateDecoder, then the same through a server/client Connection pair), and bytes per full,
moving and idle soldier. ``quantise_us_per_batch`` is the float-to-code share of encode, which a server can do
once per tick for every client (``UpdateEncoder.encode_codes``). Times are medians of this process's CPU time
(robust on a shared machine); the ``*_wall_*`` fields are wall-clock medians. ``--json``: one JSON object.
``--front K``: also a front-end's encode (issue 21): K encoders, each its own 8,000-soldier crowd
(``--front-soldiers``), CPU per tick of all K encodes.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

import numpy as np

from protocol.connection import CLIENT, SERVER, Connection
from protocol.events import PROTOCOL_VERSION, Accept, Hello, JointUpdates, Subscribe, UpdateTableMsg
from protocol.legacy import packet_floats
from protocol.update_table import example_di_table
from protocol.updates import UpdateDecoder, UpdateEncoder, quantise

N = 10_000
HZ = 30.0
BIG = 1 << 24


class Crowd:
    """Deterministic synthetic motion for N soldiers."""

    def __init__(self, n: int, moving_share: float = 0.7, seed: int = 0) -> None:
        rng = np.random.default_rng(seed)
        self.n = n
        self.moving = rng.random(n) < moving_share
        self.base = rng.uniform(0.3, 1.2, (n, 50)) * np.where(np.arange(50) == 2, 0.02, 1.0)  # 2: spine slide
        self.amp = rng.uniform(0.02, 0.5, (n, 50)) * np.where(np.arange(50) == 2, 0.02, 1.0)
        self.phase = rng.uniform(0, 2 * np.pi, (n, 50))
        self.root = np.array([0.0, 0.0, 1.0]), np.array([0.1, 0.3, 1.2])  # soldier, rifle (m, local)

    def pose(self, tick: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.where(self.moving, tick / HZ, 0.0)[:, None]
        dofs = self.base + self.amp * np.sin(2 * np.pi * t + self.phase)
        bob = 0.02 * np.sin(4 * np.pi * t[:, 0])
        pos = np.empty((self.n, 2, 3))
        pos[:, 0] = self.root[0]
        pos[:, 1] = self.root[1]
        pos[:, :, 2] += bob[:, None]
        yaw = np.radians(5.0) * np.sin(2 * np.pi * t[:, 0])
        quat = np.zeros((self.n, 2, 4))
        quat[:, :, 0] = np.cos(yaw / 2)[:, None]
        quat[:, :, 3] = np.sin(yaw / 2)[:, None]
        return dofs, pos, quat


def run(ticks: int, protocol: int = PROTOCOL_VERSION) -> dict[str, object]:
    table = example_di_table()
    crowd = Crowd(N)
    idx = np.arange(N)
    enc, dec = UpdateEncoder(table, N, version=protocol), UpdateDecoder(table, N, version=protocol)

    full = enc.encode(JointUpdates(1, idx, *crowd.pose(0)), BIG)
    for p in full:
        dec.decode(p)
    full_bytes = sum(len(p) for p in full)

    enc_us, dec_us, enc_wall, dec_wall, moving_bytes, quant_us = [], [], [], [], [], []
    poses = [crowd.pose(k) for k in range(1, ticks + 1)]
    for k, pose in enumerate(poses, 1):
        c0, t0 = time.process_time(), time.perf_counter()
        payloads = enc.encode(JointUpdates(1, idx, *pose, tick=k), BIG)
        c1, t1 = time.process_time(), time.perf_counter()
        for p in payloads:
            dec.decode(p)
        c2, t2 = time.process_time(), time.perf_counter()
        enc_us.append((c1 - c0) * 1e6)
        dec_us.append((c2 - c1) * 1e6)
        enc_wall.append((t1 - t0) * 1e6)
        dec_wall.append((t2 - t1) * 1e6)
        moving_bytes.append(sum(len(p) for p in payloads))
        c3 = time.process_time()
        quantise(table, *pose)  # the share of encode a server could do once per tick for all clients
        quant_us.append((time.process_time() - c3) * 1e6)
    exact = bool(np.array_equal(dec.codes(idx), enc.codes(idx)))

    idle_only = np.flatnonzero(~crowd.moving)
    last = poses[-1]
    idle_payloads = enc.encode(JointUpdates(1, idle_only, *(a[idle_only] for a in last), tick=ticks + 1), BIG)
    idle_bytes = sum(len(p) for p in idle_payloads)

    conn_us = connection_round_trip(table, crowd, ticks=max(3, ticks // 4))
    nmov = int(crowd.moving.sum())
    return {
        "soldiers": N,
        "moving": nmov,
        "ticks": ticks,
        "encode_us_per_batch": round(statistics.median(enc_us)),
        "decode_us_per_batch": round(statistics.median(dec_us)),
        "quantise_us_per_batch": round(statistics.median(quant_us)),
        "encode_decode_us_per_batch": round(statistics.median(np.add(enc_us, dec_us).tolist())),
        "encode_wall_us_per_batch": round(statistics.median(enc_wall)),
        "decode_wall_us_per_batch": round(statistics.median(dec_wall)),
        "connection_send_receive_us_per_batch": round(conn_us),
        "bytes_per_full_soldier": round((full_bytes - 8 * len(full)) / N, 2),
        "bytes_per_moving_soldier": round(statistics.median(moving_bytes) / nmov, 2),
        "bytes_per_idle_soldier": round(idle_bytes / max(len(idle_only), 1), 2),
        "legacy_bytes_per_full_soldier": 8 + 4 * packet_floats(table),
        "exact_reconstruction": exact,
    }


def front_case(
    encoders: int, soldiers: int, ticks: int, protocol: int = PROTOCOL_VERSION
) -> dict[str, object]:
    """A front-end's encode: ``encoders`` clients in different states, each sent its own crowd of
    ``soldiers`` (70 % moving, the rest idle) as codes already quantised (``encode_codes``, 65,535-byte
    payloads), every tick. Median process CPU per tick of all the encodes (after the full first tick)."""
    table = example_di_table()
    idx = np.arange(soldiers)
    crowds = [Crowd(soldiers, seed=s) for s in range(encoders)]
    codes = [[quantise(table, *c.pose(k)) for k in range(ticks + 1)] for c in crowds]
    encs = [UpdateEncoder(table, soldiers, version=protocol) for _ in range(encoders)]
    for enc, cs in zip(encs, codes, strict=True):
        enc.encode_codes(idx, cs[0], 0, 0xFFFF)
    per_tick = []
    for k in range(1, ticks + 1):
        c0 = time.process_time()
        for enc, cs in zip(encs, codes, strict=True):
            enc.encode_codes(idx, cs[k], k, 0xFFFF)
        per_tick.append((time.process_time() - c0) * 1e6)
    return {
        "front_encoders": encoders,
        "front_soldiers": soldiers,
        "front_encode_us_per_tick": round(statistics.median(per_tick)),
        "front_encode_us_per_tick_min": round(min(per_tick)),
    }


def connection_round_trip(table: object, crowd: Crowd, ticks: int) -> float:
    """Median µs for server.send(JointUpdates) + client.receive_data/next_event over the same batches."""
    client, server = Connection(CLIENT), Connection(SERVER, max_frame=1 << 22, max_soldiers=N)
    server.receive_data(client.send(Hello("bench", max_frame=1 << 22)))
    server.next_event()
    client.receive_data(server.send(Accept("jack", max_frame=1 << 22, max_soldiers=N)))
    client.next_event()
    client.receive_data(server.send(UpdateTableMsg(table)))
    client.next_event()
    server.receive_data(client.send(Subscribe(tuple(range(N)))))
    server.next_event()
    idx = np.arange(N)
    times = []
    for k in range(ticks + 1):
        pose = crowd.pose(k)
        t0 = time.process_time()
        client.receive_data(server.send(JointUpdates(1, idx, *pose, tick=k)))
        while isinstance(client.next_event(), JointUpdates):
            pass
        if k:  # tick 0 is the full update on subscription
            times.append((time.process_time() - t0) * 1e6)
    return statistics.median(times)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    ap.add_argument("--ticks", type=int, default=20)
    ap.add_argument("--protocol", type=int, default=PROTOCOL_VERSION, choices=(1, 2), help="update format")
    ap.add_argument("--front", type=int, default=0, metavar="K", help="also K encoders of their own crowds")
    ap.add_argument("--front-soldiers", type=int, default=8000, help="soldiers of each --front encoder")
    args = ap.parse_args()
    r = run(args.ticks, args.protocol)
    if args.front:
        r |= front_case(args.front, args.front_soldiers, args.ticks, args.protocol)
    if args.json:
        print(json.dumps(r))
        return 0
    print(f"joint updates, {r['soldiers']} soldiers per batch ({r['moving']} moving), DI.fig-shaped table")
    for kind, suffix in (("CPU", ""), ("wall", "_wall")):
        e, d = r[f"encode{suffix}_us_per_batch"], r[f"decode{suffix}_us_per_batch"]
        print(f"  encode {e:>8} µs/batch   decode {d:>8} µs/batch ({kind})")
    print(f"  of which quantise {r['quantise_us_per_batch']} µs/batch (shareable: encode_codes)")
    print(
        f"  encode+decode {r['encode_decode_us_per_batch']} µs/batch; via Connection pair "
        f"{r['connection_send_receive_us_per_batch']} µs/batch"
    )
    legacy = r["legacy_bytes_per_full_soldier"]
    print(f"  bytes per full soldier   {r['bytes_per_full_soldier']:>7}  (1994 layout: {legacy})")
    print(f"  bytes per moving soldier {r['bytes_per_moving_soldier']:>7}")
    print(f"  bytes per idle soldier   {r['bytes_per_idle_soldier']:>7}")
    print(f"  decoder reconstructs the encoder's codes exactly: {r['exact_reconstruction']}")
    if args.front:
        print(
            f"  front-end: {r['front_encoders']} encoders x {r['front_soldiers']} soldiers, encode "
            f"{r['front_encode_us_per_tick']} µs/tick (CPU, median; min {r['front_encode_us_per_tick_min']})"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
