//! The `[flight]` table: the whole-flight pipeline of `pssba run` and `pssba adjust` on long
//! inputs (keyframes, places seen again, loop closure, the motion prior), over
//! [`pssba_core::FlightSettings`]'s defaults.

use pssba_core::{FlightSettings, MotionPrior};
use serde::{Deserialize, Serialize};

/// The `[flight]` table.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FlightConfig {
    /// Find places seen again and close the loop (false: sliding windows only).
    pub loop_closure: bool,
    /// After the last window of a flight that closed a loop, one pose graph over all its
    /// keyframes and loop edges.
    pub global_pass: bool,
    /// Sigma (m) of the motion prior on consecutive frames' relative translation; 0 with
    /// `motion_prior_rotation_rad` 0: off.
    pub motion_prior_translation_m: f64,
    /// Sigma (rad) of the motion prior on relative rotation.
    pub motion_prior_rotation_rad: f64,
    /// Keyframe every this much motion (m) ...
    pub keyframe_step_m: f64,
    /// ... or rotation (deg).
    pub keyframe_step_deg: f64,
    /// Voxel edge of a keyframe's stored cloud (m).
    pub keyframe_voxel_m: f64,
    /// Old keyframes this close to a new one (m) are revisit candidates ...
    pub revisit_radius_m: f64,
    /// ... when the flight went at least this far between them (m).
    pub revisit_min_path_m: f64,
    /// Share of the new keyframes' voxels the old ones must occupy to confirm a revisit.
    pub revisit_min_overlap: f64,
    /// Largest drift (m) a revisit may correct; larger is not believed.
    pub max_correction_m: f64,
}

impl Default for FlightConfig {
    fn default() -> Self {
        let s = FlightSettings::default();
        Self {
            loop_closure: s.enabled,
            global_pass: s.global_pass,
            motion_prior_translation_m: s.motion_prior.translation_m,
            motion_prior_rotation_rad: s.motion_prior.rotation_rad,
            keyframe_step_m: s.keyframe_step_m,
            keyframe_step_deg: s.keyframe_step_deg,
            keyframe_voxel_m: s.keyframe_voxel_m,
            revisit_radius_m: s.revisit_radius_m,
            revisit_min_path_m: s.revisit_min_path_m,
            revisit_min_overlap: s.revisit_min_overlap,
            max_correction_m: s.max_correction_m,
        }
    }
}

impl FlightConfig {
    /// The settings `pssba-core` takes.
    pub fn settings(&self) -> FlightSettings {
        FlightSettings {
            enabled: self.loop_closure,
            global_pass: self.global_pass,
            motion_prior: MotionPrior {
                translation_m: self.motion_prior_translation_m,
                rotation_rad: self.motion_prior_rotation_rad,
            },
            keyframe_step_m: self.keyframe_step_m,
            keyframe_step_deg: self.keyframe_step_deg,
            keyframe_voxel_m: self.keyframe_voxel_m,
            revisit_radius_m: self.revisit_radius_m,
            revisit_min_path_m: self.revisit_min_path_m,
            revisit_min_overlap: self.revisit_min_overlap,
            max_correction_m: self.max_correction_m,
            ..FlightSettings::default()
        }
    }

    /// Checks the values; the message names the key.
    pub fn validate(&self) -> Result<(), String> {
        let motion = [
            self.motion_prior_translation_m,
            self.motion_prior_rotation_rad,
        ];
        if motion.iter().any(|v| !(v.is_finite() && *v >= 0.0)) {
            return Err(format!(
                "flight.motion_prior_translation_m = {}, motion_prior_rotation_rad = {}: must \
                 be finite and >= 0 (0: off)",
                motion[0], motion[1]
            ));
        }
        if !(self.revisit_min_path_m.is_finite() && self.revisit_min_path_m >= 0.0) {
            return Err(format!(
                "flight.revisit_min_path_m = {} must be finite and >= 0",
                self.revisit_min_path_m
            ));
        }
        self.settings()
            .validate()
            .map_err(|e| format!("[flight] {e}"))
    }
}
