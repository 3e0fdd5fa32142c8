//! The internal part of the protocol: the services between the system's own stages (factor
//! blocks, pose sets, window results, rewinds, the recorder's confirmations). Not part of
//! docs/interface.md: it may change between releases.

pub mod services;
pub mod types;
