//! The multi-lane planner (Sec. IV–V, SPEC §5–6): the MPC for lane change (13) on the
//! unicycle (1), the Lane Change Protocol (16)–(18), the Yield Protocol (20)(21), dead
//! ends (22) and the commitment distance (23)(24).
//!
//! One step, data flowing one way: observation → protocol bookkeeping (ℓ, α, β) → front
//! sets and x̄ (15)(21)(22) → free space and Ω (28)–(31) → speeds (the convex part of
//! (13), our interior-point solver, with dH in V^k_t) → yaw rates (the linearised
//! lateral QP of [`crate::lateral`]) → verification on the exact model → command.
//!
//! Certified fallback. Lemma 7 shows that while dH > dL some braking motion with a
//! turning radius in ⟦ρH⟧ stays in the band and stops. We apply one concrete motion —
//! max braking (Lemma 2) with maximal straightening, ω = −sign θ · min(|θ|/h, v/ρmin)
//! — and certify it directly rather than through the lemma's geometry: a command is
//! applied only if, from the state it leads to, this braking motion keeps the vehicle's
//! exact L × W rectangle inside its band and its heading within bounds until it stops
//! ([`braking_tail_ok`]). So at every step the fallback is known safe before it is
//! needed; longitudinally it is Lemma 2's, certified by the invariant toward (15).
//!
//! One file per concept, in the order of the step: `gaps` (who is around: the sets
//! (15)(21), x̄ and the leader's credit, vehicles behind for (17)), `protocol` (ℓ, α,
//! β: declaring, starting, completing, re-centring), `reference` (the S-curves),
//! `steer` (the lateral QP's yaw rates), `certify` (the exact check and the fallback's
//! braking tail) and `commitment` ((23)(24)). This file holds the planner, its inputs
//! and outputs, and the step that runs them in order.

use crate::free_space::FreeSpace;
use crate::lanes::{Other, Road};
use crate::lateral::{LateralWeights, LateralWork};
use crate::mpc::CostWeights;
use crate::params::Params;
use crate::planner::{
    free_road_gap, in_range, ConfigError, FallbackReason, InputError, Planner, StepStatus,
};
use crate::real::Real;
use crate::reuse::ReusePolicy;
use crate::safety::{self, Invariant};
use crate::sensing::Sensing;
use crate::solver::{IpmSolver, MpcSolver};
use crate::unicycle::Pose;

mod certify;
mod commitment;
mod gaps;
mod protocol;
mod reference;
mod steer;

pub use certify::{braking_tail_ok, straighten, verify_lateral};
pub use commitment::{commitment_distance, d_c, lane_change_length};
pub use reference::recentre_length;
use reference::Reference;
use steer::straightening_plan;

/// Heading (rad) below which a vehicle may start a lane change, and must be to end one:
/// changes start and end (nearly) parallel to the road, as Lemma 12's S-curve does.
pub const STRAIGHT_HEADING_RAD: f64 = 0.02;
/// How close (m) to the new lane's centre line a change must have come to complete.
/// Lemma 12's S-curve ends on the centre line. Completing as soon as the rectangle is
/// inside the new lane (as this planner first did) can leave a vehicle a few cm from the
/// lane's edge; once its heading is straightened there, no turn within the horizon
/// keeps its rear corner inside the lane (the rear swings out by (L/2)θ before y gains),
/// so it never steers again and a second change never starts (the dead-end sweep's
/// failures). 0.6 m from the centre leaves 0.35 m to the edge. Until the change
/// completes its band spans both lanes, so the S-curve can finish.
pub const CENTRED_M: f64 = 0.6;
/// Offset (m) from its lane's centre line beyond which a vehicle with no change under way
/// steers back along an S-curve (a quintic like a change's, see [`recentre_length`]). A
/// change completes up to [`CENTRED_M`] off the line, and the lateral QP alone, tracking
/// the line with a straight heading over its short horizon, closes such an offset only
/// over hundreds of metres — a vehicle that must be centred to hand over at a junction
/// would reach the stop line first.
pub const RECENTRE_M: f64 = 0.05;
/// Margin (m) by which the lateral QP tightens the band: the QP's linearisation and
/// move blocking are approximate; 5 cm keeps the exact check from failing on them.
pub const LATERAL_MARGIN_M: f64 = 0.05;
/// Margin (rad) by which the lateral QP tightens the heading bounds, for the same reason.
pub const HEADING_MARGIN_RAD: f64 = 0.01;
/// Shortest lane-change reference (m): a quintic S-curve over 3.6 m is steeper than
/// θmax = π/6 below ~13 m; 16 m keeps its heading ≤ 0.4 rad.
pub const MIN_CHANGE_LENGTH_M: f64 = 16.0;
/// Age (s), beyond the latency the bus adds to the paper's synchronous exchange (the
/// notification latency bound less h: [`LanePlanner::set_notify_latency`]), at which a
/// vehicle's data counts as stale (SPEC §9): a lane change does not start while any
/// vehicle behind in the target lane is known only from data this old. 0.25 s is 25
/// periods: far beyond the in-process bus (age 0) and a CAN bus with tens of ms of
/// delay, yet short next to the seconds a lane change takes.
///
/// Why beyond the bus's latency: on a bus whose messages take 1 s, every message is 1 s
/// old when it arrives, so a fixed 0.25 s made every vehicle behind stale for good and no
/// lane change could start (the fault grid's multi-lane road at 1 s of delay and 50 %
/// loss ended with a vehicle 259 m of free lane beside it, never changing). (17) is
/// inflated by the data's age and the latency bound either way; staleness only says that
/// data is older than the bus explains.
pub const STALE_AFTER_S: f64 = 0.25;

/// Steps to which the bus rounds broadcast values (0: exact).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Resolution<F> {
    position: F,
    speed: F,
}

impl<F: Real> Resolution<F> {
    const EXACT: Self = Self {
        position: F::ZERO,
        speed: F::ZERO,
    };
}

/// `x` rounded to a multiple of `step` (half away from zero, as can-gateway encodes),
/// computed in f64 like the decoder so that a decoded value rounds to itself; `x` when
/// `step` is 0.
fn round_to<F: Real>(x: F, step: F) -> F {
    if !(step > F::ZERO) {
        return x;
    }
    let s = step.to_f64();
    F::from_f64(libm::round(x.to_f64() / s) * s)
}

/// Slack (s) when comparing the time β has been held with the notification bound: the
/// held time is a sum of periods in floating point; 1 µs is far below one period.
pub const NOTIFY_SLACK_S: f64 = 1e-6;
/// The longest braking tail the certificate simulates: vmax/(|amin| h) steps is 352 for
/// Table I; the cap makes the loop bounded for any validated parameters.
pub const MAX_TAIL_STEPS: usize = 8192;

/// Why a lane change may not start now ([`LanePlanner::start_check`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum StartBlock {
    /// The heading is not yet straight.
    Heading,
    /// (16) fails toward the vehicles ahead in {ℓ, m} (or the road end).
    Ahead,
    /// (17) fails toward this vehicle behind in the target lane.
    Behind(u16),
    /// This vehicle behind in the target lane is known only from stale data.
    Stale(u16),
    /// Lemma 8's free-space condition fails.
    FreeSpace,
}

/// The lane event of a step, if any.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum LaneEvent {
    /// β set: the intention to change to this lane is declared.
    Declared(u8),
    /// α set: the change to this lane started (the Lane Change Protocol held).
    Started(u8),
    /// The change ended: this is now ℓ.
    Completed(u8),
}

/// What the ego knows at time t on a multi-lane road.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LaneObservation<'a, F> {
    /// Pose at t.
    pub pose: Pose<F>,
    /// v_{t−h}.
    pub v_prev: F,
    /// ω_{t−h}.
    pub omega_prev: F,
    /// The other vehicles (latest messages).
    pub others: &'a [Other<F>],
    /// The road.
    pub road: Road<F>,
    /// The lane the vehicle wants to end up in (its mission).
    pub target_lane: u8,
    /// x^f − x_t for the cost (ignored when its weight is 0).
    pub target: F,
    /// Reference speed.
    pub v_ref: F,
}

/// The command for [t, t+h) and the vehicle's lane bookkeeping after this step (what it
/// broadcasts next).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LaneCommand<F> {
    /// v_t (m/s).
    pub v: F,
    /// ω_t (rad/s).
    pub omega: F,
    /// How it was obtained.
    pub status: StepStatus<F>,
    /// ℓ.
    pub lane: u8,
    /// α.
    pub alpha: Option<u8>,
    /// β.
    pub beta: Option<u8>,
    /// The lane event of this step.
    pub event: Option<LaneEvent>,
    /// The gap x̄_t − x_t used (m).
    pub gap: F,
    /// Iterations of the lateral QP (0 if not solved this step).
    pub lateral_iterations: u32,
}

/// Bad multi-lane input: nothing changed; apply [`LanePlanner::braking_command`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum LaneInputError {
    /// The speed part is invalid.
    Speed(InputError),
    /// A pose, rate, other vehicle or road field is NaN or infinite.
    NotFinite,
    /// The road has no lanes, or a lane index (own, target, another vehicle's) is not on it.
    NoSuchLane,
    /// The lane width is not wider than the vehicle.
    LaneTooNarrow,
    /// The vehicle's reference point is outside its band.
    OutsideBand,
}

/// The first sentence of each variant's documentation (and its data).
impl core::fmt::Display for LaneInputError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Speed(e) => write!(f, "the speed part is invalid: {e}"),
            Self::NotFinite => f.write_str("a pose, rate, other vehicle or road field is NaN or infinite"),
            Self::NoSuchLane => f.write_str("the road has no lanes, or a lane index (own, target, another vehicle's) is not on it"),
            Self::LaneTooNarrow => f.write_str("the lane width is not wider than the vehicle"),
            Self::OutsideBand => f.write_str("the vehicle's reference point is outside its band"),
        }
    }
}

impl core::error::Error for LaneInputError {
    fn source(&self) -> Option<&(dyn core::error::Error + 'static)> {
        match self {
            Self::Speed(e) => Some(e),
            _ => None,
        }
    }
}

/// One vehicle's multi-lane planner with horizon `N` and speed solver `S`.
///
/// Each [`step`](LanePlanner::step) runs the Lane Change Protocol (16)(17) and Yield
/// (20)(21) toward `target_lane`, plans speed (10)(13) and steering, and verifies the
/// command on the exact unicycle (1), else the certified fallback.
///
/// # Examples
///
/// A change from lane 0 to lane 1 beside a car in lane 1, heard over V2V:
///
/// ```
/// use planner_core::heapless::Vec;
/// use planner_core::{
///     CostWeights, Instant, LaneEvent, LaneObservation, LanePlanner, Params, Pose, Road,
///     VehicleState, WorldView,
/// };
///
/// let p = Params::<f32>::table_i();
/// let mut lp = LanePlanner::<f32, 20>::new(p, CostWeights::default(), 0)?;
/// let road = Road { lanes: 2, lane_width: 3.6, end_x: None };
/// let mut view = WorldView::<f32, 8>::new(2);
/// let mut others = Vec::new();
/// let (mut pose, mut v, mut omega) = (Pose { x: 0.0, y: 1.8, theta: 0.0 }, 15.0, 0.0);
/// let mut done = false;
/// for k in 0..600u64 {
///     let now = Instant::from_millis(10 * k);
///     // What the bus delivered this period: the car, 40 m ahead in lane 1.
///     let car = VehicleState {
///         id: 3, x: 40.0 + 0.15 * k as f32, y: 5.4, theta: 0.0, v: 15.0, omega: 0.0,
///         lane: 1, alpha: None, beta: None, stamp: now, cooperative: true, brake: None,
///         length: None,
///     };
///     view.update(&car, now)?;
///     view.others(now, p.length(), &mut others);
///     let obs = LaneObservation {
///         pose, v_prev: v, omega_prev: omega, others: &others, road,
///         target_lane: 1, target: 0.0, v_ref: 15.0,
///     };
///     let cmd = lp.step(&obs)?;
///     pose = planner_core::unicycle::step(pose, cmd.v, cmd.omega, p.h());
///     (v, omega) = (cmd.v, cmd.omega);
///     if cmd.event == Some(LaneEvent::Completed(1)) {
///         done = true;
///         break;
///     }
/// }
/// assert!(done && pose.y > 3.6);
/// # Ok::<(), Box<dyn core::error::Error>>(())
/// ```
#[derive(Debug, Clone)]
pub struct LanePlanner<F, const N: usize, S = IpmSolver<F, N>> {
    speed: Planner<F, N, S>,
    lateral_weights: LateralWeights<F>,
    lane: u8,
    alpha: Option<u8>,
    beta: Option<u8>,
    beta_steps: u32,
    /// Bound on how long the others take to hear this vehicle's broadcast (≥ h).
    notify: F,
    /// Steps to which the bus rounds positions and speeds (0: exact).
    resolution: Resolution<F>,
    /// The ego's own range sensors, if any (their returns come as `sensed` others).
    sensing: Option<Sensing<F>>,
    /// Steps planned so far (saturating): until the notification bound has passed, a
    /// vehicle without sensors may not yet have heard of everyone.
    steps: u32,
    omega_plan: [F; N],
    reference: Option<Reference<F>>,
    /// The lateral QP's storage, here rather than on the stack.
    lateral: LateralWork<F>,
    /// The invariant kept toward the vehicle ahead.
    invariant: Invariant,
    /// The braking limit (m/s²) a vehicle behind is taken at when it declares none
    /// ([`LanePlanner::set_weakest_brake`]).
    weakest_brake: F,
}

impl<F: Real, const N: usize> LanePlanner<F, N, IpmSolver<F, N>> {
    /// A planner in `lane` using our interior-point solver.
    pub fn new(params: Params<F>, weights: CostWeights<F>, lane: u8) -> Result<Self, ConfigError> {
        Self::with_solver(params, weights, IpmSolver::default(), lane)
    }

    /// The placeholder a [`crate::slot::LanePlannerSlot`] holds before its `init` (all
    /// zeros, parameters not valid, never stepped).
    pub(crate) const fn unset() -> Self {
        Self {
            speed: Planner::unset(),
            lateral_weights: LateralWeights {
                position: F::ZERO,
                heading: F::ZERO,
                rate: F::ZERO,
                rate_change: F::ZERO,
            },
            lane: 0,
            alpha: None,
            beta: None,
            beta_steps: 0,
            notify: F::ZERO,
            resolution: Resolution::EXACT,
            sensing: None,
            steps: 0,
            omega_plan: [F::ZERO; N],
            reference: None,
            lateral: LateralWork::new(),
            invariant: Invariant::Paper,
            weakest_brake: F::ZERO,
        }
    }

    /// Makes this planner what [`LanePlanner::new`] would build, in place (no temporary
    /// of the planner's size). Invalid weights are refused and change nothing.
    pub(crate) fn rebuild(
        &mut self,
        params: Params<F>,
        weights: CostWeights<F>,
        lane: u8,
    ) -> Result<(), ConfigError> {
        // Every field named: a field added to the planner must be reset here too (the
        // compiler says so), as `with_solver` must build it.
        let Self {
            speed,
            lateral_weights,
            lane: own_lane,
            alpha,
            beta,
            beta_steps,
            notify,
            resolution,
            sensing,
            steps,
            omega_plan,
            reference,
            lateral,
            invariant,
            weakest_brake,
        } = self;
        speed.rebuild(params, weights)?;
        *lateral_weights = LateralWeights::default();
        *own_lane = lane;
        *alpha = None;
        *beta = None;
        *beta_steps = 0;
        *notify = params.h();
        *resolution = Resolution::EXACT;
        *sensing = None;
        *steps = 0;
        omega_plan.fill(F::ZERO);
        *reference = None;
        lateral.clear();
        *invariant = Invariant::Paper;
        *weakest_brake = params.brake();
        Ok(())
    }

    /// Sets its speed MPC's solver settings: [`Planner::set_solver_settings`].
    pub fn set_solver_settings(&mut self, settings: crate::solver::Settings<F>) {
        self.speed.set_solver_settings(settings);
    }

    /// Its speed MPC's solver settings.
    pub fn solver_settings(&self) -> &crate::solver::Settings<F> {
        self.speed.solver().settings()
    }
}

impl<F: Real, const N: usize, S: MpcSolver<F, N>> LanePlanner<F, N, S> {
    /// A planner in `lane` whose speed problems are solved by `solver`.
    pub fn with_solver(
        params: Params<F>,
        weights: CostWeights<F>,
        solver: S,
        lane: u8,
    ) -> Result<Self, ConfigError> {
        Ok(Self {
            speed: Planner::with_solver(params, weights, solver)?,
            lateral_weights: LateralWeights::default(),
            lane,
            alpha: None,
            beta: None,
            beta_steps: 0,
            notify: params.h(),
            resolution: Resolution::EXACT,
            sensing: None,
            steps: 0,
            omega_plan: [F::ZERO; N],
            reference: None,
            lateral: LateralWork::new(),
            invariant: Invariant::Paper,
            weakest_brake: params.brake(),
        })
    }

    /// Gives the planner its own range sensors ([`crate::sensing`]): their returns, passed
    /// among `LaneObservation::others` with `sensed = true`, are used at their worst case
    /// within the error bounds, and space they do not cover is not taken as free. `None`
    /// (the default) is the paper's world, where every vehicle is known from V2V alone.
    /// Invalid values are refused and change nothing.
    pub fn set_sensing(&mut self, sensing: Option<Sensing<F>>) -> Result<(), ConfigError> {
        if let Some(s) = &sensing {
            s.validate(self.params())?;
        }
        self.sensing = sensing;
        Ok(())
    }

    /// Lets the speed planner reuse its previous plan when it is verified and certified
    /// near-optimal ([`crate::reuse`], [`Planner::set_reuse`]); `None` solves every step.
    pub fn set_reuse(&mut self, policy: Option<ReusePolicy<F>>) -> Result<(), ConfigError> {
        self.speed.set_reuse(policy)
    }

    /// Sets a bound on the time until every other vehicle has heard what this one
    /// broadcasts (delay, jitter and repeated losses on a real bus; SPEC §9). The default,
    /// h, is the paper's synchronous exchange: what is sent now is known next period.
    /// With more, the change starts only after β has been out that long, and (17) assumes
    /// each vehicle behind may go on unaware for the extra time (at vmax, gaining amax).
    /// Values below h count as h; a non-finite value is refused and changes nothing.
    pub fn set_notify_latency(&mut self, latency: F) -> Result<(), ConfigError> {
        if !latency.is_finite() {
            return Err(ConfigError::InvalidLatency);
        }
        self.notify = latency.max(self.params().h());
        Ok(())
    }

    /// The notification latency bound in use.
    pub fn notify_latency(&self) -> F {
        self.notify
    }

    /// Sets the steps to which the bus rounds the positions and speeds every vehicle
    /// broadcasts (to nearest; e.g. can-gateway's 0.01 m and 0.02 m/s). Two things follow:
    /// ≺ is decided on rounded values, this vehicle's own included, so that every vehicle
    /// computes the same order from what it hears (with exact own values, two vehicles
    /// side by side could each see the other behind, and neither yields); and the safety
    /// checks take every other vehicle half a position step longer at each end and, as a
    /// vehicle behind in (17), half a speed step faster. Zero (the default) is exact.
    /// Values that are negative, not finite or ≥ 1 are refused and change nothing.
    pub fn set_bus_resolution(&mut self, position: F, speed: F) -> Result<(), ConfigError> {
        if !(crate::planner::valid_resolution(position) && crate::planner::valid_resolution(speed))
        {
            return Err(ConfigError::InvalidResolution);
        }
        self.resolution = Resolution { position, speed };
        Ok(())
    }

    /// Chooses the invariant kept toward the vehicle ahead (default
    /// [`Invariant::Paper`]). Under [`Invariant::LeaderAware`] a vehicle that leads
    /// ([`safety::leads`], judged by its ghost once its message is old) and whose
    /// braking limit is known over V2V ([`crate::Other::brake`]) is credited with the
    /// least distance it still travels ([`safety::leader_credit`]) from its last
    /// message, however old (docs/spec.md §11, "A credit is never withdrawn"); the lane-change checks
    /// toward vehicles behind, yielding and road ends keep the paper's wall, which
    /// implies the leader-aware invariant (its wall is never farther).
    pub fn set_invariant(&mut self, invariant: Invariant) {
        self.invariant = invariant;
    }

    /// Whether the speed MPC's solve after a fallback starts from the fallback's braking
    /// plan (`true`, the default) or cold: [`Planner::set_warm_from_fallback`], where the
    /// firmware's reason for `false` is measured.
    pub fn set_warm_from_fallback(&mut self, warm: bool) {
        self.speed.set_warm_from_fallback(warm);
    }

    /// See [`LanePlanner::set_warm_from_fallback`].
    pub fn warm_from_fallback(&self) -> bool {
        self.speed.warm_from_fallback()
    }

    /// Sets the braking limit |amin| (m/s²) of the weakest-braking vehicle that may be
    /// behind this one without declaring its own limit (a sensor return, a vehicle that
    /// does not cooperate or sent none): the Lane Change Protocol's check (17) that a
    /// vehicle behind in the target lane can still stop takes it at this limit, and a
    /// cooperating vehicle that declared one at its own ([`Other::brake`]). The paper's
    /// vehicles are all alike, so the default is this vehicle's own limit; in traffic
    /// with trucks it is the trucks' (docs/spec.md §11, "Vehicles of different
    /// sizes"). Values above this vehicle's own limit count as its own (it is itself
    /// such a vehicle to others); one that is not positive and finite is refused and
    /// changes nothing.
    pub fn set_weakest_brake(&mut self, brake: F) -> Result<(), ConfigError> {
        if !(brake.is_finite() && brake > F::ZERO) {
            return Err(ConfigError::InvalidBrake);
        }
        self.weakest_brake = brake.min(self.params().brake());
        Ok(())
    }

    /// The braking limit a vehicle behind that declares none is taken at.
    pub fn weakest_brake(&self) -> F {
        self.weakest_brake
    }

    /// The invariant kept toward the vehicle ahead.
    pub fn invariant(&self) -> Invariant {
        self.invariant
    }

    /// The parameters.
    pub fn params(&self) -> &Params<F> {
        self.speed.params()
    }
    /// ℓ.
    pub fn lane(&self) -> u8 {
        self.lane
    }
    /// α.
    pub fn alpha(&self) -> Option<u8> {
        self.alpha
    }
    /// β.
    pub fn beta(&self) -> Option<u8> {
        self.beta
    }

    /// The certified fallback command from the current state (for use on bad input).
    pub fn braking_command(&self, theta: F, v_prev: F) -> (F, F) {
        let p = self.params();
        let v = safety::max_braking_command(p, v_prev);
        (v, straighten(p, theta, v))
    }

    fn check(&self, obs: &LaneObservation<'_, F>) -> Result<(), LaneInputError> {
        let r = &obs.road;
        let scalars = [
            obs.pose.x,
            obs.pose.y,
            obs.pose.theta,
            obs.v_prev,
            obs.omega_prev,
            obs.target,
            obs.v_ref,
            r.lane_width,
        ];
        if !scalars.iter().all(|x| x.is_finite())
            || r.end_x.is_some_and(|x| !x.is_finite())
            || obs
                .others
                .iter()
                .any(|c| ![c.x, c.v, c.length, c.age].iter().all(|x| x.is_finite()))
        {
            return Err(LaneInputError::NotFinite);
        }
        if !(obs.v_prev >= F::ZERO && obs.v_prev <= self.params().v_max()) {
            return Err(LaneInputError::Speed(InputError::SpeedOutOfRange));
        }
        if !(in_range(&[obs.pose.x, obs.pose.y, obs.target, r.lane_width])
            && r.end_x.is_none_or(|x| in_range(&[x]))
            && obs.others.iter().all(|c| in_range(&[c.x, c.length])))
        {
            return Err(LaneInputError::Speed(InputError::OutOfRange));
        }
        if obs.others.iter().any(|c| !(c.length > F::ZERO)) {
            return Err(LaneInputError::Speed(InputError::BadLength));
        }
        let lanes_ok = |c: &Other<F>| {
            r.has_lane(c.lane)
                && c.alpha.is_none_or(|a| r.has_lane(a))
                && c.beta.is_none_or(|b| r.has_lane(b))
        };
        if !(r.has_lane(self.lane)
            && r.has_lane(obs.target_lane)
            && obs.others.iter().all(lanes_ok))
        {
            return Err(LaneInputError::NoSuchLane);
        }
        if !(r.lane_width > self.params().width()) {
            return Err(LaneInputError::LaneTooNarrow);
        }
        let band = r.band(self.lane, self.alpha);
        let hw = F::HALF * self.params().width();
        if !(band.lo + hw <= obs.pose.y && obs.pose.y <= band.hi - hw) {
            return Err(LaneInputError::OutsideBand);
        }
        Ok(())
    }

    /// One planning step at time t.
    pub fn step(&mut self, obs: &LaneObservation<'_, F>) -> Result<LaneCommand<F>, LaneInputError> {
        self.check(obs)?;
        let p = *self.params();
        let event = self.update_lanes(obs);
        self.recentre(obs);
        if self.beta.is_some() {
            self.beta_steps = self.beta_steps.saturating_add(1);
        }
        let lanes = obs.road.band(self.lane, self.alpha);
        let band = lanes.shrunk(F::HALF * p.width());
        let (safe, all) = self.gaps(obs, self.alpha, self.beta);
        self.steps = self.steps.saturating_add(1);
        let free = free_road_gap(&p, N);
        let gap_all = all.map_or(free, |g| g.min(free));
        let gap_safe = safe.map_or(free, |g| g.min(free));
        // Lane keeping on the centre line, straight: no steering is needed, the free space
        // ahead is the whole gap (d̂H = ∞), and a one-lane road reduces exactly to the
        // single-lane planner; the free-space geometry is skipped.
        let centre = obs.road.lane_centre(self.lane);
        let straight = self.alpha.is_none()
            && obs.pose.theta == F::ZERO
            && obs.omega_prev == F::ZERO
            && obs.pose.y == centre;
        let fs = if straight {
            None
        } else {
            match FreeSpace::new(&p, obs.pose, obs.v_prev, obs.omega_prev, band, gap_all) {
                Ok(fs) => Some(fs),
                Err(_) => return Ok(self.fallback(obs, FallbackReason::Lateral, gap_all, event)),
            }
        };
        let d_h = fs.map_or(gap_all, |f| f.d_h);
        let d_h_hat = fs.and_then(|f| f.d_h_hat);
        let cmd = self
            .speed
            .step_gap(obs.v_prev, d_h, obs.target, obs.v_ref)
            .map_err(LaneInputError::Speed)?;
        match cmd.status {
            StepStatus::Solved { .. } | StepStatus::Reused { .. } => {}
            StepStatus::Fallback(FallbackReason::InvariantViolated) => {
                // Still safe toward (15) and inside the band: the (21) set made it fail.
                let d_safe = d_h_hat.map_or(gap_safe, |d| d.min(gap_safe));
                let why = if safety::invariant_holds(&p, obs.v_prev, d_safe - F::SAFETY_MARGIN_M) {
                    FallbackReason::Yield
                } else {
                    FallbackReason::InvariantViolated
                };
                return Ok(self.fallback(obs, why, d_h, event));
            }
            StepStatus::Fallback(why) => return Ok(self.fallback(obs, why, d_h, event)),
        }
        let v_plan = match self.speed.plan() {
            Some(v) => *v,
            None => return Ok(self.fallback(obs, FallbackReason::Lateral, d_h, event)),
        };
        let (omega, lateral_iterations) = match fs {
            None => ([F::ZERO; N], 0),
            Some(fs) => self.plan_lateral(obs, &fs, &v_plan, lanes),
        };
        let accept = |w: &[F; N]| {
            verify_lateral(&p, obs.pose, &v_plan, w, lanes) && self.entering_ok(obs, &v_plan, w)
        };
        let omega = if accept(&omega) {
            omega
        } else {
            let alt = straightening_plan(&p, obs.pose.theta, &v_plan);
            if accept(&alt) {
                alt
            } else {
                return Ok(self.fallback(obs, FallbackReason::Lateral, d_h, event));
            }
        };
        self.omega_plan = omega;
        let (v, w) = (
            v_plan.first().copied().unwrap_or(F::ZERO),
            omega.first().copied().unwrap_or(F::ZERO),
        );
        Ok(LaneCommand {
            v,
            omega: w,
            status: cmd.status,
            lane: self.lane,
            alpha: self.alpha,
            beta: self.beta,
            event,
            gap: d_h,
            lateral_iterations,
        })
    }

    fn fallback(
        &mut self,
        obs: &LaneObservation<'_, F>,
        why: FallbackReason<F>,
        gap: F,
        event: Option<LaneEvent>,
    ) -> LaneCommand<F> {
        self.speed.set_braking_plan(obs.v_prev);
        let (v, omega) = self.braking_command(obs.pose.theta, obs.v_prev);
        self.omega_plan = [F::ZERO; N];
        LaneCommand {
            v,
            omega,
            status: StepStatus::Fallback(why),
            lane: self.lane,
            alpha: self.alpha,
            beta: self.beta,
            event,
            gap,
            lateral_iterations: 0,
        }
    }
}

#[cfg(test)]
mod audit;
#[cfg(test)]
mod tests;
