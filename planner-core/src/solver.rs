//! The embedded solver for (10): a primal-dual interior-point method (Mehrotra
//! predictor-corrector) whose Newton systems are pentadiagonal and solved in O(N).
//!
//! # Why this design
//! (10) is a small convex QCQP: N speeds, 4N linear inequalities and N convex quadratic
//! safety constraints. Written in the speeds, the safety constraint of step k depends on
//! the prefix sum h Σ_{j≤k} v_j, so its Jacobian is dense and every Newton system would
//! cost O(N³). In the prefix-sum variables z_k = Σ_{j≤k} v_j instead,
//! - v_k = z_k − z_{k−1} and v_k − v_{k−1} = z_k − 2 z_{k−1} + z_{k−2},
//! - x_{k+1} − x_t = h z_k,
//!
//! so every constraint and every cost term touches at most three consecutive variables.
//! The reduced Newton matrix P + Σ λ_i ∇²g_i + Σ (λ_i/s_i) ∇g_i ∇g_iᵀ is therefore
//! symmetric positive definite with bandwidth 2 and factorises in O(N) with no fill-in
//! ([`crate::banded`]). An interior-point method was preferred over ADMM because it
//! reaches 1e-10 accuracy in tens of iterations regardless of conditioning (ADMM needs
//! thousands for that), which the Clarabel cross-check demands; its iteration count
//! hardly grows with N. Warm start reuses the previous plan and duals, shifted one step.
//!
//! Every loop is bounded: the iteration cap is [`Settings::max_iter`].

use crate::banded::{get, Penta};
use crate::mpc::SingleLaneProblem;
use crate::real::Real;

/// `a[f][k]`, or 0 out of range.
#[inline(always)]
fn get2<F: Real, const N: usize>(a: &[[F; N]; FAMILIES], f: usize, k: usize) -> F {
    a.get(f).and_then(|r| r.get(k)).copied().unwrap_or(F::ZERO)
}

#[inline(always)]
fn set2<F: Real, const N: usize>(a: &mut [[F; N]; FAMILIES], f: usize, k: usize, x: F) {
    if let Some(slot) = a.get_mut(f).and_then(|r| r.get_mut(k)) {
        *slot = x;
    }
}

/// Number of constraint families (upper and lower speed, accel, decel, safety).
const FAMILIES: usize = 5;
const UPPER: usize = 0;
const LOWER: usize = 1;
const ACCEL: usize = 2;
const DECEL: usize = 3;
const SAFETY: usize = 4;

/// Solver settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings<F> {
    /// Iteration cap (the loop never runs longer).
    pub max_iter: u32,
    /// Stopping tolerance: primal residual (absolute, plus a rounding floor) and duality
    /// gap sᵀλ (relative to 1 + |J|).
    pub tol: F,
    /// Stopping tolerance of the dual residual, relative to its largest term.
    pub tol_dual: F,
    /// Fraction of the step to the boundary of the positive orthant (keeps s, λ > 0).
    pub step_fraction: F,
    /// Static regularisation added to the Newton matrix diagonal (guards factorisation
    /// against round-off when many constraints are active).
    pub regularization: F,
    /// Dynamic regularisation: smallest pivot relative to its diagonal entry
    /// (see [`Penta::factor`]).
    pub pivot_floor: F,
    /// Iterative-refinement passes per Newton solve, against the unregularised matrix
    /// (they undo the regularisation's perturbation; each costs O(N)).
    pub refinement_steps: u32,
}

impl<F: Real> Default for Settings<F> {
    fn default() -> Self {
        Self {
            max_iter: 60,
            tol: F::SOLVER_TOL,
            tol_dual: F::SOLVER_DUAL_TOL,
            step_fraction: F::from_f64(0.99),
            regularization: F::EPSILON * F::from_f64(1e3),
            pivot_floor: F::EPSILON * F::from_f64(16.0),
            refinement_steps: 2,
        }
    }
}

/// Why the solver stopped without a solution.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SolveError {
    /// The iteration cap was reached before the tolerances were met.
    IterationLimit {
        /// Iterations run.
        iterations: u32,
    },
    /// A Newton matrix was not positive definite to working precision.
    Numerical {
        /// Iteration at which it happened.
        iteration: u32,
    },
    /// The warm start or an iterate held NaN or ∞.
    NonFinite,
}

/// An optimal plan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Solution<F, const N: usize> {
    /// v_0..v_{N−1}.
    pub v: [F; N],
    /// J at `v`.
    pub objective: F,
    /// Interior-point iterations used.
    pub iterations: u32,
}

/// Progress of one interior-point iteration, for diagnostics ([`IpmSolver::solve_traced`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IterationInfo<F> {
    /// Iteration number.
    pub iteration: u32,
    /// J at the iterate.
    pub objective: F,
    /// Largest primal residual |g + s|.
    pub primal_residual: F,
    /// Largest dual residual.
    pub dual_residual: F,
    /// Duality measure sᵀλ / m.
    pub mu: F,
    /// Step length taken after this report (0 on the last report).
    pub step: F,
}

/// A solver for (10). Implemented by [`IpmSolver`]; host tools implement it with
/// reference solvers (Clarabel) so that plans can be compared.
pub trait MpcSolver<F: Real, const N: usize> {
    /// Solves `problem`, starting from `warm_start` speeds if given.
    fn solve(
        &mut self,
        problem: &SingleLaneProblem<F, N>,
        warm_start: Option<&[F; N]>,
    ) -> Result<Solution<F, N>, SolveError>;
}

/// Our interior-point solver, with all working storage inline (no allocation):
/// about (12 + 5·6) N scalars.
#[derive(Debug, Clone)]
pub struct IpmSolver<F, const N: usize> {
    settings: Settings<F>,
    /// The primal iterate, kept in speeds: prefix sums z reach N·vmax and would cost
    /// log2(N) bits of every speed in f32. Only Newton directions live in z-coordinates.
    v: [F; N],
    dz: [F; N],
    rhs: [F; N],
    r_d: [F; N],
    q: [F; N],
    p: Penta<F, N>,
    kkt: Penta<F, N>,
    /// The Newton matrix before factorisation, for iterative refinement.
    kkt_raw: Penta<F, N>,
    g: [[F; N]; FAMILIES],
    s: [[F; N]; FAMILIES],
    lam: [[F; N]; FAMILIES],
    ds: [[F; N]; FAMILIES],
    dl: [[F; N]; FAMILIES],
    rc: [[F; N]; FAMILIES],
    /// Safety-constraint gradient coefficients (at k and k−1), which depend on v_k.
    sgrad: [[F; 2]; N],
    /// Duals of the last successful solve are available for a warm start.
    have_duals: bool,
}

impl<F: Real, const N: usize> Default for IpmSolver<F, N> {
    fn default() -> Self {
        Self::new(Settings::default())
    }
}

impl<F: Real, const N: usize> IpmSolver<F, N> {
    /// A solver with the given settings.
    pub fn new(settings: Settings<F>) -> Self {
        let zn = [F::ZERO; N];
        let zf = [[F::ZERO; N]; FAMILIES];
        Self {
            settings,
            v: zn,
            dz: zn,
            rhs: zn,
            r_d: zn,
            q: zn,
            p: Penta::default(),
            kkt: Penta::default(),
            kkt_raw: Penta::default(),
            g: zf,
            s: zf,
            lam: zf,
            ds: zf,
            dl: zf,
            rc: zf,
            sgrad: [[F::ZERO; 2]; N],
            have_duals: false,
        }
    }

    /// The settings in use.
    pub fn settings(&self) -> &Settings<F> {
        &self.settings
    }

    /// Gradient stencil of constraint (family `f`, step k): coefficients at z_k, z_{k−1},
    /// z_{k−2}.
    #[inline(always)]
    fn stencil(&self, f: usize, k: usize) -> [F; 3] {
        let one = F::ONE;
        let two = F::TWO;
        match f {
            UPPER => [one, -one, F::ZERO],
            LOWER => [-one, one, F::ZERO],
            ACCEL => [one, -two, one],
            DECEL => [-one, two, -one],
            _ => {
                let [a, b] = self.sgrad.get(k).copied().unwrap_or([F::ZERO; 2]);
                [a, b, F::ZERO]
            }
        }
    }

    /// cᵀ x for stencil c at step k.
    #[inline(always)]
    fn dot(c: [F; 3], x: &[F; N], k: usize) -> F {
        let [c0, c1, c2] = c;
        let mut acc = c0 * get(x, k);
        if let Some(i) = k.checked_sub(1) {
            acc += c1 * get(x, i);
        }
        if let Some(i) = k.checked_sub(2) {
            acc += c2 * get(x, i);
        }
        acc
    }

    /// x += a c at step k.
    #[inline(always)]
    fn scatter(c: [F; 3], a: F, x: &mut [F; N], k: usize) {
        let [c0, c1, c2] = c;
        if let Some(slot) = x.get_mut(k) {
            *slot += a * c0;
        }
        if let Some(slot) = k.checked_sub(1).and_then(|i| x.get_mut(i)) {
            *slot += a * c1;
        }
        if let Some(slot) = k.checked_sub(2).and_then(|i| x.get_mut(i)) {
            *slot += a * c2;
        }
    }

    /// The Hessian P of J in z (J = ½ zᵀ P z + qᵀ z + const); q is kept for tests of the
    /// gradient, which the iteration computes from the speeds instead.
    fn build_cost(&mut self, pr: &SingleLaneProblem<F, N>) {
        let w = pr.weights;
        let two = F::TWO;
        self.p.clear();
        self.q = [F::ZERO; N];
        // w_x (X − h z_{N−1})²
        if let Some(last) = N.checked_sub(1) {
            let c = [pr.h, F::ZERO, F::ZERO];
            self.p.add_stencil(last, c, two * w.target_position);
            Self::scatter(c, -two * w.target_position * pr.target, &mut self.q, last);
        }
        for k in 0..N {
            // w_v (v_k − v_ref)²
            let c = [F::ONE, -F::ONE, F::ZERO];
            self.p.add_stencil(k, c, two * w.reference_speed);
            Self::scatter(c, -two * w.reference_speed * pr.v_ref, &mut self.q, k);
            // w_Δ (v_k − v_{k−1})²; for k = 0 the target is v_{t−h}.
            let c = [F::ONE, -two, F::ONE];
            self.p.add_stencil(k, c, two * w.smoothness);
            if k == 0 {
                Self::scatter(c, -two * w.smoothness * pr.v_prev, &mut self.q, k);
            }
        }
    }

    /// Evaluates every constraint g at the iterate, and the safety gradients.
    fn evaluate(&mut self, pr: &SingleLaneProblem<F, N>) {
        let mut zk = F::ZERO;
        let mut v_prev = pr.v_prev;
        let inv_b = F::ONE / pr.brake;
        for k in 0..N {
            let vk = get(&self.v, k);
            zk += vk;
            let dv = vk - v_prev;
            set2(&mut self.g, UPPER, k, vk - get(&pr.hi, k));
            set2(&mut self.g, LOWER, k, get(&pr.lo, k) - vk);
            set2(&mut self.g, ACCEL, k, dv - pr.dv_max);
            set2(&mut self.g, DECEL, k, pr.dv_min - dv);
            set2(&mut self.g, SAFETY, k, pr.safety_value(pr.h * zk, vk));
            let slope = pr.h + vk * inv_b;
            if let Some(sg) = self.sgrad.get_mut(k) {
                *sg = [pr.h + slope, -slope];
            }
            v_prev = vk;
        }
    }

    /// ∇_z J, computed from the speeds (no cancellation between large prefix sums):
    /// ∂J/∂z_k = ∂J/∂v_k − ∂J/∂v_{k+1}, plus the target term on z_{N−1}.
    fn cost_gradient(&self, pr: &SingleLaneProblem<F, N>, out: &mut [F; N]) {
        let w = pr.weights;
        let two = F::TWO;
        let dv = |k: usize| -> F {
            let vk = get(&self.v, k);
            let before = if k == 0 {
                pr.v_prev
            } else {
                get(&self.v, k - 1)
            };
            vk - before
        };
        let mut pos = F::ZERO;
        for (k, o) in out.iter_mut().enumerate() {
            let vk = get(&self.v, k);
            pos += vk * pr.h;
            let mut gv = two * w.reference_speed * (vk - pr.v_ref) + two * w.smoothness * dv(k);
            let mut gnext = F::ZERO;
            if k + 1 < N {
                gv -= two * w.smoothness * dv(k + 1);
                let vn = get(&self.v, k + 1);
                gnext = two * w.reference_speed * (vn - pr.v_ref) + two * w.smoothness * dv(k + 1);
                if k + 2 < N {
                    gnext -= two * w.smoothness * dv(k + 2);
                }
            }
            *o = gv - gnext;
        }
        if let Some(last) = out.last_mut() {
            *last -= two * w.target_position * pr.h * (pr.target - pos);
        }
    }

    /// rhs = −r_d + Σ ∇g_i (rc_i − λ_i r_p,i) / s_i, with r_p = g + s.
    fn build_rhs(&mut self) {
        for (r, d) in self.rhs.iter_mut().zip(self.r_d.iter()) {
            *r = -*d;
        }
        for f in 0..FAMILIES {
            for k in 0..N {
                let s = get2(&self.s, f, k);
                let l = get2(&self.lam, f, k);
                let rp = get2(&self.g, f, k) + s;
                let a = (get2(&self.rc, f, k) - l * rp) / s;
                let c = self.stencil(f, k);
                Self::scatter(c, a, &mut self.rhs, k);
            }
        }
    }

    /// dz = K⁻¹ rhs with the factorised (regularised) K, refined against the exact K.
    fn newton_solve(&mut self, refinement_steps: u32) {
        self.dz = self.rhs;
        self.kkt.solve(&mut self.dz);
        for _ in 0..refinement_steps {
            let mut r = [F::ZERO; N];
            self.kkt_raw.mul(&self.dz, &mut r);
            for (ri, bi) in r.iter_mut().zip(self.rhs.iter()) {
                *ri = *bi - *ri;
            }
            self.kkt.solve(&mut r);
            for (d, ri) in self.dz.iter_mut().zip(r.iter()) {
                *d += *ri;
            }
        }
    }

    /// After solving for dz: ds = −r_p − ∇gᵀ dz, dλ = (−rc − λ ds) / s; returns the
    /// largest step in (0, 1] keeping s + α ds ≥ 0 and λ + α dλ ≥ 0.
    fn recover_and_step_length(&mut self) -> F {
        let mut alpha = F::ONE;
        for f in 0..FAMILIES {
            for k in 0..N {
                let c = self.stencil(f, k);
                let s = get2(&self.s, f, k);
                let l = get2(&self.lam, f, k);
                let rp = get2(&self.g, f, k) + s;
                let ds = -rp - Self::dot(c, &self.dz, k);
                let dl = (-get2(&self.rc, f, k) - l * ds) / s;
                set2(&mut self.ds, f, k, ds);
                set2(&mut self.dl, f, k, dl);
                if ds < F::ZERO {
                    alpha = alpha.min(-s / ds);
                }
                if dl < F::ZERO {
                    alpha = alpha.min(-l / dl);
                }
            }
        }
        alpha
    }

    fn initialize(&mut self, pr: &SingleLaneProblem<F, N>, warm: Option<&[F; N]>) -> bool {
        let warm_ok = match warm {
            Some(w) => {
                self.v = *w;
                w.iter().all(|x| x.is_finite())
            }
            None => false,
        };
        if !warm_ok {
            // Cold: hold the current speed as far as V^k_t allows.
            for ((vk, &lo), &hi) in self.v.iter_mut().zip(pr.lo.iter()).zip(pr.hi.iter()) {
                *vk = pr.v_prev.min(hi).max(lo);
            }
        }
        self.evaluate(pr);
        let use_duals = warm_ok && self.have_duals;
        // Starting centrality: a warm start sits close to the central path, so it starts
        // with a small barrier; a cold start with a unit one.
        let floor = if warm_ok { F::from_f64(1e-2) } else { F::ONE };
        for f in 0..FAMILIES {
            for k in 0..N {
                let s = (-get2(&self.g, f, k)).max(floor);
                set2(&mut self.s, f, k, s);
                let l = if use_duals {
                    // Previous duals, shifted one step (the last one repeated).
                    let prev = get2(&self.lam, f, (k + 1).min(N.saturating_sub(1)));
                    prev.max(floor * floor / s)
                } else {
                    floor / s.max(F::ONE)
                };
                set2(&mut self.lam, f, k, l);
            }
        }
        warm_ok
    }
}

impl<F: Real, const N: usize> MpcSolver<F, N> for IpmSolver<F, N> {
    fn solve(
        &mut self,
        pr: &SingleLaneProblem<F, N>,
        warm_start: Option<&[F; N]>,
    ) -> Result<Solution<F, N>, SolveError> {
        self.solve_traced(pr, warm_start, &mut |_| {})
    }
}

impl<F: Real, const N: usize> IpmSolver<F, N> {
    /// [`MpcSolver::solve`], reporting every iteration to `trace`.
    pub fn solve_traced(
        &mut self,
        pr: &SingleLaneProblem<F, N>,
        warm_start: Option<&[F; N]>,
        trace: &mut dyn FnMut(IterationInfo<F>),
    ) -> Result<Solution<F, N>, SolveError> {
        let st = self.settings;
        self.build_cost(pr);
        self.initialize(pr, warm_start);
        self.have_duals = false;
        let m = F::from_usize(FAMILIES * N);
        // Rounding floor of the primal residual: a few ulp of the largest quantity.
        let floor_p = F::from_f64(16.0) * F::EPSILON * (pr.gap.abs() + F::from_f64(100.0));
        let tol_p = st.tol + floor_p;
        for it in 0..st.max_iter {
            self.evaluate(pr);
            // Dual residual r_d = ∇J + Σ λ ∇g, measured against its largest single term:
            // on degenerate vertices (speed cap and acceleration limit active together)
            // the duals are not unique and grow in opposite directions, so the round-off
            // of Σ λ ∇g is ε·max|λ_i ∇g_i| even where the sum is small.
            let mut rd = [F::ZERO; N];
            self.cost_gradient(pr, &mut rd);
            let mut scale = F::ONE;
            for r in rd.iter() {
                scale = scale.max(r.abs());
            }
            let mut jl = [F::ZERO; N];
            let mut max_rp = F::ZERO;
            let mut gap_sum = F::ZERO;
            for f in 0..FAMILIES {
                for k in 0..N {
                    let l = get2(&self.lam, f, k);
                    let s = get2(&self.s, f, k);
                    let c = self.stencil(f, k);
                    let [c0, c1, c2] = c;
                    scale = scale.max(l.abs() * c0.abs().max(c1.abs()).max(c2.abs()));
                    Self::scatter(c, l, &mut jl, k);
                    max_rp = max_rp.max((get2(&self.g, f, k) + s).abs());
                    gap_sum += s * l;
                }
            }
            for (r, j) in rd.iter_mut().zip(jl.iter()) {
                *r += *j;
            }
            self.r_d = rd;
            let max_rd = rd.iter().fold(F::ZERO, |a, &x| a.max(x.abs()));
            let v = self.v;
            let obj = pr.objective(&v);
            if !(obj.is_finite() && gap_sum.is_finite() && max_rd.is_finite()) {
                return Err(SolveError::NonFinite);
            }
            let mut info = IterationInfo {
                iteration: it,
                objective: obj,
                primal_residual: max_rp,
                dual_residual: max_rd,
                mu: gap_sum / m,
                step: F::ZERO,
            };
            if max_rp <= tol_p
                && max_rd <= st.tol_dual * scale
                && gap_sum <= st.tol * (F::ONE + obj.abs())
            {
                trace(info);
                self.have_duals = true;
                return Ok(Solution {
                    v,
                    objective: obj,
                    iterations: it,
                });
            }
            let mu = gap_sum / m;

            // Newton matrix: P + Σ λ ∇²g + Σ (λ/s) ∇g ∇gᵀ + δ I.
            self.kkt_raw.clone_from(&self.p);
            let inv_b = F::ONE / pr.brake;
            for f in 0..FAMILIES {
                for k in 0..N {
                    let w = get2(&self.lam, f, k) / get2(&self.s, f, k);
                    let c = self.stencil(f, k);
                    self.kkt_raw.add_stencil(k, c, w);
                }
            }
            for k in 0..N {
                let l = get2(&self.lam, SAFETY, k);
                self.kkt_raw
                    .add_stencil(k, [F::ONE, -F::ONE, F::ZERO], l * inv_b);
            }
            self.kkt.clone_from(&self.kkt_raw);
            for d in self.kkt.d.iter_mut() {
                *d += st.regularization;
            }
            if self.kkt.factor(st.pivot_floor).is_err() {
                return Err(SolveError::Numerical { iteration: it });
            }

            // Predictor (affine scaling): rc = s∘λ.
            for f in 0..FAMILIES {
                for k in 0..N {
                    set2(
                        &mut self.rc,
                        f,
                        k,
                        get2(&self.s, f, k) * get2(&self.lam, f, k),
                    );
                }
            }
            self.build_rhs();
            self.newton_solve(st.refinement_steps);
            let alpha_aff = self.recover_and_step_length();
            let mut mu_aff = F::ZERO;
            for f in 0..FAMILIES {
                for k in 0..N {
                    let s = get2(&self.s, f, k) + alpha_aff * get2(&self.ds, f, k);
                    let l = get2(&self.lam, f, k) + alpha_aff * get2(&self.dl, f, k);
                    mu_aff += s * l;
                }
            }
            mu_aff = mu_aff / m;
            let ratio = (mu_aff / mu).max(F::ZERO).min(F::ONE);
            let sigma = ratio * ratio * ratio;

            // Corrector: rc = s∘λ + Δs_aff∘Δλ_aff − σμ.
            for f in 0..FAMILIES {
                for k in 0..N {
                    let rc = get2(&self.s, f, k) * get2(&self.lam, f, k)
                        + get2(&self.ds, f, k) * get2(&self.dl, f, k)
                        - sigma * mu;
                    set2(&mut self.rc, f, k, rc);
                }
            }
            self.build_rhs();
            self.newton_solve(st.refinement_steps);
            let alpha_max = self.recover_and_step_length();
            let alpha = (st.step_fraction * alpha_max).min(F::ONE);
            info.step = alpha;
            trace(info);
            if !(alpha > F::ZERO) {
                return Err(SolveError::Numerical { iteration: it });
            }
            // v_k += α (dz_k − dz_{k−1}).
            let mut dz_prev = F::ZERO;
            for (v, &dz) in self.v.iter_mut().zip(self.dz.iter()) {
                *v += alpha * (dz - dz_prev);
                dz_prev = dz;
            }
            for f in 0..FAMILIES {
                for k in 0..N {
                    let s = get2(&self.s, f, k) + alpha * get2(&self.ds, f, k);
                    let l = get2(&self.lam, f, k) + alpha * get2(&self.dl, f, k);
                    set2(&mut self.s, f, k, s);
                    set2(&mut self.lam, f, k, l);
                }
            }
        }
        Err(SolveError::IterationLimit {
            iterations: st.max_iter,
        })
    }
}
