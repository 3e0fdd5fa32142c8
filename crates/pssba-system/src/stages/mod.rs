//! The four stages, each a process of the `pssba` binary (`pssba stage NAME`): `main` sets up
//! (the CLI, then [`run_stage`]), each module's `run(&Options)` does the work, and tests drive
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

use crate::source::SourceSpec;
use pssba_config::Config;
use pssba_msg::Stage;
use table::StageArgs;

/// Runs `stage` with `args` (checked against [`table::STAGES`]) and the config they name,
/// loaded once here.
pub fn run_stage(stage: Stage, args: StageArgs) -> anyhow::Result<()> {
    args.check(stage).map_err(anyhow::Error::msg)?;
    let config = Config::load(args.config.as_deref())?;
    let StageArgs {
        prefix,
        out,
        live,
        progress,
        source,
        rate_hz,
        ..
    } = args;
    match stage {
        Stage::Ingest => {
            let source = source.unwrap_or_default();
            let SourceSpec::Input(source) = source.parse()? else {
                anyhow::bail!(
                    "--source {source}: live frames come from outside producers, not ingest"
                );
            };
            ingest::run(&ingest::IngestOptions {
                prefix,
                source,
                rate_hz,
                config,
                progress,
            })
        }
        Stage::Smooth => smooth::run(&smooth::SmoothOptions {
            prefix,
            config,
            live,
            progress,
        }),
        Stage::Adjust => adjust::run(&adjust::AdjustOptions { prefix, config }),
        Stage::Record => record::run(&record::RecordOptions {
            prefix,
            out: out.unwrap_or_default(),
            config,
            live,
            progress,
        }),
    }
}
