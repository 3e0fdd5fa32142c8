//! The Levenberg-Marquardt damping that PSS-BA's solve of a factor block
//! ([`crate::lm::solve_block`], DESIGN step 8, paper section "Poses Adjustment") and the BALM
//! baseline's LM share: each linearisation solves `(H + lambda D) dx = -b` with the diagonal
//! damped relative to itself and floored ([`Damping`]); a step is applied as
//! `R <- Exp(dtheta) R`, `t <- t + dt` to the free frames and kept only if the cost drops
//! ([`damped_step`]); lambda shrinks 3x after a kept step and grows 10x after a refused one.
//! The callers keep what differs: the cost, the solver, the number of tries and when to stop
//! re-linearising (both measure the [`relative_decrease`]).

use crate::geometry::Pose;

/// Damping floor relative to the largest diagonal entry, so directions no residual observes
/// (a planar scene's in-plane slide, an empty frame) stay put instead of going singular.
pub const DIAGONAL_FLOOR: f64 = 1e-9;

/// The damping of one LM run: lambda, and the floor of the current linearisation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Damping {
    lambda: f64,
    floor: f64,
}

impl Damping {
    /// Damping `initial_lambda` (relative to the diagonal), before any linearisation.
    pub fn new(initial_lambda: f64) -> Self {
        Self {
            lambda: initial_lambda,
            floor: 0.0,
        }
    }

    /// Current lambda.
    pub fn lambda(&self) -> f64 {
        self.lambda
    }

    /// Sets the floor of a new linearisation from its diagonal entries (or their magnitudes):
    /// [`DIAGONAL_FLOOR`] times the largest (at least 1e-300).
    pub fn relinearised(&mut self, diagonal: impl Iterator<Item = f64>) {
        let max_diag = diagonal.fold(0.0f64, f64::max);
        self.floor = DIAGONAL_FLOOR * max_diag.max(1e-300);
    }

    /// A damped diagonal entry of a positive semi-definite H:
    /// `h + lambda max(h, floor) + floor`.
    pub fn damped(&self, h: f64) -> f64 {
        h + self.lambda * h.max(self.floor) + self.floor
    }

    /// A damped diagonal entry of an H that may be indefinite (BALM's second-order Hessian far
    /// from the optimum): `h + lambda max(|h|, floor) + floor`.
    pub fn damped_magnitude(&self, h: f64) -> f64 {
        h + self.lambda * h.abs().max(self.floor) + self.floor
    }

    /// After a kept step: lambda / 3, at least 1e-12.
    fn step_kept(&mut self) {
        self.lambda = (self.lambda / 3.0).max(1e-12);
    }

    /// After a refused step or a failed solve: lambda x 10.
    fn step_refused(&mut self) {
        self.lambda *= 10.0;
    }
}

/// A step that lowered the cost.
#[derive(Debug, Clone, PartialEq)]
pub struct KeptStep<T> {
    /// The poses after the step.
    pub poses: Vec<Pose>,
    /// The step (6 per free frame: rotation then translation).
    pub step: Vec<f64>,
    /// The cost at `poses`.
    pub cost: f64,
    /// The lambda it was solved with.
    pub lambda: f64,
    /// What the cost function returned besides the cost.
    pub extra: T,
}

/// One linearisation's damping loop: at most `tries` times, solve for a step at the current
/// damping (`solve`, `None` if the damped system cannot be solved), apply it to the free frames
/// of `poses` (`variable_of`: each frame's first parameter, `None` if held fixed) and evaluate
/// `cost_at` there, which returns the cost and anything else the caller wants back. The first
/// step whose cost is finite and below `cost` with all poses finite is kept. `None` if no
/// try lowered the cost.
pub fn damped_step<T>(
    damping: &mut Damping,
    tries: usize,
    poses: &[Pose],
    variable_of: &[Option<usize>],
    cost: f64,
    mut solve: impl FnMut(&Damping) -> Option<Vec<f64>>,
    mut cost_at: impl FnMut(&[Pose]) -> (f64, T),
) -> Option<KeptStep<T>> {
    for _ in 0..tries {
        let Some(step) = solve(damping) else {
            damping.step_refused();
            continue;
        };
        let candidate: Vec<Pose> = poses
            .iter()
            .enumerate()
            .map(|(k, pose)| match variable_of[k] {
                Some(v) => pose.perturbed(&step[v..v + 6]),
                None => *pose,
            })
            .collect();
        let (candidate_cost, extra) = cost_at(&candidate);
        if candidate_cost.is_finite()
            && candidate_cost < cost
            && candidate.iter().all(Pose::is_finite)
        {
            let lambda = damping.lambda;
            damping.step_kept();
            return Some(KeptStep {
                poses: candidate,
                step,
                cost: candidate_cost,
                lambda,
                extra,
            });
        }
        damping.step_refused();
    }
    None
}

/// The relative cost decrease of a linearisation, `(before - after) / before` (`before` at
/// least 1e-300), that decides whether re-linearising is worth it.
pub fn relative_decrease(before: f64, after: f64) -> f64 {
    (before - after) / before.max(1e-300)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solve::lm::variable_layout;

    fn poses(n: usize) -> Vec<Pose> {
        vec![Pose::from_isometry(&nalgebra::Isometry3::identity()); n]
    }

    #[test]
    fn floor_follows_the_largest_diagonal_entry() {
        let mut damping = Damping::new(1e-3);
        damping.relinearised([2.0, 8.0, 4.0].into_iter());
        assert_eq!(damping.damped(0.0), 1e-3 * 8e-9 + 8e-9);
        assert_eq!(damping.damped(4.0), 4.0 + 1e-3 * 4.0 + 8e-9);
        // Nothing on the diagonal: the floor stays positive.
        damping.relinearised(std::iter::empty());
        assert!(damping.damped(0.0) > 0.0);
    }

    #[test]
    fn magnitude_damping_differs_only_for_negative_entries() {
        let mut damping = Damping::new(0.5);
        damping.relinearised([1.0].into_iter());
        for h in [0.0, 1e-12, 0.3, 7.0] {
            assert_eq!(damping.damped(h), damping.damped_magnitude(h));
        }
        assert_eq!(damping.damped_magnitude(-2.0), -2.0 + 0.5 * 2.0 + 1e-9);
        assert_eq!(damping.damped(-2.0), -2.0 + 0.5 * 1e-9 + 1e-9);
    }

    #[test]
    fn refused_tries_raise_lambda_and_a_kept_step_lowers_it() {
        let (variable_of, _) = variable_layout(&[true, false]);
        let start = poses(2);
        let mut damping = Damping::new(1e-3);
        let lambdas = std::cell::RefCell::new(Vec::new());
        // The solve fails once, then the cost rises once, then it drops.
        let kept = damped_step(
            &mut damping,
            10,
            &start,
            &variable_of,
            1.0,
            |d| {
                lambdas.borrow_mut().push(d.lambda());
                (lambdas.borrow().len() > 1).then(|| vec![0.0, 0.0, 0.0, 0.1, 0.0, 0.0])
            },
            |candidate| {
                let cost = if lambdas.borrow().len() < 3 { 2.0 } else { 0.5 };
                (cost, candidate[1].translation.x)
            },
        )
        .expect("the third try lowers the cost");
        assert_eq!(*lambdas.borrow(), [1e-3, 1e-3 * 10.0, 1e-3 * 10.0 * 10.0]);
        assert_eq!(kept.lambda, 1e-3 * 10.0 * 10.0);
        assert_eq!(damping.lambda(), 1e-3 * 10.0 * 10.0 / 3.0);
        assert_eq!(kept.cost, 0.5);
        assert_eq!(kept.extra, 0.1);
        assert_eq!(kept.poses[0], start[0], "the fixed frame stays");
        assert_eq!(kept.poses[1].translation.x, 0.1);
    }

    #[test]
    fn gives_up_after_the_tries_and_keeps_lambda_above_its_floor() {
        let (variable_of, _) = variable_layout(&[false]);
        let mut damping = Damping::new(1.0);
        let no_step = damped_step(
            &mut damping,
            3,
            &poses(1),
            &variable_of,
            1.0,
            |_| Some(vec![0.0; 6]),
            |_| (f64::NAN, ()),
        );
        assert!(no_step.is_none());
        assert_eq!(damping.lambda(), 1000.0);
        let mut damping = Damping::new(1e-12);
        let kept = damped_step(
            &mut damping,
            1,
            &poses(1),
            &variable_of,
            1.0,
            |_| Some(vec![0.0; 6]),
            |_| (0.0, ()),
        );
        assert!(kept.is_some());
        assert_eq!(damping.lambda(), 1e-12);
    }

    #[test]
    fn relative_decrease_of_a_zero_cost_is_finite() {
        assert_eq!(relative_decrease(4.0, 3.0), 0.25);
        assert_eq!(relative_decrease(0.0, 0.0), 0.0);
    }
}
