//! The `uavnav` binary's tests, in one test binary: each module was once its own binary, and each
//! linked the CLI with the whole service at opt-level 3 (see `server/tests/service/main.rs`).
//!
//! Run one module with e.g. `cargo test -p uavnav-cli --test uavnav logs::`.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

#[path = "../common/mod.rs"]
mod common;
#[path = "../tls_fake/mod.rs"]
mod tls_fake;

mod cli;
mod loadtest;
mod logs;
mod recording;
mod security;
