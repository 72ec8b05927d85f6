//! The single-lane MPC problem (10) as plain data, independent of any solver
//! (Clarabel.rs style: problem data here, the solver in [`crate::solver`]).
//!
//! Decision: speeds v_0..v_{N−1} (v_k = v_{t+kh}). Constraints, for k = 0..N−1:
//! - safety (10): x_{k+1} + dS(v_k) ≤ x̄_t, with x_{k+1} = x_t + h Σ_{j≤k} v_j;
//! - acceleration (10): amin h ≤ v_k − v_{k−1} ≤ amax h, v_{−1} = v_{t−h};
//! - speed region (7): v_k ∈ V^k_t = [lo_k, hi_k].
//!
//! Cost (configurable, SPEC §4 "J is free"):
//! J = w_x (x^f − x_N)² + w_v Σ (v_k − v_ref)² + w_Δ Σ (v_k − v_{k−1})².

use crate::params::Params;
use crate::real::Real;
use crate::safety;

/// Minimum width (m/s) of the speed interval V^k_t handed to a solver.
///
/// Why: beyond tH(v̄_t) the upper profile of V_t is 0 and so is the lower line, so
/// V^k_t = {0}: an equality written as two inequalities, which leaves (10) without an
/// interior point. Interior-point methods (ours and Clarabel) then stall near the
/// boundary. Widening such intervals to [lo, lo + 1e-3] restores an interior; the
/// verifier ([`crate::planner::verify`]) clamps the plan back into the exact V^k_t, which
/// only lowers speeds and so keeps every safety constraint satisfied.
pub const PIN_WIDTH: f64 = 1e-3;

/// Weights of the quadratic cost J.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CostWeights<F> {
    /// w_x: weight of (x^f − x_N)² (1/m²).
    pub target_position: F,
    /// w_v: weight of Σ (v_k − v_ref)² (s²/m²).
    pub reference_speed: F,
    /// w_Δ: weight of Σ (v_k − v_{k−1})² (s²/m²).
    pub smoothness: F,
}

impl<F: Real> CostWeights<F> {
    /// One step's term of J without the target term: w_v (v − v_ref)² + w_Δ (v − v_prev)²
    /// (also what a closed loop pays per applied speed).
    #[inline]
    pub fn stage_cost(&self, v: F, v_prev: F, v_ref: F) -> F {
        self.reference_speed * (v - v_ref).sq() + self.smoothness * (v - v_prev).sq()
    }
}

impl<F: Real> Default for CostWeights<F> {
    /// Track the reference speed, with gentle smoothing; no target position.
    fn default() -> Self {
        Self {
            target_position: F::ZERO,
            reference_speed: F::ONE,
            smoothness: F::from_f64(10.0),
        }
    }
}

/// Why a problem could not be built.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum ProblemError {
    /// A weight is negative or not finite, or both w_v and w_Δ are 0 (J must be strictly
    /// convex for the optimum to be unique and the Newton systems nonsingular).
    InvalidWeights,
    /// An input (position, speed, target) is NaN or infinite.
    NotFinite,
    /// v_{t−h} is outside [0, vmax].
    SpeedOutOfRange,
    /// The safety invariant x_t < x̄ − dS(v_{t−h}) does not hold for the tightened gap:
    /// (10) may be infeasible and Lemma 2 does not apply.
    InvariantViolated,
}

/// The first sentence of each variant's documentation (and its data).
impl core::fmt::Display for ProblemError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::InvalidWeights => f.write_str("a weight is negative or not finite, or both w_v and w_Δ are 0 (J must be strictly convex for the optimum to be unique and the Newton systems nonsingular)"),
            Self::NotFinite => f.write_str("an input (position, speed, target) is NaN or infinite"),
            Self::SpeedOutOfRange => f.write_str("v_{{t−h}} is outside [0, vmax]"),
            Self::InvariantViolated => f.write_str("the safety invariant x_t < x̄ − dS(v_{{t−h}}) does not hold for the tightened gap: (10) may be infeasible and Lemma 2 does not apply"),
        }
    }
}

impl core::error::Error for ProblemError {}

/// One instance of problem (10) in gap coordinates (x_t = 0).
#[derive(Debug, Clone, PartialEq)]
pub struct SingleLaneProblem<F, const N: usize> {
    /// h (s).
    pub h: F,
    /// |amin| (m/s²).
    pub brake: F,
    /// amax h (m/s).
    pub dv_max: F,
    /// amin h (m/s), negative.
    pub dv_min: F,
    /// x̄_t − x_t − margin (m): the gap the constraints use.
    pub gap: F,
    /// v_{t−h} (m/s).
    pub v_prev: F,
    /// Lower ends of V^k_t.
    pub lo: [F; N],
    /// Upper ends of V^k_t as the solver sees them: exact, except that the zero-width tail
    /// of V^k_t is widened by [`PIN_WIDTH`] (see there).
    pub hi: [F; N],
    /// Exact upper ends of V^k_t, eq. (7), which the verifier enforces.
    pub hi_exact: [F; N],
    /// Cost weights.
    pub weights: CostWeights<F>,
    /// x^f − x_t (m).
    pub target: F,
    /// v_ref (m/s).
    pub v_ref: F,
}

/// Which constraint of (10) a check refers to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum ConstraintKind {
    /// v_k ≤ hi_k (V^k_t, upper).
    SpeedUpper,
    /// v_k ≥ lo_k (V^k_t, lower).
    SpeedLower,
    /// v_k − v_{k−1} ≤ amax h.
    Accel,
    /// v_k − v_{k−1} ≥ amin h.
    Decel,
    /// x_{k+1} + dS(v_k) ≤ x̄.
    Safety,
}

/// The largest constraint violation of a plan, in the constraint's own unit.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Violation<F> {
    /// Amount by which the constraint is exceeded (≤ 0 when satisfied).
    pub amount: F,
    /// Which constraint.
    pub kind: ConstraintKind,
    /// At which step k.
    pub step: usize,
}

impl<F> Violation<F> {
    /// The same violation with its amount converted by `f` (e.g. `f32` → `f64` for a log
    /// on a host that mirrors an MCU).
    pub fn map<G>(self, f: impl FnOnce(F) -> G) -> Violation<G> {
        Violation {
            amount: f(self.amount),
            kind: self.kind,
            step: self.step,
        }
    }
}

impl<F: Real, const N: usize> SingleLaneProblem<F, N> {
    /// Builds (10) for the ego at x_t with speed v_{t−h} and obstacle gap x̄_t − x_t.
    /// The gap is tightened by `margin` (see [`Real::SAFETY_MARGIN_M`]).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        p: &Params<F>,
        v_prev: F,
        gap: F,
        margin: F,
        weights: CostWeights<F>,
        target: F,
        v_ref: F,
    ) -> Result<Self, ProblemError> {
        let w = weights;
        let ws = [w.target_position, w.reference_speed, w.smoothness];
        if ws.iter().any(|x| !x.is_finite() || *x < F::ZERO)
            || !(w.reference_speed > F::ZERO || w.smoothness > F::ZERO)
        {
            return Err(ProblemError::InvalidWeights);
        }
        if ![v_prev, gap, margin, target, v_ref]
            .iter()
            .all(|x| x.is_finite())
        {
            return Err(ProblemError::NotFinite);
        }
        if !(v_prev >= F::ZERO && v_prev <= p.v_max()) {
            return Err(ProblemError::SpeedOutOfRange);
        }
        let gap = gap - margin;
        // The verifier accepts plans that exceed the tightened safety constraint by up to
        // VERIFY_SLACK_M, so the next step's invariant test must grant the same slack;
        // the exact invariant still holds with SAFETY_MARGIN_M − VERIFY_SLACK_M > 0.
        if !safety::invariant_holds(p, v_prev, gap + F::VERIFY_SLACK_M) {
            return Err(ProblemError::InvariantViolated);
        }
        let (lo, hi_exact) =
            safety::speed_region::<F, N>(p, v_prev, gap).ok_or(ProblemError::InvariantViolated)?;
        let mut hi = hi_exact;
        let width = F::from_f64(PIN_WIDTH);
        for (h, &l) in hi.iter_mut().zip(lo.iter()) {
            if *h < l + width {
                *h = l + width;
            }
        }
        Ok(Self {
            h: p.h(),
            brake: p.brake(),
            dv_max: p.a_max() * p.h(),
            dv_min: p.a_min() * p.h(),
            gap,
            v_prev,
            lo,
            hi,
            hi_exact,
            weights,
            target,
            v_ref,
        })
    }

    /// The safety function g_k = x_{k+1} + dS(v_k) − x̄ given x_{k+1} − x_t = `pos`.
    #[inline]
    pub fn safety_value(&self, pos: F, v: F) -> F {
        pos + v * self.h + v * v / (F::TWO * self.brake) + F::HALF * self.brake * self.h * self.h
            - self.gap
    }

    /// J evaluated exactly from the speeds (the figure both solvers are compared on).
    pub fn objective(&self, v: &[F; N]) -> F {
        let w = &self.weights;
        let mut prev = self.v_prev;
        let mut pos = F::ZERO;
        let mut j = F::ZERO;
        for &vk in v.iter() {
            pos += vk * self.h;
            j += w.stage_cost(vk, prev, self.v_ref);
            prev = vk;
        }
        j + w.target_position * (self.target - pos).sq()
    }

    /// Calls `visit(g, kind, k)` for every constraint g ≤ 0 of (10), in order of k, until
    /// `visit` returns `false`. The one definition of the constraints that the verifier,
    /// the cross-checks and [`Self::max_violation`] share.
    pub fn for_each_constraint(
        &self,
        v: &[F; N],
        mut visit: impl FnMut(F, ConstraintKind, usize) -> bool,
    ) {
        let mut prev = self.v_prev;
        let mut pos = F::ZERO;
        for (k, ((&vk, &lo), &hi)) in v.iter().zip(self.lo.iter()).zip(self.hi.iter()).enumerate() {
            pos += vk * self.h;
            let values = [
                (vk - hi, ConstraintKind::SpeedUpper),
                (lo - vk, ConstraintKind::SpeedLower),
                (vk - prev - self.dv_max, ConstraintKind::Accel),
                (self.dv_min - (vk - prev), ConstraintKind::Decel),
                (self.safety_value(pos, vk), ConstraintKind::Safety),
            ];
            for (g, kind) in values {
                if !visit(g, kind, k) {
                    return;
                }
            }
            prev = vk;
        }
    }

    /// The largest violation over every constraint of (10) (≤ 0 means feasible; NaN
    /// counts as the worst).
    pub fn max_violation(&self, v: &[F; N]) -> Violation<F> {
        let mut worst = Violation {
            amount: F::from_f64(-1e30),
            kind: ConstraintKind::Safety,
            step: 0,
        };
        self.for_each_constraint(v, |amount, kind, step| {
            if amount > worst.amount || !amount.is_finite() {
                worst = Violation { amount, kind, step };
            }
            amount.is_finite()
        });
        worst
    }
}
