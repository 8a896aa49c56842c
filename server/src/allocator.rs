//! The allocator's options for a long-running service. mimalloc reads its options from the
//! environment when the process starts, before `main`, so the binaries that run the service
//! (`uavnavd`, the `memory` bench) re-execute themselves once with them set: same pid, same
//! arguments (`std::os::unix::process::CommandExt::exec`).

/// mimalloc options for a long-running service, applied unless the environment sets them.
///
/// - `MIMALLOC_PURGE_DELAY=0`: memory freed returns to the OS at once. With mimalloc's 1 s delay
///   the purge runs only when the allocator is busy again, so after a burst (a flood of vehicle
///   ids, large batches, camera vehicles) an idle service kept up to 192 MiB more (the `memory`
///   bench).
/// - `MIMALLOC_ARENA_EAGER_COMMIT=0`: arenas are committed as they are used, not up front (the
///   service at rest: 29 → 19 MiB).
/// - `MIMALLOC_ABANDONED_PAGE_PURGE=1`, `MIMALLOC_ABANDONED_RECLAIM_ON_FREE=1`: the free pages
///   of a thread that exits are returned at once, and a block it left is taken back by the thread
///   that frees it. With the vision workers' hand-over after an idle spell
///   (`vehicle::vision_pool`), what 16 camera vehicles of 2048×2048 kept after they left went
///   from 11.5 to 6.7 MiB (`memory` bench, `--only 4`).
///
/// Measured with `uavnav loadtest --no-camera --vehicles 2000 --duration 60s --decimation 10`:
/// 3.53 µs of CPU per IMU sample and 125 MiB resident without them, 3.61 µs and 102 MiB with
/// them (within the run-to-run spread of these machines).
pub const ALLOCATOR_ENV: [(&str, &str); 4] = [
    ("MIMALLOC_PURGE_DELAY", "0"),
    ("MIMALLOC_ARENA_EAGER_COMMIT", "0"),
    ("MIMALLOC_ABANDONED_PAGE_PURGE", "1"),
    ("MIMALLOC_ABANDONED_RECLAIM_ON_FREE", "1"),
];

/// Set on the re-executed process, so that it never re-executes again.
pub const REEXEC_GUARD: &str = "UAVNAVD_ALLOCATOR_OPTIONS_SET";

/// Re-executes this binary with [`ALLOCATOR_ENV`] (what the environment does not set already)
/// unless it did already; returns when nothing is to be done or the exec failed.
#[cfg(unix)]
pub fn apply_service_options() {
    use std::os::unix::process::CommandExt;
    if std::env::var_os(REEXEC_GUARD).is_some() {
        return;
    }
    let missing: Vec<_> = ALLOCATOR_ENV
        .iter()
        .filter(|(k, _)| std::env::var_os(k).is_none())
        .collect();
    if missing.is_empty() {
        return;
    }
    let Ok(exe) = std::env::current_exe() else {
        return;
    };
    let mut cmd = std::process::Command::new(exe);
    cmd.args(std::env::args_os().skip(1)).env(REEXEC_GUARD, "1");
    for (k, v) in missing {
        cmd.env(k, v);
    }
    // Returns only when the exec failed: the service then runs with the allocator's defaults.
    let err = cmd.exec();
    eprintln!("uavnavd: could not re-execute with the allocator options ({err}); running without");
}

/// Nothing to do off Unix (no exec): the allocator's defaults apply.
#[cfg(not(unix))]
pub fn apply_service_options() {}
