#!/usr/bin/env bash
# The docker deployment, tested for real (run by .ci/run when a Docker engine is reachable):
#
#   docker/test.sh [--profile dev|release] [--pull] [--no-build] [--keep]
#
#  1. builds the image (docker/build.sh; default --no-pull --profile dev, which reuses the target/debug
#     binaries `cargo test --workspace` built);
#  2. `compose up -d` under a unique project name, with free host ports; waits until uavnavd is healthy;
#     the deployment is secure: plaintext, no certificate and a ground station resetting a drone are
#     refused, the operator's certificate gets in (the `security` step);
#  3. poses of EVERY simulated drone reach the ground station's CSV within a bound, and their
#     horizontal error against the recording's truth is within a few metres;
#  4. `docker network disconnect` of one drone container: its vehicles' inputs go stale (the service's
#     `uavnav health --max-age` says so) while the other container's stay fresh; after
#     `docker network connect` they recover within a bound;
#  5. `compose down -v` leaves no container, network or volume of the project.
# Prints progress lines with the elapsed time and the measured figures. Exit 0 on success.
set -euo pipefail

here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/.." && pwd)
profile=dev
build_args=(--no-pull)
build=1
keep=0
while [ $# -gt 0 ]; do
    case "$1" in
        --profile) profile=${2:?}; shift ;;
        --profile=*) profile=${1#--profile=} ;;
        --pull) build_args=(--pull) ;;
        --no-build) build=0 ;;
        --keep) keep=1 ;;
        -h|--help) sed -n '2,16p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
        *) echo "test.sh: unknown argument '$1'" >&2; exit 2 ;;
    esac
    shift
done

# --- bounds and sizes (seconds unless named otherwise) ------------------------------------------
readonly DRONES_PER_CONTAINER=3      # vehicles per replay container (2 containers)
readonly UP_TIMEOUT=240              # compose up (the recording is simulated first), incl. healthy
readonly FIRST_POSES_TIMEOUT=60      # from healthy until every drone has MIN_ROWS poses at the ground station
readonly MIN_ROWS=100                # poses per drone at the ground station (5 s at 20 Hz)
readonly SCORED_ROWS=500             # poses per drone before scoring accuracy (25 s at 20 Hz)
readonly SCORED_TIMEOUT=60           # from "every drone has MIN_ROWS" until SCORED_ROWS
readonly ACCURACY_SKIP_S=5           # filter convergence not scored
readonly MAX_RMS_H_M=3.0             # horizontal RMS error bound per drone
readonly MAX_H_M=8.0                 # horizontal max error bound per drone
readonly STALE_AGE_S=2.5             # `uavnav health --max-age`: input older than this = stale
readonly STALE_TIMEOUT=20            # disconnect -> every vehicle of the container stale
readonly HOLD_DISCONNECTED=2         # extra time disconnected once stale
readonly RECOVER_TIMEOUT=60          # connect -> every vehicle fresh again

project="uavnavtest$$"
image="uavnav-test:$project"
tmp=$(mktemp -d "${TMPDIR:-/tmp}/uavnav-docker-test.XXXXXX")
t_start=$(date +%s.%N)
say() { printf 'test.sh [%6.1f s] %s\n' "$(since "$t_start")" "$*"; }
fail() { say "FAIL: $*"; exit 1; }

if docker compose version >/dev/null 2>&1; then
    compose_cmd=(docker compose)
elif command -v docker-compose >/dev/null 2>&1; then
    compose_cmd=(docker-compose)
else
    echo "test.sh: neither 'docker compose' nor 'docker-compose' is available" >&2
    exit 1
fi
compose() { "${compose_cmd[@]}" -p "$project" -f "$here/compose.yaml" "$@"; }

# Free TCP ports on the host for the published ports (a developer's own uavnavd may hold 50051).
used_ports() {
    local hex
    for hex in $(cat /proc/net/tcp /proc/net/tcp6 2>/dev/null | awk 'NR > 1 {split($2, a, ":"); print a[2]}'); do
        echo $((16#$hex))
    done
}
free_port() {
    local p used
    used=$(used_ports)
    for _ in $(seq 1 200); do
        p=$(( 20000 + RANDOM % 30000 ))
        if ! grep -qx "$p" <<<"$used" && ! grep -qx "$p" <<<"${taken:-}"; then taken="${taken:-}"$'\n'"$p"; echo "$p"; return; fi
    done
    echo "test.sh: no free port found" >&2; exit 1
}
taken=""
grpc_port=$(free_port); taken+=$'\n'$grpc_port
http_port=$(free_port); taken+=$'\n'$http_port
zenoh_port=$(free_port)
export UAVNAV_IMAGE=$image UAVNAV_GRPC_PORT=$grpc_port UAVNAV_HTTP_PORT=$http_port UAVNAV_ZENOH_PORT=$zenoh_port
export UAVNAV_DRONES_PER_CONTAINER=$DRONES_PER_CONTAINER

cleanup() {
    local rc=$?
    trap - EXIT
    if [ "$rc" != 0 ]; then
        say "failure (exit $rc): last logs of the project"
        compose logs --no-color --tail=25 2>&1 | sed 's/^/    /' || true
    fi
    if [ "$keep" = 1 ]; then
        say "--keep: project $project left running (compose -p $project -f docker/compose.yaml down -v)"
    else
        compose down -v --remove-orphans >/dev/null 2>&1 || true
        docker image rm "$image" >/dev/null 2>&1 || true
    fi
    rm -rf "$tmp"
    exit "$rc"
}
trap cleanup EXIT
trap 'exit 130' INT TERM

# Containers of one service of the project (including exited ones), by compose's labels.
cid_of() {
    docker ps -aq --filter "label=com.docker.compose.project=$project" --filter "label=com.docker.compose.service=$1" | head -n1
}
# The service's own view, through our CLI inside the uavnavd container, as the operator (`ops`).
tls_as() { printf -- '--tls-ca /certs/ca.pem --tls-cert /certs/%s.pem --tls-key /certs/%s.key' "$1" "$1"; }
# shellcheck disable=SC2046 # word splitting of tls_as is intended
in_service() { docker exec "$svc" /usr/local/bin/uavnav "$@" --from grpcs://localhost:50051 $(tls_as ops); }
ids_of() { local p=$1; for k in $(seq 0 $((DRONES_PER_CONTAINER - 1))); do printf '%s%s ' "$p" "$k"; done; }
# "id:age" for the given ids, from `uavnav vehicles --json` (age "null" when never fed).
ages() {
    local json; json=$(in_service vehicles --json 2>/dev/null || true)
    for id in "$@"; do
        local age; age=$(grep "\"vehicle_id\":\"$id\"" <<<"$json" | sed -n 's/.*"input_age_s":\([^,}]*\).*/\1/p')
        printf '%s=%ss ' "$id" "$(printf '%.1f' "${age:-nan}" 2>/dev/null || echo "${age:-?}")"
    done
}
now() { date +%s.%N; }
# Seconds since a `now` value, one decimal; `before T LIMIT`: less than LIMIT seconds since T.
since() { awk -v a="$1" -v b="$(now)" 'BEGIN { printf "%.1f", b - a }'; }
before() { awk -v a="$1" -v b="$(now)" -v l="$2" 'BEGIN { exit !(b - a < l) }'; }
# The service's staleness rule (`uavnav health --max-age`): exit 0 fresh, 3 stale, else an error.
freshness() {
    local rc=0
    in_service health --vehicle "$1" --max-age "$STALE_AGE_S" --wait 0 >/dev/null 2>&1 || rc=$?
    case $rc in 0) echo fresh ;; 3) echo stale ;; *) echo "error($rc)" ;; esac
}
# True when every listed vehicle is in state $1 (fresh|stale).
all_are() {
    local want=$1 id; shift
    for id in "$@"; do [ "$(freshness "$id")" = "$want" ] || return 1; done
}

# --- 1. build ------------------------------------------------------------------------------------
if [ "$build" = 1 ]; then
    say "building $image (docker/build.sh ${build_args[*]} --profile $profile)"
    "$here/build.sh" "${build_args[@]}" --profile "$profile" --tag "$image"
else
    docker image inspect uavnav:latest >/dev/null || fail "--no-build: no image uavnav:latest"
    docker tag uavnav:latest "$image"
fi

# --- 2. up and healthy ---------------------------------------------------------------------------
say "compose up -d (project $project; host ports gRPC $grpc_port, HTTP $http_port, Zenoh $zenoh_port)"
t_up=$(now)
timeout "$UP_TIMEOUT" "${compose_cmd[@]}" -p "$project" -f "$here/compose.yaml" up -d 2>&1 | sed 's/^/    /' \
    || fail "compose up did not complete within $UP_TIMEOUT s"
svc=$(cid_of uavnavd)
[ -n "$svc" ] || fail "no uavnavd container"
deadline=$(( $(date +%s) + 60 ))
until [ "$(docker inspect -f '{{.State.Health.Status}}' "$svc")" = healthy ]; do
    [ "$(date +%s)" -lt "$deadline" ] || fail "uavnavd not healthy within 60 s of compose up"
    sleep 1
done
t_healthy_s=$(since "$t_up")
docker cp "$svc:/certs/ca.pem" "$tmp/ca.pem" || fail "no CA certificate in the certs volume"
for f in ops.pem ops.key; do docker cp "$svc:/certs/$f" "$tmp/$f" || fail "no $f in the certs volume"; done
# Every caller presents a certificate here (require_client_certificate), the probes' too.
say "uavnavd healthy $t_healthy_s s after compose up; /readyz over mutual TLS: $(curl -fsS --cacert "$tmp/ca.pem" --cert "$tmp/ops.pem" --key "$tmp/ops.key" "https://localhost:$http_port/readyz" 2>/dev/null || echo '(curl failed)')"

# --- security: nothing gets in without the deployment's certificates and grants -------------------
refused() { # refused WHAT CMD...: the command must fail
    local what=$1; shift
    if "$@" >/dev/null 2>&1; then fail "security: $what was let in"; fi
    say "security: $what refused"
}
# (the client retries a bare transport error for a while: 10 s is enough to know it got nothing)
refused "plaintext gRPC" timeout 10 docker exec "$svc" /usr/local/bin/uavnav vehicles --from grpc://127.0.0.1:50051
refused "TLS without a client certificate" docker exec "$svc" /usr/local/bin/uavnav vehicles \
    --from grpcs://localhost:50051 --tls-ca /certs/ca.pem
refused "plaintext HTTP" curl -fsS --max-time 3 "http://127.0.0.1:$http_port/readyz"
in_service vehicles >/dev/null || fail "security: the operator's certificate was refused"
say "security: the operator's certificate gets in"
t_healthy=$(now)
for s in recordings drones-a drones-b ground-station; do
    [ -n "$(cid_of "$s")" ] || fail "service $s has no container"
done
rec_exit=$(docker inspect -f '{{.State.ExitCode}}' "$(cid_of recordings)")
[ "$rec_exit" = 0 ] || fail "the recordings init container exited $rec_exit"

# The recording's truth, from the volume the drones replay (through the exited init container).
docker cp "$(cid_of recordings):/recordings/fleet/mav0/state_groundtruth_estimate0" "$tmp/truth" \
    || fail "cannot copy the truth out of the recordings volume"
read -r lat0 lon0 alt0 < <(sed -n 's/^origin: *\[\([^]]*\)\].*/\1/p' "$tmp/truth/sensor.yaml" | tr -d ' ' | tr ',' ' ')
[ -n "${alt0:-}" ] || fail "no origin in the truth's sensor.yaml"
say "recording truth: $(grep -vc '^#' "$tmp/truth/data.csv") samples, origin $lat0 $lon0 $alt0"

# --- 3. every drone's poses reach the ground station, accurately -----------------------------------
drones_a=$(ids_of drone-a-); drones_b=$(ids_of drone-b-)
gs=$(cid_of ground-station)
deadline=$(( $(date +%s) + FIRST_POSES_TIMEOUT ))
declare -A first_seen=()
while :; do
    docker cp "$gs:/data/poses.csv" "$tmp/poses.csv" 2>/dev/null || : >"$tmp/poses.csv"
    missing=""
    for id in $drones_a $drones_b; do
        rows=$(grep -c ",$id\$" "$tmp/poses.csv" || true)
        if [ "$rows" -gt 0 ] && [ -z "${first_seen[$id]:-}" ]; then first_seen[$id]=$(since "$t_healthy"); fi
        [ "$rows" -ge "$MIN_ROWS" ] || missing+=" $id($rows)"
    done
    [ -z "$missing" ] && break
    if [ "$(date +%s)" -ge "$deadline" ]; then
        fail "within $FIRST_POSES_TIMEOUT s of healthy, too few poses (< $MIN_ROWS) at the ground station for:$missing"
    fi
    sleep 2
done
say "every drone has >= $MIN_ROWS poses at the ground station, $(since "$t_healthy") s after healthy"
# The vehicle exists now: a refusal is the grant's, not an unknown vehicle's.
# shellcheck disable=SC2046
refused "the ground station resetting a drone" docker exec "$svc" /usr/local/bin/uavnav reset \
    --vehicle drone-a-0 --from grpcs://localhost:50051 $(tls_as ground-station)
for id in $drones_a $drones_b; do
    printf '    %-10s first pose at the ground station %5.1f s after healthy\n' "$id" "${first_seen[$id]}"
done

# Let every drone fly a while (turn and climb included) before scoring.
deadline=$(( $(date +%s) + SCORED_TIMEOUT ))
until [ "$(docker cp "$gs:/data/poses.csv" - 2>/dev/null | tar -xO | awk -F, -v n="$SCORED_ROWS" \
        'NR > 1 { c[$NF]++ } END { k = 0; for (i in c) if (c[i] >= n) k++; print k }')" -ge $((2 * DRONES_PER_CONTAINER)) ]; do
    [ "$(date +%s)" -lt "$deadline" ] || fail "fewer than $SCORED_ROWS poses for some drone $SCORED_TIMEOUT s later"
    sleep 2
done
docker cp "$gs:/data/poses.csv" "$tmp/poses.csv"
awk -v lat0="$lat0" -v lon0="$lon0" -v alt0="$alt0" -v skip_s="$ACCURACY_SKIP_S" \
    -f "$here/accuracy.awk" "$tmp/truth/data.csv" "$tmp/poses.csv" >"$tmp/accuracy.txt"
say "accuracy against the recording's truth (first $ACCURACY_SKIP_S s of each drone not scored):"
printf '    %-10s %6s %9s %9s %9s %9s\n' vehicle poses rms_h_m max_h_m rms_v_m max_v_m
bad=""
for id in $drones_a $drones_b; do
    line=$(awk -v id="$id" '$1 == id' "$tmp/accuracy.txt")
    [ -n "$line" ] || { bad+=" $id(no scored pose)"; continue; }
    read -r _ n rms_h max_h rms_v max_v <<<"$line"
    printf '    %-10s %6s %9s %9s %9s %9s\n' "$id" "$n" "$rms_h" "$max_h" "$rms_v" "$max_v"
    if [ "$n" -lt $((SCORED_ROWS / 2)) ] || ! awk -v r="$rms_h" -v m="$max_h" -v br="$MAX_RMS_H_M" -v bm="$MAX_H_M" 'BEGIN { exit !(r < br && m < bm) }'; then
        bad+=" $id"
    fi
done
[ -z "$bad" ] || fail "horizontal error above bounds (rms < $MAX_RMS_H_M m, max < $MAX_H_M m, >= $((SCORED_ROWS / 2)) scored poses) for:$bad"
say "every drone within rms_h < $MAX_RMS_H_M m and max_h < $MAX_H_M m"

# --- 4. a drone container loses its link, then gets it back --------------------------------------
drone_b=$(cid_of drones-b)
network=$(docker inspect -f '{{range $k, $v := .NetworkSettings.Networks}}{{$k}} {{end}}' "$drone_b" | awk '{print $1}')
all_are fresh $drones_b || fail "drones-b vehicles are not fresh before the disconnect: $(ages $drones_b)"
say "disconnecting drones-b from $network (input ages before: $(ages $drones_b))"
docker network disconnect "$network" "$drone_b"
t_disc=$(now)
until all_are stale $drones_b; do
    before "$t_disc" "$STALE_TIMEOUT" || fail "drones-b vehicles not stale $STALE_TIMEOUT s after the disconnect: $(ages $drones_b)"
    sleep 0.5
done
t_stale=$(since "$t_disc")
say "every drones-b vehicle stale (input age > $STALE_AGE_S s) $t_stale s after the disconnect: $(ages $drones_b)"
sleep "$HOLD_DISCONNECTED"
all_are fresh $drones_a || fail "drones-a vehicles went stale too while drones-b was disconnected: $(ages $drones_a)"
say "drones-a vehicles still fresh meanwhile: $(ages $drones_a)"
rows_before=$(docker cp "$gs:/data/poses.csv" - 2>/dev/null | tar -xO | grep -c ",drone-b-0\$" || true)
docker network connect "$network" "$drone_b"
t_conn=$(now)
say "reconnected drones-b after $(since "$t_disc") s offline"
until all_are fresh $drones_b; do
    [ "$(docker inspect -f '{{.State.Running}}' "$drone_b")" = true ] || fail "the drones-b container exited: $(docker logs --tail 5 "$drone_b" 2>&1)"
    before "$t_conn" "$RECOVER_TIMEOUT" || fail "drones-b vehicles not fresh again $RECOVER_TIMEOUT s after reconnecting: $(ages $drones_b)"
    sleep 0.5
done
t_recover=$(since "$t_conn")
say "every drones-b vehicle fresh again $t_recover s after reconnecting: $(ages $drones_b)"
deadline=$(( $(date +%s) + 30 ))
while :; do
    rows_after=$(docker cp "$gs:/data/poses.csv" - 2>/dev/null | tar -xO | grep -c ",drone-b-0\$" || true)
    [ "$rows_after" -gt "$rows_before" ] && break
    [ "$(date +%s)" -lt "$deadline" ] || fail "no new drone-b-0 pose at the ground station within 30 s of recovery"
    sleep 1
done
say "drone-b-0 poses at the ground station resumed ($rows_before -> $rows_after rows)"
in_service health --all --wait 1.5 | sed 's/^/    /'

# --- 5. down -v leaves nothing -------------------------------------------------------------------
if [ "$keep" = 1 ]; then say "PASS (project kept running)"; exit 0; fi
say "compose down -v"
compose down -v --remove-orphans 2>&1 | sed 's/^/    /'
left_c=$(docker ps -aq --filter "label=com.docker.compose.project=$project")
left_n=$(docker network ls -q --filter "label=com.docker.compose.project=$project")
left_v=$(docker volume ls -q --filter "label=com.docker.compose.project=$project")
left_named=$(docker volume ls -q | grep "^${project}_" || true)
[ -z "$left_c$left_n$left_v$left_named" ] || fail "left behind: containers [$left_c] networks [$left_n] volumes [$left_v $left_named]"
say "nothing of project $project left (containers, networks, volumes)"
say "PASS: healthy $t_healthy_s s after up; every drone's poses at the ground station within bounds; stale $t_stale s after the disconnect; fresh again $t_recover s after reconnecting"
