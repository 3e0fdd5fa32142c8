//! What a run takes its frames from: an input read by the ingest stage (any source of
//! `pssba-source`, carried to the stage as one `--source` argument), or live frames that
//! outside producers publish (no ingest stage).

use crate::error::{Context, bail};
pub use pssba_source::{InputSpec, OpenOptions, SimSpec};

/// A run's frames, as named on the command line.
#[derive(Debug, Clone, PartialEq)]
pub enum SourceSpec {
    /// A file, a folder or the simulated scene, read by the ingest stage.
    Input(InputSpec),
    /// Live frames from processes outside the system, on the frames service of this instance
    /// (`pssba run --input live --instance NAME`; docs/interface.md). No ingest stage.
    Live(String),
}

impl SourceSpec {
    /// Checks what can be checked before any process starts (the input opens, its headers
    /// read, the sizes make sense); the error names the file or value.
    pub fn check(&self) -> crate::Result<()> {
        match self {
            SourceSpec::Input(input) => input.check()?,
            SourceSpec::Live(instance) => pssba_client::instance::check(instance)?,
        }
        Ok(())
    }

    /// What the source is, for logs and summaries.
    pub fn describe(&self) -> String {
        match self {
            SourceSpec::Input(input) => input.describe(),
            SourceSpec::Live(instance) => format!(
                "live frames from outside producers on pssba/{instance}/frames (iceoryx2 prefix {})",
                pssba_client::instance::prefix(instance)
            ),
        }
    }
}

const INPUT_PREFIX: &str = "input:";
const LIVE_PREFIX: &str = "live:";

/// `input:{JSON of InputSpec}` or `live:INSTANCE`: the `--source` argument of
/// `pssba stage ingest`.
impl std::fmt::Display for SourceSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SourceSpec::Live(instance) => write!(f, "{LIVE_PREFIX}{instance}"),
            SourceSpec::Input(input) => {
                let json = serde_json::to_string(input).map_err(|_| std::fmt::Error)?;
                write!(f, "{INPUT_PREFIX}{json}")
            }
        }
    }
}

impl std::str::FromStr for SourceSpec {
    type Err = crate::Error;

    fn from_str(text: &str) -> crate::Result<Self> {
        if let Some(instance) = text.strip_prefix(LIVE_PREFIX) {
            return Ok(SourceSpec::Live(instance.to_string()));
        }
        if let Some(json) = text.strip_prefix(INPUT_PREFIX) {
            let input = serde_json::from_str(json)
                .with_context(|| format!("source '{text}': expected input:{{JSON}}"))?;
            return Ok(SourceSpec::Input(input));
        }
        bail!(
            Usage,
            "source '{text}': expected input:{{JSON}} or live:INSTANCE"
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Isometry3;
    use std::path::PathBuf;

    #[test]
    fn the_source_argument_round_trips() {
        for spec in [
            SourceSpec::Input(InputSpec::Path {
                path: PathBuf::from("/data/flight 1"),
                options: OpenOptions::default(),
            }),
            SourceSpec::Input(InputSpec::Simulated(SimSpec {
                frames: 200,
                points_per_frame: 8000,
                seed: 1,
            })),
            SourceSpec::Input(InputSpec::Path {
                path: PathBuf::from("/data/flight.bag"),
                options: OpenOptions {
                    recording: pssba_bag::RecordingOptions {
                        points_topic: Some("/livox/lidar".into()),
                        extrinsic: Some(Isometry3::translation(0.1, 0.0, -0.2)),
                        frames: Some(3..40),
                        ..Default::default()
                    },
                    poses: Some(PathBuf::from("/data/odometry.txt")),
                },
            }),
            SourceSpec::Live("drone1".into()),
        ] {
            let parsed: SourceSpec = spec.to_string().parse().expect("parses");
            assert_eq!(parsed, spec);
        }
        for bad in ["", "sim:1,2", "input:{", "folder"] {
            assert!(bad.parse::<SourceSpec>().is_err(), "{bad}");
        }
    }
}
