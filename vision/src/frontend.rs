//! The per-frame pipeline: decode → pyramid → frame checks → IMU-aided KLT with a
//! forward–backward check → egomotion → feature replenishment.

use nalgebra::{Isometry3, Matrix2, Matrix3, Point2, Unit, UnitQuaternion, Vector2, Vector3};
use thiserror::Error;
use uavnav_core::rng::Rng;
use uavnav_core::{CameraModel, Egomotion, EgomotionSolver, ImageFormat, MotionPrior};

use crate::corners::{CornerScratch, best_corner_with};
use crate::decode::{DecodeError, LumaDecoder};
use crate::essential::to_quat;
use crate::klt::{Affine, KltParams, KltScratch, Slot, invert2, track_with_templates};
use crate::pyramid::{Pyramid, frame_stats};
use crate::solve::{SolveParams, SolveScratch, solve};

/// Why a frame pair gave no egomotion.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum NoMeasurement {
    /// First frame, or the previous frame was rejected: nothing to pair with.
    #[error("no reference frame (first frame or previous frame rejected)")]
    NoReference,
    /// The frame could not be decoded (corrupt or truncated).
    #[error("decode error: {0}")]
    Decode(String),
    /// The frame size differs from the configured camera.
    #[error("frame is {got_w}x{got_h}, camera expects {want_w}x{want_h}")]
    SizeMismatch {
        /// Decoded width.
        got_w: u32,
        /// Decoded height.
        got_h: u32,
        /// Expected width.
        want_w: u32,
        /// Expected height.
        want_h: u32,
    },
    /// Frame (nearly) black.
    #[error("black frame (mean {mean:.1})")]
    Black {
        /// Mean intensity.
        mean: f32,
    },
    /// Frame (nearly) saturated.
    #[error("saturated frame (mean {mean:.1}, {fraction:.2} of pixels saturated)")]
    Saturated {
        /// Mean intensity.
        mean: f32,
        /// Saturated fraction.
        fraction: f32,
    },
    /// No contrast.
    #[error("textureless frame (std {std:.2})")]
    Textureless {
        /// Intensity standard deviation.
        std: f32,
    },
    /// Fine detail missing (motion or focus blur).
    #[error("blurred frame (sharpness {sharpness:.2})")]
    Blurred {
        /// Sharpness figure, see [`crate::pyramid::FrameStats::sharpness`].
        sharpness: f32,
    },
    /// Too few features tracked into the new frame.
    #[error("too few tracks ({tracked} < {needed})")]
    TooFewTracks {
        /// Tracked features.
        tracked: u32,
        /// Needed.
        needed: u32,
    },
    /// Too few inliers for a trustworthy solution.
    #[error("too few inliers ({inliers})")]
    TooFewInliers {
        /// Inliers found.
        inliers: u32,
    },
    /// The plane method was requested but the prior has no ground normal/distance.
    #[error("plane method requested without a ground prior")]
    NoGroundPrior,
    /// The geometry is not determined.
    #[error("degenerate geometry: {0}")]
    Degenerate(&'static str),
}

impl NoMeasurement {
    /// Short machine-readable tag (CSV `reason` column).
    pub fn tag(&self) -> &'static str {
        match self {
            NoMeasurement::NoReference => "no_reference",
            NoMeasurement::Decode(_) => "decode_error",
            NoMeasurement::SizeMismatch { .. } => "size_mismatch",
            NoMeasurement::Black { .. } => "black",
            NoMeasurement::Saturated { .. } => "saturated",
            NoMeasurement::Textureless { .. } => "textureless",
            NoMeasurement::Blurred { .. } => "blurred",
            NoMeasurement::TooFewTracks { .. } => "too_few_tracks",
            NoMeasurement::TooFewInliers { .. } => "too_few_inliers",
            NoMeasurement::NoGroundPrior => "no_ground_prior",
            NoMeasurement::Degenerate(_) => "degenerate",
        }
    }
}

/// Front-end settings. Defaults target 640×480 at 20–30 Hz.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VisionParams {
    /// Target number of features (one per grid cell). Default 250.
    pub max_features: usize,
    /// Pyramid levels built and used without a prior. Default 3.
    pub pyramid_levels: usize,
    /// Levels used when the prior predicts the whole flow (rotation, terrain and translation;
    /// paper IV-A). Default 2.
    pub aided_levels: usize,
    /// With the full prediction, KLT first runs on the finest level alone; the result is kept
    /// when it converged within this distance of the prediction, px, else the `aided_levels`
    /// pyramid is searched (paper IV-A: a good prediction needs no coarse levels). 0 disables.
    /// Default 2.
    pub aided_trust_px: f32,
    /// Use the prior to predict feature positions (IMU aid). Default true.
    pub imu_aid: bool,
    /// Lucas–Kanade settings.
    pub klt: KltParams,
    /// Forward–backward consistency threshold, px. Default 0.5.
    pub fb_threshold_px: f32,
    /// Minimum Shi–Tomasi score for a new corner (on pyramid level 1). Default 20.
    pub min_corner_score: f32,
    /// Candidate stride when searching a grid cell, level-1 px. Default 2.
    pub corner_step: usize,
    /// Frames a grid cell without any corner is skipped before it is searched again. Default 4.
    pub empty_cell_cooldown: u8,
    /// A tracked feature closer than this to an older one is dropped, px. Default 16 (about
    /// half a grid cell at the default `max_features`).
    pub min_distance_px: f32,
    /// Minimum tracks for solving. Default 20.
    pub min_tracks: usize,
    /// Mean intensity below which a frame is black. Default 12.
    pub black_mean: f32,
    /// Saturated-pixel fraction above which a frame is saturated. Default 0.8.
    pub saturated_fraction: f32,
    /// Intensity std below which a frame is textureless. Default 4.
    pub textureless_std: f32,
    /// Absolute sharpness floor (see [`crate::pyramid::FrameStats::sharpness`]), 1/px. Default 0.02.
    pub blur_sharpness: f32,
    /// A frame whose sharpness falls below this fraction of the reference frame's is blurred.
    /// Default 0.6.
    pub blur_relative: f32,
    /// Egomotion solver settings.
    pub solve: SolveParams,
    /// Seed of the RANSAC generator (results are deterministic given the inputs).
    pub seed: u64,
}

impl Default for VisionParams {
    fn default() -> Self {
        Self {
            max_features: 250,
            pyramid_levels: 3,
            aided_levels: 2,
            aided_trust_px: 2.0,
            imu_aid: true,
            klt: KltParams::default(),
            fb_threshold_px: 0.5,
            min_corner_score: 20.0,
            corner_step: 2,
            empty_cell_cooldown: 4,
            min_distance_px: 16.0,
            min_tracks: 20,
            black_mean: 12.0,
            saturated_fraction: 0.8,
            textureless_std: 4.0,
            blur_sharpness: 0.02,
            blur_relative: 0.6,
            solve: SolveParams::default(),
            seed: 0x005E_ED0F_u64,
        }
    }
}

/// Per-stage wall times, µs (0 unless a clock was set with [`FrontEnd::set_clock`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StageTimings {
    /// Decode.
    pub decode_us: u64,
    /// Pyramid, checks, tracking and feature replenishment (the sum of the three below).
    pub track_us: u64,
    /// Egomotion solver.
    pub solve_us: u64,
    /// Part of `track_us`: pyramid and frame checks.
    pub pyramid_us: u64,
    /// Part of `track_us`: IMU-aided KLT with the forward–backward check.
    pub klt_us: u64,
    /// Part of `track_us`: keeping tracks and detecting corners in empty cells.
    pub detect_us: u64,
}

/// Output for one incoming frame.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameResult {
    /// Time of the reference frame paired with this one, when there was one.
    pub t0_ns: Option<i64>,
    /// Time of this frame.
    pub t1_ns: i64,
    /// The measurement, or why there is none.
    pub outcome: Result<Egomotion, NoMeasurement>,
    /// Stage timings (never used for results).
    pub timings: StageTimings,
    /// Features tracked from the reference into this frame.
    pub tracked: u32,
}

/// A monotonic microsecond clock injected by the caller (the library never reads the clock).
pub type Clock = Box<dyn FnMut() -> u64 + Send>;

/// The vision front end for one camera. Feed frames in time order with [`FrontEnd::process`].
pub struct FrontEnd {
    camera: CameraModel,
    body_from_cam: Isometry3<f64>,
    params: VisionParams,
    decoder: LumaDecoder,
    prev: Pyramid,
    cur: Pyramid,
    prev_t_ns: Option<i64>,
    prev_sharpness: f32,
    cur_sharpness: f32,
    /// Feature pixels in the reference frame and their normalized rays.
    pts: Vec<[f32; 2]>,
    /// Per feature: the slot of its level-0 template saved by the last backward check
    /// (`u32::MAX`: none, e.g. a new corner).
    tmpl: Vec<u32>,
    rays: Vec<Vector3<f64>>,
    // per-frame scratch
    m_x0: Vec<Vector3<f64>>,
    m_x1: Vec<Vector3<f64>>,
    m_px1: Vec<[f32; 2]>,
    /// Per grid cell: the first kept feature in it (`u32::MAX`: none); `next_in_cell` chains
    /// the others.
    cell_head: Vec<u32>,
    next_in_cell: Vec<u32>,
    cooldown: Vec<u8>,
    klt: KltScratch,
    corners: CornerScratch,
    solve_scratch: SolveScratch,
    rng: Rng,
    clock: Clock,
}

impl std::fmt::Debug for FrontEnd {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FrontEnd")
            .field("camera", &self.camera)
            .field("params", &self.params)
            .field("features", &self.pts.len())
            .field("prev_t_ns", &self.prev_t_ns)
            .finish_non_exhaustive()
    }
}

impl FrontEnd {
    /// A front end for `camera` mounted at `body_from_cam`.
    pub fn new(camera: &CameraModel, body_from_cam: Isometry3<f64>, params: VisionParams) -> Self {
        let cap = params.max_features * 2;
        Self {
            camera: *camera,
            body_from_cam,
            params,
            decoder: LumaDecoder::new(camera.width, camera.height),
            prev: Pyramid::default(),
            cur: Pyramid::default(),
            prev_t_ns: None,
            prev_sharpness: 0.0,
            cur_sharpness: 0.0,
            pts: Vec::with_capacity(cap),
            tmpl: Vec::with_capacity(cap),
            rays: Vec::with_capacity(cap),
            m_x0: Vec::with_capacity(cap),
            m_x1: Vec::with_capacity(cap),
            m_px1: Vec::with_capacity(cap),
            cell_head: Vec::new(),
            next_in_cell: Vec::with_capacity(cap),
            cooldown: Vec::new(),
            klt: KltScratch::default(),
            corners: CornerScratch::default(),
            solve_scratch: SolveScratch::default(),
            rng: Rng::derive(params.seed, "vision-ransac"),
            clock: Box::new(|| 0),
        }
    }

    /// Sets the clock used for [`StageTimings`] (e.g. µs since an `Instant`).
    pub fn set_clock(&mut self, clock: Clock) {
        self.clock = clock;
    }

    /// The parameters in use.
    pub fn params(&self) -> &VisionParams {
        &self.params
    }

    /// Time of the current reference frame: the prior passed to the next
    /// [`process`](Self::process) must describe the motion from this time.
    pub fn reference_t_ns(&self) -> Option<i64> {
        self.prev_t_ns
    }

    /// Converts a body rotation `body1_from_body0` (e.g. integrated gyro) into the camera
    /// rotation `cam1_from_cam0` through the mounting.
    pub fn cam_rotation_from_body(
        &self,
        body1_from_body0: &UnitQuaternion<f64>,
    ) -> UnitQuaternion<f64> {
        let bc = self.body_from_cam.rotation;
        bc.inverse() * body1_from_body0 * bc
    }

    /// Forgets the reference frame and all tracks.
    pub fn reset(&mut self) {
        self.prev_t_ns = None;
        self.pts.clear();
        self.rays.clear();
        self.tmpl.clear();
        self.cooldown.clear();
    }

    /// Processes one frame taken at `t_ns`; `prior` describes the motion from
    /// [`reference_t_ns`](Self::reference_t_ns) to `t_ns`. Deterministic given the inputs.
    /// A rejected frame (decode error, black, …) also drops the reference.
    pub fn process(
        &mut self,
        t_ns: i64,
        format: ImageFormat,
        data: &[u8],
        prior: &MotionPrior,
    ) -> FrameResult {
        let t_start = (self.clock)();
        let t0_ns = self.prev_t_ns;
        let mut res = FrameResult {
            t0_ns,
            t1_ns: t_ns,
            outcome: Err(NoMeasurement::NoReference),
            timings: StageTimings::default(),
            tracked: 0,
        };
        // straight into the new frame's pyramid (no copy)
        let decoded = self
            .decoder
            .decode_into(format, data, &mut self.cur.base.data);
        let t_decoded = (self.clock)();
        res.timings.decode_us = t_decoded.saturating_sub(t_start);
        if let Err(e) = decoded {
            self.reset();
            res.outcome = Err(match e {
                DecodeError::SizeMismatch {
                    got_w,
                    got_h,
                    want_w,
                    want_h,
                } => NoMeasurement::SizeMismatch {
                    got_w,
                    got_h,
                    want_w,
                    want_h,
                },
                other => NoMeasurement::Decode(other.to_string()),
            });
            return res;
        }
        let (w, h) = (self.camera.width as usize, self.camera.height as usize);
        (self.cur.base.width, self.cur.base.height) = (w, h);
        self.cur.rebuild(self.params.pyramid_levels.max(2));
        let reject = self.check_frame();
        let t_pyramid = (self.clock)();
        res.timings.pyramid_us = t_pyramid.saturating_sub(t_decoded);
        if let Some(reject) = reject {
            self.reset();
            res.outcome = Err(reject);
            res.timings.track_us = res.timings.pyramid_us;
            return res;
        }
        if t0_ns.is_none() {
            self.replenish();
            self.finish_frame(t_ns);
            let t_end = (self.clock)();
            res.timings.detect_us = t_end.saturating_sub(t_pyramid);
            res.timings.track_us = t_end.saturating_sub(t_decoded);
            return res;
        }
        self.track(prior);
        res.tracked = self.m_x0.len() as u32;
        let t_tracked = (self.clock)();
        res.timings.klt_us = t_tracked.saturating_sub(t_pyramid);
        res.outcome = if self.m_x0.len() < self.params.min_tracks {
            Err(NoMeasurement::TooFewTracks {
                tracked: res.tracked,
                needed: self.params.min_tracks as u32,
            })
        } else {
            let f = 0.5 * (self.camera.fx + self.camera.fy);
            solve(
                &self.m_x0,
                &self.m_x1,
                prior,
                f,
                &self.params.solve,
                &mut self.rng,
                &mut self.solve_scratch,
            )
            .map(|s| Egomotion {
                t0_ns: t0_ns.unwrap_or(t_ns),
                t1_ns: t_ns,
                cam1_from_cam0: to_quat(&s.r),
                t_dir_cam1: s.t_dir.map(Unit::new_normalize),
                t_cam1_m: s.t_m,
                // Only the plane solver scales `t` (by the prior's distance).
                scale_distance_m: match s.solver {
                    EgomotionSolver::Plane if s.t_m.is_some() => prior.ground_distance_m,
                    _ => None,
                },
                rot_cov: s.cov.fixed_view::<3, 3>(0, 0).into_owned(),
                t_cov: s.cov.fixed_view::<3, 3>(3, 3).into_owned(),
                joint_cov: s.cov,
                tracked: res.tracked,
                inliers: s.inliers as u32,
                quality: s.quality,
                solver: s.solver,
            })
        };
        let t_solved = (self.clock)();
        res.timings.solve_us = t_solved.saturating_sub(t_tracked);
        self.keep_tracks(res.outcome.is_ok());
        self.replenish();
        self.finish_frame(t_ns);
        res.timings.detect_us = (self.clock)().saturating_sub(t_solved);
        res.timings.track_us = res.timings.detect_us + t_tracked.saturating_sub(t_decoded);
        res
    }

    fn check_frame(&mut self) -> Option<NoMeasurement> {
        let st = frame_stats(&self.cur);
        self.cur_sharpness = st.sharpness;
        let blur_floor = match self.prev_t_ns {
            Some(_) => self
                .params
                .blur_sharpness
                .max(self.params.blur_relative * self.prev_sharpness),
            None => self.params.blur_sharpness,
        };
        let p = &self.params;
        if st.mean < p.black_mean {
            Some(NoMeasurement::Black { mean: st.mean })
        } else if st.saturated_fraction > p.saturated_fraction {
            Some(NoMeasurement::Saturated {
                mean: st.mean,
                fraction: st.saturated_fraction,
            })
        } else if st.std < p.textureless_std {
            Some(NoMeasurement::Textureless { std: st.std })
        } else if st.sharpness < blur_floor {
            Some(NoMeasurement::Blurred {
                sharpness: st.sharpness,
            })
        } else {
            None
        }
    }

    /// Predicted pixel of a feature in the new frame (paper IV-A): the prior rotation and, when
    /// known, the terrain plane and the predicted translation (`x1 ∝ R x0 + t · nᵀx0 / d`).
    fn predict(
        &self,
        px: [f32; 2],
        ray: &Vector3<f64>,
        r: &Matrix3<f64>,
        prior: &MotionPrior,
    ) -> [f32; 2] {
        let mut p = r * ray;
        if let (Some(t), Some(n), Some(d)) = (
            prior.t_cam1_m,
            prior.ground_normal_cam0,
            prior.ground_distance_m,
        ) {
            let c = n.dot(ray);
            if c > 1e-6 && d > 0.0 {
                p += t * (c / d);
            }
        }
        if p.z <= 1e-6 {
            return px;
        }
        let q = self
            .camera
            .normalized_to_pixel(&Vector2::new(p.x / p.z, p.y / p.z));
        if q.x.is_finite() && q.y.is_finite() {
            [q.x as f32, q.y as f32]
        } else {
            px
        }
    }

    /// Prediction plus its local affine map: finite differences of [`Self::predict`] over a
    /// step of about one pixel taken in normalized coordinates, mapped back to pixels through
    /// the finite-difference Jacobian of the lens distortion (so only the distortion is
    /// evaluated, never its iterative inverse). The map is dropped when it is within 3% of the
    /// identity (fast path).
    fn predict_affine(
        &self,
        px: [f32; 2],
        ray: &Vector3<f64>,
        r: &Matrix3<f64>,
        prior: &MotionPrior,
    ) -> ([f32; 2], Affine) {
        let g = self.predict(px, ray, r, prior);
        let h = 1.0 / self.camera.fx;
        let p0 = self.camera.normalized_to_pixel(&Vector2::new(ray.x, ray.y));
        // columns: pixel change in frame 0 (d0) and predicted pixel change in frame 1 (d1)
        // per normalized step along x and y
        let (mut d0, mut d1) = (Matrix2::zeros(), Matrix2::zeros());
        for k in 0..2 {
            let mut n = *ray;
            n[k] += h;
            let pk = self.camera.normalized_to_pixel(&Vector2::new(n.x, n.y));
            let gk = self.predict(px, &n, r, prior);
            d0.set_column(k, &Vector2::new(pk.x - p0.x, pk.y - p0.y));
            let dg = [f64::from(gk[0] - g[0]), f64::from(gk[1] - g[1])];
            d1.set_column(k, &Vector2::new(dg[0], dg[1]));
        }
        let Some(m) = d0.try_inverse().map(|i| d1 * i) else {
            return (g, None);
        };
        let a = [
            m[(0, 0)] as f32,
            m[(0, 1)] as f32,
            m[(1, 0)] as f32,
            m[(1, 1)] as f32,
        ];
        let dev = (a[0] - 1.0).abs() + a[1].abs() + a[2].abs() + (a[3] - 1.0).abs();
        let sane = a.iter().all(|v| v.is_finite()) && (a[0] * a[3] - a[1] * a[2]) > 0.25;
        (g, (dev > 0.03 && sane).then_some(a))
    }

    fn track(&mut self, prior: &MotionPrior) {
        self.m_x0.clear();
        self.m_x1.clear();
        self.m_px1.clear();
        let aid = self.params.imu_aid && prior.cam1_from_cam0.is_some();
        let r = prior
            .cam1_from_cam0
            .map(|q| *q.to_rotation_matrix().matrix())
            .unwrap_or_else(Matrix3::identity);
        // The full prediction (rotation + terrain + translation) leaves a small residual flow, so
        // fewer levels suffice (paper IV-A); a rotation-only prediction leaves the parallax of
        // the unknown translation, so the full pyramid is kept.
        let full_prediction = prior.t_cam1_m.is_some()
            && prior.ground_normal_cam0.is_some()
            && prior.ground_distance_m.is_some();
        let levels = if aid && full_prediction {
            self.params.aided_levels
        } else {
            self.params.pyramid_levels
        };
        // With the full prediction the backward search starts next to its answer: the finest
        // level suffices for the consistency check.
        let back_top = if aid && full_prediction {
            0
        } else {
            levels.max(1) - 1
        };
        let top = levels.max(1) - 1;
        let direct = aid && full_prediction && self.params.aided_trust_px > 0.0;
        let fb2 = self.params.fb_threshold_px * self.params.fb_threshold_px;
        for i in 0..self.pts.len() {
            let p0 = self.pts[i];
            let (guess, affine) = if aid {
                self.predict_affine(p0, &self.rays[i], &r, prior)
            } else {
                (p0, None)
            };
            let load = match self.tmpl[i] {
                u32::MAX => Slot::None,
                k => Slot::Load(k as usize),
            };
            let Some(p1) = self.track_forward(p0, guess, affine, top, direct, load) else {
                continue;
            };
            // backward: start from the inverse prediction (p1 shifted back by the predicted flow);
            // its level-0 template is the next frame's forward template if p1 is kept (slot =
            // index of this track)
            let bg = [p1[0] - (guess[0] - p0[0]), p1[1] - (guess[1] - p0[1])];
            let back_affine = affine.and_then(invert2);
            let save = Slot::Save(self.m_px1.len());
            let Some(pb) = track_with_templates(
                &self.cur,
                &self.prev,
                p1,
                bg,
                back_affine,
                back_top,
                &self.params.klt,
                &mut self.klt,
                save,
            ) else {
                continue;
            };
            let pb = pb.pos;
            let (dx, dy) = (pb[0] - p0[0], pb[1] - p0[1]);
            if dx * dx + dy * dy > fb2 {
                continue;
            }
            let n1 = self
                .camera
                .pixel_to_normalized(&Point2::new(f64::from(p1[0]), f64::from(p1[1])));
            self.m_x0.push(self.rays[i]);
            self.m_x1.push(Vector3::new(n1.x, n1.y, 1.0));
            self.m_px1.push(p1);
        }
    }

    /// Forward KLT from `p0` starting at `guess`: with `direct`, the finest level alone first
    /// (kept when it converged within `aided_trust_px` of the guess), else from `top`. `load`:
    /// the saved level-0 template of this feature, if any.
    fn track_forward(
        &mut self,
        p0: [f32; 2],
        guess: [f32; 2],
        affine: Affine,
        top: usize,
        direct: bool,
        load: Slot,
    ) -> Option<[f32; 2]> {
        let (prev, cur, kp) = (&self.prev, &self.cur, &self.params.klt);
        if direct && top > 0 {
            let trust2 = self.params.aided_trust_px * self.params.aided_trust_px;
            let s = &mut self.klt;
            if let Some(t) = track_with_templates(prev, cur, p0, guess, affine, 0, kp, s, load) {
                let (dx, dy) = (t.pos[0] - guess[0], t.pos[1] - guess[1]);
                if t.converged && dx * dx + dy * dy <= trust2 {
                    return Some(t.pos);
                }
            }
        }
        track_with_templates(prev, cur, p0, guess, affine, top, kp, &mut self.klt, load)
            .map(|t| t.pos)
    }

    /// Keeps the tracked features (only the solver's inliers when it succeeded) as the new
    /// reference features.
    fn keep_tracks(&mut self, solved: bool) {
        self.pts.clear();
        self.rays.clear();
        self.tmpl.clear();
        if solved {
            for &i in &self.solve_scratch.inliers {
                self.pts.push(self.m_px1[i]);
                self.rays.push(self.m_x1[i]);
                self.tmpl.push(i as u32);
            }
        } else {
            self.pts.extend_from_slice(&self.m_px1);
            self.rays.extend_from_slice(&self.m_x1);
            self.tmpl.extend(0..self.m_px1.len() as u32);
        }
    }

    /// Grid geometry: square cells so that the grid holds about `max_features` cells.
    fn grid(&self) -> (usize, usize, usize) {
        let (w, h) = (self.camera.width as usize, self.camera.height as usize);
        let cell = (((w * h) as f64 / self.params.max_features.max(1) as f64)
            .sqrt()
            .floor() as usize)
            .max(8);
        (cell, w.div_ceil(cell), h.div_ceil(cell))
    }

    /// Drops features crowding an older one (closer than `min_distance_px`), then detects new
    /// corners in the grid cells left without a feature. Tracks are kept across cell borders:
    /// forcing one feature per cell would, under a uniform image motion, discard and re-detect
    /// a quarter of the features every frame.
    fn replenish(&mut self) {
        let (cell, gw, gh) = self.grid();
        self.cell_head.clear();
        self.cell_head.resize(gw * gh, u32::MAX);
        self.next_in_cell.clear();
        let md2 = self.params.min_distance_px * self.params.min_distance_px;
        let mut k = 0;
        for i in 0..self.pts.len() {
            let p = self.pts[i];
            let (cx, cy) = (
                (p[0].max(0.0) as usize / cell).min(gw - 1),
                (p[1].max(0.0) as usize / cell).min(gh - 1),
            );
            if self.crowded(p, (cx, cy), gw, gh, md2) {
                continue;
            }
            let c = cy * gw + cx;
            self.pts[k] = p;
            self.rays[k] = self.rays[i];
            self.tmpl[k] = self.tmpl[i];
            self.next_in_cell.push(self.cell_head[c]);
            self.cell_head[c] = k as u32;
            k += 1;
        }
        self.pts.truncate(k);
        self.rays.truncate(k);
        self.tmpl.truncate(k);
        // Search on level 1 (4× fewer candidates; the exact corner peak does not matter to KLT).
        // A cell that had no corner is left alone for a few frames: re-searching texture-poor
        // cells every frame would dominate the frame time.
        self.cooldown.resize(gw * gh, 0);
        let lvl = usize::from(!self.cur.coarse.is_empty());
        for c in 0..gw * gh {
            if self.cell_head[c] != u32::MAX || self.pts.len() >= gw * gh {
                continue;
            }
            if self.cooldown[c] > 0 {
                self.cooldown[c] -= 1;
                continue;
            }
            let (cx, cy) = (c % gw, c / gw);
            let rect = (
                (cx * cell) >> lvl,
                ((cx + 1) * cell) >> lvl,
                (cy * cell) >> lvl,
                ((cy + 1) * cell) >> lvl,
            );
            let (step, min_score) = (self.params.corner_step, self.params.min_corner_score);
            let cs = &mut self.corners;
            let corner = match self.cur.coarse.first() {
                Some(img) => best_corner_with(img, rect, step, min_score, cs),
                None => best_corner_with(&self.cur.base, rect, step, min_score, cs),
            };
            match corner {
                Some((p, _)) => {
                    let p = [p[0] * (1 << lvl) as f32, p[1] * (1 << lvl) as f32];
                    let n = self
                        .camera
                        .pixel_to_normalized(&Point2::new(f64::from(p[0]), f64::from(p[1])));
                    self.pts.push(p);
                    self.rays.push(Vector3::new(n.x, n.y, 1.0));
                    self.tmpl.push(u32::MAX);
                }
                None => self.cooldown[c] = self.params.empty_cell_cooldown,
            }
        }
    }

    /// Whether a kept feature in the 3×3 cells around `(cx, cy)` is within √`md2` of `p`.
    fn crowded(
        &self,
        p: [f32; 2],
        (cx, cy): (usize, usize),
        gw: usize,
        gh: usize,
        md2: f32,
    ) -> bool {
        for y in cy.saturating_sub(1)..(cy + 2).min(gh) {
            for x in cx.saturating_sub(1)..(cx + 2).min(gw) {
                let mut j = self.cell_head[y * gw + x];
                while j != u32::MAX {
                    let q = self.pts[j as usize];
                    if (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2) < md2 {
                        return true;
                    }
                    j = self.next_in_cell[j as usize];
                }
            }
        }
        false
    }

    fn finish_frame(&mut self, t_ns: i64) {
        std::mem::swap(&mut self.prev, &mut self.cur);
        self.klt.next_frame();
        self.prev_t_ns = Some(t_ns);
        self.prev_sharpness = self.cur_sharpness;
    }
}
