//! What can be wrong with a message read from shared memory (defined next to the public
//! frames protocol, in pssba-client).

pub use pssba_client::error::MsgError;
