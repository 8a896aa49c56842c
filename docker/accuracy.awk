# Horizontal and vertical position error of watched poses against a recording's truth, per vehicle.
#
#   awk -v lat0=DEG -v lon0=DEG -v alt0=M -v skip_s=S -f docker/accuracy.awk TRUTH.csv POSES.csv
#
# TRUTH.csv: the ASL `state_groundtruth_estimate0/data.csv` (timestamp ns, body position in the local
# NED frame at the origin lat0/lon0/alt0, ...). POSES.csv: `uavnav watch` CSV (the `uavnav estimate`
# columns timestamp_ns, latitude_deg, longitude_deg, altitude_m, ..., then vehicle_id). Every copy of
# the recording keeps its sensor times, so all vehicles compare against the same truth. Geodetic
# positions go to NED exactly (WGS84 -> ECEF -> NED at the origin): a flat-earth shortcut would be off
# by metres a few kilometres out. Truth is interpolated linearly at each pose time; poses in the first
# skip_s seconds of each vehicle's output (filter convergence) are not scored.
#
# Output, one line per vehicle:  vehicle_id n rms_h_m max_h_m rms_v_m max_v_m
BEGIN {
    FS = ","
    pi = atan2(0, -1); a = 6378137.0; f = 1 / 298.257223563; e2 = f * (2 - f)
    ecef(lat0, lon0, alt0); x0 = X; y0 = Y; z0 = Z
    sp0 = sin(lat0 * pi / 180); cp0 = cos(lat0 * pi / 180)
    sl0 = sin(lon0 * pi / 180); cl0 = cos(lon0 * pi / 180)
    nt = 0
}
function ecef(lat, lon, h,    p, l, s, n) {
    p = lat * pi / 180; l = lon * pi / 180; s = sin(p)
    n = a / sqrt(1 - e2 * s * s)
    X = (n + h) * cos(p) * cos(l); Y = (n + h) * cos(p) * sin(l); Z = (n * (1 - e2) + h) * s
}
function ned(lat, lon, h,    dx, dy, dz) {
    ecef(lat, lon, h); dx = X - x0; dy = Y - y0; dz = Z - z0
    N = -sp0 * cl0 * dx - sp0 * sl0 * dy + cp0 * dz
    E = -sl0 * dx + cl0 * dy
    D = -cp0 * cl0 * dx - cp0 * sl0 * dy - sp0 * dz
}
# Truth at time t by binary search + linear interpolation; 0 when t is outside the truth.
function truth_at(t,    lo, hi, mid, w) {
    if (nt < 2 || t < tt[1] || t > tt[nt]) return 0
    lo = 1; hi = nt
    while (hi - lo > 1) { mid = int((lo + hi) / 2); if (tt[mid] <= t) lo = mid; else hi = mid }
    w = (tt[hi] > tt[lo]) ? (t - tt[lo]) / (tt[hi] - tt[lo]) : 0
    TN = tn[lo] + w * (tn[hi] - tn[lo]); TE = te[lo] + w * (te[hi] - te[lo]); TD = td[lo] + w * (td[hi] - td[lo])
    return 1
}
FNR == NR {
    if ($1 ~ /^#/ || $1 == "") next
    nt++; tt[nt] = $1 + 0; tn[nt] = $2 + 0; te[nt] = $3 + 0; td[nt] = $4 + 0
    next
}
FNR == 1 { for (i = 1; i <= NF; i++) col[$i] = i; next }
{
    id = $col["vehicle_id"]; t = $col["timestamp_ns"] + 0
    if (!(id in first)) { first[id] = t; ids[++nid] = id }
    if (t - first[id] < skip_s * 1e9) next
    if (!truth_at(t)) next
    ned($col["latitude_deg"], $col["longitude_deg"], $col["altitude_m"])
    eh2 = (N - TN) ^ 2 + (E - TE) ^ 2; ev = D - TD
    n[id]++; sh[id] += eh2; sv[id] += ev * ev
    if (eh2 > mh[id]) mh[id] = eh2
    if (ev * ev > mv[id]) mv[id] = ev * ev
}
END {
    for (k = 1; k <= nid; k++) {
        id = ids[k]
        if (n[id] == 0) { printf "%s 0 nan nan nan nan\n", id; continue }
        printf "%s %d %.3f %.3f %.3f %.3f\n", id, n[id], sqrt(sh[id] / n[id]), sqrt(mh[id]), sqrt(sv[id] / n[id]), sqrt(mv[id])
    }
}
