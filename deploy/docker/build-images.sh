#!/usr/bin/env bash
# Builds tessera:local (coordinator and client) and tessera-worker:local from the release build,
# with no registry: the base image, tessera-base:local, is a minimal Debian made here with
# debootstrap from the build machine's own Debian release and imported with `docker import`
# (deploy/README.md says why). The base is made once and reused; --rebuild-base makes it again.
#
#   deploy/docker/build-images.sh [--no-build] [--rebuild-base] [--tag TAG]
#
# Environment: CARGO_TARGET_DIR (where the release binaries are; default ./target),
# DEBIAN_MIRROR (default http://deb.debian.org/debian), TESSERA_BASE_CACHE (a folder for the
# debootstrap tarball, so that a rebuilt base needs no download; default ~/.cache/tessera-deploy).
set -euo pipefail

repo=$(cd "$(dirname "$0")/../.." && pwd)
build=1
rebuild_base=0
tag=local
while [ $# -gt 0 ]; do
    case "$1" in
        --no-build) build=0 ;;
        --rebuild-base) rebuild_base=1 ;;
        --tag) tag=$2; shift ;;
        -h|--help) sed -n '2,12p' "$0"; exit 0 ;;
        *) echo "build-images.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
    esac
    shift
done

say() { echo "build-images: $*" >&2; }
die() { echo "build-images: error: $*" >&2; exit 1; }

command -v docker >/dev/null || die "docker is not installed"
docker info >/dev/null 2>&1 || die "the Docker daemon is not reachable (docker info fails)"
# the legacy builder needs no buildx plugin and handles this Dockerfile (multi-stage, no RUN)
if ! docker buildx version >/dev/null 2>&1; then export DOCKER_BUILDKIT=0; fi

target_dir=${CARGO_TARGET_DIR:-$repo/target}
bin=$target_dir/release
if [ "$build" = 1 ]; then
    say "cargo build --release -p tessera-coordinator -p tessera-worker"
    (cd "$repo" && cargo build --release -p tessera-coordinator -p tessera-worker)
fi
for b in tessera tessera-worker; do
    [ -x "$bin/$b" ] || die "$bin/$b is missing: build it (cargo build --release -p tessera-coordinator -p tessera-worker) or drop --no-build"
done

# --- the base: the build machine's Debian release, so the glibc the binaries link is the one
# they run on
base=tessera-base:$tag
suite=$(. /etc/os-release && [ "${ID:-}" = debian ] && echo "${VERSION_CODENAME:-}" || true)
[ -n "$suite" ] || die "the base is made with debootstrap from the build machine's Debian release, and this is not Debian"
have_suite=$(docker image inspect --format '{{ index .Config.Labels "tessera.base.suite" }}' "$base" 2>/dev/null || true)
if [ "$rebuild_base" = 1 ] || [ "$have_suite" != "$suite" ]; then
    cache=${TESSERA_BASE_CACHE:-${XDG_CACHE_HOME:-$HOME/.cache}/tessera-deploy}
    tarball=$cache/debootstrap-$suite-minbase.tar
    if [ "$rebuild_base" = 1 ] || [ ! -s "$tarball" ]; then
        command -v debootstrap >/dev/null || die "debootstrap is missing: apt-get install -y debootstrap"
        [ "$(id -u)" = 0 ] || die "debootstrap needs root to make the base image (run this script as root once; the base is then reused)"
        mkdir -p "$cache"
        root=$(mktemp -d "$cache/root.XXXXXX")
        trap 'rm -rf "$root"' EXIT
        mirror=${DEBIAN_MIRROR:-http://deb.debian.org/debian}
        say "debootstrap --variant=minbase $suite from $mirror (once; about a minute)"
        debootstrap --variant=minbase --include=ca-certificates "$suite" "$root" "$mirror" >"$cache/debootstrap.log" 2>&1 \
            || { tail -n 20 "$cache/debootstrap.log" >&2; die "debootstrap failed (log: $cache/debootstrap.log)"; }
        # the service user of both images, and the folders they write
        chroot "$root" groupadd --gid 10001 tessera
        chroot "$root" useradd --uid 10001 --gid 10001 --home-dir /var/lib/tessera --no-create-home \
            --shell /usr/sbin/nologin tessera
        install -d -o 10001 -g 10001 -m 0750 "$root/var/lib/tessera" "$root/var/cache/tessera-worker"
        # what an image never uses: package caches and lists, documentation, locales
        rm -rf "$root"/var/cache/apt/archives/*.deb "$root"/var/lib/apt/lists/* "$root"/usr/share/doc/* \
            "$root"/usr/share/man/* "$root"/usr/share/info/* "$root"/usr/share/locale/* "$root"/var/log/*
        tar -C "$root" --numeric-owner -cf "$tarball.tmp" .
        mv "$tarball.tmp" "$tarball"
        rm -rf "$root"
        trap - EXIT
    fi
    say "docker import $base from $tarball"
    docker import --change "LABEL tessera.base.suite=$suite" \
        --change 'ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin' \
        "$tarball" "$base" >/dev/null
fi

# --- the images
context=$(mktemp -d)
trap 'rm -rf "$context"' EXIT
cp "$repo/deploy/docker/Dockerfile" "$bin/tessera" "$bin/tessera-worker" "$context/"
version=$("$bin/tessera" --version | awk '{print $2}')
revision=$(git -C "$repo" rev-parse HEAD 2>/dev/null || echo unknown)
if [ "$revision" != unknown ] && [ -n "$(git -C "$repo" status --porcelain --untracked-files=no 2>/dev/null)" ]; then
    revision=$revision-dirty
fi
source_url=$(git -C "$repo" config --get remote.origin.url 2>/dev/null || echo unknown)
created=$(date -u +%Y-%m-%dT%H:%M:%SZ)
for image in tessera tessera-worker; do
    say "docker build $image:$tag (version $version, revision $revision)"
    # the output only matters when it fails (the legacy builder warns that it is deprecated)
    docker build --quiet --target "$image" --tag "$image:$tag" \
        --build-arg "BASE=$base" --build-arg "VERSION=$version" --build-arg "REVISION=$revision" \
        --build-arg "SOURCE=$source_url" --build-arg "CREATED=$created" "$context" >"$context/build.log" 2>&1 \
        || { cat "$context/build.log" >&2; die "docker build of $image:$tag failed"; }
done

# each build relabels (created, revision), so the image it replaced is left untagged: drop ours
for image in tessera tessera-worker; do
    docker image prune --force --filter "label=org.opencontainers.image.title=$image" >/dev/null
done

# the binaries must start in the base (a glibc they cannot load shows here, not on a farm)
docker run --rm "tessera:$tag" --version >/dev/null || die "tessera does not start in tessera:$tag"
docker run --rm "tessera-worker:$tag" --version >/dev/null || die "tessera-worker does not start in tessera-worker:$tag"
say "built tessera:$tag and tessera-worker:$tag ($(docker image inspect --format '{{.Size}}' "tessera-worker:$tag" | awk '{printf "%.0f MB", $1/1e6}'))"
