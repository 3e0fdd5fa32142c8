//! The motion prior of one scale's LM (for inputs from odometry, set by the whole-flight
//! pipeline): each pair of consecutive frames, one of them free, keeps its relative pose near
//! its value at the start of the scale, `r = [Log(Z^T R_k^T R_k+1); R_k^T (t_k+1 - t_k) - t_z]`
//! over sigmas `[rotation; translation]` (the residual and Jacobians of [`pose_graph`]). Where
//! the scene constrains a direction, its residuals outweigh the prior; where it does not (open
//! ground: x, y, yaw), the frames keep the odometry's increments instead of sliding apart.

use crate::geometry::Pose;
use crate::solve::normal_equations::NormalEquations;
use crate::solve::pose_graph::{self, Edge, relative};
use nalgebra::Matrix6;

/// The prior's edges for one LM run.
#[derive(Debug, Clone)]
pub struct MotionPriorEdges {
    edges: Vec<Edge>,
}

impl MotionPriorEdges {
    /// Edges between consecutive frames with at least one free, measured at `start`; `None`
    /// when a sigma is infinite (the prior is off) or no pair has a free frame.
    pub fn new(
        start: &[Pose],
        variable_of: &[Option<usize>],
        translation_m: f64,
        rotation_rad: f64,
    ) -> Option<Self> {
        if !(translation_m.is_finite() && rotation_rad.is_finite()) {
            return None;
        }
        let mut information = Matrix6::zeros();
        for k in 0..3 {
            information[(k, k)] = 1.0 / (rotation_rad * rotation_rad);
            information[(k + 3, k + 3)] = 1.0 / (translation_m * translation_m);
        }
        let edges: Vec<Edge> = (1..start.len())
            .filter(|&k| variable_of[k - 1].is_some() || variable_of[k].is_some())
            .map(|k| Edge {
                from: k - 1,
                to: k,
                measured: relative(&start[k - 1], &start[k]),
                information,
            })
            .collect();
        (!edges.is_empty()).then_some(Self { edges })
    }

    /// The pairs of free-frame indices the prior couples (for the Hessian's pattern).
    pub fn free_pairs(&self, variable_of: &[Option<usize>]) -> Vec<(usize, usize)> {
        self.edges
            .iter()
            .filter_map(|e| Some((variable_of[e.from]? / 6, variable_of[e.to]? / 6)))
            .collect()
    }

    /// The prior's cost at `poses`.
    pub fn cost(&self, poses: &[Pose]) -> f64 {
        self.edges
            .iter()
            .map(|e| {
                let r = pose_graph::residual(e, poses);
                (r.transpose() * e.information * r)[0]
            })
            .sum()
    }

    /// Adds the prior to the normal equations at `poses`.
    pub fn add_to(&self, eq: &mut NormalEquations, poses: &[Pose], variable_of: &[Option<usize>]) {
        for edge in &self.edges {
            let r = pose_graph::residual(edge, poses);
            let (j_from, j_to) = pose_graph::jacobians(edge, poses);
            let ends = [
                (variable_of[edge.from], j_from),
                (variable_of[edge.to], j_to),
            ];
            for (row, j_row) in ends.iter().filter_map(|(v, j)| Some((v.as_ref()? / 6, j))) {
                let g = j_row.transpose() * edge.information * r;
                for (i, value) in g.iter().enumerate() {
                    eq.gradient[6 * row + i] += value;
                }
                for (col, j_col) in ends.iter().filter_map(|(v, j)| Some((v.as_ref()? / 6, j))) {
                    if row <= col {
                        let block = j_row.transpose() * edge.information * j_col;
                        eq.hessian.add(row, col, &block);
                    }
                }
            }
            eq.cost += (r.transpose() * edge.information * r)[0];
        }
    }
}
