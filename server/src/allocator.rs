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

/// Called by each async worker thread when it parks (it has nothing to run): the thread's heap
/// gives back what it no longer uses.
///
/// Why: mimalloc keeps a thread's emptied pages, and the blocks other threads freed into it, until
/// that thread allocates again — and an idle worker seldom does. After issue 19's attacks (`memory`
/// bench, five attacks in turn, their vehicles evicted) the service stayed at 28.1–31.0 MiB
/// against a 16.7–17.2 MiB baseline, 12–15 MiB of it anonymous.
///
/// Why at every park: collections used to be at most one a second per thread, and that kept most
/// of what a burst left behind. A worker's last park after a burst usually falls within the
/// second of its previous collection, is skipped, and the worker then sleeps, holding the heap,
/// until work comes again. After a flood of 20,000 new ids without Zenoh (whose threads
/// otherwise wake the workers now and then), the anonymous memory stayed at 44.5 MiB against a
/// 2.8 MiB baseline; collecting at every park: 4.3 MiB (`cargo bench -p uavnavd --bench memory
/// -- --only 1 --no-zenoh`). The cost did not show: 1,000 vehicles in real time, 0.76 / 0.74
/// cores with the limit and 0.76 / 0.73 without, p99 25.6 / 25.7 against 25.8 / 25.9 ms
/// (`--bench fleet -- --vehicles 1000 --duration-s 10`, back to back); one normal collection,
/// `mi_collect(false)`, took 0.1 µs with 100 MB of small blocks live on the thread (measured once,
/// release build).
///
/// Why forced: a normal collection skips the pages it holds as full (mimalloc 3 does not visit
/// them: a page whose blocks other threads have since freed stays in the full queue, emptied but
/// kept), keeps the pages it retired a moment ago for reuse, and purges only what the arenas
/// already marked as due. A forced one visits every page of the thread, frees the retired ones
/// and purges the arenas' free pages now. After all of the `memory` bench's attacks (release,
/// 2026-12-07): +17 / +18 / +19 % above the warm baseline in three runs, anonymous 9.0–9.1 MiB
/// against 5.5–5.6, where a normal collection left +22 / +23 % (anonymous 9.2–10.2 MiB); the
/// stalled-streams attack alone +9 % against +13–14 %. Its cost did not show either: under
/// `uavnav loadtest --no-camera --decimation 10` with 600 and 900 vehicles, `perf` put the
/// collection's functions at 0.8 % of the service's CPU (0.6 % of it `_mi_page_free_collect`,
/// which frees as often without the collection: 0.35–0.5 % in the same runs before).
pub fn collect_on_park() {
    collect_this_thread();
}

/// The one call into the allocator's C API (the workspace denies `unsafe` everywhere else).
#[allow(unsafe_code)]
fn collect_this_thread() {
    // SAFETY: `mi_collect` has no preconditions: it walks the calling thread's own heap and
    // (forced) purges the arenas' free pages under their own locks; it is safe to call from any
    // thread at any time.
    unsafe { libmimalloc_sys::mi_collect(true) };
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What the collection gives back is measured by the `memory` bench (under mimalloc, which
    /// this library's own tests do not run with); here: it can run on any thread, any number of
    /// times, with memory freed by another thread pending.
    #[test]
    fn a_thread_can_collect_at_every_park() {
        let junk: Vec<Vec<u8>> = (0..1000).map(|i| vec![0u8; 100 + i]).collect();
        std::thread::spawn(move || {
            drop(junk);
            for _ in 0..3 {
                collect_on_park();
            }
        })
        .join()
        .unwrap();
        collect_on_park();
    }
}
