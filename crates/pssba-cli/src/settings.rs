//! Loading the algorithm config from TOML. The same file can carry the process system's
//! `[system]` table (see `pssba run`), so one config serves `adjust` and `run`.

use pssba_core::PssBaConfig;
use pssba_system::RunConfig;
use std::path::Path;

/// Reads `path` (keys missing from the file take their defaults) and validates it.
pub fn load_config(path: Option<&Path>) -> anyhow::Result<PssBaConfig> {
    Ok(RunConfig::load(path)?.pssba)
}
