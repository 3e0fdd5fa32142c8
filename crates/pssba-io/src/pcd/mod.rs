//! PCD (Point Cloud Library) v0.7 files: reading x/y/z from any PCD and
//! writing x/y/z-only PCDs.
//!
//! The reader accepts `DATA ascii`, `binary` and `binary_compressed`, with
//! x, y, z stored as `TYPE F` of `SIZE` 4 or 8 (`COUNT 1`). Any other fields
//! (intensity, rgb, t, ring, ...; any TYPE I/U/F, SIZE 1/2/4/8, COUNT >= 1)
//! are skipped. Organised clouds (HEIGHT > 1) are returned row-major as a
//! flat list.
//!
//! [`read_pcd_with_times`] also reads a `time` field ([`TIME_FIELD`]), and
//! [`pcd_to_bytes_with_times`] writes one.
//!
//! **NaN and infinite coordinates are returned unchanged**: organised
//! clouds use NaN for missing returns, and filtering them is the caller's
//! job (so that it can report how many there were).

mod header;
mod read;
mod write;

pub use read::{
    pcd_point_count, read_pcd, read_pcd_from_bytes, read_pcd_with_times,
    read_pcd_with_times_from_bytes,
};
pub use write::{pcd_to_bytes, pcd_to_bytes_with_times, write_pcd, write_pcd_with_precision};

/// The field of a dataset frame's point times: `TYPE F`, `SIZE 4`, seconds after the frame's
/// stamp (its `poses.txt` stamp), the instant its pose describes.
pub const TIME_FIELD: &str = "time";

/// A frame's points and, when its file has a `time` field, each point's time (s).
pub type TimedPoints = (Vec<nalgebra::Point3<f64>>, Option<Vec<f32>>);

/// How a PCD data section is stored (the header's `DATA` key).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PcdEncoding {
    /// Text, one point per line, values separated by whitespace.
    Ascii,
    /// Packed little-endian records, one per point.
    Binary,
    /// LZF-compressed, field-by-field (column-major) little-endian values.
    BinaryCompressed,
}

impl PcdEncoding {
    /// The header spelling: `ascii`, `binary` or `binary_compressed`.
    pub fn as_str(self) -> &'static str {
        match self {
            PcdEncoding::Ascii => "ascii",
            PcdEncoding::Binary => "binary",
            PcdEncoding::BinaryCompressed => "binary_compressed",
        }
    }
}

impl std::fmt::Display for PcdEncoding {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Floating-point width used when writing x, y, z.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum PcdPrecision {
    /// `SIZE 4` (f32): about 7 significant digits, i.e. ~0.01 mm at 100 m,
    /// ~1 mm at 10 km; what PCL and most tools write.
    #[default]
    F32,
    /// `SIZE 8` (f64): exact round-trip of the `f64` input.
    F64,
}

impl PcdPrecision {
    /// Bytes per value (4 or 8).
    pub fn size(self) -> usize {
        match self {
            PcdPrecision::F32 => 4,
            PcdPrecision::F64 => 8,
        }
    }
}
