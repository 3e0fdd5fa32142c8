//! BALM, the eigenvalue bundle-adjustment baseline (Liu et al. 2023, "Efficient and
//! Consistent Bundle Adjustment on Lidar Point Clouds", i.e. BALM2), as a pure library: no
//! files, no IPC, no CLI, no global thread pool (rayon only through [`Parallelism`]).
//!
//! Adaptive voxelisation of the world cloud ([`voxel`]) finds planar patches; each frame's
//! points in a patch are summarised by a point cluster ([`cluster`]); the cost is the sum over
//! plane voxels of `N lambda_min(covariance)`, minimised by Levenberg-Marquardt with its
//! closed-form gradient and second-order Hessian ([`derivatives`], [`lm`]). Frame 0 is held
//! fixed. See DESIGN.md section 3. Written from the paper; hku-mars/BALM was not copied.

pub mod cluster;
pub mod config;
pub mod derivatives;
pub mod error;
pub mod lm;
pub mod normal_equations;
pub mod pipeline;
pub mod result;
pub mod voxel;

pub use config::BalmConfig;
pub use error::BalmError;
pub use pipeline::adjust;
pub use pssba_core::Parallelism;
pub use result::{BalmResult, LmIterationReport, OuterReport};
