//! What leaves the vehicles: the pose and health fan-out, the health reports, the recording.
//!
//! | file | responsibility |
//! |---|---|
//! | [`hub`] | broadcast fan-out of poses and health |
//! | [`health`] | per-vehicle health reports |
//! | [`record`] | recording of accepted inputs and poses to rotating MCAP files |

pub mod health;
pub mod hub;
pub mod record;
