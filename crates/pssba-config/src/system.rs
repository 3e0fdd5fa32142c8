//! The `[system]` table: the process system's settings (`pssba run` and its stages).

use serde::{Deserialize, Serialize};
use std::time::Duration;

/// What the intake does when the backlog is full.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Overflow {
    /// Wait for room (lossless; the producer waits in turn).
    Block,
    /// Drop the new frame and count it (the producer never waits).
    Drop,
}

/// What the system does when a live producer vanishes without its end-of-stream marker.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ProducerLost {
    /// Finish the frames received, record them and exit 0.
    Finish,
    /// Finish the frames received, record them, then wait for a new producer on the same
    /// instance; its frames start a new sequence of windows.
    Wait,
}

/// Settings of the process system: the `[system]` table of `config/default.toml`, which a
/// test keeps equal to [`SystemConfig::default`]. Nothing here limits the size of ordinary
/// data: replayed frames size the frames service from their largest frame, and factor blocks
/// and window results of any size travel as several samples.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SystemConfig {
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
    /// launcher's policy table (`pssba-system`'s launcher).
    pub max_restarts: u32,
    /// Wait before a crashed stage's first restart; it doubles with each further restart of
    /// the same stage.
    pub restart_backoff_s: f64,
}

impl Default for SystemConfig {
    fn default() -> Self {
        Self {
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
    /// Checks the values; the error names the key.
    pub fn validate(&self) -> Result<(), String> {
        for (key, value, low) in [
            ("live_max_frame_points", self.live_max_frame_points, 1),
            ("live_backlog_frames", self.live_backlog_frames, 1),
            ("sample_words", self.sample_words, 1024),
        ] {
            if !(low..=1 << 28).contains(&value) {
                return Err(format!("system.{key} = {value} must be in {low}..=2^28"));
            }
        }
        for (key, value) in [
            ("startup_timeout_s", self.startup_timeout_s),
            ("backpressure_timeout_s", self.backpressure_timeout_s),
            ("reply_timeout_s", self.reply_timeout_s),
            ("restart_backoff_s", self.restart_backoff_s),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(format!(
                    "system.{key} = {value} must be a positive number of seconds"
                ));
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
