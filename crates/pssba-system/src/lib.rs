//! The PSS-BA process system (DESIGN.md section 6): ingest, smooth, adjust and record as
//! separate processes exchanging frames, factor blocks, pose sets and window results over
//! iceoryx2 shared memory; the recorder writes MCAP with Foxglove schemas; the launcher runs
//! them with one command. Each stage module is a thin adapter around the libraries
//! (`pssba-core` does the math, `pssba-msg` the messages).

pub mod adjust;
pub mod config;
pub mod ingest;
pub mod intake;
pub mod latency;
pub mod launcher;
pub mod mcap_out;
pub mod mcap_read;
pub mod outputs;
pub mod progress;
pub mod record;
pub mod record_book;
pub mod record_journal;
pub mod replay;
pub mod restart;
pub mod resume;
pub mod retained;
pub mod shm;
pub mod smooth;
pub mod source;
pub mod stream;

pub use config::{RunConfig, SystemConfig};
