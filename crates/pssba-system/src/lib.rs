//! The PSS-BA process system (DESIGN.md section 6): ingest, smooth, adjust and record as
//! separate processes exchanging frames, factor blocks, pose sets and window results over
//! iceoryx2 shared memory; the recorder writes MCAP with Foxglove schemas; the launcher runs
//! them with one command. Each stage module is a thin adapter around the libraries
//! (`pssba-core` does the math, `pssba-msg` the messages, `pssba-source` the inputs,
//! `pssba-recording` the MCAP format, `pssba-config` the settings).
//!
//! By concern: [`stages`] (one module per process), [`transport`] (shared-memory helpers),
//! [`supervision`] (the launcher and its restart policy), [`resume`] (what a restarted stage
//! needs), [`source`] (what a run reads). The stages' modules are also at the top level
//! (`pssba_system::smooth`), as the launcher is.

mod error;
pub mod resume;
pub mod source;
pub mod stages;
pub mod supervision;
pub mod transport;

pub use error::{Error, Result};
pub use pssba_config::{Config, SystemConfig};
pub use pssba_msg::Stage;
pub use stages::{adjust, ingest, record, smooth};
pub use supervision::launcher;
pub use transport::shm;
