#!/usr/bin/env bash
# Build docker/Dockerfile without a Docker engine (buildah: chroot isolation, vfs storage) and run the image as
# compose.yaml does: the server with a controller token, `ttes ping` inside the container (the HEALTHCHECK) and
# from outside, the headless stub and the crowd against it into /out (the uid 1000 user's), and the gateway on
# UDP for a moment. Needs root and buildah (`apt-get install buildah`); run from anywhere: docker/buildah_check.sh
#   BASE=IMAGE        the base image (default: the Dockerfile's pinned tag, pulled from its registry)
#   BASE=debootstrap  a Debian bookworm base with python3.11 made here with debootstrap, for machines that reach
#                     Debian's mirrors but no image registry; it trusts the host's extra CAs
#                     (/usr/local/share/ca-certificates/*.crt), as pip must behind a TLS-inspecting proxy
#   PORT=N            the server's port (default 17000; chroot isolation shares the host's network); the
#                     scaled profile's front-end and shards use PORT+10 .. PORT+12 and the fabric PORT+13
#   IMAGE=NAME        the tag to build (default localhost/jack-ttes:local)
# Then compose's scaled profile: a front-end and 2 shards on the Zenoh fabric (127.0.0.1 for the service name
# "front"), the stub and `ttes loadtest` against the front-end (its JSON names the shards).
set -euo pipefail
REPO="$(cd "$(dirname "$0")/.." && pwd)"
B=(buildah --storage-driver vfs)
PORT="${PORT:-17000}"
IMAGE="${IMAGE:-localhost/jack-ttes:local}"
OUT="$(mktemp -d /tmp/ttes-buildah-check.XXXXXX)"
step() { echo "buildah-check: $*"; }

local_base() {  # a bookworm root file system with python3.11, imported as an image
    local root="$OUT/rootfs" ctx="$OUT/base"
    debootstrap --variant=minbase --include=python3,python3-venv,python-is-python3,ca-certificates \
        bookworm "$root" http://deb.debian.org/debian >"$OUT/debootstrap.log"
    rm -rf "$root"/var/cache/apt/archives/*.deb
    mkdir -p "$ctx"
    tar -C "$root" -cf "$ctx/rootfs.tar" .
    cp /usr/local/share/ca-certificates/*.crt "$ctx/" 2>/dev/null || true
    cat >"$ctx/Containerfile" <<'CF'
FROM scratch
ADD rootfs.tar /
COPY *.crt /usr/local/share/ca-certificates/
RUN update-ca-certificates
ENV PIP_CERT=/etc/ssl/certs/ca-certificates.crt SSL_CERT_FILE=/etc/ssl/certs/ca-certificates.crt
CF
    touch "$ctx/none.crt"  # COPY needs a match; an empty file is skipped by update-ca-certificates
    "${B[@]}" bud --isolation chroot -f "$ctx/Containerfile" -t localhost/bookworm-python:3.11 "$ctx" >/dev/null
    rm -rf "$root" "$ctx"
    echo localhost/bookworm-python:3.11
}

BASE_ARG=()
if [[ "${BASE:-}" == debootstrap ]]; then
    step "making a Debian bookworm base with debootstrap"
    BASE_ARG=(--build-arg "BASE=$(local_base)")
elif [[ -n "${BASE:-}" ]]; then
    BASE_ARG=(--build-arg "BASE=$BASE")
fi
step "building $IMAGE ${BASE_ARG[*]}"
"${B[@]}" bud --isolation chroot --format docker "${BASE_ARG[@]}" -f "$REPO/docker/Dockerfile" -t "$IMAGE" \
    "$REPO" >"$OUT/build.log" 2>&1 || { tail -30 "$OUT/build.log"; exit 1; }

CTR="$("${B[@]}" from "$IMAGE")"
TOKEN="check-$(od -An -N12 -tx1 /dev/urandom | tr -d ' \n')"
SERVER=""
SCALED=()
cleanup() {
    [[ -z "$SERVER" ]] || kill -TERM "$SERVER" 2>/dev/null || true
    for pid in "${SCALED[@]}"; do kill -TERM "$pid" 2>/dev/null || true; done
    sleep 1
    "${B[@]}" rm "$CTR" >/dev/null 2>&1 || true
}
trap cleanup EXIT
run() { "${B[@]}" run --isolation chroot --env "TTES_TOKEN=$TOKEN" "$CTR" -- "$@"; }

# the image's CMD with compose's environment (chroot isolation: its pid is a host pid)
"${B[@]}" run --isolation chroot --env "TTES_CONTROLLER_TOKEN=$TOKEN" --env "TTES_TOKEN=$TOKEN" "$CTR" -- \
    sh -c "ttes server --config /etc/ttes/server.toml --port $PORT & echo \$! >/tmp/server.pid; wait" \
    >"$OUT/server.log" 2>&1 &
for _ in $(seq 1 180); do grep -q '"listening"' "$OUT/server.log" && break; sleep 1; done
SERVER="$(run cat /tmp/server.pid)"
run ttes ping --host 127.0.0.1 --port "$PORT" --timeout 2 || { tail "$OUT/server.log"; exit 1; }
step "ok: the server in the container answers its healthcheck's ttes ping"
if ! "${B[@]}" run --isolation chroot --env TTES_TOKEN= "$CTR" -- ttes ping --host 127.0.0.1 --port "$PORT" \
    --timeout 2 >/dev/null 2>&1; then
    step "ok: without the token the server refuses (it binds 0.0.0.0)"
else
    step "FAILED: a ping without the token was answered"; exit 1
fi
grep -o '"data_dir": "[^"]*"' "$OUT/server.log"
run ttes stub --host 127.0.0.1 --port "$PORT" --headless --seconds 3 --fps 5 --size 320x240 --out /out/stub.png
run ttes crowd --headless --host 127.0.0.1 --port "$PORT" --soldiers 20 --seconds 1 --size 320x240 \
    --out /out/crowd.png | tail -1
run ttes gateway --listen 0.0.0.0 --dis-port "$((PORT + 1))" --host 127.0.0.1 --port "$PORT" --seconds 2 \
    | tail -1
MNT="$("${B[@]}" mount "$CTR")"
cp "$MNT/out/stub.png" "$MNT/out/crowd.png" "$OUT/"
step "ok: stub, crowd and gateway ran in the image; pictures in $OUT/stub.png, $OUT/crowd.png"

# compose's scaled profile (its commands, with the host's loopback for the service name and ports moved)
FRONT=$((PORT + 10)) FABRIC=$((PORT + 13))
scaled() {  # NAME ARGS...: one process of the profile in the background; its pid in /tmp/NAME.pid
    local name="$1"; shift
    "${B[@]}" run --isolation chroot --env "TTES_CONTROLLER_TOKEN=$TOKEN" --env "TTES_TOKEN=$TOKEN" "$CTR" -- \
        sh -c "$* & echo \$! >/tmp/$name.pid; wait" >"$OUT/$name.log" 2>&1 &
}
scaled front ttes front --config /etc/ttes/server.toml --port "$FRONT" --shards 2 --fabric-listen "0.0.0.0:$FABRIC"
for _ in $(seq 1 180); do grep -q '"listening"' "$OUT/front.log" && break; sleep 1; done
for k in 0 1; do
    scaled "shard$k" ttes server --config /etc/ttes/server.toml --port "$((FRONT + 1 + k))" --shard "$k/2" \
        --fabric-connect "127.0.0.1:$FABRIC"
done
for p in "$FRONT" "$((FRONT + 1))" "$((FRONT + 2))"; do
    for _ in $(seq 1 90); do run ttes ping --host 127.0.0.1 --port "$p" --timeout 2 >/dev/null 2>&1 && break; sleep 2; done
done
SCALED=("$(run cat /tmp/front.pid)" "$(run cat /tmp/shard0.pid)" "$(run cat /tmp/shard1.pid)")
run ttes stub --host 127.0.0.1 --port "$FRONT" --headless --seconds 3 --fps 5 --size 320x240 --out /out/scaled.png
run ttes loadtest --port "$FRONT" --soldiers 20 --clients 2 --seconds 3 --warmup 2 --json >"$OUT/loadtest.json"
grep -q '"role": "front-end"' "$OUT/loadtest.json" || { step "FAILED: loadtest did not name the shards"; exit 1; }
cp "$MNT/out/scaled.png" "$OUT/"
step "ok: scaled profile: a front-end and 2 shards answer ttes ping, the stub ($OUT/scaled.png) and ttes loadtest \
ran against the front-end; its JSON names the shards ($OUT/loadtest.json)"
