//! Loading the algorithm config from TOML.

use anyhow::Context;
use pssba_core::PssBaConfig;
use std::path::Path;

/// Reads `path` (keys missing from the file take their defaults) and validates it.
pub fn load_config(path: Option<&Path>) -> anyhow::Result<PssBaConfig> {
    let config = match path {
        None => PssBaConfig::default(),
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("reading config {}", path.display()))?;
            toml::from_str(&text).with_context(|| format!("config {}", path.display()))?
        }
    };
    config.validate().map_err(|e| {
        anyhow::anyhow!(
            "{}: {e}",
            path.map_or("default config".into(), |p| p.display().to_string())
        )
    })?;
    Ok(config)
}
