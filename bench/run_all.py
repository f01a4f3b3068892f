"""Run every benchmark under bench/ and collect their JSON results.

Each ``bench/bench_*.py`` is a standalone script that prints one JSON object with ``--json``.
Results are printed and written to ``bench/results.json`` (not committed automatically: quote them in notes).
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main() -> int:
    results: dict[str, object] = {}
    failed = []
    for script in sorted(HERE.glob("bench_*.py")):
        name = script.stem.removeprefix("bench_")
        print(f"== {name}", flush=True)
        t0 = time.perf_counter()
        proc = subprocess.run(
            [sys.executable, str(script), "--json"], capture_output=True, text=True, cwd=HERE.parent
        )
        wall = time.perf_counter() - t0
        if proc.returncode != 0:
            failed.append(name)
            print(proc.stdout[-2000:], proc.stderr[-2000:], sep="\n")
            continue
        try:
            obj = json.loads(proc.stdout.strip().splitlines()[-1])
        except (json.JSONDecodeError, IndexError):
            failed.append(name)
            print(proc.stdout[-2000:])
            continue
        obj["wall_s"] = round(wall, 2)
        results[name] = obj
        print(json.dumps(obj, indent=2))
    (HERE / "results.json").write_text(json.dumps(results, indent=2) + "\n")
    if failed:
        print(f"failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
