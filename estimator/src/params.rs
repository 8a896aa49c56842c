//! Tuning parameters of both profiles, with documented defaults.

/// Parameters of the estimator (both profiles). Sensor noise comes from the [`VehicleConfig`]
/// (`uavnav_core::VehicleConfig`); these are the filter's own choices.
#[derive(Debug, Clone, PartialEq)]
pub struct EstimatorParams {
    /// How far the fusion horizon trails the newest IMU sample, ns, beyond the GNSS delay (which
    /// the `eskf` adds: a delayed fix arrives that much after its validity time). Must exceed the
    /// camera latency plus one frame interval for vision to be fused at its own time (PX4 EKF2
    /// `delay_max`).
    pub fusion_delay_ns: i64,
    /// Covariance prediction period, s: the nominal state is integrated at every IMU sample, the
    /// covariance over accumulated intervals of about this length (PX4 `FILTER_UPDATE_PERIOD`,
    /// 10 ms; ArduPilot EKF3 about 12 ms). 20 ms: the error dynamics change slowly against it
    /// (the simulated 200 Hz flights' errors and 3σ shares moved by under 1 % from 10 ms), the
    /// real logs' IMUs at 50 Hz or less propagate at nearly every sample either way, and a 200 Hz IMU's
    /// `push_imu` costs 0.92 instead of 1.12 µs per sample (`--bench filter`), for every vehicle
    /// of the service.
    pub cov_period_s: f64,
    /// Largest gap between consecutive IMU samples taken as an ordinary interval, ns. A larger
    /// one is bridged (up to [`Self::max_bridge_gap_ns`]) or, beyond that, refused until
    /// the stream is continuous again, when the estimator restarts.
    pub max_imu_gap_ns: i64,
    /// Largest IMU gap the estimator bridges instead of restarting, ns: a telemetry link that drops
    /// for a few seconds, or a logger that stalls. The interval is integrated with the rates and
    /// specific force of the samples either side of it, as any interval is, and the covariance
    /// then takes what that cannot know ([`Self::bridge_rate_sigma_radps`],
    /// [`Self::bridge_accel_sigma_mps2`]). A restart would forget the heading, the biases and the
    /// tilt, and a flying vehicle without a compass can take minutes of manoeuvres to find its
    /// heading again. Longer gaps (a vehicle disarmed between flights, a clock that jumped) still
    /// restart. 5 s. Both profiles (`paper` once both its filters run with GNSS).
    pub max_bridge_gap_ns: i64,
    /// 1-σ of the angular rate a bridged gap did not see, per axis, rad/s, at least (half the
    /// change of the rate across the gap when that is larger): over a gap of `T` the attitude
    /// error variance grows by `(σ T)²`, at most that of 30° (eq. G1, `Eskf::widen_for_gap`).
    /// 0.02 rad/s: 2.3° over 2 s. More is not more honest: on the simulated multirotor, a 4.5 s
    /// gap widened by 0.1 rad/s (26°) let the next few GNSS velocities, whose noise the wide tilt
    /// then explained, turn the tilt by 5° and walk the yaw 25° off (yaw RMS after the gap
    /// 18.1°, against 1.6° with 0.02 and 90° when restarting; `tests/imu_gaps.rs`).
    pub bridge_rate_sigma_radps: f64,
    /// 1-σ of the acceleration a bridged gap did not see, per axis, m/s², at least (half the
    /// change of the specific force across the gap when that is larger): the velocity variance
    /// grows by `(σ T)²`, the position variance by `(σ T² / 2)²`; the first fix after the gap
    /// then widens both to its innovation, decorrelated, as at the end of an outage.
    pub bridge_accel_sigma_mps2: f64,
    /// Largest accepted |specific force|, m/s² (absurd-value check). 64 g: above any MEMS range
    /// (±16–32 g) even with all three axes at full scale, so a clipped sample is handled as one
    /// (`imu_accel_clip_mps2`), not refused.
    pub max_accel_mps2: f64,
    /// Largest accepted |angular rate|, rad/s (absurd-value check; 2 × a ±2000 °/s range).
    pub max_gyro_radps: f64,
    /// An accelerometer axis at or beyond this is clipped, m/s²: 15.5 g, just under the ±16 g
    /// range most autopilot IMUs use. A clipped sample understates the specific force by an
    /// unknown amount, so its interval gets [`crate::eskf::imu_noise::CLIP_ACCEL_SIGMA_MPS2`] of extra
    /// process noise and is counted in [`crate::Health::imu_clipped`]. An axis that repeats the
    /// same reading above 2 g is clipped too, whatever the range.
    pub imu_accel_clip_mps2: f64,
    /// A gyro axis at or beyond this is clipped, rad/s (0.98 × 2000 °/s).
    pub imu_gyro_clip_radps: f64,
    /// Measurements older than this behind the newest IMU sample are refused, ns.
    pub max_measurement_age_ns: i64,
    /// Accelerometer averaging window for levelling at initialisation, s.
    pub init_level_window_s: f64,
    /// Ground speed above which the GNSS course gives the initial heading, m/s.
    pub init_min_speed_mps: f64,
    /// Initial 1-σ heading uncertainty when aligned from the GNSS course (sideslip, crab), rad.
    pub init_yaw_sigma_rad: f64,
    /// Initial 1-σ roll/pitch uncertainty, rad.
    pub init_tilt_sigma_rad: f64,
    /// Initial 1-σ gyro bias, rad/s.
    pub init_gyro_bias_sigma_radps: f64,
    /// Initial 1-σ accelerometer bias, m/s².
    pub init_accel_bias_sigma_mps2: f64,
    /// Correlation time of the GNSS position error (first-order Gauss–Markov), s.
    pub gnss_pos_tau_s: f64,
    /// Fraction of the reported GNSS position variance that is time-correlated (the Gauss–Markov
    /// state); the rest is treated as white measurement noise. 0.5: the state cannot be told from
    /// a slow drift of the inertial solution except through the GNSS velocities, whose own errors
    /// are correlated on real receivers; with 0.9 the estimate stayed 1.7–2 m (copters) and up to
    /// 6 m (plane) from the shared real flights' fixes while the autopilot stayed within 0.3–1.2 m
    /// (0.5: 1.1 / 0.6 / 1.0 m). The simulated flights keep their bounds with either.
    pub gnss_pos_correlated_fraction: f64,
    /// Floor on the white GNSS position noise, m.
    pub gnss_pos_white_min_m: f64,
    /// How far GNSS velocities are trusted beyond their reported σ: their consistency with the
    /// receiver's own positions (`aid_sources::gnss_consistency`, eq. V1).
    pub gnss_vel_consistency: crate::aid_sources::gnss_consistency::ConsistencyParams,
    /// Innovation gate as a normal quantile (σ): the chi-square gate is χ²(dof) at the
    /// probability of this quantile (Wilson–Hilferty), test ratio = NIS / gate. 3.29 ≈ 0.9995.
    pub gate_sigma: f64,
    /// GNSS rejected continuously for this long triggers an inflate-and-fuse reset, ns.
    pub gnss_reset_timeout_ns: i64,
    /// A source counts as active if fused within this time, ns.
    pub aid_timeout_ns: i64,
    /// Scale applied to the vision covariances before fusion: the effective information of one
    /// egomotion in a stream whose errors are time-correlated. The front end's covariance is
    /// calibrated per frame (NEES ≈ dof on the simulated paper flights), but consecutive frames
    /// share ground texture and tracks: the mean of its errors over 5 s (20 s) windows varies
    /// 2–3× (4–10×) more than white errors would (2–6×, 4–19× with the earlier front end), so
    /// fusing every frame at face value makes the attitude overconfident (NEES 9.6 for 3). 6 keeps
    /// the pose NEES ≈ 2.5–3.3. Use 1 for an egomotion source with white errors.
    pub vision_cov_scale: f64,
    /// Use vision relative rotation.
    pub use_vision_rotation: bool,
    /// Use vision translation (direction or metric).
    pub use_vision_translation: bool,
    /// Fuse the vision rotation and translation in one update with the solver's joint
    /// covariance (their errors are correlated, |ρ| ≈ 0.98 for the plane solver); `false` fuses
    /// them as two independent updates.
    pub vision_joint_update: bool,
    /// Paper profile: PSD added to the gyro noise in VIDEO-IMU(1) for the un-modelled gyro bias
    /// (the paper's filter has no bias state), (rad/s)²/Hz. Not read by the ESKF (it estimates the
    /// bias). White noise of PSD `q` grows the attitude variance as `q t`; the bias of the simulated
    /// tactical MEMS (`sim` `ImuSpec`, scenarios/paper-*.toml), a turn-on constant of σ_b = 5e-5
    /// rad/s (≈ 10 °/h) plus a random walk of σ_rw = 2e-6 rad/s²/√Hz, makes the attitude error
    /// grow as `σ_b² t² + σ_rw² t³ / 3` without aiding. The smallest `q` that covers it up to a
    /// horizon `T` is `σ_b² T + σ_rw² T² / 3`; for the 250 s paper flight (the small-lever attitude
    /// is unaided for most of it) that is 6.25e-7 + 0.83e-7 ≈ 7e-7. A smaller value (the earlier
    /// 1e-7) makes the gyro-integrated attitude overconfident, so that the video pseudo-attitude
    /// and the lever-arm GNSS hardly correct it.
    pub paper_gyro_instability_psd: f64,
    /// Paper profile: 1-σ per axis of the gyro bias left after start-up when the IMU
    /// configuration states none (`ImuConfig::gyro_bias_sigma_radps` = 0, as for flight logs),
    /// rad/s. VIDEO-IMU(1) grows its attitude covariance by what such a bias builds up
    /// (`paper::attitude::AttitudeEkf::predict`). The same prior as the `eskf` bias states start
    /// from (`init_gyro_bias_sigma_radps`): there it is then estimated, here it stays.
    pub paper_unknown_gyro_bias_sigma_radps: f64,
    /// Paper profile without GNSS (our addition, `paper::gnssless`): 1-σ of the vehicle's
    /// velocity, held at zero, against which the accelerometers' tilt is taken over 5 s windows
    /// (`paper::gnss_tilt::GnssTilt::at_hold`), m/s. Larger makes the tilt σ wider and the
    /// correction weaker. On the 47 surveyed flights with GNSS withheld (median of the worse of
    /// roll and pitch RMSE; mean share within 3σ of the worse axis): 3 m/s 5.1°, 78.9 %; 5 m/s
    /// 5.7°, 81.7 %; 10 m/s 7.5°, 84.3 % (`eskf`: 3.5°, 78.7 %).
    pub paper_noaid_speed_sigma_mps: f64,
    /// Paper profile: correlation time of the attitude error as the position/velocity filters see
    /// it through the specific force, s. The paper's split into an attitude filter and
    /// position/velocity filters drops their cross-covariance, so the attitude's uncertainty
    /// enters eqs. (29)–(30) as acceleration noise `|f|² σ_θ²`. Taken as white, it grows the
    /// velocity σ as `|f| σ_θ √t`, while the attitude error it stands for is slowly varying (the
    /// gyro bias, the video chain): the velocity error then grows as `|f| σ_θ t` (0.15° of tilt
    /// gives 3 m/s over a 120 s outage, where a white allowance gave 0.3 m/s). A first-order
    /// Gauss–Markov error of variance σ² and time constant τ has the long-run PSD `2 σ² τ`, used
    /// here. 0 gives the earlier white allowance (`|f|² σ_θ²` as PSD).
    pub paper_attitude_error_tau_s: f64,
    /// Paper profile: the video pseudo-attitude (eq. 34) starts from the filter's attitude only
    /// once every attitude σ is below this, rad (the "initial known value").
    pub paper_video_start_sigma_rad: f64,
    /// Paper profile: inflation of each video delta-attitude's covariance as it enters the
    /// eq. (34) pseudo-attitude chain (the growth of the chain-error state `η`). The chain SUMS the
    /// deltas, so what matters is the long-run variance of their errors, not the per-frame one:
    /// consecutive frames share ground texture and tracks, and the mean of the front end's errors
    /// over 50 (200) frames varies 1.7–3.4× (3.6–9.7×) more than for white errors (see
    /// `estimator/README.md`, "Vision calibration"). 6 is the allowance the `eskf` profile uses for
    /// the same front end (`vision_cov_scale`). Use 1 for an egomotion source with white errors.
    pub paper_chain_cov_scale: f64,
    /// Paper profile, OUR ADDITION (not in the paper): fuse the video's direction of travel in
    /// VIDEO-IMU(1) while GNSS is available (eq. D1 of `paper::attitude`): the essential matrix's
    /// translation direction rotated into NED with the attitude, against the direction of the
    /// GNSS-IMU velocity (course and flight-path angle). It makes the heading observable with a
    /// small lever arm (the paper's attitude sees GNSS only through the lever arm, eqs. 32–33).
    /// Fused only while a GNSS velocity was fused in the last 0.5 s; during outages the direction
    /// goes to VIDEO-IMU(2) (eq. 35) instead. `false` gives the paper's filter as written.
    pub paper_video_direction: bool,
    /// Paper profile: inflation of the video direction's per-frame covariance in the eq. (D1)
    /// measurement. 1, unlike `vision_cov_scale`: the smallest value that keeps the attitude
    /// consistent, which it is without inflation (real vision chain on the paper flights: attitude
    /// NEES 1.5 / 1.3 for 3 on the small / big lever, 100 % within 3σ; the D1 innovations are
    /// smaller than their covariance, which the attitude's own σ dominates, the gyro-instability
    /// allowance `paper_gyro_instability_psd` keeping it wide). 6 gives 0.171/0.118/0.088° /
    /// 0.133/0.060/0.076° roll/pitch/yaw instead of 0.162/0.108/0.073° / 0.143/0.094/0.073°
    /// (attitude NEES 1.5 / 1.0): less heading and pitch information from the video, so the big
    /// lever arm's own keeps the configurations apart (pitch 2.0×).
    pub paper_direction_cov_scale: f64,
    /// Paper profile, OUR ADDITION (not in the paper): while no video pseudo-attitude chain runs,
    /// fuse roll and pitch from the GNSS acceleration against the accelerometers over windows of
    /// about a second (eq. T1 of `paper::gnss_tilt`). Without a camera the paper's attitude is
    /// gyro integration, observable through the lever arm only; with a real airframe's lever arm
    /// it drifted to 6–9° of roll/pitch RMSE on the shared real flights. `false` gives the
    /// paper's filter as written.
    pub paper_gnss_tilt: bool,
    /// Paper profile, OUR ADDITION (not in the paper): the heading of a vehicle whose course is
    /// not its heading (a multirotor, unless `course_heading`) from the yaw-hypothesis bank fed by
    /// the IMU and the GNSS velocity (`paper::heading`), handed to the attitude filter once the
    /// bank has converged and reset to it when the two disagree for `paper::heading::CONTRADICTION_NS`.
    /// Without it such a vehicle has no heading in this profile (its yaw σ says so). `false`
    /// gives the paper's filter as written.
    pub paper_yaw_bank: bool,
    /// Position σ above which the filter is declared diverged, m.
    pub diverged_pos_sigma_m: f64,
    /// 1-σ error of a magnetometer heading, rad: calibration residue and motor interference, which
    /// are time-correlated (fused at most at 2 Hz). 0.2 rad: an uncompensated compass near the
    /// motors wanders by 3–5° (1σ) and more in manoeuvres (the shared ArduPilot copter: 7–15 mG of
    /// a 163 mG horizontal field), and its errors repeat from sample to sample; autopilots use
    /// 0.3 rad (PX4 `EKF2_HEAD_NOISE`). 0.1 made the yaw σ 1° on the shared copter with 2.4°
    /// RMSE against its autopilot (78 % within 3σ); 0.2 and 0.3 give 1.6–1.7° and 98–99 %.
    pub mag_heading_sigma_rad: f64,
    /// A magnetometer sample whose inclination (through the filter's tilt) is further than this
    /// from the world magnetic model's is disturbed and not fused, rad.
    pub mag_max_inclination_error_rad: f64,
    /// A compass heading that contradicts a converged yaw bank (beyond 3σ of both) this long in
    /// a row stops the compass for the flight and resets the heading to the bank, ns. Long
    /// against a manoeuvre (a few seconds), short against a flight.
    pub mag_contradiction_timeout_ns: i64,
    /// `eskf`: the in-flight compass calibration (hard-iron offset and the compass's own field,
    /// eq. M2, `aid_sources::mag_calibration`).
    pub mag_calibration: crate::aid_sources::mag_calibration::MagCalibrationParams,

    /// Heading-course alignment: use the GNSS course as the heading when the yaw estimator has not
    /// converged and the vehicle moves faster than `init_min_speed_mps`. Only right for a vehicle
    /// that flies nose first (a fixed wing); a multirotor flies sideways and backwards, so the
    /// default is `false` and the heading comes from the magnetometer or the yaw estimator.
    pub course_heading: bool,
    /// Learn the GNSS velocity's own delay from the data (`eskf`; eq. L1, `crate::gnss_delay`),
    /// starting from the configured one, and fuse each velocity carried to its fix's configured
    /// time of validity (eq. L2; positions keep the configured delay): the delay an autopilot's
    /// log states is what it assumed, and on the public ArduPilot logs the fixed wings'
    /// velocities lagged their IMU by 0.00–0.04 s where 0.22 s was stated.
    pub learn_gnss_delay: bool,
    /// Barometer: 1-σ height noise per sample beyond the sensor's pressure noise, m (static-port
    /// and propeller-wash errors: a few decimetres to metres on multirotors).
    pub baro_height_sigma_m: f64,
    /// Barometer: random walk of the pressure-height offset, m/√s (weather; the sensor warming
    /// 3–5 °C in flight: 0.1 gives 0.8 m in a minute, 2.4 m in ten).
    pub baro_offset_walk_m_per_sqrt_s: f64,
    /// Tuning of the yaw estimator (Gaussian sum of heading hypotheses).
    pub yaw_estimator: crate::yaw_estimator::YawEstimatorParams,
    /// `eskf`, with the heading aligned from the yaw estimator and no magnetometer: GNSS velocity
    /// rejected this long while the yaw estimator disagrees beyond 3σ resets the heading to it, ns.
    pub yaw_reset_timeout_ns: i64,
    /// `eskf`: IMU data with no GNSS fix for this long starts the filter without one, s, in
    /// [`crate::Mode::AttitudeOnly`] (`eskf::gnssless`); the first fix then starts it as usual.
    /// 10 s: longer than the wait for a receiver that is already tracking when the stream starts
    /// (so a flight with GNSS runs exactly as before from its first fix), short against a
    /// receiver's cold start (30–60 s) or a vehicle that has none. A vehicle configured without
    /// GNSS starts as soon as it is level. `f64::INFINITY`: never without GNSS.
    pub start_without_gnss_after_s: f64,
    /// `eskf`: a filter that had GNSS and has fused no horizontal position or velocity (GNSS or
    /// vision) for `aid_timeout_ns` stops dead reckoning once it no longer knows where it is
    /// (horizontal position σ beyond `noaid_pos_sigma_m`) and its tilt σ has grown past this,
    /// rad: it then holds its position (`aid_sources::position_hold`, as a filter started without
    /// GNSS does) and reports attitude only until GNSS comes back (`eskf::outage`). A good IMU
    /// coasts through a minute's outage with its tilt σ well under a degree and is left to do
    /// so; the shared fixed wing's 10 Hz IMU log passed 3° within 5 s of losing its fixes (its
    /// tilt σ is 1.4–1.8° with them). `f64::INFINITY`: dead reckoning without limit.
    pub dead_reckoning_max_tilt_sigma_rad: f64,
    /// `eskf`: 1-σ of the gyro's scale-factor error, as a fraction (MEMS gyros of the MPU-6000
    /// class state ±3 % as built, uncalibrated). The filter does not estimate it: while the
    /// heading is observed (GNSS velocity, compass, vision) the bias state and the heading's
    /// own corrections absorb it at the turn rate flown; once nothing observes the heading, each
    /// radian turned about the vertical adds this much of a radian of yaw error, and the reported
    /// yaw σ grows by it (`eskf::outage`; only the σ reported, not the filter's covariance).
    pub gyro_scale_sigma: f64,
    /// `eskf` without position aiding: 1-σ of the position-hold pseudo-measurement that keeps the
    /// velocity, and through it the tilt, bounded (`aid_sources::position_hold`), m, fused every
    /// 0.2 s. PX4 fuses the same "fake position" with 10 m (`EKF2_NOAID_NOISE`), but the hold's
    /// error is where the vehicle really went, the same for many updates, not white noise: at
    /// 10 m the tilt σ shrank below what the vehicle's own accelerations left. On the three
    /// shared real flights with GNSS withheld (roll / pitch RMSE °, % within 3σ):
    /// 3 m: 1.40/1.22 66/89 %, 2.30/2.49 91/94 %, 7.98/6.73 72/83 %;
    /// 10 m: 1.07/1.13 91/96 %, 2.21/2.31 94/97 %, 5.65/6.51 94/88 %;
    /// 30 m: 1.01/1.20 96/97 %, 2.28/2.23 98/97 %, 3.53/5.56 100/91 %;
    /// 100 m: 1.19/1.44 99/98 %, 2.49/2.22 99/98 %, 4.05/4.00 95/96 % (copter_218, copter_103,
    /// plane_E). 30 m: about the radius a small UAV flies within, and the best copters.
    pub noaid_pos_sigma_m: f64,
    /// `eskf` without a known position: 1-σ of the unknown magnetic declination, rad. Without a
    /// position the world magnetic model cannot say where true north is from magnetic north;
    /// over where people fly, declination lies mostly within ±20° (10° covers it at 2σ).
    pub unknown_declination_sigma_rad: f64,
}

impl EstimatorParams {
    /// Whether an IMU interval from `a_t_ns` to `b_t_ns` that reached a filter is a gap the
    /// [`Estimator`](crate::Estimator) chose to bridge: only bridged gaps pass its validation
    /// longer than [`Self::max_imu_gap_ns`] (eq. G1 then widens for what they hid).
    pub fn is_bridged_gap(&self, a_t_ns: i64, b_t_ns: i64) -> bool {
        b_t_ns - a_t_ns > self.max_imu_gap_ns
    }
}

impl Default for EstimatorParams {
    fn default() -> Self {
        Self {
            fusion_delay_ns: 200_000_000,
            cov_period_s: 0.02,
            max_imu_gap_ns: 500_000_000,
            max_bridge_gap_ns: 5_000_000_000,
            bridge_rate_sigma_radps: 0.02,
            bridge_accel_sigma_mps2: 1.0,
            max_accel_mps2: 64.0 * 9.81,
            max_gyro_radps: 70.0,
            imu_accel_clip_mps2: 15.5 * 9.81,
            imu_gyro_clip_radps: 0.98 * 2000f64.to_radians(),
            max_measurement_age_ns: 2_000_000_000,
            init_level_window_s: 0.5,
            init_min_speed_mps: 3.0,
            init_yaw_sigma_rad: 10f64.to_radians(),
            init_tilt_sigma_rad: 2f64.to_radians(),
            init_gyro_bias_sigma_radps: 1e-3,
            init_accel_bias_sigma_mps2: 0.05,
            gnss_pos_tau_s: 300.0,
            gnss_pos_correlated_fraction: 0.5,
            gnss_pos_white_min_m: 0.05,
            gnss_vel_consistency: Default::default(),
            gate_sigma: 3.29,
            gnss_reset_timeout_ns: 5_000_000_000,
            aid_timeout_ns: 2_000_000_000,
            vision_cov_scale: 6.0,
            use_vision_rotation: true,
            use_vision_translation: true,
            vision_joint_update: true,
            paper_gyro_instability_psd: 7e-7,
            paper_unknown_gyro_bias_sigma_radps: 1e-3,
            paper_noaid_speed_sigma_mps: 5.0,
            paper_attitude_error_tau_s: 60.0,
            paper_video_start_sigma_rad: 0.5f64.to_radians(),
            paper_chain_cov_scale: 6.0,
            paper_video_direction: true,
            paper_direction_cov_scale: 1.0,
            paper_gnss_tilt: true,
            paper_yaw_bank: true,
            diverged_pos_sigma_m: 5_000.0,
            mag_heading_sigma_rad: 0.2,
            mag_max_inclination_error_rad: 10f64.to_radians(),
            mag_contradiction_timeout_ns: 10_000_000_000,
            mag_calibration: Default::default(),

            course_heading: false,
            learn_gnss_delay: true,
            baro_height_sigma_m: 0.5,
            baro_offset_walk_m_per_sqrt_s: 0.1,
            yaw_estimator: crate::yaw_estimator::YawEstimatorParams::default(),
            yaw_reset_timeout_ns: 1_000_000_000,
            start_without_gnss_after_s: 10.0,
            dead_reckoning_max_tilt_sigma_rad: 3f64.to_radians(),
            gyro_scale_sigma: 0.03,
            noaid_pos_sigma_m: 30.0,
            unknown_declination_sigma_rad: 10f64.to_radians(),
        }
    }
}
