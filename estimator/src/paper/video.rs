//! The video in the `paper` profile: the eq. (34) pseudo-attitude, our eq. (D1) direction of
//! travel while GNSS is fused, and eq. (35) (VIDEO-IMU(2)) through GNSS outages.

use super::*;

impl PaperFilter {
    /// Video egomotion: pseudo-attitude (eq. 34) and, during outages, eq. (35).
    pub fn push_egomotion(&mut self, m: &Egomotion) {
        let (Some(bfc), Some(att)) = (self.body_from_cam, self.att.as_mut()) else {
            return;
        };
        let gate = self.params.gate_sigma;
        // A chain starts only once aligned; a restart later is allowed whatever σ has grown to
        // (the chain's error state starts from the filter's covariance, so it stays honest).
        let start_sigma = if self.aligned || self.settled {
            f64::INFINITY
        } else {
            self.params.paper_video_start_sigma_rad
        };
        att.video_update(
            m,
            &bfc,
            gate,
            start_sigma,
            self.params.paper_chain_cov_scale,
            &mut self.health.vision_rot,
        );
        let now_ns = self.imu.back().map_or(m.t1_ns, |s| s.t_ns);
        if self.params.paper_video_direction
            && (self.aligned || self.settled)
            && self.vio2.is_none()
            && self.health.gnss_vel.active(now_ns, D1_GNSS_VEL_RECENT_NS)
            && let Some(d1) = self.direction_meas(m, &bfc)
        {
            let Some(att) = self.att.as_mut() else { return };
            att.direction_update(&d1, gate, &mut self.health.vision_trans);
        }
        let Some(att) = self.att.as_ref() else { return };
        let Some(v2) = self.vio2.as_mut() else { return };
        let Some(dir) = m
            .t_dir_cam1
            .map(|d| d.into_inner())
            .or(m.t_cam1_m.map(|t| t.normalize()))
        else {
            return;
        };
        let Some(c1) = att.rotation_at(m.t1_ns) else {
            return;
        };
        // Camera displacement c1 − c0 = −R_nc1 t (eq. 35's Δp, a unit vector), speed = last valid.
        let dir_n = -(c1 * bfc.rotation.to_rotation_matrix().matrix() * dir);
        // 1-σ of the direction, rad: `t_cov` is of the unit vector, or of the metric `t` (m²) when
        // the solver knew the terrain distance.
        let t_norm = m.t_cam1_m.map_or(1.0, |t| t.norm().max(1e-3));
        let dir_sigma =
            ((m.t_cov.trace().max(0.0) * self.params.vision_cov_scale).sqrt() / t_norm).max(1e-3);
        // |V| is held at the last valid value (eq. 35); the longer the outage, the less it is
        // trusted (the vehicle may have sped up or slowed down).
        let since_s = self
            .last_fix
            .map_or(0.0, |(f, _)| (m.t1_ns - f.t_ns).max(0) as f64 * 1e-9);
        let speed_sigma = SPEED_SIGMA_MPS + SPEED_SIGMA_GROWTH_MPS_PER_S * since_s;
        let sigma = ((self.last_speed_mps * dir_sigma).powi(2) + speed_sigma.powi(2)).sqrt();
        v2.update_velocity(
            &(dir_n * self.last_speed_mps),
            sigma,
            m.t1_ns,
            gate,
            &mut self.health.vision_trans,
        );
        // The held speed's error is one error shared by every frame of the outage: fusing it at
        // every frame as if it were fresh would shrink the along-track velocity σ far below it
        // (measured: 92 % of the velocities within 3σ, the position 91 %). Only the direction
        // is new information per frame; along it the velocity stays as uncertain as the speed.
        // The position error it builds is its integral since the last fix, along a path that
        // turns: each horizontal axis is kept at least that uncertain.
        if let Some(u) = dir_n.try_normalize(1e-9) {
            v2.floor_velocity_along(&u, speed_sigma * speed_sigma);
        }
        let along_m =
            SPEED_SIGMA_MPS * since_s + 0.5 * SPEED_SIGMA_GROWTH_MPS_PER_S * since_s * since_s;
        v2.floor_position(&Vector3::new(along_m * along_m, along_m * along_m, 0.0));
    }

    /// The inputs of eq. (D1) for egomotion `m` (see `attitude::AttitudeEkf::direction_update`):
    /// the video direction of travel in body-1 axes with its covariance (times
    /// `paper_direction_cov_scale`), and the GNSS-IMU filter's mean camera
    /// velocity over the frame pair: `(∫v dt + (C₁ − C₀) r_c) / Δt` (trapezoids over the velocity
    /// history; `r_c` the camera's offset from the IMU), with the filter's current velocity
    /// covariance (its error hardly changes over 0.1 s). `None` when the pair is not covered by the
    /// history or has no direction.
    fn direction_meas(&self, m: &Egomotion, bfc: &Isometry3<f64>) -> Option<DirectionMeas> {
        let att = self.att.as_ref()?;
        let gi = self.gps_imu.as_ref()?;
        let r_bc = bfc.rotation.to_rotation_matrix().into_inner();
        let (t_cam, cov_cam) = match (m.t_dir_cam1, m.t_cam1_m) {
            (Some(u), _) => (u.into_inner(), m.t_cov),
            (None, Some(t)) => {
                // Metric translation: the direction's covariance is that of t across itself,
                // over |t|².
                let n = t.norm();
                if n <= 1e-6 {
                    return None;
                }
                let u = t / n;
                let perp = Matrix3::identity() - u * u.transpose();
                (u, perp * m.t_cov * perp / (n * n))
            }
            (None, None) => return None,
        };
        let dir_body = -(r_bc * t_cam);
        let dir_cov_body =
            r_bc * cov_cam * r_bc.transpose() * self.params.paper_direction_cov_scale;
        let dt_s = (m.t1_ns - m.t0_ns) as f64 * 1e-9;
        let (first, last) = (self.vel_hist.front()?, self.vel_hist.back()?);
        if dt_s <= 0.0 || first.0 > m.t0_ns || last.0 < m.t1_ns {
            return None;
        }
        let mut disp = Vector3::zeros();
        for (a, b) in self.vel_hist.iter().zip(self.vel_hist.iter().skip(1)) {
            let (lo, hi) = (a.0.max(m.t0_ns), b.0.min(m.t1_ns));
            if hi <= lo {
                continue;
            }
            // Linear interpolation of v between the samples, integrated over [lo, hi].
            let span = (b.0 - a.0) as f64;
            let at = |t: i64| a.1 + (b.1 - a.1) * ((t - a.0) as f64 / span);
            disp += (at(lo) + at(hi)) * (0.5 * (hi - lo) as f64 * 1e-9);
        }
        let r_c = bfc.translation.vector;
        let (c0, c1) = (att.rotation_at(m.t0_ns)?, att.rotation_at(m.t1_ns)?);
        disp += (c1 - c0) * r_c;
        Some(DirectionMeas {
            t0_ns: m.t0_ns,
            t1_ns: m.t1_ns,
            dir_body,
            dir_cov_body,
            vel_ned_mps: disp / dt_s,
            vel_cov: gi.p.fixed_view::<3, 3>(3, 3).into_owned(),
        })
    }
}
