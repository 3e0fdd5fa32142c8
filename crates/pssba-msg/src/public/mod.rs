//! The public part of the protocol: what an outside process sends (frames) and reads (final
//! poses, window summaries, map chunks, surfaces), as docs/interface.md specifies it.

pub mod frame;
pub mod services;
pub mod types;
