"""The interactive window, driven without a display (pyglet's headless EGL mode, in a child process)."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

SCRIPT = textwrap.dedent(
    """
    import json, os, sys
    os.environ["PYOPENGL_PLATFORM"] = "egl"
    import numpy as np
    import pyglet
    pyglet.options["headless"] = True
    from pyglet.window import key
    from client_stub.stub.app import StubApp
    from client_stub.stub.live import populate_demo
    from client_stub.stub.render import StubRenderer
    from client_stub.stub.terrain import load_terrain
    from client_stub.stub.viewer import make_window

    terrain = load_terrain()
    app = StubApp(terrain, artic_dir=sys.argv[1])
    populate_demo(app)
    app.renderer = StubRenderer(160, 120, offscreen=False)
    app.renderer.set_terrain(terrain.meshes)
    win = make_window(app, 160, 120, visible=False)
    for ch in "c3":
        win.dispatch_event("on_text", ch)
    win.dispatch_event("on_key_press", key.UP, 0)
    win.dispatch_event("on_key_press", key.RIGHT, 0)
    win.dispatch_events()
    app.frame(0.5)
    app.draw()
    win.switch_to()
    win.dispatch_event("on_draw")
    win.dispatch_events()
    buf = pyglet.image.get_buffer_manager().get_color_buffer().get_image_data()
    img = np.frombuffer(buf.get_data("RGB", buf.width * 3), np.uint8).reshape(buf.height, buf.width, 3)
    r, g, b = (img[..., k].astype(int) for k in range(3))
    olive = (g >= r - 6) & (g - b >= 10) & (r - b >= 5)
    caption_text = int((img[-14:, :100].min(axis=2) > 200).sum())  # the caption, top left (rows bottom-up)
    win.dispatch_event("on_text", "?")
    win.dispatch_events()
    app.draw()  # the window's clock tick draws the app: the overlay now holds the keys
    win.dispatch_event("on_draw")
    win.dispatch_events()
    buf = pyglet.image.get_buffer_manager().get_color_buffer().get_image_data()
    keys = np.frombuffer(buf.get_data("RGB", buf.width * 3), np.uint8).reshape(buf.height, buf.width, 3)
    help_dark = float(keys[20:90, 5:150].mean() - img[20:90, 5:150].mean())
    win.dispatch_event("on_key_press", key.ESCAPE, 0)
    win.dispatch_events()
    print(json.dumps({"appearance": int(app.soldiers.appearance[0]), "speed": float(app.soldiers.speed[0]),
                      "heading": float(app.soldiers.heading[0]), "view": app.camera.view.value,
                      "olive_centre": int(olive[30:110, 40:120].sum()), "std": float(img.std()),
                      "caption_text": caption_text, "help_dark": help_dark}))
    """
)


def test_window_keys_drive_the_soldier_and_draw_him(tmp_path: Path) -> None:
    proc = subprocess.run(
        [sys.executable, "-c", SCRIPT, str(tmp_path)], cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    if proc.returncode != 0 or not lines:
        if "headless" in proc.stderr or "EGL" in proc.stderr:
            pytest.skip(f"no headless pyglet window here: {proc.stderr.strip().splitlines()[-1:]}")
        raise AssertionError(proc.stderr[-3000:])
    result = json.loads(lines[-1])
    assert result["appearance"] == 3 and result["speed"] == 0.5 and result["heading"] == 10.0
    assert result["view"] == "SOLDIER CAM"
    assert result["std"] > 5 and result["olive_centre"] > 20  # the tethered camera shows soldier 0
    assert "soldier 0: KNEEL" in proc.stdout  # key messages go to the console, as the seed's do
    assert result["caption_text"] > 20  # the overlay's caption over pyrender's picture
    assert result["help_dark"] < -15  # '?' lays the keys' dark box over the picture
