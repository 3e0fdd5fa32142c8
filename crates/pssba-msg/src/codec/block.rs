//! Factor blocks in shared memory (smooth -> adjust). Payload: `[f64]` words in this order:
//! - per window frame (`frame_count`): pose `[R row-major (9), t (3)]`, fixed flag (0/1);
//! - per surface (`surface_count`): frame, kernel point in that lidar frame (3),
//!   tangent_from_lidar row-major (9), coefficients a0..a5 (6), gamma (m), and the number of
//!   residual points that follow for it;
//! - per residual point (`point_count`), grouped by surface in surface order (so the surface
//!   index is implied): frame, point in lidar (3), weight.
//!
//! f64 words throughout, so the adjust stage sees exactly what the in-process run sees: a
//! residual point and its weight are held in f32 (see `FactorPoint`), travel exactly as f64
//! and are read back into f32 (a value beyond f32's range is an error). The words are
//! produced by an iterator ([`block_words`]) that the smooth stage writes straight into
//! loaned shared memory, split into samples ([`crate::codec::parts`]) when the block is larger than
//! one sample.

use crate::codec::words::{WordReader, checked_words, expect_len};
use crate::error::MsgError;
use crate::internal::types::{BlockHeader, PoseMsg, block_kind};
use nalgebra::{Matrix3, Vector3};
use pssba_core::factor::{FactorBlock, FactorPoint, Surface};
use pssba_core::fit::Polynomial;
use pssba_core::geometry::Pose;
use pssba_core::lm::LmSettings;

const MESSAGE: &str = "factor block";
const FRAME_WORDS: usize = PoseMsg::WORDS + 1;
const SURFACE_WORDS: usize = 21;
const POINT_WORDS: usize = 5;
/// Largest window accepted from shared memory.
pub const MAX_FRAMES: u64 = 1 << 20;
/// Largest surface or point count accepted from shared memory.
pub const MAX_ITEMS: u64 = 1 << 28;

/// A factor block with everything the adjust stage needs to solve it.
#[derive(Debug, Clone, PartialEq)]
pub struct BlockMessage {
    /// Window index.
    pub window: u64,
    /// Scale index.
    pub scale: u32,
    /// Surfaces and residual points.
    pub block: FactorBlock,
    /// Poses the block was extracted at (world from lidar).
    pub poses: Vec<Pose>,
    /// Frames held fixed.
    pub fixed: Vec<bool>,
    /// LM settings of this scale.
    pub settings: LmSettings,
}

/// The header of the block of `window`, `scale` extracted at `poses`.
pub fn block_header(
    window: u64,
    scale: u32,
    b: &FactorBlock,
    poses: &[Pose],
    settings: &LmSettings,
) -> BlockHeader {
    BlockHeader {
        kind: block_kind::SOLVE,
        scale,
        window,
        gamma_m: b.gamma_m,
        robust_scale_m: b.robust_scale_m,
        frame_count: poses.len() as u64,
        surface_count: b.surfaces.len() as u64,
        point_count: b.points.len() as u64,
        max_iterations: settings.max_iterations as u64,
        initial_lambda: settings.initial_lambda,
        prior_translation_m: settings.prior_translation_m,
        prior_rotation_rad: settings.prior_rotation_rad,
        motion_translation_m: settings.motion_translation_m,
        motion_rotation_rad: settings.motion_rotation_rad,
        ..BlockHeader::default()
    }
}

/// Payload words of a block with these counts (saturating: the counts of a block that exists
/// in memory never overflow).
pub fn block_len(frames: usize, surfaces: usize, points: usize) -> usize {
    frames
        .saturating_mul(FRAME_WORDS)
        .saturating_add(surfaces.saturating_mul(SURFACE_WORDS))
        .saturating_add(points.saturating_mul(POINT_WORDS))
}

/// The payload words of block `b` at `poses` with `fixed` flags, in layout order; exactly
/// [`block_len`] of them. Points not grouped by surface are sent grouped (stable order).
pub fn block_words<'a>(
    b: &'a FactorBlock,
    poses: &'a [Pose],
    fixed: &'a [bool],
) -> impl Iterator<Item = f64> + 'a {
    let mut per_surface = vec![0u64; b.surfaces.len()];
    for p in &b.points {
        if let Some(count) = per_surface.get_mut(p.surface as usize) {
            *count += 1;
        }
    }
    let order: Option<Vec<u32>> = if b.points.is_sorted_by_key(|p| p.surface) {
        None
    } else {
        let mut order: Vec<u32> = (0..b.points.len() as u32).collect();
        order.sort_by_key(|&j| b.points[j as usize].surface);
        Some(order)
    };
    let frames = poses.iter().zip(fixed).flat_map(|(pose, &fixed)| {
        let mut words = [0.0; FRAME_WORDS];
        words[..PoseMsg::WORDS].copy_from_slice(&PoseMsg::from_pose(pose).words());
        words[PoseMsg::WORDS] = if fixed { 1.0 } else { 0.0 };
        words
    });
    let surfaces = b.surfaces.iter().zip(per_surface).flat_map(|(s, count)| {
        let mut words = [0.0; SURFACE_WORDS];
        words[0] = s.frame as f64;
        words[1..4].copy_from_slice(s.kernel_in_lidar.as_slice());
        words[4..13].copy_from_slice(s.tangent_from_lidar.transpose().as_slice());
        words[13..19].copy_from_slice(&s.polynomial.coefficients);
        words[19] = s.gamma_m;
        words[20] = count as f64;
        words
    });
    let points = (0..b.points.len()).flat_map(move |j| {
        let p = &b.points[order.as_ref().map_or(j, |o| o[j] as usize)];
        let q = p.point_in_lidar_m();
        [p.frame as f64, q.x, q.y, q.z, p.weight_f64()]
    });
    frames.chain(surfaces).chain(points)
}

/// Header and payload words of the block of `window`, `scale` extracted at `poses`.
pub fn encode_block(
    window: u64,
    scale: u32,
    b: &FactorBlock,
    poses: &[Pose],
    fixed: &[bool],
    settings: &LmSettings,
) -> (BlockHeader, Vec<f64>) {
    let header = block_header(window, scale, b, poses, settings);
    let mut words = Vec::with_capacity(block_len(poses.len(), b.surfaces.len(), b.points.len()));
    words.extend(block_words(b, poses, fixed));
    (header, words)
}

fn positive(value: f64, field: &'static str) -> Result<f64, MsgError> {
    if value.is_finite() && value > 0.0 {
        Ok(value)
    } else {
        Err(MsgError::OutOfRange {
            message: MESSAGE,
            field,
            value,
            index: 0,
        })
    }
}

/// Validates and decodes a factor block read from shared memory.
pub fn decode_block(header: &BlockHeader, words: &[f64]) -> Result<BlockMessage, MsgError> {
    let frame_words = checked_words(
        MESSAGE,
        "frame_count",
        header.frame_count,
        FRAME_WORDS,
        MAX_FRAMES,
    )?;
    let surface_words = checked_words(
        MESSAGE,
        "surface_count",
        header.surface_count,
        SURFACE_WORDS,
        MAX_ITEMS,
    )?;
    let point_words = checked_words(
        MESSAGE,
        "point_count",
        header.point_count,
        POINT_WORDS,
        MAX_ITEMS,
    )?;
    expect_len(
        MESSAGE,
        &[frame_words, surface_words, point_words],
        words.len(),
    )?;
    let gamma_m = positive(header.gamma_m, "gamma_m")?;
    let robust_scale_m = positive(header.robust_scale_m, "robust_scale_m")?;
    let initial_lambda = positive(header.initial_lambda, "initial_lambda")?;
    for (value, field) in [
        (header.prior_translation_m, "prior_translation_m"),
        (header.prior_rotation_rad, "prior_rotation_rad"),
        (header.motion_translation_m, "motion_translation_m"),
        (header.motion_rotation_rad, "motion_rotation_rad"),
    ] {
        // Infinite means "no prior"; NaN and non-positive values are refused.
        if value.is_nan() || value <= 0.0 {
            return Err(MsgError::OutOfRange {
                message: MESSAGE,
                field,
                value,
                index: 0,
            });
        }
    }
    if header.max_iterations > 10_000 {
        return Err(MsgError::TooLarge {
            message: MESSAGE,
            field: "max_iterations",
            value: header.max_iterations,
            limit: 10_000,
        });
    }
    let mut reader = WordReader::new(MESSAGE, words);
    let mut poses = Vec::with_capacity(header.frame_count as usize);
    let mut fixed = Vec::with_capacity(header.frame_count as usize);
    for k in 0..header.frame_count {
        let pose = PoseMsg::from_words(reader.finite(PoseMsg::WORDS, "pose", k)?);
        poses.push(pose.to_pose(MESSAGE, k)?);
        fixed.push(reader.index(2, "fixed", k)? == 1);
    }
    let mut surfaces = Vec::with_capacity(header.surface_count as usize);
    let mut points_per_surface = Vec::with_capacity(header.surface_count as usize);
    let mut points_claimed = 0u64;
    for i in 0..header.surface_count {
        let frame = reader.index(header.frame_count, "surface frame", i)? as usize;
        let kernel = reader.finite(3, "kernel_in_lidar", i)?;
        let tangent = reader.finite(9, "tangent_from_lidar", i)?;
        let coefficients = reader.finite(6, "coefficients", i)?;
        let surface_gamma_m = reader.finite(1, "surface gamma_m", i)?[0];
        let count = reader.index(header.point_count + 1, "surface point count", i)?;
        points_claimed += count;
        points_per_surface.push(count);
        let mut poly = [0.0; 6];
        poly.copy_from_slice(coefficients);
        surfaces.push(Surface {
            frame,
            kernel_in_lidar: Vector3::from_column_slice(kernel),
            tangent_from_lidar: Matrix3::from_row_slice(tangent),
            polynomial: Polynomial { coefficients: poly },
            gamma_m: surface_gamma_m,
        });
    }
    if points_claimed != header.point_count {
        return Err(MsgError::OutOfRange {
            message: MESSAGE,
            field: "surface point counts (sum)",
            value: points_claimed as f64,
            index: 0,
        });
    }
    let mut points = Vec::with_capacity(header.point_count as usize);
    let mut j = 0u64;
    for (surface, &count) in points_per_surface.iter().enumerate() {
        for _ in 0..count {
            let frame = reader.index(header.frame_count, "point frame", j)? as u32;
            let point = reader.finite(3, "point_in_lidar", j)?;
            if let Some(&value) = point.iter().find(|v| v.abs() > f64::from(f32::MAX)) {
                // Held in f32 (see FactorPoint): beyond its range it would turn infinite.
                return Err(MsgError::OutOfRange {
                    message: MESSAGE,
                    field: "point_in_lidar",
                    value,
                    index: j,
                });
            }
            let weight = reader.finite(1, "weight", j)?[0];
            if !(0.0..=f64::from(f32::MAX)).contains(&weight) {
                return Err(MsgError::OutOfRange {
                    message: MESSAGE,
                    field: "weight",
                    value: weight,
                    index: j,
                });
            }
            points.push(FactorPoint::new(
                surface as u32,
                frame,
                Vector3::from_column_slice(point),
                weight,
            ));
            j += 1;
        }
    }
    Ok(BlockMessage {
        window: header.window,
        scale: header.scale,
        block: FactorBlock {
            gamma_m,
            robust_scale_m,
            surfaces,
            points,
            rejected: Default::default(),
        },
        poses,
        fixed,
        settings: LmSettings {
            max_iterations: header.max_iterations as usize,
            initial_lambda,
            prior_translation_m: header.prior_translation_m,
            prior_rotation_rad: header.prior_rotation_rad,
            motion_translation_m: header.motion_translation_m,
            motion_rotation_rad: header.motion_rotation_rad,
        },
    })
}
