#!/usr/bin/env bash
# Builds the uavnav image (uavnavd + the uavnav CLI), either way:
#
#   docker/build.sh [--pull|--no-pull] [--profile release|dev] [--tag IMAGE] [--no-cargo]
#
#   --pull        docker/Dockerfile: a rust:1-bookworm builder and a debian:bookworm-slim runtime,
#                 pulled from the registry (needs a registry; the usual path).
#   --no-pull     no registry: the binaries are built on this host with cargo, then an image is
#                 assembled FROM scratch with them, the shared libraries `ldd` lists (with the dynamic
#                 loader), /etc/passwd with a non-root user, the configs and scenarios. (default)
#   --profile P   cargo profile of the --no-pull binaries: release (default) or dev. dev builds
#                 them as `cargo test --workspace` does (`--no-run`), so after the README's test
#                 command it compiles nothing (CI). `cargo build -p uavnavd -p uavnav-cli` would
#                 not reuse them: the workspace's test build unifies tokio's `test-util` (the test
#                 kit's) into the dependency graph, and a build of the two packages alone rebuilt
#                 tokio, zenoh, tonic and the service in the middle of CI.
#   --tag IMAGE   image name (default uavnav:latest, what docker/compose.yaml runs).
#   --no-cargo    --no-pull only: do not run cargo, use the binaries already in the target dir.
#
# The target dir is $CARGO_TARGET_DIR when set, else ./target. Both paths give an image with the same
# layout: /usr/local/bin/{uavnavd,uavnav}, /etc/uavnav/uavnavd.toml, /usr/share/uavnav/scenarios/,
# user uavnav (10001:10001), writable /data, /recordings and /certs, and the same HEALTHCHECK.
set -euo pipefail

here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/.." && pwd)
mode=no-pull
profile=release
tag=uavnav:latest
run_cargo=1

usage() { sed -n '2,19p' "$0" | sed 's/^# \{0,1\}//'; }
while [ $# -gt 0 ]; do
    case "$1" in
        --pull) mode=pull ;;
        --no-pull) mode=no-pull ;;
        --profile) profile=${2:?--profile needs release or dev}; shift ;;
        --profile=*) profile=${1#--profile=} ;;
        --tag) tag=${2:?--tag needs an image name}; shift ;;
        --tag=*) tag=${1#--tag=} ;;
        --no-cargo) run_cargo=0 ;;
        -h|--help) usage; exit 0 ;;
        *) echo "build.sh: unknown argument '$1'" >&2; usage >&2; exit 2 ;;
    esac
    shift
done
case "$profile" in
    release) profile_dir=release ;;
    dev|debug) profile=dev; profile_dir=debug ;;
    *) echo "build.sh: --profile must be release or dev, not '$profile'" >&2; exit 2 ;;
esac
command -v docker >/dev/null || { echo "build.sh: docker not found on PATH" >&2; exit 1; }

# Build context: the repository's tracked and untracked-but-not-ignored files, streamed as a tar, so
# target dirs never reach the engine whatever the builder (the legacy builder ignores
# docker/Dockerfile.dockerignore).
context_tar() {
    (cd "$root" && git ls-files -z --cached --others --exclude-standard \
        | xargs -0 -I{} sh -c 'test -e "$1" && printf "%s\0" "$1"' _ {} \
        | tar --null -T - -cf -)
}

if [ "$mode" = pull ]; then
    echo "build.sh: building $tag from docker/Dockerfile (pulls rust:1-bookworm, debian:bookworm-slim)"
    context_tar | docker build -f docker/Dockerfile -t "$tag" -
    echo "build.sh: built $tag"
    exit 0
fi

# --- no-pull: host binaries into a FROM scratch image -------------------------------------------
target_dir=${CARGO_TARGET_DIR:-$root/target}
bin_dir=$target_dir/$profile_dir
if [ "$run_cargo" = 1 ]; then
    if [ "$profile" = dev ]; then
        echo "build.sh: cargo test --workspace --no-run (the test build's binaries; target dir $target_dir)"
        (cd "$root" && cargo test --locked --workspace --no-run)
    else
        echo "build.sh: cargo build --profile $profile -p uavnavd -p uavnav-cli (target dir $target_dir)"
        (cd "$root" && cargo build --locked --profile "$profile" -p uavnavd -p uavnav-cli)
    fi
fi
for b in uavnavd uavnav; do
    [ -x "$bin_dir/$b" ] || { echo "build.sh: $bin_dir/$b missing (build it, or drop --no-cargo)" >&2; exit 1; }
done

stage=$(mktemp -d "${TMPDIR:-/tmp}/uavnav-image.XXXXXX")
trap 'rm -rf "$stage"' EXIT
rootfs=$stage/rootfs
mkdir -p "$rootfs"/{usr/local/bin,etc/uavnav,usr/share/uavnav/scenarios,tmp} "$stage"/owned/{data,recordings,certs}
install -m 0755 "$bin_dir/uavnavd" "$bin_dir/uavnav" "$rootfs/usr/local/bin/"
# Debug info is most of a dev binary's size (hundreds of MB); the image needs none of it.
if command -v strip >/dev/null; then strip --strip-debug "$rootfs"/usr/local/bin/*; fi

# Shared libraries, at the paths the binaries look them up, plus the dynamic loader. `ldd` prints
# "name => /path (addr)" for libraries and "/path (addr)" for the loader; vdso has no file.
libs=$(ldd "$bin_dir/uavnavd" "$bin_dir/uavnav" | awk '$2 == "=>" && $3 ~ /^\// {print $3} $1 ~ /^\// && $1 !~ /:$/ {print $1}' | sort -u)
for lib in $libs; do
    mkdir -p "$rootfs$(dirname "$lib")"
    cp -L "$lib" "$rootfs$lib"
done
# glibc resolves container names (Docker's DNS) through NSS: files then DNS.
printf 'hosts: files dns\npasswd: files\ngroup: files\n' >"$rootfs/etc/nsswitch.conf"
printf 'root:x:0:0:root:/root:/sbin/nologin\nuavnav:x:10001:10001:uavnav:/data:/sbin/nologin\n' >"$rootfs/etc/passwd"
printf 'root:x:0:\nuavnav:x:10001:\n' >"$rootfs/etc/group"
cp "$root/server/uavnavd.toml" "$rootfs/etc/uavnav/uavnavd.toml"
cp "$root/docker/uavnavd.toml" "$rootfs/etc/uavnav/uavnavd.docker.toml"
cp "$root"/scenarios/*.toml "$here/fleet.toml" "$rootfs/usr/share/uavnav/scenarios/"
chmod 1777 "$rootfs/tmp"

# The image's metadata must match docker/Dockerfile's runtime stage.
healthcheck=$(sed -n '/^HEALTHCHECK/,/CMD/p' "$here/Dockerfile")
cat >"$stage/Dockerfile" <<EOF
FROM scratch
COPY --chown=0:0 rootfs/ /
COPY --chown=10001:10001 owned/ /
USER 10001:10001
WORKDIR /data
EXPOSE 50051 9464 7447
$healthcheck
CMD ["/usr/local/bin/uavnavd", "--config", "/etc/uavnav/uavnavd.toml"]
EOF
n_libs=$(printf '%s\n' $libs | wc -l)
echo "build.sh: assembling $tag FROM scratch ($profile binaries from $bin_dir, $n_libs shared libraries)"
docker build -q -t "$tag" "$stage" >/dev/null
echo "build.sh: built $tag ($(docker image inspect -f '{{.Size}}' "$tag" | awk '{printf "%.1f MB", $1/1e6}'))"
