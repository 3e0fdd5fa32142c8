//! Cost, gradient and Hessian of one plane voxel, `lambda_min(S)` with `S` the scatter of all
//! its points (BALM2: the voxel cost `N lambda_min(A)`, `A = S / N`), with respect to the
//! left perturbations `R_i <- Exp(theta_i) R_i`, `t_i <- t_i + dt_i` of each frame seen,
//! `x_i = [theta_i (rad); dt_i (m)]`. Closed form from the point clusters only.
//!
//! With the voxel centroid `c` as origin (so the summed points vanish at x = 0), frame i's
//! part of S is `Q_i = sum_j p_j p_j^T` and moves as `p_j <- Exp(theta)(p_j - t_i) + t_i + dt`.
//! BALM2's eigenvalue derivatives then read, with `u` the eigenvector of `lambda_min` and
//! `u_k, lambda_k` the other two:
//! - gradient: `d lambda = u^T dS u` (first-order eigenvalue perturbation);
//! - Hessian: `u^T d2S u + 2 sum_k (u_k^T dS u)^2 / (lambda - lambda_k)`, the second term
//!   being the eigenvector-derivative part; `d2S` holds the per-frame second derivative of
//!   `Q_i` and the cross-frame term `-(ds ds^T) / N` of the centroid.
//!
//! Per frame (`n` points, world mean `mu` relative to c, scatter `W`, lever `r = R mean_lidar`,
//! `M = W + n r r^T`, `B = W + n r mu^T`):
//! - gradient `[2 (B u) x u ; 2 n (mu.u) u]`;
//! - own block `[[-(U^T V + V^T U) + 2 U^T M U, 2 n (r x u) u^T], [.., 2 n u u^T]]`,
//!   `U = [u]x`, `V = [B u]x`;
//! - low-rank parts over all frames: `-2/N h h^T` with `h_i = [n (r x u); n u]` and
//!   `2/(lambda - lambda_k) c_k c_k^T` with
//!   `c_k,i = [(B u) x u_k + (B u_k) x u ; n (mu.u) u_k + n (mu.u_k) u]`.

use crate::cluster::{PointCluster, WorldCluster, combined_scatter, sorted_eigen};
use nalgebra::{Matrix3, Matrix6, Matrix6x3, Vector3, Vector6};
use pssba_core::geometry::{Pose, skew};

/// The world clusters of a voxel at `poses`.
pub fn world_clusters(clusters: &[(usize, PointCluster)], poses: &[Pose]) -> Vec<WorldCluster> {
    clusters
        .iter()
        .map(|(frame, cluster)| cluster.in_world(&poses[*frame]))
        .collect()
}

/// Voxel cost `lambda_min(S)` (m^2): the sum of squared point-to-plane distances.
pub fn voxel_cost(clusters: &[(usize, PointCluster)], poses: &[Pose]) -> f64 {
    let (_, _, scatter) = combined_scatter(&world_clusters(clusters, poses));
    sorted_eigen(&scatter).0[0].max(0.0)
}

/// Derivatives of one voxel's cost; the Hessian is kept in its structured form
/// `blockdiag(own) + sum_r weight_r L_r L_r^T` (never a dense 6F x 6F matrix).
#[derive(Debug, Clone, PartialEq)]
pub struct VoxelDerivatives {
    /// `lambda_min(S)` (m^2).
    pub cost: f64,
    /// Per cluster, d cost / d x_i.
    pub gradient: Vec<Vector6<f64>>,
    /// Per cluster, its own 6x6 block of `u^T d2S u` (without the centroid term).
    pub own_blocks: Vec<Matrix6<f64>>,
    /// Per cluster, the three low-rank vectors `[h_i, c_1,i, c_2,i]` as columns.
    pub low_rank: Vec<Matrix6x3<f64>>,
    /// Weights of the three low-rank terms: `-2/N`, `2/(lambda - lambda_k)`.
    pub low_rank_weights: Vector3<f64>,
}

impl VoxelDerivatives {
    /// The 6x6 Hessian block between clusters `a` and `b`.
    pub fn block(&self, a: usize, b: usize) -> Matrix6<f64> {
        let low = self.low_rank[a]
            * Matrix3::from_diagonal(&self.low_rank_weights)
            * self.low_rank[b].transpose();
        if a == b {
            low + self.own_blocks[a]
        } else {
            low
        }
    }
}

/// Cost, gradient and Hessian of a voxel at `poses` (see the module doc for the formulas).
pub fn voxel_derivatives(clusters: &[(usize, PointCluster)], poses: &[Pose]) -> VoxelDerivatives {
    let world = world_clusters(clusters, poses);
    let (count, centroid, scatter) = combined_scatter(&world);
    let (values, vectors) = sorted_eigen(&scatter);
    let u: Vector3<f64> = vectors.column(0).into_owned();
    let others = [
        vectors.column(1).into_owned(),
        vectors.column(2).into_owned(),
    ];
    // Coincident eigenvalues make the eigenvector derivative undefined; drop that term.
    let gap_floor = 1e-12 * values[2].abs().max(f64::MIN_POSITIVE);
    let eigen_weight = |k: usize| {
        let gap = values[0] - values[k];
        if gap.abs() > gap_floor {
            2.0 / gap
        } else {
            0.0
        }
    };
    let low_rank_weights = Vector3::new(-2.0 / count, eigen_weight(1), eigen_weight(2));
    let skew_u = skew(&u);
    let mut gradient = Vec::with_capacity(world.len());
    let mut own_blocks = Vec::with_capacity(world.len());
    let mut low_rank = Vec::with_capacity(world.len());
    for cluster in &world {
        let n = cluster.count;
        let mu = cluster.mean_world - centroid;
        let r = cluster.lever_world;
        let m_matrix = cluster.scatter_world + r * r.transpose() * n;
        let b_matrix = cluster.scatter_world + r * mu.transpose() * n;
        let bu = b_matrix * u;
        let mu_u = mu.dot(&u);
        let mut g = Vector6::zeros();
        g.fixed_rows_mut::<3>(0).copy_from(&(2.0 * bu.cross(&u)));
        g.fixed_rows_mut::<3>(3).copy_from(&(2.0 * n * mu_u * u));
        gradient.push(g);

        let skew_bu = skew(&bu);
        let rot_rot = -(skew_u.transpose() * skew_bu + skew_bu.transpose() * skew_u)
            + 2.0 * skew_u.transpose() * m_matrix * skew_u;
        let rot_trans = 2.0 * n * r.cross(&u) * u.transpose();
        let mut own = Matrix6::zeros();
        own.fixed_view_mut::<3, 3>(0, 0).copy_from(&rot_rot);
        own.fixed_view_mut::<3, 3>(0, 3).copy_from(&rot_trans);
        own.fixed_view_mut::<3, 3>(3, 0)
            .copy_from(&rot_trans.transpose());
        own.fixed_view_mut::<3, 3>(3, 3)
            .copy_from(&(2.0 * n * u * u.transpose()));
        own_blocks.push(own);

        let mut columns = Matrix6x3::zeros();
        columns
            .fixed_view_mut::<3, 1>(0, 0)
            .copy_from(&(n * r.cross(&u)));
        columns.fixed_view_mut::<3, 1>(3, 0).copy_from(&(n * u));
        for (k, uk) in others.iter().enumerate() {
            let rot = bu.cross(uk) + (b_matrix * uk).cross(&u);
            let trans = n * mu_u * uk + n * mu.dot(uk) * u;
            columns.fixed_view_mut::<3, 1>(0, k + 1).copy_from(&rot);
            columns.fixed_view_mut::<3, 1>(3, k + 1).copy_from(&trans);
        }
        low_rank.push(columns);
    }
    VoxelDerivatives {
        cost: values[0].max(0.0),
        gradient,
        own_blocks,
        low_rank,
        low_rank_weights,
    }
}
