//! The vehicles: one actor per vehicle owning its engine, the registry that finds it, and the
//! shared face the rest of the service reads without asking the actor.
//!
//! | file | responsibility |
//! |---|---|
//! | [`registry`] | vehicle id → actor handle; creation on first data, removal on eviction |
//! | [`actor`] | one task per vehicle owning its engine; bounded queues, reorder, overload policy |
//! | [`queue`] | an actor's ordered input queue: bounded in messages, senders wait for room |
//! | [`shared`] | the shared face of a vehicle: counters, the ingest time gate's state, latest pose/health (re-exported here) |
//! | [`budgets`] | the budgets the actors share: queued sensor bytes, queued camera bytes, camera pixels |
//! | [`ticks`] | an actor's health ticks, aligned to its start |
//! | [`reorder`] | the bounded timestamp reorder window |
//! | [`engine`] | the seam to the estimator ([`engine::Engine`]) |
//! | [`runner_engine`] | the product engine (the estimator runner) |
//! | [`vision_pool`] | bounded OS-thread pool for vision work |

pub mod actor;
pub mod budgets;
pub mod engine;
pub mod queue;
pub mod registry;
pub mod reorder;
pub mod runner_engine;
pub mod shared;
pub mod ticks;
pub mod vision_pool;

pub use shared::{INPUT_KINDS, InputKind, VehicleShared, VehicleStats, mono_now, wall_ns};

/// The ingest time gate, re-exported at its former paths (`crate::vehicle::TimeGate`, ...), from
/// before it moved to [`crate::ingest::gate`].
pub use crate::ingest::gate::{Admitted, GateLimits, GateRefusal, TimeGate};
