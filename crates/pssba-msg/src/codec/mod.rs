//! Payload codecs: the `[f64]` word layouts of factor blocks ([`block`]) and window results
//! ([`result`]), checked word reading ([`words`]), and messages of any size over fixed-size
//! samples ([`parts`]).

#[cfg(feature = "core")]
pub mod block;
pub mod parts;
#[cfg(feature = "core")]
pub mod result;
pub mod words;
