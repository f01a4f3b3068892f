"""Benchmark the server's hot path: vectorised clip sampling for many soldiers at once.

A synthetic library of 40 clips (~100 frames each at 60 fps) for a 50-DOF soldier plus a rifle; every call
samples 10,000 soldiers, each at its own clip, start time, direction and duration. Also times the channelset
text parser, the writer and the .npz cache on clips of the same size (the start-up costs).

    python bench/bench_sampling.py [--json] [--soldiers N]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from server.motion.cache import load_channelset
from server.motion.channelset_file import format_channelset, parse_channelsets, save_channelset
from server.motion.sampling import ClipLibrary, LibrarySample
from server.motion.synthetic import make_soldier, synthetic_channelset, toy_rifle


def rate(fn, min_time: float = 1.0) -> tuple[float, int]:  # type: ignore[no-untyped-def]
    """Seconds per call (best of batches) and calls made."""
    fn()
    calls, best, start = 0, float("inf"), time.perf_counter()
    while time.perf_counter() - start < min_time:
        t0 = time.perf_counter()
        for _ in range(5):
            fn()
        best = min(best, (time.perf_counter() - t0) / 5)
        calls += 5
    return best, calls


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--soldiers", type=int, default=10_000)
    ap.add_argument("--clips", type=int, default=40)
    args = ap.parse_args()

    soldier, rifle = make_soldier(ndof=50), toy_rifle()
    rng = np.random.default_rng(0)
    clips = [
        synthetic_channelset(f"clip{i}", [soldier, rifle], int(rng.integers(80, 121)), 60.0, seed=i)
        for i in range(args.clips)
    ]
    lib = ClipLibrary([soldier, rifle])
    lib.extend(clips)

    n = args.soldiers
    clip_id = rng.integers(0, lib.nclips, n)
    start = rng.uniform(0.0, 2.0, n)
    direction = rng.choice(np.array([-1, 1], np.int8), n)
    duration = np.where(rng.random(n) < 0.5, -1.0, rng.uniform(0.5, 3.0, n))
    out = LibrarySample.empty(n, lib.ndof, lib.nfig)
    clock = [2.0]

    def tick(interpolate: bool) -> None:
        clock[0] += 1 / 60
        lib.sample(clip_id, start, direction, duration, clock[0], out, interpolate=interpolate)

    t_interp, _ = rate(lambda: tick(True))
    t_exact, _ = rate(lambda: tick(False))

    # start-up costs on one ~100-frame clip: text parse / write, and the cache of the whole library
    text = format_channelset(clips[0])
    lines = text.count("\n")
    t_parse, _ = rate(lambda: parse_channelsets(text, "bench.chset.env"), 0.5)
    t_format, _ = rate(lambda: format_channelset(clips[0]), 0.5)
    with tempfile.TemporaryDirectory() as tmp:
        paths = []
        for cs in clips:
            p = Path(tmp) / f"{cs.name}.chset.env"
            save_channelset(cs, p)
            paths.append(p)
        t0 = time.perf_counter()
        for p in paths:
            load_channelset(p)  # parses and writes the caches
        t_first = time.perf_counter() - t0
        t_cached, _ = rate(lambda: [load_channelset(p) for p in paths], 0.5)

    result = {
        "soldiers": n,
        "dofs": lib.ndof,
        "figures": lib.nfig,
        "clips": lib.nclips,
        "library_frames": int(lib.clip_nframes.sum()),
        "library_bytes": lib.nbytes,
        "interp_calls_per_s": round(1 / t_interp, 1),
        "interp_us_per_call": round(t_interp * 1e6, 1),
        "interp_ns_per_soldier": round(t_interp * 1e9 / n, 1),
        "exact_calls_per_s": round(1 / t_exact, 1),
        "exact_us_per_call": round(t_exact * 1e6, 1),
        "exact_ns_per_soldier": round(t_exact * 1e9 / n, 1),
        "parse_lines_per_s": round(lines / t_parse),
        "parse_ms_per_clip": round(t_parse * 1e3, 2),
        "format_ms_per_clip": round(t_format * 1e3, 2),
        "library_first_load_s": round(t_first, 3),
        "library_cached_load_ms": round(t_cached * 1e3, 2),
    }
    if args.json:
        print(json.dumps(result))
        return 0
    shape = f"{n} soldiers x {lib.ndof} DOFs + {lib.nfig} figure channels"
    print(f"vectorised sampling: {shape}, {lib.nclips} clips")
    for key, label in (("interp", "interpolated"), ("exact", "exact frame ")):
        print(
            f"  {label}: {result[f'{key}_calls_per_s']:>8} calls/s  "
            f"{result[f'{key}_us_per_call']:>9} us/call  ({result[f'{key}_ns_per_soldier']} ns/soldier)"
        )
    print(
        f"channelset text: parse {result['parse_lines_per_s']} lines/s ({result['parse_ms_per_clip']} ms per "
        f"{lines}-line clip), write {result['format_ms_per_clip']} ms"
    )
    print(
        f"library of {lib.nclips} clips: first load (parse + cache) {result['library_first_load_s']} s, "
        f"from cache {result['library_cached_load_ms']} ms"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
