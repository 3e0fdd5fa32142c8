//! Spatial smoothing at one scale (DESIGN steps 4-7, paper section "Spatial Smoothing for
//! LiDAR Factor Extraction"): per kernel, L0-refined normal, tangent frame, weighted
//! polynomial fit, and the residual points of other frames tied to the surface.

use crate::cloud::scale_cloud::ScaleCloud;
use crate::config::PssBaConfig;
use crate::factor::{FactorBlock, FactorPoint, KernelRejections, Surface};
use crate::geometry::Pose;
use crate::kernels::anchors::{AnchorScratch, anchor_frames, frame_groups};
use crate::kernels::block_assembly::ordered_by_frame_pair;
use crate::kernels::fit::{FitLimits, FitRejection, SurfaceModel, fit_polynomial};
use crate::kernels::frame_set::FrameSet;
use crate::kernels::l0::refine_normal_l0;
use crate::kernels::tangent::tangent_from_world;
use crate::parallel::{Parallelism, map_indexed};
use nalgebra::Vector3;

/// Outcome of one kernel.
enum KernelOutcome {
    Accepted(Surface, Vec<FactorPoint>),
    Rejected(fn(&mut KernelRejections)),
}

/// Every `len / keep`-th index when `len > keep`, so a cap keeps the spatial spread; `phase`
/// in [0, 1) shifts the picks by that fraction of the step (0: from the first index).
fn evenly(len: usize, keep: usize, phase: f64) -> impl Iterator<Item = usize> {
    let step = if len > keep {
        len as f64 / keep as f64
    } else {
        1.0
    };
    let phase = if len > keep { phase } else { 0.0 };
    (0..len.min(keep)).map(move |k| ((k as f64 + phase) * step) as usize)
}

/// Builds the factor block of one scale from the cloud of that scale.
pub fn extract_block(
    cloud: &ScaleCloud,
    poses: &[Pose],
    gamma_m: f64,
    model: SurfaceModel,
    config: &PssBaConfig,
    parallelism: Parallelism,
) -> FactorBlock {
    let kernels = cloud.sample_kernels(gamma_m, parallelism);
    let groups = frame_groups(poses.len(), config.frames_per_kernel_group);
    // Few kernels (coarse scales) may each carry more residuals, so every frame stays tied.
    let residuals_per_kernel = config
        .residuals_per_kernel
        .max(config.residuals_per_scale / (kernels.len() * groups).max(1));
    // A kernel's lists (the neighbours: thousands at coarse scales) reuse the thread's buffers
    // (`KernelBuffers`) instead of being allocated, and grown by doubling, for every kernel.
    let outcomes = map_indexed(kernels.len(), parallelism, |k| {
        KERNEL_BUFFERS.with_borrow_mut(|buffers| {
            smooth_kernel(
                cloud,
                poses,
                kernels[k],
                buffers,
                groups,
                gamma_m,
                model,
                config,
                residuals_per_kernel,
            )
        })
    });
    let mut rejected = KernelRejections::default();
    // Sized exactly: at 1000 frames a scale has 400k surfaces, which doubling would overshoot.
    let accepted = (outcomes.iter().flatten())
        .filter(|outcome| matches!(outcome, KernelOutcome::Accepted(..)))
        .count();
    let (mut surfaces, mut lists) = (Vec::with_capacity(accepted), Vec::with_capacity(accepted));
    for outcome in outcomes.into_iter().flatten() {
        match outcome {
            KernelOutcome::Accepted(surface, points) => {
                surfaces.push(surface);
                lists.push(points);
            }
            KernelOutcome::Rejected(count) => count(&mut rejected),
        }
    }
    // In the order the normal equations sum them (see `normal_equations`), once here rather
    // than in a copy at every LM run.
    let points = ordered_by_frame_pair(&surfaces, &lists, poses.len(), parallelism);
    drop(lists);
    FactorBlock {
        gamma_m,
        robust_scale_m: config.robust_scale_m(gamma_m),
        surfaces,
        points,
        rejected,
    }
}

/// Steps 4-7 for the kernel at cloud point `kernel`: the surface is fitted once, then anchored
/// to each of its anchor frames in turn (see anchors.rs; one group: the kernel's own frame),
/// one surface each with its own residual points. `buffers` are the thread's (their contents
/// are replaced).
#[allow(clippy::too_many_arguments)]
fn smooth_kernel(
    cloud: &ScaleCloud,
    poses: &[Pose],
    kernel: usize,
    buffers: &mut KernelBuffers,
    groups: usize,
    gamma_m: f64,
    model: SurfaceModel,
    config: &PssBaConfig,
    residuals_per_kernel: usize,
) -> Vec<KernelOutcome> {
    let rejected = |count: fn(&mut KernelRejections)| vec![KernelOutcome::Rejected(count)];
    let Some(kernel_normal) = cloud.normal(kernel) else {
        return rejected(|r| r.no_normal += 1);
    };
    let KernelBuffers {
        neighbours,
        normal_sample,
        own_points,
        fit_points,
        fit_weights,
        others,
    } = buffers;
    neighbours.clear();
    cloud.within_with_normal(kernel, gamma_m, neighbours);
    // The fit below takes at most these neighbours (the gate only removes some): too few
    // already, the kernel is rejected as the fit would reject it, without the L0 and gate
    // passes (sparse far points: most kernels of a 0.4 m scale on the crane flight).
    let limits = FitLimits {
        min_points: config.fit_min_points,
        min_eigen_ratio: config.fit_min_eigen_ratio,
        max_rms_m: config.fit_max_rms_per_gamma * gamma_m,
    };
    if neighbours.len() < limits.fewest_points(model) {
        return rejected(|r| r.too_few_points += 1);
    }
    let kernel_world = cloud.world(kernel);

    // Step 4: L0 refinement against a spread sample of neighbour normals.
    normal_sample.clear();
    normal_sample.extend(
        evenly(neighbours.len(), config.l0_max_neighbours, 0.0)
            .filter_map(|k| cloud.normal(neighbours[k])),
    );
    let normal = refine_normal_l0(
        &kernel_normal,
        normal_sample,
        config.l0_mu,
        config.l0_beta_max,
    );

    // Neighbours across an edge or with outlier normals stay out of fit and residuals. The
    // same pass picks step 7's candidates (from every frame its nearest points to the
    // kernel) and, with one frame group, the anchor frame's (the kernel's frame) own points.
    let gate = config.gate_deg_at(gamma_m).to_radians().cos();
    let kernel_frame = cloud.frame_of[kernel];
    own_points.clear();
    let per_frame = config.residuals_per_kernel_frame;
    let candidates = NEAREST_SCRATCH.with_borrow_mut(|scratch| {
        scratch.prepare(per_frame, poses.len());
        cloud.retain_facing_then(neighbours, &normal, gate, |j| {
            scratch.offer(cloud, j, &kernel_world, per_frame);
            if groups == 1 && cloud.frame_of[j] == kernel_frame {
                own_points.push(j);
            }
        });
        scratch.drain(per_frame, neighbours.len())
    });

    // Step 5: tangent frame; step 6: weighted fit.
    let tangent_from_world = tangent_from_world(&normal);
    let inv_gamma_sq = 1.0 / (gamma_m * gamma_m);
    let local = |j: usize| tangent_from_world * (cloud.world(j) - kernel_world);
    fit_points.clear();
    fit_weights.clear();
    for k in evenly(neighbours.len(), config.fit_max_points, 0.0) {
        let s = local(neighbours[k]);
        fit_points.push(s);
        fit_weights.push((-s.norm_squared() * inv_gamma_sq).exp());
    }
    let consensus = match fit_polynomial(fit_points, fit_weights, gamma_m, model, &limits) {
        Ok((polynomial, _rms)) => polynomial,
        Err(FitRejection::TooFewPoints) => return rejected(|r| r.too_few_points += 1),
        Err(FitRejection::IllConditioned) => return rejected(|r| r.ill_conditioned += 1),
        Err(FitRejection::TooRough) => return rejected(|r| r.too_rough += 1),
    };

    let anchors = if groups == 1 {
        vec![kernel_frame]
    } else {
        ANCHOR_SCRATCH.with_borrow_mut(|scratch| {
            let point_frames = neighbours.iter().map(|&j| cloud.frame_of[j]);
            anchor_frames(point_frames, poses.len(), groups, scratch)
        })
    };
    if anchors.is_empty() {
        // No frame has enough of its own points here to carry the surface.
        return rejected(|r| r.too_few_points += 1);
    }
    // Each anchor's offset onto its own points (see `anchor_offsets`). One group: the anchor
    // is the kernel's frame, whose points were gathered by the gate's pass.
    let anchor_points: &[usize] = if groups == 1 { own_points } else { neighbours };
    let offsets = if config.anchor_offset_to_kernel_frame {
        anchor_offsets(
            &consensus,
            anchor_points,
            &anchors,
            cloud,
            &local,
            inv_gamma_sq,
        )
    } else {
        vec![None; anchors.len()]
    };
    // (Several groups: every anchor frame has enough points by choice.)
    debug_assert!(
        groups == 1 || !config.anchor_offset_to_kernel_frame || offsets.iter().all(Option::is_some)
    );
    anchors
        .iter()
        .zip(offsets)
        .enumerate()
        .map(|(g, (&frame_a, offset))| {
            let mut polynomial = consensus;
            if let Some(offset) = offset {
                polynomial.coefficients[5] += offset;
            }
            // Step 7: residual points from the other frames, capped per frame and per
            // surface; the anchors of one kernel pick interleaved candidates.
            others.clear();
            others.extend((candidates.iter().copied()).filter(|&j| cloud.frame_of[j] != frame_a));
            if others.is_empty() {
                return KernelOutcome::Rejected(|r| r.single_frame += 1);
            }
            let phase = g as f64 / anchors.len() as f64;
            let points = evenly(others.len(), residuals_per_kernel, phase)
                .map(|k| {
                    let j = others[k];
                    let s = local(j);
                    FactorPoint::new(
                        0,
                        cloud.frame_of[j],
                        cloud.lidar(j),
                        (-s.norm_squared() * inv_gamma_sq).exp(),
                    )
                })
                .collect();
            let pose_a = &poses[frame_a as usize];
            let kernel_in_lidar = if frame_a == kernel_frame {
                cloud.lidar(kernel)
            } else {
                pose_a.rotation.transpose() * (kernel_world - pose_a.translation)
            };
            let surface = Surface {
                frame: frame_a as usize,
                kernel_in_lidar,
                tangent_from_lidar: tangent_from_world * pose_a.rotation,
                polynomial,
                gamma_m,
            };
            KernelOutcome::Accepted(surface, points)
        })
        .collect()
}

/// Per anchor frame `a` of `anchors`, the offset along the normal that moves the consensus
/// surface onto `a`'s own points (weighted mean of their residuals), from one pass over
/// `points` (the gated neighbours, or any part of them holding all the anchors' points).
/// The consensus fit sits at the average of all frames; attached to frame `a` at that height,
/// it would pull every other frame only part of the way towards `a`, so alignment would
/// shrink by a fraction per scale. Anchored, the shape still comes from all frames but the
/// offset is `a`'s. `None` (the consensus stays) with fewer than 3 own points.
fn anchor_offsets(
    consensus: &crate::kernels::fit::Polynomial,
    points: &[usize],
    anchors: &[u32],
    cloud: &ScaleCloud,
    local: &impl Fn(usize) -> Vector3<f64>,
    inv_gamma_sq: f64,
) -> Vec<Option<f64>> {
    // (sum of weighted residuals, sum of weights, count) per anchor, each summed in the
    // order of `points`.
    let mut sums = vec![(0.0, 0.0, 0usize); anchors.len()];
    ANCHOR_SLOT.with_borrow_mut(|slot_of_frame| {
        let frames = anchors.iter().map(|&a| a as usize + 1).max().unwrap_or(0);
        if slot_of_frame.len() < frames {
            slot_of_frame.resize(frames, u32::MAX);
        }
        for (slot, &a) in anchors.iter().enumerate() {
            slot_of_frame[a as usize] = slot as u32;
        }
        for &j in points {
            let frame = cloud.frame_of[j] as usize;
            let Some(&slot) = slot_of_frame.get(frame) else {
                continue;
            };
            if slot == u32::MAX {
                continue;
            }
            let s = local(j);
            let w = (-s.norm_squared() * inv_gamma_sq).exp();
            let (sum, weight, count) = &mut sums[slot as usize];
            *sum += w * (s.z - consensus.height(s.x, s.y));
            *weight += w;
            *count += 1;
        }
        // Left all unset for the next kernel.
        for &a in anchors {
            slot_of_frame[a as usize] = u32::MAX;
        }
    });
    sums.into_iter()
        .map(|(sum, weight, count)| (count >= 3 && weight > 0.0).then(|| sum / weight))
        .collect()
}

/// The residual candidates of one kernel site: from each frame, its `per_frame` neighbours
/// nearest the kernel (ties by index), frames in ascending order, nearest first. (Each
/// anchor then leaves out its own frame's.) `smooth_kernel` picks them in its gate's pass;
/// this is the same on its own, for the tests.
#[cfg(test)]
fn nearest_per_frame(
    cloud: &ScaleCloud,
    neighbours: &[usize],
    kernel_world: &Vector3<f64>,
    per_frame: usize,
    frames: usize,
) -> Vec<usize> {
    if per_frame == 0 {
        return Vec::new();
    }
    NEAREST_SCRATCH.with_borrow_mut(|scratch| {
        scratch.prepare(per_frame, frames);
        for &j in neighbours {
            scratch.offer(cloud, j, kernel_world, per_frame);
        }
        scratch.drain(per_frame, neighbours.len())
    })
}

/// The lists one kernel fills, kept by each thread from kernel to kernel instead of allocated
/// for each (a 0.4 m scale has 45k kernels of about 100 neighbours each: the allocations
/// were a fixed cost of every kernel).
#[derive(Default)]
struct KernelBuffers {
    /// The cloud points within gamma of the kernel, then those the normal gate keeps.
    neighbours: Vec<usize>,
    /// The neighbour normals the L0 refinement sees.
    normal_sample: Vec<Vector3<f64>>,
    /// The gated neighbours of the kernel's own frame (one frame group).
    own_points: Vec<usize>,
    /// The fit's points (tangent frame) and weights.
    fit_points: Vec<Vector3<f64>>,
    fit_weights: Vec<f64>,
    /// One anchor's residual candidates: those of the other frames.
    others: Vec<usize>,
}

/// An unused candidate slot: farther than any point.
const EMPTY_SLOT: (f64, usize) = (f64::INFINITY, usize::MAX);

/// Per-thread buffers of [`nearest_per_frame`], kept all empty between calls: a kernel then
/// costs in proportion to its neighbours and the frames it touches, not to the window's
/// frames (1000 frames x 4 slots: 64 kB to clear per kernel otherwise).
#[derive(Default)]
struct PerFrameScratch {
    /// Per frame, `per_frame` slots of (squared distance, point), nearest first.
    best: Vec<(f64, usize)>,
    /// Per frame, slots filled.
    found: Vec<usize>,
    /// Frames with at least one slot filled.
    touched: FrameSet,
}

impl PerFrameScratch {
    /// Room for `per_frame` slots for each of `frames` frames, all empty.
    fn prepare(&mut self, per_frame: usize, frames: usize) {
        if self.best.len() < frames * per_frame {
            self.best.resize(frames * per_frame, EMPTY_SLOT);
        }
        if self.found.len() < frames {
            self.found.resize(frames, 0);
        }
        self.touched.reserve_frames(frames);
    }

    /// Offers cloud point `j` as a candidate of its frame (kept if among the frame's
    /// `per_frame` nearest to `kernel_world` so far; ties by index).
    #[inline]
    fn offer(
        &mut self,
        cloud: &ScaleCloud,
        j: usize,
        kernel_world: &Vector3<f64>,
        per_frame: usize,
    ) {
        if per_frame == 0 {
            return;
        }
        let frame = cloud.frame_of[j] as usize;
        let candidate = ((cloud.world(j) - kernel_world).norm_squared(), j);
        let slots = &mut self.best[frame * per_frame..(frame + 1) * per_frame];
        // Squared distances of finite points are finite and never -0, so `<` orders them as
        // `total_cmp` would (and costs less; empty slots hold +inf).
        let closer = |x: &(f64, usize), y: &(f64, usize)| x.0 < y.0 || (x.0 == y.0 && x.1 < y.1);
        // Insertion into the short sorted list; the farthest falls off the end.
        if closer(&candidate, &slots[per_frame - 1]) {
            let mut k = per_frame - 1;
            while k > 0 && closer(&candidate, &slots[k - 1]) {
                slots[k] = slots[k - 1];
                k -= 1;
            }
            slots[k] = candidate;
            self.touched.insert(frame);
            self.found[frame] = (self.found[frame] + 1).min(per_frame);
        }
    }

    /// The candidates kept (frames in ascending order, nearest first), leaving the buffers
    /// empty for the next kernel; `offered` bounds their number.
    fn drain(&mut self, per_frame: usize, offered: usize) -> Vec<usize> {
        let Self {
            best,
            found,
            touched,
        } = self;
        let mut out = Vec::with_capacity(offered.min(found.len() * per_frame));
        touched.drain_ascending(|frame| {
            let slots = &mut best[frame * per_frame..(frame + 1) * per_frame];
            out.extend(slots[..found[frame]].iter().map(|&(_, j)| j));
            slots.fill(EMPTY_SLOT);
            found[frame] = 0;
        });
        out
    }
}

thread_local! {
    /// Per-thread frame -> anchor slot table of [`anchor_offsets`] (`u32::MAX`: no anchor),
    /// kept all unset between kernels.
    static ANCHOR_SLOT: std::cell::RefCell<Vec<u32>> = const { std::cell::RefCell::new(Vec::new()) };
    /// Per-thread buffer of [`anchor_frames`].
    static ANCHOR_SCRATCH: std::cell::RefCell<AnchorScratch> =
        std::cell::RefCell::new(AnchorScratch::default());
    static NEAREST_SCRATCH: std::cell::RefCell<PerFrameScratch> =
        std::cell::RefCell::new(PerFrameScratch::default());
    /// Per-thread buffers of [`smooth_kernel`].
    static KERNEL_BUFFERS: std::cell::RefCell<KernelBuffers> =
        std::cell::RefCell::new(KernelBuffers::default());
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::parallel::Parallelism;

    /// Five frames of a tilted plane, each seen from its own offset.
    fn cloud() -> (ScaleCloud, usize) {
        let (cloud, poses) = plane_window();
        (cloud, poses.len())
    }

    /// [`cloud`] with its poses.
    fn plane_window() -> (ScaleCloud, Vec<Pose>) {
        let frames = 5;
        let poses: Vec<Pose> = (0..frames)
            .map(|k| Pose {
                rotation: nalgebra::Matrix3::identity(),
                translation: Vector3::new(0.1 * k as f64, -0.05 * k as f64, 2.0),
            })
            .collect();
        let lidar_frames: Vec<Vec<Vector3<f64>>> = poses
            .iter()
            .enumerate()
            .map(|(k, pose)| {
                (0..400)
                    .map(|i| {
                        let (x, y) = (
                            (i % 20) as f64 * 0.11,
                            (i / 20) as f64 * 0.13 + 0.01 * k as f64,
                        );
                        Vector3::new(x, y, 0.2 * x) - pose.translation
                    })
                    .collect()
            })
            .collect();
        let cloud = ScaleCloud::build(&lidar_frames, &poses, 0.05, 8, Parallelism::Serial);
        (cloud, poses)
    }

    #[test]
    fn frame_groups_anchor_one_surface_per_group() {
        let (cloud, poses) = plane_window();
        let extract = |frames_per_kernel_group: usize| {
            let config = PssBaConfig {
                frames_per_kernel_group,
                ..PssBaConfig::default()
            };
            let model = SurfaceModel::Quadratic;
            extract_block(&cloud, &poses, 0.6, model, &config, Parallelism::Serial)
        };
        let paper = extract(100);
        // A group as long as the window: one surface per kernel, on the kernel's frame.
        assert_eq!(extract(5), paper);
        // 5 frames in groups of 2: {0, 1}, {2, 3}, {4}.
        let grouped = extract(2);
        assert!(
            grouped.surfaces.len() > 2 * paper.surfaces.len(),
            "{} surfaces against {}",
            grouped.surfaces.len(),
            paper.surfaces.len()
        );
        let group = |frame: usize| frame / 2;
        let kernel_world = |s: &Surface| poses[s.frame].apply(&s.kernel_in_lidar);
        // One kernel's surfaces are consecutive: each on a frame of a later group.
        for pair in grouped.surfaces.windows(2) {
            if (kernel_world(&pair[0]) - kernel_world(&pair[1])).norm() < 1e-9 {
                assert!(group(pair[0].frame) < group(pair[1].frame));
            }
        }
        // No surface ties its own frame, and every group anchors surfaces.
        for p in &grouped.points {
            assert_ne!(p.frame as usize, grouped.surfaces[p.surface as usize].frame);
        }
        for g in 0..3 {
            assert!(grouped.surfaces.iter().any(|s| group(s.frame) == g));
        }
    }

    /// A crease: the floor z = 0 for x < 0 and a face rising at 40 deg for x > 0, seen by four
    /// sensors above it; points 4 cm apart, jittered per frame.
    fn crease_window() -> (ScaleCloud, Vec<Pose>) {
        let poses: Vec<Pose> = (0..4)
            .map(|k| Pose {
                rotation: nalgebra::Matrix3::identity(),
                translation: Vector3::new(0.3 * k as f64 - 0.45, 0.2, 3.0),
            })
            .collect();
        let slope = 40f64.to_radians().tan();
        let lidar_frames = (poses.iter().enumerate())
            .map(|(k, pose)| {
                (0..50 * 25)
                    .map(|i| {
                        let x = (i % 50) as f64 * 0.04 - 1.0 + 0.013 * k as f64;
                        let y = (i / 50) as f64 * 0.04 + 0.007 * k as f64;
                        Vector3::new(x, y, slope * x.max(0.0)) - pose.translation
                    })
                    .collect()
            })
            .collect::<Vec<Vec<Vector3<f64>>>>();
        let cloud = ScaleCloud::build(&lidar_frames, &poses, 0.05, 8, Parallelism::Serial);
        (cloud, poses)
    }

    #[test]
    fn the_fine_gate_keeps_the_other_face_of_a_crease_out_and_the_coarse_scales_unchanged() {
        let (cloud, poses) = crease_window();
        let model = SurfaceModel::Quadratic;
        let extract = |fine_normal_gate_deg: f64, gamma_m: f64| {
            let config = PssBaConfig {
                fine_normal_gate_deg,
                ..PssBaConfig::default()
            };
            extract_block(&cloud, &poses, gamma_m, model, &config, Parallelism::Serial)
        };
        // How far the surfaces of the floor's kernels near the crease stray from the floor
        // (m), at the floor point beside the crease: the slope's points bend a fit that takes
        // them. (Residual points are each frame's nearest to the kernel, on the floor here.)
        let bend = |block: &FactorBlock| {
            (block.surfaces.iter())
                .filter_map(|surface| {
                    let pose = &poses[surface.frame];
                    let kernel = pose.apply(&surface.kernel_in_lidar);
                    (-0.3..-0.05).contains(&kernel.x).then(|| {
                        let floor = Vector3::new(-0.01, kernel.y, 0.0);
                        let lidar = pose.rotation.transpose() * (floor - pose.translation);
                        let s = surface.tangent_from_lidar * (lidar - surface.kernel_in_lidar);
                        (s.z - surface.polynomial.height(s.x, s.y)).abs()
                    })
                })
                .fold(0.0f64, f64::max)
        };
        // 0.4 m is a fine scale (below prior_min_gamma_m): at 60 deg the slope's points (40
        // deg off) bend the floor's surfaces by 3 cm; at the default 30 deg only the points
        // right at the crease, whose PCA normals lean both ways, get in (7.5 mm).
        let (fine, wide) = (extract(30.0, 0.4), extract(60.0, 0.4));
        assert!(!fine.surfaces.is_empty() && !fine.points.is_empty());
        let (bend_fine, bend_wide) = (bend(&fine), bend(&wide));
        assert!(bend_wide > 0.02, "60 deg bends the floor: {bend_wide} m");
        assert!(bend_fine < bend_wide / 3.0, "{bend_fine} m at 30 deg");
        // A coarse scale keeps normal_gate_deg whatever the fine gate.
        let config = PssBaConfig::default();
        assert!(1.6 >= config.prior_min_gamma_m);
        assert_eq!(extract(30.0, 1.6), extract(60.0, 1.6));
        assert_eq!(config.gate_deg_at(1.6), config.normal_gate_deg);
        assert_eq!(config.gate_deg_at(0.4), config.fine_normal_gate_deg);
    }

    #[test]
    fn kernels_with_fewer_neighbours_than_a_fit_takes_count_as_too_few_points() {
        let (cloud, poses) = plane_window();
        let config = PssBaConfig::default();
        let model = SurfaceModel::Quadratic;
        // 0.1 m: a kernel's ball holds the kernel and the other frames' copies of its point
        // (5 frames), fewer than the 12 a fit takes.
        let sparse = extract_block(&cloud, &poses, 0.1, model, &config, Parallelism::Serial);
        assert!(sparse.surfaces.is_empty());
        assert!(sparse.rejected.too_few_points > 0);
        assert_eq!(sparse.rejected.total(), sparse.rejected.too_few_points);
        // The same cloud at a width holding enough neighbours gives surfaces.
        let dense = extract_block(&cloud, &poses, 0.6, model, &config, Parallelism::Serial);
        assert!(!dense.surfaces.is_empty());
    }

    #[test]
    fn anchor_offsets_in_one_pass_equal_one_scan_per_anchor() {
        let (cloud, _) = plane_window();
        let kernel = 210;
        let mut neighbours = Vec::new();
        cloud.within_with_normal(kernel, 0.6, &mut neighbours);
        let kernel_world = cloud.world(kernel);
        let local = |j: usize| cloud.world(j) - kernel_world;
        let inv_gamma_sq = 1.0 / 0.36;
        // A tilted guess, so the offsets differ per frame.
        let consensus = crate::kernels::fit::Polynomial {
            coefficients: [0.01, 0.0, 0.0, 0.1, 0.0, 0.002],
        };
        let scan = |a: u32| {
            let (mut sum, mut weight, mut count) = (0.0, 0.0, 0);
            for &j in neighbours.iter().filter(|&&j| cloud.frame_of[j] == a) {
                let s = local(j);
                let w = (-s.norm_squared() * inv_gamma_sq).exp();
                sum += w * (s.z - consensus.height(s.x, s.y));
                weight += w;
                count += 1;
            }
            (count >= 3 && weight > 0.0).then(|| sum / weight)
        };
        // Frame 9 is not in the window: no points, no offset.
        let anchors = [3, 0, 4, 9];
        let offsets = anchor_offsets(
            &consensus,
            &neighbours,
            &anchors,
            &cloud,
            &local,
            inv_gamma_sq,
        );
        let expected: Vec<Option<f64>> = anchors.iter().map(|&a| scan(a)).collect();
        assert_eq!(offsets, expected);
        assert!(expected[..3].iter().all(Option::is_some));
        assert_eq!(expected[3], None);
        // The table is left unset: the next call with other anchors is unaffected.
        let again = anchor_offsets(&consensus, &neighbours, &[1], &cloud, &local, inv_gamma_sq);
        assert_eq!(again, vec![scan(1)]);
    }

    /// Per frame, the `per_frame` nearest by (distance, index).
    fn brute_force(
        cloud: &ScaleCloud,
        neighbours: &[usize],
        kernel: &Vector3<f64>,
        per_frame: usize,
        frames: usize,
    ) -> Vec<usize> {
        (0..frames as u32)
            .flat_map(|f| {
                let mut own: Vec<(f64, usize)> = neighbours
                    .iter()
                    .filter(|&&j| cloud.frame_of[j] == f)
                    .map(|&j| ((cloud.world(j) - kernel).norm_squared(), j))
                    .collect();
                own.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
                own.into_iter().take(per_frame).map(|(_, j)| j)
            })
            .collect()
    }

    #[test]
    fn nearest_per_frame_matches_brute_force_kernel_after_kernel() {
        let (cloud, frames) = cloud();
        // One thread, many kernels in a row: each must start from empty buffers.
        for (kernel, per_frame, radius_m) in
            [(0, 4, 0.5), (57, 1, 0.3), (300, 3, 0.8), (999, 4, 0.2)]
        {
            let mut neighbours = Vec::new();
            cloud.within_with_normal(kernel, radius_m, &mut neighbours);
            let world = cloud.world(kernel);
            let got = nearest_per_frame(&cloud, &neighbours, &world, per_frame, frames);
            let expected = brute_force(&cloud, &neighbours, &world, per_frame, frames);
            assert!(!expected.is_empty());
            assert_eq!(got, expected, "kernel {kernel}");
        }
    }
}
