//! Which stages the launcher restarts when they crash, and why (README, "When a stage dies").
//! A crash is a death by a signal or a panic (exit code 101); an error a stage reports itself
//! (exit code 1: bad input, a timeout) is never retried, since it would fail the same way again.

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

/// Each stage's restart policy and the reason for it, in one place.
pub const RESTART_POLICY: [(&str, Restart, &str); 4] = [
    (
        "record",
        Restart::OnCrash,
        "it ends the part it was writing at the last flush (its journal) and goes on in a new \
         part; the ingest stage sends the frames after that point again, the smooth stage the \
         windows",
    ),
    (
        "adjust",
        Restart::OnCrash,
        "it keeps nothing between factor blocks; the smooth stage sends the pending block again",
    ),
    (
        "smooth",
        Restart::OnCrash,
        "it goes on after the last window it published (its progress file); the ingest stage \
         sends the open window's frames again",
    ),
    (
        "ingest",
        Restart::OnCrash,
        "it resumes after the last frame it published (its progress file)",
    ),
];

/// With live input the frames came from an outside producer, which cannot send them again: a
/// crashed smooth stage (its open window) or record stage (its unwritten frames) then stops
/// the run.
const LIVE_SMOOTH: (Restart, &str) = (
    Restart::Never,
    "with live input the open window's frames are gone with it (an outside producer cannot \
     send them again)",
);
const LIVE_RECORD: (Restart, &str) = (
    Restart::Never,
    "with live input the frames it had not written are gone with it (an outside producer \
     cannot send them again)",
);

/// The policy of `stage` and why (a stage missing from the table is never restarted), for a
/// run on files or (`live`) on an outside producer's frames.
pub fn policy(stage: &str, live: bool) -> (Restart, &'static str) {
    match stage {
        "smooth" if live => return LIVE_SMOOTH,
        "record" if live => return LIVE_RECORD,
        _ => {}
    }
    RESTART_POLICY
        .iter()
        .find(|(name, ..)| *name == stage)
        .map_or(
            (Restart::Never, "it has no restart policy"),
            |&(_, p, why)| (p, why),
        )
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
    fn every_stage_has_a_policy_and_only_stages_whose_state_survives_restart() {
        for stage in crate::supervision::launcher::STAGES {
            assert!(
                RESTART_POLICY.iter().any(|(name, ..)| *name == stage),
                "{stage}"
            );
        }
        for live in [false, true] {
            assert_eq!(policy("adjust", live).0, Restart::OnCrash);
            assert_eq!(policy("ingest", live).0, Restart::OnCrash);
            assert_eq!(policy("no such stage", live).0, Restart::Never);
        }
        for stage in ["smooth", "record"] {
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
