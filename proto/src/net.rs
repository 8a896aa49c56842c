//! Host names both ends check: the service before it serves in clear, the client before it sends
//! a token in clear. Std only (it is here because both depend on this crate, not for the wire).

use std::net::IpAddr;

/// Whether `host` (an IP, `[v6]`, or a name) names this machine: `localhost` or a loopback
/// address. Other names are not resolved: a name that happens to resolve to loopback is treated
/// as a network host (the safe side for both checks).
pub fn is_loopback_host(host: &str) -> bool {
    let h = host.trim_start_matches('[').trim_end_matches(']');
    h.eq_ignore_ascii_case("localhost") || h.parse::<IpAddr>().is_ok_and(|ip| ip.is_loopback())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loopback_hosts() {
        for h in [
            "127.0.0.1",
            "127.3.2.1",
            "::1",
            "[::1]",
            "LOCALHOST",
            "localhost",
        ] {
            assert!(is_loopback_host(h), "{h}");
        }
        for h in [
            "10.0.0.1",
            "0.0.0.0",
            "[::]",
            "uavnavd",
            "localhost.example",
            "",
        ] {
            assert!(!is_loopback_host(h), "{h}");
        }
    }
}
