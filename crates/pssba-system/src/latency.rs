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
        let now = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as u64);
        if sent_unix_ns > 0 && now >= sent_unix_ns {
            self.samples_ns.push(now - sent_unix_ns);
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
