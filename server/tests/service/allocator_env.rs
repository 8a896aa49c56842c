//! The `uavnavd` binary re-executes itself once with the allocator options of a long-running
//! service (`uavnavd::allocator::ALLOCATOR_ENV`), keeping the pid and the
//! arguments, and leaves alone what the environment already sets.
#![cfg(target_os = "linux")]
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The environment of a running process, as `KEY=VALUE` strings.
fn environ(pid: u32) -> Vec<String> {
    std::fs::read(format!("/proc/{pid}/environ"))
        .unwrap_or_default()
        .split(|b| *b == 0)
        .map(|s| String::from_utf8_lossy(s).into_owned())
        .collect()
}

/// Starts the binary with `env` (and no other MIMALLOC_ variable), waits until it has
/// re-executed, and returns its environment.
fn run_with(env: &[(&str, &str)]) -> Vec<String> {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_uavnavd"));
    cmd.args([
        "--no-zenoh",
        "--grpc-addr",
        "127.0.0.1:0",
        "--http-addr",
        "127.0.0.1:0",
    ])
    .env_remove("UAVNAVD_ALLOCATOR_OPTIONS_SET")
    .env_remove("UAVNAV_CONFIG")
    .stdout(Stdio::null())
    .stderr(Stdio::null());
    for (k, _) in uavnavd::allocator::ALLOCATOR_ENV {
        cmd.env_remove(k);
    }
    for (k, v) in env {
        cmd.env(k, v);
    }
    let mut child = cmd.spawn().unwrap();
    let pid = child.id();
    let deadline = Instant::now() + Duration::from_secs(20);
    let mut seen = Vec::new();
    while Instant::now() < deadline {
        seen = environ(pid);
        if seen.iter().any(|e| e == "UAVNAVD_ALLOCATOR_OPTIONS_SET=1") {
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let still_running = child.try_wait().unwrap().is_none();
    let _ = child.kill();
    let _ = child.wait();
    assert!(still_running, "uavnavd exited: {seen:?}");
    seen
}

#[test]
fn the_service_runs_with_the_allocator_options_of_a_long_running_process() {
    let env = run_with(&[]);
    for (k, v) in uavnavd::allocator::ALLOCATOR_ENV {
        assert!(env.iter().any(|e| *e == format!("{k}={v}")), "{k}: {env:?}");
    }
}

#[test]
fn options_set_by_the_environment_are_kept() {
    let env = run_with(&[("MIMALLOC_PURGE_DELAY", "250")]);
    assert!(
        env.iter().any(|e| e == "MIMALLOC_PURGE_DELAY=250"),
        "{env:?}"
    );
    assert!(
        env.iter().any(|e| e == "MIMALLOC_ARENA_EAGER_COMMIT=0"),
        "{env:?}"
    );
}
