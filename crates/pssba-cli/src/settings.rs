//! Loading the algorithm configs from TOML: the top-level keys are [`PssBaConfig`] (as in
//! `config/default.toml`); an optional `[balm]` table holds [`BalmConfig`] keys for
//! `--method balm` (missing keys, or a missing table, take BALM's defaults).

use anyhow::Context;
use pssba_balm::BalmConfig;
use pssba_core::PssBaConfig;
use std::path::Path;

/// Both configs of one run.
#[derive(Debug, Clone, Default)]
pub struct Settings {
    /// PSS-BA and its ablations.
    pub pssba: PssBaConfig,
    /// The BALM baseline (`[balm]` table).
    pub balm: BalmConfig,
}

/// Reads `path` (keys missing from the file take their defaults) and validates both configs.
pub fn load_settings(path: Option<&Path>) -> anyhow::Result<Settings> {
    let name = || path.map_or("default config".into(), |p| p.display().to_string());
    let settings = match path {
        None => Settings::default(),
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("reading config {}", path.display()))?;
            let mut table: toml::Table =
                toml::from_str(&text).with_context(|| format!("config {}", path.display()))?;
            let balm = match table.remove("balm") {
                Some(value) => value
                    .try_into()
                    .with_context(|| format!("config {}: [balm]", path.display()))?,
                None => BalmConfig::default(),
            };
            let pssba = toml::Value::Table(table)
                .try_into()
                .with_context(|| format!("config {}", path.display()))?;
            Settings { pssba, balm }
        }
    };
    settings
        .pssba
        .validate()
        .map_err(|e| anyhow::anyhow!("{}: {e}", name()))?;
    settings
        .balm
        .validate()
        .map_err(|e| anyhow::anyhow!("{}: {e}", name()))?;
    Ok(settings)
}
