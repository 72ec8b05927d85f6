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

use crate::free_space::{FreeSpace, D_TURN_M};
use crate::lanes::{in_front_set, in_yield_set, may_occupy, Band, Key, Other, Road};
use crate::lateral::{solve_lateral_in, LateralInput, LateralWeights, LateralWork};
use crate::mpc::CostWeights;
use crate::params::Params;
use crate::planner::{
    free_road_gap, in_range, ConfigError, FallbackReason, InputError, Planner, StepStatus,
};
use crate::real::Real;
use crate::reuse::ReusePolicy;
use crate::safety::{self, Invariant};
use crate::sensing::{still_unheard, Sensing};
use crate::solver::{IpmSolver, MpcSolver};
use crate::unicycle::{lateral_half_extent, step, Pose};

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
/// Age (s) beyond which a vehicle's data counts as stale (SPEC §9): a lane change does
/// not start while any vehicle behind in the target lane is known only from data this
/// old. 0.25 s is 25 periods: far beyond the in-process bus (age 0) and a CAN bus with
/// tens of ms of delay, yet short next to the seconds a lane change takes.
pub const STALE_AFTER_S: f64 = 0.25;
/// Membership in the yield set (21), with ≺ decided on where the other vehicle is now by
/// its data (x + v·age): on a bus with latency two vehicles side by side each see the
/// other behind by its data's age, and neither would yield. Exact with age 0.
/// Positions are rounded to the bus's step (`step`), as the ego's own key is.
fn yields_to<F: Real>(
    ego: &Key<F>,
    alpha: Option<u8>,
    beta: Option<u8>,
    c: &Other<F>,
    step: F,
) -> bool {
    let now = Other {
        x: round_to(c.x + c.v * c.age, step),
        ..*c
    };
    in_yield_set(ego, alpha, beta, &now)
}

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

/// The smaller of two optional gaps (`None`: no obstacle).
fn min_gap<F: Real>(a: Option<F>, b: Option<F>) -> Option<F> {
    match (a, b) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    }
}

/// How far a vehicle last seen at speed `v` may have gone in `tau` and how fast it may be
/// by then (SPEC §9: at most amax faster per second, never above vmax).
fn unaware_reach<F: Real>(p: &Params<F>, v: F, tau: F) -> (F, F) {
    let accel = v * tau + F::HALF * p.a_max() * tau * tau;
    let reach = accel.min(p.v_max() * tau);
    (reach, (v + tau * p.a_max()).min(p.v_max()))
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

/// Length (m) of the S-curve back to the centre line at speed `v`: two seconds of travel,
/// at least 8 m (a 0.6 m offset then needs a radius of ≥ 18 m, above ρmin).
pub fn recentre_length<F: Real>(v: F) -> F {
    (F::TWO * v).max(F::from_f64(8.0))
}

/// A lane change's reference path: a quintic S-curve from (x0, y0) to (x0 + len, y1).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Reference<F> {
    x0: F,
    y0: F,
    y1: F,
    len: F,
}

impl<F: Real> Reference<F> {
    /// (y_ref, θ_ref) at x.
    fn at(&self, x: F) -> (F, F) {
        let u = ((x - self.x0) / self.len).max(F::ZERO).min(F::ONE);
        let (u2, u3) = (u * u, u * u * u);
        let s = u3 * (F::from_f64(10.0) - F::from_f64(15.0) * u + F::from_f64(6.0) * u2);
        let ds = F::from_f64(30.0) * u2 * (F::ONE - u).sq();
        let dy = self.y1 - self.y0;
        (self.y0 + dy * s, (dy * ds / self.len).atan2(F::ONE))
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
        Ok(())
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
    /// [`Invariant::Paper`]). Under [`Invariant::LeaderAware`] a vehicle ahead that is
    /// known over V2V, cooperates, declared its braking limit and was heard within the
    /// notification bound or [`STALE_AFTER_S`], whichever is longer, is credited with the least
    /// distance it still travels ([`safety::leader_credit`]); the lane-change checks
    /// toward vehicles behind, yielding and road ends keep the paper's wall, which
    /// implies the leader-aware invariant (its wall is never farther).
    pub fn set_invariant(&mut self, invariant: Invariant) {
        self.invariant = invariant;
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

    /// x̄_t − x_t over the vehicles selected by `select` and the road end (22),
    /// extent-adjusted, and over space the ego cannot vouch for (see
    /// [`LanePlanner::unknown_ahead`]); `None` if there is no obstacle.
    fn gap_over(
        &self,
        obs: &LaneObservation<'_, F>,
        select: impl Fn(&Other<F>) -> bool,
    ) -> Option<F> {
        let p = self.params();
        let end = obs
            .road
            .end_x
            .map(|xr| xr - F::HALF * p.length() - p.d0() - obs.pose.x);
        let known = min_gap(end, self.leader_gap(obs, select, |_| true));
        min_gap(known, self.unknown_ahead())
    }

    /// Where space ahead stops being known (as x̄_t − x_t), if it does. With sensors:
    /// the end of the forward range, as if a stopped vehicle stood just beyond it. Without
    /// (the paper's world): nowhere, except until the notification bound has passed since
    /// the first step — a vehicle may then not yet have heard of one just ahead (off the ideal world:
    /// a follower at the smallest safe gap accelerated for a period of bus delay before
    /// it first heard its braking leader), so it takes the road ahead as blocked at once
    /// and brakes, which is safe whatever is there.
    fn unknown_ahead(&self) -> Option<F> {
        let p = self.params();
        match &self.sensing {
            Some(s) => Some(s.ahead_m - p.d0()),
            None => still_unheard(self.steps, p.h(), self.notify).then_some(F::ZERO),
        }
    }

    /// The sensing error bounds (position m, speed m/s); zero without sensors.
    fn errors(&self) -> (F, F) {
        self.sensing.map_or((F::ZERO, F::ZERO), |s| {
            (s.position_error_m, s.speed_error_mps)
        })
    }

    /// The least x a vehicle ahead can have: a sensor return may be `position_error_m`
    /// further back than measured; a V2V position only grows after its stamp (v ≥ 0), so
    /// it is used as stamped, never extrapolated.
    fn nearest_x(&self, c: &Other<F>) -> F {
        if c.sensed {
            c.x - self.errors().0
        } else {
            c.x
        }
    }

    /// x̄_t − x_t over the vehicles selected by `select` alone, extent-adjusted.
    fn vehicle_gap(
        &self,
        obs: &LaneObservation<'_, F>,
        select: impl Fn(&Other<F>) -> bool,
    ) -> Option<F> {
        let p = self.params();
        // Half a position step at each end: the true rear of a vehicle heard at c.x.
        let len = p.length() + self.resolution.position;
        obs.others
            .iter()
            .filter(|c| select(c))
            .map(|c| self.nearest_x(c) - F::HALF * (c.length + len) - p.d0() - obs.pose.x)
            .reduce(|a, b| a.min(b))
    }

    /// x̄_t − x_t toward the vehicles selected by `select` under the invariant in use:
    /// [`LanePlanner::vehicle_gap`], those of them `credited` selects credited under
    /// [`Invariant::LeaderAware`] with [`LanePlanner::credit`].
    fn leader_gap(
        &self,
        obs: &LaneObservation<'_, F>,
        select: impl Fn(&Other<F>) -> bool,
        credited: impl Fn(&Other<F>) -> bool,
    ) -> Option<F> {
        if self.invariant == Invariant::Paper {
            return self.vehicle_gap(obs, select);
        }
        let p = self.params();
        let len = p.length() + self.resolution.position;
        obs.others
            .iter()
            .filter(|c| select(c))
            .map(|c| {
                let raw = self.nearest_x(c) - F::HALF * (c.length + len) - p.d0() - obs.pose.x;
                if credited(c) {
                    raw + self.credit(c, raw)
                } else {
                    raw
                }
            })
            .reduce(|a, b| a.min(b))
    }

    /// What a vehicle ahead at wall distance `raw` is credited with under the
    /// leader-aware invariant: the least distance it still travels from its stamped
    /// speed (the speed taken half a bus step lower, as the bus may have rounded it up),
    /// if it is known over V2V, cooperates, declared its braking limit, was heard
    /// recently enough, and is ahead (`raw` > 0: a vehicle beside or behind the ego's
    /// front is no leader, and its stop point says nothing about the ego's way to it).
    fn credit(&self, c: &Other<F>, raw: F) -> F {
        let p = self.params();
        let fresh = c.age <= self.notify.max(F::from_f64(STALE_AFTER_S));
        match c.brake {
            Some(b) if !c.sensed && c.cooperative && fresh && raw > F::ZERO => {
                safety::leader_credit(p, c.v - F::HALF * self.resolution.speed, b.mps2())
            }
            _ => F::ZERO,
        }
    }

    /// Extra room a vehicle at speed `v` needs so that, after `tau` of moving unseen, it
    /// still satisfies the invariant: the distance it may cover plus its stopping
    /// distance's growth.
    fn unaware_margin(&self, v: F, tau: F) -> F {
        let p = self.params();
        let (reach, v_up) = unaware_reach(p, v, tau);
        reach + safety::d_s(p, v_up) - safety::d_s(p, v)
    }

    /// The room this vehicle keeps, beyond the invariant, toward a vehicle that is
    /// entering or wants to enter one of its lanes, so that the other's entry check
    /// ([`LanePlanner::entry_ok`]) passes: that check takes this vehicle at its worst
    /// case — measured with the sensing error bounds, and moving unaware for the age of
    /// the other's data of it plus a period. Aware vehicles keep that much more room, or
    /// the other could never enter in front of one that follows it closely.
    /// τ = max(h, 2(notify − h)) covers data up to the notification bound old.
    fn entry_allowance(&self, v: F) -> F {
        let p = self.params();
        let (e, ev) = self.errors();
        let tau = p.h().max(F::TWO * (self.notify - p.h()));
        F::TWO * e + self.unaware_margin(v + ev, tau) + safety::d_s(p, v + ev) - safety::d_s(p, v)
    }

    /// This vehicle in ≺, as the others hear it (rounded to the bus's steps).
    fn key(&self, obs: &LaneObservation<'_, F>) -> Key<F> {
        let r = self.resolution;
        Key {
            x: round_to(obs.pose.x, r.position),
            v: round_to(obs.v_prev, r.speed),
            lane: self.lane,
            id: u16::MAX,
        }
    }

    /// The gaps toward (15) alone and toward (15) ∪ (21), for lanes {ℓ, α} and intention β.
    fn gaps(
        &self,
        obs: &LaneObservation<'_, F>,
        alpha: Option<u8>,
        beta: Option<u8>,
    ) -> (Option<F>, Option<F>) {
        let key = self.key(obs);
        let x = obs.pose.x;
        let lane = self.lane;
        let mine = |j: u8| j == lane || Some(j) == alpha;
        // A return up to `e` behind the ego may be ahead of it.
        let e = self.errors().0;
        let ahead = |c: &Other<F>| Other {
            x: if c.sensed { c.x + e } else { c.x },
            ..*c
        };
        // (15). While changing into α, also whatever may be entering α unheard of.
        let front = |c: &Other<F>| {
            in_front_set(x, lane, alpha, &ahead(c))
                || alpha
                    .is_some_and(|m| x <= ahead(c).x && may_occupy(m, c, self.intent_known(obs, c)))
        };
        let safe = self.gap_over(obs, front);
        // Vehicles entering one of my lanes (α, or β under (21)) get the entry allowance.
        let entering = |c: &Other<F>| {
            !mine(c.lane)
                && (in_front_set(x, lane, alpha, &ahead(c))
                    || yields_to(&key, alpha, beta, c, self.resolution.position))
        };
        let allowance = self.entry_allowance(obs.v_prev);
        // A vehicle ahead in ≺ that is in one of my lanes is a leader like any other;
        // one entering them is checked by its own entry check, which takes me at the
        // wall: it is not credited.
        let yielding = self
            .leader_gap(
                obs,
                |c| entering(c) || yields_to(&key, alpha, beta, c, self.resolution.position),
                |c| !entering(c),
            )
            .map(|g| g - allowance);
        let all = min_gap(safe, yielding);
        (safe, all)
    }

    /// The V2V record of vehicle `id`, if any.
    fn heard<'a>(obs: &'a LaneObservation<'_, F>, id: u16) -> Option<&'a Other<F>> {
        obs.others.iter().find(|o| o.id == id && !o.sensed)
    }

    /// `true` if c's intention is known: it cooperates and its V2V data is younger than
    /// the notification bound (a change into a lane must have been declared that long
    /// before it starts, so nothing newer can be under way), whichever record c is.
    fn intent_known(&self, obs: &LaneObservation<'_, F>, c: &Other<F>) -> bool {
        let v2v = if c.sensed {
            Self::heard(obs, c.id)
        } else {
            Some(c)
        };
        v2v.is_some_and(|v| !v.cooperative || v.age < self.notify)
    }

    /// Every vehicle that may be in lane `m` behind the ego, fused per vehicle: a sensor
    /// return (fresh, within the error bounds) is used in place of a V2V record of the same
    /// vehicle, with that record's declared change and cooperation; a vehicle known only
    /// from the sensor is taken as one that does not cooperate. With sensors, a vehicle
    /// closing in at vmax from just beyond the rear range is added. Each is handed to `f`
    /// with its worst-case position and speed and whether it cooperates.
    fn for_each_behind(
        &self,
        obs: &LaneObservation<'_, F>,
        m: u8,
        mut f: impl FnMut(&Other<F>, F, F, bool) -> Result<(), StartBlock>,
    ) -> Result<(), StartBlock> {
        let x = obs.pose.x;
        let (e, ev) = self.errors();
        for c in obs.others.iter() {
            let heard = if c.sensed {
                Self::heard(obs, c.id)
            } else {
                None
            };
            if !c.sensed && obs.others.iter().any(|o| o.sensed && o.id == c.id) {
                continue;
            }
            let cooperative = if c.sensed {
                heard.is_some_and(|h| h.cooperative)
            } else {
                c.cooperative
            };
            let declared = heard.is_some_and(|h| h.alpha == Some(m));
            let occupant = Other { cooperative, ..*c };
            // A return up to `e` ahead of the ego may be behind it.
            let behind = if c.sensed { c.x - e <= x } else { c.x <= x };
            if !(behind && (declared || may_occupy(m, &occupant, self.intent_known(obs, c)))) {
                continue;
            }
            let (cx, cv) = if c.sensed {
                (c.x + e, c.v + ev)
            } else {
                (c.x, c.v)
            };
            f(c, cx, cv, cooperative)?;
        }
        if let Some(s) = &self.sensing {
            let p = self.params();
            let phantom = Other::v2v(
                u16::MAX,
                x - p.length() - s.behind_m,
                p.v_max(),
                p.length(),
                m,
                F::ZERO,
            );
            // Handed on as a vehicle that does not cooperate (the last argument, which is
            // what the checks read): nothing is known of it.
            f(&phantom, phantom.x, phantom.v, false)?;
        }
        Ok(())
    }

    /// (17) toward one vehicle behind, taken at worst-case position `cx` and speed `cv`
    /// and moving unaware for `tau`: it can still stop behind the ego.
    fn clear_of(&self, obs: &LaneObservation<'_, F>, c: &Other<F>, cx: F, cv: F, tau: F) -> bool {
        let p = self.params();
        // Half a step on the bus's rounding: the true front and speed at their worst.
        let r = self.resolution;
        let (reach, v) = unaware_reach(p, cv + F::HALF * r.speed, tau);
        let room = obs.pose.x
            - F::HALF * (c.length + p.length() + r.position)
            - p.d0()
            - cx
            - reach
            - F::SAFETY_MARGIN_M;
        safety::invariant_holds(p, v, room)
    }

    /// The entry check (RSS-style: the ego, changing into `m`, may put its
    /// rectangle into lane `m` at `lead` from now only if every vehicle that may be in `m`
    /// behind it could stop behind it then even had it never heard of the change — moving
    /// unaware, at up to amax, for the age of the ego's data of it plus `lead`. The
    /// paper's (17) at the start assumes the others hear the ego's α within a period and
    /// yield; on a bus that loses or delays messages without bound, or toward a vehicle
    /// that does not cooperate, nothing else keeps it safe. Aware vehicles keep room for
    /// this check ([`LanePlanner::entry_allowance`]), so on a working bus it passes.
    fn entry_ok(&self, obs: &LaneObservation<'_, F>, m: u8, lead: F) -> bool {
        self.for_each_behind(obs, m, |c, cx, cv, _| {
            if self.clear_of(obs, c, cx, cv, c.age + lead) {
                Ok(())
            } else {
                Err(StartBlock::Behind(c.id))
            }
        })
        .is_ok()
    }

    /// The Lane Change Protocol (16)(17) for a change into `m`, with (17) tested against
    /// every vehicle of C⁻_t (18) (SPEC's choice), each inflated for the age of its data
    /// plus the notification latency beyond one period (SPEC §9: at most amax faster, see
    /// `unaware_reach`), and the free-space condition of Lemma 8 for the widened band.
    /// A vehicle that does not cooperate will not hear the change: toward it (17) must
    /// hold as if the ego entered its lane now (the test of the private
    /// `LanePlanner::entry_ok`).
    /// `Ok` when a change into `m` may start now; otherwise the first condition that fails.
    pub fn start_check(&self, obs: &LaneObservation<'_, F>, m: u8) -> Result<(), StartBlock> {
        let p = self.params();
        if !(obs.pose.theta.abs() <= F::from_f64(STRAIGHT_HEADING_RAD)) {
            return Err(StartBlock::Heading);
        }
        let (_, all) = self.gaps(obs, Some(m), None);
        let free = free_road_gap(p, N);
        let gap = all.map_or(free, |g| g.min(free));
        // (16): x_t < x̄_t − dS(v_{t−h}) with the planner's margin.
        if !safety::invariant_holds(p, obs.v_prev, gap - F::SAFETY_MARGIN_M) {
            return Err(StartBlock::Ahead);
        }
        // (17) for every c ∈ C⁻_t; stale data behind blocks the start (SPEC §9).
        let unaware = self.notify - p.h();
        self.for_each_behind(obs, m, |c, cx, cv, cooperative| {
            if !(c.age <= F::from_f64(STALE_AFTER_S)) {
                return Err(StartBlock::Stale(c.id));
            }
            let tau = c.age + if cooperative { unaware } else { p.h() };
            if self.clear_of(obs, c, cx, cv, tau) {
                Ok(())
            } else {
                Err(StartBlock::Behind(c.id))
            }
        })?;
        // Lemma 8 (i)(ii) in the widened band.
        let band = obs
            .road
            .band(self.lane, Some(m))
            .shrunk(F::HALF * p.width());
        match FreeSpace::new(p, obs.pose, obs.v_prev, obs.omega_prev, band, gap) {
            Ok(fs) if fs.d_h > fs.d_l && fs.lemma5_angles() => Ok(()),
            _ => Err(StartBlock::FreeSpace),
        }
    }

    /// A change under way whose S-curve has been driven but that has not come within
    /// [`CENTRED_M`] of lane `m`'s centre (a fallback or a yield bent it off its curve):
    /// a new S-curve from where the vehicle is to the centre, over [`recentre_length`].
    /// Without it the lateral QP alone closes the rest only over hundreds of metres, and
    /// a vehicle near a road end stops there short of the centre, unable to steer at
    /// standstill (the dead-end sweep's sweep, case 536 of 2,000).
    fn rejoin(&mut self, obs: &LaneObservation<'_, F>, m: u8) {
        let centre = obs.road.lane_centre(m);
        let driven = self.reference.is_none_or(|r| obs.pose.x >= r.x0 + r.len);
        if driven && (obs.pose.y - centre).abs() > F::HALF * F::from_f64(CENTRED_M) {
            self.reference = Some(Reference {
                x0: obs.pose.x,
                y0: obs.pose.y,
                y1: centre,
                len: recentre_length(obs.v_prev),
            });
        }
    }

    /// With no change under way: the S-curve back to the centre line ([`RECENTRE_M`]),
    /// dropped once driven.
    fn recentre(&mut self, obs: &LaneObservation<'_, F>) {
        if self.alpha.is_some() {
            return;
        }
        if self.reference.is_some_and(|r| obs.pose.x >= r.x0 + r.len) {
            self.reference = None;
        }
        let centre = obs.road.lane_centre(self.lane);
        if self.reference.is_none() && (obs.pose.y - centre).abs() > F::from_f64(RECENTRE_M) {
            self.reference = Some(Reference {
                x0: obs.pose.x,
                y0: obs.pose.y,
                y1: centre,
                len: recentre_length(obs.v_prev),
            });
        }
    }

    /// Protocol bookkeeping at the start of a step: completes, declares or starts a change.
    fn update_lanes(&mut self, obs: &LaneObservation<'_, F>) -> Option<LaneEvent> {
        let p = *self.params();
        if let Some(m) = self.alpha {
            let lane_m = obs.road.band(m, None);
            let centred = (obs.pose.y - obs.road.lane_centre(m)).abs() <= F::from_f64(CENTRED_M);
            // The tail's certificate starts with the pose itself: the rectangle inside
            // lane m, with its heading in bounds.
            if centred
                && obs.pose.theta.abs() <= F::from_f64(STRAIGHT_HEADING_RAD)
                && braking_tail_ok(&p, obs.pose, obs.v_prev, lane_m)
            {
                self.lane = m;
                self.alpha = None;
                self.reference = None;
                return Some(LaneEvent::Completed(m));
            }
            self.rejoin(obs, m);
            return None;
        }
        if obs.target_lane == self.lane {
            self.beta = None;
            self.beta_steps = 0;
            return None;
        }
        let want = if obs.target_lane > self.lane {
            self.lane + 1
        } else {
            self.lane.saturating_sub(1)
        };
        if self.beta != Some(want) {
            self.beta = Some(want);
            self.beta_steps = 0;
            return Some(LaneEvent::Declared(want));
        }
        // Start only once the intention has been out for the notification bound (one
        // broadcast period on the paper's bus), so that every vehicle that could start a
        // conflicting change this step already treats the ego by (21).
        let held = F::from_f64(f64::from(self.beta_steps)) * p.h();
        if self.beta_steps >= 1
            && held >= self.notify - F::from_f64(NOTIFY_SLACK_S)
            && self.start_check(obs, want).is_ok()
        {
            self.alpha = Some(want);
            self.beta = None;
            self.beta_steps = 0;
            let dy = obs.road.lane_centre(want) - obs.pose.y;
            // Length of Lemma 12's manoeuvre at the allowed radius: a quintic's peak
            // curvature is 5.77 Δy / len², so len = sqrt(5.77 |Δy| ρ).
            let band = obs
                .road
                .band(self.lane, Some(want))
                .shrunk(F::HALF * p.width());
            let free = safety::d_s(&p, obs.v_prev) + F::from_f64(D_TURN_M);
            let kappa = FreeSpace::new(&p, obs.pose, obs.v_prev, obs.omega_prev, band, free)
                .map(|fs| {
                    if dy > F::ZERO {
                        fs.arc_h.kappa_plus
                    } else {
                        fs.arc_h.kappa_minus
                    }
                })
                .unwrap_or(F::ZERO);
            let rho = if kappa > F::ZERO {
                F::ONE / kappa
            } else {
                p.rho_min()
            };
            let len = (F::from_f64(5.77) * dy.abs() * rho.max(p.rho_min()))
                .sqrt()
                .max(F::from_f64(MIN_CHANGE_LENGTH_M));
            self.reference = Some(Reference {
                x0: obs.pose.x,
                y0: obs.pose.y,
                y1: obs.road.lane_centre(want),
                len,
            });
            return Some(LaneEvent::Started(want));
        }
        None
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

    /// The yaw rates for the speed plan `v_plan`: the lateral QP about the previous plan,
    /// clamped into Ω^k_t (31), or the straightening plan if the QP has no answer; and the
    /// QP's iterations. Not inlined into [`LanePlanner::step`]: its references and the
    /// QP then take stack only while the lateral part runs, not beside the speed solve
    ///.
    #[inline(never)]
    fn plan_lateral(
        &mut self,
        obs: &LaneObservation<'_, F>,
        fs: &FreeSpace<F>,
        v_plan: &[F; N],
        lanes: Band<F>,
    ) -> ([F; N], u32) {
        let p = *self.params();
        let centre = obs.road.lane_centre(self.lane);
        let mut y_ref = [F::ZERO; N];
        let mut th_ref = [F::ZERO; N];
        let mut lo = [F::ZERO; N];
        let mut hi = [F::ZERO; N];
        let mut x = obs.pose.x;
        for (k, &vk) in v_plan.iter().enumerate() {
            x += vk * p.h();
            let (y, th) = match self.reference {
                Some(r) => r.at(x),
                None => (centre, F::ZERO),
            };
            let (l, u) = fs.omega_bounds(vk);
            if let (Some(a), Some(b), Some(c), Some(d)) = (
                y_ref.get_mut(k),
                th_ref.get_mut(k),
                lo.get_mut(k),
                hi.get_mut(k),
            ) {
                *a = y;
                *b = th;
                *c = l;
                *d = u;
            }
        }
        let nominal = crate::planner::shifted(&self.omega_plan);
        let tm = F::from_f64(HEADING_MARGIN_RAD);
        let input = LateralInput {
            h: p.h(),
            y: obs.pose.y,
            theta: obs.pose.theta,
            omega_prev: obs.omega_prev,
            v: v_plan,
            omega_nominal: &nominal,
            y_ref: &y_ref,
            theta_ref: &th_ref,
            omega_lo: &lo,
            omega_hi: &hi,
            theta_bounds: (p.theta_min() + tm, p.theta_max() - tm),
            band: qp_band(&p, obs.pose, lanes),
            half_length: F::HALF * p.length(),
            half_width: F::HALF * p.width(),
            weights: self.lateral_weights,
        };
        match solve_lateral_in(&mut self.lateral, &input) {
            Ok((w, it)) => (clamp_to_omega(fs, v_plan, w), it),
            Err(_) => (straightening_plan(&p, obs.pose.theta, v_plan), 0),
        }
    }

    /// The entry check ([`LanePlanner::entry_ok`]) for a plan: while a change into m has
    /// not yet put the ego's rectangle into lane m, a plan is accepted only if neither its
    /// first step nor the certified fallback from there (the braking tail) enters m before
    /// the vehicles that may be there behind could stop for it. So the fallback, applied
    /// when a later step finds no plan, is safe here too.
    fn entering_ok(&self, obs: &LaneObservation<'_, F>, v: &[F; N], omega: &[F; N]) -> bool {
        let Some(m) = self.alpha else {
            return true;
        };
        let p = self.params();
        let lane_m = obs.road.band(m, None);
        if overlaps(p, obs.pose, lane_m) {
            return true;
        }
        let (Some(&v0), Some(&w0)) = (v.first(), omega.first()) else {
            return true;
        };
        let q1 = step(obs.pose, v0, w0, p.h());
        match first_overlap(p, q1, v0, lane_m) {
            None => true,
            Some(j) => self.entry_ok(obs, m, p.h() * F::from_usize(j + 1)),
        }
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

/// The fallback's yaw rate at speed v: turn toward θ = 0 as fast as ρmin allows.
#[inline]
pub fn straighten<F: Real>(p: &Params<F>, theta: F, v: F) -> F {
    let limit = v / p.rho_min();
    (-theta / p.h()).max(-limit).min(limit)
}

/// ω_k clamped into Ω^k_t (31) exactly.
fn clamp_to_omega<F: Real, const N: usize>(fs: &FreeSpace<F>, v: &[F; N], mut w: [F; N]) -> [F; N] {
    for (wk, &vk) in w.iter_mut().zip(v.iter()) {
        let (lo, hi) = fs.omega_bounds(vk);
        *wk = wk.max(lo).min(hi);
    }
    w
}

/// Straightening yaw rates along a speed plan (used when the lateral QP has no answer).
fn straightening_plan<F: Real, const N: usize>(p: &Params<F>, theta: F, v: &[F; N]) -> [F; N] {
    let mut th = theta;
    let mut out = [F::ZERO; N];
    for (o, &vk) in out.iter_mut().zip(v.iter()) {
        *o = straighten(p, th, vk);
        th += *o * p.h();
    }
    out
}

/// The band the lateral QP keeps the rectangle in: `lanes` tightened by
/// [`LATERAL_MARGIN_M`] on each side, but never by more than the clearance the rectangle
/// has there now. A vehicle closer to an edge than the margin would otherwise make the
/// QP's own start state infeasible; the QP then fails every step and the straightening
/// plan pins θ at 0 (the dead-end sweep's failures). The exact check
/// ([`verify_lateral`]) is on the untightened lanes.
fn qp_band<F: Real>(p: &Params<F>, pose: Pose<F>, lanes: Band<F>) -> (F, F) {
    let margin = F::from_f64(LATERAL_MARGIN_M);
    let ext = lateral_half_extent(p.length(), p.width(), pose.theta);
    let below = (pose.y - ext - lanes.lo).max(F::ZERO);
    let above = (lanes.hi - pose.y - ext).max(F::ZERO);
    (lanes.lo + margin.min(below), lanes.hi - margin.min(above))
}

/// `true` if the rectangle at `pose` is inside the lanes `band` and its heading within
/// bounds.
#[inline]
fn pose_ok<F: Real>(p: &Params<F>, pose: Pose<F>, band: Band<F>) -> bool {
    let ext = lateral_half_extent(p.length(), p.width(), pose.theta);
    band.lo <= pose.y - ext
        && pose.y + ext <= band.hi
        && p.theta_min() <= pose.theta
        && pose.theta <= p.theta_max()
}

/// `true` if the rectangle at `pose` overlaps the lane `band` (its interior).
fn overlaps<F: Real>(p: &Params<F>, pose: Pose<F>, lane: Band<F>) -> bool {
    let ext = lateral_half_extent(p.length(), p.width(), pose.theta);
    pose.y + ext > lane.lo && pose.y - ext < lane.hi
}

/// The first step (0 = `pose` itself) of the braking tail from `pose` with v_{t−h} =
/// `v_prev` (max braking with maximal straightening, as [`braking_tail_ok`] simulates)
/// at which the rectangle overlaps `lane`; `None` if it stops first.
fn first_overlap<F: Real>(p: &Params<F>, pose: Pose<F>, v_prev: F, lane: Band<F>) -> Option<usize> {
    let mut q = pose;
    let mut v = v_prev;
    for j in 0..MAX_TAIL_STEPS {
        if overlaps(p, q, lane) {
            return Some(j);
        }
        if !(v > F::ZERO) {
            return None;
        }
        if q.theta == F::ZERO {
            // Straight: y and θ stay as they are (see [`stops_within`]), so it never
            // overlaps; what is left is whether it stops within the cap.
            return if stops_within(p, v, MAX_TAIL_STEPS - j) {
                None
            } else {
                Some(MAX_TAIL_STEPS)
            };
        }
        v = safety::max_braking_command(p, v);
        q = step(q, v, straighten(p, q.theta, v), p.h());
    }
    // Not stopped within the cap: assume it enters at the end of it.
    Some(MAX_TAIL_STEPS)
}

/// Whether max braking from v_{t−h} = `v` reaches standstill within `steps` steps: what
/// the braking tail's loops decide once the heading is exactly 0. From θ = 0 the
/// straightening yaw rate is (−0/h) clamped = ±0, so the unicycle step adds d·sin(±0) = ±0
/// to y and ±0·h to θ: y and θ never change again, and neither do the pose checks. The
/// loops below skip the transcendental functions of those steps (they were ~95 % of the
/// certificate's cost during a lane change) and still return exactly what the full
/// simulation returns, cap included.
fn stops_within<F: Real>(p: &Params<F>, mut v: F, steps: usize) -> bool {
    for _ in 0..steps {
        if !(v > F::ZERO) {
            return true;
        }
        v = safety::max_braking_command(p, v);
    }
    // As the loops do when their cap runs out (even on the step that reached 0).
    false
}

/// The certificate of the fallback: from `pose` with v_{t−h} = `v_prev`, max braking
/// with maximal straightening keeps the exact rectangle in the lanes `band` (edges, not
/// shrunk) and the heading within bounds at every step until standstill.
pub fn braking_tail_ok<F: Real>(p: &Params<F>, pose: Pose<F>, v_prev: F, band: Band<F>) -> bool {
    if !pose_ok(p, pose, band) {
        return false;
    }
    if pose.theta == F::ZERO {
        // Straight: y never changes.
        return true;
    }
    let mut q = pose;
    let mut v = v_prev;
    for i in 0..MAX_TAIL_STEPS {
        if !(v > F::ZERO) {
            return true;
        }
        v = safety::max_braking_command(p, v);
        let w = straighten(p, q.theta, v);
        q = step(q, v, w, p.h());
        if !pose_ok(p, q, band) {
            return false;
        }
        if q.theta == F::ZERO {
            // Straight from here on: the pose checks cannot change ([`stops_within`]).
            return stops_within(p, v, MAX_TAIL_STEPS - 1 - i);
        }
    }
    false
}

/// Verifies a plan (v_k, ω_k) of (13) on the exact unicycle: every state of the horizon
/// inside the lanes with its heading in bounds, and the fallback certificate from the
/// state after the first step. (The longitudinal constraints were verified on the speeds
/// with x_{k+1} − x_t ≤ h Σ v_j, which bounds the exact x since |cos θ| ≤ 1.)
pub fn verify_lateral<F: Real, const N: usize>(
    p: &Params<F>,
    pose: Pose<F>,
    v: &[F; N],
    omega: &[F; N],
    band: Band<F>,
) -> bool {
    let mut q = pose;
    let mut first = None;
    for (k, (&vk, &wk)) in v.iter().zip(omega.iter()).enumerate() {
        if !(wk.is_finite() && wk.abs() * p.rho_min() <= vk * (F::ONE + F::EPSILON)) {
            return false;
        }
        q = step(q, vk, wk, p.h());
        if !pose_ok(p, q, band) {
            return false;
        }
        if k == 0 {
            first = Some((q, vk));
        }
    }
    match first {
        Some((q1, v0)) => braking_tail_ok(p, q1, v0, band),
        None => true,
    }
}

/// LC(ρ) of (24): the x-distance of Lemma 12's S-curve over one lane at radius ρ,
/// 2 sqrt(Wl (2ρ − Wl)) − ρ θ_t.
pub fn lane_change_length<F: Real>(p: &Params<F>, rho: F, theta: F) -> F {
    let wl = p.spec().lane_width;
    F::TWO * (wl * (F::TWO * rho - wl)).max(F::ZERO).sqrt() - rho * theta
}

/// dC(v) = max{dS(v), LC(ρ_t)}, eq. (24).
pub fn d_c<F: Real>(p: &Params<F>, v: F, rho: F, theta: F) -> F {
    safety::d_s(p, v).max(lane_change_length(p, rho, theta))
}

/// The commitment distance (23): a vehicle needing `m` lane changes can make them before
/// x_R if x_R − x_t ≥ M (dS(v) + dC(v)); the paper takes v = vmax.
pub fn commitment_distance<F: Real>(p: &Params<F>, m: u8, v: F, rho: F, theta: F) -> F {
    F::from_usize(usize::from(m)) * (safety::d_s(p, v) + d_c(p, v, rho, theta))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_unaware_vehicle_reaches_at_most_amax_then_vmax() {
        let p = Params::<f64>::table_i();
        let (a, vm) = (p.a_max(), p.v_max());
        let (reach, v1) = unaware_reach(&p, 10.0, 1.0);
        assert!((reach - (10.0 + 0.5 * a)).abs() < 1e-12 && (v1 - (10.0 + a)).abs() < 1e-12);
        let (reach, v1) = unaware_reach(&p, 0.0, 0.5);
        assert!((reach - 0.125 * a).abs() < 1e-12 && (v1 - 0.5 * a).abs() < 1e-12);
        // Near vmax the cap binds, on the distance and the speed.
        let (reach, v1) = unaware_reach(&p, vm - 0.1, 10.0);
        assert!((reach - 10.0 * vm).abs() < 1e-9 && v1 == vm);
    }

    #[test]
    fn yielding_is_decided_on_where_the_other_vehicle_is_now() {
        // Its data is 0.5 s old: it was 1 m behind, at 20 m/s it is now 9 m ahead.
        let ego = Key {
            x: 100.0,
            v: 10.0,
            lane: 0,
            id: 1,
        };
        let mut c = Other::v2v(2, 99.0, 20.0, 4.5, 0, 0.5);
        c.beta = Some(1);
        let now = Other { x: 109.0, ..c };
        let then = in_yield_set(&ego, None, Some(1), &c);
        let want = in_yield_set(&ego, None, Some(1), &now);
        assert_ne!(then, want, "the test needs the age to matter");
        assert_eq!(yields_to(&ego, None, Some(1), &c, 0.0), want);
    }

    #[test]
    fn margins_are_what_their_docs_say() {
        let p = Params::<f64>::table_i();
        let mut pl = LanePlanner::<f64, 20>::new(p, CostWeights::default(), 0).expect("valid");
        pl.set_notify_latency(0.1).expect("valid");
        pl.set_sensing(Some(Sensing::radar())).expect("valid");
        let v = 12.0;
        let tau = 0.5;
        let (reach, v_up) = unaware_reach(&p, v, tau);
        let margin = reach + safety::d_s(&p, v_up) - safety::d_s(&p, v);
        assert!((pl.unaware_margin(v, tau) - margin).abs() < 1e-12);
        assert!(margin > reach, "a faster vehicle needs more room to stop");
        // τ = max(h, 2 (notify − h)) = 0.18 s; errors 0.1 m and 0.1 m/s.
        let t = 2.0 * (0.1 - p.h());
        let (e, ev) = (0.1, 0.1);
        let want =
            2.0 * e + pl.unaware_margin(v + ev, t) + safety::d_s(&p, v + ev) - safety::d_s(&p, v);
        assert!((pl.entry_allowance(v) - want).abs() < 1e-12);
    }

    /// A follower at vmax, `gap` m of wall distance behind a leader at vmax, after its
    /// first steps (so nothing ahead is unheard of): its command under `invariant`.
    fn follow(
        invariant: Invariant,
        gap: f64,
        leader: impl Fn(&mut Other<f64>),
    ) -> LaneCommand<f64> {
        let p = Params::<f64>::table_i();
        let mut pl = LanePlanner::<f64, 20>::new(p, CostWeights::default(), 0).expect("valid");
        pl.set_invariant(invariant);
        pl.steps = 100;
        let v = p.v_max();
        let x_leader = gap + p.length() + p.d0();
        let mut c = Other::v2v(2, x_leader, v, p.length(), 0, 0.0);
        c.brake = safety::BrakeLimit::from_mps2(p.brake());
        leader(&mut c);
        let others = [c];
        let obs = LaneObservation {
            pose: Pose {
                x: 0.0,
                y: 1.8,
                theta: 0.0,
            },
            v_prev: v,
            omega_prev: 0.0,
            others: &others,
            road: Road {
                lanes: 1,
                lane_width: 3.6,
                end_x: None,
            },
            target_lane: 0,
            target: 0.0,
            v_ref: v,
        };
        pl.step(&obs).expect("a valid observation")
    }

    #[test]
    fn a_cooperating_leader_is_credited_with_its_least_travel_and_nothing_else_is() {
        let p = Params::<f64>::table_i();
        let v = p.v_max();
        // Half the follower's stopping distance: the paper's invariant is broken.
        let gap = 0.5 * safety::d_s(&p, v);
        let paper = follow(Invariant::Paper, gap, |_| {});
        assert!(matches!(paper.status, StepStatus::Fallback(_)), "{paper:?}");
        let aware = follow(Invariant::LeaderAware, gap, |_| {});
        assert!(
            !matches!(aware.status, StepStatus::Fallback(_)),
            "{aware:?}"
        );
        // What the planner reports is capped where no constraint of the horizon can bind.
        let free = crate::planner::free_road_gap(&p, 20);
        let want = (gap + safety::leader_credit(&p, v, p.brake())).min(free);
        assert!((aware.gap - want).abs() < 1e-9, "{} vs {want}", aware.gap);
        // No credit for what is not a cooperating leader heard recently that declared
        // its braking limit, nor for a vehicle whose rear is not ahead.
        type Case = (&'static str, f64, fn(&mut Other<f64>));
        let cases: [Case; 5] = [
            ("no limit declared", gap, |c| c.brake = None),
            ("not cooperating", gap, |c| c.cooperative = false),
            ("a sensor return", gap, |c| c.sensed = true),
            ("silent", gap, |c| c.age = 1.0),
            ("beside", -1.0, |_| {}),
        ];
        for (why, g, f) in cases {
            let c = follow(Invariant::LeaderAware, g, f);
            assert!(c.gap <= g + 1e-9, "{why}: gap {} > {g}", c.gap);
        }
        // A leader with a weaker brake is taken to brake at the follower's limit: its
        // stop is placed earlier than it can be, never later (what makes comparing
        // stopping points enough). A stronger one is credited less.
        let weak = follow(Invariant::LeaderAware, gap, |c| {
            c.brake = safety::BrakeLimit::from_mps2(1.0)
        });
        assert!(
            (weak.gap - want).abs() < 1e-9,
            "a weak brake is not credited more"
        );
        let strong = follow(Invariant::LeaderAware, gap, |c| {
            c.brake = safety::BrakeLimit::from_mps2(20.0)
        });
        // (The leader is also in the yield set (21), whose gap keeps the entry allowance.)
        let pl = LanePlanner::<f64, 20>::new(p, CostWeights::default(), 0).expect("valid");
        let less = gap + safety::leader_credit(&p, v, 20.0) - pl.entry_allowance(v);
        assert!((strong.gap - less).abs() < 1e-9, "{} vs {less}", strong.gap);
    }

    /// The lane [0, 3.6] m and the table's vehicle.
    fn lane0() -> Band<f64> {
        Band { lo: 0.0, hi: 3.6 }
    }

    /// The half-extent across the road, computed here: ½ (L |sin θ| + W |cos θ|).
    fn ext(p: &Params<f64>, theta: f64) -> f64 {
        0.5 * (p.length() * theta.sin().abs() + p.width() * theta.cos().abs())
    }

    #[test]
    fn a_pose_is_in_its_band_to_the_edge_and_not_beyond() {
        let p = Params::<f64>::table_i();
        for theta in [0.0, 0.1, -0.2] {
            let e = ext(&p, theta);
            let at = |y: f64| pose_ok(&p, Pose { x: 0.0, y, theta }, lane0());
            assert!(at(e + 1e-9) && at(3.6 - e - 1e-9), "{theta}");
            assert!(!at(e - 1e-6) && !at(3.6 - e + 1e-6), "{theta}");
        }
        let two = Band { lo: 0.0, hi: 7.2 };
        let tilted = |theta: f64| {
            pose_ok(
                &p,
                Pose {
                    x: 0.0,
                    y: 3.6,
                    theta,
                },
                two,
            )
        };
        assert!(tilted(p.theta_max() - 1e-9) && !tilted(p.theta_max() + 1e-6));
        assert!(tilted(p.theta_min() + 1e-9) && !tilted(p.theta_min() - 1e-6));
    }

    #[test]
    fn overlapping_means_reaching_into_the_lanes_interior() {
        let p = Params::<f64>::table_i();
        let upper = Band { lo: 3.6, hi: 7.2 };
        for theta in [0.0, 0.15] {
            let e = ext(&p, theta);
            let at = |y: f64| overlaps(&p, Pose { x: 0.0, y, theta }, upper);
            assert!(
                !at(3.6 - e - 1e-6),
                "touching from below is not overlapping"
            );
            assert!(at(3.6 - e + 1e-6) && at(5.4) && at(7.2 + e - 1e-6));
            assert!(!at(7.2 + e + 1e-6) && !at(-20.0) && !at(30.0));
        }
    }

    #[test]
    fn the_braking_tail_enters_a_lane_only_while_moving() {
        let p = Params::<f64>::table_i();
        let upper = Band { lo: 7.2, hi: 10.8 };
        // Heading for the lane above at 0.5 rad, 1 cm short of it: straightening at ρmin
        // swings the front corner up faster than the rear comes down (above ~0.35 rad),
        // so at speed it gets in.
        let theta = 0.5;
        let pose = Pose {
            x: 0.0,
            y: 7.2 - ext(&p, theta) - 0.01,
            theta,
        };
        let enters = first_overlap(&p, pose, 20.0, upper);
        assert!(matches!(enters, Some(j) if j > 0 && j < 20), "{enters:?}");
        // Standing still it never does.
        assert_eq!(first_overlap(&p, pose, 0.0, upper), None);
        // Already in: step 0.
        let inside = Pose { y: 7.0, ..pose };
        assert_eq!(first_overlap(&p, inside, 20.0, upper), Some(0));
    }

    /// The two lanes of a change, [0, 7.2] m.
    fn two_lanes() -> Band<f64> {
        Band { lo: 0.0, hi: 7.2 }
    }

    /// A pose inside the two lanes near their upper edge, heading out at `theta`, at
    /// speed `v`, whose braking tail leaves them (found by scanning y; asserted to exist).
    fn leaving_pose(p: &Params<f64>, theta: f64, v: f64) -> Pose<f64> {
        (0..400)
            .map(|i| Pose {
                x: 0.0,
                y: 7.2 - ext(p, theta) - 0.001 * f64::from(i),
                theta,
            })
            .find(|&q| pose_ok(p, q, two_lanes()) && !braking_tail_ok(p, q, v, two_lanes()))
            .expect("a pose inside whose braking tail leaves the lanes")
    }

    #[test]
    fn the_fallback_certificate_follows_the_tail_to_standstill() {
        let p = Params::<f64>::table_i();
        let q = leaving_pose(&p, 0.5, 25.0);
        // The tail really leaves: simulate it here.
        let (mut r, mut v, mut left) = (q, 25.0, false);
        while v > 0.0 {
            v = safety::max_braking_command(&p, v);
            r = step(r, v, straighten(&p, r.theta, v), p.h());
            left |= !pose_ok(&p, r, two_lanes());
        }
        assert!(left);
        // Straight and inside: certified at once; standing still and tilted: too.
        assert!(braking_tail_ok(
            &p,
            Pose {
                theta: 0.0,
                y: 3.6,
                ..q
            },
            25.0,
            two_lanes()
        ));
        assert!(braking_tail_ok(&p, q, 0.0, two_lanes()));
    }

    #[test]
    fn a_plan_is_verified_with_its_turning_radius_and_the_tail_after_its_first_step() {
        const N: usize = 20;
        let p = Params::<f64>::table_i();
        let v = [20.0; N];
        let straight = Pose {
            x: 0.0,
            y: 1.8,
            theta: 0.0,
        };
        // ρ ≥ ρmin: |ω| ≤ v / ρmin, to the rounding.
        let turn = |k: f64| {
            let mut w = [0.0; N];
            w[0] = k * 20.0 / p.rho_min();
            w[1] = -w[0];
            w
        };
        assert!(verify_lateral(&p, straight, &v, &turn(1.0), lane0()));
        assert!(!verify_lateral(&p, straight, &v, &turn(1.01), lane0()));
        // A plan turning toward the upper edge, ending at 0.5 rad next to it: every state
        // inside, the tail from the state after its first step (nearly straight) certified,
        // the tail from its last state not — the certificate is the first step's.
        let two = two_lanes();
        // ρ = 20 / 2.5 = 8 m ≥ ρmin; θ grows by 0.025 per step to 0.5.
        let w = [2.5; N];
        for i in 0..600 {
            let q0 = Pose {
                x: 0.0,
                y: 1.0 + 0.01 * f64::from(i),
                theta: 0.0,
            };
            let mut q = q0;
            let mut inside = true;
            for &wk in &w {
                q = step(q, 20.0, wk, p.h());
                inside &= pose_ok(&p, q, two);
            }
            let q1 = step(q0, 20.0, w[0], p.h());
            if inside && braking_tail_ok(&p, q1, 20.0, two) && !braking_tail_ok(&p, q, 20.0, two) {
                assert!(verify_lateral(&p, q0, &v, &w, two));
                return;
            }
        }
        panic!("no plan whose last state's tail leaves while its first state's does not");
    }

    /// The braking-tail checks as they were before the straight-line shortcut: every
    /// step simulated on the unicycle until standstill or the cap.
    fn full_tail<F: Real>(p: &Params<F>, pose: Pose<F>, v_prev: F, band: Band<F>) -> bool {
        if !pose_ok(p, pose, band) {
            return false;
        }
        if pose.theta == F::ZERO {
            return true;
        }
        let (mut q, mut v) = (pose, v_prev);
        for _ in 0..MAX_TAIL_STEPS {
            if !(v > F::ZERO) {
                return true;
            }
            v = safety::max_braking_command(p, v);
            q = step(q, v, straighten(p, q.theta, v), p.h());
            if !pose_ok(p, q, band) {
                return false;
            }
        }
        false
    }

    fn full_overlap<F: Real>(
        p: &Params<F>,
        pose: Pose<F>,
        v_prev: F,
        lane: Band<F>,
    ) -> Option<usize> {
        let (mut q, mut v) = (pose, v_prev);
        for j in 0..MAX_TAIL_STEPS {
            if overlaps(p, q, lane) {
                return Some(j);
            }
            if !(v > F::ZERO) {
                return None;
            }
            v = safety::max_braking_command(p, v);
            q = step(q, v, straighten(p, q.theta, v), p.h());
        }
        Some(MAX_TAIL_STEPS)
    }

    /// Random poses near a lane edge, headings, speeds and bands, in `F`, for Table I and
    /// for a period so short that the tail outlasts [`MAX_TAIL_STEPS`]: the shortcut
    /// returns exactly what the full simulation returns, and it is really taken.
    fn shortcut_agrees<F: Real>(p: &Params<F>) -> usize {
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut r = move || {
            seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
            F::from_f64(((seed >> 11) as f64) / ((1u64 << 53) as f64))
        };
        let mut straightened = 0;
        for _ in 0..3000 {
            let theta = (r() - F::HALF) * F::from_f64(1.0);
            let v = r() * F::from_f64(28.0);
            let lo = F::from_f64(-0.5) * r();
            let band = Band {
                lo,
                hi: lo + F::from_f64(3.6) + F::from_f64(3.6) * r(),
            };
            let y = band.lo + (band.hi - band.lo) * r();
            let pose = Pose {
                x: F::ZERO,
                y,
                theta,
            };
            assert_eq!(
                braking_tail_ok(p, pose, v, band),
                full_tail(p, pose, v, band),
                "{pose:?} v={v:?} {band:?}"
            );
            let lane = Band {
                lo: band.hi,
                hi: band.hi + F::from_f64(3.6),
            };
            assert_eq!(
                first_overlap(p, pose, v, lane),
                full_overlap(p, pose, v, lane)
            );
            // Did the tail reach θ = 0 exactly while still moving (the shortcut's case)?
            let (mut q, mut w) = (pose, v);
            for _ in 0..MAX_TAIL_STEPS {
                if !(w > F::ZERO) {
                    break;
                }
                w = safety::max_braking_command(p, w);
                q = step(q, w, straighten(p, q.theta, w), p.h());
                if q.theta == F::ZERO && w > F::ZERO {
                    straightened += 1;
                    break;
                }
            }
        }
        straightened
    }

    #[test]
    fn the_straight_tail_shortcut_answers_what_the_full_simulation_does() {
        let short = |p: Params<f64>| {
            Params::new(crate::params::ParamsSpec {
                h: 1e-4,
                ..*p.spec()
            })
            .expect("valid")
        };
        for (name, n) in [
            ("f64", shortcut_agrees(&Params::<f64>::table_i())),
            ("f32", shortcut_agrees(&Params::<f32>::table_i())),
            (
                "f64, h = 0.1 ms",
                shortcut_agrees(&short(Params::table_i())),
            ),
        ] {
            assert!(
                n > 1000,
                "{name}: the tail reached θ = 0 in only {n} of 3000 cases"
            );
        }
        // At the cap's edge: speeds around the one from which max braking takes exactly
        // MAX_TAIL_STEPS steps, with a slight heading (straight after a few steps), on
        // both sides of the edge and in agreement with the full simulation.
        let p = short(Params::table_i());
        let band = Band { lo: 0.0, hi: 7.2 };
        let lane = Band { lo: 7.2, hi: 10.8 };
        let pose = Pose {
            x: 0.0,
            y: 3.6,
            theta: 0.01,
        };
        let edge = MAX_TAIL_STEPS as f64 * p.h() * p.brake();
        let (mut certified, mut refused) = (0, 0);
        for i in 0..400 {
            let v = edge - 2.0 * p.h() * p.brake() + 1e-5 * f64::from(i);
            let full = full_tail(&p, pose, v, band);
            assert_eq!(braking_tail_ok(&p, pose, v, band), full, "v = {v}");
            assert_eq!(
                first_overlap(&p, pose, v, lane),
                full_overlap(&p, pose, v, lane)
            );
            if full {
                certified += 1;
            } else {
                refused += 1;
            }
        }
        assert!(certified > 0 && refused > 0, "{certified} / {refused}");
        let p32 = Params::<f32>::table_i();
        let short32 = Params::new(crate::params::ParamsSpec {
            h: 1e-4,
            ..*p32.spec()
        })
        .expect("valid");
        assert!(shortcut_agrees(&short32) > 1000);
    }
}

#[cfg(test)]
#[path = "lane_change_audit.rs"]
mod audit;
