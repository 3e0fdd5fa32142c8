//! What a stage restarted after a crash needs to go on where its predecessor stopped (README,
//! "When a stage dies"): the [`progress`] file every stage keeps, the smooth stage's windows
//! ([`smooth_state`]) and the results it keeps until they are on disk ([`retained`]), the
//! record stage's journal ([`record_journal`]).

pub mod progress;
pub mod record_journal;
pub mod retained;
pub mod smooth_state;
