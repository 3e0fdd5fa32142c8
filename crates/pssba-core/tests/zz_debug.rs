use pssba_core::cloud::ScaleCloud;
use pssba_core::fit::SurfaceModel;
use pssba_core::geometry::Pose;
use pssba_core::lm::solve_block;
use pssba_core::smoothing::extract_block;
use pssba_core::{Parallelism, PssBaConfig};
use pssba_sim::{SceneSpec, curved_window, perturb_poses};

#[test]
fn debug() {
    let window = curved_window(&SceneSpec {
        frames: 5,
        points_per_frame: 2000,
        seed: 21,
        ..SceneSpec::default()
    });
    let initial = perturb_poses(&window.ground_truth, 0.1, 0.5, 121);
    let frames: Vec<Vec<nalgebra::Vector3<f64>>> = window
        .frames
        .iter()
        .map(|f| f.iter().map(|p| p.coords).collect())
        .collect();
    let poses: Vec<Pose> = initial.iter().map(Pose::from_isometry).collect();
    let config = PssBaConfig::default();
    let fixed: Vec<bool> = (0..5).map(|k| k == 0).collect();
    let cloud = ScaleCloud::build(
        &frames,
        &poses,
        config.downsample_m(3.0),
        config.normal_neighbours,
        Parallelism::Serial,
    );
    let block = extract_block(
        &cloud,
        &poses,
        3.0,
        SurfaceModel::Quadratic,
        &config,
        Parallelism::Serial,
    );
    let (ps, _) = solve_block(&block, &poses, &fixed, 8, 1e-4, Parallelism::Serial);
    let (pr, _) = solve_block(&block, &poses, &fixed, 8, 1e-4, Parallelism::Rayon);
    for (a, b) in ps.iter().zip(&pr) {
        eprintln!(
            "dt {:e} dR {:e}",
            (a.translation - b.translation).norm(),
            (a.rotation - b.rotation).norm()
        );
    }
    let g = 3.0 / 1.4;
    let cs = ScaleCloud::build(
        &frames,
        &ps,
        config.downsample_m(g),
        config.normal_neighbours,
        Parallelism::Serial,
    );
    let cr = ScaleCloud::build(
        &frames,
        &pr,
        config.downsample_m(g),
        config.normal_neighbours,
        Parallelism::Serial,
    );
    let nd = cs
        .normals
        .iter()
        .zip(&cr.normals)
        .filter(|(a, b)| match (a, b) {
            (Some(a), Some(b)) => (*a - *b).norm() > 1e-9,
            (None, None) => false,
            _ => true,
        })
        .count();
    eprintln!("normals differing {nd}");
    for (i, (a, b)) in cs.normals.iter().zip(&cr.normals).enumerate() {
        let d = match (a, b) {
            (Some(a), Some(b)) => (*a - *b).norm(),
            (None, None) => 0.0,
            _ => f64::INFINITY,
        };
        if d > 1e-9 {
            eprintln!("point {i}: {a:?} vs {b:?}");
        }
    }
    let ks = cs.sample_kernels(g);
    let kr = cr.sample_kernels(g);
    eprintln!("kernels equal {}", ks == kr);
    let bs = extract_block(
        &cs,
        &ps,
        g,
        SurfaceModel::Quadratic,
        &config,
        Parallelism::Serial,
    );
    let br = extract_block(
        &cr,
        &pr,
        g,
        SurfaceModel::Quadratic,
        &config,
        Parallelism::Serial,
    );
    eprintln!(
        "points {} vs {}, surfaces {} vs {}",
        bs.points.len(),
        br.points.len(),
        bs.surfaces.len(),
        br.surfaces.len()
    );
    let mut i = 0;
    let mut j = 0;
    for (k, (a, b)) in bs.surfaces.iter().zip(&br.surfaces).enumerate() {
        let na = bs.points.iter().filter(|p| p.surface as usize == k).count();
        let nb = br.points.iter().filter(|p| p.surface as usize == k).count();
        if na != nb || (a.polynomial.coefficients[5] - b.polynomial.coefficients[5]).abs() > 1e-6 {
            eprintln!(
                "surface {k}: {na} vs {nb} pts, coef {:?} vs {:?}",
                a.polynomial.coefficients, b.polynomial.coefficients
            );
        }
        i += na;
        j += nb;
    }
    let _ = (i, j);
}
