//! Pose adjustment on one factor block (DESIGN steps 7-8, paper section "Poses Adjustment
//! using Polynomial Surface Constraints"): Levenberg-Marquardt over all free poses ([`lm`];
//! its damping loop, shared with the BALM baseline, in [`damping`]), the relative
//! point-to-surface residuals and their Jacobians ([`residual`]), the robust normal equations
//! ([`normal_equations`]) in 6 x 6 blocks per coupled frame pair ([`block_hessian`]), and the
//! damped linear solve ([`step_solver`]: dense or sparse Cholesky, [`dense_solve`],
//! [`sparse_solve`], or conjugate gradients, [`cg_solve`]). [`pose_graph`]: relative-pose
//! edges, for the motion prior within a window and the whole flight's keyframe graph.

pub(crate) mod block_hessian;
pub mod cg_solve;
pub(crate) mod damping;
pub(crate) mod dense_solve;
pub(crate) mod lm;
pub(crate) mod motion_prior;
pub(crate) mod normal_equations;
pub(crate) mod pose_graph;
pub(crate) mod residual;
pub(crate) mod sparse_solve;
pub(crate) mod step_solver;
