#!/usr/bin/env bash
# The deployment part of CI (called by .ci/run after the test suite): offline checks of the
# Dockerfile, compose file and Kubernetes manifests, then the image built and run for real.
# Prints how long each step took. Needs root for the Docker engine; outside CI a machine without
# root or Docker runs the offline checks only.
set -euo pipefail
cd "$(dirname "$0")/../.."

TIMES=()
step() {  # step NAME COMMAND...: run, time, and remember the duration
    local name=$1 start=$SECONDS
    shift
    echo "== deploy: $name"
    "$@"
    TIMES+=("$(printf '%-16s %4d s' "$name" $((SECONDS - start)))")
}
summary() {
    echo "== deploy: step times"
    printf '  %s\n' "${TIMES[@]}"
}
trap summary EXIT

step manifests bash deploy/ci/check-manifests.sh

if [ "$(id -u)" != 0 ] || ! command -v dockerd >/dev/null; then
    if [ "${CI:-}" = true ]; then
        echo "deploy: CI needs root and Debian's docker.io to build and run the image" >&2
        exit 1
    fi
    echo "deploy: not root or no dockerd here: image build and run skipped"
    exit 0
fi
step docker-engine bash deploy/ci/docker-engine.sh
step docker-base bash deploy/ci/docker-base.sh
step docker-smoke bash deploy/ci/docker-smoke.sh
step docker-bus bash deploy/ci/docker-bus-smoke.sh
