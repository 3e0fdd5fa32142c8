//! Factor blocks in shared memory (smooth -> adjust). Payload: `[f64]` words in this order:
//! - per window frame (`frame_count`): pose `[R row-major (9), t (3)]`, fixed flag (0/1);
//! - per surface (`surface_count`): frame, kernel point in that lidar frame (3),
//!   tangent_from_lidar row-major (9), coefficients a0..a5 (6), gamma (m);
//! - per residual point (`point_count`): surface, frame, point in lidar (3), weight.
//!
//! f64 throughout, so the adjust stage sees exactly what the in-process run sees.

use crate::error::MsgError;
use crate::types::{BlockHeader, PoseMsg, block_kind};
use crate::words::{WordReader, checked_words, expect_len};
use nalgebra::{Matrix3, Vector3};
use pssba_core::factor::{FactorBlock, FactorPoint, Surface};
use pssba_core::fit::Polynomial;
use pssba_core::geometry::Pose;
use pssba_core::lm::LmSettings;

const MESSAGE: &str = "factor block";
const FRAME_WORDS: usize = PoseMsg::WORDS + 1;
const SURFACE_WORDS: usize = 20;
const POINT_WORDS: usize = 6;
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

/// Header and payload words of the block of `window`, `scale` extracted at `poses`.
pub fn encode_block(
    window: u64,
    scale: u32,
    b: &FactorBlock,
    poses: &[Pose],
    fixed: &[bool],
    settings: &LmSettings,
) -> (BlockHeader, Vec<f64>) {
    let header = BlockHeader {
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
    };
    let mut words = Vec::with_capacity(
        poses.len() * FRAME_WORDS + b.surfaces.len() * SURFACE_WORDS + b.points.len() * POINT_WORDS,
    );
    for (pose, &fixed) in poses.iter().zip(fixed) {
        words.extend_from_slice(&PoseMsg::from_pose(pose).words());
        words.push(if fixed { 1.0 } else { 0.0 });
    }
    for s in &b.surfaces {
        words.push(s.frame as f64);
        words.extend_from_slice(s.kernel_in_lidar.as_slice());
        words.extend_from_slice(s.tangent_from_lidar.transpose().as_slice());
        words.extend_from_slice(&s.polynomial.coefficients);
        words.push(s.gamma_m);
    }
    for p in &b.points {
        words.extend_from_slice(&[p.surface as f64, p.frame as f64]);
        words.extend_from_slice(p.point_in_lidar.as_slice());
        words.push(p.weight);
    }
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
    for i in 0..header.surface_count {
        let frame = reader.index(header.frame_count, "surface frame", i)? as usize;
        let kernel = reader.finite(3, "kernel_in_lidar", i)?;
        let tangent = reader.finite(9, "tangent_from_lidar", i)?;
        let coefficients = reader.finite(6, "coefficients", i)?;
        let surface_gamma_m = reader.finite(1, "surface gamma_m", i)?[0];
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
    let mut points = Vec::with_capacity(header.point_count as usize);
    for j in 0..header.point_count {
        let surface = reader.index(header.surface_count, "point surface", j)? as u32;
        let frame = reader.index(header.frame_count, "point frame", j)? as u32;
        let point = reader.finite(3, "point_in_lidar", j)?;
        let weight = reader.finite(1, "weight", j)?[0];
        if weight < 0.0 {
            return Err(MsgError::OutOfRange {
                message: MESSAGE,
                field: "weight",
                value: weight,
                index: j,
            });
        }
        points.push(FactorPoint {
            surface,
            frame,
            point_in_lidar: Vector3::from_column_slice(point),
            weight,
        });
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
        },
    })
}
