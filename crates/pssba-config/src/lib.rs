//! The one configuration of a PSS-BA process: a TOML file (`config/default.toml` spells out
//! every key with its unit) whose top-level keys are the algorithm ([`PssBaConfig`]), with
//! tables `[windows]`, `[flight]`, `[balm]`, `[system]`, `[recording]` and `[output]`. Loaded once per process
//! ([`Config::load`]) and passed down; keys left out take the defaults of each section's
//! `Default`, which a test keeps equal to the file.

mod error;
mod flight;
mod output;
mod recording;
mod system;

pub use error::ConfigError;
pub use flight::FlightConfig;
pub use output::OutputConfig;
pub use recording::RecordingConfig;
pub use system::{Overflow, ProducerLost, SystemConfig};

use pssba_balm::BalmConfig;
use pssba_core::{PssBaConfig, WindowSpec};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The `[windows]` table: the sliding windows of `pssba run` (and `pssba adjust
/// --window-frames`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct WindowsConfig {
    /// Frames per sliding window (W).
    pub window_frames: usize,
    /// New frames per window after the first (S < W); the other W - S frames of each later
    /// window are already final and hold the window in place.
    pub window_stride: usize,
}

impl Default for WindowsConfig {
    fn default() -> Self {
        Self {
            window_frames: 100,
            window_stride: 80,
        }
    }
}

impl WindowsConfig {
    /// The window length and stride, for `pssba-core`.
    pub fn spec(&self) -> WindowSpec {
        WindowSpec {
            window_frames: self.window_frames,
            window_stride: self.window_stride,
        }
    }
}

/// Every section of the configuration.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Config {
    /// PSS-BA and its ablations (the top-level keys).
    pub algorithm: PssBaConfig,
    /// Sliding windows (`[windows]`).
    pub windows: WindowsConfig,
    /// The whole flight over the windows (`[flight]`).
    pub flight: FlightConfig,
    /// The BALM baseline (`[balm]`, for `--method balm`).
    pub balm: BalmConfig,
    /// The process system (`[system]`).
    pub system: SystemConfig,
    /// How robot recordings are read (`[recording]`).
    pub recording: RecordingConfig,
    /// The files `pssba run` writes beside its recording (`[output]`).
    pub output: OutputConfig,
}

/// Keys that moved from `[system]` to `[windows]`; the old spelling still works, warned.
const MOVED_TO_WINDOWS: [&str; 2] = ["window_frames", "window_stride"];

impl Config {
    /// Reads `path`, or the defaults when `None`.
    pub fn load(path: Option<&Path>) -> Result<Self, ConfigError> {
        let Some(path) = path else {
            return Ok(Self::default());
        };
        let text = std::fs::read_to_string(path).map_err(|cause| ConfigError::Read {
            path: path.to_path_buf(),
            cause,
        })?;
        Self::from_toml(&text, &path.display().to_string())
    }

    /// Parses TOML text; `origin` names the file in errors.
    pub fn from_toml(text: &str, origin: &str) -> Result<Self, ConfigError> {
        let table: toml::Table = toml::from_str(text).map_err(|cause| ConfigError::Parse {
            origin: origin.to_string(),
            table: None,
            cause,
        })?;
        Self::from_table(table, origin)
    }

    /// From a parsed TOML table.
    pub fn from_table(mut table: toml::Table, origin: &str) -> Result<Self, ConfigError> {
        move_deprecated_window_keys(&mut table, origin)?;
        let mut section = |name: &'static str| -> Option<toml::Value> { table.remove(name) };
        let (windows, flight, balm, system, recording, output) = (
            section("windows"),
            section("flight"),
            section("balm"),
            section("system"),
            section("recording"),
            section("output"),
        );
        let config = Self {
            windows: parse_table(windows, "windows", origin)?,
            flight: parse_table(flight, "flight", origin)?,
            balm: parse_table(balm, "balm", origin)?,
            system: parse_table(system, "system", origin)?,
            recording: parse_table(recording, "recording", origin)?,
            output: parse_table(output, "output", origin)?,
            algorithm: toml::Value::Table(table).try_into().map_err(|cause| {
                ConfigError::Parse {
                    origin: origin.to_string(),
                    table: None,
                    cause,
                }
            })?,
        };
        config.validate(origin)?;
        Ok(config)
    }

    /// Checks every section; the error names the file and the key.
    pub fn validate(&self, origin: &str) -> Result<(), ConfigError> {
        let invalid = |message: String| ConfigError::Invalid {
            origin: origin.to_string(),
            message,
        };
        self.algorithm
            .validate()
            .map_err(|e| invalid(e.to_string()))?;
        self.windows
            .spec()
            .validate()
            .map_err(|e| invalid(format!("[windows] {e}")))?;
        self.balm
            .validate()
            .map_err(|e| invalid(format!("[balm] {e}")))?;
        self.flight.validate().map_err(invalid)?;
        self.system.validate().map_err(invalid)?;
        self.recording.validate().map_err(invalid)?;
        self.output.validate().map_err(invalid)?;
        Ok(())
    }

    /// The TOML text of this config, every section spelled out (what the launcher hands to
    /// the stages).
    pub fn to_toml(&self) -> Result<String, ConfigError> {
        let mut table = toml::Table::try_from(&self.algorithm)?;
        table.insert("windows".into(), toml::Value::try_from(self.windows)?);
        table.insert("flight".into(), toml::Value::try_from(self.flight)?);
        table.insert("balm".into(), toml::Value::try_from(&self.balm)?);
        table.insert("system".into(), toml::Value::try_from(&self.system)?);
        table.insert("recording".into(), toml::Value::try_from(&self.recording)?);
        table.insert("output".into(), toml::Value::try_from(&self.output)?);
        Ok(toml::to_string(&table)?)
    }
}

/// One table, its keys over the defaults.
fn parse_table<T: Default + serde::de::DeserializeOwned>(
    value: Option<toml::Value>,
    name: &'static str,
    origin: &str,
) -> Result<T, ConfigError> {
    match value {
        None => Ok(T::default()),
        Some(value) => value.try_into().map_err(|cause| ConfigError::Parse {
            origin: origin.to_string(),
            table: Some(name),
            cause,
        }),
    }
}

/// `[system] window_frames/window_stride` (the old spelling) into `[windows]`, warned; set in
/// both places, an error.
fn move_deprecated_window_keys(table: &mut toml::Table, origin: &str) -> Result<(), ConfigError> {
    let Some(toml::Value::Table(system)) = table.get_mut("system") else {
        return Ok(());
    };
    let moved: Vec<(&str, toml::Value)> = MOVED_TO_WINDOWS
        .iter()
        .filter_map(|key| Some((*key, system.remove(*key)?)))
        .collect();
    if moved.is_empty() {
        return Ok(());
    }
    let windows = table
        .entry("windows")
        .or_insert_with(|| toml::Value::Table(toml::Table::new()));
    let toml::Value::Table(windows) = windows else {
        return Err(ConfigError::Invalid {
            origin: origin.to_string(),
            message: "[windows] must be a table".into(),
        });
    };
    for (key, value) in moved {
        if windows.contains_key(key) {
            return Err(ConfigError::Invalid {
                origin: origin.to_string(),
                message: format!(
                    "{key} is set in [windows] and in [system] (its old place): keep the one \
                     in [windows]"
                ),
            });
        }
        tracing::warn!(
            "{origin}: [system] {key} is deprecated: it moved to the [windows] table (read as \
             [windows] {key} = {value})"
        );
        windows.insert(key.to_string(), value);
    }
    Ok(())
}
