//! The launcher with stand-in stages (a shell script in place of `pssba stage ...`): an adjust
//! stage restarted after the run's last factor block can receive no block, and must not keep
//! the run from ending. Each scenario is its own test binary's only `launch` (the launcher
//! installs the process's Ctrl-C handler once).

mod launcher_stand_in;

use std::time::Duration;

#[test]
fn a_restarted_adjust_stage_is_stopped_once_the_smooth_stage_finishes() {
    // adjust dies at 0.3 s and is restarted after 0.1 s; its stand-in then waits for ever,
    // as a real one would for blocks; smooth finishes at 3 s. Before, the launcher waited
    // for the restarted stage until the watchdog failed the run.
    let run = launcher_stand_in::Run::new("adjust_dies_early");
    let outcome = run.launch(Duration::from_secs(30));
    assert!(outcome.is_ok(), "{outcome:?}");
    assert_eq!(run.adjust_starts(), 2);
}
