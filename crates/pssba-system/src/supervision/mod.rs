//! `pssba run`: the [`launcher`] starts, supervises and stops the stages; [`restart`] is its
//! policy for stages that crash.

pub mod launcher;
pub mod restart;
