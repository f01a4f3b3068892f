"""Benchmark: the browser image generator's frames per second (`ttes web`) at 100 and 1,000 soldiers.

Headless Chromium (/usr/bin/chromium) with WebGL on SwiftShader (CPU only: no GPU here), 800×600, driven by
puppeteer-core (tests/tools/drive_web.js; the npm folder of tests/npm_support.py). One `ttes web
--with-server` (the shipped data) serves every run; each run is a fresh page that takes N soldiers in a grid
(the start-up script's, then CREATE_SOLDIER), waits until every one is drawn from the wire, then counts the
frames its requestAnimationFrame loop renders for --seconds. `stand`: every soldier at rest (no joint updates
after the first); `walk`: every soldier walking at 1.4 m/s (a joint update per soldier per tick). The bird's
eye view shows the whole grid.

    python bench/bench_web.py [--soldiers 100,1000] [--motion stand,walk] [--seconds 5] [--shots DIR] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from bench.machine import Machine  # noqa: E402


def shot(folder: Path | None, n: int, motion: str) -> dict[str, str]:
    """drive_web.js's SHOT variable: where the run's screenshot goes (none without --shots)."""
    if folder is None:
        return {}
    folder.mkdir(parents=True, exist_ok=True)
    return {"SHOT": str(folder / f"web_{n}_{motion}.png")}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--soldiers", default="100,1000")
    ap.add_argument("--motion", default="stand,walk")
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--shots", type=Path, help="save a screenshot of each run in this folder")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    from npm_support import TOOLS, npm_dir

    where = npm_dir("puppeteer-core")
    chromium = os.environ.get("CHROMIUM", "/usr/bin/chromium")  # as drive_web.js and tests/test_web.py
    if where is None or not Path(chromium).is_file():
        print(f"bench_web: needs node, npm (puppeteer-core) and {chromium}", file=sys.stderr)
        return 1
    machine = Machine()
    cmd = [sys.executable, "-m", "ttes", "web", "--with-server", "--port", "0", "--json", "--seconds", "3600"]
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONUNBUFFERED": "1"}
    web = subprocess.Popen(
        cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True
    )
    runs = []
    try:
        assert web.stdout is not None
        url = json.loads(web.stdout.readline())["url"]
        for motion in args.motion.split(","):
            for n in (int(v) for v in args.soldiers.split(",")):
                page = f"{url}?soldiers={n}&motion={motion}&view=birds-eye&spacing=2"
                env = {**os.environ, "NODE_PATH": str(where / "node_modules"), **shot(args.shots, n, motion)}
                run = subprocess.run(
                    ["node", str(TOOLS / "drive_web.js"), "fps", page, str(args.seconds)],
                    env=env,
                    capture_output=True, text=True, timeout=900,
                )  # fmt: skip
                if run.returncode != 0:
                    print(run.stderr[-2000:], file=sys.stderr)
                    return 1
                got = json.loads(run.stdout)
                rate = round(got["updates_per_s"], 1)
                runs.append(
                    {"soldiers": n, "motion": motion, "fps": round(got["fps"], 2), "updates_per_s": rate}
                )
    finally:
        web.terminate()
        web.wait(timeout=30)
    out = {
        "renderer": "headless Chromium, WebGL on SwiftShader (CPU)",
        "size": "800x600",
        "runs": runs,
        **machine.facts(),
    }
    if args.json:
        print(json.dumps(out))
        return 0
    print(f"bench_web: {out['renderer']}, {out['size']}, {out['cpus']} CPUs, load {out['loadavg_before']}")
    for r in runs:
        print(
            f"  {r['soldiers']:>5} soldiers ({r['motion']}): {r['fps']} fps, "
            f"{r['updates_per_s']} JOINT_UPDATES frames/s"
        )
    print(f"  {out['wall_s']} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
