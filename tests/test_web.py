"""`ttes web`, the browser image generator: the HTTP side serves the page and nothing else, and the page, in
a real headless Chromium (SwiftShader WebGL) against a real server's WebSocket port, draws a soldier from the
wire and shows the posture a key asks for (screenshots: soldier-blue pixels where he stands, a standing
silhouette taller than wide, a prone one wider than tall). Skipped without chromium, node or puppeteer-core
(tests/tools/package.json, installed outside the checkout); the screenshots stay in the test's tmp folder."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import trio
import trio.testing
from npm_support import TOOLS, npm_dir

from client_stub.link.spawn import free_port
from client_stub.web.site import Site
from client_stub.web.vendor import vendored

REPO = Path(__file__).resolve().parents[1]
CHROMIUM = os.environ.get("CHROMIUM", "/usr/bin/chromium")


def test_the_site_serves_the_page_its_data_and_config_only() -> None:
    site = Site({"ws": "ws://127.0.0.1:7001/", "soldiers": 3})
    status, kind, body = site.body("/")
    assert status == 200 and kind.startswith("text/html") and b'src="js/app.js"' in body
    assert site.body("/js/wire.js")[1].startswith("text/javascript")
    assert json.loads(site.body("/config.json?x=1")[2]) == {"ws": "ws://127.0.0.1:7001/", "soldiers": 3}
    assert site.body("/data/village.glb")[2][:4] == b"glTF"
    assert json.loads(site.body("/data/village.json")[2])["office"]
    for bad in ("/../setup.py", "/js/../../setup.py", "/site.py", "/vendor.py", "/data/DI.tips", "/.git/HEAD",
                "/js/.hidden.js", "/package.json", "/data/../site.py"):  # fmt: skip
        assert site.body(bad)[0] == 404, bad


async def _http(site: Site, request: bytes) -> bytes:
    ours, theirs = trio.testing.memory_stream_pair()
    async with trio.open_nursery() as n:
        n.start_soon(site.serve_client, ours)
        await theirs.send_all(request)
        got = bytearray()
        while chunk := await theirs.receive_some(1 << 20):
            got += chunk
            if request.startswith(b"HEAD") or b"Connection: close" in request:
                continue
        return bytes(got)


async def test_http_get_head_keep_alive_and_refusals() -> None:
    site = Site({"ws": "ws://x/"})
    two = (
        b"GET /config.json HTTP/1.1\r\nHost: a\r\n\r\nHEAD / HTTP/1.1\r\nHost: a\r\nConnection: close\r\n\r\n"
    )
    got = await _http(site, two)
    assert got.count(b"HTTP/1.1 200") == 2 and b'{"ws": "ws://x/"}' in got and b"<html" not in got
    got = await _http(site, b"POST / HTTP/1.1\r\nHost: a\r\nContent-Length: 2\r\nConnection: close\r\n\r\nhi")
    assert got.startswith(b"HTTP/1.1 405")
    assert (await _http(site, b"NONSENSE\r\n\r\n")) == b""  # not HTTP: closed
    assert site.requests == 3


VIEWPORT = (480, 360)  # the page's pixels: SwiftShader draws each on the CPU


def _skip_without_browser() -> Path:
    if not Path(CHROMIUM).is_file():
        pytest.skip(f"no chromium at {CHROMIUM}")
    if not vendored():
        pytest.skip("three.js is not vendored (make vendor)")
    where = npm_dir("puppeteer-core")
    if where is None:
        pytest.skip("node/npm or puppeteer-core is not available")
    return where


def _blue(png: Path) -> np.ndarray:
    """The soldier-blue pixels (the page draws soldiers 0x2f6fe0, lit) of a screenshot, as a boolean mask."""
    import imageio.v3 as iio

    rgb = iio.imread(png)[..., :3].astype(int)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return (b > 90) & (b > 1.8 * r) & (b > 1.3 * g)  # the sky (157, 184, 214) is not


def _extent(mask: np.ndarray) -> tuple[int, int]:
    ys, xs = np.nonzero(mask)
    return int(xs.max() - xs.min() + 1), int(ys.max() - ys.min() + 1)


@pytest.fixture(scope="module")
def browser() -> Iterator[dict[str, str]]:
    """One headless Chromium for the module's browser tests (each drives a page of it: a browser's start is
    not paid per test): the drivers' environment (NODE_PATH, BROWSER_WS, VIEWPORT)."""
    where = _skip_without_browser()
    env = {**os.environ, "NODE_PATH": str(where / "node_modules"), "CHROMIUM": CHROMIUM,
           "VIEWPORT": "{}x{}".format(*VIEWPORT)}  # fmt: skip
    cmd = ["node", str(TOOLS / "drive_web.js"), "browser"]
    proc = subprocess.Popen(cmd, env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    assert proc.stdin is not None and proc.stdout is not None
    try:
        endpoint = proc.stdout.readline().strip()
        assert endpoint.startswith("ws://"), endpoint
        yield {**env, "BROWSER_WS": endpoint}
    finally:
        proc.stdin.close()  # the browser closes
        proc.wait(timeout=60)


def _web_and_browser(
    web_args: list[str], drive_args: list[str], cwd: Path, browser: dict[str, str]
) -> tuple[dict[str, Any], dict[str, Any]]:
    """`ttes web WEB_ARGS --port 0 --json` in a process, tests/tools/drive_web.js MODE URL ARGS... in
    a page of the module's headless Chromium against it: (the ready line, what the driver printed)."""
    cmd = [sys.executable, "-m", "ttes", "web", *web_args, "--port", "0", "--json"]
    env_web = {**os.environ, "PYTHONPATH": str(REPO), "PYTHONUNBUFFERED": "1"}
    web = subprocess.Popen(
        cmd, cwd=cwd, env=env_web, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True
    )
    try:
        assert web.stdout is not None
        ready = json.loads(web.stdout.readline())
        drive = subprocess.run(
            ["node", str(TOOLS / "drive_web.js"), drive_args[0], ready["url"], *drive_args[1:]],
            env=browser,
            capture_output=True, text=True, timeout=300,
        )  # fmt: skip
        assert drive.returncode == 0, drive.stderr[-3000:]
    finally:
        web.terminate()
        web.wait(timeout=30)
    return ready, json.loads(drive.stdout)


@pytest.mark.browser
def test_the_page_draws_a_soldier_and_key_4_lays_him_prone(tmp_path: Path, browser: dict[str, str]) -> None:
    web = ["--with-server", "--soldiers", "1"]
    ready, got = _web_and_browser(web, ["keys", str(tmp_path)], tmp_path, browser)
    assert ready["event"] == "ready" and ready["server"].startswith("ws://127.0.0.1:")
    before, after = got["before"], got["after"]
    assert before["version"] == 2 and before["role"] == "controller" and not before["errors"], before
    assert before["soldiers"][0]["force"] == 1 and before["soldiers"][0]["colour"] == 0x2F6FE0  # friendly
    assert before["soldiers"][0]["rootZ"] > 0.8 and after["soldiers"][0]["rootZ"] < 0.4
    assert after["soldiers"][0]["appearance"] == 4 and not after["errors"]
    standing, prone = _blue(tmp_path / "standing.png"), _blue(tmp_path / "prone.png")
    x0, y0, x1, y1 = (int(v) for v in before["soldiers"][0]["box"])
    inside = standing[max(y0, 0) : y1 + 1, max(x0, 0) : x1 + 1].sum()
    assert inside > 300 and inside > 0.95 * standing.sum(), (inside, standing.sum())  # blue where he stands
    w, h = _extent(standing)
    assert h > 1.5 * w, (w, h)  # a standing soldier: taller than wide
    w2, h2 = _extent(prone)
    assert w2 / h2 > 2 * w / h and h2 < 0.8 * h, (w, h, w2, h2)  # lying: much wider for his height, lower
    assert (standing != prone).sum() > 300
    _assert_the_view_keys(got, prone, _blue(tmp_path / "action.png"))


def _assert_the_view_keys(got: dict[str, Any], prone: np.ndarray, action_shot: np.ndarray) -> None:
    """x: ACTION CAM frames the prone soldier (another picture, he fills more of it, every corner of his
    box inside it); f: fly from the stub's start (0, -60, 20); w: 5 m forward (north); v: the next view."""
    after, action, fly, forward = got["after"], got["action"], got["fly"], got["forward"]
    assert after["camera"]["view"] == "soldier" and action["camera"]["view"] == "action"
    assert np.linalg.norm(np.subtract(action["camera"]["position"], after["camera"]["position"])) > 1
    assert (action_shot != prone).sum() > 300
    assert action_shot.sum() > prone.sum(), (action_shot.sum(), prone.sum())
    x0, y0, x1, y1 = action["soldiers"][0]["box"]
    assert 0 <= x0 < x1 <= VIEWPORT[0] and 0 <= y0 < y1 <= VIEWPORT[1], action["soldiers"][0]["box"]
    assert fly["camera"]["view"] == "fly" and fly["camera"]["position"] == pytest.approx([0, -60, 20])
    assert forward["camera"]["position"] == pytest.approx([0, -55, 20])
    assert got["next"]["camera"]["view"] == "action"  # the stub's order: ..., fly, ACTION CAM
    firsts = [line.split()[0] for line in got["help"].splitlines()]  # ?: every key the stub has
    for keys in ("1", "5", "n", "a", "A", "u", "i", "o", "b", "x", "w", "q", "r", "←", "↑", "?"):
        assert keys in firsts, (keys, got["help"])


@pytest.mark.skipif(shutil.which("node") is None, reason="needs node")
def test_the_page_modules_parse() -> None:
    """Every ES module of the page is valid JavaScript (node --check), without a browser."""
    for js in sorted((REPO / "client_stub" / "web" / "js").glob("*.js")):
        cmd = ["node", "--check", "--input-type=module"]
        run = subprocess.run(cmd, input=js.read_text(), capture_output=True, text=True, timeout=30)
        assert run.returncode == 0, (js.name, run.stderr)


@pytest.mark.skipif(shutil.which("node") is None, reason="needs node")
@pytest.mark.parametrize("version", [1, 2])
def test_the_page_decodes_joint_updates_as_the_python_decoder(version: int, tmp_path: Path) -> None:
    """client_stub/web/js/wire.js (run by node; msgpack by the vendored @msgpack/msgpack) over the Python
    encoder's frames of the DI.fig-shaped table: the UPDATE_TABLE message, then JOINT_UPDATES of smooth
    motion, jumps, repeated and skipped ticks (v2's prediction), soldiers that come and go; the same codes as
    protocol.updates.UpdateDecoder, and the same decoded values. And the page's HELLO reads in Python."""
    from protocol.events import Hello, UpdateTableMsg
    from protocol.framing import FrameReader
    from protocol.messages import CODECS, MessageType
    from protocol.update_table import example_di_table
    from protocol.updates import UpdateDecoder, UpdateEncoder

    if not vendored():
        pytest.skip("msgpack is not vendored (make vendor)")
    table, n = example_di_table(), 6
    lay = table.layout
    rng = np.random.default_rng(version)
    enc, dec = UpdateEncoder(table, n, version=version), UpdateDecoder(table, n, version=version)
    codes = rng.integers(0, lay.max_code + 1, (n, lay.nfields)).astype(np.int64)
    vel = rng.integers(-20, 21, codes.shape)
    payloads, tick = [], 7
    for step in range(40):
        tick += (1, 1, 0, 3)[step % 4]
        vel += rng.integers(-2, 3, vel.shape)
        jump = (rng.random(codes.shape) < 0.02) * rng.integers(-3000, 3000, codes.shape)
        codes = np.clip(codes + vel + jump, 0, lay.max_code)
        sent = np.sort(rng.choice(n, int(rng.integers(1, n + 1)), replace=False))
        for p in enc.encode_codes(sent, codes[sent].astype(np.int32), tick, 1 << 16):
            payloads.append(p.hex())
            dec.decode(p)
    update_table = CODECS[MessageType.UPDATE_TABLE][1](UpdateTableMsg(table)).hex()
    case = tmp_path / "case.json"
    case.write_text(json.dumps({"version": version, "update_table": update_table, "payloads": payloads}))
    run = subprocess.run(["node", str(TOOLS / "check_wire.mjs"), str(case)], capture_output=True, text=True,
                         timeout=60)  # fmt: skip
    assert run.returncode == 0, run.stderr
    out = json.loads(run.stdout)
    got = out["soldiers"]
    assert sorted(int(i) for i in got) == list(range(n))
    for i in range(n):
        assert got[str(i)]["codes"] == dec.codes(np.array([i]))[0].tolist()
        d, p, q = dec.current(np.array([i]))
        np.testing.assert_allclose(got[str(i)]["pose"]["dofs"], d[0], atol=1e-9)
        figs = got[str(i)]["pose"]["figures"]
        np.testing.assert_allclose([f["position"] for f in figs], p[0], atol=1e-9)
        js_q, py_q = np.array([f["quaternion"] for f in figs]), q[0]
        assert np.allclose(np.abs((js_q * py_q).sum(axis=1)), 1.0, atol=1e-9)  # the same rotation (±q)
    frames = FrameReader()
    frames.feed(bytes.fromhex(out["hello"]))
    kind, payload = frames.next_frame(1 << 24) or (0, b"")
    assert kind == MessageType.HELLO and frames.buffered == 0
    hello = CODECS[MessageType.HELLO][2](payload, 0)
    assert isinstance(hello, Hello)
    assert (hello.name, hello.role, hello.version, hello.token) == ("ttes-web", "observer", version, "sésame")
    assert hello.max_frame == 1 << 24


def test_entities_json_rows() -> None:
    from protocol.entity import make_entity_requests

    rows = make_entity_requests(
        index=[12, 3], appearance=[3, 2], weapon=[1, 0], velocity=[(1, 2, 0), (0, 0, 0)],
        heading=[90.0, 0.0], position=[(5.0, -2.0, 0.5), (0.0, 0.0, 0.0)],
    )  # fmt: skip
    site = Site(entities=lambda: (rows, np.array([2, 1], np.uint8)))
    got = json.loads(site.body("/entities.json")[2])
    assert got == {
        "soldiers": [[12, 5.0, -2.0, 0.5, 90.0, 1.0, 2.0, 0.0, 3, 1, 2], [3, 0, 0, 0, 0, 0, 0, 0, 2, 0, 1]]
    }
    assert Site().body("/entities.json")[0] == 404  # no replay: no such file


def _red(png: Path) -> np.ndarray:
    """The opposing-red pixels (the page's 0xa82a1a, lit) of a screenshot, as a boolean mask."""
    import imageio.v3 as iio

    rgb = iio.imread(png)[..., :3].astype(int)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return (r > 70) & (r > 2 * g) & (r > 2 * b)  # the ground (brown-grey) and the roofs are not


def _inside(mask: np.ndarray, box: list[float]) -> int:
    x0, y0, x1, y1 = (int(v) for v in box)
    return int(mask[max(y0, 0) : y1 + 1, max(x0, 0) : x1 + 1].sum())


HIDDEN_XY = (-30.0, -11.0)  # a street north of a house: from ACTION CAM's 200°, 35° its roof hides 3 soldiers


@pytest.mark.browser
def test_the_action_cam_rises_over_the_house_hiding_them(tmp_path: Path, browser: dict[str, str]) -> None:
    """x: soldiers standing behind a house (from ACTION CAM's compass 200°) are seen: the camera rises over
    its roof as the stub's does (client_stub/stub/camera.py clear_pose), each one's blue inside his box."""
    drive = ["hidden", str(tmp_path), "{},{}".format(*HIDDEN_XY)]
    _, got = _web_and_browser(["--with-server", "--soldiers", "3"], drive, tmp_path, browser)
    hidden = got["hidden"]
    assert hidden["camera"]["view"] == "action" and not hidden["errors"], hidden
    blue = _blue(tmp_path / "hidden.png")
    for s in hidden["soldiers"]:  # each framed and seen: without the rise the house covers the third
        x0, y0, x1, y1 = s["box"]
        assert 0 <= x0 < x1 <= VIEWPORT[0] and 0 <= y0 < y1 <= VIEWPORT[1], s["box"]
        assert _inside(blue, s["box"]) > 200, (_inside(blue, s["box"]), s["box"], hidden["camera"])


@pytest.mark.browser
def test_the_page_follows_a_dis_replay_coloured_by_force(tmp_path: Path, browser: dict[str, str]) -> None:
    """`ttes web --replay LOG`: the page, an observer, draws every soldier the replay drives, posed by the
    server's updates and placed where the log puts them (entities.json), each in his DIS force's colour as
    the stub does: a friendly soldier (force 1) blue, an opposing one (force 2) red, from his tethered
    camera (screenshots force-1.png, force-2.png)."""
    env = {**os.environ, "PYTHONPATH": str(REPO), "PYTHONUNBUFFERED": "1"}
    log = tmp_path / "squad.pcap"
    subprocess.run([sys.executable, "-m", "ttes", "dis", "synth", "--out", str(log), "--soldiers", "4",
                    "--seconds", "60"], env=env, check=True, capture_output=True, timeout=120)  # fmt: skip
    _, got = _web_and_browser(["--replay", str(log)], ["forces", str(tmp_path)], tmp_path, browser)
    assert got["soldiers"] == 4 and not got["errors"] and got["updates"] > 0, got
    forces = [s["force"] for s in got["shots"]["2"]["soldiers"]]
    assert sorted(set(forces)) == [1, 2], forces
    for force, mine, other in ((1, _blue, _red), (2, _red, _blue)):
        shot = got["shots"][str(force)]
        me = shot["soldiers"][shot["current"]]
        assert me["force"] == force and me["colour"] == {1: 0x2F6FE0, 2: 0xA82A1A}[force], me
        png = tmp_path / f"force-{force}.png"
        ours, theirs = _inside(mine(png), me["box"]), _inside(other(png), me["box"])
        assert ours > 300 and theirs < ours / 10, (force, ours, theirs)


def _start_server(port: int, ws_port: int, env: dict[str, str]) -> subprocess.Popen[str]:
    cmd = [sys.executable, "-m", "ttes", "server", "--json"]  # the real data: starts in half the time
    cmd += ["--port", str(port), "--ws-port", str(ws_port)]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    assert proc.stdout is not None
    assert json.loads(proc.stdout.readline())["websocket"] == [f"127.0.0.1:{ws_port}"]
    return proc


@pytest.mark.browser
def test_the_page_binds_its_soldiers_again_after_a_server_restart(browser: dict[str, str]) -> None:
    """The server goes away (SIGTERM: GOODBYE, close) and comes back on the same ports: the page retries with
    backoff, shakes hands again and binds its soldiers as they were (soldier 0 still asked to kneel)."""
    env = {**os.environ, "PYTHONPATH": str(REPO), "PYTHONUNBUFFERED": "1"}
    port, ws_port = free_port(), free_port()
    server = _start_server(port, ws_port, env)
    cmd = [
        sys.executable,
        "-m",
        "ttes",
        "web",
        "--port",
        "0",
        "--soldiers",
        "3",
        "--json",
        "--seconds",
        "600",
    ]
    cmd += ["--server", f"127.0.0.1:{ws_port}"]
    web = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    drive = None
    try:
        assert web.stdout is not None
        url = json.loads(web.stdout.readline())["url"]
        drive = subprocess.Popen(
            ["node", str(TOOLS / "drive_web.js"), "reconnect", url],
            env=browser,
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        assert drive.stdout is not None
        first = json.loads(drive.stdout.readline())
        assert first["phase"] == "restart the server", first
        server.terminate()
        server.wait(timeout=30)
        server = _start_server(port, ws_port, env)
        out, err = drive.communicate(timeout=300)
        assert drive.returncode == 0, err[-3000:]
    finally:
        for proc in (drive, web, server):
            if proc is not None and proc.poll() is None:
                proc.terminate()
                proc.wait(timeout=30)
    got = json.loads(out)
    assert got["lost"] >= 1 and got["after"]["version"] == 2 and not got["after"]["errors"], got
    soldiers = got["after"]["soldiers"]
    assert len(soldiers) == 3 and all(s["index"] >= 0 for s in soldiers)
    assert [s["appearance"] for s in soldiers] == [3, 2, 2]  # the kneel asked for before, asked for again
