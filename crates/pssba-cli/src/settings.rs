//! Loading the configs from TOML: the top-level keys are [`PssBaConfig`] (as in
//! `config/default.toml`); an optional `[balm]` table holds [`BalmConfig`] keys for
//! `--method balm`, and an optional `[system]` table the process system's keys (`pssba run`).
//! Missing keys, or missing tables, take their defaults.

use anyhow::Context;
use pssba_balm::BalmConfig;
use pssba_core::PssBaConfig;
use pssba_system::{RunConfig, SystemConfig};
use std::path::Path;

/// The algorithm configs of one run.
#[derive(Debug, Clone, Default)]
pub struct Settings {
    /// PSS-BA and its ablations.
    pub pssba: PssBaConfig,
    /// The BALM baseline (`[balm]` table).
    pub balm: BalmConfig,
    /// The process system (`[system]` table); its window keys also serve
    /// `pssba adjust --window-frames`.
    pub system: SystemConfig,
}

/// Reads `path` (keys missing from the file take their defaults) and validates the configs.
pub fn load_settings(path: Option<&Path>) -> anyhow::Result<Settings> {
    let Some(path) = path else {
        return Ok(Settings::default());
    };
    let origin = path.display().to_string();
    let text = std::fs::read_to_string(path).with_context(|| format!("reading config {origin}"))?;
    let table: toml::Table = toml::from_str(&text).with_context(|| format!("config {origin}"))?;
    let balm: BalmConfig = match table.get("balm") {
        Some(value) => value
            .clone()
            .try_into()
            .with_context(|| format!("config {origin}: [balm]"))?,
        None => BalmConfig::default(),
    };
    balm.validate()
        .map_err(|e| anyhow::anyhow!("{origin}: {e}"))?;
    let RunConfig { pssba, system } = RunConfig::from_table(table, &origin)?;
    Ok(Settings {
        pssba,
        balm,
        system,
    })
}
