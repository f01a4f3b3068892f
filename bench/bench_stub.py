"""Benchmark the stub image generator: frames per second with 10, 100 and 1,000 soldiers (headless).

Each run places the soldiers on the village (a mix of standing, walking, running, kneeling and prone,
both forces, posed offline: no server), looks at them from a tethered-camera height, and times
``app.frame`` (simulation, dead reckoning, ground rays, scene-graph updates), ``app.draw`` (world matrices
into the instance buffers, labels) and the offscreen render (EGL; Mesa llvmpipe on a machine without a GPU)
with each renderer: ``gl`` (moderngl, what headless runs use) and ``pyrender`` (the window's). The CPU
time a frame (all threads, llvmpipe's included) is the cost that other work on the machine does not
inflate; CPU ms / CPUs is the frame time of an idle machine when llvmpipe keeps every CPU busy.

    python bench/bench_stub.py [--json] [--size 1280x720] [--counts 10,100,1000] [--budget 4]
                               [--renderers gl,pyrender]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from client_stub.stub.app import StubApp
from client_stub.stub.camera import look_at
from client_stub.stub.gl_render import GLStubRenderer, offscreen_renderer
from client_stub.stub.simsoldier import Behaviour, Force
from client_stub.stub.terrain import load_terrain
from protocol.entity import Appearance, WeaponState


def crowd(app: StubApp, n: int, rng: np.random.Generator) -> None:
    """``n`` soldiers on a grid south of the village centre, in every posture and gait."""
    side = int(np.ceil(np.sqrt(n)))
    spacing = 2.5
    for k in range(n):
        x = (k % side - side / 2) * spacing
        y = -20.0 - (k // side) * spacing
        mode = k % 6
        kw: dict = {"force": Force.OPPOSING if k % 2 else Force.FRIENDLY}
        if mode == 1:
            kw.update(speed=1.4, behaviour=Behaviour.CIRCLE, size=1.0)
        elif mode == 2:
            kw.update(speed=3.5, behaviour=Behaviour.CIRCLE, size=1.0)
        elif mode == 3:
            kw.update(appearance=Appearance.KNEEL, weapon=WeaponState.FIRING)
        elif mode == 4:
            kw.update(appearance=Appearance.PRONE, weapon=WeaponState.FIRING)
        elif mode == 5:
            kw.update(weapon=WeaponState.FIRING)
        app.add_soldier((x, y), float(rng.uniform(0, 360)), **kw)


def run(n: int, width: int, height: int, budget: float, backend: str = "gl") -> dict:
    terrain = load_terrain()
    app = StubApp(terrain, capacity=max(n, 16), max_soldiers=n + 1)
    crowd(app, n, np.random.default_rng(n))
    app.renderer = offscreen_renderer(width, height, backend)
    app.renderer.set_terrain(terrain.meshes)
    side = np.ceil(np.sqrt(n)) * 2.5
    target = np.array([0.0, -20.0 - side / 2, 0.0])
    eye = target + np.array([0.0, -max(12.0, 0.9 * side), max(6.0, 0.45 * side)])
    dt = 1 / 30
    app.frame(dt)
    app.draw()
    app.renderer.set_camera(look_at(eye, target))
    app.renderer.render()  # first frame uploads the meshes
    update = draw = render = 0.0
    frames = 0
    start = time.perf_counter()
    cpu = time.process_time()  # every thread of the process: ours and llvmpipe's
    while frames < 3 or (time.perf_counter() - start < budget and frames < 60):
        t0 = time.perf_counter()
        app.frame(dt)
        t1 = time.perf_counter()
        app.draw()
        app.renderer.set_camera(look_at(eye, target))
        t2 = time.perf_counter()
        app.renderer.render()
        t3 = time.perf_counter()
        update += t1 - t0
        draw += t2 - t1
        render += t3 - t2
        frames += 1
    total = update + draw + render
    cpu = time.process_time() - cpu
    renderer = gl_renderer(app.renderer)
    app.renderer.close()
    return {
        "renderer": backend,
        "soldiers": n,
        "frames": frames,
        "fps": round(frames / total, 2),
        "update_ms": round(1000 * update / frames, 2),
        "draw_ms": round(1000 * draw / frames, 2),
        "render_ms": round(1000 * render / frames, 2),
        "cpu_ms": round(1000 * cpu / frames, 2),
        "cpus": os.cpu_count(),
        "load": round(os.getloadavg()[0], 2),
        "gl_renderer": renderer,
    }


def gl_renderer(r: object) -> str:
    if isinstance(r, GLStubRenderer):
        return str(r.ctx.info.get("GL_RENDERER", "unknown"))
    try:
        r._offscreen._platform.make_current()  # type: ignore[attr-defined]
        from OpenGL.GL import GL_RENDERER, glGetString

        value = glGetString(GL_RENDERER)
        return value.decode() if isinstance(value, bytes) else str(value)
    except Exception:  # no current context: not essential to the numbers
        return "unknown"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--size", default="1280x720", help="the goal's size (issue 19: 100 soldiers >= 20 fps)")
    ap.add_argument("--counts", default="10,100,1000")
    ap.add_argument("--budget", type=float, default=4.0, help="seconds of frames per soldier count")
    ap.add_argument("--renderers", default="gl,pyrender", help="back ends to time (gl, pyrender)")
    args = ap.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    results = [
        run(int(n), width, height, args.budget, backend)
        for backend in args.renderers.split(",")
        for n in args.counts.split(",")
    ]
    out = {"benchmark": "stub", "size": [width, height], "results": results}
    if args.json:
        print(json.dumps(out))
    else:
        print(f"ttes stub, {width}x{height}, offline poses, village terrain")
        for r in results:
            print(
                f"  {r['renderer']:>8} {r['soldiers']:>5} soldiers: {r['fps']:7.2f} fps  "
                f"(update {r['update_ms']:.1f} ms, "
                f"draw {r['draw_ms']:.1f} ms, render {r['render_ms']:.1f} ms; "
                f"CPU {r['cpu_ms']:.1f} ms a frame on {r['cpus']} CPUs, load {r['load']})"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
