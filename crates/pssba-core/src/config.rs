//! Every tunable of the algorithm, with its unit. `config/default.toml` mirrors
//! [`PssBaConfig::default`]; a test keeps the two equal.

use serde::{Deserialize, Serialize};

/// Which variant of the method runs (the paper's Table I rows that use our pipeline).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// Progressive spatial smoothing: gamma shrinks by `k` each scale (the paper's PSS-BA).
    #[default]
    PssBa,
    /// Fixed scale: one gamma, iterated to convergence (the paper's PSS-BA(FS) ablation).
    PssBaFs,
    /// Planar kernels `z = a3 x + a4 y + a5` on the progressive schedule (Point2Plane ablation).
    Point2plane,
}

impl Method {
    /// Name as used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Method::PssBa => "pss-ba",
            Method::PssBaFs => "pss-ba-fs",
            Method::Point2plane => "point2plane",
        }
    }
}

/// Configuration of one bundle-adjustment run. Units are in the field names.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PssBaConfig {
    /// Variant to run.
    pub method: Method,
    /// Initial kernel width gamma (paper: 3 m).
    pub gamma0_m: f64,
    /// Shrink factor k: gamma <- gamma / k after each scale (paper: 1.4).
    pub gamma_shrink: f64,
    /// Smallest kernel width; the schedule stays here until it converges. Chosen so a kernel
    /// still holds enough neighbours of a Mid-360-like scan at the downsampling below.
    pub gamma_min_m: f64,
    /// Kernel width of the fixed-scale variant (PSS-BA(FS)).
    pub fixed_gamma_m: f64,
    /// Convergence threshold T_conv on the norm of the stacked 6N pose change of one scale
    /// (translation in m, rotation in rad; paper: 0.01).
    pub convergence_threshold: f64,
    /// Once gamma has reached `gamma_min_m`, the schedule can only repeat the same kernel
    /// width: it does so only while the last scale moved the free frames by at least this
    /// fraction of gamma (RMS of their translation change). Measured (`pssba bench`, 6
    /// scenes): at the first scale at 0.4 m the frames moved 1.3-6.0 mm (0.3-1.5 % of
    /// gamma) on five scenes, where a repeat changed the APE by -0.3 to +0.7 mm, and
    /// 105 mm (26 %) on the crane, where it lowered the APE from 36.0 to 28.8 mm.
    pub min_repeat_move_per_gamma: f64,
    /// Upper bound on the number of scales (smoothing + adjustment rounds).
    pub max_scales: usize,
    /// Rounds at the finest width with the paper's plain consensus surfaces (no anchor
    /// offset) once the anchored schedule has converged; they are not counted in
    /// `max_scales`. An anchor offset rests on a few points of one frame, and its noise
    /// passes to every residual of its surface: started from the true poses, one round at
    /// 0.4 m ends 2.7 mm from them with anchors and 1.3 mm without (hangar, 100 frames),
    /// while without anchors the schedule would converge slowly from rough poses.
    pub final_plain_rounds: usize,
    /// Per-frame voxel downsampling edge as a fraction of gamma.
    pub downsample_per_gamma: f64,
    /// Lower bound of the downsampling voxel edge.
    pub downsample_min_m: f64,
    /// Neighbours used by the PCA normal of each point (k-nearest in the downsampled cloud).
    pub normal_neighbours: usize,
    /// L0 normal refinement weight mu (paper eq. `normal`: 0.05).
    pub l0_mu: f64,
    /// Largest beta of the half-quadratic splitting; the inlier threshold ends at
    /// D_j < sqrt(mu / beta_max).
    pub l0_beta_max: f64,
    /// Neighbour normals sampled for the L0 refinement of one kernel.
    pub l0_max_neighbours: usize,
    /// Neighbours whose normal deviates more than this from the refined kernel normal are
    /// left out of the fit and the residuals (they lie across an edge or are outliers), at
    /// the coarse scales (gamma >= `prior_min_gamma_m`), where a kernel spans a bend.
    pub normal_gate_deg: f64,
    /// The same gate at the fine scales (gamma < `prior_min_gamma_m`), where a smooth
    /// surface turns little within a kernel but a point's normal (PCA over a few voxels)
    /// still leans towards any edge nearby: 30 instead of 60 deg keeps those points out
    /// (BENCHMARK.md, 2026-12-05 (16)).
    pub fine_normal_gate_deg: f64,
    /// Move each fitted surface along its normal onto its kernel frame's own points (see
    /// `smoothing::anchor_offset`); off: the paper's plain consensus surface.
    pub anchor_offset_to_kernel_frame: bool,
    /// Least number of points for a polynomial fit.
    pub fit_min_points: usize,
    /// Smallest accepted ratio of the smallest to the largest eigenvalue of the (scaled)
    /// normal matrix of the fit; below it the fit is ill-posed (points along a line).
    pub fit_min_eigen_ratio: f64,
    /// Largest accepted weighted RMS of the fit, as a fraction of gamma.
    pub fit_max_rms_per_gamma: f64,
    /// Points used in one fit at most (evenly subsampled beyond).
    pub fit_max_points: usize,
    /// Frames per kernel group: kernel sampling takes one kernel per voxel and per run of
    /// this many consecutive frames that sees the voxel (see `cloud::kernel_frame_groups`);
    /// windows up to this long get the paper's one kernel per voxel.
    pub frames_per_kernel_group: usize,
    /// Residual points per (kernel, frame) pair at most.
    pub residuals_per_kernel_frame: usize,
    /// Residual points per kernel at most (raised to `residuals_per_scale / kernels` when
    /// that is larger, so coarse scales with few kernels still tie every frame).
    pub residuals_per_kernel: usize,
    /// Residual budget of one scale that sets the per-kernel cap at coarse scales.
    pub residuals_per_scale: usize,
    /// Cauchy loss scale as a fraction of gamma.
    pub robust_scale_per_gamma: f64,
    /// Lower bound of the Cauchy loss scale.
    pub robust_scale_min_m: f64,
    /// Levenberg-Marquardt iterations (re-linearisations) per scale at most.
    pub lm_max_iterations: usize,
    /// Sigma (m) of the prior tying each pose's translation to its value at the start of a
    /// coarse scale (about the expected initial error): a frame must not slide along crude,
    /// extrapolated coarse surfaces.
    pub prior_translation_m: f64,
    /// Sigma (rad) of the same prior on rotation.
    pub prior_rotation_rad: f64,
    /// The prior applies at scales with gamma at least this (m); finer scales run without it.
    pub prior_min_gamma_m: f64,
    /// Initial LM damping lambda (relative to the Hessian diagonal).
    pub lm_initial_lambda: f64,
    /// Minimum points a frame needs to take part (fewer: it is held fixed, with a warning).
    pub min_points_per_frame: usize,
    /// A prior keeping consecutive frames' relative pose near its value at the start of each
    /// scale: for inputs from odometry, whose increments are good where the scene leaves
    /// directions open (open ground: x, y, yaw). Off (the paper) unless the whole-flight
    /// pipeline sets it (`FlightSettings`); not a key of the config file.
    #[serde(skip)]
    pub motion_prior: MotionPrior,
}

/// Sigmas of the motion prior on one frame-to-frame increment; 0 turns it off.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MotionPrior {
    /// Translation (m).
    pub translation_m: f64,
    /// Rotation (rad).
    pub rotation_rad: f64,
}

impl MotionPrior {
    /// True when both sigmas are set.
    pub fn is_on(&self) -> bool {
        self.translation_m > 0.0 && self.rotation_rad > 0.0
    }
}

impl Default for PssBaConfig {
    fn default() -> Self {
        Self {
            method: Method::PssBa,
            gamma0_m: 3.0,
            gamma_shrink: 1.4,
            gamma_min_m: 0.4,
            fixed_gamma_m: 1.0,
            convergence_threshold: 0.01,
            min_repeat_move_per_gamma: 0.025,
            final_plain_rounds: 1,
            max_scales: 8,
            downsample_per_gamma: 0.15,
            downsample_min_m: 0.2,
            normal_neighbours: 12,
            l0_mu: 0.05,
            l0_beta_max: 1000.0,
            l0_max_neighbours: 48,
            normal_gate_deg: 60.0,
            fine_normal_gate_deg: 30.0,
            anchor_offset_to_kernel_frame: true,
            fit_min_points: 12,
            fit_min_eigen_ratio: 1e-5,
            fit_max_rms_per_gamma: 0.2,
            fit_max_points: 256,
            frames_per_kernel_group: 100,
            residuals_per_kernel_frame: 4,
            residuals_per_kernel: 64,
            residuals_per_scale: 200_000,
            robust_scale_per_gamma: 0.1,
            robust_scale_min_m: 0.05,
            lm_max_iterations: 8,
            prior_translation_m: 0.2,
            prior_rotation_rad: 0.02,
            prior_min_gamma_m: 1.5,
            lm_initial_lambda: 1e-4,
            min_points_per_frame: 10,
            motion_prior: MotionPrior::default(),
        }
    }
}

impl PssBaConfig {
    /// Checks ranges; returns the first bad field with its value.
    pub fn validate(&self) -> Result<(), crate::CoreError> {
        let positive = [
            ("gamma0_m", self.gamma0_m),
            ("gamma_min_m", self.gamma_min_m),
            ("fixed_gamma_m", self.fixed_gamma_m),
            ("convergence_threshold", self.convergence_threshold),
            ("min_repeat_move_per_gamma", self.min_repeat_move_per_gamma),
            ("downsample_per_gamma", self.downsample_per_gamma),
            ("downsample_min_m", self.downsample_min_m),
            ("l0_mu", self.l0_mu),
            ("l0_beta_max", self.l0_beta_max),
            ("normal_gate_deg", self.normal_gate_deg),
            ("fine_normal_gate_deg", self.fine_normal_gate_deg),
            ("fit_min_eigen_ratio", self.fit_min_eigen_ratio),
            ("fit_max_rms_per_gamma", self.fit_max_rms_per_gamma),
            ("robust_scale_per_gamma", self.robust_scale_per_gamma),
            ("robust_scale_min_m", self.robust_scale_min_m),
            ("lm_initial_lambda", self.lm_initial_lambda),
            ("prior_translation_m", self.prior_translation_m),
            ("prior_rotation_rad", self.prior_rotation_rad),
            ("prior_min_gamma_m", self.prior_min_gamma_m),
        ];
        for (field, value) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(crate::CoreError::InvalidConfig {
                    field,
                    value: value.to_string(),
                    reason: "must be a finite number > 0",
                });
            }
        }
        for (field, value) in [
            (
                "motion_prior.translation_m",
                self.motion_prior.translation_m,
            ),
            ("motion_prior.rotation_rad", self.motion_prior.rotation_rad),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(crate::CoreError::InvalidConfig {
                    field,
                    value: value.to_string(),
                    reason: "must be a finite number >= 0 (0: off)",
                });
            }
        }
        if !(self.gamma_shrink.is_finite() && self.gamma_shrink > 1.0) {
            return Err(crate::CoreError::InvalidConfig {
                field: "gamma_shrink",
                value: self.gamma_shrink.to_string(),
                reason: "must be > 1",
            });
        }
        let counts = [
            ("max_scales", self.max_scales, 1),
            ("normal_neighbours", self.normal_neighbours, 3),
            ("fit_min_points", self.fit_min_points, 6),
            ("fit_max_points", self.fit_max_points, 6),
            (
                "residuals_per_kernel_frame",
                self.residuals_per_kernel_frame,
                1,
            ),
            ("frames_per_kernel_group", self.frames_per_kernel_group, 1),
            ("residuals_per_kernel", self.residuals_per_kernel, 1),
            ("residuals_per_scale", self.residuals_per_scale, 1),
            ("lm_max_iterations", self.lm_max_iterations, 1),
            ("l0_max_neighbours", self.l0_max_neighbours, 1),
        ];
        for (field, value, min) in counts {
            if value < min {
                return Err(crate::CoreError::InvalidConfig {
                    field,
                    value: value.to_string(),
                    reason: "too small",
                });
            }
        }
        Ok(())
    }

    /// Cauchy loss scale (m) at kernel width `gamma_m`.
    pub fn robust_scale_m(&self, gamma_m: f64) -> f64 {
        (self.robust_scale_per_gamma * gamma_m).max(self.robust_scale_min_m)
    }

    /// A coarse scale (kernel width `gamma_m` at least `prior_min_gamma_m`): it carries the
    /// pose prior and the wide normal gate; the finer scales do neither.
    pub fn is_coarse(&self, gamma_m: f64) -> bool {
        gamma_m >= self.prior_min_gamma_m
    }

    /// The normal gate (deg) at kernel width `gamma_m`: `normal_gate_deg` at the coarse
    /// scales, `fine_normal_gate_deg` below `prior_min_gamma_m`.
    pub fn gate_deg_at(&self, gamma_m: f64) -> f64 {
        if self.is_coarse(gamma_m) {
            self.normal_gate_deg
        } else {
            self.fine_normal_gate_deg
        }
    }

    /// Per-frame downsampling voxel edge (m) at kernel width `gamma_m`.
    pub fn downsample_m(&self, gamma_m: f64) -> f64 {
        (self.downsample_per_gamma * gamma_m).max(self.downsample_min_m)
    }
}
