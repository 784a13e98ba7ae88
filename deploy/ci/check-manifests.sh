#!/usr/bin/env bash
# Offline checks of the deployment files: hadolint on the Dockerfile, kubernetes-validate --strict
# on the Kubernetes manifests, promtool on the Prometheus config, `docker-compose config` on the
# compose file.
# Usage: deploy/ci/check-manifests.sh    (tools from the dev extra in .venv, docker-compose from Debian)
set -euo pipefail
cd "$(dirname "$0")/../.."

VENV_BIN=${VENV_BIN:-.venv/bin}
tool() {  # the dev-extra tool from the project's venv, else from PATH
    if [ -x "$VENV_BIN/$1" ]; then echo "$VENV_BIN/$1"; else command -v "$1"; fi
}

HADOLINT=$(tool hadolint) || { echo "check-manifests: hadolint missing (pip install -e '.[dev]')" >&2; exit 1; }
"$HADOLINT" --failure-threshold warning deploy/Dockerfile
echo "check-manifests: hadolint deploy/Dockerfile ok"

VALIDATE=$(tool kubernetes-validate) || {
    echo "check-manifests: kubernetes-validate missing (pip install -e '.[dev]')" >&2
    exit 1
}
# Every manifest but the kustomization (a kustomize file, not a Kubernetes resource).
mapfile -t MANIFESTS < <(find deploy/k8s -name '*.yaml' ! -name kustomization.yaml | sort)
"$VALIDATE" --strict --quiet "${MANIFESTS[@]}"
echo "check-manifests: kubernetes-validate --strict ${#MANIFESTS[@]} manifests ok"

if command -v promtool >/dev/null; then
    promtool check config deploy/prometheus/prometheus.yml >/dev/null
    echo "check-manifests: promtool check config deploy/prometheus/prometheus.yml ok"
elif [ "${CI:-}" = true ]; then
    echo "check-manifests: promtool missing in CI (apt-get install -y prometheus)" >&2
    exit 1
else
    echo "check-manifests: promtool not installed here, Prometheus config not checked"
fi

if command -v docker-compose >/dev/null; then
    docker-compose -f deploy/compose.yaml config --quiet
    echo "check-manifests: docker-compose config deploy/compose.yaml ok"
elif [ "${CI:-}" = true ]; then
    echo "check-manifests: docker-compose missing in CI (apt-get install -y docker-compose)" >&2
    exit 1
else
    echo "check-manifests: docker-compose not installed here, compose file not checked"
fi
