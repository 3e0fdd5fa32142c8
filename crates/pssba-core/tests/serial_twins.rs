//! Every kernel that runs on rayon has a serial twin (`Parallelism::Serial`), and the two
//! agree: exactly where each item is computed on its own and collected in order, within
//! 1e-9 relative where a parallel reduction sums in a different order.
//!
//! The rayon side runs in a 4-thread pool so work is really split even on a 2-core machine.

use nalgebra::{Point3, Vector3};
use pssba_core::cloud::ScaleCloud;
use pssba_core::fit::SurfaceModel;
use pssba_core::geometry::Pose;
use pssba_core::lm::{solve_block, variable_layout};
use pssba_core::normal_equations::{accumulate, block_cost};
use pssba_core::smoothed::smoothed_cloud;
use pssba_core::smoothing::extract_block;
use pssba_core::{FactorBlock, Parallelism, PssBaConfig, Window, adjust_window};
use pssba_sim::{SceneSpec, curved_window, perturb_poses};

/// Runs `f` in a dedicated 4-thread rayon pool.
fn in_pool<T: Send>(f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(4)
        .build()
        .expect("rayon pool")
        .install(f)
}

/// A small curved window (5 frames x 2000 points) with perturbed poses.
struct Fixture {
    points: Vec<Vec<Point3<f64>>>,
    frames: Vec<Vec<Vector3<f64>>>,
    initial: Vec<nalgebra::Isometry3<f64>>,
    poses: Vec<Pose>,
    fixed: Vec<bool>,
    config: PssBaConfig,
}

fn fixture() -> Fixture {
    let window = curved_window(&SceneSpec {
        frames: 5,
        points_per_frame: 2000,
        seed: 21,
        ..SceneSpec::default()
    });
    let initial = perturb_poses(&window.ground_truth, 0.1, 0.5, 121);
    let frames = window
        .frames
        .iter()
        .map(|f| f.iter().map(|p| p.coords).collect())
        .collect();
    Fixture {
        points: window.frames,
        frames,
        poses: initial.iter().map(Pose::from_isometry).collect(),
        initial,
        fixed: (0..5).map(|k| k == 0).collect(),
        config: PssBaConfig::default(),
    }
}

/// Kernel widths at which the scale-level kernels are compared: the first scale and a
/// finer one with many more kernels and residuals.
const GAMMAS_M: [f64; 2] = [3.0, 0.8];

fn cloud(f: &Fixture, gamma_m: f64, parallelism: Parallelism) -> ScaleCloud {
    ScaleCloud::build(
        &f.frames,
        &f.poses,
        f.config.downsample_m(gamma_m),
        f.config.normal_neighbours,
        parallelism,
    )
}

fn block(f: &Fixture, cloud: &ScaleCloud, gamma_m: f64, parallelism: Parallelism) -> FactorBlock {
    extract_block(
        cloud,
        &f.poses,
        gamma_m,
        SurfaceModel::Quadratic,
        &f.config,
        parallelism,
    )
}

/// `|a - b| <= 1e-9 max(|a|, |b|)`, with an absolute floor of 1e-9 times `scale` for entries
/// that cancel to about zero.
fn assert_close(a: f64, b: f64, scale: f64, what: &str) {
    let tolerance = 1e-9 * a.abs().max(b.abs()).max(scale);
    assert!(
        (a - b).abs() <= tolerance,
        "{what}: serial {a:e} vs rayon {b:e}"
    );
}

fn assert_poses_close(serial: &[Pose], rayon: &[Pose], what: &str) {
    assert_eq!(serial.len(), rayon.len());
    for (k, (s, r)) in serial.iter().zip(rayon).enumerate() {
        let dt = (s.translation - r.translation).norm();
        let dr = (s.rotation - r.rotation).norm();
        assert!(
            dt <= 1e-9 && dr <= 1e-9,
            "{what}: frame {k}: dt {dt:e}, dR {dr:e}"
        );
    }
}

#[test]
fn scale_cloud_build() {
    let f = fixture();
    for gamma_m in GAMMAS_M {
        let serial = cloud(&f, gamma_m, Parallelism::Serial);
        let rayon = in_pool(|| cloud(&f, gamma_m, Parallelism::Rayon));
        assert!(serial.len() > 5000, "{}", serial.len());
        assert_eq!(serial.points_world, rayon.points_world);
        assert_eq!(serial.points_lidar, rayon.points_lidar);
        assert_eq!(serial.frame_of, rayon.frame_of);
        assert_eq!(serial.normals, rayon.normals);
        let with_normal = serial.normals.iter().filter(|n| n.is_some()).count();
        assert!(
            with_normal > serial.len() / 2,
            "{with_normal} of {}",
            serial.len()
        );
        assert_eq!(
            serial.sample_kernels(gamma_m),
            rayon.sample_kernels(gamma_m)
        );
    }
}

#[test]
fn extract_block_is_identical() {
    let f = fixture();
    for gamma_m in GAMMAS_M {
        let cloud = cloud(&f, gamma_m, Parallelism::Serial);
        let serial = block(&f, &cloud, gamma_m, Parallelism::Serial);
        let rayon = in_pool(|| block(&f, &cloud, gamma_m, Parallelism::Rayon));
        assert!(
            serial.surfaces.len() > 50 && serial.points.len() > 500,
            "gamma {gamma_m}: {} surfaces, {} points",
            serial.surfaces.len(),
            serial.points.len()
        );
        assert_eq!(serial, rayon);
    }
}

#[test]
fn normal_equations_accumulate() {
    let f = fixture();
    let (variable_of, dim) = variable_layout(&f.fixed);
    assert_eq!(dim, 24);
    for gamma_m in GAMMAS_M {
        let cloud = cloud(&f, gamma_m, Parallelism::Serial);
        let block = block(&f, &cloud, gamma_m, Parallelism::Serial);
        let serial = accumulate(&block, &f.poses, &variable_of, dim, Parallelism::Serial);
        let rayon = in_pool(|| accumulate(&block, &f.poses, &variable_of, dim, Parallelism::Rayon));
        assert_eq!(serial.dim, rayon.dim);
        assert_eq!(serial.residuals, rayon.residuals);
        assert_eq!(serial.residuals, block.points.len());
        assert!(serial.cost > 0.0);
        assert_close(serial.cost, rayon.cost, 0.0, "cost");
        let h_scale = serial.hessian.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let g_scale = serial.gradient.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(h_scale > 0.0 && g_scale > 0.0);
        for (k, (s, r)) in serial.hessian.iter().zip(&rayon.hessian).enumerate() {
            assert_close(*s, *r, h_scale, &format!("H[{}][{}]", k / dim, k % dim));
        }
        for (k, (s, r)) in serial.gradient.iter().zip(&rayon.gradient).enumerate() {
            assert_close(*s, *r, g_scale, &format!("b[{k}]"));
        }
        // Both are mirrored to full symmetric matrices.
        for r in 0..dim {
            for c in 0..r {
                assert_eq!(serial.hessian[r * dim + c], serial.hessian[c * dim + r]);
                assert_eq!(rayon.hessian[r * dim + c], rayon.hessian[c * dim + r]);
            }
        }
    }
}

#[test]
fn block_cost_agrees() {
    let f = fixture();
    for gamma_m in GAMMAS_M {
        let cloud = cloud(&f, gamma_m, Parallelism::Serial);
        let block = block(&f, &cloud, gamma_m, Parallelism::Serial);
        let serial = block_cost(&block, &f.poses, Parallelism::Serial);
        let rayon = in_pool(|| block_cost(&block, &f.poses, Parallelism::Rayon));
        assert!(serial > 0.0);
        assert_close(serial, rayon, 0.0, "block cost");
        // The derivative-free cost and the one of the normal equations are the same sum.
        let (variable_of, dim) = variable_layout(&f.fixed);
        let eq = accumulate(&block, &f.poses, &variable_of, dim, Parallelism::Serial);
        assert_close(serial, eq.cost, 0.0, "block cost vs normal-equation cost");
    }
}

#[test]
fn lm_solve_block() {
    let f = fixture();
    let cloud = cloud(&f, GAMMAS_M[0], Parallelism::Serial);
    let block = block(&f, &cloud, GAMMAS_M[0], Parallelism::Serial);
    let run = |parallelism| {
        solve_block(
            &block,
            &f.poses,
            &f.fixed,
            f.config.lm_max_iterations,
            f.config.lm_initial_lambda,
            parallelism,
        )
    };
    let (serial, serial_report) = run(Parallelism::Serial);
    let (rayon, rayon_report) = in_pool(|| run(Parallelism::Rayon));
    assert!(serial_report.cost_after < serial_report.cost_before);
    assert_eq!(serial_report.iterations, rayon_report.iterations);
    assert_eq!(serial_report.residuals, rayon_report.residuals);
    assert_close(
        serial_report.cost_after,
        rayon_report.cost_after,
        0.0,
        "cost after",
    );
    assert_poses_close(&serial, &rayon, "solve_block");
    assert_eq!(serial[0], f.poses[0], "the fixed frame stays");
}

#[test]
fn smoothed_cloud_is_identical() {
    let f = fixture();
    for gamma_m in GAMMAS_M {
        let cloud = cloud(&f, gamma_m, Parallelism::Serial);
        let block = block(&f, &cloud, gamma_m, Parallelism::Serial);
        let serial = smoothed_cloud(&cloud, &block, &f.poses, Parallelism::Serial);
        let rayon = in_pool(|| smoothed_cloud(&cloud, &block, &f.poses, Parallelism::Rayon));
        assert!(
            serial.len() > cloud.len() / 4,
            "{} of {}",
            serial.len(),
            cloud.len()
        );
        assert_eq!(serial, rayon);
    }
}

#[test]
fn adjust_window_agrees() {
    let f = fixture();
    let run = |parallelism| {
        adjust_window(
            Window {
                frames: &f.points,
                world_from_lidar: &f.initial,
                fixed: None,
            },
            &f.config,
            parallelism,
        )
        .expect("adjust")
    };
    let serial = run(Parallelism::Serial);
    let rayon = in_pool(|| run(Parallelism::Rayon));
    assert!(serial.scales.len() > 1);
    assert_eq!(serial.scales.len(), rayon.scales.len());
    assert_eq!(serial.converged, rayon.converged);
    for (s, r) in serial.scales.iter().zip(&rayon.scales) {
        eprintln!("S {s:?}\nR {r:?}");
    }
    for (s, r) in serial.scales.iter().zip(&rayon.scales) {
        assert_eq!(s.gamma_m, r.gamma_m);
        assert_eq!(s.kernels_used, r.kernels_used);
        assert_eq!(s.kernels_rejected, r.kernels_rejected);
        assert_eq!(s.residuals, r.residuals);
        assert_eq!(s.iterations, r.iterations);
    }
    let to_poses = |r: &pssba_core::AdjustResult| -> Vec<Pose> {
        r.world_from_lidar.iter().map(Pose::from_isometry).collect()
    };
    assert_poses_close(&to_poses(&serial), &to_poses(&rayon), "adjust_window");
    assert_eq!(serial.surfaces.len(), rayon.surfaces.len());
    assert_eq!(serial.smoothed_cloud.len(), rayon.smoothed_cloud.len());
    for (s, r) in serial.smoothed_cloud.iter().zip(&rayon.smoothed_cloud) {
        assert!((s - r).norm() <= 1e-9, "smoothed point {s} vs {r}");
    }
}
