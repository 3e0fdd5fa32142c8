//! Shared-memory helpers the stages share: publishing a header + slice, waiting for consumers,
//! termination checks ([`shm`]), and the transport's latency against a memcpy ([`latency`]).
//! The messages themselves are `pssba-msg`'s.

pub mod latency;
pub mod shm;
