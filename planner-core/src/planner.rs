//! The single-lane planner step (Sec. III, Theorem 1): obstacle position x̄ (2)/(22),
//! problem (10), solve, verify against the exact constraints, else the certified
//! max-braking fallback of Lemma 2.
//!
//! Data flows one way: [`Observation`] (what the vehicle knows) → [`Planner::step`] →
//! [`Command`] (what to apply, and why).

use crate::mpc::{ConstraintKind, CostWeights, ProblemError, SingleLaneProblem, Violation};
use crate::params::Params;
use crate::real::Real;
use crate::reuse::{self, ReusePolicy};
use crate::safety::{self, BrakeLimit, Invariant};
use crate::solver::{IpmSolver, Method, MpcSolver, Settings, SolveError};

/// Another vehicle in the ego's lane, as the ego knows it.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Vehicle<F> {
    /// Centre position x(c) along the lane (m); for a vehicle heard over V2V, where it
    /// was at its stamp.
    pub x: F,
    /// Length L(c) (m).
    pub length: F,
    /// Its speed at `x` (m/s), as it broadcast it; read only when `brake` is `Some`.
    pub v: F,
    /// Its braking limit, when the ego may credit it under the leader-aware invariant
    /// ([`Planner::set_invariant`]): a vehicle heard over V2V that cooperates and
    /// declared one ([`crate::WorldView::lane_leaders`] fills it so). `None` — a vehicle
    /// seen only by a sensor, not cooperating, or one that declared no limit — is a wall
    /// that may stop at once, as in Lemma 3.
    pub brake: Option<BrakeLimit>,
    /// The age (s) of `x` and `v` at this step: now − its stamp (0 for a measurement).
    /// A credited vehicle is judged ahead or not by its ghost, the least it has moved
    /// since ([`safety::ghost_advance`]), not by its stamped position, which a follower
    /// that relied on the credit may have passed.
    pub age: F,
}

impl<F: Real> Vehicle<F> {
    /// A vehicle taken as a wall (Lemma 3's leader): at `x`, `length` long, credited
    /// with nothing under either invariant.
    pub const fn wall(x: F, length: F) -> Self {
        Self {
            x,
            length,
            v: F::ZERO,
            brake: None,
            age: F::ZERO,
        }
    }
}

/// What the ego knows at time t.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Observation<'a, F> {
    /// x_t: ego centre position (m).
    pub x: F,
    /// v_{t−h}: the speed applied over the last period (m/s).
    pub v_prev: F,
    /// Vehicles in the lane (any order; those not ahead are ignored, as in (2)).
    pub vehicles: &'a [Vehicle<F>],
    /// Road end or stop line x_R (22), if any (m).
    pub stop_line: Option<F>,
    /// Target position x^f for the cost (m); ignored when its weight is 0.
    pub target_x: F,
    /// Reference speed v_ref for the cost (m/s).
    pub v_ref: F,
}

/// Why the certified fallback was applied.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum FallbackReason<F> {
    /// The invariant x_t < x̄ − dS(v_{t−h}) (with margin) did not hold: (10) may be
    /// infeasible, so the planner brakes as hard as it can.
    InvariantViolated,
    /// Max braking satisfies (10) with less than [`MIN_ROOM_M`] to spare: (10) has
    /// (almost) no interior and max braking is the forced answer, e.g. standing behind a
    /// stopped vehicle. Not a failure.
    NoRoom,
    /// The solver stopped without a solution.
    Solver(SolveError),
    /// The solver's plan failed verification against the exact constraints.
    Verification(Violation<F>),
    /// The Yield Protocol (20)(21): a vehicle ahead in ≺_t that is in, entering or
    /// intending to enter one of the ego's lanes is within dS; the ego brakes until
    /// (20) holds. Not a failure: the invariant toward the front set (15) still holds.
    Yield,
    /// The lane-change step (13) could not be verified on the exact unicycle model
    /// (lateral plan out of the band, Ω or heading bounds): max braking with
    /// straightening, certified one step earlier, is applied.
    Lateral,
}

/// What the planner did this step.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum StepStatus<F> {
    /// The optimal plan was verified and its first input applied.
    Solved {
        /// Solver iterations (Newton steps of the method that answered).
        iterations: u32,
        /// Which method of the solver answered.
        method: Method,
    },
    /// No solve: the previous plan, shifted, was verified against this step's exact
    /// constraints and certified near-optimal by duality ([`crate::reuse`]); its first
    /// input applied. Only with a [`ReusePolicy`] set.
    Reused {
        /// Consecutive steps without a solve, this one included (1 ..= `max_age`).
        age: u8,
        /// Certified bound on J(plan) − J*, the cost given up at this step.
        certified_gap: F,
    },
    /// The certified max-braking fallback (Lemma 2) was applied.
    Fallback(FallbackReason<F>),
}

impl<F> FallbackReason<F> {
    /// The same reason with its number (a violation's amount) converted by `f`, e.g.
    /// `f32` → `f64`: the enum grows (`#[non_exhaustive]`), so a conversion outside this
    /// crate could not be written exhaustively.
    pub fn map<G>(self, f: impl FnOnce(F) -> G) -> FallbackReason<G> {
        match self {
            Self::InvariantViolated => FallbackReason::InvariantViolated,
            Self::NoRoom => FallbackReason::NoRoom,
            Self::Solver(e) => FallbackReason::Solver(e),
            Self::Verification(v) => FallbackReason::Verification(v.map(f)),
            Self::Yield => FallbackReason::Yield,
            Self::Lateral => FallbackReason::Lateral,
        }
    }
}

impl<F> StepStatus<F> {
    /// The same status with its number converted by `f` (see [`FallbackReason::map`]).
    pub fn map<G>(self, f: impl FnOnce(F) -> G) -> StepStatus<G> {
        match self {
            Self::Solved { iterations, method } => StepStatus::Solved { iterations, method },
            Self::Reused { age, certified_gap } => StepStatus::Reused {
                age,
                certified_gap: f(certified_gap),
            },
            Self::Fallback(why) => StepStatus::Fallback(why.map(f)),
        }
    }
}

/// The command to apply over [t, t+h).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Command<F> {
    /// v_t (m/s).
    pub v: F,
    /// How it was obtained.
    pub status: StepStatus<F>,
    /// The gap x̄_t − x_t the planner used (m), before the margin.
    pub gap: F,
}

/// Bad input: nothing was planned and the planner's state is unchanged. The caller should
/// apply [`safety::max_braking_command`] for the step (the safe action whatever happened).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum InputError {
    /// A position, speed, length or target is NaN or infinite.
    NotFinite,
    /// v_{t−h} is negative or above vmax.
    SpeedOutOfRange,
    /// A vehicle length is not positive.
    BadLength,
    /// A coordinate's magnitude exceeds [`Real::MAX_COORD_M`], where the precision's
    /// spacing of representable positions approaches the safety margins.
    OutOfRange,
}

/// The first sentence of each variant's documentation (and its data).
impl core::fmt::Display for InputError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::NotFinite => f.write_str("a position, speed, length or target is NaN or infinite"),
            Self::SpeedOutOfRange => f.write_str("v_{{t−h}} is negative or above vmax"),
            Self::BadLength => f.write_str("a vehicle length is not positive"),
            Self::OutOfRange => f.write_str("a coordinate's magnitude exceeds Real::MAX_COORD_M, where the precision's spacing of representable positions approaches the safety margins"),
        }
    }
}

impl core::error::Error for InputError {}

/// `true` if every value is within ±[`Real::MAX_COORD_M`] (NaN is not).
pub fn in_range<F: Real>(values: &[F]) -> bool {
    values.iter().all(|x| x.abs() <= F::MAX_COORD_M)
}

/// Invalid planner configuration.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum ConfigError {
    /// See [`ProblemError::InvalidWeights`].
    InvalidWeights,
    /// A notification latency that is not a finite number.
    InvalidLatency,
    /// A bus resolution that is negative, not finite, or 1 or more.
    InvalidResolution,
    /// Sensing values that are not finite, ranges below `Sensing::min_range`, or error
    /// bounds outside [0, 1).
    InvalidSensing,
    /// A [`ReusePolicy`] tolerance that is negative or not finite.
    InvalidReuse,
    /// A braking limit that is not a positive finite number.
    InvalidBrake,
}

/// The first sentence of each variant's documentation (and its data).
impl core::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::InvalidWeights => f.write_str("invalid cost weights (see ProblemError::InvalidWeights)"),
            Self::InvalidLatency => f.write_str("a notification latency that is not a finite number"),
            Self::InvalidResolution => f.write_str("a bus resolution that is negative, not finite, or 1 or more"),
            Self::InvalidSensing => f.write_str("sensing values that are not finite, ranges below Sensing::min_range, or error bounds outside [0, 1)"),
            Self::InvalidReuse => f.write_str("a ReusePolicy tolerance that is negative or not finite"),
            Self::InvalidBrake => f.write_str("a braking limit that is not a positive finite number"),
        }
    }
}

impl core::error::Error for ConfigError {}

/// The position x̄_t of the nearest obstacle ahead, extent-adjusted (SPEC §1):
/// min over vehicles c with x(c) > x_t of x(c) − (L(c) + L)/2 − d0, eq. (2), and the stop
/// line x_R − L/2 − d0, eq. (22). `None` when there is neither.
pub fn obstacle_position<F: Real>(
    p: &Params<F>,
    x: F,
    vehicles: &[Vehicle<F>],
    stop_line: Option<F>,
) -> Option<F> {
    obstacle_nearer(
        p,
        x,
        vehicles,
        stop_line,
        F::ZERO,
        (|_, _| F::ZERO, |_| F::ZERO),
    )
}

/// [`obstacle_position`] with every vehicle taken `nearer` metres nearer (a position heard
/// rounded by the bus) and moved ahead by what `credit` credits it with (the leader-aware
/// invariant; given the vehicle and its wall distance x̄(c) − x_t).
fn obstacle_nearer<F: Real>(
    p: &Params<F>,
    x: F,
    vehicles: &[Vehicle<F>],
    stop_line: Option<F>,
    nearer: F,
    (credit, ghost): (impl Fn(&Vehicle<F>, F) -> F, impl Fn(&Vehicle<F>) -> F),
) -> Option<F> {
    let half = F::HALF;
    let mut best: Option<F> = stop_line.map(|xr| xr - half * p.length() - p.d0());
    // A vehicle that may be credited is judged by its ghost (0 for every other one), so
    // that one whose old stamp the ego has passed still counts (`safety::leads`).
    for c in vehicles.iter().filter(|c| c.x + ghost(c) > x) {
        let wall = c.x - half * (c.length + p.length()) - p.d0() - nearer;
        let xb = wall + credit(c, wall - x);
        best = Some(match best {
            Some(b) => b.min(xb),
            None => xb,
        });
    }
    best
}

/// `true` for a usable bus resolution: finite, non-negative, below 1 (m or m/s). Every
/// planner's and the manager's `set_bus_resolution` / `set_resolution` check with it.
pub(crate) fn valid_resolution<F: Real>(r: F) -> bool {
    r.is_finite() && r >= F::ZERO && r < F::ONE
}

/// A gap so large that no safety constraint of an N-step horizon can be active: the
/// farthest the ego can travel in N steps plus dS(vmax), plus 1 m.
pub fn free_road_gap<F: Real>(p: &Params<F>, n: usize) -> F {
    F::from_usize(n) * p.h() * p.v_max() + safety::d_s(p, p.v_max()) + F::ONE
}

/// Slack (m) below which the planner does not call the solver: when the first step of the
/// max-braking plan satisfies the safety constraint of (10) with less than 0.5 mm to
/// spare, the feasible set is a sliver around that plan (a single point when standing
/// behind a stopped vehicle), which interior-point methods cannot centre in; max braking
/// is then applied as the answer. A moving vehicle on the invariant's boundary still has
/// 1.5 |amin| h² ≈ 1.2 mm here, so this only triggers at (near) standstill.
pub const MIN_ROOM_M: f64 = 5e-4;

/// Slack allowed on the linear constraints (speed, acceleration) after the plan has been
/// clamped into them exactly: the rounding of one subtraction of speeds ≤ vmax.
pub fn speed_slack<F: Real>(p: &Params<F>) -> F {
    F::from_f64(8.0) * F::EPSILON * (p.v_max() + F::ONE)
}

/// One vehicle's single-lane MPC planner with horizon `N`, solver `S`.
///
/// Each [`step`](Planner::step) solves (10), verifies the plan's first input against the
/// exact constraints and applies it, else the certified fallback (Lemma 2's maximum
/// braking); an invalid observation is refused with an [`InputError`] and changes nothing.
///
/// # Examples
///
/// A vehicle at 15 m/s behind a car stopped 30 m ahead, toward a stop line at 100 m:
///
/// ```
/// use planner_core::{CostWeights, Observation, Params, Planner, StepStatus, Vehicle};
///
/// let p = Params::<f64>::table_i();
/// let mut planner = Planner::<f64, 20>::new(p, CostWeights::default())?;
/// // Positions heard over CAN are rounded to 0.01 m: each car is taken that much nearer.
/// planner.set_bus_resolution(0.01, 0.02)?;
/// let stopped = [Vehicle::wall(30.0, 4.5)];
/// let (mut x, mut v) = (0.0, 15.0);
/// for _ in 0..1_000 {
///     let obs = Observation {
///         x,
///         v_prev: v,
///         vehicles: &stopped,
///         stop_line: Some(100.0),
///         target_x: 0.0,
///         v_ref: p.v_max(),
///     };
///     let cmd = planner.step(&obs)?;
///     if let StepStatus::Fallback(why) = cmd.status {
///         // Maximum braking, certified safe; standing behind the car it is the answer.
///         let _ = why;
///     }
///     v = cmd.v;
///     x += v * p.h();
/// }
/// // Stopped behind the car: its rear less d0 and half our length.
/// assert_eq!(v, 0.0);
/// assert!(x < 30.0 - 4.5 / 2.0 - p.d0() - 4.5 / 2.0 + 1e-9);
/// # Ok::<(), Box<dyn core::error::Error>>(())
/// ```
#[derive(Debug, Clone)]
pub struct Planner<F, const N: usize, S = IpmSolver<F, N>> {
    params: Params<F>,
    weights: CostWeights<F>,
    solver: S,
    plan: [F; N],
    have_plan: bool,
    reuse: Option<ReusePolicy<F>>,
    /// Steps since the last solve whose duals certify reuse; `None` when the plan is not
    /// a solved one (cold, or a fallback's braking plan).
    age: Option<u8>,
    /// The step to which the bus rounds other vehicles' positions (0: exact).
    resolution: F,
    /// The step to which it rounds their speeds (0: exact).
    speed_resolution: F,
    /// The invariant kept toward the vehicle ahead.
    invariant: Invariant,
    /// Whether a solve after a fallback starts from the braking plan.
    warm_from_fallback: bool,
}

impl<F: Real, const N: usize> Planner<F, N, IpmSolver<F, N>> {
    /// A planner using our interior-point solver with default settings.
    pub fn new(params: Params<F>, weights: CostWeights<F>) -> Result<Self, ConfigError> {
        Self::with_solver(params, weights, IpmSolver::default())
    }

    /// The placeholder a [`crate::slot::PlannerSlot`] holds before its `init`: all
    /// zeros (so a `static` of it sits in `.bss`), parameters *not* valid, never stepped.
    pub(crate) const fn unset() -> Self {
        Self {
            params: Params::unset(),
            weights: CostWeights {
                target_position: F::ZERO,
                reference_speed: F::ZERO,
                smoothness: F::ZERO,
            },
            solver: IpmSolver::new(crate::solver::Settings::unset()),
            plan: [F::ZERO; N],
            have_plan: false,
            reuse: None,
            age: None,
            resolution: F::ZERO,
            speed_resolution: F::ZERO,
            invariant: Invariant::Paper,
            // Not the default: a zero, so that a `static` slot stays in `.bss` (a `true`
            // here moved 30 KB of the firmware's slots into flash); `rebuild` sets it.
            warm_from_fallback: false,
        }
    }

    /// Makes this planner what [`Planner::new`] would build, in place (no temporary of
    /// the planner's size on the stack: [`IpmSolver::reset`]). Invalid weights are
    /// refused and change nothing.
    pub(crate) fn rebuild(
        &mut self,
        params: Params<F>,
        weights: CostWeights<F>,
    ) -> Result<(), ConfigError> {
        check_weights(&weights)?;
        // Every field named: a field added to the planner must be reset here too (the
        // compiler says so), as `with_solver` must build it.
        let Self {
            params: p,
            weights: w,
            solver,
            plan,
            have_plan,
            reuse,
            age,
            resolution,
            speed_resolution,
            invariant,
            warm_from_fallback,
        } = self;
        *p = params;
        *w = weights;
        solver.reset(crate::solver::Settings::default());
        plan.fill(F::ZERO);
        *have_plan = false;
        *reuse = None;
        *age = None;
        *resolution = F::ZERO;
        *speed_resolution = F::ZERO;
        *invariant = Invariant::Paper;
        *warm_from_fallback = true;
        Ok(())
    }

    /// Sets the speed solver's settings (they take effect at the next solve; its warm
    /// state stays): e.g. [`Settings::with_scaled_cold_start`], which the firmware sets.
    pub fn set_solver_settings(&mut self, settings: Settings<F>) {
        self.solver.set_settings(settings);
    }
}

/// [`ConfigError::InvalidWeights`] unless every weight is finite and ≥ 0 and J is strictly
/// convex in v (w_v > 0 or w_Δ > 0).
fn check_weights<F: Real>(weights: &CostWeights<F>) -> Result<(), ConfigError> {
    let w = [
        weights.target_position,
        weights.reference_speed,
        weights.smoothness,
    ];
    if w.iter().any(|x| !x.is_finite() || *x < F::ZERO)
        || !(weights.reference_speed > F::ZERO || weights.smoothness > F::ZERO)
    {
        return Err(ConfigError::InvalidWeights);
    }
    Ok(())
}

impl<F: Real, const N: usize, S: MpcSolver<F, N>> Planner<F, N, S> {
    /// A planner using `solver`.
    pub fn with_solver(
        params: Params<F>,
        weights: CostWeights<F>,
        solver: S,
    ) -> Result<Self, ConfigError> {
        check_weights(&weights)?;
        Ok(Self {
            params,
            weights,
            solver,
            plan: [F::ZERO; N],
            have_plan: false,
            reuse: None,
            age: None,
            resolution: F::ZERO,
            speed_resolution: F::ZERO,
            invariant: Invariant::Paper,
            warm_from_fallback: true,
        })
    }

    /// Sets the steps to which the bus rounds the positions and speeds every vehicle
    /// broadcasts (to nearest; e.g. can-gateway's `wire::POS_RES` and `wire::SPEED_RES`,
    /// 0.01 m and 0.02 m/s), as [`crate::LanePlanner::set_bus_resolution`] does: a vehicle
    /// whose position was heard rounded may be up to half a step nearer, so each is taken
    /// half a position step longer at each end; under [`Invariant::LeaderAware`] a
    /// credited leader's speed may have been rounded up, so it is credited from half a
    /// speed step lower. Zero (the default) is exact. Values that are negative, not
    /// finite or ≥ 1 are refused and change nothing.
    pub fn set_bus_resolution(&mut self, position: F, speed: F) -> Result<(), ConfigError> {
        if !(valid_resolution(position) && valid_resolution(speed)) {
            return Err(ConfigError::InvalidResolution);
        }
        self.resolution = position;
        self.speed_resolution = speed;
        Ok(())
    }

    /// Chooses the invariant kept toward the vehicle ahead (default [`Invariant::Paper`],
    /// Lemma 3's wall). Under [`Invariant::LeaderAware`] each vehicle ahead whose
    /// [`Vehicle::brake`] is `Some` is credited with the least distance it still travels
    /// ([`safety::leader_credit`], from its speed half a bus step lower): x̄ of (2) moves
    /// ahead by that much, and (10)'s safety constraint, the certified fallback and the
    /// verifier all work on the moved x̄ (docs/spec.md §11). The stop line (22) and every
    /// vehicle without a braking limit stay walls.
    pub fn set_invariant(&mut self, invariant: Invariant) {
        self.invariant = invariant;
    }

    /// The invariant kept toward the vehicle ahead.
    pub fn invariant(&self) -> Invariant {
        self.invariant
    }

    /// What vehicle `c`, `wall` metres (x̄(c) − x_t) ahead, is credited with under the
    /// invariant in use: nothing under the paper's, nor for a vehicle without a braking
    /// limit or that does not lead ([`safety::leads`]: its stopping point says nothing
    /// about the ego's way to it).
    fn credit(&self, c: &Vehicle<F>, wall: F) -> F {
        match (self.invariant, c.brake) {
            (Invariant::LeaderAware, Some(b)) => {
                let v = self.credited_speed(c);
                safety::credit_if_leads(&self.params, v, b.mps2(), wall, c.age)
            }
            _ => F::ZERO,
        }
    }

    /// Its speed as credited: half a bus step lower (the bus may have rounded it up).
    fn credited_speed(&self, c: &Vehicle<F>) -> F {
        c.v - F::HALF * self.speed_resolution
    }

    /// How far past its stamped position vehicle `c` is at the least by now under the
    /// leader-aware invariant ([`safety::ghost_advance`]); 0 for a wall.
    fn ghost(&self, c: &Vehicle<F>) -> F {
        match (self.invariant, c.brake) {
            (Invariant::LeaderAware, Some(b)) => {
                safety::ghost_advance(&self.params, self.credited_speed(c), b.mps2(), c.age)
            }
            _ => F::ZERO,
        }
    }

    /// The position step of the bus in use (0: exact).
    pub fn bus_resolution(&self) -> F {
        self.resolution
    }

    /// Lets the planner apply its previous plan, shifted, instead of solving, when that
    /// plan is verified and certified within `policy` of the optimum ([`crate::reuse`]);
    /// `None` (the default) solves every step. Safety is unaffected: every applied
    /// command is verified against the exact constraints either way.
    pub fn set_reuse(&mut self, policy: Option<ReusePolicy<F>>) -> Result<(), ConfigError> {
        if let Some(p) = policy {
            if !(p.tolerance.is_finite() && p.tolerance >= F::ZERO) {
                return Err(ConfigError::InvalidReuse);
            }
        }
        self.reuse = policy;
        Ok(())
    }

    /// The reuse policy in force, if any.
    pub fn reuse(&self) -> Option<ReusePolicy<F>> {
        self.reuse
    }

    /// The speed solver (its duals certify reuse: [`MpcSolver::duals`]).
    pub fn solver(&self) -> &S {
        &self.solver
    }

    /// The parameters.
    pub fn params(&self) -> &Params<F> {
        &self.params
    }

    /// The plan of the last step (v_t .. v_{t+(N−1)h}), if any.
    pub fn plan(&self) -> Option<&[F; N]> {
        self.have_plan.then_some(&self.plan)
    }

    /// Whether a solve after a fallback starts from the fallback's braking plan, shifted
    /// (`true`, the default: every figure in docs/ was measured so), or cold (`false`).
    /// A solve after a solve always starts from that solve's plan and duals.
    ///
    /// Why `false` exists: the braking plan is a vertex of (10)'s feasible set — every
    /// step on its deceleration or lower bound, all of them at v = 0 for a vehicle that
    /// stands — and the interior-point method, started there at the small warm barrier
    /// with no duals that belong to it, creeps along the boundary. Measured on the
    /// firmware in the loop (multi-lane road, vehicle 2 starting a lane change after a
    /// forced stop, N = 20, f32): 32 iterations from the braking plan, 15 cold; that
    /// period's work 1.30 M instructions (over h = 10 ms at 125 MHz) against 0.70 M.
    /// On the host it changes little on average (`host-sim traffic --cases 40`, built
    /// with either default: 2,109,930 solver iterations against 2,107,314, the same
    /// cost), so the default keeps the published figures; a computer with a deadline
    /// sets `false` (the firmware does).
    pub fn set_warm_from_fallback(&mut self, warm: bool) {
        self.warm_from_fallback = warm;
    }

    /// See [`Planner::set_warm_from_fallback`].
    pub fn warm_from_fallback(&self) -> bool {
        self.warm_from_fallback
    }

    /// Forgets the previous plan (next step starts cold).
    pub fn reset(&mut self) {
        self.have_plan = false;
        self.age = None;
    }

    fn check_input(&self, obs: &Observation<'_, F>) -> Result<(), InputError> {
        let scalars = [obs.x, obs.v_prev, obs.target_x, obs.v_ref];
        if !scalars.iter().all(|x| x.is_finite())
            || obs.stop_line.is_some_and(|x| !x.is_finite())
            || obs.vehicles.iter().any(|c| {
                !(c.x.is_finite() && c.length.is_finite() && c.v.is_finite() && c.age.is_finite())
            })
        {
            return Err(InputError::NotFinite);
        }
        if obs.vehicles.iter().any(|c| !(c.length > F::ZERO)) {
            return Err(InputError::BadLength);
        }
        if !(in_range(&[obs.x, obs.target_x])
            && obs.stop_line.is_none_or(|x| in_range(&[x]))
            && obs
                .vehicles
                .iter()
                .all(|c| in_range(&[c.x, c.length]) && c.age >= F::ZERO))
        {
            return Err(InputError::OutOfRange);
        }
        if !(obs.v_prev >= F::ZERO && obs.v_prev <= self.params.v_max()) {
            return Err(InputError::SpeedOutOfRange);
        }
        Ok(())
    }

    /// One planning step at time t.
    pub fn step(&mut self, obs: &Observation<'_, F>) -> Result<Command<F>, InputError> {
        self.check_input(obs)?;
        let p = self.params;
        let free = free_road_gap(&p, N);
        // A position heard rounded may be half a step nearer: each vehicle is taken that
        // much longer at its rear (the stop line is the planner's own, exact).
        let nearer = F::HALF * self.resolution;
        let credit = |c: &Vehicle<F>, wall: F| self.credit(c, wall);
        let ghost = |c: &Vehicle<F>| self.ghost(c);
        let gap = obstacle_nearer(
            &p,
            obs.x,
            obs.vehicles,
            obs.stop_line,
            nearer,
            (credit, ghost),
        )
        .map_or(free, |xb| (xb - obs.x).min(free));
        Ok(self.plan_speed(obs.v_prev, gap, obs.target_x - obs.x, obs.v_ref))
    }

    /// One planning step given the gap x̄_t − x_t directly (for planners that build x̄
    /// from their own vehicle sets, e.g. [`crate::lane_change`]). `target` = x^f − x_t.
    pub fn step_gap(
        &mut self,
        v_prev: F,
        gap: F,
        target: F,
        v_ref: F,
    ) -> Result<Command<F>, InputError> {
        if ![v_prev, gap, target, v_ref].iter().all(|x| x.is_finite()) {
            return Err(InputError::NotFinite);
        }
        if !(v_prev >= F::ZERO && v_prev <= self.params.v_max()) {
            return Err(InputError::SpeedOutOfRange);
        }
        Ok(self.plan_speed(v_prev, gap, target, v_ref))
    }

    fn plan_speed(&mut self, v_prev: F, gap: F, target: F, v_ref: F) -> Command<F> {
        let p = self.params;
        let problem = SingleLaneProblem::<F, N>::new(
            &p,
            v_prev,
            gap,
            F::SAFETY_MARGIN_M,
            self.weights,
            target,
            v_ref,
        );
        let problem = match problem {
            Ok(pr) => pr,
            // Inputs and weights were checked by the callers, so only the invariant can
            // fail here.
            Err(ProblemError::InvariantViolated)
            | Err(ProblemError::NotFinite)
            | Err(ProblemError::SpeedOutOfRange)
            | Err(ProblemError::InvalidWeights) => {
                return self.fallback(v_prev, gap, FallbackReason::InvariantViolated)
            }
        };
        let v_brake = safety::max_braking_command(&p, v_prev);
        let room = -problem.safety_value(p.h() * v_brake, v_brake);
        if room < F::from_f64(MIN_ROOM_M) {
            return self.fallback(v_prev, gap, FallbackReason::NoRoom);
        }
        if let Some(cmd) = self.try_reuse(&problem, gap) {
            return cmd;
        }
        // A fallback's braking plan warm-starts only if asked: see `set_warm_from_fallback`.
        let solved_plan = self.age.is_some();
        let warm = (self.have_plan && (solved_plan || self.warm_from_fallback))
            .then(|| shifted(&self.plan));
        let solution = match self.solver.solve(&problem, warm.as_ref()) {
            Ok(s) => s,
            Err(e) => return self.fallback(v_prev, gap, FallbackReason::Solver(e)),
        };
        match verify(&p, &problem, solution.v) {
            Ok(plan) => {
                self.plan = plan;
                self.have_plan = true;
                self.age = Some(0);
                Command {
                    v: plan.first().copied().unwrap_or(F::ZERO),
                    status: StepStatus::Solved {
                        iterations: solution.iterations,
                        method: solution.method,
                    },
                    gap,
                }
            }
            Err(v) => self.fallback(v_prev, gap, FallbackReason::Verification(v)),
        }
    }

    /// The previous plan, shifted, if the policy allows it, it passes [`verify`] for
    /// `problem` and the solver's duals certify it within the policy's tolerance.
    // Not inlined: its dual bound's work vectors would otherwise sit in every step's frame,
    // reuse or not.
    #[inline(never)]
    fn try_reuse(&mut self, problem: &SingleLaneProblem<F, N>, gap: F) -> Option<Command<F>> {
        let policy = self.reuse?;
        let age = self.age.filter(|&a| a < policy.max_age && self.have_plan)?;
        let plan = verify(&self.params, problem, shifted(&self.plan)).ok()?;
        let duals = self.solver.duals()?.shifted(1);
        // J once: the certificate J − q(λ) and the tolerance's scale both need it.
        let j = problem.objective(&plan);
        let certified_gap = j - reuse::dual_bound(problem, &duals, &plan)?;
        let allowed = policy.tolerance * (F::ONE + j.abs());
        if !(certified_gap <= allowed) {
            return None;
        }
        self.solver.advance();
        self.plan = plan;
        let age = age.saturating_add(1);
        self.age = Some(age);
        Some(Command {
            v: plan.first().copied().unwrap_or(F::ZERO),
            status: StepStatus::Reused { age, certified_gap },
            gap,
        })
    }

    /// Replaces the plan by the max-braking sequence from `v_prev` (used when a caller
    /// applies the fallback for reasons of its own, so the next warm start matches).
    pub fn set_braking_plan(&mut self, v_prev: F) {
        self.plan = safety::max_braking(&self.params, v_prev);
        self.have_plan = true;
        self.age = None;
    }

    fn fallback(&mut self, v_prev: F, gap: F, why: FallbackReason<F>) -> Command<F> {
        self.plan = safety::max_braking(&self.params, v_prev);
        self.have_plan = true;
        self.age = None;
        Command {
            v: safety::max_braking_command(&self.params, v_prev),
            status: StepStatus::Fallback(why),
            gap,
        }
    }
}

/// The previous plan shifted one step (the last speed repeated): the warm start.
pub fn shifted<F: Real, const N: usize>(plan: &[F; N]) -> [F; N] {
    let mut out = *plan;
    out.rotate_left(1.min(N));
    if let (Some(last), Some(prev)) = (N.checked_sub(1), N.checked_sub(2)) {
        let v = out.get(prev).copied().unwrap_or(F::ZERO);
        if let Some(slot) = out.get_mut(last) {
            *slot = v;
        }
    }
    out
}

/// Verifies a plan against the exact constraints of (10).
///
/// The linear constraints (V^k_t and acceleration) are first enforced exactly by clamping
/// each v_k, in order, into [max(lo_k, v_{k−1} + amin h), min(hi_k, v_{k−1} + amax h)];
/// the solver's output violates them by at most its tolerance, so the clamp moves v_k by
/// that much (where rounding leaves the interval empty by less than [`speed_slack`], its
/// lower end is taken). Then every constraint is checked: linear ones within [`speed_slack`],
/// safety within [`Real::VERIFY_SLACK_M`] of the margin-tightened gap, so the exact
/// (untightened) safety constraint holds with `SAFETY_MARGIN_M − VERIFY_SLACK_M` to spare.
pub fn verify<F: Real, const N: usize>(
    p: &Params<F>,
    problem: &SingleLaneProblem<F, N>,
    mut v: [F; N],
) -> Result<[F; N], Violation<F>> {
    let slack = speed_slack(p);
    let mut prev = problem.v_prev;
    for (k, ((vk, &lo), &hi)) in v
        .iter_mut()
        .zip(problem.lo.iter())
        .zip(problem.hi_exact.iter())
        .enumerate()
    {
        let lower = lo.max(prev + problem.dv_min);
        let upper = hi.min(prev + problem.dv_max);
        // The interval can be empty by rounding where V^k_t's upper edge falls at exactly
        // the braking rate; within the slack, take its lower (slower, safer) end.
        if !(lower <= upper + slack) || !vk.is_finite() {
            return Err(Violation {
                amount: lower - upper,
                kind: ConstraintKind::SpeedUpper,
                step: k,
            });
        }
        *vk = if lower > upper {
            lower
        } else {
            vk.max(lower).min(upper)
        };
        prev = *vk;
    }
    let worst = worst_relative(p, problem, &v);
    match worst {
        Some(violation) => Err(violation),
        None => Ok(v),
    }
}

/// The first constraint of the exact (10) exceeded beyond its slack, if any.
fn worst_relative<F: Real, const N: usize>(
    p: &Params<F>,
    problem: &SingleLaneProblem<F, N>,
    v: &[F; N],
) -> Option<Violation<F>> {
    let lin = speed_slack(p);
    let mut found = None;
    let mut exact = problem.clone();
    exact.hi = problem.hi_exact;
    exact.for_each_constraint(v, |amount, kind, step| {
        let slack = match kind {
            ConstraintKind::Safety => F::VERIFY_SLACK_M,
            _ => lin,
        };
        // `!(a <= b)` also catches NaN.
        if !(amount <= slack) {
            found = Some(Violation { amount, kind, step });
            return false;
        }
        true
    });
    found
}
