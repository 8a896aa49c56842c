//! Configuration: defaults < file < environment < flags; unknown keys are named.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::collections::HashMap;
use std::io::Write;

use uavnavd::Config;
use uavnavd::config::{ConfigError, ZenohMode};

fn env(pairs: &[(&str, &str)]) -> impl Fn(&str) -> Option<String> + use<> {
    let m: HashMap<String, String> = pairs
        .iter()
        .map(|(k, v)| (k.to_string(), v.to_string()))
        .collect();
    move |k| m.get(k).cloned()
}

#[test]
fn defaults_match_the_issue() {
    let c = Config::load(["uavnavd"], env(&[])).unwrap();
    // Loopback only, in clear (issue 20: plaintext is for loopback unless --insecure).
    assert_eq!(c.grpc.addr.to_string(), "127.0.0.1:50051");
    assert_eq!(c.http.addr.to_string(), "127.0.0.1:9464");
    assert_eq!(c.zenoh.mode, ZenohMode::Peer);
    assert_eq!(c.zenoh.listen, vec!["tcp/127.0.0.1:7447".to_string()]);
    assert!(!c.security.insecure && c.security.tls.is_none() && !c.grpc.reflection);
    assert!(c.zenoh.enabled);
    assert!(c.grpc.max_message_bytes >= 8 << 20);
}

#[test]
fn file_then_env_then_flags() {
    let mut f = tempfile::NamedTempFile::new().unwrap();
    writeln!(f, "[grpc]\naddr = \"127.0.0.1:1000\"\n[http]\naddr = \"127.0.0.1:2000\"\n[zenoh]\nmode = \"client\"\nconnect = [\"tcp/10.0.0.1:7447\"]\n[vehicles]\nidle_evict_s = 5.0").unwrap();
    let path = f.path().to_str().unwrap().to_string();
    // A plaintext Zenoh link to another host is refused, naming it, unless insecure.
    let e = Config::load(["uavnavd", "--config", &path], env(&[])).unwrap_err();
    assert!(
        e.to_string().contains("zenoh.connect tcp/10.0.0.1:7447"),
        "{e}"
    );
    assert!(Config::load(["uavnavd", "--config", &path, "--insecure"], env(&[])).is_ok());
    let mut f2 = tempfile::NamedTempFile::new().unwrap();
    writeln!(f2, "[grpc]\naddr = \"127.0.0.1:1000\"\n[http]\naddr = \"127.0.0.1:2000\"\n[zenoh]\nmode = \"client\"\nconnect = [\"tcp/10.0.0.1:7447\"]\n[vehicles]\nidle_evict_s = 5.0\n[security]\ninsecure = true").unwrap();
    let path = f2.path().to_str().unwrap().to_string();
    // File only.
    let c = Config::load(["uavnavd", "--config", &path], env(&[])).unwrap();
    assert_eq!(c.grpc.addr.port(), 1000);
    assert_eq!(c.zenoh.mode, ZenohMode::Client);
    assert_eq!(c.vehicles.idle_evict_s, 5.0);
    // Environment over the file (UAVNAV_CONFIG names the file too).
    let e = env(&[
        ("UAVNAV_CONFIG", &path),
        ("UAVNAV_GRPC_ADDR", "127.0.0.1:1001"),
        ("UAVNAV_ZENOH_MODE", "router"),
    ]);
    let c = Config::load(["uavnavd"], &e).unwrap();
    assert_eq!(c.grpc.addr.port(), 1001);
    assert_eq!(c.http.addr.port(), 2000, "file value kept");
    assert_eq!(c.zenoh.mode, ZenohMode::Router);
    // Flags over the environment.
    let c = Config::load(
        [
            "uavnavd",
            "--grpc-addr",
            "127.0.0.1:1002",
            "--zenoh-mode",
            "peer",
            "--zenoh-listen",
            "tcp/127.0.0.1:1",
            "--zenoh-listen",
            "udp/127.0.0.1:2",
            "--zenoh-connect",
            "tcp/127.0.0.1:3",
            "--zenoh-config",
            "/z.json5",
            "--no-zenoh",
        ],
        &e,
    )
    .unwrap();
    assert_eq!(c.grpc.addr.port(), 1002);
    assert_eq!(c.zenoh.mode, ZenohMode::Peer);
    assert_eq!(c.zenoh.listen, vec!["tcp/127.0.0.1:1", "udp/127.0.0.1:2"]);
    assert_eq!(c.zenoh.connect, vec!["tcp/127.0.0.1:3"]);
    assert_eq!(
        c.zenoh.config_file.as_deref(),
        Some(std::path::Path::new("/z.json5"))
    );
    assert!(!c.zenoh.enabled);
    assert_eq!(c.http.addr.port(), 2000);
}

#[test]
fn unknown_keys_and_bad_values_are_named() {
    let mut f = tempfile::NamedTempFile::new().unwrap();
    writeln!(f, "[vehicles]\nreorder_windw_ms = 5.0").unwrap();
    let err = Config::load(
        ["uavnavd", "--config", f.path().to_str().unwrap()],
        env(&[]),
    )
    .unwrap_err();
    assert!(matches!(err, ConfigError::Parse { .. }));
    assert!(err.to_string().contains("reorder_windw_ms"), "{err}");

    let mut f = tempfile::NamedTempFile::new().unwrap();
    writeln!(f, "[nonsense]\nx = 1").unwrap();
    let err = Config::load(
        ["uavnavd", "--config", f.path().to_str().unwrap()],
        env(&[]),
    )
    .unwrap_err();
    assert!(err.to_string().contains("nonsense"), "{err}");

    let err = Config::load(["uavnavd"], env(&[("UAVNAV_ZENOH_MODE", "mesh")])).unwrap_err();
    assert!(err.to_string().contains("UAVNAV_ZENOH_MODE"), "{err}");
    assert!(Config::load(["uavnavd", "--zenoh-mode", "mesh"], env(&[])).is_err());
    assert!(Config::load(["uavnavd", "--bogus"], env(&[])).is_err());
}
