//! Transport latency of frames (ingest send -> smooth receive), compared at the end with the
//! time of one memcpy of the largest frame's bytes: the floor of any shared-memory transport.

use std::time::{Instant, SystemTime, UNIX_EPOCH};

/// Running latency statistics (ns).
#[derive(Debug, Default)]
pub struct LatencyStats {
    samples_ns: Vec<u64>,
}

impl LatencyStats {
    /// Records the latency of a sample sent at `sent_unix_ns` (ignored if the clock is odd).
    pub fn record(&mut self, sent_unix_ns: u64) {
        let now = now_unix_ns();
        if sent_unix_ns > 0 && now >= sent_unix_ns {
            self.samples_ns.push(now - sent_unix_ns);
        }
    }

    /// Records the latency of a sample sent at `sent_unix_ns` and received at
    /// `received_unix_ns` (ignored if the clock is odd).
    pub fn record_received(&mut self, sent_unix_ns: u64, received_unix_ns: u64) {
        if sent_unix_ns > 0 && received_unix_ns >= sent_unix_ns {
            self.samples_ns.push(received_unix_ns - sent_unix_ns);
        }
    }

    /// Median of the recorded latencies (ns).
    pub fn median_ns(&self) -> Option<u64> {
        let mut sorted = self.samples_ns.clone();
        sorted.sort_unstable();
        sorted.get(sorted.len() / 2).copied()
    }

    /// Median of the first `n` latencies (ns): frames that arrived while the first window was
    /// still filling, so this stage was waiting for them (pure transport + wake-up).
    pub fn median_of_first_ns(&self, n: usize) -> Option<u64> {
        let mut first: Vec<u64> = self.samples_ns.iter().take(n).copied().collect();
        first.sort_unstable();
        first.get(first.len() / 2).copied()
    }

    /// Logs median/min latency next to the memcpy time of `points` xyz f32 points.
    pub fn log_summary(&self, points: usize, first_window: usize) {
        let Some(median) = self.median_ns() else {
            return;
        };
        let idle_median = self
            .median_of_first_ns(first_window.saturating_sub(1))
            .unwrap_or(0);
        let min = self.samples_ns.iter().copied().min().unwrap_or(0);
        let bytes = points * 12;
        let source = vec![1u8; bytes];
        let mut target = vec![0u8; bytes];
        let started = Instant::now();
        target.copy_from_slice(&source);
        let memcpy_ns = started.elapsed().as_nanos();
        std::hint::black_box(&target);
        tracing::info!(
            "frame transport ingest->smooth over {} frames: median {:.1} us while the first \
             window filled (receiver waiting), median {:.1} us overall (includes queueing while \
             this stage was busy), min {:.1} us; memcpy of one {bytes}-byte frame: {:.1} us",
            self.samples_ns.len(),
            idle_median as f64 / 1e3,
            median as f64 / 1e3,
            min as f64 / 1e3,
            memcpy_ns as f64 / 1e3
        );
    }
}

/// Wall clock, ns since the Unix epoch (0 before 1970).
pub(crate) fn now_unix_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}

/// How long after it was sent each frame got its final pose: the delay a user of the live
/// poses sees (at least the time to fill a window's new frames, plus the window's run).
#[derive(Debug, Default)]
pub struct FinalLag {
    sent_unix_ns: Vec<u64>,
    lags_s: Vec<f64>,
}

impl FinalLag {
    /// Frame `sequence` (the next one) was sent at `sent_unix_ns`.
    pub fn sent(&mut self, sequence: usize, sent_unix_ns: u64) {
        if self.sent_unix_ns.len() <= sequence {
            self.sent_unix_ns.resize(sequence + 1, 0);
        }
        self.sent_unix_ns[sequence] = sent_unix_ns;
    }

    /// These frames just became final; returns (min, max) lag (s) among them.
    pub fn finalised(&mut self, sequences: impl Iterator<Item = usize>) -> Option<(f64, f64)> {
        let now = now_unix_ns();
        let lags: Vec<f64> = sequences
            .filter_map(|k| self.sent_unix_ns.get(k).copied())
            .filter(|&sent| sent > 0 && now >= sent)
            .map(|sent| (now - sent) as f64 * 1e-9)
            .collect();
        self.lags_s.extend_from_slice(&lags);
        let min = lags.iter().copied().reduce(f64::min)?;
        let max = lags.iter().copied().reduce(f64::max)?;
        Some((min, max))
    }

    /// Logs the median and largest lag over the run.
    pub fn log_summary(&self) {
        let mut sorted = self.lags_s.clone();
        sorted.sort_unstable_by(f64::total_cmp);
        let p99_index = (sorted.len() * 99).div_ceil(100).saturating_sub(1);
        if let (Some(median), Some(p99), Some(max)) = (
            sorted.get(sorted.len() / 2),
            sorted.get(p99_index),
            sorted.last(),
        ) {
            tracing::info!(
                "frame sent -> final pose over {} frames: median {median:.2} s, p99 {p99:.2} s, \
                 max {max:.2} s",
                sorted.len()
            );
        }
    }
}
