//! The intersection manager (Sec. VI, SPEC §7): arrival registration by the
//! intersection's clock, and the crossing algorithms that decide which vehicles of C^I_t
//! (25) may enter A_S — the maximal elements of the ordering ≺^I_t (26).
//!
//! Sans-IO and bounded: the manager is fed vehicle reports and the time, and answers
//! which vehicles hold a permission; it tracks at most `CAP` vehicles.

use crate::intersection::{Layout, Route, CONFLICT_SAMPLE_M, MAX_ROUTES};
use crate::params::Params;
use crate::planner::{valid_resolution, ConfigError};
use crate::real::Real;
use crate::safety::{self, BrakeLimit, Invariant};
use crate::sensing::{still_unheard, Sensing};
use crate::time::{Duration, Instant};
use core::cmp::Ordering;
use heapless::Vec;

/// The crossing algorithm.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum Algorithm {
    /// All-Way STOP as drivers keep it: every vehicle comes to a full stop at its stop
    /// line; the stopped vehicles then go in the order they stopped, each as soon as no
    /// vehicle whose route conflicts with its own holds A_S — and never ahead of an
    /// earlier-stopped vehicle it conflicts with. Vehicles on routes that do not
    /// conflict (opposite straights, say) go together.
    AllWayStop,
    /// All-Way STOP one vehicle at a time, the baseline this project first took for the
    /// paper's Fig. 9 (SPEC §7): every vehicle stops at its stop line; vehicles are
    /// served in the order they stopped, one vehicle inside A_S at a time.
    AllWayStopSingle,
    /// FIFO Crossing: order by arrival τ, ties by route index Ψ; only the first vehicle,
    /// and only when no other holds a permission.
    Fifo,
    /// Concurrent Crossing, exactly the paper's Steps 1–5.
    Concurrent,
    /// Concurrent Crossing that never admits a vehicle ahead of an earlier waiting
    /// vehicle whose route it conflicts with (closes SPEC §7's liveness gap).
    ConcurrentFair,
    /// Beyond the paper: starvation-free Concurrent Crossing with four relaxations that
    /// keep every safety guarantee.
    ///
    /// 1. *Following on the same route.* A vehicle may be permitted while a vehicle ahead
    ///    of it on the same route holds a permission (the paper's own conclusion): both
    ///    share one path from inlet to outlet, on which the follower's planner treats the
    ///    leader as its x̄ (2), so Theorem 1 keeps them apart.
    /// 2. *Releasing a conflict zone once passed.* A permitted vehicle on route γ blocks
    ///    route γ′ only until its centre has passed the last point of γ whose L × W
    ///    footprint (plus margin) meets γ′'s swept area. Vehicles never reverse (v ≥ 0),
    ///    so from then on its footprint cannot meet any vehicle on γ′ inside A_S.
    /// 3. *Requesting just in time.* Only vehicles within [`REQUEST_DISTANCE_M`] of their
    ///    stop line compete for permissions, so a permission is not held for the whole
    ///    approach through A_C. Permissions are only ever an addition to the stop line
    ///    (IC Protocol (ii)); a vehicle without one still stops before A_S.
    /// 4. *Only a lane's head waits.* A vehicle queued behind an unpermitted vehicle on
    ///    its inlet lane is neither granted nor counted as waiting, so its route holds
    ///    back no other route until it is the lane's head (it cannot reach the stop line
    ///    before then). Granting less is always safe; fairness holds per lane head.
    ///
    /// No two permitted vehicles ever have footprints that can meet inside A_S except
    /// followers on one route, which Theorem 1 covers; every other guarantee (the stop
    /// line, Spaciousness, the outlet invariant) is the paper's.
    Pipelined,
    /// Beyond the paper: [`Algorithm::Pipelined`] with platoons — a signal's phases,
    /// made of whatever fits together, without its fixed timing. Two changes to PIPE:
    ///
    /// 1. *Trailing on a shared inlet.* A vehicle may be permitted behind a holder on its
    ///    own inlet lane whose route differs from its own but trails it
    ///    ([`Layout::trails`]: at the invariant's spacing along their common arc length
    ///    their footprints cannot meet while the leader is in its conflict zone with the
    ///    follower's route), both of the length the layout checked. Its crossing planner
    ///    keeps the leader as a wall until the leader has left that zone
    ///    ([`CrossingPlanner::step`]), so Theorem 1 keeps them apart along the arc and
    ///    the layout's check turns that into footprints that do not meet.
    /// 2. *Joining the flow.* A vehicle admissible beside every holder may be granted
    ///    ahead of earlier vehicles waiting on conflicting routes when each of those was
    ///    refused because a route already held or granted conflicts with its own — it
    ///    could not go now whatever this one does — and has waited less than
    ///    [`PLATOON_MAX_WAIT`].
    ///
    /// Every grant still passes the pipelined admissibility test (with 1 added to its
    /// following rule), so the safety argument is [`Algorithm::Pipelined`]'s with one
    /// more kind of follower (docs/spec.md, Theorem 4 under PLATOON); only the order
    /// changes otherwise.
    ///
    /// Why: under the fair scan a saturated junction serves one lane head at a time,
    /// each starting from a standstill at its line, and a lane whose vehicles turn left
    /// and go straight by turns serves one vehicle per clearance of the box. Joining
    /// lets every lane that fits with the current flow go with it, as a signal's phase
    /// does, and trailing lets a lane discharge whatever its vehicles' movements; the
    /// bound on waiting keeps it starvation-free (docs/spec.md, Theorem 5: once a vehicle
    /// has waited [`PLATOON_MAX_WAIT`] as its lane's head, nothing conflicting with it is
    /// granted out of order).
    Platoon,
}

impl Algorithm {
    /// Every algorithm, in the order of the paper's Fig. 9 plus ours.
    pub const ALL: [Algorithm; 7] = [
        Algorithm::AllWayStop,
        Algorithm::AllWayStopSingle,
        Algorithm::Fifo,
        Algorithm::Concurrent,
        Algorithm::ConcurrentFair,
        Algorithm::Pipelined,
        Algorithm::Platoon,
    ];
    /// Short name.
    pub fn name(self) -> &'static str {
        match self {
            Algorithm::AllWayStop => "STOP",
            Algorithm::AllWayStopSingle => "STOP-1",
            Algorithm::Fifo => "FIFO",
            Algorithm::Concurrent => "CON",
            Algorithm::ConcurrentFair => "CON-fair",
            Algorithm::Pipelined => "PIPE",
            Algorithm::Platoon => "PLATOON",
        }
    }

    /// It takes the pipelined relaxations (1–4 of [`Algorithm::Pipelined`]).
    pub fn pipelined(self) -> bool {
        matches!(self, Algorithm::Pipelined | Algorithm::Platoon)
    }
}

/// Under [`Algorithm::Platoon`], how long a lane's head may wait while vehicles on
/// conflicting routes go ahead of it: past this, nothing that conflicts with it is granted
/// out of order (a signal's maximum green).
pub const PLATOON_MAX_WAIT: Duration = Duration::from_millis(60_000);

/// Distance (m) from the stop line within which a vehicle competes for a permission
/// under [`Algorithm::Pipelined`]: 30 m is dS(vImax) ≈ 12.4 m plus ~1.2 s at vImax, so a
/// vehicle granted at once never has to brake for its stop line.
pub const REQUEST_DISTANCE_M: f64 = 30.0;

/// How far (m) a vehicle's length may be from the length a layout's trails were checked
/// for ([`Layout::trails`]) for [`Algorithm::Platoon`] to let it trail or be trailed: the
/// same body, up to rounding far below the 0.1 m margin of the check.
pub const TRAIL_LENGTH_TOLERANCE_M: f64 = 1e-3;

/// How close (m) to its stop line a vehicle at standstill counts as "stopped at the line"
/// for All-Way STOP: the planner halts its front d0 = 0.5 m before the line; 1.5 m allows
/// for the last centimetres of its approach.
pub const STOP_LINE_ZONE_M: f64 = 1.5;

/// What a vehicle reports about itself to the intersection.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CrossingReport<F> {
    /// Vehicle id.
    pub id: u16,
    /// Its route (index into [`Layout::routes`]).
    pub route: u8,
    /// Its centre's distance along the route's whole path (m).
    pub s: F,
    /// Its speed (m/s).
    pub v: F,
    /// Its length (m).
    pub length: F,
    /// Its braking limit |amin|, if it declares one: a follower under
    /// [`Invariant::LeaderAware`] credits it with the distance it still travels braking no
    /// harder ([`safety::leader_credit`]); one that declares none is taken as a wall.
    pub brake: Option<BrakeLimit>,
}

/// A vehicle on a crossing vehicle's path known other than by its report to this
/// junction's manager: a sensor return, or a vehicle heard of on a road its path joins
/// ([`CrossingPlanner::hear_sensed`], [`CrossingPlanner::hear_mapped`]). It is taken as a
/// wall: a vehicle that may stop at once.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PathVehicle<F> {
    /// Its centre's distance along the path (m).
    pub s: F,
    /// Its length (m): its rear is half of it behind `s`.
    pub length: F,
}

/// Why a report was not taken.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum ManagerError {
    /// No such route.
    UnknownRoute,
    /// A field is NaN, infinite or out of range.
    BadValue,
    /// The manager already tracks `CAP` vehicles.
    Full,
    /// The vehicle changed its route after registering (the IC Protocol forbids it).
    RouteChanged,
    /// The report is physically impossible after the last one accepted from the same
    /// vehicle (see [`Manager::observe`]): the vehicle is a suspect from now on.
    Implausible,
    /// From a suspect: nothing it reports is taken any more.
    Distrusted,
}

/// The first sentence of each variant's documentation (and its data).
impl core::fmt::Display for ManagerError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::UnknownRoute => f.write_str("no such route"),
            Self::BadValue => f.write_str("a field is NaN, infinite or out of range"),
            Self::Full => f.write_str("the manager already tracks CAP vehicles"),
            Self::RouteChanged => f.write_str("the vehicle changed its route after registering (the IC Protocol forbids it)"),
            Self::Implausible => f.write_str("the report is physically impossible after the last one accepted from the same vehicle (see Manager::observe): the vehicle is a suspect from now on"),
            Self::Distrusted => f.write_str("from a suspect: nothing it reports is taken any more"),
        }
    }
}

impl core::error::Error for ManagerError {}

/// Slack (m) on a report's move since the last one accepted from the same vehicle,
/// forward and back: far above a bus's rounding (0.01 m), far below a lie that matters.
pub const PLAUSIBLE_POSITION_M: f64 = 0.5;
/// Slack (m/s) on a reported speed above vmax.
pub const PLAUSIBLE_SPEED_MPS: f64 = 0.5;

/// Where a vehicle first heard stands: what [`Manager::observe`] computed of its report.
#[derive(Debug, Clone, Copy)]
struct Start<F> {
    /// Its centre's distance along the path past the stop line, as far back as the
    /// reports' rounding allows.
    progress: F,
    /// Its front's distance to the stop line.
    to_line: F,
    /// Stopped in the stop-line zone.
    stopped: bool,
    /// It can no longer stop before the line.
    committed: bool,
}

/// A registered vehicle.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Entry<F> {
    /// Id.
    pub id: u16,
    /// Route.
    pub route: u8,
    /// Arrival τ(c): when it entered A_C, by the intersection's clock.
    pub tau: Instant,
    /// Distance of its centre past the A_S entry (negative before).
    pub progress: F,
    /// Distance from its front to the stop line (negative once inside).
    pub to_line: F,
    /// Its last reported speed (m/s).
    pub v: F,
    /// When it was first seen stopped at its stop line (All-Way STOP).
    pub stopped_at: Option<Instant>,
    /// This manager grants it a permission (a lease is sent to it each period).
    pub permitted: bool,
    /// It can no longer stop before its line, or is inside A_S (see
    /// [`Manager::observe`]): it holds its zones whatever the algorithm decides, with a
    /// permission or not.
    pub committed: bool,
    /// When its last report was accepted (the manager's clock).
    pub heard_at: Instant,
    /// It sent a physically impossible report (or one its roadside measurement belies):
    /// nothing it reports is taken any more, and if it held a permission or was committed
    /// then, it holds its zones until the roadside sensor measures it gone (for good,
    /// without one). Without a roadside sensor its record is frozen at its last trusted
    /// report and it is never granted again; with one, its record follows the sensor
    /// and it is granted as any vehicle ([`Manager::measure`], [`Entry::managed`]).
    pub suspect: bool,
    /// Its centre's distance past the A_S entry as the manager's roadside sensor last
    /// measured it ([`Manager::measure`]), if it has one and has seen it.
    pub measured: Option<F>,
    /// When the fair scan first refused it as its lane's head (it then held back every
    /// route conflicting with its own); the bound of [`Algorithm::Platoon`].
    pub waiting_since: Option<Instant>,
}

/// The terms of a manager's permissions (IC Protocol (iii)): every permission is a lease
/// that the manager renews each period while it stands, and that lapses by itself.
///
/// Why leases: a manager that stops (power, software, its link) cannot withdraw what it
/// granted; a lease ends anyway, so a vehicle that has not yet entered A_S when renewals
/// stop halts at its stop line. The lease must outlive its own delivery and a few lost
/// renewals, hence `length` is the bus's notification bound plus a margin.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Lease {
    /// How long a grant stays valid after the manager sends it: its `until` minus the
    /// time of sending ([`Manager::lease_until`]).
    pub length: Duration,
    /// Bound on how late a vehicle's report reaches the manager after the state it
    /// reports: the bus's delay bound (at least one period) plus the clock error ε
    /// ([`crate::time`]).
    pub notify: Duration,
}

impl Default for Lease {
    /// 0.1 s leases on a bus that delivers within one period h = 10 ms.
    fn default() -> Self {
        Self {
            length: Duration::from_millis(100),
            notify: Duration::from_millis(10),
        }
    }
}

impl Lease {
    /// How long a manager that has just started grants nothing ([`Manager::update`]):
    /// the longest an earlier incarnation's lease can still be acted on (`length`), then
    /// until a vehicle that entered A_S on it at the last moment has been heard there
    /// (a period and the notification bound: 2 · `notify` ≥ both).
    pub const fn quiet(&self) -> Duration {
        self.length
            .saturating_add(self.notify)
            .saturating_add(self.notify)
    }
}

impl<F> Entry<F> {
    /// It holds its route's conflict zones: this manager permits it, or it is committed
    /// (it will be in A_S whatever is decided).
    pub fn holds(&self) -> bool {
        self.permitted || self.committed
    }

    /// The manager knows where it is, and may grant it: it is no suspect, or a suspect
    /// its roadside sensor has measured ([`Manager::measure`]).
    ///
    /// Why a measured suspect may be granted: what the manager needs of a holder is where
    /// it surely is (to free the zones behind it, `Manager::released` (private), and to
    /// take it off the list), and a measurement gives that whatever the vehicle says.
    /// Without one, a suspect granted would hold its route for good, since its word that
    /// it left is not taken — and one that is never granted costs only itself.
    pub fn managed(&self) -> bool {
        !self.suspect || self.measured.is_some()
    }
}

/// The intersection manager for up to `CAP` vehicles.
///
/// **Starting (and restarting) safely.** A manager cannot tell a first start from a
/// restart after an outage: the grants of the incarnation before it may still be valid,
/// and the vehicles holding them may enter A_S on them — about which the new manager,
/// having heard nothing, knows nothing. So from its first [`Manager::update`] on, a
/// manager grants nothing for [`Lease::quiet`]: by then every lease it may have sent
/// before has lapsed, and every vehicle that entered A_S on one has reported itself
/// inside A_S, where [`Manager::observe`] holds its route's conflict zones for it as a
/// permission would. After that, every grant it makes is checked against everything an
/// old lease could have let in. (A red team's 10 ms outage at a queued intersection
/// caused collisions under every algorithm before this rule: the restarted manager
/// granted a route crossing one whose vehicle entered A_S on its old lease.)
#[derive(Debug, Clone)]
pub struct Manager<F, const CAP: usize> {
    layout: Layout<F>,
    algorithm: Algorithm,
    entries: Vec<Entry<F>, CAP>,
    crossed: u32,
    /// Half the step to which reported positions were rounded (0: exact reports).
    half_step: F,
    lease: Lease,
    /// When its first update ran (its clock at start-up).
    started: Option<Instant>,
    /// Half the step to which reported speeds were rounded (0: exact reports).
    half_speed_step: F,
    /// The limits it assumes of every vehicle (the weakest brakes among them): which
    /// vehicles can no longer stop before their stop line ([`Manager::observe`]).
    vehicles: Params<F>,
    /// The error bound (m) of its roadside sensor, if it has one ([`Manager::measure`]).
    roadside: Option<F>,
}

impl<F: Real, const CAP: usize> Manager<F, CAP> {
    /// A manager for `layout` running `algorithm`.
    pub fn new(layout: Layout<F>, algorithm: Algorithm) -> Self {
        Self {
            layout,
            algorithm,
            entries: Vec::new(),
            crossed: 0,
            half_step: F::ZERO,
            lease: Lease::default(),
            started: None,
            half_speed_step: F::ZERO,
            vehicles: Params::table_i(),
            roadside: None,
        }
    }

    /// Gives the manager a roadside sensor that measures every vehicle in A_C within
    /// ± `error` m ([`Manager::measure`]); `None` (the default): the paper's manager, which
    /// knows the vehicles from their reports alone. An error that is not finite, negative,
    /// or over 1 m (about the onboard sensors' bound, [`crate::Sensing::validate`]) is
    /// refused: two vehicles of one lane are L + d0 apart, more than twice that, and the
    /// manager orders a suspect among them by its measurement (`follow`, private).
    pub fn set_roadside_sensor(&mut self, error: Option<F>) -> Result<(), ConfigError> {
        if error.is_some_and(|e| !(e.is_finite() && e >= F::ZERO && e <= F::ONE)) {
            return Err(ConfigError::InvalidSensing);
        }
        self.roadside = error;
        Ok(())
    }

    /// A roadside measurement of registered vehicle `id`, taken this period: its centre at
    /// `s` along its route's path (m), within the sensor's error.
    ///
    /// **Why a measurement.** Reports are checked against physics ([`Manager::observe`]),
    /// which catches a vehicle whose claims jump, but a vehicle that misreports its
    /// position by a constant offset from its first report on, or by one that creeps,
    /// stays within every physical bound: no check on reports can tell it from the truth,
    /// and the manager frees conflict zones and routes on reported progress. With a
    /// roadside sensor the manager frees a zone, or takes a vehicle off its list, only
    /// where the measurement (taken at its nearest) agrees; and a vehicle whose report
    /// differs from the measurement by more than the error and
    /// [`PLAUSIBLE_POSITION_M`] is a suspect, as one whose report jumps.
    pub fn measure(&mut self, id: u16, s: F) -> Result<(), ManagerError> {
        let Some(err) = self.roadside else {
            return Ok(());
        };
        if !s.is_finite() {
            return Err(ManagerError::BadValue);
        }
        let Some(i) = self.entries.iter().position(|e| e.id == id) else {
            return Ok(());
        };
        let Some(route) = self
            .entries
            .get(i)
            .and_then(|e| self.layout.route(usize::from(e.route)))
        else {
            return Ok(());
        };
        let (entry, exit) = (route.path.entry(), route.path.exit());
        let Some(e) = self.entries.get_mut(i) else {
            return Ok(());
        };
        let measured = s - entry;
        e.measured = Some(measured);
        if e.suspect {
            // Its word is not taken: its record follows the sensor (Entry::managed).
            follow(e, measured, err);
        }
        // A report is older than the measurement (by up to the notification bound), and
        // positions only grow: a vehicle may be measured ahead of its last report by what
        // vmax covers in that time, never behind it.
        let slack = err + F::from_f64(PLAUSIBLE_POSITION_M) + self.half_step;
        let lag: F = self.lease.notify.as_secs::<F>() * self.vehicles.v_max();
        let ahead_of_truth = e.progress - measured > slack;
        let behind_truth = measured - e.progress > slack + lag;
        if !e.suspect && (ahead_of_truth || behind_truth) {
            e.suspect = true;
            e.committed = e.committed || e.permitted;
            return Err(ManagerError::Implausible);
        }
        // Its rear surely past A_S: off the list (C^I_t (25)), whatever it reports — a
        // suspect too: the sensor, not its word, says it has left.
        if measured - err - F::HALF * self.vehicles.length() >= exit - entry {
            self.entries.swap_remove(i);
            self.crossed = self.crossed.saturating_add(1);
        }
        Ok(())
    }

    /// Reports reach the manager with speeds rounded to `speed` (m/s): a vehicle may be up
    /// to half a step faster than reported, and is taken so when the manager judges
    /// whether it can still stop before its line. Zero (the default) takes them as exact.
    pub fn set_speed_resolution(&mut self, speed: F) -> Result<(), ConfigError> {
        if !valid_resolution(speed) {
            return Err(ConfigError::InvalidResolution);
        }
        self.half_speed_step = F::HALF * speed;
        Ok(())
    }

    /// The kinematic limits it assumes of every vehicle it manages — for mixed traffic,
    /// those of the weakest brakes (default: Table I).
    pub fn set_vehicle_params(&mut self, p: Params<F>) {
        self.vehicles = p;
    }

    /// Sets the terms of its leases (see [`Lease`]); a notification bound of zero is
    /// refused (a report takes at least a period).
    pub fn set_lease(&mut self, lease: Lease) -> Result<(), ConfigError> {
        if lease.notify == Duration::ZERO || lease.length == Duration::ZERO {
            return Err(ConfigError::InvalidLatency);
        }
        self.lease = lease;
        Ok(())
    }

    /// The terms of its leases.
    pub fn lease(&self) -> Lease {
        self.lease
    }

    /// The end of a lease sent at `now`.
    pub fn lease_until(&self, now: Instant) -> Instant {
        now.saturating_add(self.lease.length)
    }

    /// `true` while it may not grant yet at `now`: within [`Lease::quiet`] of its first
    /// update (before the first update, too).
    pub fn quiet(&self, now: Instant) -> bool {
        self.started
            .is_none_or(|t0| now < t0.saturating_add(self.lease.quiet()))
    }

    /// Reports reach the manager with positions rounded to `position` (m), e.g. by a CAN
    /// codec: a reported s may then be up to half a step ahead of the vehicle. The
    /// manager takes every report half a step further back — registration, progress
    /// through A_S (Step 4's conflict-zone test) and departure onto the outlet all
    /// happen no earlier than on exact data. Zero (the default) takes reports as exact.
    pub fn set_position_resolution(&mut self, position: F) -> Result<(), ConfigError> {
        if !valid_resolution(position) {
            return Err(ConfigError::InvalidResolution);
        }
        self.half_step = F::HALF * position;
        Ok(())
    }

    /// The layout.
    pub fn layout(&self) -> &Layout<F> {
        &self.layout
    }

    /// The algorithm.
    pub fn algorithm(&self) -> Algorithm {
        self.algorithm
    }

    /// Registered vehicles (C^I_t).
    pub fn entries(&self) -> &[Entry<F>] {
        &self.entries
    }

    /// Vehicles that reached their outlet track so far.
    pub fn crossed(&self) -> u32 {
        self.crossed
    }

    /// `true` if vehicle `id` holds a permission.
    pub fn permitted(&self, id: u16) -> bool {
        self.entries.iter().any(|e| e.id == id && e.permitted)
    }

    /// `true` if vehicle `id` holds its route's conflict zones: it is permitted, or
    /// committed ([`Entry::holds`]).
    pub fn holds(&self, id: u16) -> bool {
        self.entries.iter().any(|e| e.id == id && e.holds())
    }

    /// Takes a vehicle's report at time `now`: registers it when it is first seen inside
    /// A_C (τ = now), tracks its progress, and removes it once it is on its outlet track
    /// (its rear past A_S). A bad report changes nothing.
    ///
    /// **Committed vehicles hold their zones.** A vehicle inside A_S, or one that can no
    /// longer stop before its stop line — its front within dS(v) (8) of the line, taken as
    /// far forward and as fast as the reports' rounding allows — is committed: it will be
    /// in A_S, with a permission from this manager or not. Every other vehicle stops
    /// before the line without a permission (IC Protocol (ii): its planner keeps the
    /// invariant toward the line, and its certified fallback brakes at once), so only
    /// these can enter without one: a lease granted by an earlier incarnation of this
    /// manager, or one that lapsed (lost renewals) while its holder was already too close
    /// to stop. Each holds its route's conflict zones as a permission would.
    pub fn observe(&mut self, r: &CrossingReport<F>, now: Instant) -> Result<(), ManagerError> {
        let route = self
            .layout
            .route(usize::from(r.route))
            .ok_or(ManagerError::UnknownRoute)?;
        if !([r.s, r.v, r.length].iter().all(|x| x.is_finite())
            && r.v >= F::ZERO
            && r.length > F::ZERO)
        {
            return Err(ManagerError::BadValue);
        }
        let (entry, exit) = (route.path.entry(), route.path.exit());
        let half = F::HALF * r.length;
        // The furthest back the vehicle can be, given the reports' rounding.
        let s = r.s - self.half_step;
        let idx = self.entries.iter().position(|e| e.id == r.id);
        if let Some(e) = idx.and_then(|i| self.entries.get_mut(i)) {
            if e.suspect {
                return Err(ManagerError::Distrusted);
            }
            if e.route != r.route {
                return Err(ManagerError::RouteChanged);
            }
            if !plausible(&self.vehicles, self.lease.notify, e, s - entry, r.v, now) {
                // Frozen where it was last trusted. Not granted again; one that could
                // already be in A_S holds its zones for good (see the type's docs).
                e.suspect = true;
                e.committed = e.committed || e.permitted;
                return Err(ManagerError::Implausible);
            }
        }
        if s - half >= exit {
            // On its outlet track: no longer in C^I_t (25) — on its word alone only where
            // there is no roadside sensor; with one, [`Manager::measure`] takes it off
            // when the sensor sees its rear past A_S (a measurement that showed that
            // already took it off, so no measured entry is still here to confirm).
            if let Some(i) = idx.filter(|_| self.roadside.is_none()) {
                self.entries.swap_remove(i);
                self.crossed = self.crossed.saturating_add(1);
                return Ok(());
            }
            if idx.is_none() {
                return Ok(());
            }
        }
        let to_line = entry - (s + half);
        // As far forward and as fast as the rounding allows: can it still stop before the
        // line (its front not past it)?
        // Its centre as far forward as its report allows, or as the roadside measurement
        // (plus its error) does, if that is further.
        let reported = r.s + self.half_step;
        let furthest = idx
            .and_then(|i| self.entries.get(i))
            .and_then(|e| Some(e.measured? + entry + self.roadside?))
            .map_or(reported, |m| m.max(reported));
        let front_gap = entry - (furthest + half);
        let v_hi = r.v + self.half_speed_step;
        let committed = to_line < F::ZERO || front_gap < safety::d_s(&self.vehicles, v_hi);
        let stopped =
            r.v == F::ZERO && to_line >= F::ZERO && to_line <= F::from_f64(STOP_LINE_ZONE_M);
        match idx.and_then(|i| self.entries.get_mut(i)) {
            Some(e) => {
                e.progress = s - entry;
                e.to_line = to_line;
                e.v = r.v;
                e.heard_at = now;
                if stopped && e.stopped_at.is_none() {
                    e.stopped_at = Some(now);
                }
                e.committed = committed;
            }
            None => {
                let start = Start {
                    progress: s - entry,
                    to_line,
                    stopped,
                    committed,
                };
                self.register(r, start, now)?;
            }
        }
        Ok(())
    }

    /// Registers a vehicle first heard in `r`, if it is inside A_C (until then it has
    /// no business with this manager).
    fn register(
        &mut self,
        r: &CrossingReport<F>,
        start: Start<F>,
        now: Instant,
    ) -> Result<(), ManagerError> {
        let route = self
            .layout
            .route(usize::from(r.route))
            .ok_or(ManagerError::UnknownRoute)?;
        // Only an unregistered vehicle needs its pose: is it inside A_C yet?
        let pose = route.path.pose_at(r.s - self.half_step);
        if !self.layout.in_comm_region(pose.x, pose.y) {
            return Ok(());
        }
        if r.v > self.vehicles.v_max() + F::from_f64(PLAUSIBLE_SPEED_MPS) {
            return Err(ManagerError::Implausible);
        }
        self.entries
            .push(Entry {
                id: r.id,
                route: r.route,
                tau: now,
                progress: start.progress,
                to_line: start.to_line,
                v: r.v,
                stopped_at: start.stopped.then_some(now),
                permitted: false,
                // First heard committed (see [`Manager::observe`]): a manager restarted
                // while the vehicle crossed or was about to.
                committed: start.committed,
                heard_at: now,
                suspect: false,
                measured: None,
                waiting_since: None,
            })
            .map_err(|_| ManagerError::Full)
    }

    /// Forgets vehicle `id` (e.g. its messages stopped: its permission lapses) — unless
    /// it is a suspect holding its zones: its word that it left is not taken.
    pub fn forget(&mut self, id: u16) {
        self.entries
            .retain(|e| e.id != id || (e.suspect && e.holds()));
    }

    /// Recomputes the permissions by the algorithm at `now`; nothing new is granted while
    /// the manager is [`Manager::quiet`] (see the type's docs).
    ///
    /// Every algorithm but [`Algorithm::Concurrent`] (kept exactly as the paper writes
    /// it) orders vehicles consistently with their order on each inlet lane and gives
    /// up a permission that a vehicle cannot use; see `Manager::priority` and
    /// `Manager::revoke_blocked` (private; their comments in the source) for why both are
    /// needed for liveness.
    pub fn update(&mut self, now: Instant) {
        let t0 = *self.started.get_or_insert(now);
        if now < t0.saturating_add(self.lease.quiet()) {
            return;
        }
        let as_written = self.algorithm == Algorithm::Concurrent;
        if !as_written {
            self.revoke_blocked();
        }
        if let Some(err) = self.roadside {
            // A measured suspect reports nothing: the sensor says when it stands at its line.
            for e in self.entries.iter_mut() {
                if e.suspect
                    && e.measured.is_some()
                    && e.stopped_at.is_none()
                    && at_line(e.to_line, err)
                {
                    e.stopped_at = Some(now);
                }
            }
        }
        match self.algorithm {
            Algorithm::Fifo | Algorithm::AllWayStopSingle => {
                if self.entries.iter().any(Entry::holds) {
                    return;
                }
                let order = self.priority(false);
                // A suspect not measured is never granted, and holds back no one by
                // waiting.
                let suspect = |i: &&usize| self.entries.get(**i).is_none_or(|e| !e.managed());
                let first = if self.algorithm == Algorithm::AllWayStopSingle {
                    // Served in the order they stopped (only a lane's first vehicle can
                    // stop at its line); ties in priority order.
                    let stopped = |i: &usize| self.entries.get(*i).and_then(|e| e.stopped_at);
                    order
                        .iter()
                        .filter(|i| stopped(i).is_some() && !suspect(i))
                        .min_by(|a, b| stopped(a).cmp(&stopped(b)))
                } else {
                    order.iter().find(|i| !suspect(i))
                };
                if let Some(e) = first.copied().and_then(|b| self.entries.get_mut(b)) {
                    e.permitted = true;
                }
            }
            Algorithm::AllWayStop
            | Algorithm::Concurrent
            | Algorithm::ConcurrentFair
            | Algorithm::Pipelined
            | Algorithm::Platoon => self.scan(now, as_written),
        }
    }

    /// Steps 3–5 of Concurrent Crossing over the vehicles in priority order (Step 1: the
    /// permitted keep their permission, they are still in C^I_t; Step 2: the rest in
    /// priority order — FIFO, lane-consistent but for CON), with the pipelined and
    /// platoon relaxations where chosen.
    fn scan(&mut self, now: Instant, as_written: bool) {
        let order = if self.algorithm == Algorithm::AllWayStop {
            self.stop_order()
        } else {
            self.priority(as_written)
        };
        // Routes of the vehicles refused so far (`stuck`: those refused because a route
        // held conflicts with theirs), and since when each has waited at most.
        let mut waiting: u32 = 0;
        let mut stuck: u32 = 0;
        let mut since = [now; MAX_ROUTES];
        let mut grant: Vec<usize, CAP> = Vec::new();
        let mut refused: Vec<usize, CAP> = Vec::new();
        for &i in order.iter() {
            let Some(c) = self.entries.get(i) else {
                continue;
            };
            if c.holds() || !c.managed() {
                continue;
            }
            if self.algorithm.pipelined()
                && (!(c.to_line <= F::from_f64(REQUEST_DISTANCE_M))
                    || self.queued_behind(c, &grant))
            {
                continue;
            }
            let blocking = self
                .layout
                .conflicts
                .get(usize::from(c.route))
                .map_or(0, |m| m & waiting);
            let fair = self.algorithm == Algorithm::Concurrent || blocking == 0;
            let admissible = self.admissible(c, &grant);
            let ok = admissible && (fair || self.joins_flow(c, blocking, stuck, &since, now));
            if ok {
                let _ = grant.push(i);
            } else {
                if !admissible {
                    stuck |= 1 << c.route;
                }
                waiting |= 1 << c.route;
                let r = usize::from(c.route);
                if let Some(t) = since.get_mut(r) {
                    *t = (*t).min(c.waiting_since.unwrap_or(now));
                }
                let _ = refused.push(i);
            }
        }
        for i in grant {
            if let Some(e) = self.entries.get_mut(i) {
                e.permitted = true;
            }
        }
        for i in refused {
            if let Some(e) = self.entries.get_mut(i) {
                e.waiting_since.get_or_insert(now);
            }
        }
    }

    /// [`Algorithm::AllWayStop`]'s order: only the vehicles that have stopped at their line
    /// (only a lane's first vehicle can), in the order they stopped, ties in priority
    /// order.
    fn stop_order(&self) -> Vec<usize, CAP> {
        let priority = self.priority(false);
        let mut order = priority.clone();
        order.retain(|i| self.entries.get(*i).is_some_and(|e| e.stopped_at.is_some()));
        let stopped = |i: &usize| self.entries.get(*i).and_then(|e| e.stopped_at);
        let rank = |i: &usize| priority.iter().position(|j| j == i);
        order.sort_unstable_by(|a, b| stopped(a).cmp(&stopped(b)).then(rank(a).cmp(&rank(b))));
        order
    }

    /// `true` if every waiting route in `blocking` has waited less than
    /// [`PLATOON_MAX_WAIT`] (`since`: the earliest a vehicle refused on each route began
    /// to wait): [`Algorithm::Platoon`]'s exception to fairness may still pass it.
    fn patient(blocking: u32, since: &[Instant; MAX_ROUTES], now: Instant) -> bool {
        !since
            .iter()
            .enumerate()
            .any(|(r, t)| blocking & (1 << r) != 0 && now.since(*t) >= PLATOON_MAX_WAIT)
    }

    /// [`Algorithm::Platoon`]'s exception to fairness, joining the flow: every
    /// earlier vehicle waiting on a route `c` conflicts with (`blocking`) was refused
    /// because a route already held or granted conflicts with its own (`stuck`) — it
    /// could not go now whatever `c` does, as a vehicle at a red light cannot — and has
    /// waited less than [`PLATOON_MAX_WAIT`]. Then `c`, admissible beside every holder,
    /// goes with them: a signal's phase, made of whatever fits together. Not behind a
    /// suspect on its own inlet lane: its crossing planner would follow what the suspect
    /// says of itself, which the manager no longer believes.
    fn joins_flow(
        &self,
        c: &Entry<F>,
        blocking: u32,
        stuck: u32,
        since: &[Instant; MAX_ROUTES],
        now: Instant,
    ) -> bool {
        // The scan over the entries last: it runs only where the cheap tests pass.
        let behind_suspect = || {
            self.entries.iter().any(|l| {
                l.suspect
                    && l.id != c.id
                    && self.inlet_of(l) == self.inlet_of(c)
                    && l.progress > c.progress
            })
        };
        self.algorithm == Algorithm::Platoon
            && blocking & !stuck == 0
            && Self::patient(blocking, since, now)
            && !behind_suspect()
    }

    /// The inlet lane of entry `e`, as an index in Ψ's order ([`Layout::inlet_index`]).
    fn inlet_of(&self, e: &Entry<F>) -> usize {
        self.layout
            .route(usize::from(e.route))
            .map_or(usize::MAX, |r| self.layout.inlet_index(r.inlet))
    }

    /// `true` if `a` is ahead of `b` on the same inlet lane, `a` not having entered A_S.
    fn ahead_on_inlet(&self, a: &Entry<F>, b: &Entry<F>) -> bool {
        self.inlet_of(a) == self.inlet_of(b)
            && a.id != b.id
            && a.progress > b.progress
            && a.to_line >= F::ZERO
    }

    /// `true` if a vehicle ahead of `c` on its inlet lane is neither permitted nor
    /// granted in this scan (`granted_now`): `c` cannot reach the stop line before that
    /// one has crossed it. The pipelined manager then neither grants `c` (the grant
    /// would be withdrawn, [`Manager::revoke_blocked`]) nor counts it as waiting: a
    /// queued follower's route holds back no other route, since its turn begins only
    /// when the vehicle ahead of it goes. The first waiting vehicle of each lane still
    /// holds back every route that conflicts with its own, which keeps the scan
    /// starvation-free: each lane's head gets its turn, then the next becomes the head.
    /// With nothing granted yet (`&[]`) it is also the test of [`Manager::revoke_blocked`].
    fn queued_behind(&self, c: &Entry<F>, granted_now: &[usize]) -> bool {
        self.entries
            .iter()
            .enumerate()
            .any(|(i, l)| !l.holds() && !granted_now.contains(&i) && self.ahead_on_inlet(l, c))
    }

    /// Liveness fix 2 (root cause of the queue deadlocks the liveness sweeps found): a permitted vehicle
    /// that has not entered A_S while an *unpermitted* vehicle is ahead of it on its inlet
    /// lane cannot use its permission — it cannot pass that vehicle — yet under FIFO it
    /// keeps every other vehicle out, and under the Concurrent algorithms it keeps
    /// conflicting routes out, while the vehicle ahead waits for exactly those: a
    /// deadlock. Such a permission is withdrawn (its lease lapses).
    ///
    /// Safe: the vehicle ahead is not permitted, so by IC Protocol (ii) it is still
    /// before the stop line, and the follower keeps the invariant toward it (it is an
    /// obstacle on their common inlet), so the follower can stop before the vehicle
    /// ahead and hence before the line; withdrawing only ever adds the stop line to
    /// constraints it already keeps. Positions in reports may be stale, but the order of
    /// two vehicles on one lane cannot change.
    fn revoke_blocked(&mut self) {
        let mut revoke: Vec<usize, CAP> = Vec::new();
        for (i, f) in self.entries.iter().enumerate() {
            let usable = !f.permitted || f.committed || !self.queued_behind(f, &[]);
            if !usable {
                let _ = revoke.push(i);
            }
        }
        for i in revoke {
            if let Some(e) = self.entries.get_mut(i) {
                e.permitted = false;
            }
        }
    }

    /// Indices of the entries in priority order ≺^I_t (26): FIFO by arrival τ, ties by
    /// the route index Ψ, then id (total on any input).
    ///
    /// Liveness fix 1: unless `as_written`, a vehicle ranks by the earliest arrival of
    /// itself and every vehicle behind it on its inlet lane, and ties go by inlet lane
    /// (in Ψ's order across lanes), then by position along it (ahead first). So no vehicle ever ranks before a vehicle ahead of it on its own lane.
    /// The paper's order breaks ties between vehicles that arrive together — all that
    /// start inside A_C, or reports delayed or lost on a real bus — by Ψ alone, which can
    /// put a follower first: it gets the permission it cannot use (see
    /// [`Manager::revoke_blocked`]). When vehicles arrive one at a time, a follower
    /// always after its leader, both orders coincide.
    fn priority(&self, as_written: bool) -> Vec<usize, CAP> {
        let mut key: Vec<Instant, CAP> = Vec::new();
        for e in self.entries.iter() {
            let behind = self
                .entries
                .iter()
                .filter(|b| !as_written && self.ahead_on_inlet(e, b))
                .map(|b| b.tau);
            let _ = key.push(behind.fold(e.tau, |k, t| k.min(t)));
        }
        let mut order: Vec<usize, CAP> = Vec::new();
        for i in 0..self.entries.len() {
            let _ = order.push(i);
        }
        let cmp = |a: &usize, b: &usize| {
            let (Some(x), Some(y), Some(kx), Some(ky)) = (
                self.entries.get(*a),
                self.entries.get(*b),
                key.get(*a),
                key.get(*b),
            ) else {
                return Ordering::Equal;
            };
            let by_key = kx.cmp(ky);
            if as_written {
                return by_key.then(x.route.cmp(&y.route)).then(x.id.cmp(&y.id));
            }
            by_key
                .then(self.inlet_of(x).cmp(&self.inlet_of(y)))
                .then(
                    y.progress
                        .partial_cmp(&x.progress)
                        .unwrap_or(Ordering::Equal),
                )
                .then(x.route.cmp(&y.route))
                .then(x.id.cmp(&y.id))
        };
        order.sort_unstable_by(cmp);
        order
    }

    /// How far past its A_S entry a holder surely is, for freeing the zones behind it: as
    /// reported, and no further than measured (at its nearest) when the manager has a
    /// roadside sensor — not at all, if the sensor has not seen it.
    fn released(&self, h: &Entry<F>) -> F {
        match self.roadside {
            None => h.progress,
            Some(err) => h
                .measured
                .map_or(F::from_f64(-1e30), |m| h.progress.min(m - err)),
        }
    }

    /// `true` if, under [`Algorithm::Platoon`], `c` may follow holder `h` into A_S from
    /// their common inlet lane on another route ([`Layout::trails`]): `h` is no suspect
    /// (`c`'s planner would follow what `h` says of itself), and both are of the
    /// length the trails were checked for (within [`TRAIL_LENGTH_TOLERANCE_M`]; a
    /// vehicle's length is twice the distance from its centre to its front,
    /// `−(to_line + progress)`). `c`'s crossing planner keeps `h` as a wall until `h`'s
    /// centre has passed its conflict zone with `c`'s route
    /// ([`CrossingPlanner::step`]), so the two stay L + d0 apart along their common arc
    /// length, where the layout has checked that their footprints cannot meet.
    fn trails(&self, h: &Entry<F>, c: &Entry<F>) -> bool {
        let l = self.layout.trail_length;
        let tol = F::from_f64(TRAIL_LENGTH_TOLERANCE_M);
        let fits = |e: &Entry<F>| (-F::TWO * (e.to_line + e.progress) - l).abs() <= tol;
        // `may_trail` holds only for two routes of one inlet lane (or a route and itself,
        // which the caller has already let follow), so the lane needs no test of its own.
        self.algorithm == Algorithm::Platoon
            && !h.suspect
            && self
                .layout
                .may_trail(usize::from(h.route), usize::from(c.route))
            && fits(h)
            && fits(c)
    }

    /// Step 4's test: c's route conflicts with no route held by a permitted vehicle or
    /// one granted earlier in this scan (with the pipelined relaxations when chosen).
    fn admissible(&self, c: &Entry<F>, granted_now: &[usize]) -> bool {
        let holders = self
            .entries
            .iter()
            .filter(|e| e.holds())
            .chain(granted_now.iter().filter_map(|&i| self.entries.get(i)));
        for h in holders {
            let (hr, cr) = (usize::from(h.route), usize::from(c.route));
            if !self.layout.conflict(hr, cr) {
                continue;
            }
            if self.algorithm.pipelined() {
                if (hr == cr || self.trails(h, c)) && h.progress > c.progress {
                    // 1: following on the same route (or, under PLATOON, on a route
                    // that trails the holder's), behind the holder.
                    continue;
                }
                let end = self
                    .layout
                    .zone_end
                    .get(hr)
                    .and_then(|row| row.get(cr))
                    .copied()
                    .unwrap_or(F::from_f64(1e30));
                // 2: the holder's centre is past its conflict zone with c's route — as
                // reported, and as measured if the manager measures.
                if hr != cr && self.released(h) > end + F::from_f64(CONFLICT_SAMPLE_M) {
                    continue;
                }
            }
            return false;
        }
        true
    }
}

/// A suspect's record moved to where the roadside sensor measured its centre (`measured`
/// past the A_S entry): its progress, and its front's distance to the stop line — its
/// half-length is what its last trusted report made of the two (`to_line` = −(progress +
/// L/2), [`Manager::observe`]).
///
/// The zones behind it are freed by the measurement's nearest bound, not by this record
/// (`Manager::released`); the record serves the order and the request distance. It is
/// committed — it holds its zones with a permission or without — while its front is
/// surely past its line (by more than the sensor's error `err`): a vehicle that keeps
/// the protocol and lies only in words stands before its line until granted, and one
/// granted keeps its permission until measured gone or withdrawn while queued behind an
/// unpermitted vehicle on its lane, which it cannot pass (`Manager::revoke_blocked`:
/// two vehicles of one lane are L + d0 apart, more than twice any error the sensor may
/// have, so the measured order is the true one). Frozen as it was when it lied, the
/// record held a permission given on a lie for good: a liar claiming to be 29.5 m
/// further on was granted ahead of the vehicle in front of it, and both waited forever
/// (`host-sim liars`, case 18).
fn follow<F: Real>(e: &mut Entry<F>, measured: F, err: F) {
    let half = -(e.to_line + e.progress);
    e.progress = measured;
    e.to_line = -(measured + half);
    e.committed = e.to_line < -err;
}

/// `true` if a suspect measured `to_line` from its stop line (its front) may be standing
/// at it, the sensor's error `err` either way: All-Way STOP then counts it as stopped
/// (only the order of service depends on it; every grant is checked against the holders).
fn at_line<F: Real>(to_line: F, err: F) -> bool {
    to_line >= -err && to_line <= F::from_f64(STOP_LINE_ZONE_M) + err
}

/// Whether a report of progress `progress` past the A_S entry at speed `v`, heard at
/// `now`, is physically possible after `last`, the last accepted from the same vehicle:
/// no faster than vmax (+ [`PLAUSIBLE_SPEED_MPS`]), no further forward than vmax can take
/// it in the time between (each report may have been delayed by up to `notify`, so the
/// time between their sending may be longer by that much), and not backwards — each with
/// [`PLAUSIBLE_POSITION_M`] to spare.
///
/// Why the manager checks: authentication (SecOC) proves who sent a report, not that it
/// is true, and the manager releases conflict zones and frees routes on the reported
/// progress. A vehicle that claims, from mid-run, to be 15 m further on than it is would
/// otherwise have its zones given away while it is still in them (a red team found
/// exactly that under the pipelined algorithm). A lie that stays within the physical
/// bounds from the first report on cannot be told from the truth by any check on the
/// reports; only a measurement bounds it.
fn plausible<F: Real>(
    p: &Params<F>,
    notify: Duration,
    last: &Entry<F>,
    progress: F,
    v: F,
    now: Instant,
) -> bool {
    let margin = F::from_f64(PLAUSIBLE_POSITION_M);
    let dt: F = now.since(last.heard_at).saturating_add(notify).as_secs();
    let reach = p.v_max() * dt + margin;
    let moved = progress - last.progress;
    v <= p.v_max() + F::from_f64(PLAUSIBLE_SPEED_MPS) && moved <= reach && moved >= -margin
}

/// Another vehicle's newest report, as a crossing vehicle keeps it.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Heard<F> {
    report: CrossingReport<F>,
    stamp: Instant,
}

/// The vehicle side of the Intersection-Crossing Protocol: one vehicle's planner along
/// its route's path (inlet track, route through A_S, outlet track), fed with what it
/// hears (other vehicles' reports, permissions, departures).
///
/// (i) No lane change inside A_C: the route is fixed for the whole path. (ii) Without a
/// live permission the stop line — the entry of A_S — is x_R in (22); once its front is
/// past the line the vehicle is committed (Lemma 14 (ii): a permission is kept until
/// the vehicle is on its outlet). (iii) Permissions are leases from the manager.
/// Obstacles along the path: vehicles on the same route; vehicles on the same inlet
/// until their rear has left it; vehicles whose front is on the same outlet. Positions
/// only grow (v ≥ 0), so stale reports are conservative. Target switching of Sec. VII-B:
/// x^f is the end of the inlet while not permitted, the end of the route when permitted,
/// the end of the outlet after A_S.
#[derive(Debug, Clone)]
pub struct CrossingPlanner<F, const N: usize, const CAP: usize> {
    planner: crate::planner::Planner<F, N>,
    route: u8,
    id: u16,
    length: F,
    /// The end of its lease (its manager's clock), if it was ever granted one.
    lease_until: Option<Instant>,
    /// Step to which others' reported positions were rounded (0: exact).
    position_step: F,
    /// Bound on how long reports take to arrive (≥ h); see [`CrossingPlanner::set_notify_latency`].
    notify: F,
    /// The ego's range sensors, if any.
    sensing: Option<Sensing<F>>,
    /// Steps planned so far (saturating).
    steps: u32,
    /// Reports heard, the newest of each vehicle.
    others: Vec<Heard<F>, CAP>,
    /// Step to which others' reported speeds were rounded (0: exact).
    speed_step: F,
    /// The invariant kept toward the vehicles ahead on its path.
    invariant: Invariant,
    /// A report could not be kept (`CAP` vehicles already known): until the reports are
    /// cleared, some vehicle may be unknown, and the path is taken as blocked.
    overflowed: bool,
    /// Sensor returns of this step: vehicles on this vehicle's path, as measured.
    sensed: Vec<PathVehicle<F>, CAP>,
    /// Vehicles heard of in other frames this step (on the roads its inlet and outlet lie
    /// on): on this vehicle's path, as heard.
    mapped: Vec<PathVehicle<F>, CAP>,
    obstacles: Vec<crate::planner::Vehicle<F>, CAP>,
}

impl<F: Real, const N: usize, const CAP: usize> CrossingPlanner<F, N, CAP> {
    /// Vehicle `id` of `length` on `route`, planning with `planner`.
    pub fn new(planner: crate::planner::Planner<F, N>, id: u16, route: u8, length: F) -> Self {
        Self {
            route,
            id,
            length,
            lease_until: None,
            position_step: F::ZERO,
            speed_step: F::ZERO,
            invariant: Invariant::Paper,
            notify: planner.params().h(),
            sensing: None,
            steps: 0,
            others: Vec::new(),
            overflowed: false,
            sensed: Vec::new(),
            mapped: Vec::new(),
            obstacles: Vec::new(),
            planner,
        }
    }

    /// Sets a bound on how long other vehicles' reports take to arrive (delay, jitter,
    /// repeated losses; ≥ h, the default). Until that long has passed since the first
    /// step, a vehicle without sensors may not yet have heard of one just ahead of it, and
    /// takes its path as blocked (on a bus with 0.1 s of delay, a vehicle
    /// accelerated into one standing 0.5 m ahead that it had not heard of yet). Reports
    /// older than the bound may miss that their vehicle has reached this one's outlet;
    /// such a vehicle is placed where it may be. A non-finite value changes nothing.
    pub fn set_notify_latency(&mut self, latency: F) -> Result<(), ConfigError> {
        if !latency.is_finite() {
            return Err(ConfigError::InvalidLatency);
        }
        self.notify = latency.max(self.planner.params().h());
        Ok(())
    }

    /// Gives the vehicle its own range sensors ([`crate::sensing`]); their returns come
    /// through [`CrossingPlanner::hear_sensed`]. `None` (the default) is the paper's world.
    pub fn set_sensing(&mut self, sensing: Option<Sensing<F>>) -> Result<(), ConfigError> {
        if let Some(s) = &sensing {
            s.validate(self.planner.params())?;
        }
        self.sensing = sensing;
        Ok(())
    }

    /// This step's vehicles known from messages sent in other frames — a road carrying
    /// this vehicle's inlet or outlet, or the next junction — on this vehicle's path
    /// (replacing the last step's), each as long as it declared (or as the longest
    /// vehicle expected, if it declared nothing). Positions only grow (v ≥ 0), so stale
    /// ones are conservative and are used as they are. `Err(BadValue)` for a position
    /// that is not finite or a length that is not positive and finite; `Err(Full)` past
    /// `CAP`. A refused list leaves none heard.
    pub fn hear_mapped(&mut self, vehicles: &[PathVehicle<F>]) -> Result<(), ManagerError> {
        Self::hear_into(&mut self.mapped, vehicles)
    }

    /// This step's sensor returns: the vehicles its forward sensor sees on its own path
    /// (replacing the last step's), each where its centre was measured and as long as it
    /// was measured (a truck's rear is 8.25 m behind its centre, a car's 2.25 m). Each is
    /// taken `position_error_m` closer than measured. Errors as for
    /// [`CrossingPlanner::hear_mapped`].
    pub fn hear_sensed(&mut self, vehicles: &[PathVehicle<F>]) -> Result<(), ManagerError> {
        Self::hear_into(&mut self.sensed, vehicles)
    }

    fn hear_into(
        into: &mut Vec<PathVehicle<F>, CAP>,
        vehicles: &[PathVehicle<F>],
    ) -> Result<(), ManagerError> {
        into.clear();
        for &v in vehicles {
            if !(v.s.is_finite() && v.length.is_finite() && v.length > F::ZERO) {
                into.clear();
                return Err(ManagerError::BadValue);
            }
            if into.push(v).is_err() {
                into.clear();
                return Err(ManagerError::Full);
            }
        }
        Ok(())
    }

    /// The route.
    pub fn route(&self) -> u8 {
        self.route
    }

    /// Others' reports arrive with positions rounded to `position` (m) and speeds to
    /// `speed` (m/s), e.g. by a CAN codec: each reported vehicle may be up to half a step
    /// further back or ahead, so it is taken as an obstacle one step longer (half a step
    /// at each end), which keeps (2) and the invariant on the true positions; under
    /// [`Invariant::LeaderAware`] a leader is credited from its speed half a step lower.
    /// Zero (the default) takes reports as exact. A bad value changes nothing.
    pub fn set_bus_resolution(&mut self, position: F, speed: F) -> Result<(), ConfigError> {
        if !(valid_resolution(position) && valid_resolution(speed)) {
            return Err(ConfigError::InvalidResolution);
        }
        self.position_step = position;
        self.speed_step = speed;
        Ok(())
    }

    /// Chooses the invariant kept toward the vehicles ahead on its path (default
    /// [`Invariant::Paper`]). Under [`Invariant::LeaderAware`] a vehicle ahead that
    /// declared its braking limit is credited with the least distance it still travels
    /// from its last report ([`safety::leader_credit`]), however old that report is: the
    /// bound stays valid, and a follower that relied on it cannot do without it later
    /// (docs/spec.md §11); sensor returns, vehicles known from
    /// other frames, unknown space and the stop line stay walls. Every vehicle at a
    /// crossing plans with a planner and reports itself, so all of them cooperate.
    pub fn set_invariant(&mut self, invariant: Invariant) {
        self.invariant = invariant;
    }

    /// The invariant kept toward the vehicles ahead on its path.
    pub fn invariant(&self) -> Invariant {
        self.invariant
    }

    /// How far past its reported centre a vehicle ahead, at `wall` (the distance from this
    /// vehicle's centre to its reported centre), heard `age` ago, is credited under the
    /// invariant in use (see [`CrossingPlanner::set_invariant`]): nothing unless it leads
    /// ([`safety::leads`]: ahead by more than both half-lengths and d0 — a vehicle beside
    /// this one is no leader — or, once its report is old, its ghost's rear ahead of this
    /// vehicle's front). Not by its stamped position alone: a follower that relied on the
    /// credit may be past that once the report is old, and a credit withdrawn then would
    /// leave it no wall at all.
    fn credit(&self, r: &CrossingReport<F>, wall: F, age: F) -> F {
        let p = self.planner.params();
        let (v, step) = (r.v - F::HALF * self.speed_step, self.position_step);
        let Some(b) = r.brake.filter(|_| self.invariant == Invariant::LeaderAware) else {
            return F::ZERO;
        };
        let raw = wall - F::HALF * (r.length + self.length + step) - p.d0();
        safety::credit_if_leads(p, v, b.mps2(), raw, age)
    }

    /// Takes another vehicle's report stamped `stamp`; older or duplicate reports and
    /// its own are ignored. `Err(Full)` if `CAP` vehicles are already known.
    pub fn hear_report(
        &mut self,
        r: &CrossingReport<F>,
        stamp: Instant,
    ) -> Result<(), ManagerError> {
        if r.id == self.id {
            return Ok(());
        }
        if !(r.s.is_finite() && r.v.is_finite() && r.length.is_finite()) {
            return Err(ManagerError::BadValue);
        }
        let heard = Heard { report: *r, stamp };
        match self.others.iter_mut().find(|o| o.report.id == r.id) {
            Some(o) => {
                if stamp > o.stamp {
                    *o = heard;
                }
                Ok(())
            }
            None => self.others.push(heard).map_err(|_| {
                self.overflowed = true;
                ManagerError::Full
            }),
        }
    }

    /// Forgets every report (for a host that hands the planner its whole view of the
    /// junction each step), and the overflow with them.
    pub fn clear_reports(&mut self) {
        self.others.clear();
        self.overflowed = false;
    }

    /// Takes a permission lease addressed to anyone (only its own counts).
    pub fn hear_grant(&mut self, id: u16, until: Instant) {
        if id == self.id {
            self.lease_until = self.lease_until.max(Some(until));
        }
    }

    /// Vehicle `id` has left the area.
    pub fn hear_left(&mut self, id: u16) {
        self.others.retain(|o| o.report.id != id);
    }

    /// `true` if, at `now` and position `s`, the vehicle may be in A_S.
    pub fn permitted(&self, layout: &Layout<F>, s: F, now: Instant) -> bool {
        let entry = layout
            .route(usize::from(self.route))
            .map_or(F::ZERO, |r| r.path.entry());
        s + F::HALF * self.length > entry || self.lease_until.is_some_and(|u| u >= now)
    }

    /// Where along my path (my arc position) the vehicle of report `rep`, heard `age`
    /// seconds ago, stands as an obstacle, if it is on my path at all: on my route; on my
    /// inlet lane while its rear is on it, or on another route while its centre is in
    /// its conflict zone with mine; on my outlet once its front is (or may be) there.
    fn on_my_path(
        &self,
        layout: &Layout<F>,
        route: &Route<F>,
        rep: &CrossingReport<F>,
        age: F,
    ) -> Option<F> {
        let (r, x) = (rep.route, rep.s);
        let other = layout.route(usize::from(r))?;
        let (oe, ox) = (other.path.entry(), other.path.exit());
        let (exit, half) = (route.path.exit(), F::HALF * self.length);
        // How far it may have gone since its report: reports older than the bound may
        // not show it on my outlet yet.
        let reach = if age > self.notify {
            self.planner.params().v_max() * age
        } else {
            F::ZERO
        };
        // Its conflict zone with my route, along its route from its A_S entry.
        let zone = layout
            .zone_end
            .get(usize::from(r))
            .and_then(|row| row.get(usize::from(self.route)))
            .copied()
            .unwrap_or(F::ZERO);
        let shared = other.inlet == route.inlet;
        let in_zone =
            x - F::HALF * self.position_step - oe <= zone + F::from_f64(CONFLICT_SAMPLE_M);
        if r == self.route || (shared && (x - half < oe || in_zone)) {
            // Same route, or still partly on our common inlet — or past it but still in
            // its conflict zone with my route, where PLATOON may have let me follow it
            // (`Layout::trails`): as a wall at its arc length, which my own counts from
            // the same start, until it has surely left that zone (its report rounded
            // down), as the manager counts it.
            Some(x)
        } else if other.outlet == route.outlet && x + reach + half > ox {
            // Its front is (or may be) on my outlet: where it is along my path, at
            // least (positions only grow).
            Some(exit + (x - ox))
        } else {
            None
        }
    }

    /// One planning step at `now`, at path position `s` with v_{t−h} = `v_prev`.
    pub fn step(
        &mut self,
        layout: &Layout<F>,
        s: F,
        v_prev: F,
        now: Instant,
    ) -> Result<crate::planner::Command<F>, crate::planner::InputError> {
        let Some(route) = layout.route(usize::from(self.route)) else {
            return Err(crate::planner::InputError::NotFinite);
        };
        let (entry, exit) = (route.path.entry(), route.path.exit());
        let permitted = self.permitted(layout, s, now);
        let half = F::HALF * self.length;
        let p = *self.planner.params();
        self.obstacles.clear();
        for heard in self.others.iter() {
            let (rep, stamp) = (&heard.report, heard.stamp);
            let age: F = now.since(stamp).as_secs();
            let on_my_path = self.on_my_path(layout, route, rep, age);
            if let Some(x) = on_my_path {
                // Ahead of this vehicle: credited under the leader-aware invariant.
                let credit = self.credit(rep, x - s, age);
                let _ = self.obstacles.push(crate::planner::Vehicle::wall(
                    x + credit,
                    rep.length + self.position_step,
                ));
            }
        }
        // Sensor returns, each taken at its nearest; space beyond the forward range (or,
        // without sensors, all space until reports can have arrived) is not free.
        for v in self.mapped.iter() {
            let _ = self.obstacles.push(crate::planner::Vehicle::wall(
                v.s,
                v.length + self.position_step,
            ));
        }
        let e = self.sensing.map_or(F::ZERO, |x| x.position_error_m);
        for v in self.sensed.iter() {
            let _ = self
                .obstacles
                .push(crate::planner::Vehicle::wall(v.s - e, v.length));
        }
        // Not yet heard of everyone (without sensors to see for itself), or a vehicle it
        // could not keep: nothing is known free.
        let blind = (self.sensing.is_none() && still_unheard(self.steps, p.h(), self.notify))
            || self.overflowed;
        let unknown = match (self.sensing, blind) {
            (_, true) => Some(s + F::from_f64(1e-3)),
            (Some(sn), false) => Some(s + half + sn.ahead_m + half),
            (None, false) => None,
        };
        if let Some(x) = unknown {
            let _ = self
                .obstacles
                .push(crate::planner::Vehicle::wall(x, self.length));
        }
        self.steps = self.steps.saturating_add(1);
        let front = s + half;
        let target = if !permitted {
            entry
        } else if front <= exit {
            exit
        } else {
            route.path.length()
        };
        let obs = crate::planner::Observation {
            x: s,
            v_prev,
            vehicles: &self.obstacles,
            stop_line: (!permitted).then_some(entry),
            target_x: target,
            v_ref: self.planner.params().v_max(),
        };
        self.planner.step(&obs)
    }
}

#[cfg(test)]
mod tests {
    //! The vehicle side's bookkeeping, read from its private state: what it keeps of the
    //! reports, grants and sensor returns it hears (the second mutation pass).
    use super::*;
    use crate::intersection::LayoutSpec;
    use crate::mpc::CostWeights;
    use crate::planner::Planner;
    use crate::Params;

    /// `s` seconds after the epoch.
    fn at(s: f64) -> Instant {
        Instant::from_micros((s * 1e6).round() as u64)
    }

    type Car = CrossingPlanner<f64, 20, 2>;
    type Car8 = CrossingPlanner<f64, 20, 8>;

    fn car<const CAP: usize>(id: u16, route: u8) -> CrossingPlanner<f64, 20, CAP> {
        let p = Params::<f64>::table_i();
        let planner = Planner::<f64, 20>::new(p, CostWeights::default()).expect("planner");
        CrossingPlanner::new(planner, id, route, 4.5)
    }

    fn spec8() -> Layout<f64> {
        let p = Params::<f64>::table_i();
        Layout::new(&p, LayoutSpec::spec8(&p)).expect("layout")
    }

    /// A route other than 0 whose inlet (and outlet) is, or is not, route 0's.
    fn route_like_0(l: &Layout<f64>, same_inlet: bool, same_outlet: bool) -> usize {
        let mine = *l.route(0).expect("route 0");
        (1..crate::intersection::ROUTES)
            .find(|&q| {
                l.route(q).is_some_and(|r| {
                    (r.inlet == mine.inlet) == same_inlet
                        && (r.outlet == mine.outlet) == same_outlet
                })
            })
            .expect("such a route in the SPEC §8 layout")
    }

    fn report(id: u16, s: f64) -> CrossingReport<f64> {
        CrossingReport {
            id,
            route: 3,
            s,
            v: 5.0,
            length: 4.5,
            brake: None,
        }
    }

    /// What `c` keeps of the reports heard: (id, route, s, stamp).
    fn kept<const CAP: usize>(
        c: &CrossingPlanner<f64, 20, CAP>,
    ) -> Vec<(u16, u8, f64, Instant), CAP> {
        c.others
            .iter()
            .map(|o| (o.report.id, o.report.route, o.report.s, o.stamp))
            .collect()
    }

    #[test]
    fn the_notify_bound_is_at_least_one_period_and_a_bad_one_changes_nothing() {
        let mut c: Car = car(1, 0);
        let h = c.planner.params().h();
        assert_eq!(
            c.set_notify_latency(f64::NAN),
            Err(ConfigError::InvalidLatency)
        );
        assert_eq!(c.notify, h);
        c.set_notify_latency(0.3).expect("finite");
        assert_eq!(c.notify, 0.3);
        c.set_notify_latency(h / 2.0).expect("finite");
        assert_eq!(c.notify, h);
    }

    #[test]
    fn sensors_are_validated_before_they_are_taken() {
        let mut c: Car = car(1, 0);
        let mut bad = Sensing::radar();
        bad.position_error_m = -0.1;
        assert_eq!(c.set_sensing(Some(bad)), Err(ConfigError::InvalidSensing));
        assert!(c.sensing.is_none());
        c.set_sensing(Some(Sensing::radar())).expect("radar");
        assert!(c.sensing.is_some());
    }

    #[test]
    fn mapped_and_sensed_positions_replace_the_last_steps_and_refuse_bad_ones() {
        let mut c: Car = car(1, 0);
        let car_at = |s: f64| PathVehicle { s, length: 4.5 };
        c.hear_mapped(&[car_at(1.0), car_at(2.0)]).expect("two fit");
        assert_eq!(c.mapped.as_slice(), &[car_at(1.0), car_at(2.0)]);
        c.hear_mapped(&[car_at(3.0)]).expect("one");
        assert_eq!(c.mapped.as_slice(), &[car_at(3.0)]);
        assert_eq!(
            c.hear_mapped(&[car_at(f64::NAN)]),
            Err(ManagerError::BadValue)
        );
        assert!(c.mapped.is_empty(), "a refused list leaves none heard");
        let no_length = PathVehicle {
            s: 1.0,
            length: 0.0,
        };
        assert_eq!(c.hear_mapped(&[no_length]), Err(ManagerError::BadValue));
        let three = [car_at(1.0), car_at(2.0), car_at(3.0)];
        assert_eq!(c.hear_mapped(&three), Err(ManagerError::Full));
        assert!(c.mapped.is_empty());
        c.hear_sensed(&[car_at(4.0), car_at(5.0)]).expect("two fit");
        assert_eq!(c.sensed.as_slice(), &[car_at(4.0), car_at(5.0)]);
        c.hear_sensed(&[car_at(6.0)]).expect("one");
        assert_eq!(c.sensed.as_slice(), &[car_at(6.0)]);
        assert_eq!(
            c.hear_sensed(&[car_at(f64::INFINITY)]),
            Err(ManagerError::BadValue)
        );
        let long = PathVehicle {
            s: 1.0,
            length: f64::INFINITY,
        };
        assert_eq!(c.hear_sensed(&[long]), Err(ManagerError::BadValue));
    }

    #[test]
    fn a_bad_bus_resolution_changes_nothing() {
        let mut c: Car = car(1, 0);
        c.set_bus_resolution(0.1, 0.02).expect("valid");
        for (pos, speed) in [(f64::NAN, 0.0), (0.0, -0.1), (0.0, 1.0), (1.5, 0.0)] {
            assert_eq!(
                c.set_bus_resolution(pos, speed),
                Err(ConfigError::InvalidResolution)
            );
            assert_eq!((c.position_step, c.speed_step), (0.1, 0.02));
        }
    }

    /// A leader 20 m ahead at 10 m/s that says it brakes at 4.5 m/s².
    fn leader(brake: Option<f64>) -> CrossingReport<f64> {
        CrossingReport {
            id: 2,
            route: 0,
            s: 20.0,
            v: 10.0,
            length: 4.5,
            brake: brake.and_then(BrakeLimit::from_mps2),
        }
    }

    #[test]
    fn the_leader_aware_credit_is_the_leaders_least_travel_when_it_may_be_given() {
        let p = Params::<f64>::table_i();
        let mut c: Car = car(1, 0);
        assert_eq!(c.invariant(), Invariant::Paper);
        let l = leader(Some(4.5));
        assert_eq!(c.credit(&l, 20.0, 0.0), 0.0, "the paper's wall");
        c.set_invariant(Invariant::LeaderAware);
        assert_eq!(c.invariant(), Invariant::LeaderAware);
        // The harder of the two limits: the follower's 7.9.
        let full = safety::leader_credit(&p, 10.0, 4.5);
        assert!(full > 5.0);
        assert_eq!(c.credit(&l, 20.0, 0.0), full);
        assert_eq!(c.credit(&leader(None), 20.0, 0.0), 0.0, "no limit declared");
        // However old the report: the bound it gives stays valid.
        assert_eq!(c.credit(&l, 20.0, 0.25), full);
        assert_eq!(c.credit(&l, 20.0, 60.0), full, "never withdrawn by age");
        // Ahead only when more than both half-lengths and d0 ahead.
        let touching = 4.5 + p.d0();
        assert_eq!(c.credit(&l, touching, 0.0), 0.0, "beside, not ahead");
        assert_eq!(c.credit(&l, touching + 0.01, 0.0), full);
        // Judged by its ghost: a report 2 s old of a leader at 10 m/s whose stamped
        // centre the follower has passed still credits it (it has moved at least
        // ghost_advance since), and the wall stays where the stamp puts it.
        let ghost = safety::ghost_advance(&p, 10.0, 4.5, 2.0);
        assert!(ghost > touching + 0.3, "{ghost}");
        assert_eq!(
            c.credit(&l, -0.3, 2.0),
            full,
            "passed its stamp, behind its ghost"
        );
        assert_eq!(
            c.credit(&l, 4.5 - ghost - 0.01, 2.0),
            0.0,
            "its ghost's rear level with this vehicle's front"
        );
        assert_eq!(
            c.credit(&l, -0.5, 0.0),
            0.0,
            "a fresh report of a vehicle beside"
        );
        // The speed taken half a bus step lower, the length a position step longer.
        c.set_bus_resolution(0.2, 0.5).expect("valid");
        assert_eq!(
            c.credit(&l, 20.0, 0.0),
            safety::leader_credit(&p, 9.75, 4.5)
        );
        assert_eq!(c.credit(&l, touching + 0.1, 0.0), 0.0);
        assert!(c.credit(&l, touching + 0.21, 0.0) > 0.0);
    }

    #[test]
    fn a_credited_leader_moves_the_wall_and_the_follower_goes_faster() {
        let l = spec8();
        let route = *l.route(0).expect("route 0");
        // Both on route 0, on its inlet, the leader 9 m ahead at 10 m/s: within the
        // paper's stopping distance of the follower at 10 m/s, not the leader-aware one.
        let s = route.path.entry() - 40.0;
        let mut speeds = [0.0; 2];
        for (k, inv) in [Invariant::Paper, Invariant::LeaderAware]
            .into_iter()
            .enumerate()
        {
            let mut c: Car = car(1, 0);
            c.set_invariant(inv);
            c.hear_grant(1, at(100.0));
            let mut r = leader(Some(7.9));
            r.s = s + 9.0;
            c.hear_report(&r, at(0.0)).expect("room");
            // Past the start-up blindness (one period's notification bound).
            c.steps = 10;
            speeds[k] = c.step(&l, s, 10.0, at(0.0)).expect("step").v;
        }
        let p = Params::<f64>::table_i();
        assert!(
            speeds[0] < 10.0 + p.a_min() * p.h() + 1e-9,
            "the wall: the fallback's braking, {speeds:?}"
        );
        assert!(speeds[1] > 10.0, "credited: keeps going, {speeds:?}");
        // The obstacle: the leader's reported centre moved by its credit, one position
        // step longer; a vehicle level with this one is not credited at all.
        for (ahead, credited) in [(9.0, true), (4.9, false)] {
            let mut c: Car = car(1, 0);
            c.set_invariant(Invariant::LeaderAware);
            c.set_bus_resolution(0.2, 0.0).expect("valid");
            c.steps = 10;
            let mut r = leader(Some(7.9));
            r.s = s + ahead;
            c.hear_report(&r, at(0.0)).expect("room");
            c.step(&l, s, 10.0, at(0.0)).expect("step");
            let credit = safety::leader_credit(&p, 10.0, 7.9);
            let x = if credited { r.s + credit } else { r.s };
            assert!(
                c.obstacles
                    .iter()
                    .any(|o| (o.x - x).abs() < 1e-9 && (o.length - 4.7).abs() < 1e-9),
                "{ahead}: {:?}",
                c.obstacles
            );
        }
    }

    #[test]
    fn reports_keep_the_newest_per_vehicle_and_never_the_own() {
        let mut c: Car = car(1, 5);
        assert_eq!(c.route(), 5);
        c.hear_report(&report(1, 10.0), at(0.0)).expect("own");
        assert!(c.others.is_empty(), "its own report is not an obstacle");
        c.hear_report(&report(2, 10.0), at(1.0)).expect("first");
        c.hear_report(&report(2, 8.0), at(0.5)).expect("older");
        assert_eq!(
            kept(&c).as_slice(),
            &[(2, 3, 10.0, at(1.0))],
            "older ignored"
        );
        c.hear_report(&report(2, 11.0), at(1.0)).expect("duplicate");
        assert_eq!(
            kept(&c).as_slice(),
            &[(2, 3, 10.0, at(1.0))],
            "same stamp ignored"
        );
        c.hear_report(&report(2, 12.0), at(1.5)).expect("newer");
        assert_eq!(kept(&c).as_slice(), &[(2, 3, 12.0, at(1.5))]);
        assert_eq!(
            c.hear_report(&report(3, f64::NAN), at(2.0)),
            Err(ManagerError::BadValue)
        );
        c.hear_report(&report(3, 1.0), at(2.0)).expect("second");
        assert!(!c.overflowed);
        assert_eq!(
            c.hear_report(&report(4, 1.0), at(2.0)),
            Err(ManagerError::Full)
        );
        assert!(c.overflowed, "an unknown vehicle may be anywhere");
        c.hear_left(3);
        assert_eq!(kept(&c).as_slice(), &[(2, 3, 12.0, at(1.5))], "only 3 left");
        c.clear_reports();
        assert!(c.others.is_empty() && !c.overflowed);
    }

    #[test]
    fn only_its_own_grants_extend_the_lease_and_none_shortens_it() {
        let l = spec8();
        let entry = l.route(0).expect("route 0").path.entry();
        let before = entry - 10.0;
        let mut c: Car = car(1, 0);
        assert!(!c.permitted(&l, before, at(0.0)));
        c.hear_grant(2, at(5.0));
        assert!(!c.permitted(&l, before, at(0.0)), "another vehicle's grant");
        c.hear_grant(1, at(5.0));
        assert!(c.permitted(&l, before, at(5.0)), "up to the lease's end");
        assert!(!c.permitted(&l, before, at(5.01)), "not after it");
        c.hear_grant(1, at(3.0));
        assert!(
            c.permitted(&l, before, at(5.0)),
            "an older lease does not shorten it"
        );
        // Without a lease, a vehicle whose front is past the line is inside A_S (it
        // entered when it held one) and keeps going.
        assert!(c.permitted(&l, entry - 2.25 + 0.01, at(9.0)));
        assert!(!c.permitted(&l, entry - 2.25 - 0.01, at(9.0)));
        // Front exactly on the line: not yet inside (it needs a lease to go on).
        let on_line = [
            entry - 2.25,
            (entry - 2.25).next_up(),
            (entry - 2.25).next_down(),
        ]
        .into_iter()
        .find(|s| s + 2.25 == entry)
        .expect("a centre whose front is exactly on the line");
        assert!(!c.permitted(&l, on_line, at(9.0)));
    }

    /// Another route's vehicle about to reach this one's outlet: it is an obstacle on
    /// this path once its front is on the outlet, or may be because its report is older
    /// than the notify bound and it may have driven on at v_max since.
    #[test]
    fn a_vehicle_heading_for_the_same_outlet_counts_once_it_is_or_may_be_there() {
        let p = Params::<f64>::table_i();
        let l = spec8();
        let mine = l.route(0).expect("route 0");
        let q = route_like_0(&l, false, true);
        let other = l.route(q).expect("route onto the same outlet");
        let (exit, ox) = (mine.path.exit(), other.path.exit());
        let vmax = p.v_max();
        // Obstacles this step for a report of the other's centre at `x` stamped `stamp`.
        let seen = |x: f64, stamp: f64, now: f64| {
            let mut c: Car = car(1, 0);
            c.set_sensing(Some(Sensing::radar())).expect("radar");
            c.set_notify_latency(0.25).expect("bound");
            c.hear_report(
                &CrossingReport {
                    id: 2,
                    route: q as u8,
                    s: x,
                    v: 5.0,
                    length: 4.5,
                    brake: None,
                },
                at(stamp),
            )
            .expect("kept");
            c.step(&l, mine.path.entry() - 60.0, 5.0, at(now))
                .expect("step");
            let at = exit + (x - ox);
            c.obstacles.iter().any(|o| (o.x - at).abs() < 1e-9)
        };
        // Fresh reports: its front 1 m before the outlet, or 1 m onto it.
        assert!(!seen(ox - 2.25 - 1.0, 1.0, 1.05));
        assert!(seen(ox - 2.25 + 1.0, 1.0, 1.05));
        // Exactly as old as the bound: still fresh.
        assert!(!seen(ox - 2.25 - 1.0, 1.0, 1.25));
        // Older: it may have covered v_max · age, here half a second.
        let reach = vmax * 0.5;
        assert!(seen(ox - 2.25 - reach + 0.5, 1.0, 1.5));
        assert!(!seen(ox - 2.25 - reach - 0.5, 1.0, 1.5));
    }

    /// The obstacles (position, length) of one step of vehicle 1 on route 0 at `s`,
    /// after hearing vehicle 2 on `route` at `x` (stamped now).
    fn obstacles_with(l: &Layout<f64>, route: u8, x: f64, sensing: bool) -> Vec<(f64, f64), 8> {
        let mut c: Car8 = car(1, 0);
        if sensing {
            c.set_sensing(Some(Sensing::radar())).expect("radar");
        }
        let r = CrossingReport {
            id: 2,
            route,
            s: x,
            v: 5.0,
            length: 4.5,
            brake: None,
        };
        c.hear_report(&r, at(0.0)).expect("kept");
        let s = l.route(0).expect("route 0").path.entry() - 60.0;
        c.step(l, s, 5.0, at(0.0)).expect("step");
        c.obstacles.iter().map(|o| (o.x, o.length)).collect()
    }

    /// Which heard vehicles are on this vehicle's path: its own route anywhere; its inlet
    /// lane until the other's rear has left it and its centre its conflict zone with
    /// this route; nothing else before the outlet.
    #[test]
    fn vehicles_on_the_same_route_or_still_on_the_same_inlet_are_obstacles() {
        let l = spec8();
        let mine = *l.route(0).expect("route 0");
        let on = |route: usize, x: f64| {
            obstacles_with(&l, route as u8, x, true)
                .iter()
                .any(|o| (o.0 - x).abs() < 1e-9)
        };
        // The same route: before, inside and past A_S.
        for x in [
            mine.path.entry() - 10.0,
            mine.path.entry() + 5.0,
            mine.path.exit() + 1.0,
        ] {
            assert!(on(0, x), "same route at {x}");
        }
        let sibling = route_like_0(&l, true, false);
        let oe = l.route(sibling).expect("sibling").path.entry();
        assert!(on(sibling, oe + 2.0), "rear still on the common inlet");
        // Off it, but still where its footprint meets my route's sweep (PLATOON may
        // have let me trail it): kept until its centre is past that zone.
        let zone = l.zone_end[sibling][0];
        assert!(zone > 2.5, "{zone}");
        assert!(on(sibling, oe + 2.5), "rear off the inlet, in the zone");
        assert!(
            on(sibling, oe + zone + CONFLICT_SAMPLE_M),
            "at the zone's last sample"
        );
        assert!(
            !on(sibling, oe + zone + CONFLICT_SAMPLE_M + 0.01),
            "past it"
        );
        let stranger = route_like_0(&l, false, false);
        let se = l.route(stranger).expect("stranger").path.entry();
        assert!(!on(stranger, se - 5.0), "another inlet lane");
    }

    /// Sensor returns are taken their error closer; heard positions one bus step longer;
    /// and what is not known is blocked: right ahead while blind, beyond the forward
    /// range with sensors.
    #[test]
    fn sensed_mapped_and_unknown_space_become_obstacles_where_they_may_be() {
        let l = spec8();
        let entry = l.route(0).expect("route 0").path.entry();
        let s = entry - 60.0;
        let new = |sensing: bool| {
            let mut c: Car8 = car(1, 0);
            if sensing {
                c.set_sensing(Some(Sensing::radar())).expect("radar");
            }
            c.set_bus_resolution(0.1, 0.0).expect("step");
            c
        };
        let has = |c: &Car8, x: f64, len: f64| {
            c.obstacles
                .iter()
                .any(|o| (o.x - x).abs() < 1e-9 && (o.length - len).abs() < 1e-9)
        };
        let mut c = new(true);
        let truck = |s| PathVehicle { s, length: 16.5 };
        c.hear_sensed(&[
            PathVehicle {
                s: s + 30.0,
                length: 4.5,
            },
            truck(s + 70.0),
        ])
        .expect("two");
        c.hear_mapped(&[
            PathVehicle {
                s: s + 40.0,
                length: 4.5,
            },
            truck(s + 90.0),
        ])
        .expect("two");
        c.step(&l, s, 5.0, at(0.0)).expect("step");
        assert!(has(&c, s + 30.0 - 0.1, 4.5), "sensed: its error closer");
        assert!(has(&c, s + 70.0 - 0.1, 16.5), "sensed: as long as measured");
        assert!(has(&c, s + 40.0, 4.6), "mapped: one bus step longer");
        assert!(has(&c, s + 90.0, 16.6), "mapped: as long as declared");
        assert!(
            has(&c, s + 2.25 + 150.0 + 2.25, 4.5),
            "beyond the radar's range"
        );
        let mut c = new(false);
        c.set_notify_latency(0.5).expect("bound");
        c.step(&l, s, 5.0, at(0.0)).expect("step");
        assert!(
            has(&c, s + 1e-3, 4.5),
            "blind until reports can have arrived"
        );
    }

    /// The command follows the permission: without one the vehicle stops at the line;
    /// with one, or once inside or past A_S, it drives on toward its outlet.
    #[test]
    fn the_stop_line_and_the_target_follow_the_permission() {
        let l = spec8();
        let r = *l.route(0).expect("route 0");
        let (entry, exit) = (r.path.entry(), r.path.exit());
        // Where the front is after 8 s of closed loop from front position `front`.
        let drive = |front: f64, lease: bool| {
            let mut c: Car = car(1, 0);
            c.set_sensing(Some(Sensing::radar())).expect("radar");
            if lease {
                c.hear_grant(1, at(100.0));
            }
            let h = c.planner.params().h();
            let (mut s, mut v) = (front - 2.25, 5.0);
            for k in 0..(8.0 / h) as u32 {
                let now = f64::from(k) * h;
                let next = c.step(&l, s, v, at(now)).expect("step").v;
                s += 0.5 * (v + next) * h;
                v = next;
            }
            s + 2.25
        };
        let stopped = drive(entry - 20.0, false);
        assert!(
            stopped <= entry && stopped > entry - 1.0,
            "{stopped} vs {entry}"
        );
        assert!(drive(entry - 20.0, true) > exit, "permitted: through A_S");
        assert!(drive(entry + 1.0, false) > exit, "inside A_S it drives out");
        assert!(
            drive(exit + 1.0, false) > exit + 30.0,
            "on its outlet it drives on"
        );
    }

    /// One step equals the single-lane planner's on the observation the IC Protocol
    /// prescribes: the stop line and x^f = the line while not permitted; x^f = the end of
    /// A_S once permitted; the end of the route once the front is past A_S (Sec. VII-B).
    #[test]
    fn the_step_is_the_planners_on_the_prescribed_observation() {
        let l = spec8();
        let r = *l.route(0).expect("route 0");
        let (entry, exit, end) = (r.path.entry(), r.path.exit(), r.path.length());
        let p = Params::<f64>::table_i();
        // A target weight, so that x^f shows in the command.
        let w = CostWeights {
            target_position: 0.05,
            ..CostWeights::default()
        };
        for (front, lease, stop, target) in [
            (entry - 15.0, false, Some(entry), entry),
            (entry - 15.0, true, None, exit),
            (exit - 1.0, false, None, exit),
            (exit + 1.0, false, None, end),
        ] {
            let s = front - 2.25;
            let mut c =
                CrossingPlanner::<f64, 20, 2>::new(Planner::new(p, w).expect("planner"), 1, 0, 4.5);
            c.set_sensing(Some(Sensing::radar())).expect("radar");
            if lease {
                c.hear_grant(1, at(100.0));
            }
            let got = c.step(&l, s, 6.0, at(0.0)).expect("step").v;
            let unknown = [crate::planner::Vehicle::wall(s + 2.25 + 150.0 + 2.25, 4.5)];
            let obs = crate::planner::Observation {
                x: s,
                v_prev: 6.0,
                vehicles: &unknown,
                stop_line: stop,
                target_x: target,
                v_ref: p.v_max(),
            };
            let want = Planner::<f64, 20>::new(p, w)
                .expect("planner")
                .step(&obs)
                .expect("step")
                .v;
            assert_eq!(
                got.to_bits(),
                want.to_bits(),
                "front {front}: {got} vs {want}"
            );
        }
    }

    /// Ties at the boundaries: a front exactly at the outlet's start is not on it yet; a
    /// vehicle of the same inlet whose centre is exactly at the end of its conflict zone
    /// (plus the sample) is still in it — as the manager, which frees the zone only
    /// past that point, counts it.
    #[test]
    fn a_vehicle_exactly_at_a_boundary_is_on_the_far_side_of_it() {
        let l = spec8();
        let mine = *l.route(0).expect("route 0");
        // The position within one ulp of `target + shift` that is exactly `shift` from it.
        let exactly = |target: f64, shift: f64| {
            let x = target + shift;
            [x, x.next_up(), x.next_down()]
                .into_iter()
                .find(|x| x - shift == target)
                .expect("an exact position")
        };
        let sibling = route_like_0(&l, true, false);
        let oe = l.route(sibling).expect("sibling").path.entry();
        let zone = l.zone_end[sibling][0] + CONFLICT_SAMPLE_M;
        let at_zone_end = exactly(oe, zone);
        let seen = obstacles_with(&l, sibling as u8, at_zone_end, true);
        assert!(seen.iter().any(|o| (o.0 - at_zone_end).abs() < 1e-9));
        let past = at_zone_end.next_up();
        let seen = obstacles_with(&l, sibling as u8, past, true);
        assert!(!seen.iter().any(|o| (o.0 - past).abs() < 1e-9));
        let q = route_like_0(&l, false, true);
        let ox = l.route(q).expect("route onto the same outlet").path.exit();
        let front_at_outlet = exactly(ox, -2.25);
        assert_eq!(front_at_outlet + 2.25, ox);
        let seen = obstacles_with(&l, q as u8, front_at_outlet, true);
        let at = mine.path.exit() + (front_at_outlet - ox);
        assert!(!seen.iter().any(|o| (o.0 - at).abs() < 1e-9));
    }
}
