//! Serial and rayon execution of the same per-item kernel, so tests can compare the two.
//! The library never configures a global thread pool: rayon work runs in the caller's pool.

use rayon::prelude::*;

/// How per-item kernels are executed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Parallelism {
    /// One thread, in order: the reference twin.
    Serial,
    /// rayon, in the pool of the calling thread.
    #[default]
    Rayon,
}

/// `(0..n).map(f).collect()`, serially or in parallel; the output order is the same.
pub fn map_indexed<T: Send>(
    n: usize,
    parallelism: Parallelism,
    f: impl Fn(usize) -> T + Sync + Send,
) -> Vec<T> {
    match parallelism {
        Parallelism::Serial => (0..n).map(f).collect(),
        Parallelism::Rayon => (0..n).into_par_iter().map(f).collect(),
    }
}
