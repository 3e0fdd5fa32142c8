//! Closing a loop (DESIGN section 9): find old keyframes near the window's new ones, confirm
//! by voxel overlap, align the new keyframes onto the old (held fixed) with the progressive
//! schedule, then solve the pose graph from the newest old keyframe used to the window's last
//! frame and move every final frame in between by its keyframes' corrections.

use super::FlightWindows;
use super::keyframes::{Keyframe, occupied};
use crate::config::{MotionPrior, PssBaConfig};
use crate::geometry::Pose;
use crate::parallel::Parallelism;
use crate::schedule::pipeline::adjust_window;
use crate::schedule::progressive::Window;
use crate::solve::pose_graph::{self, Edge, GraphReport, edge_information, relative};
use nalgebra::{Isometry3, Matrix6, Translation3, UnitQuaternion, Vector3};
use std::collections::BTreeMap;
use std::time::Instant;

/// A loop edge kept for later graph solves: the new keyframe's pose relative to an old one,
/// as the alignment measured it.
#[derive(Debug, Clone)]
pub(super) struct LoopEdge {
    old: usize,
    new: usize,
    measured: Pose,
    information: Matrix6<f64>,
}

/// What one loop closure did.
#[derive(Debug, Clone, PartialEq)]
pub struct LoopClosure {
    /// Window that saw the place again.
    pub window: usize,
    /// Stream indices of the old keyframes held fixed and the new keyframes aligned.
    pub old_keyframes: Vec<usize>,
    pub new_keyframes: Vec<usize>,
    /// Share of the new keyframes' voxels the old ones occupy.
    pub overlap: f64,
    /// Largest and mean translation the alignment's rigid correction gives a new keyframe (m):
    /// the drift.
    pub max_correction_m: f64,
    pub mean_correction_m: f64,
    /// RMS distance (m) between each new keyframe's own alignment and the rigid correction.
    pub spread_m: f64,
    /// Stream indices of the final frames the closure moved, ascending.
    pub moved: Vec<usize>,
    /// The pose graph's solve.
    pub graph: GraphReport,
    /// Wall time of the alignment and of the rest (s).
    pub align_s: f64,
    pub graph_s: f64,
}

/// Pose of a final frame.
fn pose_of(flight: &FlightWindows, sequence: usize) -> Pose {
    Pose::from_isometry(
        &flight
            .windows
            .final_pose(sequence)
            .expect("keyframes are final"),
    )
}

/// Old and new keyframe indices (into the keyframe list) of a revisit: new keyframes from
/// `first_new` on with old ones near them, long ago and before the window (`window_first`).
fn candidates(
    flight: &FlightWindows,
    first_new: usize,
    window_first: usize,
) -> (Vec<usize>, Vec<usize>) {
    let s = &flight.settings;
    let all = flight.keyframes.all();
    let mut old: BTreeMap<usize, f64> = BTreeMap::new();
    let mut new = Vec::new();
    for (n, keyframe) in all.iter().enumerate().skip(first_new) {
        let position = pose_of(flight, keyframe.sequence).translation;
        let mut any = false;
        for o in flight.keyframes.near(&position, s.revisit_radius_m) {
            let candidate = &all[o];
            // A keyframe without its cloud has an older one at its place.
            if candidate.sequence < window_first
                && !candidate.points.is_empty()
                && keyframe.path_m - candidate.path_m >= s.revisit_min_path_m
            {
                let d = (pose_of(flight, candidate.sequence).translation - position).norm();
                let best = old.entry(o).or_insert(d);
                *best = best.min(d);
                any = true;
            }
        }
        if any {
            new.push(n);
        }
    }
    let mut old: Vec<(usize, f64)> = old.into_iter().collect();
    old.sort_by(|a, b| a.1.total_cmp(&b.1));
    old.truncate(s.max_old_keyframes);
    let mut old: Vec<usize> = old.into_iter().map(|(o, _)| o).collect();
    old.sort_unstable();
    // Evenly spread over the window.
    if new.len() > s.max_new_keyframes {
        let step = new.len() as f64 / s.max_new_keyframes as f64;
        new = (0..s.max_new_keyframes)
            .map(|i| new[(i as f64 * step) as usize])
            .collect();
    }
    (old, new)
}

/// Share of the new keyframes' occupied voxels that the old ones occupy too.
fn overlap(flight: &FlightWindows, old: &[&Keyframe], new: &[&Keyframe]) -> f64 {
    let voxel_m = flight.settings.overlap_voxel_m;
    let voxels_old = occupied(old, |k| pose_of(flight, k), voxel_m);
    let voxels_new = occupied(new, |k| pose_of(flight, k), voxel_m);
    let shared = voxels_new.iter().filter(|v| voxels_old.contains(v)).count();
    shared as f64 / voxels_new.len().max(1) as f64
}

/// Poses of the new keyframes before and after their alignment.
struct Aligned {
    before: Vec<Isometry3<f64>>,
    after: Vec<Isometry3<f64>>,
}

/// Aligns the new keyframes onto the old ones (held fixed) with the progressive schedule;
/// `None` if the alignment failed.
fn align(
    flight: &FlightWindows,
    old: &[&Keyframe],
    new: &[&Keyframe],
    config: &PssBaConfig,
    parallelism: Parallelism,
) -> Option<Aligned> {
    let clouds: Vec<_> = old.iter().chain(new).map(|k| k.cloud()).collect();
    let initial: Vec<Isometry3<f64>> = old
        .iter()
        .chain(new)
        .map(|k| pose_of(flight, k.sequence).to_isometry())
        .collect();
    let fixed: Vec<bool> = (0..clouds.len()).map(|i| i < old.len()).collect();
    let window = Window {
        frames: &clouds,
        world_from_lidar: &initial,
        fixed: Some(&fixed),
        times: None,
    };
    // No motion prior: the old and the new keyframes are not consecutive.
    let align_config = PssBaConfig {
        motion_prior: MotionPrior::default(),
        ..config.clone()
    };
    match adjust_window(window, &align_config, parallelism) {
        Ok(result) => Some(Aligned {
            before: initial[old.len()..].to_vec(),
            after: result.world_from_lidar[old.len()..].to_vec(),
        }),
        Err(error) => {
            tracing::warn!("revisit alignment failed ({error}); the loop stays open");
            None
        }
    }
}

/// A loop edge per new keyframe at `correction * its pose`, to the nearest old keyframe.
fn loop_edges(
    flight: &FlightWindows,
    old: &[&Keyframe],
    new: &[&Keyframe],
    correction: &Isometry3<f64>,
) -> Vec<LoopEdge> {
    let s = &flight.settings;
    new.iter()
        .map(|keyframe| {
            let a = Pose::from_isometry(
                &(correction * pose_of(flight, keyframe.sequence).to_isometry()),
            );
            let distance =
                |k: &&&Keyframe| (pose_of(flight, k.sequence).translation - a.translation).norm();
            let nearest = old
                .iter()
                .min_by(|x, y| distance(x).total_cmp(&distance(y)))
                .expect("old keyframes are not empty");
            LoopEdge {
                old: nearest.sequence,
                new: keyframe.sequence,
                measured: relative(&pose_of(flight, nearest.sequence), &a),
                information: edge_information(
                    &keyframe.geometry,
                    s.loop_sigma_m,
                    s.odometry_sigma_rad,
                    s.odometry_sigma_m,
                ),
            }
        })
        .collect()
}

/// Closes the loop a window's new keyframes (from `first_new`) make, if any.
pub(super) fn close(
    flight: &mut FlightWindows,
    first_new: usize,
    window_first: usize,
    config: &PssBaConfig,
    parallelism: Parallelism,
) -> Option<LoopClosure> {
    let (old, new) = candidates(flight, first_new, window_first);
    if old.is_empty() || new.is_empty() {
        return None;
    }
    let s = flight.settings;
    let all = flight.keyframes.all();
    let pick = |ids: &[usize]| -> Vec<&Keyframe> { ids.iter().map(|&i| &all[i]).collect() };
    let (old_frames, new_frames) = (pick(&old), pick(&new));
    let overlap = overlap(flight, &old_frames, &new_frames);
    if overlap < s.revisit_min_overlap {
        tracing::debug!("revisit candidates overlap {overlap:.2}: not a revisit");
        return None;
    }
    let started = Instant::now();
    let Aligned {
        before: new_initial,
        after: new_aligned,
    } = align(flight, &old_frames, &new_frames, config, parallelism)?;
    let align_s = started.elapsed().as_secs_f64();
    let (correction, spread_m) = rigid_correction(&new_initial, &new_aligned);
    let drifts: Vec<f64> = new_initial
        .iter()
        .map(|t| ((correction * t).translation.vector - t.translation.vector).norm())
        .collect();
    let max_correction_m = drifts.iter().copied().fold(0.0, f64::max);
    let mean_correction_m = drifts.iter().sum::<f64>() / drifts.len() as f64;
    if max_correction_m > s.max_correction_m || spread_m > s.max_alignment_spread_m {
        tracing::warn!(
            "revisit alignment: drift {max_correction_m:.2} m, keyframes {spread_m:.3} m apart \
             from one rigid correction (limits: max_correction_m {} m, max_alignment_spread_m \
             {} m); the loop stays open",
            s.max_correction_m,
            s.max_alignment_spread_m
        );
        return None;
    }
    let started = Instant::now();
    let loop_edges = loop_edges(flight, &old_frames, &new_frames, &correction);
    let old_sequences: Vec<usize> = old_frames.iter().map(|k| k.sequence).collect();
    let new_sequences: Vec<usize> = new_frames.iter().map(|k| k.sequence).collect();
    let chain_start = *old_sequences
        .iter()
        .max()
        .expect("old keyframes are not empty");
    flight.loop_edges.extend(loop_edges);
    let (graph, moved) = solve_and_apply(flight, chain_start)?;
    let windows = &flight.windows;
    flight
        .keyframes
        .reindex(|k| Pose::from_isometry(&windows.final_pose(k).expect("keyframes are final")));
    let closure = LoopClosure {
        window: flight.windows.windows_done() - 1,
        old_keyframes: old_sequences,
        new_keyframes: new_sequences,
        overlap,
        max_correction_m,
        mean_correction_m,
        spread_m,
        moved,
        graph,
        align_s,
        graph_s: started.elapsed().as_secs_f64(),
    };
    tracing::info!(
        "window {}: revisit of {} old keyframes (overlap {:.2}), drift {:.3} m; {} frames moved",
        closure.window,
        closure.old_keyframes.len(),
        overlap,
        mean_correction_m,
        closure.moved.len()
    );
    Some(closure)
}

/// What the global pass did.
#[derive(Debug, Clone, PartialEq)]
pub struct GlobalPass {
    /// Keyframes in the graph and loop edges among them.
    pub keyframes: usize,
    pub loop_edges: usize,
    /// Stream indices of the final frames it moved, ascending.
    pub moved: Vec<usize>,
    /// The pose graph's solve.
    pub graph: GraphReport,
    /// Wall time (s).
    pub seconds: f64,
}

/// The global pass (DESIGN section 9), once every frame is final: the pose graph over all
/// keyframes, the first held fixed, with every window edge and every loop edge of the
/// flight. Each closure solved only the keyframes after its old visit, with the old ones
/// fixed; here each loop's disagreement is shared by the whole flight, and later loops can
/// move the frames earlier ones set. `None` without loop edges: the windows' relative poses
/// then hold exactly and there is nothing to share.
pub(super) fn global_pass(flight: &mut FlightWindows) -> Option<GlobalPass> {
    if flight.loop_edges.is_empty() {
        return None;
    }
    let started = Instant::now();
    let first = flight.keyframes.all().first()?.sequence;
    let (graph, moved) = solve_and_apply(flight, first)?;
    let pass = GlobalPass {
        keyframes: flight.keyframes.all().len(),
        loop_edges: flight.loop_edges.len(),
        moved,
        graph,
        seconds: started.elapsed().as_secs_f64(),
    };
    tracing::info!(
        "global pass: {} keyframes, {} loop edges, cost {:.3e} -> {:.3e} in {} iterations; \
         {} frames moved ({:.2} s)",
        pass.keyframes,
        pass.loop_edges,
        pass.graph.initial_cost,
        pass.graph.final_cost,
        pass.graph.iterations,
        pass.moved.len(),
        pass.seconds
    );
    Some(pass)
}

/// The pose graph from keyframe `chain_start` (held fixed) to the last keyframe, with every
/// loop edge that reaches into it; applies the keyframes' corrections to every final frame
/// after `chain_start` (interpolated between keyframes). Returns the solve and the frames moved.
fn solve_and_apply(
    flight: &mut FlightWindows,
    chain_start: usize,
) -> Option<(GraphReport, Vec<usize>)> {
    let s = flight.settings;
    let chain: Vec<&Keyframe> = flight
        .keyframes
        .all()
        .iter()
        .filter(|k| k.sequence >= chain_start)
        .collect();
    // Graph poses: the chain's keyframes, then the fixed old ends of loop edges before it.
    let mut node_of: BTreeMap<usize, usize> = BTreeMap::new();
    let mut sequences: Vec<usize> = Vec::new();
    for keyframe in &chain {
        node_of.insert(keyframe.sequence, sequences.len());
        sequences.push(keyframe.sequence);
    }
    let loops: Vec<&LoopEdge> = flight
        .loop_edges
        .iter()
        .filter(|e| e.new > chain_start && node_of.contains_key(&e.new))
        .collect();
    for edge in &loops {
        if let std::collections::btree_map::Entry::Vacant(slot) = node_of.entry(edge.old) {
            slot.insert(sequences.len());
            sequences.push(edge.old);
        }
    }
    let before: Vec<Pose> = sequences.iter().map(|&k| pose_of(flight, k)).collect();
    let fixed: Vec<bool> = sequences.iter().map(|&k| k <= chain_start).collect();
    let mut edges = Vec::new();
    for pair in chain.windows(2) {
        let geometry = (pair[0].geometry + pair[1].geometry) * 0.5;
        edges.push(Edge {
            from: node_of[&pair[0].sequence],
            to: node_of[&pair[1].sequence],
            measured: pair[1]
                .from_previous
                .expect("a keyframe after the first has one"),
            information: edge_information(
                &geometry,
                s.window_sigma_m,
                s.odometry_sigma_rad,
                s.odometry_sigma_m,
            ),
        });
    }
    for edge in loops {
        edges.push(Edge {
            from: node_of[&edge.old],
            to: node_of[&edge.new],
            measured: edge.measured,
            information: edge.information,
        });
    }
    let mut after = before.clone();
    let report = pose_graph::solve(&mut after, &fixed, &edges, 20)?;
    // World-side corrections of the chain's keyframes: after * before^-1.
    let corrections: Vec<(usize, Isometry3<f64>)> = chain
        .iter()
        .map(|k| {
            let i = node_of[&k.sequence];
            let c = after[i].to_isometry() * before[i].to_isometry().inverse();
            (k.sequence, c)
        })
        .collect();
    let mut moved = Vec::new();
    for pair in corrections.windows(2) {
        let ((a, ca), (b, cb)) = (pair[0], pair[1]);
        for sequence in a + 1..=b {
            let t = (sequence - a) as f64 / (b - a) as f64;
            let correction = interpolate(&ca, &cb, t);
            if let Some(pose) = flight.windows.final_pose(sequence) {
                flight
                    .windows
                    .revise_final_pose(sequence, correction * pose);
                moved.push(sequence);
            }
        }
    }
    Some((report, moved))
}

/// One world-side correction `C` with `C T_k ~ A_k` for every new keyframe (`T` as the
/// windows left them, `A` as the alignment moved each alone): the window is consistent within
/// itself, only its drift is unknown, and a keyframe that sees little aligns loosely. The
/// rotation is the mean of the keyframes' (quaternion average), the translation the per-axis
/// median. Also returns the RMS distance between `C T_k` and `A_k` (m).
fn rigid_correction(
    current: &[Isometry3<f64>],
    aligned: &[Isometry3<f64>],
) -> (Isometry3<f64>, f64) {
    let each: Vec<Isometry3<f64>> = current
        .iter()
        .zip(aligned)
        .map(|(t, a)| a * t.inverse())
        .collect();
    let reference = each[0].rotation;
    let mut sum = nalgebra::Vector4::zeros();
    for c in &each {
        let q = c.rotation.into_inner().coords;
        sum += if q.dot(&reference.into_inner().coords) < 0.0 {
            -q
        } else {
            q
        };
    }
    let rotation = UnitQuaternion::from_quaternion(nalgebra::Quaternion::from(sum));
    let median = |axis: usize| {
        let mut values: Vec<f64> = current
            .iter()
            .zip(aligned)
            .map(|(t, a)| a.translation.vector[axis] - (rotation * t.translation.vector)[axis])
            .collect();
        values.sort_by(f64::total_cmp);
        let n = values.len();
        if n % 2 == 1 {
            values[n / 2]
        } else {
            0.5 * (values[n / 2 - 1] + values[n / 2])
        }
    };
    let correction = Isometry3::from_parts(
        Translation3::from(Vector3::new(median(0), median(1), median(2))),
        rotation,
    );
    let spread_sq = current
        .iter()
        .zip(aligned)
        .map(|(t, a)| ((correction * t).translation.vector - a.translation.vector).norm_squared())
        .sum::<f64>()
        / current.len() as f64;
    (correction, spread_sq.sqrt())
}

/// `a` at 0 to `b` at 1: translations linearly, rotations along the shortest arc.
fn interpolate(a: &Isometry3<f64>, b: &Isometry3<f64>, t: f64) -> Isometry3<f64> {
    let translation = a.translation.vector.lerp(&b.translation.vector, t);
    let rotation = a.rotation.slerp(&b.rotation, t);
    Isometry3::from_parts(Translation3::from(translation), rotation)
}
