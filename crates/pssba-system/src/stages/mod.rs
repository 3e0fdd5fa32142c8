//! The four stages, each a process of the `pssba` binary (`pssba stage NAME`): `main` sets up
//! (the CLI, then [`run_stage`] and the module's `main(args, config)`: options from
//! arguments), its `run(&Options)` does the work, and tests drive
//! `run` in-process. Their names, arguments and restart policies are in [`table`].
//! - [`ingest`]: frames from an input into shared memory;
//! - [`smooth`]: sliding windows and kernel extraction (with its frame [`intake`] thread, the
//!   [`stream`] of frames into the windows, and the public [`outputs`]);
//! - [`adjust`]: the Levenberg-Marquardt solve of each factor block;
//! - [`record`]: everything to MCAP (its bookkeeping in [`record_book`]).

pub mod adjust;
pub mod ingest;
pub mod intake;
pub mod outputs;
pub mod record;
pub mod record_book;
pub mod smooth;
pub mod stream;
pub mod table;

use pssba_config::Config;
use pssba_msg::Stage;
use table::StageArgs;

/// Runs `stage` with `args`, checked against its row of [`table::STAGES`], and the config they
/// name, loaded once here and passed down.
pub fn run_stage(stage: Stage, args: StageArgs) -> crate::Result<()> {
    args.check(stage).map_err(crate::Error::Usage)?;
    let config = Config::load(args.config.as_deref())?;
    (table::spec(stage).main)(args, config)
}
