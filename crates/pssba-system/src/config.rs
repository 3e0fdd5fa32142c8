//! The run configuration: one TOML file for every stage. The PSS-BA keys sit at the top level
//! (as in `config/default.toml`); the process system's keys live in a `[system]` table.

use crate::intake::{Overflow, ProducerLost};
use anyhow::{Context, bail};
use pssba_core::PssBaConfig;
use pssba_core::WindowSpec;
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::time::Duration;

/// Settings of the process system: the `[system]` table of `config/default.toml`, which a
/// test keeps equal to [`SystemConfig::default`]. Nothing here limits the size of ordinary
/// data: replayed frames size the frames service from their largest frame, and factor blocks
/// and window results of any size travel as several samples.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SystemConfig {
    /// Frames per sliding window (W).
    pub window_frames: usize,
    /// New frames per window after the first (S < W); the other W - S frames of each later
    /// window are already final and hold the window in place.
    pub window_stride: usize,
    /// Keep going when a window's adjustment fails (its frames keep their corrected initial
    /// poses); `false` makes `pssba run` exit non-zero after recording everything.
    pub allow_failed_windows: bool,
    /// How long a stage waits for the others to appear at start-up (s).
    pub startup_timeout_s: f64,
    /// A publisher gives up when a consumer has not made room for this long (s).
    pub backpressure_timeout_s: f64,
    /// The smooth stage gives up waiting for the adjust stage's poses after this long (s).
    pub reply_timeout_s: f64,
    /// Largest frame (points) of live input, whose size is not known up front; replayed data
    /// sizes the frames service from its own largest frame instead. The default covers a
    /// 128-beam spinning LiDAR (2048 x 128 = 262,144 points).
    pub live_max_frame_points: usize,
    /// Live input: what the smooth stage does when `live_backlog_frames` frames wait for it
    /// (a window is being solved). `drop` (the default for live input: a live sensor must
    /// never be stalled; frames are dropped and counted) or `block` (lossless: the producer's
    /// `send` waits). Replayed input is always lossless.
    pub live_overflow: Overflow,
    /// Frames that may wait for the smooth stage while it solves a window (live input, and the
    /// read-ahead of replayed input). At 10 Hz the default holds 10 s of frames; its memory is
    /// 12 bytes per point (24 MB for 100 Mid-360 frames).
    pub live_backlog_frames: usize,
    /// Live input: when the producer vanishes without its end-of-stream marker (a crash),
    /// `finish` the frames received and exit 0, or finish them and `wait` for a new producer
    /// on the same instance (its frames start new windows: a restarted odometry may start a
    /// new world frame). With `wait` the run ends on a marker, `--frames N` or Ctrl-C.
    pub live_producer_lost: ProducerLost,
    /// Live input: stop after this many frames, as if the end-of-stream marker had come
    /// (`pssba run --input live --frames N`); 0: no limit.
    pub live_max_frames: u64,
    /// f64 words in one shared-memory sample of a factor block or a window result; a larger
    /// message is split into several samples of a sequence.
    pub sample_words: usize,
    /// Restarts of one stage that crashed (killed by a signal, or a panic) before the run is
    /// stopped, naming it; 0 = never restart. Which stages may be restarted is the
    /// launcher's policy table (`launcher::RESTART_POLICY`).
    pub max_restarts: u32,
    /// Wait before a crashed stage's first restart; it doubles with each further restart of
    /// the same stage.
    pub restart_backoff_s: f64,
}

impl Default for SystemConfig {
    fn default() -> Self {
        Self {
            window_frames: 100,
            window_stride: 80,
            allow_failed_windows: false,
            startup_timeout_s: 60.0,
            backpressure_timeout_s: 120.0,
            reply_timeout_s: 600.0,
            live_max_frame_points: 1 << 18,
            live_overflow: Overflow::Drop,
            live_backlog_frames: 100,
            live_producer_lost: ProducerLost::Finish,
            live_max_frames: 0,
            sample_words: 1 << 20,
            max_restarts: 3,
            restart_backoff_s: 0.2,
        }
    }
}

impl SystemConfig {
    /// The window length and stride.
    pub fn window_spec(&self) -> WindowSpec {
        WindowSpec {
            window_frames: self.window_frames,
            window_stride: self.window_stride,
        }
    }

    /// Checks the values; the error names the key.
    pub fn validate(&self) -> anyhow::Result<()> {
        self.window_spec()
            .validate()
            .map_err(|e| anyhow::anyhow!("[system] {e}"))?;
        for (key, value, low) in [
            ("live_max_frame_points", self.live_max_frame_points, 1),
            ("live_backlog_frames", self.live_backlog_frames, 1),
            ("sample_words", self.sample_words, 1024),
        ] {
            if !(low..=1 << 28).contains(&value) {
                bail!("system.{key} = {value} must be in {low}..=2^28");
            }
        }
        for (key, value) in [
            ("startup_timeout_s", self.startup_timeout_s),
            ("backpressure_timeout_s", self.backpressure_timeout_s),
            ("reply_timeout_s", self.reply_timeout_s),
            ("restart_backoff_s", self.restart_backoff_s),
        ] {
            if !(value.is_finite() && value > 0.0) {
                bail!("system.{key} = {value} must be a positive number of seconds");
            }
        }
        Ok(())
    }

    /// Start-up timeout.
    pub fn startup_timeout(&self) -> Duration {
        Duration::from_secs_f64(self.startup_timeout_s)
    }

    /// Wait before restart `restart` (1, 2, ...) of a stage: the backoff, doubled each time
    /// (capped at 2^6 times).
    pub fn restart_backoff(&self, restart: u32) -> Duration {
        let doublings = restart.saturating_sub(1).min(6);
        Duration::from_secs_f64(self.restart_backoff_s * f64::from(1u32 << doublings))
    }

    /// Publisher backpressure timeout.
    pub fn backpressure_timeout(&self) -> Duration {
        Duration::from_secs_f64(self.backpressure_timeout_s)
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
        // Read by the command-line tool only (how recordings are read); see pssba-cli.
        table.remove("recording");
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
