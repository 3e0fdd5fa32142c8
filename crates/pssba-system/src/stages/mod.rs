//! The four stages, each a process of the `pssba` binary (`pssba stage NAME`): `main` sets up
//! (the CLI), each module's `run(&Options)` does the work, and tests drive `run` in-process.
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
