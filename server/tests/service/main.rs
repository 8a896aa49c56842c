//! The service's integration tests, in one test binary: each module was once its own binary,
//! and every binary linked the whole service (zenoh, tonic) at opt-level 3, which made the
//! service's test build the largest share of CI. Tests that change process-wide state (the
//! open-file limit: `fd_exhaustion.rs`) or measure the process's own memory
//! (`amplification.rs`) run in a child process of this binary (`own_process.rs`).
//!
//! Run one module with e.g. `cargo test -p uavnavd --test service hostile::`.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

#[path = "../common/mod.rs"]
mod common;

mod own_process;

mod ack_runs;
mod actor_time;
mod admission;
mod allocator_env;
mod amplification;
mod arrivals;
mod bad_input;
mod config_precedence;
mod connections;
mod e2e_flight;
mod fd_exhaustion;
mod fleet;
mod hostile;
mod kit;
mod live;
mod liveliness;
mod reconfigure;
mod record;
mod security;
mod shutdown;
mod stalled_watch;
mod zenoh;
mod zenoh_security;
mod zenoh_slow;
