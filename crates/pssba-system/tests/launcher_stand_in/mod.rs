//! Stand-in stages for launcher tests: a shell script run as `SCRIPT stage NAME --prefix ...`
//! that sleeps, exits or SIGKILLs itself on its scenario's schedule, counting each stage's
//! starts in a file beside it.

use pssba_system::launcher::{LaunchOptions, launch};
use pssba_system::source::{InputSpec, OpenOptions, SourceSpec};
use pssba_system::{Config, SystemConfig};
use std::os::unix::fs::PermissionsExt;
use std::path::PathBuf;
use std::time::Duration;

/// `@SCENARIO@` is replaced by the scenario's name.
const SCRIPT: &str = r#"#!/bin/sh
# $1 = "stage", $2 = the stage's name.
dir=$(dirname "$0")
echo start >> "$dir/$2.starts"
starts=$(wc -l < "$dir/$2.starts")
case "@SCENARIO@:$2" in
  *:record|*:ingest) sleep 4; exit 0 ;;
  adjust_dies_early:smooth) sleep 3; exit 0 ;;
  adjust_dies_early:adjust)
    if [ "$starts" -eq 1 ]; then sleep 0.3; kill -9 $$; fi
    exec sleep 1000 ;;
  adjust_dies_late:smooth) sleep 0.3; exit 0 ;;
  adjust_dies_late:adjust)
    if [ "$starts" -eq 1 ]; then sleep 2; kill -9 $$; fi
    exec sleep 1000 ;;
esac
exit 3
"#;

/// A run of the launcher on stand-in stages, in its own temporary folder.
pub struct Run {
    dir: tempfile::TempDir,
}

impl Run {
    pub fn new(scenario: &str) -> Self {
        let dir = tempfile::tempdir().expect("tempdir");
        let script = dir.path().join("stand-in.sh");
        std::fs::write(&script, SCRIPT.replace("@SCENARIO@", scenario)).expect("script");
        std::fs::set_permissions(&script, std::fs::Permissions::from_mode(0o755)).expect("chmod");
        Self { dir }
    }

    /// `launch` with a watchdog of `timeout`.
    pub fn launch(&self, timeout: Duration) -> pssba_system::Result<PathBuf> {
        let config = Config {
            system: SystemConfig {
                restart_backoff_s: 0.1,
                ..SystemConfig::default()
            },
            ..Config::default()
        };
        launch(&LaunchOptions {
            exe: self.dir.path().join("stand-in.sh"),
            config,
            source: SourceSpec::Input(InputSpec::Path {
                path: self.dir.path().join("no-such-dataset"),
                options: OpenOptions::default(),
            }),
            out: self.dir.path().join("run.mcap"),
            rate_hz: None,
            verbose: 0,
            timeout: Some(timeout),
        })
    }

    /// How many times the adjust stage was started.
    pub fn adjust_starts(&self) -> usize {
        std::fs::read_to_string(self.dir.path().join("adjust.starts"))
            .map_or(0, |s| s.lines().count())
    }
}
