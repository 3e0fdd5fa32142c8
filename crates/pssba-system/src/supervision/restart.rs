//! Which stages the launcher restarts when they crash, and why (README, "When a stage dies").
//! A crash is a death by a signal or a panic (exit code 101); an error a stage reports itself
//! (exit code 1: bad input, a timeout) is never retried, since it would fail the same way again.

use crate::stages::table::{self, Live};
use pssba_msg::Stage;
use std::os::unix::process::ExitStatusExt;
use std::process::ExitStatus;

/// What the launcher does when a stage crashes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Restart {
    /// Start it again, up to `[system] max_restarts` times, after a doubling backoff.
    OnCrash,
    /// Stop the run, naming the stage.
    Never,
}

/// The policy of `stage` and why ([`crate::stages::table`]), for a run on files or (`live`)
/// on an outside producer's frames.
pub fn policy(stage: Stage, live: bool) -> (Restart, &'static str) {
    let spec = table::spec(stage);
    match spec.live {
        Live::Restart(restart, why) if live => (restart, why),
        Live::NotRun if live => (Restart::Never, "it does not run on live input"),
        _ => spec.restart,
    }
}

/// Exit code of a Rust process that panicked.
const PANIC_EXIT_CODE: i32 = 101;

/// True if `status` is a crash (a signal or a panic), not an error the stage reported.
pub fn crashed(status: &ExitStatus) -> bool {
    status.signal().is_some() || status.code() == Some(PANIC_EXIT_CODE)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_stages_whose_state_survives_restart_are_restarted() {
        for live in [false, true] {
            assert_eq!(policy(Stage::Adjust, live).0, Restart::OnCrash);
        }
        assert_eq!(policy(Stage::Ingest, false).0, Restart::OnCrash);
        for stage in [Stage::Smooth, Stage::Record] {
            assert_eq!(policy(stage, false).0, Restart::OnCrash, "{stage}");
            assert_eq!(policy(stage, true).0, Restart::Never, "{stage}");
        }
    }

    #[test]
    fn signals_and_panics_are_crashes_reported_errors_are_not() {
        // Raw wait statuses: a signal in the low 7 bits, an exit code in bits 8..16.
        assert!(crashed(&ExitStatus::from_raw(9)));
        assert!(crashed(&ExitStatus::from_raw(101 << 8)));
        assert!(!crashed(&ExitStatus::from_raw(1 << 8)));
        assert!(!crashed(&ExitStatus::from_raw(0)));
    }
}
