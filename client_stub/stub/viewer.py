"""The interactive window (1994: ``pickfly``'s window; here pyglet + pyrender's on-screen renderer).

Characters arrive through ``on_text`` (so ``A`` and ``a``, ``?`` work with any keyboard layout), the arrows
through ``on_key_press``; both go to :meth:`StubApp.handle_key`, whose messages are printed to the console,
as the seed's ``?`` list is. The simulation steps on a pyglet clock; drawing uploads the instance poses,
renders the scene and blends the overlay (labels, caption, the keys while ``?`` shows them) over it.
Escape closes the window.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from client_stub.stub.app import StubApp

ARROWS = {"LEFT": "LEFT", "RIGHT": "RIGHT", "UP": "UP", "DOWN": "DOWN"}


def make_window(app: StubApp, width: int = 800, height: int = 600, fps: float = 30.0, visible: bool = True):
    """Create the window and schedule the simulation; call ``pyglet.app.run()`` to start."""
    import pyglet
    import pyrender
    from pyglet.window import key as keys

    from client_stub.stub.render import StubRenderer

    stub_renderer = app.renderer
    if not isinstance(stub_renderer, StubRenderer):
        raise RuntimeError("the window draws with the pyrender StubRenderer")
    # pyglet.gl.Config is the platform's concrete class at run time; mypy sees the abstract base that
    # pyglet's first (documentation-build) import branch names.
    configs = [
        pyglet.gl.Config(sample_buffers=1, samples=4, depth_size=24, double_buffer=True,  # type: ignore[abstract]
                         major_version=4, minor_version=1, forward_compatible=True),
        pyglet.gl.Config(depth_size=24, double_buffer=True, major_version=4, minor_version=1,  # type: ignore[abstract]
                         forward_compatible=True),
    ]  # fmt: skip
    window = None
    for config in configs:
        try:
            window = pyglet.window.Window(
                width, height, config=config, resizable=True, caption="ttes-stub", visible=visible
            )
            break
        except (pyglet.window.NoSuchConfigException, pyglet.gl.ContextException):
            continue
    if window is None:
        raise RuntimeError("no OpenGL 4.1 window available")
    renderer = pyrender.Renderer(width, height)
    scene = stub_renderer.scene

    @window.event
    def on_resize(w: int, h: int) -> None:
        fw, fh = window.get_framebuffer_size()
        renderer.viewport_width, renderer.viewport_height = fw, fh
        stub_renderer.camera.aspectRatio = fw / max(fh, 1)

    @window.event
    def on_draw() -> None:
        window.clear()
        stub_renderer.upload()
        renderer.render(scene, pyrender.RenderFlags.NONE)
        _draw_overlay(stub_renderer, window)

    @window.event
    def on_text(text: str) -> None:
        for ch in text:
            _report(app.handle_key(ch))

    @window.event
    def on_key_press(symbol: int, modifiers: int) -> bool | None:
        name = {keys.LEFT: "LEFT", keys.RIGHT: "RIGHT", keys.UP: "UP", keys.DOWN: "DOWN"}.get(symbol)
        if name is not None:
            _report(app.handle_key(name))
            return True
        if symbol == keys.ESCAPE:
            window.close()
            return True
        return None

    @window.event
    def on_close() -> None:
        pyglet.clock.unschedule(tick)
        renderer.delete()

    shown = [""]

    def tick(dt: float) -> None:
        app.frame(float(np.clip(dt, 0.0, 0.25)))
        app.draw()
        _show_server(app, window, shown)

    pyglet.clock.schedule_interval(tick, 1.0 / fps)
    app.frame(0.0)
    app.draw()
    return window


def _draw_overlay(stub_renderer: Any, window: Any) -> None:
    """The labels, caption and keys (``?``) over pyrender's picture: one premultiplied RGBA image blitted
    with blending (pyrender sets its own GL state again for the next frame)."""
    import pyglet
    from pyglet import gl

    from client_stub.stub.camera import viewproj

    overlay = stub_renderer.overlay
    if overlay is None:
        return
    w, h = window.get_framebuffer_size()
    pose = stub_renderer.scene.get_pose(stub_renderer.camera_node)
    rgba = overlay.rgba(w, h, viewproj(pose, stub_renderer.yfov_deg, w / max(h, 1)))
    image = pyglet.image.ImageData(w, h, "RGBA", np.ascontiguousarray(rgba[::-1]).tobytes())
    gl.glDisable(gl.GL_DEPTH_TEST)
    gl.glEnable(gl.GL_BLEND)
    gl.glBlendFunc(gl.GL_ONE, gl.GL_ONE_MINUS_SRC_ALPHA)
    gl.glViewport(0, 0, w, h)
    window.projection = pyglet.math.Mat4.orthogonal_projection(0, w, 0, h, -1, 1)
    image.blit(0, 0)


def _show_server(app: StubApp, window: Any, shown: list[str]) -> None:
    """A lost server shows in the caption (and the console) at the next frame; giving up closes the window."""
    news = app.gave_up or app.server_lost
    if news != shown[0]:
        _report(news or "server back")
        window.set_caption(f"ttes-stub: {news.upper()}" if news else "ttes-stub")
        shown[0] = news
    if app.gave_up:
        window.close()


def _report(message: str | None) -> None:
    if message:
        print(message, flush=True)


def run_viewer(app: StubApp, width: int = 800, height: int = 600, fps: float = 30.0) -> None:
    """Open the window and run until it is closed."""
    import pyglet

    make_window(app, width, height, fps)
    print("ttes-stub: press ? for the keys, Escape to quit", flush=True)
    pyglet.app.run()
