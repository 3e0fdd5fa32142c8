//! Why a configuration was refused: each error names the file, and the table and key where
//! one is at fault.

use std::path::PathBuf;

/// Every error this crate returns.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("reading config {}: {cause}", .path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The cause (in the message only).
        cause: std::io::Error,
    },

    /// Not TOML, an unknown key, or a value of the wrong type.
    #[error(
        "config {origin}{}: {cause}",
        .table.map_or(String::new(), |t| format!(": [{t}]"))
    )]
    Parse {
        /// The file.
        origin: String,
        /// The table at fault, if not the top level.
        table: Option<&'static str>,
        /// What the TOML reader said, naming the key (in the message only: an error chain
        /// printed whole says it once).
        cause: toml::de::Error,
    },

    /// A value out of range.
    #[error("config {origin}: {message}")]
    Invalid {
        /// The file.
        origin: String,
        /// The key and what is wrong with its value.
        message: String,
    },

    /// The config could not be written as TOML.
    #[error("serialising the config")]
    Serialize(#[from] toml::ser::Error),
}
