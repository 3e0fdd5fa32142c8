//! The `pssba run` recording format, as its own library (dora's shape): MCAP with Foxglove
//! schemas, written through any `Write + Seek` ([`write::McapRecorder`]) and read back
//! ([`read::read_recording`]); the flight out of it, its final trajectory and map
//! ([`export`]). The record stage is a thin adapter around the writer; the
//! replay of a recording as frames is `pssba-source`'s `pssba_run` source.

mod error;
pub mod export;
pub mod read;
pub mod recover;
pub mod write;

pub use error::RecordingError;
pub use export::{FinalPose, VoxelMap, add_flight_to_map, final_trajectory};
pub use read::{
    Recording, WindowRecord, cloud_point_times, cloud_points, isometries, read_recording,
    read_recording_parts,
};
pub use recover::{Summarized, add_summaries, add_summary, has_summary};
pub use write::{
    KnownFrame, McapRecorder, TIME_FIELD, end_cut_file, existing_parts, part_path, topics,
};

/// Results of this crate.
pub type Result<T, E = RecordingError> = std::result::Result<T, E>;
