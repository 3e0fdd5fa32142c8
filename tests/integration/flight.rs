//! The whole flight through the process system (issue 38): a flight that leaves a place over
//! open ground and comes back, replayed by `pssba run`, closes its loop in the smooth stage;
//! the final trajectory beside the recording (from the last `/pssba/poses/optimized`, which
//! carries the poses the closure moved) equals `pssba adjust` on the same folder, and both
//! visits of the place agree.

use crate::system::{pssba_watched, s, stderr};
use nalgebra::Isometry3;
use pssba_io::{Dataset, PcdEncoding, StampedPose};
use pssba_sim::{
    Mid360, OdometryDrift, SimulationSpec, drift_poses, revisit_frames, revisit_scene,
    simulate_scene,
};
use std::path::Path;
use std::time::Duration;

/// A CI-sized revisit flight (60 m out, 3 m/s, 4000 rays of 40 m, twice the default drift)
/// as a dataset folder; returns the true poses.
fn revisit_dataset(dir: &Path) -> Vec<Isometry3<f64>> {
    let mut scene = revisit_scene(60.0);
    scene.trajectory.speed_m_s = 3.0;
    let sensor = Mid360 {
        rays_per_frame: 4000,
        max_range_m: 40.0,
        ..Mid360::default()
    };
    let spec = SimulationSpec {
        frames: revisit_frames(&scene, sensor.frame_rate_hz),
        seed: 5,
        sensor,
        ..SimulationSpec::default()
    };
    let data = simulate_scene(&scene, &spec).expect("simulation");
    let d = OdometryDrift::default();
    let drift = OdometryDrift {
        translation_m: 2.0 * d.translation_m,
        yaw_deg: 2.0 * d.yaw_deg,
        tilt_deg: 2.0 * d.tilt_deg,
    };
    let stamped = |poses: &[Isometry3<f64>]| -> Vec<StampedPose> {
        poses
            .iter()
            .zip(&data.stamps)
            .map(|(p, &stamp)| StampedPose {
                stamp,
                world_from_lidar: *p,
            })
            .collect()
    };
    let initial = drift_poses(&data.ground_truth, drift, 11);
    Dataset::write(
        dir,
        &data.frames,
        &stamped(&initial),
        Some(&stamped(&data.ground_truth)),
        PcdEncoding::Binary,
    )
    .expect("dataset");
    data.ground_truth
}

fn read_poses(path: &Path) -> Vec<Isometry3<f64>> {
    pssba_io::read_tum(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .iter()
        .map(|p| p.world_from_lidar)
        .collect()
}

fn ape_m(truth: &[Isometry3<f64>], estimate: &[Isometry3<f64>], frames: &[usize]) -> f64 {
    let pick = |poses: &[Isometry3<f64>]| frames.iter().map(|&k| poses[k]).collect::<Vec<_>>();
    pssba_eval::ape_translation_paired(&pick(truth), &pick(estimate))
        .expect("ape")
        .rmse_m
}

#[test]
fn a_revisit_flight_through_the_processes_closes_its_loop_as_pssba_adjust_does() {
    let tmp = tempfile::tempdir().expect("tmp");
    let dir = tmp.path().join("revisit");
    let truth = revisit_dataset(&dir);
    let mcap = tmp.path().join("run.mcap");
    let out = pssba_watched(
        &["-q", "run", "--dataset", s(&dir), "--out", s(&mcap)],
        Duration::from_secs(600),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let run = read_poses(&tmp.path().join("run.tum"));
    assert_eq!(run.len(), truth.len());
    let adjusted_path = tmp.path().join("adjusted.txt");
    let out = pssba_watched(
        &["-q", "adjust", s(&dir), "--out", s(&adjusted_path)],
        Duration::from_secs(600),
    );
    assert!(out.status.success(), "{}", stderr(&out));
    let adjusted = read_poses(&adjusted_path);
    let difference = run
        .iter()
        .zip(&adjusted)
        .map(|(a, b)| (a.to_homogeneous() - b.to_homogeneous()).abs().max())
        .fold(0.0, f64::max);
    assert!(
        difference < 5e-9,
        "pssba run vs pssba adjust: {difference:e}"
    );
    // The two visits of the place (within 14 m of it) agree.
    let near: Vec<bool> = truth
        .iter()
        .map(|p| p.translation.vector.xy().norm() < 14.0)
        .collect();
    let first_far = near.iter().position(|&n| !n).expect("the flight leaves");
    let first: Vec<usize> = (0..first_far).collect();
    let second: Vec<usize> = (first_far..truth.len()).filter(|&k| near[k]).collect();
    let both: Vec<usize> = first.iter().chain(&second).copied().collect();
    let each_m = ape_m(&truth, &run, &first).max(ape_m(&truth, &run, &second));
    let both_m = ape_m(&truth, &run, &both);
    assert!(
        both_m < 2.0 * each_m,
        "both visits {both_m} m, each {each_m} m"
    );
    let initial: Vec<Isometry3<f64>> = Dataset::open(&dir)
        .expect("dataset")
        .initial
        .iter()
        .map(|p| p.world_from_lidar)
        .collect();
    assert!(ape_m(&truth, &initial, &both) > 5.0 * both_m);
}
