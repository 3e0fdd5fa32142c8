//! The run configuration: one TOML file for every stage. The PSS-BA keys sit at the top level
//! (as in `config/default.toml`); the process system's keys live in a `[system]` table.

use anyhow::{Context, bail};
use pssba_core::PssBaConfig;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Settings of the process system.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SystemConfig {
    /// Frames per sliding window (W).
    pub window_frames: usize,
    /// New frames per window after the first (S < W); the other W - S frames of each later
    /// window are already final and hold the window in place.
    pub window_stride: usize,
    /// A publisher gives up when a consumer has not made room for this long (s).
    pub backpressure_timeout_s: f64,
    /// The smooth stage gives up waiting for the adjust stage's poses after this long (s).
    pub reply_timeout_s: f64,
    /// Largest frame (points) the frames service carries; shared memory is sized for it.
    pub max_frame_points: usize,
    /// Largest factor block (f64 words: 13 per frame, 20 per surface, 6 per residual; a
    /// 40-frame window of 8k-point frames needs about 2.6 million at the finest scales).
    pub max_block_words: usize,
    /// Largest window result (f64 words: 14 per final pose, 20 per surface, 3 per map point,
    /// 15 per scale); a larger smoothed map is thinned to fit, with a warning.
    pub max_result_words: usize,
}

impl Default for SystemConfig {
    fn default() -> Self {
        Self {
            window_frames: 100,
            window_stride: 80,
            backpressure_timeout_s: 120.0,
            reply_timeout_s: 600.0,
            max_frame_points: 1 << 16,
            max_block_words: 1 << 23,
            max_result_words: 1 << 21,
        }
    }
}

impl SystemConfig {
    /// Checks the values; the error names the key.
    pub fn validate(&self) -> anyhow::Result<()> {
        if self.window_frames < 2 {
            bail!(
                "system.window_frames = {} must be at least 2",
                self.window_frames
            );
        }
        if self.window_stride == 0 || self.window_stride >= self.window_frames {
            bail!(
                "system.window_stride = {} must be in 1..window_frames ({}): later windows \
                 need at least one final frame to anchor them",
                self.window_stride,
                self.window_frames
            );
        }
        for (key, value) in [
            ("max_frame_points", self.max_frame_points),
            ("max_block_words", self.max_block_words),
            ("max_result_words", self.max_result_words),
        ] {
            if !(1..=1 << 28).contains(&value) {
                bail!("system.{key} = {value} must be in 1..=2^28");
            }
        }
        for (key, value) in [
            ("backpressure_timeout_s", self.backpressure_timeout_s),
            ("reply_timeout_s", self.reply_timeout_s),
        ] {
            if !(value.is_finite() && value > 0.0) {
                bail!("system.{key} = {value} must be a positive number of seconds");
            }
        }
        Ok(())
    }
}

/// Everything a run needs.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RunConfig {
    /// The algorithm.
    pub pssba: PssBaConfig,
    /// The process system.
    pub system: SystemConfig,
}

impl RunConfig {
    /// Parses TOML text; `origin` names the file in errors.
    pub fn from_toml(text: &str, origin: &str) -> anyhow::Result<Self> {
        let table: toml::Table =
            toml::from_str(text).with_context(|| format!("config {origin}"))?;
        Self::from_table(table, origin)
    }

    /// From a parsed TOML table. A `[balm]` table (the BALM baseline's settings, read by
    /// `pssba adjust --method balm`) is ignored here.
    pub fn from_table(mut table: toml::Table, origin: &str) -> anyhow::Result<Self> {
        table.remove("balm");
        let system = match table.remove("system") {
            Some(value) => value
                .try_into::<SystemConfig>()
                .with_context(|| format!("config {origin}: [system]"))?,
            None => SystemConfig::default(),
        };
        let pssba: PssBaConfig = toml::Value::Table(table)
            .try_into()
            .with_context(|| format!("config {origin}"))?;
        pssba
            .validate()
            .map_err(|e| anyhow::anyhow!("config {origin}: {e}"))?;
        system
            .validate()
            .with_context(|| format!("config {origin}"))?;
        Ok(Self { pssba, system })
    }

    /// Reads `path`, or the defaults when `None`.
    pub fn load(path: Option<&Path>) -> anyhow::Result<Self> {
        match path {
            None => Ok(Self::default()),
            Some(path) => {
                let text = std::fs::read_to_string(path)
                    .with_context(|| format!("reading config {}", path.display()))?;
                Self::from_toml(&text, &path.display().to_string())
            }
        }
    }

    /// The TOML text of this config (what the launcher hands to the stages).
    pub fn to_toml(&self) -> anyhow::Result<String> {
        let mut table = toml::Table::try_from(&self.pssba).context("serialising the config")?;
        table.insert(
            "system".into(),
            toml::Value::try_from(&self.system).context("serialising [system]")?,
        );
        Ok(toml::to_string(&table)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_through_toml() -> anyhow::Result<()> {
        let mut config = RunConfig::default();
        config.system.window_frames = 40;
        config.system.window_stride = 30;
        config.pssba.max_scales = 5;
        let text = config.to_toml()?;
        assert_eq!(RunConfig::from_toml(&text, "test")?, config);
        Ok(())
    }

    #[test]
    fn bad_values_name_the_key() {
        let err = RunConfig::from_toml("[system]\nwindow_stride = 0\n", "x.toml")
            .expect_err("stride 0 must be refused");
        assert!(format!("{err:#}").contains("window_stride"), "{err:#}");
        let err = RunConfig::from_toml("[system]\nwindow_frame = 3\n", "x.toml")
            .expect_err("unknown key must be refused");
        assert!(format!("{err:#}").contains("window_frame"), "{err:#}");
    }
}
