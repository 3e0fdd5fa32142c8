//! The launcher with stand-in stages: an adjust stage that crashes after the smooth stage
//! finished (every factor block answered) is not restarted, and the run succeeds.

mod launcher_stand_in;

use std::time::Duration;

#[test]
fn an_adjust_crash_after_the_smooth_stage_finished_is_not_restarted() {
    // smooth finishes at 0.3 s, adjust dies at 2 s; a restarted stand-in would wait for ever.
    let run = launcher_stand_in::Run::new("adjust_dies_late");
    let outcome = run.launch(Duration::from_secs(30));
    assert!(outcome.is_ok(), "{outcome:?}");
    assert_eq!(run.adjust_starts(), 1);
}
