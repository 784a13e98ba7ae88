#!/usr/bin/env bash
# Make the Dockerfile's base image, debian:bookworm-slim, locally when no container registry is
# reachable: debootstrap a minimal bookworm from Debian's mirror, trim it the way the official slim
# image is trimmed, and `docker import` it under the same tag. The Dockerfile is unchanged, so
# elsewhere `docker build` pulls the official image instead.
#
# Usage: deploy/ci/docker-base.sh     (root; needs debootstrap and a running engine)
# Skips all work when the tag already exists (the engine keeps it between runs).
set -euo pipefail

TAG=${FISHLOC_BASE_TAG:-debian:bookworm-slim}
SUITE=bookworm
MIRROR=${FISHLOC_DEBIAN_MIRROR:-http://deb.debian.org/debian}
DOCKER=${DOCKER:-/usr/bin/docker}

if "$DOCKER" image inspect "$TAG" >/dev/null 2>&1; then
    echo "docker-base: $TAG already present ($("$DOCKER" image inspect --format '{{.Id}}' "$TAG"))"
    exit 0
fi
command -v debootstrap >/dev/null || { echo "docker-base: debootstrap missing (apt-get install -y debootstrap)" >&2; exit 1; }

WORK=$(mktemp -d /var/tmp/fishloc-base.XXXXXX)
trap 'rm -rf "$WORK"' EXIT
ROOT=$WORK/rootfs

echo "docker-base: debootstrap --variant=minbase $SUITE from $MIRROR"
debootstrap --variant=minbase "$SUITE" "$ROOT" "$MIRROR" >"$WORK/debootstrap.log" 2>&1 || {
    tail -n 30 "$WORK/debootstrap.log" >&2
    exit 1
}

# Apt sources as in the official image: the release, its updates and security fixes.
rm -f "$ROOT/etc/apt/sources.list"
cat >"$ROOT/etc/apt/sources.list.d/debian.sources" <<EOF
Types: deb
URIs: http://deb.debian.org/debian
Suites: $SUITE $SUITE-updates
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg

Types: deb
URIs: http://deb.debian.org/debian-security
Suites: $SUITE-security
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg
EOF

# Container-friendly apt and dpkg settings, as the official images set them: no package caches,
# no translations, compressed indexes, no docs or man pages.
cat >"$ROOT/etc/apt/apt.conf.d/docker-clean" <<'EOF'
DPkg::Post-Invoke { "rm -f /var/cache/apt/archives/*.deb /var/cache/apt/archives/partial/*.deb /var/cache/apt/*.bin || true"; };
APT::Update::Post-Invoke { "rm -f /var/cache/apt/archives/*.deb /var/cache/apt/archives/partial/*.deb /var/cache/apt/*.bin || true"; };
Dir::Cache::pkgcache "";
Dir::Cache::srcpkgcache "";
EOF
echo 'Acquire::Languages "none";' >"$ROOT/etc/apt/apt.conf.d/docker-no-languages"
echo 'Acquire::GzipIndexes "true";' >"$ROOT/etc/apt/apt.conf.d/docker-gzip-indexes"
echo 'Apt::AutoRemove::SuggestsImportant "false";' >"$ROOT/etc/apt/apt.conf.d/docker-autoremove-suggests"
cat >"$ROOT/etc/dpkg/dpkg.cfg.d/docker" <<'EOF'
path-exclude /usr/share/doc/*
path-include /usr/share/doc/*/copyright
path-exclude /usr/share/man/*
path-exclude /usr/share/info/*
path-exclude /usr/share/locale/*
path-include /usr/share/locale/locale.alias
path-exclude /usr/share/lintian/*
EOF

# Trim what debootstrap leaves behind and what is specific to the machine that made it.
rm -rf "$ROOT"/var/cache/apt/archives/*.deb "$ROOT"/var/cache/apt/*.bin "$ROOT"/var/lib/apt/lists/* \
    "$ROOT"/var/log/* "$ROOT"/tmp/* "$ROOT"/usr/share/man/* "$ROOT"/usr/share/info/* \
    "$ROOT"/etc/hostname "$ROOT"/etc/resolv.conf
find "$ROOT/usr/share/doc" -mindepth 2 ! -name copyright ! -type d -delete
find "$ROOT/usr/share/doc" -mindepth 1 -type d -empty -delete
find "$ROOT/usr/share/locale" -mindepth 1 -maxdepth 1 ! -name locale.alias -exec rm -rf {} +
: >"$ROOT/etc/machine-id"

echo "docker-base: importing $(du -sh "$ROOT" | cut -f1) as $TAG"
tar --numeric-owner --xattrs -C "$ROOT" -c . | "$DOCKER" import \
    --change 'ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin' \
    --change 'CMD ["bash"]' \
    --message "debootstrap --variant=minbase $SUITE $MIRROR" \
    - "$TAG" >/dev/null
"$DOCKER" image ls "$TAG"
