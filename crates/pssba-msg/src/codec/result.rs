//! Finished windows in shared memory (smooth -> record). Payload: `[f64]` words in this order:
//! - per finalised frame (`final_count`): sequence, stamp (s), pose `[R row-major (9), t (3)]`;
//! - per world surface (`surface_count`): frame sequence, kernel point in world (3),
//!   tangent_from_world row-major (9), coefficients a0..a5 (6), gamma (m);
//! - per map point (`map_point_count`): x, y, z in world (m);
//! - per scale report (`scale_count`): [`REPORT_WORDS`] values in [`ScaleReport`] field order,
//!   the five rejection counts and the four phase times spelled out;
//! - when the window failed (`failed` = 1), the failure message: `error_bytes` UTF-8 bytes,
//!   one per word.

use crate::codec::block::{MAX_FRAMES, MAX_ITEMS};
use crate::codec::words::{WordReader, checked_words, expect_len};
use crate::error::MsgError;
use crate::internal::types::{PoseMsg, ResultHeader, result_kind};
use nalgebra::{Matrix3, Point3};
use pssba_core::factor::KernelRejections;
use pssba_core::{PhaseTimes, ScaleReport, WorldSurface};

const MESSAGE: &str = "window result";
const FINAL_WORDS: usize = 2 + PoseMsg::WORDS;
const SURFACE_WORDS: usize = 20;
const REPORT_WORDS: usize = 19;
/// Longest failure message carried (bytes); a longer one is cut at a character boundary.
pub const MAX_ERROR_BYTES: usize = 4096;

pub use crate::public::types::FinalPose;

/// One finished window.
#[derive(Debug, Clone, PartialEq)]
pub struct WindowResult {
    /// Window index.
    pub window: u64,
    /// True if the schedule reached T_conv.
    pub converged: bool,
    /// Frames finalised by this window, in sequence order.
    pub finals: Vec<FinalPose>,
    /// Frames finalised by earlier windows whose final pose this window's loop closure moved,
    /// with their new poses, in sequence order.
    pub revised: Vec<FinalPose>,
    /// Last scale's surfaces in the world; `frame` holds the frame's sequence number.
    pub surfaces: Vec<WorldSurface>,
    /// Smoothed cloud (world, m).
    pub map: Vec<Point3<f64>>,
    /// One report per scale.
    pub scales: Vec<ScaleReport>,
    /// Why the window's adjustment failed (its frames in `finals` then kept their corrected
    /// initial poses); `None` when it succeeded.
    pub failure: Option<String>,
    /// Frames the smooth stage had dropped when this window ended (live input, policy `drop`).
    pub frames_dropped: u64,
}

fn error_text(result: &WindowResult) -> &str {
    let Some(text) = result.failure.as_deref() else {
        return "";
    };
    let mut end = text.len().min(MAX_ERROR_BYTES);
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    &text[..end]
}

fn report_words(r: &ScaleReport) -> [f64; REPORT_WORDS] {
    let k = &r.kernels_rejected;
    [
        r.gamma_m,
        r.cloud_points as f64,
        r.kernels_used as f64,
        k.no_normal as f64,
        k.too_few_points as f64,
        k.ill_conditioned as f64,
        k.too_rough as f64,
        k.single_frame as f64,
        r.residuals as f64,
        r.cost_before,
        r.cost_after,
        r.iterations as f64,
        r.pose_change,
        r.unconstrained_frames as f64,
        r.wall_time_s,
        r.times.cloud_s,
        r.times.normals_s,
        r.times.extract_s,
        r.times.solve_s,
    ]
}

/// Header and payload words of `result` (`kind` = [`result_kind::WINDOW`]).
pub fn encode_result(result: &WindowResult) -> (ResultHeader, Vec<f64>) {
    let header = ResultHeader {
        kind: result_kind::WINDOW,
        converged: u32::from(result.converged),
        window: result.window,
        final_count: result.finals.len() as u64,
        revised_count: result.revised.len() as u64,
        surface_count: result.surfaces.len() as u64,
        map_point_count: result.map.len() as u64,
        scale_count: result.scales.len() as u64,
        failed: u32::from(result.failure.is_some()),
        error_bytes: error_text(result).len() as u32,
        frames_dropped: result.frames_dropped,
        ..ResultHeader::default()
    };
    let mut words = Vec::new();
    for f in result.finals.iter().chain(&result.revised) {
        words.extend_from_slice(&[f.sequence as f64, f.stamp_s]);
        words.extend_from_slice(&PoseMsg::from_isometry(&f.world_from_lidar).words());
    }
    for s in &result.surfaces {
        words.push(s.frame as f64);
        words.extend_from_slice(s.kernel_in_world.coords.as_slice());
        words.extend_from_slice(s.tangent_from_world.transpose().as_slice());
        words.extend_from_slice(&s.coefficients);
        words.push(s.gamma_m);
    }
    for p in &result.map {
        words.extend_from_slice(p.coords.as_slice());
    }
    for r in &result.scales {
        words.extend_from_slice(&report_words(r));
    }
    words.extend(error_text(result).bytes().map(f64::from));
    (header, words)
}

/// `count` final poses: sequence, stamp and pose words each.
fn read_finals(reader: &mut WordReader<'_>, count: u64) -> Result<Vec<FinalPose>, MsgError> {
    let mut finals = Vec::with_capacity(count as usize);
    for k in 0..count {
        let sequence = reader.index(u64::MAX, "sequence", k)?;
        let stamp_s = reader.finite(1, "stamp", k)?[0];
        let pose = PoseMsg::from_words(reader.finite(PoseMsg::WORDS, "pose", k)?);
        let world_from_lidar = pose.to_pose(MESSAGE, k)?.to_isometry();
        finals.push(FinalPose {
            sequence,
            stamp_s,
            world_from_lidar,
        });
    }
    Ok(finals)
}

/// Validates and decodes a window result read from shared memory.
pub fn decode_result(header: &ResultHeader, words: &[f64]) -> Result<WindowResult, MsgError> {
    if header.kind != result_kind::WINDOW {
        return Err(MsgError::OutOfRange {
            message: MESSAGE,
            field: "kind",
            value: f64::from(header.kind),
            index: 0,
        });
    }
    let parts = [
        checked_words(
            MESSAGE,
            "final_count",
            header.final_count,
            FINAL_WORDS,
            MAX_FRAMES,
        )?,
        checked_words(
            MESSAGE,
            "revised_count",
            header.revised_count,
            FINAL_WORDS,
            MAX_FRAMES,
        )?,
        checked_words(
            MESSAGE,
            "surface_count",
            header.surface_count,
            SURFACE_WORDS,
            MAX_ITEMS,
        )?,
        checked_words(
            MESSAGE,
            "map_point_count",
            header.map_point_count,
            3,
            MAX_ITEMS,
        )?,
        checked_words(
            MESSAGE,
            "scale_count",
            header.scale_count,
            REPORT_WORDS,
            1 << 16,
        )?,
        checked_words(
            MESSAGE,
            "error_bytes",
            u64::from(header.error_bytes),
            1,
            MAX_ERROR_BYTES as u64,
        )?,
    ];
    expect_len(MESSAGE, &parts, words.len())?;
    let mut reader = WordReader::new(MESSAGE, words);
    let finals = read_finals(&mut reader, header.final_count)?;
    let revised = read_finals(&mut reader, header.revised_count)?;
    let mut surfaces = Vec::with_capacity(header.surface_count as usize);
    for i in 0..header.surface_count {
        let frame = reader.index(u64::MAX, "surface frame", i)? as usize;
        let kernel = reader.finite(3, "kernel_in_world", i)?;
        let tangent = reader.finite(9, "tangent_from_world", i)?;
        let mut coefficients = [0.0; 6];
        coefficients.copy_from_slice(reader.finite(6, "coefficients", i)?);
        let gamma_m = reader.finite(1, "gamma_m", i)?[0];
        surfaces.push(WorldSurface {
            frame,
            kernel_in_world: Point3::new(kernel[0], kernel[1], kernel[2]),
            tangent_from_world: Matrix3::from_row_slice(tangent),
            coefficients,
            gamma_m,
        });
    }
    let mut map = Vec::with_capacity(header.map_point_count as usize);
    for i in 0..header.map_point_count {
        let p = reader.finite(3, "map point", i)?;
        map.push(Point3::new(p[0], p[1], p[2]));
    }
    let mut scales = Vec::with_capacity(header.scale_count as usize);
    for i in 0..header.scale_count {
        let mut w = [0.0; REPORT_WORDS];
        for (slot, field) in w.iter_mut().zip(0..REPORT_WORDS) {
            *slot = reader.any()?;
            // Costs may be NaN (no residual); counts must be whole and non-negative.
            let is_count = matches!(field, 1..=8 | 11 | 13);
            if is_count && !(slot.is_finite() && *slot >= 0.0 && slot.fract() == 0.0) {
                return Err(MsgError::OutOfRange {
                    message: MESSAGE,
                    field: "scale report count",
                    value: *slot,
                    index: i,
                });
            }
        }
        scales.push(ScaleReport {
            gamma_m: w[0],
            cloud_points: w[1] as usize,
            kernels_used: w[2] as usize,
            kernels_rejected: KernelRejections {
                no_normal: w[3] as usize,
                too_few_points: w[4] as usize,
                ill_conditioned: w[5] as usize,
                too_rough: w[6] as usize,
                single_frame: w[7] as usize,
            },
            residuals: w[8] as usize,
            cost_before: w[9],
            cost_after: w[10],
            iterations: w[11] as usize,
            pose_change: w[12],
            unconstrained_frames: w[13] as usize,
            wall_time_s: w[14],
            times: PhaseTimes {
                cloud_s: w[15],
                normals_s: w[16],
                extract_s: w[17],
                solve_s: w[18],
            },
        });
    }
    let mut error = Vec::with_capacity(header.error_bytes as usize);
    for i in 0..u64::from(header.error_bytes) {
        error.push(reader.index(256, "error byte", i)? as u8);
    }
    let failure = match header.failed {
        0 => None,
        1 => Some(String::from_utf8_lossy(&error).into_owned()),
        other => {
            return Err(MsgError::OutOfRange {
                message: MESSAGE,
                field: "failed",
                value: f64::from(other),
                index: 0,
            });
        }
    };
    Ok(WindowResult {
        window: header.window,
        converged: header.converged != 0,
        finals,
        revised,
        surfaces,
        map,
        scales,
        failure,
        frames_dropped: header.frames_dropped,
    })
}
