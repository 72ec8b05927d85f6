//! Certified plan reuse: apply the previous plan's shifted tail instead of solving (10)
//! again, when it is feasible for this step's exact constraints *and* provably within a
//! stated cost tolerance of this step's optimum.
//!
//! # Why this method
//! In a receding horizon the previous optimum, shifted one step, is often still feasible
//! and nearly optimal: a vehicle cruising at its reference speed, or following a leader
//! that does what the last plan assumed. Solving again then buys a cost improvement far
//! below anything the vehicle can feel, at the price of 5–10 interior-point iterations.
//! Feasibility alone is not enough to skip the solve: when the gap ahead opens the
//! shifted plan stays feasible forever while the optimum speeds up, and a planner that
//! kept the old plan would never accelerate. So a reused plan must also carry a
//! *certificate of near-optimality*.
//!
//! The certificate is Lagrangian duality. For any multipliers λ ≥ 0 of (10)'s
//! constraints g_i(v) ≤ 0, the dual function
//!
//! q(λ) = min over all v ∈ ℝᴺ of L(v, λ) = J(v) + Σ λ_i g_i(v)
//!
//! is a lower bound on the optimum J* of (10) (weak duality). J is a convex quadratic and
//! every g_i is linear or, for safety, a convex quadratic in one speed plus a prefix sum,
//! so L is a convex quadratic whose Hessian is tridiagonal plus the rank-one term of the
//! target-position cost: one Newton step from any point lands on its exact minimiser, an
//! O(N) solve. The multipliers are the interior-point solver's duals from the last solve,
//! shifted one step per step since — the same guess the solver's own warm start uses.
//! If the shifted plan v̂ passes [`crate::planner::verify`] and
//!
//! J(v̂) − q(λ) ≤ tol · (1 + |J(v̂)|),
//!
//! then J(v̂) − J* ≤ tol · (1 + |J(v̂)|): the cost given up at this step is bounded by the
//! stated tolerance, whatever the data did. The check costs one evaluation of the
//! constraints and one tridiagonal solve, against 5–10 Newton systems for a solve.
//!
//! Safety does not rest on any of this: the reused plan is verified against the exact
//! constraints of this step exactly as a solved plan is (Theorem 1 needs only that). A
//! streak cap ([`ReusePolicy::max_age`]) forces a fresh solve every so often, so the
//! solver's warm start, and with it the duals that certify reuse, stay current.

use crate::banded::get;
use crate::mpc::{ConstraintKind, SingleLaneProblem};
use crate::real::Real;

/// When the planner may apply its previous plan, shifted, instead of solving.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ReusePolicy<F> {
    /// Certified relative sub-optimality allowed: a plan is reused only if
    /// J(v̂) − q(λ) ≤ `tolerance` · (1 + |J(v̂)|), so J(v̂) − J* is at most that.
    pub tolerance: F,
    /// Most consecutive steps without a solve; after that the planner solves again.
    pub max_age: u8,
}

impl<F: Real> Default for ReusePolicy<F> {
    /// 1 % of the cost, at most 4 steps in a row without a solve.
    fn default() -> Self {
        Self {
            tolerance: F::from_f64(1e-2),
            max_age: 4,
        }
    }
}

/// Multipliers of (10)'s five constraint families, one per step k (all ≥ 0).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Duals<F, const N: usize> {
    /// v_k ≤ hi_k.
    pub upper: [F; N],
    /// v_k ≥ lo_k.
    pub lower: [F; N],
    /// v_k − v_{k−1} ≤ amax h.
    pub accel: [F; N],
    /// v_k − v_{k−1} ≥ amin h.
    pub decel: [F; N],
    /// x_{k+1} + dS(v_k) ≤ x̄.
    pub safety: [F; N],
}

impl<F: Real, const N: usize> Duals<F, N> {
    /// The multipliers moved `steps` steps forward in time (the last one repeated), as
    /// the plan they belong to is shifted.
    pub fn shifted(&self, steps: usize) -> Self {
        let last = N.saturating_sub(1);
        let sh = |a: &[F; N]| -> [F; N] {
            core::array::from_fn(|k| get(a, k.saturating_add(steps).min(last)))
        };
        Self {
            upper: sh(&self.upper),
            lower: sh(&self.lower),
            accel: sh(&self.accel),
            decel: sh(&self.decel),
            safety: sh(&self.safety),
        }
    }

    fn of(&self, kind: ConstraintKind, k: usize) -> F {
        let a = match kind {
            ConstraintKind::SpeedUpper => &self.upper,
            ConstraintKind::SpeedLower => &self.lower,
            ConstraintKind::Accel => &self.accel,
            ConstraintKind::Decel => &self.decel,
            ConstraintKind::Safety => &self.safety,
        };
        get(a, k)
    }

    /// `true` if every multiplier is finite and ≥ 0 (weak duality needs λ ≥ 0).
    pub fn valid(&self) -> bool {
        [
            &self.upper,
            &self.lower,
            &self.accel,
            &self.decel,
            &self.safety,
        ]
        .iter()
        .all(|a| a.iter().all(|&x| x.is_finite() && x >= F::ZERO))
    }
}

/// L(v, λ) = J(v) + Σ λ_i g_i(v), evaluated with the problem's own cost and constraint
/// definitions (the solver-facing `hi`; see [`dual_bound`]).
pub fn lagrangian<F: Real, const N: usize>(
    pr: &SingleLaneProblem<F, N>,
    duals: &Duals<F, N>,
    v: &[F; N],
) -> F {
    let mut l = pr.objective(v);
    pr.for_each_constraint(v, |g, kind, k| {
        l += duals.of(kind, k) * g;
        true
    });
    l
}

/// ∇_v L at `v` (O(N): the safety constraints' prefix sums give suffix sums of λ).
fn gradient<F: Real, const N: usize>(
    pr: &SingleLaneProblem<F, N>,
    d: &Duals<F, N>,
    v: &[F; N],
) -> [F; N] {
    let w = pr.weights;
    let two = F::TWO;
    let pos: F = v.iter().fold(F::ZERO, |a, &x| a + x) * pr.h;
    let target_term = two * w.target_position * pr.h * (pr.target - pos);
    let mut out = [F::ZERO; N];
    // Suffix sum of the safety multipliers: v_j enters x_{k+1} for every k ≥ j.
    let mut suffix = F::ZERO;
    for j in (0..N).rev() {
        let vj = get(v, j);
        let prev = if j == 0 { pr.v_prev } else { get(v, j - 1) };
        // The smoothness term of step j + 1 (none past N − 1).
        let next = if j + 1 < N {
            get(v, j + 1) - vj
        } else {
            F::ZERO
        };
        suffix += get(&d.safety, j);
        let cost = two * w.reference_speed * (vj - pr.v_ref) + two * w.smoothness * (vj - prev)
            - two * w.smoothness * next
            - target_term;
        // v_j is v_{k−1} of step k = j + 1's acceleration constraints (none past N − 1:
        // `get` reads 0 there).
        let linear = get(&d.upper, j) - get(&d.lower, j) + get(&d.accel, j)
            - get(&d.decel, j)
            - get(&d.accel, j + 1)
            + get(&d.decel, j + 1);
        let safety = pr.h * suffix + get(&d.safety, j) * (pr.h + vj / pr.brake);
        if let Some(o) = out.get_mut(j) {
            *o = cost + linear + safety;
        }
    }
    out
}

/// Solves (T + u uᵀ) x = b for the SPD tridiagonal T (diagonal `diag`, off-diagonal
/// `off`) and u = `r`·1, by Thomas' algorithm and Sherman–Morrison. `None` if a pivot is
/// not positive (cannot happen for the Hessian of L, kept as a guard).
fn solve_tridiagonal_rank_one<F: Real, const N: usize>(
    diag: &[F; N],
    off: F,
    r: F,
    b: &[F; N],
) -> Option<[F; N]> {
    let mut c = [F::ZERO; N]; // modified super-diagonal
    let mut piv = [F::ZERO; N];
    for k in 0..N {
        let p = get(diag, k)
            - if k == 0 {
                F::ZERO
            } else {
                off * get(&c, k - 1)
            };
        if !(p > F::ZERO) {
            return None;
        }
        if let (Some(pk), Some(ck)) = (piv.get_mut(k), c.get_mut(k)) {
            *pk = p;
            *ck = off / p;
        }
    }
    let solve = |rhs: &[F; N]| -> [F; N] {
        let mut y = [F::ZERO; N];
        for k in 0..N {
            let prev = if k == 0 { F::ZERO } else { get(&y, k - 1) };
            if let Some(yk) = y.get_mut(k) {
                *yk = (get(rhs, k) - off * prev) / get(&piv, k);
            }
        }
        for k in (0..N.saturating_sub(1)).rev() {
            let next = get(&y, k + 1);
            if let Some(yk) = y.get_mut(k) {
                *yk -= get(&c, k) * next;
            }
        }
        y
    };
    let x = solve(b);
    // With r = 0 (no target-position cost) the correction below is exactly 0.
    let ones = [r; N];
    let z = solve(&ones);
    let dot = |a: &[F; N]| a.iter().fold(F::ZERO, |s, &x| s + x * r);
    let factor = dot(&x) / (F::ONE + dot(&z));
    Some(core::array::from_fn(|k| get(&x, k) - factor * get(&z, k)))
}

/// q(λ) = min over v of L(v, λ): a lower bound on the optimum of (10) for any λ ≥ 0.
///
/// One Newton step from `at` reaches the minimiser (L is quadratic in v). Its Hessian is
/// the sum of 2 w_v I, 2 w_Δ (tridiagonal second difference, last step without
/// successor), diag(λ^safety_k / |amin|) and 2 w_x h² 11ᵀ. The bound is of the problem as the
/// solver sees it (`hi`, widened by [`crate::mpc::PIN_WIDTH`] where V^k_t is a point);
/// that problem's feasible set contains the exact one's, so the bound holds for the exact
/// (10) too. `None` if the duals are invalid or the Hessian not positive definite.
pub fn dual_bound<F: Real, const N: usize>(
    pr: &SingleLaneProblem<F, N>,
    duals: &Duals<F, N>,
    at: &[F; N],
) -> Option<F> {
    if !duals.valid() {
        return None;
    }
    let w = pr.weights;
    let two = F::TWO;
    let diag: [F; N] = core::array::from_fn(|k| {
        let second = if k + 1 < N { two } else { F::ONE };
        two * w.reference_speed + two * w.smoothness * second + get(&duals.safety, k) / pr.brake
    });
    let off = -two * w.smoothness;
    let r = (two * w.target_position).sqrt() * pr.h;
    let grad = gradient(pr, duals, at);
    let step = solve_tridiagonal_rank_one(&diag, off, r, &grad)?;
    let v: [F; N] = core::array::from_fn(|k| get(at, k) - get(&step, k));
    let q = lagrangian(pr, duals, &v);
    q.is_finite().then_some(q)
}

/// The certified sub-optimality J(v̂) − q(λ) of a feasible plan `v̂`, if λ gives a bound.
pub fn certified_gap<F: Real, const N: usize>(
    pr: &SingleLaneProblem<F, N>,
    duals: &Duals<F, N>,
    plan: &[F; N],
) -> Option<F> {
    let q = dual_bound(pr, duals, plan)?;
    let gap = pr.objective(plan) - q;
    gap.is_finite().then_some(gap)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The tridiagonal-plus-rank-one solve against a dense Gaussian elimination.
    #[test]
    fn tridiagonal_rank_one_solve_matches_dense() {
        const N: usize = 5;
        let diag = [4.0, 5.0, 3.5, 6.0, 2.5];
        let (off, r) = (-1.2, 0.7);
        let b = [1.0, -2.0, 0.5, 3.0, -1.5];
        let x = solve_tridiagonal_rank_one(&diag, off, r, &b).unwrap();
        let a: [[f64; N]; N] = core::array::from_fn(|i| {
            core::array::from_fn(|j| {
                r * r
                    + if i == j {
                        diag[i]
                    } else if i.abs_diff(j) == 1 {
                        off
                    } else {
                        0.0
                    }
            })
        });
        for (i, row) in a.iter().enumerate() {
            let ax: f64 = row.iter().zip(x.iter()).map(|(a, x)| a * x).sum();
            assert!((ax - b[i]).abs() < 1e-12, "row {i}: {ax} vs {}", b[i]);
        }
        // Without the rank-one term.
        let y = solve_tridiagonal_rank_one(&diag, off, 0.0, &b).unwrap();
        for i in 0..N {
            let prev = if i > 0 { off * y[i - 1] } else { 0.0 };
            let next = if i + 1 < N { off * y[i + 1] } else { 0.0 };
            assert!((prev + diag[i] * y[i] + next - b[i]).abs() < 1e-12);
        }
    }

    /// A pivot that is not positive (a matrix that is not positive definite) is refused.
    #[test]
    fn a_singular_matrix_is_refused() {
        assert!(solve_tridiagonal_rank_one(&[0.0, 1.0], 0.5, 0.0, &[1.0, 1.0]).is_none());
        assert!(solve_tridiagonal_rank_one(&[1.0, 1.0], 1.0, 0.0, &[1.0, 1.0]).is_none());
        assert!(solve_tridiagonal_rank_one(&[1.0, -1.0], 0.0, 0.0, &[1.0, 1.0]).is_none());
    }
}
