//! The client library's tests, in one test binary: each module was once its own binary, and each
//! linked the service at opt-level 3 (see `server/tests/service/main.rs`).
//!
//! Run one module with e.g. `cargo test -p uavnav-client --test client restart::`.
#![allow(clippy::unwrap_used)] // tests, examples and benches may unwrap

#[path = "../common/mod.rs"]
mod common;

// The library with its Zenoh transport and recording reader, when the features build them.
#[cfg(feature = "zenoh")]
mod library;
#[cfg(feature = "recording")]
mod recording_reader;
mod restart;
mod secure_service;
