"""DIS benchmark: batch decoding of 100k Entity State PDUs vs open-dis-python, dead reckoning of 10k entities.

* ``decode only`` (the like-for-like comparison): ``decode_entity_states(buf, offsets)`` with the PDU
  boundaries known (validation on), against ``opendis.PduFactory.createPdu`` called once per PDU on a
  subset of the same PDUs (each given its own byte string, as it needs), extrapolated to PDUs/s.
* ``pipeline``: ``read_bytes(stream, fmt="raw")``: the whole log reader on 100k PDUs concatenated with no
  framing: find the boundaries by walking length fields (vectorised runs where lengths repeat, a plain
  loop where they vary), validate, decode, lifeform filter, PDU index, timestamps. open-dis has no
  equivalent; the ratio is still printed against its per-PDU decode.
* Two mixes: all 144-byte PDUs, and PDUs with 0..3 articulation records (variable lengths).
* Dead reckoning: ``dead_reckon`` over 10k entities with random algorithms 1..9.
* Capture: reading a 100k-packet pcap (dpkt container + vectorised Ethernet/IP/UDP parse + decode).

Run ``python bench/bench_dis.py`` (``--json`` for one JSON line). open-dis-python is installed by
``make bench`` (``pip install --no-deps opendis==1.0``); without it the baseline is reported as null.
"""

from __future__ import annotations

import argparse
import io
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from protocol.dis import dead_reckon, decode_entity_states, encode_appearance, read_bytes
from protocol.dis.batch import ESPDU_DTYPE, VARIABLE_PARAMETER_DTYPE, EntityStateBatch, encode_entity_states
from protocol.dis.geo import LocalFrame

N = 100_000
BASELINE_SUBSET = 3_000


def make_stream(n: int, max_params: int, seed: int = 0) -> tuple[bytes, np.ndarray]:
    """n lifeform ESPDUs (DIS 7) around Quantico; returns the bytes and the PDU offsets."""
    rng = np.random.default_rng(seed)
    recs = np.zeros(n, ESPDU_DTYPE)
    recs["version"], recs["exercise"], recs["family"] = 7, 1, 1
    recs["entity_id"]["site"], recs["entity_id"]["application"] = 1, 1
    recs["entity_id"]["entity"] = rng.integers(1, 500, n)
    recs["force_id"] = rng.integers(1, 3, n)
    recs["entity_type"] = (3, 1, 225, 1, 27, 0, 0)
    frame = LocalFrame(38.52, -77.44, 60.0)
    recs["location"] = frame.to_ecef(np.c_[rng.uniform(-500, 500, (n, 2)), np.zeros(n)])
    recs["velocity"] = rng.normal(0, 1.5, (n, 3))
    recs["orientation"] = rng.uniform(-3, 3, (n, 3))
    recs["appearance"] = encode_appearance(state=rng.integers(1, 7, n), weapon1=rng.integers(0, 4, n))
    recs["dr_algorithm"] = 2
    recs["marking_charset"] = 1
    recs["marking"] = b"SOLDIER"
    counts = rng.integers(0, max_params + 1, n) if max_params else np.zeros(n, np.int64)
    start = np.zeros(n + 1, np.int64)
    np.cumsum(counts, out=start[1:])
    params = np.zeros(int(start[-1]), VARIABLE_PARAMETER_DTYPE)
    params["parameter_type"] = 4096 + rng.integers(0, 64, params.shape[0])
    params["value"] = rng.normal(size=params.shape[0])
    data = encode_entity_states(EntityStateBatch(recs, params, start))
    lengths = 144 + 16 * counts
    offsets = np.zeros(n, np.int64)
    np.cumsum(lengths[:-1], out=offsets[1:])
    return data, offsets


def best_of(fn, repeat: int = 3) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def bench_mix(name: str, max_params: int) -> dict[str, object]:
    data, offsets = make_stream(N, max_params)
    log = read_bytes(data, fmt="raw")
    assert len(log.batch) == N and not log.issues
    t_pipeline = best_of(lambda: read_bytes(data, fmt="raw"), repeat=5)
    t_decode = best_of(lambda: decode_entity_states(data, offsets), repeat=5)
    result: dict[str, object] = {
        "mix": name,
        "pdus": N,
        "bytes": len(data),
        "ours_pipeline_s": round(t_pipeline, 4),
        "ours_pipeline_pdus_per_s": round(N / t_pipeline),
        "ours_decode_only_s": round(t_decode, 4),
        "ours_decode_only_pdus_per_s": round(N / t_decode),
    }
    try:
        from opendis.PduFactory import createPdu
    except ImportError:
        result.update(opendis_pdus_per_s=None, speedup_pipeline=None, speedup_decode_only=None)
        return result
    ends = np.append(offsets[1:], len(data))
    pieces = [
        data[o:e]
        for o, e in zip(offsets[:BASELINE_SUBSET].tolist(), ends[:BASELINE_SUBSET].tolist(), strict=True)
    ]
    first = createPdu(pieces[0])
    assert first is not None and first.entityID.entityID == int(log.batch.records["entity_id"]["entity"][0])

    def baseline() -> None:
        for p in pieces:
            createPdu(p)

    t_base = best_of(baseline, repeat=3) / len(pieces)
    result.update(
        opendis_subset=len(pieces),
        opendis_us_per_pdu=round(t_base * 1e6, 2),
        opendis_pdus_per_s=round(1.0 / t_base),
        opendis_extrapolated_s=round(t_base * N, 2),
        speedup_pipeline=round(t_base * N / t_pipeline, 1),
        speedup_decode_only=round(t_base * N / t_decode, 1),
    )
    return result


def bench_dr(n: int = 10_000) -> dict[str, object]:
    rng = np.random.default_rng(3)
    alg = rng.integers(1, 10, n)
    p, v, a, w, o = (rng.normal(size=(n, 3)) * s for s in (1e6, 3.0, 0.5, 0.4, 1.0))
    t = best_of(lambda: dead_reckon(alg, p, v, a, w, o, 0.5), repeat=5)
    return {"entities": n, "seconds": round(t, 5), "entities_per_s": round(n / t)}


def bench_pcap(n: int = N) -> dict[str, object]:
    import dpkt

    from protocol.dis.synth import udp_frame

    data, offsets = make_stream(n, 0, seed=4)
    frame0 = udp_frame(data[:144], 0)
    head = frame0[: len(frame0) - 144]  # identical headers: reuse them
    f = io.BytesIO()
    w = dpkt.pcap.Writer(f, linktype=dpkt.pcap.DLT_EN10MB)
    for k, o in enumerate(offsets.tolist()):
        w.writepkt(head + data[o : o + 144], ts=1000.0 + k * 1e-3)
    cap = f.getvalue()
    log = read_bytes(cap)
    assert len(log.batch) == n
    t = best_of(lambda: read_bytes(cap), repeat=2)
    return {"packets": n, "bytes": len(cap), "seconds": round(t, 4), "packets_per_s": round(n / t)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true", help="one JSON object on stdout")
    args = ap.parse_args()
    t0 = time.perf_counter()
    fixed = bench_mix("fixed_144", 0)
    mixed = bench_mix("articulations_0_3", 3)
    dr = bench_dr()
    pcap = bench_pcap()
    result = {"espdu_fixed": fixed, "espdu_mixed": mixed, "dead_reckoning": dr, "pcap": pcap,
              "total_s": round(time.perf_counter() - t0, 1)}  # fmt: skip
    if args.json:
        print(json.dumps(result))
        return 0
    for r in (fixed, mixed):
        print(
            f"ESPDU batch decode [{r['mix']}], {r['pdus']} PDUs: pipeline "
            f"{r['ours_pipeline_pdus_per_s']:,} PDU/s ({r['ours_pipeline_s']} s), "
            f"decode only {r['ours_decode_only_pdus_per_s']:,} PDU/s"
        )
        if r.get("opendis_pdus_per_s"):
            print(
                f"  open-dis-python: {r['opendis_pdus_per_s']:,} PDU/s ({r['opendis_us_per_pdu']} us/PDU on "
                f"{r['opendis_subset']}, ~{r['opendis_extrapolated_s']} s for {r['pdus']}) -> speed-up "
                f"{r['speedup_pipeline']}x (pipeline), {r['speedup_decode_only']}x (decode only)"
            )
        else:
            print("  open-dis-python not installed: no baseline")
    ms = dr["seconds"] * 1e3
    print(f"dead reckoning: {dr['entities']} entities in {ms:.2f} ms ({dr['entities_per_s']:,}/s)")
    print(
        f"pcap: {pcap['packets']} packets read in {pcap['seconds']} s ({pcap['packets_per_s']:,} packets/s)"
    )
    print(f"total {result['total_s']} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
