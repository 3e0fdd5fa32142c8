//! `config/default.toml` at the workspace root mirrors `PssBaConfig::default()` field by field,
//! unknown keys are rejected, and `validate()` names the bad field. The file's tables are
//! checked in `pssba-config`; here only the keys before them.

use pssba_core::{CoreError, Method, PssBaConfig};
use std::collections::BTreeSet;

const DEFAULT_FILE: &str = include_str!("../../../config/default.toml");

/// The algorithm's part of the file: everything before the first table.
fn default_toml() -> &'static str {
    let at = DEFAULT_FILE
        .find("\n[")
        .expect("default.toml has tables after the algorithm's keys");
    &DEFAULT_FILE[..at]
}

fn parse(text: &str) -> Result<PssBaConfig, toml::de::Error> {
    toml::from_str::<PssBaConfig>(text)
}

/// The algorithm part with the value of `key` (whose `key = ` line must appear exactly once)
/// replaced by the TOML text `value`.
fn with_value(key: &str, value: &str) -> String {
    let prefix = format!("{key} = ");
    let hits = default_toml()
        .lines()
        .filter(|l| l.starts_with(&prefix))
        .count();
    assert_eq!(hits, 1, "`{key} = ` must appear once in default.toml");
    default_toml()
        .lines()
        .map(|l| {
            if l.starts_with(&prefix) {
                format!("{prefix}{value}")
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
}

#[test]
fn default_toml_equals_default_config() {
    let config = parse(default_toml()).expect("default.toml parses");
    assert_eq!(config, PssBaConfig::default());
    assert_eq!(config.method, Method::PssBa);
    config.validate().expect("defaults are valid");
}

#[test]
fn default_toml_spells_out_every_field_with_a_comment() {
    // `#[serde(default)]` would silently fill in a key missing from the file, so equality
    // alone does not prove the file is complete: compare the key sets as well.
    let file: toml::Table = toml::from_str(default_toml()).expect("default.toml is TOML");
    let serialized = toml::to_string(&PssBaConfig::default()).expect("config serializes");
    let defaults: toml::Table = toml::from_str(&serialized).expect("serialized config is TOML");
    let file_keys: BTreeSet<&String> = file.keys().collect();
    let default_keys: BTreeSet<&String> = defaults.keys().collect();
    assert_eq!(file_keys, default_keys);
    assert_eq!(file, defaults, "values differ from PssBaConfig::default()");
    assert_eq!(file["method"].as_str(), Some("pss-ba"));

    // Each key line directly follows a comment (its unit and meaning).
    let lines: Vec<&str> = default_toml().lines().collect();
    for key in file.keys() {
        let at = lines
            .iter()
            .position(|l| l.starts_with(&format!("{key} = ")))
            .unwrap_or_else(|| panic!("no `{key} = ` line"));
        assert!(
            at > 0 && lines[at - 1].starts_with('#'),
            "`{key}` has no comment above it"
        );
    }
}

#[test]
fn unknown_key_is_rejected() {
    let text = format!("{}\nnormal_neighbors = 12\n", default_toml());
    let err = parse(&text).expect_err("unknown key must be rejected");
    let message = err.to_string();
    assert!(message.contains("normal_neighbors"), "{message}");
    assert!(message.contains("unknown field"), "{message}");

    // A typo in a key of an otherwise empty file is caught as well.
    assert!(parse("gamma_0_m = 3.0").is_err());
}

#[test]
fn unknown_method_is_rejected() {
    let text = with_value("method", r#""pssba""#);
    let err = parse(&text).expect_err("unknown method must be rejected");
    assert!(err.to_string().contains("pssba"), "{err}");
    for (name, method) in [
        ("pss-ba", Method::PssBa),
        ("pss-ba-fs", Method::PssBaFs),
        ("point2plane", Method::Point2plane),
    ] {
        let text = with_value("method", &format!("\"{name}\""));
        assert_eq!(parse(&text).expect("known method").method, method);
        assert_eq!(method.name(), name);
    }
}

#[test]
fn missing_keys_take_their_default() {
    let config = parse("gamma0_m = 2.0\nmethod = \"point2plane\"\n").expect("partial file");
    assert_eq!(
        config,
        PssBaConfig {
            gamma0_m: 2.0,
            method: Method::Point2plane,
            ..PssBaConfig::default()
        }
    );
}

/// Parses `text`, which must be well-formed, and returns the `validate()` error.
fn validation_error(text: &str) -> CoreError {
    parse(text)
        .expect("well-formed TOML")
        .validate()
        .expect_err("validate must reject it")
}

#[test]
fn validate_rejects_out_of_range_values_naming_the_field() {
    for (field, value) in [
        ("gamma_shrink", "1.0"),
        ("gamma_shrink", "0.5"),
        ("gamma0_m", "-1.0"),
        ("gamma0_m", "nan"),
        ("gamma_min_m", "0.0"),
        ("l0_mu", "inf"),
        ("fit_min_points", "5"),
        ("max_scales", "0"),
    ] {
        let new = format!("{field} = {value}");
        let err = validation_error(&with_value(field, value));
        match &err {
            CoreError::InvalidConfig { field: got, .. } => assert_eq!(*got, field, "{new}"),
            other => panic!("{new}: expected InvalidConfig, got {other:?}"),
        }
        assert!(err.to_string().contains(field), "{err}");
    }
}

#[test]
fn serialized_default_round_trips() {
    let text = toml::to_string(&PssBaConfig::default()).expect("serialize");
    assert_eq!(parse(&text).expect("parse"), PssBaConfig::default());
}
