//! The validation of every shared-memory message kind, on headers and payloads of any bits:
//! frames, factor blocks, pose sets, window results, message parts, final poses and window
//! chunks. Any process of the same user can write these, so each must be refused with an
//! error, never a panic or an allocation sized from a claimed count.
#![no_main]
use libfuzzer_sys::arbitrary::{Result, Unstructured};
use libfuzzer_sys::fuzz_target;
use pssba_client::windows::{ChunkHeader, checked};
use pssba_msg::{BlockHeader, IsometryMsg, Parts, PointXyz, PoseMsg, ResultHeader};
use pssba_msg::{FrameHeader, Reassembly};

fn isometry(u: &mut Unstructured) -> Result<IsometryMsg> {
    Ok(IsometryMsg {
        quaternion_xyzw: u.arbitrary()?,
        translation_m: u.arbitrary()?,
    })
}

fn parts(u: &mut Unstructured) -> Result<Parts> {
    Ok(Parts {
        message_id: u.arbitrary()?,
        index: u.arbitrary()?,
        count: u.arbitrary()?,
        offset_words: u.arbitrary()?,
        total_words: u.arbitrary()?,
    })
}

fn words(u: &mut Unstructured) -> Result<Vec<f64>> {
    let n = u.int_in_range(0..=4096usize)?;
    (0..n).map(|_| u.arbitrary::<f64>()).collect()
}

fn run(u: &mut Unstructured) -> Result<()> {
    match u.int_in_range(0..=6u8)? {
        0 => {
            let n = u.int_in_range(0..=256usize)?;
            let header = FrameHeader {
                sequence: u.arbitrary()?,
                stamp_s: u.arbitrary()?,
                world_from_lidar: isometry(u)?,
                ground_truth: isometry(u)?,
                has_ground_truth: u.arbitrary()?,
                end_of_stream: u.arbitrary()?,
                sent_unix_ns: u.arbitrary()?,
                // Mostly the versions a consumer reads, with times for some of the points.
                layout_version: match u.int_in_range(0..=3u8)? {
                    0 => 1,
                    1 | 2 => 2,
                    _ => u.arbitrary()?,
                },
                timed_points: if u.arbitrary()? {
                    u.int_in_range(0..=n as u32)?
                } else {
                    u.arbitrary()?
                },
            };
            let points: Vec<PointXyz> = (0..n)
                .map(|_| Ok(PointXyz { xyz_m: u.arbitrary()? }))
                .collect::<Result<_>>()?;
            let _ = pssba_client::frames::check_frame(&header, u.arbitrary()?, &points);
        }
        1 => {
            let header = BlockHeader {
                kind: u.arbitrary()?,
                scale: u.arbitrary()?,
                window: u.arbitrary()?,
                frame_count: u.arbitrary()?,
                surface_count: u.arbitrary()?,
                point_count: u.arbitrary()?,
                gamma_m: u.arbitrary()?,
                robust_scale_m: u.arbitrary()?,
                max_iterations: u.arbitrary()?,
                initial_lambda: u.arbitrary()?,
                prior_translation_m: u.arbitrary()?,
                prior_rotation_rad: u.arbitrary()?,
                motion_translation_m: u.arbitrary()?,
                motion_rotation_rad: u.arbitrary()?,
                parts: parts(u)?,
            };
            let _ = pssba_msg::decode_block(&header, &words(u)?);
        }
        2 => {
            let pose = PoseMsg {
                rotation: u.arbitrary()?,
                translation_m: u.arbitrary()?,
            };
            let _ = pose.to_pose("pose set", 0);
        }
        3 => {
            let header = ResultHeader {
                kind: u.arbitrary()?,
                converged: u.arbitrary()?,
                window: u.arbitrary()?,
                final_count: u.arbitrary()?,
                revised_count: u.arbitrary()?,
                surface_count: u.arbitrary()?,
                map_point_count: u.arbitrary()?,
                scale_count: u.arbitrary()?,
                failed: u.arbitrary()?,
                error_bytes: u.arbitrary()?,
                frames_dropped: u.arbitrary()?,
                parts: parts(u)?,
            };
            let _ = pssba_msg::decode_result(&header, &words(u)?);
        }
        4 => {
            let mut reassembly = Reassembly::default();
            for _ in 0..u.int_in_range(1..=8u8)? {
                let payload = words(u)?;
                let _ = reassembly.push(parts(u)?, &payload, 1 << 16);
            }
        }
        5 => {
            let _ = isometry(u)?.to_isometry("final pose", 0);
        }
        _ => {
            let header = ChunkHeader {
                window: u.arbitrary()?,
                first_item: u.arbitrary()?,
                total_items: u.arbitrary()?,
                part: u.arbitrary()?,
                parts: u.arbitrary()?,
            };
            let _ = checked(&header, u.int_in_range(0..=1 << 20)?);
        }
    }
    Ok(())
}

fuzz_target!(|data: &[u8]| {
    let _ = run(&mut Unstructured::new(data));
});
