//! The tables of `config/default.toml` mirror their sections' `Default` key by key, every key
//! has a comment, unknown keys are refused, and the whole file loads as the default config.

use pssba_config::{
    Config, FlightConfig, OutputConfig, RecordingConfig, SystemConfig, WindowsConfig,
};
use std::collections::BTreeSet;

const DEFAULT_FILE: &str = include_str!("../../../config/default.toml");

fn table(name: &str) -> toml::Table {
    let file: toml::Table = toml::from_str(DEFAULT_FILE).expect("default.toml is TOML");
    file[name]
        .as_table()
        .unwrap_or_else(|| panic!("default.toml has a [{name}] table"))
        .clone()
}

fn system_table() -> toml::Table {
    table("system")
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
    let config = Config::from_toml(DEFAULT_FILE, "default.toml").expect("loads");
    assert_eq!(config, Config::default());
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
        let err = Config::from_toml(text, "x.toml").expect_err(text);
        let message = format!("{err:#}");
        assert!(message.contains(name), "{text}: {message}");
        assert!(message.contains("x.toml"), "{text}: {message}");
    }
}

#[test]
fn windows_table_equals_the_defaults() {
    let table = table("windows");
    let parsed: WindowsConfig = toml::Value::Table(table.clone())
        .try_into()
        .expect("[windows] parses");
    assert_eq!(parsed, WindowsConfig::default());
    let defaults: toml::Table = toml::Table::try_from(WindowsConfig::default()).expect("table");
    assert_eq!(table, defaults);
}

#[test]
fn the_recording_table_equals_the_defaults_key_by_key() {
    let table = table("recording");
    let parsed: RecordingConfig = toml::Value::Table(table.clone())
        .try_into()
        .expect("parses");
    assert_eq!(parsed, RecordingConfig::default());
    let defaults: toml::Table = toml::Table::try_from(RecordingConfig::default()).expect("table");
    assert_eq!(table, defaults);
}

#[test]
fn the_output_table_equals_the_defaults_key_by_key() {
    let table = table("output");
    let parsed: OutputConfig = toml::Value::Table(table.clone())
        .try_into()
        .expect("parses");
    assert_eq!(parsed, OutputConfig::default());
    let defaults: toml::Table = toml::Table::try_from(OutputConfig::default()).expect("table");
    assert_eq!(table, defaults);
}

#[test]
fn the_flight_table_equals_the_defaults_key_by_key() {
    let table = table("flight");
    let parsed: FlightConfig = toml::Value::Table(table.clone())
        .try_into()
        .expect("parses");
    assert_eq!(parsed, FlightConfig::default());
    assert_eq!(parsed.settings(), pssba_core::FlightSettings::default());
    let defaults: toml::Table = toml::Table::try_from(FlightConfig::default()).expect("table");
    assert_eq!(table, defaults);
}

#[test]
fn a_bad_flight_key_is_named() {
    let dir = tempfile::tempdir().expect("tmp");
    let path = dir.path().join("c.toml");
    std::fs::write(&path, "[flight]\nrevisit_min_overlap = 1.5\n").expect("write");
    let error = Config::load(Some(&path)).expect_err("refused").to_string();
    assert!(error.contains("revisit_min_overlap"), "{error}");
    std::fs::write(&path, "[flight]\nmotion_prior_rotation_rad = -1\n").expect("write");
    let error = Config::load(Some(&path)).expect_err("refused").to_string();
    assert!(error.contains("motion_prior_rotation_rad = -1"), "{error}");
}

#[test]
fn a_map_voxel_that_is_not_positive_is_named() {
    let dir = tempfile::tempdir().expect("tmp");
    let path = dir.path().join("c.toml");
    std::fs::write(&path, "[output]\nmap_voxel_m = 0.0\n").expect("write");
    let error = Config::load(Some(&path)).expect_err("refused").to_string();
    assert!(error.contains("output.map_voxel_m = 0"), "{error}");
}

#[test]
fn a_bad_recording_key_is_named() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("c.toml");
    std::fs::write(&path, "[recording]\nmax_pose_gap = 1.0\n").expect("write");
    let error = Config::load(Some(&path)).expect_err("unknown key");
    let error = format!("{:#}", anyhow::Error::new(error));
    assert!(
        error.contains("[recording]") && error.contains("max_pose_gap"),
        "{error}"
    );
}

#[test]
fn round_trips_through_toml() {
    let mut config = Config::default();
    config.windows.window_frames = 40;
    config.windows.window_stride = 30;
    config.algorithm.max_scales = 5;
    config.balm.max_lm_iterations += 1;
    config.recording.points_topic = "/livox/lidar".into();
    let text = config.to_toml().expect("serialises");
    assert_eq!(Config::from_toml(&text, "test").expect("parses"), config);
}

#[test]
fn the_old_system_spelling_of_the_window_keys_still_works() {
    let config = Config::from_toml(
        "[system]\nwindow_frames = 40\nwindow_stride = 30\n",
        "old.toml",
    )
    .expect("the old spelling is read");
    assert_eq!(
        config.windows,
        WindowsConfig {
            window_frames: 40,
            window_stride: 30
        }
    );
    let both = Config::from_toml(
        "[windows]\nwindow_frames = 40\n[system]\nwindow_frames = 50\n",
        "both.toml",
    )
    .expect_err("set twice");
    let message = both.to_string();
    assert!(
        message.contains("both.toml") && message.contains("window_frames"),
        "{message}"
    );
}
