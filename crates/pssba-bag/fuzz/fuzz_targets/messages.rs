//! Every message decoder on arbitrary bytes, in both wire formats: the first byte picks the
//! decoder and the wire, the rest is the message. Errors are expected; panics, hangs and
//! unbounded allocations are bugs.
#![no_main]

use libfuzzer_sys::fuzz_target;
use pssba_bag::msg::{self, Kind, Wire};

fuzz_target!(|data: &[u8]| {
    let Some((&selector, body)) = data.split_first() else {
        return;
    };
    let wire = if selector & 1 == 0 { Wire::Ros1 } else { Wire::Cdr };
    match (selector >> 1) % 6 {
        0 => drop(msg::decode_cloud(Kind::PointCloud2, body, wire, &msg::PointTimeChoice::Auto)),
        1 => drop(msg::decode_cloud(Kind::LivoxCustom, body, wire, &msg::PointTimeChoice::Auto)),
        2 => drop(msg::decode_pose(Kind::Odometry, body, wire)),
        3 => drop(msg::decode_pose(Kind::PoseStamped, body, wire)),
        4 => drop(msg::decode_tf(body, wire)),
        _ => {
            drop(msg::peek_cloud(Kind::PointCloud2, body, wire));
            drop(msg::peek_cloud(Kind::LivoxCustom, body, wire));
        }
    }
});
