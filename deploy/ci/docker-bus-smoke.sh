#!/usr/bin/env bash
# The built image as the scaled-out layout runs it: a `fishloc sites` container and a `fishloc serve
# --sites-bus` container on a Redis of this machine (Debian's redis-server, loopback, a free port),
# sharing one registry volume; a frame of a site's camera must come back tracked.
# Usage: deploy/ci/docker-bus-smoke.sh    (root; a running engine and the image of docker-smoke.sh)
set -euo pipefail
cd "$(dirname "$0")/../.."

DOCKER=${DOCKER:-/usr/bin/docker}
IMAGE=${FISHLOC_IMAGE:-fishloc:ci}
PYTHON=${PYTHON:-.venv/bin/python}
command -v redis-server >/dev/null || { echo "docker-bus-smoke: redis-server missing (apt-get install -y redis-server)" >&2; exit 1; }

free_port() { "$PYTHON" -c "import socket; s = socket.socket(); s.bind(('127.0.0.1', 0)); print(s.getsockname()[1])"; }
redis_port=$(free_port)
http_port=$(free_port)
BUS=redis://127.0.0.1:$redis_port/0
SITES=fishloc-bus-sites-$$
SERVE=fishloc-bus-serve-$$
VOLUME=fishloc-bus-registry-$$
REDIS_DIR=$(mktemp -d /tmp/fishloc-bus-redis.XXXXXX)

redis-server --port "$redis_port" --bind 127.0.0.1 --save "" --appendonly no --dir "$REDIS_DIR" >/dev/null 2>&1 &
redis_pid=$!
cleanup() {
    "$DOCKER" rm -f "$SITES" "$SERVE" >/dev/null 2>&1 || true
    "$DOCKER" volume rm "$VOLUME" >/dev/null 2>&1 || true
    kill "$redis_pid" 2>/dev/null || true
    rm -rf "$REDIS_DIR"
}
trap cleanup EXIT
fail() {
    echo "docker-bus-smoke: FAILED: $1; container logs:" >&2
    "$DOCKER" logs --tail 40 "$SITES" >&2 || true
    "$DOCKER" logs --tail 40 "$SERVE" >&2 || true
    exit 1
}

# Host networking so that both reach the loopback Redis; each listens on 127.0.0.1 only.
"$DOCKER" run -d --name "$SITES" --network host --read-only --tmpfs /tmp -v "$VOLUME:/var/lib/fishloc" \
    --no-healthcheck "$IMAGE" sites --bus "$BUS" >/dev/null
"$DOCKER" run -d --name "$SERVE" --network host --read-only --tmpfs /tmp -v "$VOLUME:/var/lib/fishloc" --cpus 1 \
    -e FISHLOC_HOST=127.0.0.1 -e FISHLOC_HTTP_PORT="$http_port" -e FISHLOC_GRPC_PORT=-1 \
    -e FISHLOC_SITES_BUS="$BUS" -e FISHLOC_SITES_BUS_WAIT_S=5 "$IMAGE" >/dev/null
"$PYTHON" deploy/ci/bus_smoke_client.py --http "http://127.0.0.1:$http_port" --samples samples \
    || fail "bus smoke client"
echo "docker-bus-smoke: a replica and a sites worker of $IMAGE track a site over Redis; all checks passed"
