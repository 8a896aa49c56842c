#!/usr/bin/env bash
# Fails when
# - a pure crate (no I/O, no clock, no runtime) reaches the async runtime, the RPC stack, the
#   protobuf runtime or the network middleware through its normal dependencies;
# - the client library (what a ground-station backend adds) reaches any crate of ours other than
#   the wire contract (uavnav-proto, and uavnav-core through it) — the service, the simulator, the
#   vision front end, the estimator, the runner, the report, the datasets, the CLI — or plotters,
#   with its default features (the superset: zenoh and recording);
# - the tests of a crate below the service (pure crates, datasets, logs, report) link the service
#   or zenoh: they would wait for them to build and link them into every test binary (the real-data
#   tests find their data through `uavnav-testdata`, not the service's test kit);
# - a crate that Cargo.toml builds at opt-level 0 as build-time-only code (proc macros, code
#   generators) is reached at run time, where the tests would run it unoptimised.
set -euo pipefail
cd "$(dirname "$0")/.."
status=0
# The names of the crates in a package's normal dependency tree. Called as `x=$(crates_of P)` so
# that a failing `cargo tree` (stale lock file, unknown package) stops the guard (set -e).
crates_of() {
    local tree
    tree=$(cargo tree -p "$1" -e normal --prefix none --locked) || return 1
    printf '%s\n' "$tree" | awk '{print $1}' | sort -u
}
for crate in uavnav-core uavnav-sim uavnav-vision uavnav-estimator uavnav-runner; do
    crates=$(crates_of "$crate")
    bad=$(printf '%s\n' "$crates" | grep -E '^(tokio|tonic|prost|zenoh)$' || true)
    if [ -n "$bad" ]; then
        echo "dependency guard: pure crate $crate reaches: $(echo $bad | tr '\n' ' ')" >&2
        status=1
    fi
done
crates=$(crates_of uavnav-client)
bad=$(printf '%s\n' "$crates" | grep -E '^(uavnav|plotters)' | grep -vxE 'uavnav-(client|proto|core)' || true)
if [ -n "$bad" ]; then
    echo "dependency guard: the client library uavnav-client reaches: $(echo $bad | tr '\n' ' ')(allowed of ours: uavnav-proto, uavnav-core)" >&2
    status=1
fi
for crate in uavnav-core uavnav-sim uavnav-vision uavnav-estimator uavnav-runner uavnav-dataset uavnav-logs uavnav-report; do
    tree=$(cargo tree -p "$crate" -e normal,dev --prefix none --locked) || exit 1
    bad=$(printf '%s\n' "$tree" | awk '{print $1}' | sort -u | grep -xE 'uavnavd|uavnav-tests|zenoh' || true)
    if [ -n "$bad" ]; then
        echo "dependency guard: the tests of $crate reach: $(echo $bad | tr '\n' ' ')" >&2
        status=1
    fi
done
runtime=$(cargo tree --workspace -e normal,dev,no-proc-macro --prefix none --locked) || exit 1
runtime=$(printf '%s\n' "$runtime" | awk '{print $1}' | sort -u)
build_only=$( (grep -E '^[A-Za-z0-9_-]+ = \{ opt-level = 0, debug = false \}' Cargo.toml || true) | awk '{print $1}' | sort -u)
bad=$(comm -12 <(printf '%s\n' "$runtime") <(printf '%s\n' "$build_only"))
if [ -n "$bad" ]; then
    echo "dependency guard: Cargo.toml builds these at opt-level 0 as build-time code, but they run in the service or tests: $(echo $bad | tr '\n' ' ')" >&2
    status=1
fi
[ "$status" -eq 0 ] && echo "dependency guard: the pure crates reach no tokio, tonic, prost or zenoh; uavnav-client reaches no crate of ours beyond uavnav-proto and uavnav-core, and no plotters; the tests below the service link no service or zenoh; no build-time-only crate runs unoptimised"
exit "$status"
