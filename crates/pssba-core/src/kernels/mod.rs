//! The smoothing kernels of one scale (DESIGN steps 4-7, paper section "Spatial Smoothing for
//! LiDAR Factor Extraction"): per kernel an L0-refined normal (eq. `normal`, [`l0`]), its
//! tangent frame ([`tangent`]), a weighted polynomial surface (eq. `polynomial`, [`fit`]) and
//! the residual points of other frames tied to it, anchored to one frame per group of frames
//! ([`anchors`], [`frame_set`]); [`smoothing`] runs them all and gathers the outcomes into a
//! [`FactorBlock`](crate::factor::FactorBlock) ([`block_assembly`]). [`smoothed`] gives the
//! outputs at the final poses: world surfaces and the smoothed cloud ("Points Smoothing").

pub(crate) mod anchors;
pub(crate) mod block_assembly;
pub mod fit;
pub(crate) mod frame_set;
pub(crate) mod l0;
pub(crate) mod smoothed;
pub(crate) mod smoothing;
pub(crate) mod tangent;
