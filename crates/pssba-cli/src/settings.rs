//! Loading the configs from TOML: the top-level keys are [`PssBaConfig`] (as in
//! `config/default.toml`); an optional `[balm]` table holds [`BalmConfig`] keys for
//! `--method balm`, and an optional `[system]` table the process system's keys (`pssba run`).
//! Missing keys, or missing tables, take their defaults.

use anyhow::Context;
use pssba_balm::BalmConfig;
use pssba_core::PssBaConfig;
use pssba_system::{RunConfig, SystemConfig};
use std::path::Path;

/// The algorithm configs of one run.
#[derive(Debug, Clone, Default)]
pub struct Settings {
    /// PSS-BA and its ablations.
    pub pssba: PssBaConfig,
    /// The BALM baseline (`[balm]` table).
    pub balm: BalmConfig,
    /// The process system (`[system]` table); its window keys also serve
    /// `pssba adjust --window-frames`.
    pub system: SystemConfig,
    /// How robot recordings are read (`[recording]` table).
    pub recording: RecordingConfig,
}

/// The `[recording]` table: defaults of the recording flags (`--points-topic` ...).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RecordingConfig {
    /// Cloud topic; empty: the only one.
    pub points_topic: String,
    /// Pose topic; empty: the only one.
    pub poses_topic: String,
    /// body_from_lidar `[tx, ty, tz, qx, qy, qz, qw]`; empty: from /tf_static, else identity.
    pub extrinsic: Vec<f64>,
    /// Largest gap (s) between the two poses a cloud's pose is interpolated from.
    pub max_pose_gap_s: f64,
}

impl Default for RecordingConfig {
    fn default() -> Self {
        RecordingConfig {
            points_topic: String::new(),
            poses_topic: String::new(),
            extrinsic: Vec::new(),
            max_pose_gap_s: pssba_bag::recording::DEFAULT_MAX_POSE_GAP_S,
        }
    }
}

/// Reads `path` (keys missing from the file take their defaults) and validates the configs.
pub fn load_settings(path: Option<&Path>) -> anyhow::Result<Settings> {
    let Some(path) = path else {
        return Ok(Settings::default());
    };
    let origin = path.display().to_string();
    let text = std::fs::read_to_string(path).with_context(|| format!("reading config {origin}"))?;
    let table: toml::Table = toml::from_str(&text).with_context(|| format!("config {origin}"))?;
    let balm: BalmConfig = match table.get("balm") {
        Some(value) => value
            .clone()
            .try_into()
            .with_context(|| format!("config {origin}: [balm]"))?,
        None => BalmConfig::default(),
    };
    balm.validate()
        .map_err(|e| anyhow::anyhow!("{origin}: {e}"))?;
    let recording: RecordingConfig = match table.get("recording") {
        Some(value) => value
            .clone()
            .try_into()
            .with_context(|| format!("config {origin}: [recording]"))?,
        None => RecordingConfig::default(),
    };
    let RunConfig { pssba, system } = RunConfig::from_table(table, &origin)?;
    Ok(Settings {
        pssba,
        balm,
        system,
        recording,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const DEFAULT_FILE: &str = include_str!("../../../config/default.toml");

    #[test]
    fn the_recording_table_equals_the_defaults_key_by_key() {
        let file: toml::Table = toml::from_str(DEFAULT_FILE).expect("TOML");
        let table = file["recording"].as_table().expect("[recording]").clone();
        let parsed: RecordingConfig = toml::Value::Table(table.clone())
            .try_into()
            .expect("parses");
        assert_eq!(parsed, RecordingConfig::default());
        let defaults: toml::Table =
            toml::Table::try_from(RecordingConfig::default()).expect("table");
        assert_eq!(table, defaults);
    }

    #[test]
    fn a_bad_recording_key_is_named() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("c.toml");
        std::fs::write(&path, "[recording]\nmax_pose_gap = 1.0\n").expect("write");
        let error = format!("{:#}", load_settings(Some(&path)).expect_err("unknown key"));
        assert!(
            error.contains("[recording]") && error.contains("max_pose_gap"),
            "{error}"
        );
    }
}
