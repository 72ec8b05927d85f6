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
//! A warm start first tries the [`active_set`] step: the previous step's binding
//! constraints, shifted, held as equalities and solved by Newton's method on the same
//! pentadiagonal systems — two or three solves instead of the interior-point method's
//! 3–10 iterations of two, returned only when it passes the same stopping test. Where it
//! gives up (degenerate vertices), the interior-point method answers from its last
//! iterate. A warm start whose barrier was raised to its violation
//! ([`Settings::adaptive_warm_barrier`]) and that then fails is retried once at the
//! fixed barrier from the warm start and the previous multipliers.
//!
//! Every loop is bounded: the iteration caps are [`Settings::max_iter`] (twice at most,
//! with the retry) and [`Settings::active_set_iter`].

pub mod active_set;

use crate::banded::{get, NotPositiveDefinite, Penta};
use crate::mpc::SingleLaneProblem;
use crate::real::Real;
use crate::reuse::Duals;

/// Largest fraction to the boundary τ the solver uses (see [`Settings::step_fraction`]).
pub const TAU_MAX: f64 = 0.9999;

/// Default [`Settings::warm_barrier`].
pub const WARM_BARRIER: f64 = 1e-3;

/// Default [`Settings::active_set_iter`].
pub const ACTIVE_SET_ITER: u32 = 6;

/// Number of constraint families: v_k ≤ hi_k, v_k ≥ lo_k, accel, decel, safety.
const FAMILIES: usize = 5;

/// Solver settings: private and checked, as Clarabel keeps its own. Start from
/// [`Settings::default`] (or [`Settings::interior_point_only`]) and change a value with its
/// `with_…` method, which refuses a value outside its range with a [`SettingsError`]
/// (naming the setting) and returns the settings unchanged otherwise; read a value with
/// the getter of the same name.
///
/// ```
/// use planner_core::{IpmSolver, Settings, SettingsError};
///
/// let s = Settings::<f32>::default().with_max_iter(40)?.with_active_set_iter(0)?;
/// assert_eq!((s.max_iter(), s.active_set_iter()), (40, 0));
/// // A cap of 0 would never iterate: refused, naming the setting.
/// assert_eq!(s.with_max_iter(0), Err(SettingsError::MaxIter));
/// let solver = IpmSolver::<f32, 20>::new(s);
/// # let _ = solver;
/// # Ok::<(), SettingsError>(())
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Settings<F> {
    /// Iteration cap (the loop never runs longer).
    max_iter: u32,
    /// Stopping tolerance: primal residual (absolute, plus a rounding floor) and duality
    /// gap sᵀλ (relative to 1 + |J|).
    tol: F,
    /// Stopping tolerance of the dual residual, relative to its largest term.
    tol_dual: F,
    /// Smallest fraction τ of the step to the boundary of the positive orthant (keeps
    /// s, λ > 0); the solver uses min(max(τ, 1 − μ), [`TAU_MAX`]).
    step_fraction: F,
    /// Static regularisation added to the Newton matrix diagonal (guards factorisation
    /// against round-off when many constraints are active).
    regularization: F,
    /// Dynamic regularisation: smallest pivot relative to its diagonal entry
    /// (see [`Penta::factor`]).
    pivot_floor: F,
    /// Iterative-refinement passes per Newton solve, against the unregularised matrix
    /// (they undo the regularisation's perturbation; each costs O(N)). f32 needs one to
    /// stay within ~1e-3 of the optimum; in f64 it does not change the answer measurably.
    refinement_steps: u32,
    /// Barrier level at which a warm start begins: slacks are floored at this value and
    /// duals at its square over the slack (a cold start uses 1).
    warm_barrier: F,
    /// Whether a warm start's barrier also grows to its largest constraint violation
    /// (see `IpmSolver::start`); `false` is the solver before its active-set step.
    adaptive_warm_barrier: bool,
    /// Most Newton steps of the active-set step tried before the interior-point method
    /// on a warm start ([`active_set`]); 0 turns it off.
    active_set_iter: u32,
    /// Penalty ρ of the active-set step's regularised Newton system: held constraints
    /// enter it as ρ·aaᵀ and their multipliers move by ρ·residual each step
    /// ([`active_set`]; default [`Real::ACTIVE_SET_PENALTY`]).
    active_set_penalty: F,
    /// Whether a cold start's multipliers are scaled to the cost's gradient (see
    /// `IpmSolver::start`); `false` starts them at 1 over the slack.
    scaled_cold_start: bool,
    /// Whether `max_iter` is a deadline: it counts every Newton step of a solve, and at
    /// the cap the solver answers with its iterate ([`Method::Capped`]).
    answer_at_cap: bool,
}

/// The largest iteration cap [`Settings::with_max_iter`] takes: a cap is there to bound
/// a step's time on a microcontroller.
pub const MAX_ITER_CAP: u32 = 1_000;
/// The most refinement passes [`Settings::with_refinement_steps`] takes.
pub const MAX_REFINEMENT_STEPS: u32 = 8;
/// The most active-set steps [`Settings::with_active_set_iter`] takes.
pub const MAX_ACTIVE_SET_ITER: u32 = 100;

/// A solver setting refused by its `with_…` method: which one (its range is in the
/// method's documentation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum SettingsError {
    /// `max_iter` not in 1 ..= [`MAX_ITER_CAP`].
    MaxIter,
    /// `tol` not finite in (0, 1).
    Tolerance,
    /// `tol_dual` not finite in (0, 1).
    DualTolerance,
    /// `step_fraction` not in (0, 1).
    StepFraction,
    /// `regularization` not finite in [0, 1).
    Regularization,
    /// `pivot_floor` not finite in (0, 1).
    PivotFloor,
    /// `refinement_steps` above [`MAX_REFINEMENT_STEPS`].
    RefinementSteps,
    /// `warm_barrier` not in (0, 1].
    WarmBarrier,
    /// `active_set_iter` above [`MAX_ACTIVE_SET_ITER`].
    ActiveSetIter,
    /// `active_set_penalty` not finite and positive.
    ActiveSetPenalty,
}

impl core::fmt::Display for SettingsError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Self::MaxIter => "max_iter must be 1 to 1,000",
            Self::Tolerance => "tol must be finite, above 0 and below 1",
            Self::DualTolerance => "tol_dual must be finite, above 0 and below 1",
            Self::StepFraction => "step_fraction must be above 0 and below 1",
            Self::Regularization => "regularization must be finite, at least 0 and below 1",
            Self::PivotFloor => "pivot_floor must be finite, above 0 and below 1",
            Self::RefinementSteps => "refinement_steps must be at most 8",
            Self::WarmBarrier => "warm_barrier must be above 0 and at most 1",
            Self::ActiveSetIter => "active_set_iter must be at most 100",
            Self::ActiveSetPenalty => "active_set_penalty must be finite and above 0",
        })
    }
}

impl core::error::Error for SettingsError {}

/// `x` if `ok` holds for it, else `e`.
fn checked<T>(x: T, ok: bool, e: SettingsError) -> Result<T, SettingsError> {
    if ok {
        Ok(x)
    } else {
        Err(e)
    }
}

impl<F: Real> Settings<F> {
    /// The iteration cap.
    pub fn max_iter(&self) -> u32 {
        self.max_iter
    }
    /// With iteration cap `n`, 1 ..= [`MAX_ITER_CAP`].
    pub fn with_max_iter(self, n: u32) -> Result<Self, SettingsError> {
        let ok = (1..=MAX_ITER_CAP).contains(&n);
        checked(
            Self {
                max_iter: n,
                ..self
            },
            ok,
            SettingsError::MaxIter,
        )
    }

    /// The primal and gap tolerance.
    pub fn tol(&self) -> F {
        self.tol
    }
    /// With primal and gap tolerance `t`, finite in (0, 1).
    pub fn with_tol(self, t: F) -> Result<Self, SettingsError> {
        let ok = t.is_finite() && t > F::ZERO && t < F::ONE;
        checked(Self { tol: t, ..self }, ok, SettingsError::Tolerance)
    }

    /// The dual tolerance.
    pub fn tol_dual(&self) -> F {
        self.tol_dual
    }
    /// With dual tolerance `t`, finite in (0, 1).
    pub fn with_tol_dual(self, t: F) -> Result<Self, SettingsError> {
        let ok = t.is_finite() && t > F::ZERO && t < F::ONE;
        checked(
            Self {
                tol_dual: t,
                ..self
            },
            ok,
            SettingsError::DualTolerance,
        )
    }

    /// The smallest fraction to the boundary.
    pub fn step_fraction(&self) -> F {
        self.step_fraction
    }
    /// With smallest fraction to the boundary `tau`, in (0, 1).
    pub fn with_step_fraction(self, tau: F) -> Result<Self, SettingsError> {
        let ok = tau > F::ZERO && tau < F::ONE;
        checked(
            Self {
                step_fraction: tau,
                ..self
            },
            ok,
            SettingsError::StepFraction,
        )
    }

    /// The static regularisation.
    pub fn regularization(&self) -> F {
        self.regularization
    }
    /// With static regularisation `r`, finite in [0, 1).
    pub fn with_regularization(self, r: F) -> Result<Self, SettingsError> {
        let ok = r >= F::ZERO && r < F::ONE;
        checked(
            Self {
                regularization: r,
                ..self
            },
            ok,
            SettingsError::Regularization,
        )
    }

    /// The smallest relative pivot.
    pub fn pivot_floor(&self) -> F {
        self.pivot_floor
    }
    /// With smallest relative pivot `p`, in (0, 1).
    pub fn with_pivot_floor(self, p: F) -> Result<Self, SettingsError> {
        let ok = p > F::ZERO && p < F::ONE;
        checked(
            Self {
                pivot_floor: p,
                ..self
            },
            ok,
            SettingsError::PivotFloor,
        )
    }

    /// The refinement passes per Newton solve.
    pub fn refinement_steps(&self) -> u32 {
        self.refinement_steps
    }
    /// With `n` refinement passes, at most [`MAX_REFINEMENT_STEPS`].
    pub fn with_refinement_steps(self, n: u32) -> Result<Self, SettingsError> {
        let ok = n <= MAX_REFINEMENT_STEPS;
        checked(
            Self {
                refinement_steps: n,
                ..self
            },
            ok,
            SettingsError::RefinementSteps,
        )
    }

    /// The warm start's barrier level.
    pub fn warm_barrier(&self) -> F {
        self.warm_barrier
    }
    /// With warm-start barrier level `mu`, in (0, 1].
    pub fn with_warm_barrier(self, mu: F) -> Result<Self, SettingsError> {
        let ok = mu > F::ZERO && mu <= F::ONE;
        checked(
            Self {
                warm_barrier: mu,
                ..self
            },
            ok,
            SettingsError::WarmBarrier,
        )
    }

    /// Whether a warm start's barrier grows to its largest violation.
    pub fn adaptive_warm_barrier(&self) -> bool {
        self.adaptive_warm_barrier
    }
    /// With the warm start's barrier growing to its largest violation (`true`) or fixed.
    pub fn with_adaptive_warm_barrier(self, on: bool) -> Self {
        Self {
            adaptive_warm_barrier: on,
            ..self
        }
    }

    /// The most active-set steps before the interior-point method.
    pub fn active_set_iter(&self) -> u32 {
        self.active_set_iter
    }
    /// With at most `n` active-set steps (0 turns the step off), at most
    /// [`MAX_ACTIVE_SET_ITER`].
    pub fn with_active_set_iter(self, n: u32) -> Result<Self, SettingsError> {
        let ok = n <= MAX_ACTIVE_SET_ITER;
        checked(
            Self {
                active_set_iter: n,
                ..self
            },
            ok,
            SettingsError::ActiveSetIter,
        )
    }

    /// Whether a cold start's multipliers are scaled to the cost's gradient.
    pub fn scaled_cold_start(&self) -> bool {
        self.scaled_cold_start
    }
    /// With a cold start's multipliers at ‖∇J‖∞ (at least 1) over the slack (`true`)
    /// instead of 1 over it. Stationarity, ∇J + Σ λᵢ ∇gᵢ = 0, wants multipliers of the
    /// gradient's size where constraints bind: a vehicle standing with its reference
    /// speed far above, or a plan pressed against (10)'s bounds, has ‖∇J‖∞ in the tens to
    /// hundreds, and unit multipliers leave the first Newton steps to grow them. Measured
    /// on the firmware's problems at N = 50 (`planner-core/tests/scaled_cold_start.rs`).
    /// Off by default: every figure of the host's was measured without it.
    pub fn with_scaled_cold_start(self, on: bool) -> Self {
        Self {
            scaled_cold_start: on,
            ..self
        }
    }

    /// Whether `max_iter` is a deadline that is answered at ([`Settings::with_answer_at_cap`]).
    pub fn answer_at_cap(&self) -> bool {
        self.answer_at_cap
    }
    /// With `max_iter` as a deadline (`true`): it counts every Newton step of a solve
    /// (the active-set step's, the interior-point method's and a retry's), and a solve
    /// that reaches it answers with its current iterate ([`Method::Capped`]) instead of
    /// [`SolveError::IterationLimit`]. The iterate is not optimal, and may not be
    /// feasible: the planner applies it only if it passes the exact verification of (10)
    /// that every answer passes ([`crate::planner::verify`]), else the certified fallback,
    /// so safety is the same; what is lost is optimality, for a step whose work is
    /// bounded by `max_iter` Newton steps. A microcontroller sets the cap from its period
    /// (the firmware at N = 50: docs/firmware.md). Off by default.
    pub fn with_answer_at_cap(self, on: bool) -> Self {
        Self {
            answer_at_cap: on,
            ..self
        }
    }

    /// The active-set step's penalty ρ.
    pub fn active_set_penalty(&self) -> F {
        self.active_set_penalty
    }
    /// With active-set penalty `rho`, finite and positive.
    pub fn with_active_set_penalty(self, rho: F) -> Result<Self, SettingsError> {
        let ok = rho.is_finite() && rho > F::ZERO;
        checked(
            Self {
                active_set_penalty: rho,
                ..self
            },
            ok,
            SettingsError::ActiveSetPenalty,
        )
    }
}

impl<F: Real> Settings<F> {
    /// All zeros: the placeholder of a solver in a [`crate::slot`] before its `init`
    /// (never solved with).
    pub(crate) const fn unset() -> Self {
        Self {
            max_iter: 0,
            tol: F::ZERO,
            tol_dual: F::ZERO,
            step_fraction: F::ZERO,
            regularization: F::ZERO,
            pivot_floor: F::ZERO,
            refinement_steps: 0,
            warm_barrier: F::ZERO,
            adaptive_warm_barrier: false,
            active_set_iter: 0,
            active_set_penalty: F::ZERO,
            scaled_cold_start: false,
            answer_at_cap: false,
        }
    }

    /// The solver as it was before its active-set step: the interior-point method alone, warm
    /// starts at the fixed [`Settings::warm_barrier`]. For side-by-side benchmarks
    /// (`host-sim scale --compare`, `bench-planner`); it finds the same optima, slower.
    pub fn interior_point_only() -> Self {
        Self {
            adaptive_warm_barrier: false,
            active_set_iter: 0,
            ..Self::default()
        }
    }
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
            refinement_steps: if F::EPSILON > F::from_f64(1e-10) {
                1
            } else {
                0
            },
            warm_barrier: F::from_f64(WARM_BARRIER),
            adaptive_warm_barrier: true,
            active_set_iter: ACTIVE_SET_ITER,
            active_set_penalty: F::ACTIVE_SET_PENALTY,
            scaled_cold_start: false,
            answer_at_cap: false,
        }
    }
}

/// Why the solver stopped without a solution.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
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

/// The first sentence of each variant's documentation (and its data).
impl core::fmt::Display for SolveError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::IterationLimit { .. } => write!(
                f,
                "the iteration cap was reached before the tolerances were met ({self:?})"
            ),
            Self::Numerical { .. } => write!(
                f,
                "a Newton matrix was not positive definite to working precision ({self:?})"
            ),
            Self::NonFinite => f.write_str("the warm start or an iterate held NaN or ∞"),
        }
    }
}

impl core::error::Error for SolveError {}

/// Which method produced an answer or an iteration.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum Method {
    /// The active-set step from the previous solve's multipliers ([`active_set`]).
    ActiveSet,
    /// The interior-point method.
    InteriorPoint,
    /// The interior-point method's iterate at the iteration cap, when the cap is a
    /// deadline ([`Settings::with_answer_at_cap`]): not optimal, and verified by the
    /// planner like every answer.
    Capped,
}

/// An optimal plan.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Solution<F, const N: usize> {
    /// v_0..v_{N−1}.
    pub v: [F; N],
    /// J at `v`.
    pub objective: F,
    /// Newton steps used, every one: the active-set step's, and when it gave up, its
    /// steps plus the interior-point iterations after them.
    pub iterations: u32,
    /// Which method answered.
    pub method: Method,
}

/// Progress of one interior-point iteration, for diagnostics ([`IpmSolver::solve_traced`]).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct IterationInfo<F> {
    /// Iteration number.
    pub iteration: u32,
    /// J at the iterate (0 until the residuals are small: it is computed only then).
    pub objective: F,
    /// Largest primal residual |g + s|.
    pub primal_residual: F,
    /// Largest dual residual.
    pub dual_residual: F,
    /// Duality measure sᵀλ / m.
    pub mu: F,
    /// Step length taken after this report (0 on the last report).
    pub step: F,
    /// Which method ran this iteration (an active-set step that fails is followed by
    /// the interior-point method's iterations, numbered from 0 again).
    pub method: Method,
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

    /// The multipliers of the last successful solve, aligned with its plan (moved on by
    /// [`Self::advance`]), if the solver has them: they certify plan reuse
    /// ([`crate::reuse`]). Solvers without them return `None`, and their planners
    /// always solve.
    fn duals(&self) -> Option<Duals<F, N>> {
        None
    }

    /// The planner applied the previous plan one step further without solving: move the
    /// warm-start state one step on so that it stays aligned with the plan.
    fn advance(&mut self) {}
}

/// Slacks, duals and work vectors of one constraint family (one entry per step k).
#[derive(Debug, Clone)]
struct Family<F, const N: usize> {
    /// Constraint values g (≤ 0 when satisfied).
    g: [F; N],
    /// Slacks s > 0 with g + s = 0 at convergence.
    s: [F; N],
    /// 1/s, refreshed once per iteration (divisions dominate otherwise).
    inv_s: [F; N],
    /// 1/λ, refreshed once per iteration, for the step-length ratio test.
    inv_l: [F; N],
    /// Duals λ > 0.
    lam: [F; N],
    /// Complementarity right-hand side of the current Newton system.
    rc: [F; N],
    /// Newton directions of s and λ.
    ds: [F; N],
    dl: [F; N],
    /// In the active set of [`active_set`] (held as an equality).
    act: [bool; N],
    /// The multipliers a warm-started interior-point method began from (the previous
    /// solve's, unshifted), kept for its one retry at the fixed barrier
    /// (`IpmSolver::solve_traced`).
    prev: [F; N],
}

impl<F: Real, const N: usize> Family<F, N> {
    const fn new() -> Self {
        let z = [F::ZERO; N];
        Self {
            act: [false; N],
            g: z,
            s: z,
            inv_s: z,
            inv_l: z,
            lam: z,
            rc: z,
            ds: z,
            dl: z,
            prev: z,
        }
    }

    /// What [`Family::new`] builds, written in place (one array at a time, so that no
    /// temporary of the family's size is needed).
    fn clear(&mut self) {
        for a in [
            &mut self.g,
            &mut self.s,
            &mut self.inv_s,
            &mut self.inv_l,
            &mut self.lam,
            &mut self.rc,
            &mut self.ds,
            &mut self.dl,
            &mut self.prev,
        ] {
            a.fill(F::ZERO);
        }
        self.act.fill(false);
    }
}

/// Our interior-point solver, with all working storage inline (no allocation):
/// about 62 N scalars and 5 N flags (the `size_of` table: [`crate::slot`]).
///
/// The five constraint families share three gradient stencils in z:
/// D1_k = e_k − e_{k−1} (v_k; upper bound +, lower bound −), D2_k = e_k − 2e_{k−1} + e_{k−2}
/// (Δv_k; accel +, decel −) and S_k = c0_k e_k + c1_k e_{k−1} (safety, c depends on v_k).
/// So the Newton matrix, Jᵀλ and the right-hand sides are assembled in single fused
/// passes from three per-step weights, with no scattered updates.
#[derive(Debug, Clone)]
pub struct IpmSolver<F, const N: usize> {
    settings: Settings<F>,
    /// The primal iterate, kept in speeds: prefix sums z reach N·vmax and would cost
    /// log2(N) bits of every speed in f32. Only Newton directions live in z-coordinates.
    v: [F; N],
    fam: [Family<F, N>; FAMILIES],
    /// Safety stencil coefficients at k and k−1.
    c0: [F; N],
    c1: [F; N],
    /// Work vectors.
    dz: [F; N],
    rhs: [F; N],
    rd: [F; N],
    w1: [F; N],
    w2: [F; N],
    w3: [F; N],
    kkt: Penta<F, N>,
    /// The Newton matrix before regularisation, kept only for iterative refinement.
    kkt_raw: Penta<F, N>,
    /// Duals of the last successful solve are available for a warm start.
    have_duals: bool,
    /// Warm starts left that skip the active-set step because it failed lately.
    skip: u8,
    /// Active-set failures in a row.
    fails: u8,
}

impl<F: Real, const N: usize> Default for IpmSolver<F, N> {
    fn default() -> Self {
        Self::new(Settings::default())
    }
}

/// Which stencil a family uses and with which sign.
#[derive(Clone, Copy)]
enum Proj {
    D1(bool),
    D2(bool),
    S,
}

const PROJ: [Proj; FAMILIES] = [
    Proj::D1(true),
    Proj::D1(false),
    Proj::D2(true),
    Proj::D2(false),
    Proj::S,
];

impl<F: Real, const N: usize> IpmSolver<F, N> {
    /// A solver with the given settings (a `const fn`: a `static` can hold one).
    pub const fn new(settings: Settings<F>) -> Self {
        let z = [F::ZERO; N];
        Self {
            settings,
            v: z,
            fam: [
                Family::new(),
                Family::new(),
                Family::new(),
                Family::new(),
                Family::new(),
            ],
            c0: z,
            c1: z,
            dz: z,
            rhs: z,
            rd: z,
            w1: z,
            w2: z,
            w3: z,
            kkt: Penta::zeros(),
            kkt_raw: Penta::zeros(),
            have_duals: false,
            skip: 0,
            fails: 0,
        }
    }

    /// Puts the solver in the state [`IpmSolver::new`] builds, in place: field by field,
    /// so that no temporary of the solver's size (~62 N scalars) is needed — on a
    /// microcontroller whose planner lives in a `static` ([`crate::slot`]) that
    /// temporary would be the largest thing on the stack.
    pub fn reset(&mut self, settings: Settings<F>) {
        // Every field named: one added to the solver must be reset here too.
        let Self {
            settings: s,
            v,
            fam,
            c0,
            c1,
            dz,
            rhs,
            rd,
            w1,
            w2,
            w3,
            kkt,
            kkt_raw,
            have_duals,
            skip,
            fails,
        } = self;
        *skip = 0;
        *fails = 0;
        *s = settings;
        for a in [v, c0, c1, dz, rhs, rd, w1, w2, w3] {
            a.fill(F::ZERO);
        }
        for f in fam.iter_mut() {
            f.clear();
        }
        for m in [kkt, kkt_raw] {
            for a in [&mut m.d, &mut m.e1, &mut m.e2, &mut m.dinv] {
                a.fill(F::ZERO);
            }
        }
        *have_duals = false;
    }

    /// The settings in use.
    pub fn settings(&self) -> &Settings<F> {
        &self.settings
    }

    /// Replaces the settings, keeping the warm state (the next solve uses them).
    pub fn set_settings(&mut self, settings: Settings<F>) {
        self.settings = settings;
    }

    /// Evaluates every constraint g at the iterate, and the safety stencil.
    fn evaluate(&mut self, pr: &SingleLaneProblem<F, N>) {
        let [up, lo, ac, de, sa] = &mut self.fam;
        let inv_b = F::ONE / pr.brake;
        let mut z = F::ZERO;
        let mut v_prev = pr.v_prev;
        for k in 0..N {
            let vk = get(&self.v, k);
            z += vk;
            let dv = vk - v_prev;
            put(&mut up.g, k, vk - get(&pr.hi, k));
            put(&mut lo.g, k, get(&pr.lo, k) - vk);
            put(&mut ac.g, k, dv - pr.dv_max);
            put(&mut de.g, k, pr.dv_min - dv);
            put(&mut sa.g, k, pr.safety_value(pr.h * z, vk));
            let slope = pr.h + vk * inv_b;
            put(&mut self.c0, k, pr.h + slope);
            put(&mut self.c1, k, -slope);
            v_prev = vk;
        }
    }

    /// out = Σ_k (a1_k D1_k + a2_k D2_k + a3_k S_k), in one pass.
    fn jt(&self, a1: &[F; N], a2: &[F; N], a3: &[F; N], out: &mut [F; N]) {
        let two = F::TWO;
        for (j, o) in out.iter_mut().enumerate() {
            *o = get(a1, j) - get(a1, j + 1) + get(a2, j) - two * get(a2, j + 1)
                + get(a2, j + 2)
                + get(&self.c0, j) * get(a3, j)
                + get(&self.c1, j + 1) * get(a3, j + 1);
        }
    }

    /// K = Σ_k (w1_k D1 D1ᵀ + w2_k D2 D2ᵀ + w3_k S Sᵀ) + diag_last e_{N−1}e_{N−1}ᵀ, fused,
    /// into `kkt` (unregularised).
    fn assemble(&mut self, diag_last: F) {
        let two = F::TWO;
        let four = F::from_f64(4.0);
        let (w1, w2, w3, c0, c1) = (&self.w1, &self.w2, &self.w3, &self.c0, &self.c1);
        let k = &mut self.kkt;
        for j in 0..N {
            let (c0j, c1j, c1n) = (get(c0, j), get(c1, j), get(c1, j + 1));
            let d = get(w1, j)
                + get(w1, j + 1)
                + get(w2, j)
                + four * get(w2, j + 1)
                + get(w2, j + 2)
                + get(w3, j) * c0j * c0j
                + get(w3, j + 1) * c1n * c1n;
            put(&mut k.d, j, d);
            let e1 = if j >= 1 {
                -get(w1, j) - two * get(w2, j) - two * get(w2, j + 1) + get(w3, j) * c0j * c1j
            } else {
                F::ZERO
            };
            put(&mut k.e1, j, e1);
            put(&mut k.e2, j, if j >= 2 { get(w2, j) } else { F::ZERO });
        }
        if let Some(last) = k.d.last_mut() {
            *last += diag_last;
        }
    }

    /// ∇_z J, computed from the speeds (no cancellation between large prefix sums):
    /// ∂J/∂z_k = ∂J/∂v_k − ∂J/∂v_{k+1}, plus the target term on z_{N−1}.
    fn cost_gradient(&self, pr: &SingleLaneProblem<F, N>, out: &mut [F; N]) {
        let w = pr.weights;
        let two_v = F::TWO * w.reference_speed;
        let two_s = F::TWO * w.smoothness;
        // ∂J/∂v_k (without the target term, equal for every k), into `out`.
        let mut prev = pr.v_prev;
        let mut pos = F::ZERO;
        for k in 0..N {
            let vk = get(&self.v, k);
            let dv_next = if k + 1 < N {
                get(&self.v, k + 1) - vk
            } else {
                F::ZERO
            };
            put(
                out,
                k,
                two_v * (vk - pr.v_ref) + two_s * (vk - prev - dv_next),
            );
            pos += vk * pr.h;
            prev = vk;
        }
        for k in 0..N {
            let g = get(out, k) - get(out, k + 1);
            put(out, k, g);
        }
        if let Some(last) = out.last_mut() {
            *last -= F::TWO * w.target_position * pr.h * (pr.target - pos);
        }
    }

    /// rhs = −r_d + Σ ∇g_i (rc_i − λ_i r_p,i) / s_i, with r_p = g + s.
    fn build_rhs(&mut self) {
        let mut a1 = [F::ZERO; N];
        let mut a2 = [F::ZERO; N];
        let mut a3 = [F::ZERO; N];
        let [up, lo, ac, de, sa] = &self.fam;
        let t = |f: &Family<F, N>, k: usize| -> F {
            (get(&f.rc, k) - get(&f.lam, k) * (get(&f.g, k) + get(&f.s, k))) * get(&f.inv_s, k)
        };
        for k in 0..N {
            put(&mut a1, k, t(up, k) - t(lo, k));
            put(&mut a2, k, t(ac, k) - t(de, k));
            put(&mut a3, k, t(sa, k));
        }
        let mut out = [F::ZERO; N];
        self.jt(&a1, &a2, &a3, &mut out);
        for ((r, o), d) in self.rhs.iter_mut().zip(out.iter()).zip(self.rd.iter()) {
            *r = *o - *d;
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

    /// The Newton direction Δz projected on the three stencils (type doc): D1 Δz (Δv),
    /// D2 Δz (the change of Δv) and the safety stencil S Δz — shared by the
    /// interior-point step and the active-set step. Written into the caller's arrays and
    /// inlined, so that the hot path's code and stack are those of the loop written in
    /// place (a returned array of arrays cost the firmware 1.3 KB of stack at N = 50).
    #[inline(always)]
    pub(super) fn stencil_directions(&self, d1: &mut [F; N], d2: &mut [F; N], sd: &mut [F; N]) {
        let (mut dz_prev, mut dv_prev) = (F::ZERO, F::ZERO);
        for k in 0..N {
            let dz = get(&self.dz, k);
            let dv = dz - dz_prev;
            put(d1, k, dv);
            put(d2, k, dv - dv_prev);
            put(sd, k, get(&self.c0, k) * dz + get(&self.c1, k) * dz_prev);
            dz_prev = dz;
            dv_prev = dv;
        }
    }

    /// After solving for dz: ds = −r_p − ∇gᵀ dz, dλ = (−rc − λ ds) / s; returns the
    /// largest step α > 0 keeping s + α ds ≥ 0 and λ + α dλ ≥ 0 (not capped at 1: the
    /// caller takes min(1, τ α), so a full Newton step is taken whenever it is safe).
    fn recover_and_step_length(&mut self) -> F {
        let (mut d1, mut d2, mut sd) = ([F::ZERO; N], [F::ZERO; N], [F::ZERO; N]);
        self.stencil_directions(&mut d1, &mut d2, &mut sd);
        // The ratio test as max(−ds/s, −dλ/λ) with the cached reciprocals: one division
        // at the end instead of two per constraint.
        let mut worst = F::EPSILON;
        for (f, proj) in self.fam.iter_mut().zip(PROJ.iter()) {
            let (dir, sign) = match *proj {
                Proj::D1(pos) => (&d1, pos),
                Proj::D2(pos) => (&d2, pos),
                Proj::S => (&sd, true),
            };
            let it =
                f.ds.iter_mut()
                    .zip(f.dl.iter_mut())
                    .zip(f.g.iter().zip(f.s.iter().zip(f.inv_s.iter())))
                    .zip(f.lam.iter().zip(f.rc.iter().zip(f.inv_l.iter())))
                    .zip(dir.iter());
            for ((((ds, dl), (&g, (&s, &is))), (&l, (&rc, &il))), &dd) in it {
                let proj_dz = if sign { dd } else { -dd };
                *ds = -(g + s) - proj_dz;
                *dl = (-rc - l * *ds) * is;
                worst = worst.max(-*ds * is).max(-*dl * il);
            }
        }
        F::ONE / worst
    }

    /// The dual residual r_d = ∇J + Σ λ_i ∇g_i into `rd` (after [`Self::evaluate`]);
    /// returns max |r_d| and the scale it is measured against: its largest single term.
    /// Why that scale: on degenerate vertices (speed cap and acceleration limit active
    /// together) the duals are not unique and grow in opposite directions, so the
    /// round-off of Σ λ ∇g is ε·max|λ_i ∇g_i| even where the sum is small.
    fn dual_residual(&mut self, pr: &SingleLaneProblem<F, N>) -> (F, F) {
        let two = F::TWO;
        let mut grad = [F::ZERO; N];
        self.cost_gradient(pr, &mut grad);
        let mut scale = grad.iter().fold(F::ONE, |a, &x| a.max(x.abs()));
        let [up, lo, ac, de, sa] = &self.fam;
        let a1: [F; N] = core::array::from_fn(|k| get(&up.lam, k) - get(&lo.lam, k));
        let a2: [F; N] = core::array::from_fn(|k| get(&ac.lam, k) - get(&de.lam, k));
        for k in 0..N {
            let c = get(&self.c0, k).abs().max(get(&self.c1, k).abs());
            scale = scale
                .max(get(&up.lam, k).abs())
                .max(get(&lo.lam, k).abs())
                .max(two * get(&ac.lam, k).abs())
                .max(two * get(&de.lam, k).abs())
                .max(get(&sa.lam, k).abs() * c);
        }
        let mut jl = [F::ZERO; N];
        self.jt(&a1, &a2, &sa.lam, &mut jl);
        for ((r, g), j) in self.rd.iter_mut().zip(grad.iter()).zip(jl.iter()) {
            *r = *g + *j;
        }
        let max_rd = self.rd.iter().fold(F::ZERO, |a, &x| a.max(x.abs()));
        (max_rd, scale)
    }

    /// Starts the interior-point method from `warm` (or cold); whether the barrier was
    /// raised above the fixed warm one ([`IpmSolver::start`]).
    fn initialize(&mut self, pr: &SingleLaneProblem<F, N>, warm: Option<&[F; N]>) -> bool {
        let warm_ok = match warm {
            Some(w) if w.iter().all(|x| x.is_finite()) => {
                self.v = *w;
                true
            }
            _ => false,
        };
        if !warm_ok {
            // Cold: hold the current speed as far as V^k_t allows.
            for ((vk, &lo), &hi) in self.v.iter_mut().zip(pr.lo.iter()).zip(pr.hi.iter()) {
                *vk = pr.v_prev.min(hi).max(lo);
            }
        }
        self.start(pr, warm_ok, self.settings.adaptive_warm_barrier)
    }

    /// The interior-point method's starting slacks and duals at the plan in `v` (a warm
    /// start's if `warm_ok`, else the cold one). With `warm_ok` the duals are the
    /// previous solve's, shifted, when it left any (kept unshifted in `prev` for a
    /// retry). Returns whether `adaptive` raised the barrier above the fixed warm one.
    fn start(&mut self, pr: &SingleLaneProblem<F, N>, warm_ok: bool, adaptive: bool) -> bool {
        self.evaluate(pr);
        let use_duals = warm_ok && self.have_duals;
        // Starting centrality: a warm start sits close to the central path, so it starts
        // with a small barrier; a cold start with a unit one. A warm start that the new
        // problem's constraints cut into (by d, its largest violation) is not close: its
        // slacks start at d at least, so that the first steps are not blocked by slacks
        // of 1e-3 against a residual of d (measured on the firmware's lane change in f32,
        // where d_H shrinks by up to 0.9 m a step: 3.06 → 2.73 Newton steps per solve,
        // and 4.67 → 3.53 on bench-planner's N = 50 drive).
        let floor = if !warm_ok {
            F::ONE
        } else if adaptive {
            let worst = self
                .fam
                .iter()
                .flat_map(|f| f.g.iter())
                .fold(F::ZERO, |a, &g| a.max(g));
            self.settings.warm_barrier.max(worst)
        } else {
            self.settings.warm_barrier
        };
        // A cold start's multipliers at the cost gradient's size (`Settings::
        // with_scaled_cold_start`), else at 1: λ s = scale, centred at that barrier.
        let scale = if !warm_ok && self.settings.scaled_cold_start {
            let mut grad = [F::ZERO; N];
            self.cost_gradient(pr, &mut grad);
            grad.iter().fold(F::ONE, |a, &x| a.max(x.abs()))
        } else {
            F::ONE
        };
        for f in self.fam.iter_mut() {
            f.prev = f.lam;
            // Previous duals, shifted one step (the last one repeated).
            let shifted: [F; N] =
                core::array::from_fn(|k| get(&f.lam, (k + 1).min(N.saturating_sub(1))));
            for ((s, l), (&g, &lp)) in
                f.s.iter_mut()
                    .zip(f.lam.iter_mut())
                    .zip(f.g.iter().zip(shifted.iter()))
            {
                *s = (-g).max(floor);
                *l = if use_duals {
                    lp.max(floor * floor / *s)
                } else {
                    scale * floor / s.max(F::ONE)
                };
            }
        }
        warm_ok && floor > self.settings.warm_barrier
    }

    /// Back to the multipliers the last start began from, for a retry from `warm`.
    fn restore_start(&mut self, warm: &[F; N], had_duals: bool) {
        for f in self.fam.iter_mut() {
            f.lam = f.prev;
        }
        self.have_duals = had_duals;
        self.v = *warm;
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

    fn duals(&self) -> Option<Duals<F, N>> {
        let [up, lo, ac, de, sa] = &self.fam;
        self.have_duals.then_some(Duals {
            upper: up.lam,
            lower: lo.lam,
            accel: ac.lam,
            decel: de.lam,
            safety: sa.lam,
        })
    }

    fn advance(&mut self) {
        let last = N.saturating_sub(1);
        for f in self.fam.iter_mut() {
            f.lam = core::array::from_fn(|k| get(&f.lam, (k + 1).min(last)));
        }
    }
}

impl<F: Real, const N: usize> IpmSolver<F, N> {
    /// [`MpcSolver::solve`], reporting every iteration to `trace`.
    // Not inlined into the planner: its work vectors then take stack only while it runs,
    // not for the whole of the caller's step (the firmware's peak stack).
    #[inline(never)]
    pub fn solve_traced(
        &mut self,
        pr: &SingleLaneProblem<F, N>,
        warm_start: Option<&[F; N]>,
        trace: &mut dyn FnMut(IterationInfo<F>),
    ) -> Result<Solution<F, N>, SolveError> {
        let st = self.settings;
        // Rounding floor of the primal residual: a few ulp of the largest quantity.
        let floor_p = F::from_f64(16.0) * F::EPSILON * (pr.gap.abs() + F::from_f64(100.0));
        let tol_p = st.tol + floor_p;
        // Newton steps a failed active-set attempt spent, counted in the answer.
        let mut spent = 0;
        let warm = warm_start.filter(|w| w.iter().all(|x| x.is_finite()));
        let had_duals = self.have_duals;
        let raised = match warm {
            Some(w) if self.active_set_enabled() => {
                match self.active_set_solve(pr, w, tol_p, trace) {
                    Ok(sol) => return Ok(sol),
                    Err(n) => spent = n,
                }
                // `v` holds the restart point the failed attempt chose.
                self.start(pr, true, st.adaptive_warm_barrier)
            }
            _ => self.initialize(pr, warm),
        };
        let mut result = self.interior_point(pr, tol_p, spent, trace);
        // One retry, from the warm start at the fixed barrier, when the first attempt's
        // barrier was raised to the start's violation: in f32 near vmax that start has
        // been seen to collapse the complementarity before the dual residual converges
        // (12 failures in the 247.5 M steps of the 10,000-platoon sweep, every one
        // solved in 2–5 steps by the fixed barrier). The retry is bounded like the
        // first attempt (`max_iter`) and runs only when an answer would otherwise be
        // the fallback.
        if let (Err((_, steps)), Some(w), true) = (&result, warm, raised) {
            let spent = spent + *steps;
            self.restore_start(w, had_duals);
            self.start(pr, true, false);
            result = self.interior_point(pr, tol_p, spent, trace);
        }
        result.map_err(|(e, _)| e)
    }

    /// The interior-point iteration from the start [`IpmSolver::start`] left, `spent`
    /// Newton steps already taken by this solve; on failure, the error and the steps it
    /// took. Each iteration: residuals and the convergence test, the Newton matrix, the
    /// predictor–corrector direction (Mehrotra), the step to a fraction of the boundary.
    fn interior_point(
        &mut self,
        pr: &SingleLaneProblem<F, N>,
        tol_p: F,
        spent: u32,
        trace: &mut dyn FnMut(IterationInfo<F>),
    ) -> Result<Solution<F, N>, (SolveError, u32)> {
        let st = self.settings;
        self.have_duals = false;
        let m = F::from_usize(FAMILIES * N);
        // A deadline counts the Newton steps this solve already took.
        let cap = if st.answer_at_cap {
            st.max_iter.saturating_sub(spent)
        } else {
            st.max_iter
        };
        for it in 0..cap {
            let (max_rd, scale, max_rp, gap_sum) = self.residuals(pr);
            if !(gap_sum.is_finite() && max_rd.is_finite() && max_rp.is_finite()) {
                return Err((SolveError::NonFinite, it));
            }
            let v = self.v;
            // J is needed only for the gap test (and the trace): skip it while the
            // residuals are still large.
            let feasible_enough = max_rp <= tol_p && max_rd <= st.tol_dual * scale;
            let obj = if feasible_enough {
                pr.objective(&v)
            } else {
                F::ZERO
            };
            let mut info = IterationInfo {
                iteration: it,
                objective: obj,
                primal_residual: max_rp,
                dual_residual: max_rd,
                mu: gap_sum / m,
                step: F::ZERO,
                method: Method::InteriorPoint,
            };
            if feasible_enough && gap_sum <= st.tol * (F::ONE + obj.abs()) {
                trace(info);
                self.have_duals = true;
                return Ok(Solution {
                    v,
                    objective: obj,
                    iterations: it + spent,
                    method: Method::InteriorPoint,
                });
            }
            let mu = gap_sum / m;
            if self.factor_newton_matrix(pr).is_err() {
                return Err((SolveError::Numerical { iteration: it }, it));
            }
            let alpha_max = self.predictor_corrector(m, mu);
            // Fraction to the boundary τ → 1 as μ → 0: near the optimum the blocking
            // slacks are the active constraints', which the Newton step sends to ~0, so
            // a fixed τ would cap every step at τ and converge only linearly.
            // Capped below 1 so that no slack or dual is ever driven to exactly zero.
            let tau = st.step_fraction.max(F::ONE - mu).min(F::from_f64(TAU_MAX));
            let alpha = (tau * alpha_max).min(F::ONE);
            info.step = alpha;
            trace(info);
            if !(alpha > F::ZERO) {
                return Err((SolveError::Numerical { iteration: it }, it));
            }
            self.take_step(alpha);
        }
        if st.answer_at_cap && self.v.iter().all(|x| x.is_finite()) {
            // The deadline: the iterate, for the planner to verify. Its multipliers are
            // kept, positive, for the next warm start.
            self.have_duals = true;
            return Ok(Solution {
                v: self.v,
                objective: pr.objective(&self.v),
                iterations: cap + spent,
                method: Method::Capped,
            });
        }
        Err((
            SolveError::IterationLimit {
                iterations: cap + spent,
            },
            cap,
        ))
    }

    /// At the current iterate: the largest dual residual and its scale, the largest
    /// primal residual |g + s| and the complementarity gap Σ s·λ.
    fn residuals(&mut self, pr: &SingleLaneProblem<F, N>) -> (F, F, F, F) {
        self.evaluate(pr);
        let (max_rd, scale) = self.dual_residual(pr);
        let mut max_rp = F::ZERO;
        let mut gap_sum = F::ZERO;
        for f in self.fam.iter() {
            for ((&g, &s), &l) in f.g.iter().zip(f.s.iter()).zip(f.lam.iter()) {
                max_rp = max_rp.max((g + s).abs());
                gap_sum += s * l;
            }
        }
        (max_rd, scale, max_rp, gap_sum)
    }

    /// Newton matrix ∇²J + Σ λ ∇²g + Σ (λ/s) ∇g ∇gᵀ (+ δ I), assembled and factorised;
    /// `Err` when the factorisation meets a pivot below the floor.
    fn factor_newton_matrix(
        &mut self,
        pr: &SingleLaneProblem<F, N>,
    ) -> Result<(), NotPositiveDefinite> {
        let st = self.settings;
        let two = F::TWO;
        let w = pr.weights;
        let inv_b = F::ONE / pr.brake;
        for f in self.fam.iter_mut() {
            for (is, &s) in f.inv_s.iter_mut().zip(f.s.iter()) {
                *is = F::ONE / s;
            }
            for (il, &l) in f.inv_l.iter_mut().zip(f.lam.iter()) {
                *il = F::ONE / l;
            }
        }
        let [up, lo, ac, de, sa] = &self.fam;
        for k in 0..N {
            let ls = get(&sa.lam, k);
            put(
                &mut self.w1,
                k,
                two * w.reference_speed
                    + get(&up.lam, k) * get(&up.inv_s, k)
                    + get(&lo.lam, k) * get(&lo.inv_s, k)
                    + ls * inv_b,
            );
            put(
                &mut self.w2,
                k,
                two * w.smoothness
                    + get(&ac.lam, k) * get(&ac.inv_s, k)
                    + get(&de.lam, k) * get(&de.inv_s, k),
            );
            put(&mut self.w3, k, ls * get(&sa.inv_s, k));
        }
        self.assemble(two * w.target_position * pr.h * pr.h);
        // The unregularised matrix is only needed by iterative refinement.
        if st.refinement_steps > 0 {
            self.kkt_raw.clone_from(&self.kkt);
        }
        for d in self.kkt.d.iter_mut() {
            *d += st.regularization;
        }
        self.kkt.factor(st.pivot_floor)
    }

    /// Mehrotra's predictor (affine scaling) and corrector on the factorised matrix; the
    /// direction is left in `dz`, `ds`, `dl`, and the longest step to the boundary along
    /// it returned.
    fn predictor_corrector(&mut self, m: F, mu: F) -> F {
        let st = self.settings;
        // Predictor (affine scaling): rc = s∘λ.
        for f in self.fam.iter_mut() {
            for ((rc, &s), &l) in f.rc.iter_mut().zip(f.s.iter()).zip(f.lam.iter()) {
                *rc = s * l;
            }
        }
        self.build_rhs();
        self.newton_solve(st.refinement_steps);
        let alpha_aff = self.recover_and_step_length().min(F::ONE);
        let mut mu_aff = F::ZERO;
        for f in self.fam.iter() {
            for (((&s, &l), &ds), &dl) in
                f.s.iter()
                    .zip(f.lam.iter())
                    .zip(f.ds.iter())
                    .zip(f.dl.iter())
            {
                mu_aff += (s + alpha_aff * ds) * (l + alpha_aff * dl);
            }
        }
        mu_aff = mu_aff / m;
        let ratio = (mu_aff / mu).max(F::ZERO).min(F::ONE);
        let sigma = ratio * ratio * ratio;

        // Corrector: rc = s∘λ + Δs_aff∘Δλ_aff − σμ.
        for f in self.fam.iter_mut() {
            for ((((rc, &s), &l), &ds), &dl) in
                f.rc.iter_mut()
                    .zip(f.s.iter())
                    .zip(f.lam.iter())
                    .zip(f.ds.iter())
                    .zip(f.dl.iter())
            {
                *rc = s * l + ds * dl - sigma * mu;
            }
        }
        self.build_rhs();
        self.newton_solve(st.refinement_steps);
        self.recover_and_step_length()
    }

    /// The step of length `alpha` along the direction: v_k += α (dz_k − dz_{k−1}), and
    /// the slacks and duals.
    fn take_step(&mut self, alpha: F) {
        let mut dz_prev = F::ZERO;
        for (v, &dz) in self.v.iter_mut().zip(self.dz.iter()) {
            *v += alpha * (dz - dz_prev);
            dz_prev = dz;
        }
        for f in self.fam.iter_mut() {
            for (((s, l), &ds), &dl) in
                f.s.iter_mut()
                    .zip(f.lam.iter_mut())
                    .zip(f.ds.iter())
                    .zip(f.dl.iter())
            {
                *s += alpha * ds;
                *l += alpha * dl;
            }
        }
    }
}

#[inline(always)]
fn put<F: Real>(a: &mut [F], i: usize, x: F) {
    if let Some(slot) = a.get_mut(i) {
        *slot = x;
    }
}
