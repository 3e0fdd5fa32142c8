//! The `[output]` table: the files `pssba run` writes beside its recording (the final
//! trajectory and map), and the defaults of `pssba export`.

use serde::{Deserialize, Serialize};

/// The `[output]` table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct OutputConfig {
    /// Edge (m) of the voxels the map is reduced to: one point, the centroid, per voxel.
    pub map_voxel_m: f64,
}

impl Default for OutputConfig {
    fn default() -> Self {
        OutputConfig { map_voxel_m: 0.1 }
    }
}

impl OutputConfig {
    /// Checks the voxel size.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.map_voxel_m.is_finite() && self.map_voxel_m > 0.0) {
            return Err(format!(
                "output.map_voxel_m = {} must be a positive number of metres",
                self.map_voxel_m
            ));
        }
        Ok(())
    }
}
