//! `BalmConfig`: defaults are valid and match the paper's values, TOML round trip, unknown
//! keys rejected, `validate()` names the bad field.

use pssba_balm::{BalmConfig, BalmError};

#[test]
fn defaults_are_the_papers_and_valid() {
    let config = BalmConfig::default();
    config.validate().expect("valid");
    assert_eq!(config.voxel_size_m, 2.0);
    assert_eq!(config.plane_eigen_ratio, 1.0 / 16.0);
    assert_eq!(config.plane_eigen_ratio_deepest, 1.0 / 9.0);
    assert_eq!(config.min_points_per_voxel, 15);
    assert_eq!(config.min_frames_per_voxel, 2);
    assert_eq!(config.octree_layers, 3);
}

#[test]
fn toml_round_trip_and_partial_tables() {
    let text = toml::to_string(&BalmConfig::default()).expect("serialize");
    assert_eq!(
        toml::from_str::<BalmConfig>(&text).expect("parse"),
        BalmConfig::default()
    );
    let partial: BalmConfig = toml::from_str("voxel_size_m = 1.0").expect("partial");
    assert_eq!(
        partial,
        BalmConfig {
            voxel_size_m: 1.0,
            ..BalmConfig::default()
        }
    );
    assert!(toml::from_str::<BalmConfig>("voxel_size = 1.0").is_err());
}

#[test]
fn validate_names_the_bad_field() {
    let d = BalmConfig::default;
    for (config, field) in [
        (
            BalmConfig {
                voxel_size_m: 0.0,
                ..d()
            },
            "voxel_size_m",
        ),
        (
            BalmConfig {
                voxel_size_m: f64::NAN,
                ..d()
            },
            "voxel_size_m",
        ),
        (
            BalmConfig {
                octree_layers: 0,
                ..d()
            },
            "octree_layers",
        ),
        (
            BalmConfig {
                plane_eigen_ratio: 1.5,
                ..d()
            },
            "plane_eigen_ratio",
        ),
        (
            BalmConfig {
                plane_eigen_ratio_deepest: -0.1,
                ..d()
            },
            "plane_eigen_ratio_deepest",
        ),
        (
            BalmConfig {
                min_points_per_voxel: 2,
                ..d()
            },
            "min_points_per_voxel",
        ),
        (
            BalmConfig {
                min_frames_per_voxel: 1,
                ..d()
            },
            "min_frames_per_voxel",
        ),
        (
            BalmConfig {
                max_outer_iterations: 0,
                ..d()
            },
            "max_outer_iterations",
        ),
        (
            BalmConfig {
                max_lm_iterations: 0,
                ..d()
            },
            "max_lm_iterations",
        ),
        (
            BalmConfig {
                lm_initial_lambda: 0.0,
                ..d()
            },
            "lm_initial_lambda",
        ),
        (
            BalmConfig {
                outer_pose_change_threshold: f64::INFINITY,
                ..d()
            },
            "outer_pose_change_threshold",
        ),
    ] {
        match config.validate() {
            Err(BalmError::InvalidConfig { field: got, .. }) => assert_eq!(got, field),
            other => panic!("{field}: expected InvalidConfig, got {other:?}"),
        }
    }
}

#[test]
fn config_balm_toml_equals_the_defaults() {
    const FILE: &str = include_str!("../../../config/balm.toml");
    let mut table: toml::Table = toml::from_str(FILE).expect("balm.toml is TOML");
    let balm: BalmConfig = table
        .remove("balm")
        .expect("a [balm] table")
        .try_into()
        .expect("valid [balm] table");
    assert!(table.is_empty(), "only the [balm] table");
    assert_eq!(balm, BalmConfig::default());
    // Every key is spelled out (serde's `default` would hide a missing one).
    let defaults: toml::Table =
        toml::from_str(&toml::to_string(&BalmConfig::default()).expect("ser")).expect("toml");
    let file: toml::Table = toml::from_str(FILE).expect("toml");
    assert_eq!(file["balm"].as_table().expect("table"), &defaults);
}
