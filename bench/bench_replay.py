"""Replay benchmark: PDUs per second that `ttes replay --speed 0` (unlimited) gets through, 1,000 entities.

The log: `ttes dis synth`'s squad exercise with 1,000 soldiers (500 friendly, 500 opposing) and one parked
vehicle, 30 s, written as a pcap and read back (Entity State PDUs on change, drift and heartbeat, Fire and
Detonation PDUs). Three measurements, each over the whole log:

* ``read``: reading the pcap (``protocol.dis.read_log``), for scale;
* ``translate``: the replay core alone: ``Replayer`` at unlimited speed (cursor, entity table, dead-reckoning
  state, Fire reactions, requests), every translation thrown away;
* ``server``: the whole replay into a real Jack/TTES server (the synthetic motion library) over loopback
  TCP, in this process: CREATE_SOLDIER for each entity, ENTITY_REQUESTS batches, REMOVE_SOLDIER at the end,
  back-pressure from the socket; timed until a PING sent after the last request is answered, so the server
  has applied everything. The server ticks its 1,000 soldiers at 30 Hz meanwhile, on the same cores.

Run ``python bench/bench_replay.py`` (``--json`` for one JSON line; ``--entities N --seconds S``).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from client_stub.dis import Replayer
from protocol.dis import DisLog, read_log
from protocol.dis.synth import synthesize, write_pcap


def make_log(entities: int, seconds: float, tmp: Path) -> tuple[DisLog, float, float]:
    t = time.perf_counter()
    ex = synthesize(soldiers=entities, seconds=seconds, seed=1)
    path = tmp / "bench.pcap"
    write_pcap(path, ex)
    made = time.perf_counter() - t
    t = time.perf_counter()
    log = read_log(path)
    return log, made, time.perf_counter() - t


def bench_translate(log: DisLog, repeats: int = 3) -> tuple[float, dict]:
    best = math.inf
    status: dict = {}
    for _ in range(repeats):
        r = Replayer(log, speed=math.inf)
        t = time.perf_counter()
        while not r.finished:
            r.advance_chunk()
        r.finish()
        best = min(best, time.perf_counter() - t)
        status = r.status()
    return best, status


def bench_server(log: DisLog) -> tuple[float, dict]:
    import trio

    from client_stub.dis.drive import replay_to_server
    from client_stub.dis.sink import ServerSink
    from client_stub.link.client import Client
    from ttes.commands.replay import private_server

    async def main() -> tuple[float, dict]:
        async with private_server(None, synthetic=True) as server, trio.open_nursery() as nursery:
            link = Client("bench-replay")
            await link.open(nursery, *server.addresses[0])
            sink = ServerSink(link)
            replayer = Replayer(log, speed=math.inf)
            t = time.perf_counter()
            status = await replay_to_server(replayer, sink, drain=link.drain)
            ok = await link.roundtrip(60.0)
            elapsed = time.perf_counter() - t
            status.update(server_errors=len(link.errors), answered=ok)
            await link.aclose()
            return elapsed, status

    return trio.run(main)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--entities", type=int, default=1000)
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--no-server", action="store_true", help="skip the end-to-end measurement")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        log, made_s, read_s = make_log(args.entities, args.seconds, Path(tmp))
    pdus = int(log.counters["pdus"])
    translate_s, status = bench_translate(log)
    result: dict = {
        "entities": args.entities,
        "log_seconds": args.seconds,
        "pdus": pdus,
        "entity_states": int(log.counters["lifeforms"]),
        "fire_detonation": int(log.counters["fire"] + log.counters["detonation"]),
        "synth_s": round(made_s, 3),
        "read_s": round(read_s, 3),
        "read_pdus_per_s": round(pdus / read_s),
        "translate_s": round(translate_s, 4),
        "translate_pdus_per_s": round(pdus / translate_s),
        "soldiers_created": status["created"],
        "requests": status["requests"],
    }
    if not args.no_server:
        server_s, st = bench_server(log)
        result.update(
            server_s=round(server_s, 3),
            server_pdus_per_s=round(pdus / server_s),
            server_requests_sent=st["sink_requests"],
            server_errors=st["server_errors"],
            server_answered=st["answered"],
        )
    if args.json:
        print(json.dumps(result))
    else:
        print(
            f"replay benchmark: {args.entities} entities, {args.seconds:g} s synthetic exercise, "
            f"{pdus} PDUs ({result['entity_states']} lifeform entity states, "
            f"{result['fire_detonation']} fire/detonation)"
        )
        print(f"  read pcap:            {read_s:7.3f} s  {result['read_pdus_per_s']:>10,} PDU/s")
        print(
            f"  translate (no I/O):   {translate_s:7.3f} s  {result['translate_pdus_per_s']:>10,} PDU/s "
            f"({status['created']} soldiers, {status['requests']} requests)"
        )
        if not args.no_server:
            print(
                f"  into a real server:   {result['server_s']:7.3f} s  "
                f"{result['server_pdus_per_s']:>10,} PDU/s ({result['server_requests_sent']} request rows, "
                f"{result['server_errors']} errors)"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
