//! # uavnav-vision
//!
//! The camera front end of the paper's section IV: IMU-aided KLT tracking and camera egomotion
//! with a first-order covariance, plus a plane-aware solver for flight over flat ground.
//! Pure and synchronous: no I/O, no clock (timings come from an injected [`frontend::Clock`]),
//! deterministic (seeded RANSAC), buffers reused across frames.
//!
//! | module | what it holds |
//! |---|---|
//! | [`frontend`] | [`FrontEnd`]: decode → pyramid → checks → aided KLT → solve; [`VisionParams`], [`FrameResult`], [`NoMeasurement`] |
//! | [`decode`] | JPEG/PNG → 8-bit luma into a reused buffer |
//! | [`pyramid`] | 8-bit frame + `f32` coarse levels, pyramid, frame statistics (black/saturated/textureless/blurred) |
//! | [`klt`] | pyramidal Lucas–Kanade (eq. 12), vectorizable kernels, template reuse |
//! | [`corners`] | Shi–Tomasi corner of a grid cell (box-summed structure tensors) |
//! | [`essential`] | 8-point (eqs. 13–17), Huang–Faugeras (18–20), cheirality, covariance (22–28), Sampson refinement |
//! | [`plane`] | plane-aware solver: known ground normal/distance → metric translation |
//! | [`robust`] | seeded RANSAC + local optimisation for rotation, essential and plane models |
//! | [`solve`] | per-frame solver choice ([`Method`]) and the [`solve::Solution`] |
//! | [`prior`] | gyro integration into a rotation prior |
//! | [`report`] | CLI pieces: CSV row, error statistics against truth |
//! | [`synthetic`] | deterministic textures and ground-plane views for tests and benchmarks |
//!
//! Geometry convention: `x1 = R x0 + t` with `R = cam1_from_cam0` and `t` in camera 1
//! (see [`uavnav_core::Egomotion`]).

pub mod corners;
pub mod decode;
pub mod essential;
pub mod frontend;
pub mod klt;
pub mod plane;
pub mod prior;
pub mod pyramid;
pub mod report;
pub mod robust;
pub mod solve;
pub mod synthetic;

pub use frontend::{Clock, FrameResult, FrontEnd, NoMeasurement, StageTimings, VisionParams};
pub use report::{CSV_HEADER, ErrorStats, PairError, csv_row, error_stats, pair_error};
pub use solve::{Method, SolveParams};
