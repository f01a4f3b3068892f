#!/usr/bin/env bash
# The wheel as a user gets it (issue 19): build it from the checkout's files, install it into a fresh venv
# outside the checkout, and run server, ping, headless stub, crowd and replay from an empty folder, the clients'
# dependencies installed from the image's lock as docker/Dockerfile does. Fails if the wheel lacks its data
# (the server's data dir must be the install's own copy, replay must not fall back to the synthetic library),
# if the server-only install pulls in GL, or if the lock misses a dependency. `make wheel-check`; .ci/run.
# WHEEL_CHECK_DIR=DIR keeps the work folder (default: a temporary one, removed at the end).
set -euo pipefail
REPO="$(cd "$(dirname "$0")/.." && pwd)"
PYTHON="${PYTHON:-python3}"
WORK="${WHEEL_CHECK_DIR:-$(mktemp -d /tmp/ttes-wheel-check.XXXXXX)}"
mkdir -p "$WORK"
PASSED=0
SERVER_PID=""
cleanup_server() { [[ -z "$SERVER_PID" ]] || { kill -INT "$SERVER_PID" 2>/dev/null || true; wait "$SERVER_PID" || true; }; }
cleanup() { cleanup_server; [[ -n "${WHEEL_CHECK_DIR:-}" ]] || rm -rf "$WORK"; }
trap cleanup EXIT
step() { echo "wheel-check: $*"; }
ok() { PASSED=$((PASSED + 1)); step "ok: $*"; }
fail() {
    step "FAILED: $*" >&2
    [[ -f "$WORK/run/server.log" ]] && tail -20 "$WORK/run/server.log" >&2
    echo "wheel-check: $PASSED passed, 1 failed"
    exit 1
}

# 1. the wheel, built from what a clean clone holds (tracked and untracked-not-ignored files, no build/ leftovers)
mkdir -p "$WORK/src" "$WORK/dist" "$WORK/run"
(cd "$REPO" && git ls-files -z --cached --others --exclude-standard \
    | tar --null -T - --ignore-failed-read -cf - 2>/dev/null) | tar -xf - -C "$WORK/src"
"$PYTHON" -m pip wheel -q --no-deps -w "$WORK/dist" "$WORK/src" || fail "pip wheel"
WHEEL="$(ls "$WORK"/dist/jack_ttes-*.whl)"
ok "built $(basename "$WHEEL") ($(du -k "$WHEEL" | cut -f1) KiB)"

# 2. the server alone: no GL, plotting, physics or scipy
"$PYTHON" -m venv "$WORK/venv"
VPY="$WORK/venv/bin/python"
TTES="$WORK/venv/bin/ttes"
"$VPY" -m pip install -q --upgrade pip
"$VPY" -m pip install -q "$WHEEL" || fail "pip install the wheel"
extra="$("$VPY" -m pip list --format=freeze | grep -iE '^(pyrender|pyrender-maintained|moderngl|pyopengl|matplotlib|scipy|mujoco|imageio|trimesh)==' || true)"
[[ -z "$extra" ]] || fail "a server-only install pulled in: $extra"
ok "server-only install: $("$VPY" -m pip list --format=freeze | grep -v '^pip==' | tr '\n' ' ')"

cd "$WORK/run"  # an empty folder: nothing here to find data in
export XDG_CACHE_HOME="$WORK/cache" PYOPENGL_PLATFORM="${PYOPENGL_PLATFORM:-egl}"
"$VPY" - <<'PY' || fail "the installed data"
import sysconfig
from pathlib import Path
from server.config import DEFAULT_DATA_DIR
from ttes.paths import FIGURES
from client_stub.data_paths import CROWD_DATA, DEFAULT_TERRAIN, STUB_DATA
site = Path(sysconfig.get_paths()["purelib"]).resolve()
assert DEFAULT_DATA_DIR.is_relative_to(site), f"the data dir {DEFAULT_DATA_DIR} is not the install's ({site})"
need = [DEFAULT_DATA_DIR / "posture_graphs" / "jack-ttes-soldier_low.jcl", FIGURES / "DI.fig", DEFAULT_TERRAIN,
        STUB_DATA / "DI.tips", CROWD_DATA / "soldier.tips"]
missing = [str(p) for p in need if not p.is_file()]
assert not missing, f"missing from the install: {missing}"
counts = {d: len(list((DEFAULT_DATA_DIR / d).rglob("*.*"))) for d in ("figures", "channelsets", "posture_graphs")}
assert counts["channelsets"] >= 100 and counts["figures"] >= 90, counts
print(f"data dir {DEFAULT_DATA_DIR}: {counts}")
PY
ok "the install carries its data"

start_server() {
    "$TTES" server --port 0 --json >server.out 2>server.log &
    SERVER_PID=$!
    for _ in $(seq 1 240); do
        grep -q '"ready"' server.out 2>/dev/null && break
        kill -0 "$SERVER_PID" 2>/dev/null || fail "ttes server exited before it was ready"
        sleep 0.5
    done
    PORT="$("$VPY" -c 'import json,sys; print(json.loads(open("server.out").readline())["port"])')" \
        || fail "no ready line from ttes server"
}
start_server
grep -q "synthetic" server.log && fail "the server fell back to a synthetic library"
"$TTES" ping --host 127.0.0.1 --port "$PORT" >/dev/null || fail "ttes ping"
ok "ttes server (port $PORT) answers ttes ping"

# 3. the [stub] extra as the image installs it (docker/Dockerfile): the lock with its hashes, then `pip check`
"$VPY" -m pip install -q --require-hashes --no-deps -r "$REPO/docker/requirements.lock" \
    || fail "pip install docker/requirements.lock"
"$VPY" -m pip check || fail "docker/requirements.lock does not hold what the wheel and its [stub] extra need"
"$VPY" -m pip install -q --no-deps "$WHEEL[stub]" && "$VPY" -m pip check >/dev/null || fail "the [stub] extra"
ok "docker/requirements.lock installs with its hashes"
"$TTES" stub --host 127.0.0.1 --port "$PORT" --headless --seconds 2 --fps 5 --size 160x120 --out stub.png \
    >stub.log 2>&1 || { cat stub.log >&2; fail "ttes stub --headless"; }
[[ -s stub.png ]] || fail "ttes stub wrote no stub.png"
ok "ttes stub --headless against the server"
"$TTES" crowd --headless --host 127.0.0.1 --port "$PORT" --soldiers 20 --seconds 1 --size 160x120 \
    --out crowd.png >crowd.log 2>&1 || { cat crowd.log >&2; fail "ttes crowd --headless"; }
[[ -s crowd.png ]] || fail "ttes crowd wrote no crowd.png"
ok "ttes crowd --headless against the server"
cleanup_server
SERVER_PID=""

"$TTES" dis synth --out squad.pcap --soldiers 4 --seconds 4 >/dev/null || fail "ttes dis synth"
"$TTES" replay squad.pcap --headless --size 160x120 --out replay.png >replay.log 2>&1 \
    || { cat replay.log >&2; fail "ttes replay"; }
grep -qi "synthetic" replay.log && { cat replay.log >&2; fail "ttes replay fell back to the synthetic library"; }
[[ -s replay.png ]] || fail "ttes replay wrote no replay.png"
ok "ttes replay --headless on the shipped library"

# the browser IG's page: three.js and msgpack vendored by the wheel's build (setup.py runs npm; without npm they are left out)
if command -v npm >/dev/null; then
    TTES="$TTES" "$VPY" - <<'PY' || fail "ttes web: the page, its three.js and msgpack"
import json, os, subprocess, urllib.request
cmd = [os.environ["TTES"], "web", "--port", "0", "--json", "--seconds", "20"]
web = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True)
url = json.loads(web.stdout.readline())["url"]
for path in ("", "js/app.js", "vendor/three.module.js", "vendor/addons/loaders/GLTFLoader.js", "vendor/msgpack/index.mjs",
             "vendor/msgpack/utils/utf8.mjs", "data/village.glb"):
    with urllib.request.urlopen(url + path) as r:
        assert r.status == 200 and r.read(), path
web.terminate()
web.wait()
PY
    ok "ttes web serves the page, three.js, msgpack and the village from the install"
fi

"$VPY" -c 'from ttes.commands.figure import figure_summaries as f; s = f(); assert len(s) >= 4, s' \
    || fail "the figures the demo lists"
ok "the demo's figure list"
echo "wheel-check: $PASSED passed, 0 failed"
