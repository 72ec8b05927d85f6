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
use crate::lanes::{in_behind_set, in_front_set, in_yield_set, Band, Key, Other, Road};
use crate::lateral::{solve_lateral, LateralInput, LateralWeights};
use crate::mpc::CostWeights;
use crate::params::Params;
use crate::planner::{free_road_gap, ConfigError, FallbackReason, InputError, Planner, StepStatus};
use crate::real::Real;
use crate::safety;
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
/// so it never steers again and a second change never starts (issue 14's dead-end
/// failures). 0.6 m from the centre leaves 0.35 m to the edge. Until the change
/// completes its band spans both lanes, so the S-curve can finish.
pub const CENTRED_M: f64 = 0.6;
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
    omega_plan: [F; N],
    reference: Option<Reference<F>>,
}

impl<F: Real, const N: usize> LanePlanner<F, N, IpmSolver<F, N>> {
    /// A planner in `lane` using our interior-point solver.
    pub fn new(params: Params<F>, weights: CostWeights<F>, lane: u8) -> Result<Self, ConfigError> {
        Self::with_solver(params, weights, IpmSolver::default(), lane)
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
            omega_plan: [F::ZERO; N],
            reference: None,
        })
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
        let ok = |r: F| r.is_finite() && r >= F::ZERO && r < F::ONE;
        if !(ok(position) && ok(speed)) {
            return Err(ConfigError::InvalidResolution);
        }
        self.resolution = Resolution { position, speed };
        Ok(())
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
    /// extent-adjusted; `None` if there is no obstacle.
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
        min_gap(end, self.vehicle_gap(obs, select))
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
            .map(|c| c.x - F::HALF * (c.length + len) - p.d0() - obs.pose.x)
            .reduce(|a, b| a.min(b))
    }

    /// Extra room a vehicle at speed `v` needs so that, after `tau` of moving unseen, it
    /// still satisfies the invariant: the distance it may cover plus its stopping
    /// distance's growth.
    fn unaware_margin(&self, v: F, tau: F) -> F {
        let p = self.params();
        let (reach, v_up) = unaware_reach(p, v, tau);
        reach + safety::d_s(p, v_up) - safety::d_s(p, v)
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
        let safe = self.gap_over(obs, |c| in_front_set(x, lane, alpha, c));
        // (21) adds the vehicles I yield to. On a bus with latency I keep the room the
        // declarer's (17) asks of me (my data up to `notify − h` old, then up to
        // `notify − h` unaware), or it never starts; no extra room on the paper's bus.
        let tau = F::from_f64(2.0) * (self.notify - self.params().h());
        let yielding = self
            .vehicle_gap(obs, |c| {
                yields_to(&key, alpha, beta, c, self.resolution.position)
            })
            .map(|g| {
                if tau > F::ZERO {
                    g - self.unaware_margin(obs.v_prev, tau)
                } else {
                    g
                }
            });
        let all = min_gap(safe, yielding);
        (safe, all)
    }

    /// The Lane Change Protocol (16)(17) for a change into `m`, with (17) tested against
    /// every vehicle of C⁻_t (18) (SPEC's choice), each inflated for the age of its data
    /// plus the notification latency beyond one period (SPEC §9: at most amax faster, see
    /// `unaware_reach`), and the free-space condition of Lemma 8 for the widened band.
    /// `Ok` when a change into `m` may start now; otherwise the first condition that fails.
    pub fn start_check(&self, obs: &LaneObservation<'_, F>, m: u8) -> Result<(), StartBlock> {
        let p = self.params();
        let x = obs.pose.x;
        let len = p.length();
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
        // (17) for every c ∈ C⁻_t; stale data behind blocks the start (SPEC §9). Each is
        // inflated for its data's age plus the time it may still not know of the change
        // beyond the paper's one period.
        let unaware = self.notify - p.h();
        for c in obs.others.iter().filter(|c| in_behind_set(x, m, c)) {
            if !(c.age <= F::from_f64(STALE_AFTER_S)) {
                return Err(StartBlock::Stale(c.id));
            }
            // Half a step on the bus's rounding: the true front and speed at their worst.
            let r = self.resolution;
            let (reach, v) = unaware_reach(p, c.v + F::HALF * r.speed, c.age + unaware);
            let room = x
                - F::HALF * (c.length + len + r.position)
                - p.d0()
                - c.x
                - reach
                - F::SAFETY_MARGIN_M;
            if !safety::invariant_holds(p, v, room) {
                return Err(StartBlock::Behind(c.id));
            }
        }
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

    /// Protocol bookkeeping at the start of a step: completes, declares or starts a change.
    fn update_lanes(&mut self, obs: &LaneObservation<'_, F>) -> Option<LaneEvent> {
        let p = *self.params();
        if let Some(m) = self.alpha {
            let lane_m = obs.road.band(m, None);
            let ext = lateral_half_extent(p.length(), p.width(), obs.pose.theta);
            let inside = lane_m.lo <= obs.pose.y - ext && obs.pose.y + ext <= lane_m.hi;
            let centred = (obs.pose.y - obs.road.lane_centre(m)).abs() <= F::from_f64(CENTRED_M);
            if inside
                && centred
                && obs.pose.theta.abs() <= F::from_f64(STRAIGHT_HEADING_RAD)
                && braking_tail_ok(&p, obs.pose, obs.v_prev, lane_m)
            {
                self.lane = m;
                self.alpha = None;
                self.reference = None;
                return Some(LaneEvent::Completed(m));
            }
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
        if self.beta.is_some() {
            self.beta_steps = self.beta_steps.saturating_add(1);
        }
        let lanes = obs.road.band(self.lane, self.alpha);
        let band = lanes.shrunk(F::HALF * p.width());
        let (safe, all) = self.gaps(obs, self.alpha, self.beta);
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
            StepStatus::Solved { .. } => {}
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
        let mut lateral_iterations = 0;
        let omega = match fs {
            None => [F::ZERO; N],
            Some(fs) => {
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
                    v: &v_plan,
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
                match solve_lateral(&input) {
                    Ok((w, it)) => {
                        lateral_iterations = it;
                        clamp_to_omega(&fs, &v_plan, w)
                    }
                    Err(_) => straightening_plan(&p, obs.pose.theta, &v_plan),
                }
            }
        };
        let omega = if verify_lateral(&p, obs.pose, &v_plan, &omega, lanes) {
            omega
        } else {
            let alt = straightening_plan(&p, obs.pose.theta, &v_plan);
            if verify_lateral(&p, obs.pose, &v_plan, &alt, lanes) {
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
/// plan pins θ at 0 (issue 14's dead-end failures). The exact check
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
    for _ in 0..MAX_TAIL_STEPS {
        if !(v > F::ZERO) {
            return true;
        }
        v = safety::max_braking_command(p, v);
        let w = straighten(p, q.theta, v);
        q = step(q, v, w, p.h());
        if !pose_ok(p, q, band) {
            return false;
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
