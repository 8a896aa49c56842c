#!/usr/bin/env bash
# Fails when a pure crate (no I/O, no clock, no runtime) reaches the async runtime, the RPC stack,
# the protobuf runtime or the network middleware through its normal dependencies.
set -euo pipefail
cd "$(dirname "$0")/.."
status=0
for crate in uavnav-core uavnav-sim uavnav-vision uavnav-estimator uavnav-runner; do
    tree=$(cargo tree -p "$crate" -e normal --prefix none --locked)
    bad=$(printf '%s\n' "$tree" | awk '{print $1}' | sort -u | grep -E '^(tokio|tonic|prost|zenoh)$' || true)
    if [ -n "$bad" ]; then
        echo "dependency guard: pure crate $crate reaches: $(echo $bad | tr '\n' ' ')" >&2
        status=1
    fi
done
[ "$status" -eq 0 ] && echo "dependency guard: the pure crates reach no tokio, tonic, prost or zenoh"
exit "$status"
