#!/usr/bin/env bash
# Start Debian's Docker engine by hand (CI machines have no systemd) unless one already answers.
# Usage: deploy/ci/docker-engine.sh     (root; needs the docker.io package)
# The engine's log goes to ${FISHLOC_DOCKERD_LOG:-/var/log/fishloc-dockerd.log}.
set -euo pipefail

SOCKET=/var/run/docker.sock
LOG=${FISHLOC_DOCKERD_LOG:-/var/log/fishloc-dockerd.log}
# Debian's client speaks to Debian's engine and brings BuildKit; another `docker` earlier on PATH
# may be a newer client that needs the buildx plugin for `--secret`.
DOCKER=${DOCKER:-/usr/bin/docker}

if [ -S "$SOCKET" ] && "$DOCKER" info >/dev/null 2>&1; then
    echo "docker-engine: already running ($("$DOCKER" version --format '{{.Server.Version}}'))"
    exit 0
fi
command -v dockerd >/dev/null || { echo "docker-engine: dockerd missing (apt-get install -y docker.io)" >&2; exit 1; }

# containerd is started by dockerd itself; setsid keeps the engine alive after this script exits.
mkdir -p "$(dirname "$LOG")"
setsid nohup dockerd >"$LOG" 2>&1 </dev/null &
echo "docker-engine: started dockerd (pid $!), log in $LOG"

for _ in $(seq 1 60); do
    if [ -S "$SOCKET" ] && "$DOCKER" info >/dev/null 2>&1; then
        echo "docker-engine: ready ($("$DOCKER" version --format '{{.Server.Version}}'))"
        exit 0
    fi
    sleep 1
done
echo "docker-engine: dockerd did not answer within 60 s; last lines of $LOG:" >&2
tail -n 30 "$LOG" >&2
exit 1
