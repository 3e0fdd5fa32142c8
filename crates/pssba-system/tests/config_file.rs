//! The `[system]` table of `config/default.toml` mirrors `SystemConfig::default()` key by key,
//! every key has a comment, unknown keys are refused, and the whole file loads as a run config.

use pssba_system::{RunConfig, SystemConfig};
use std::collections::BTreeSet;

const DEFAULT_FILE: &str = include_str!("../../../config/default.toml");

fn system_table() -> toml::Table {
    let file: toml::Table = toml::from_str(DEFAULT_FILE).expect("default.toml is TOML");
    file["system"]
        .as_table()
        .expect("default.toml has a [system] table")
        .clone()
}

#[test]
fn system_table_equals_the_defaults() {
    let table = system_table();
    let parsed: SystemConfig = toml::Value::Table(table.clone())
        .try_into()
        .expect("[system] parses");
    assert_eq!(parsed, SystemConfig::default());
    parsed.validate().expect("defaults are valid");
    // `#[serde(default)]` would fill in a missing key: compare the key sets as well.
    let serialized: toml::Table =
        toml::from_str(&toml::to_string(&SystemConfig::default()).expect("serializes"))
            .expect("TOML");
    let file_keys: BTreeSet<&String> = table.keys().collect();
    let default_keys: BTreeSet<&String> = serialized.keys().collect();
    assert_eq!(file_keys, default_keys);
    assert_eq!(table, serialized);
}

#[test]
fn every_system_key_has_a_comment() {
    let lines: Vec<&str> = DEFAULT_FILE.lines().collect();
    let start = lines
        .iter()
        .position(|l| *l == "[system]")
        .expect("[system] line");
    for key in system_table().keys() {
        let at = lines[start..]
            .iter()
            .position(|l| l.starts_with(&format!("{key} = ")))
            .map(|i| i + start)
            .unwrap_or_else(|| panic!("no `{key} = ` line under [system]"));
        assert!(
            lines[at - 1].starts_with('#'),
            "`{key}` has no comment above it"
        );
    }
}

#[test]
fn the_whole_file_loads_as_the_default_run_config() {
    let config = RunConfig::from_toml(DEFAULT_FILE, "default.toml").expect("loads");
    assert_eq!(config, RunConfig::default());
}

#[test]
fn unknown_or_bad_system_keys_are_refused_by_name() {
    for (text, name) in [
        ("[system]\nwindow_frame = 3\n", "window_frame"),
        ("[system]\nwindow_stride = 0\n", "window_stride"),
        ("[system]\nwindow_frames = 1\n", "window_frames"),
        ("[system]\nstartup_timeout_s = -1.0\n", "startup_timeout_s"),
        ("[system]\nsample_words = 10\n", "sample_words"),
        (
            "[system]\nlive_max_frame_points = 0\n",
            "live_max_frame_points",
        ),
    ] {
        let err = RunConfig::from_toml(text, "x.toml").expect_err(text);
        let message = format!("{err:#}");
        assert!(message.contains(name), "{text}: {message}");
        assert!(message.contains("x.toml"), "{text}: {message}");
    }
}
