//! Intersection crossing (Sec. VI–VII, SPEC §7–8): vehicles follow their routes (inlet
//! track, a line or arc through A_S, outlet track), each running its own planner along
//! its path; the intersection manager is one more node on the bus. Vehicles and the
//! manager know of each other only through bus messages: vehicles broadcast
//! [`Message::Crossing`] reports, the manager broadcasts [`Message::Grant`] leases.
//!
//! Vehicle side, the IC Protocol: (i) no lane change inside A_C (vehicles keep their
//! inlet lane; routes start in the lane they need); (ii) without a live permission the
//! stop line (the entry of A_S) is x_R in (22); (iii) permissions come from the
//! manager. Once its front is past the stop line a vehicle is committed and goes on
//! (Lemma 14 (ii): a permission is kept until the vehicle is on its outlet). Target
//! switching of Sec. VII-B: x^f = end of inlet while not permitted, end of route when
//! permitted, end of outlet after A_S.
//!
//! [`CrossingSim`] runs every vehicle and the manager in one task on the in-process bus;
//! [`crate::crossing_fleet`] runs the same vehicle, manager and monitor parts (`Car`,
//! `manage`, `CrossingMonitor`) as tasks on CAN.

use crate::bus::{Bus, Faults, InProcessBus, Message, Received};
use crate::monitor::{rectangles_overlap, Limits, Truth};
use crate::sim::{LENGTH_M, WIDTH_M};
use planner_core::crossing::{Algorithm, CrossingPlanner, CrossingReport, Manager};
use planner_core::intersection::{Layout, LayoutSpec, ROUTES};
use planner_core::{CostWeights, Params, ParamsSpec, Planner, StepStatus};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

/// A vehicle's (id, x, y, θ, v) at one instant.
pub type PoseSample = (u16, f64, f64, f64, f64);

/// The manager's bus node.
pub const MANAGER_NODE: u16 = 0;
/// Lease of a permission (s): renewed every period while held; 0.1 s lets a few
/// messages go missing before a vehicle that has not yet entered A_S must stop.
pub const LEASE_S: f64 = 0.1;
/// How long a vehicle that has left A_C repeats its `Left` message (s): 50 periods, so
/// that even at 20 % loss every receiver has it (0.2^50) and drops its last position.
pub const LEFT_REPEAT_S: f64 = 0.5;
/// Vehicles the manager can track.
pub const MANAGER_CAP: usize = 64;
/// Horizon of the intersection planners.
pub const HORIZON: usize = 20;

/// Cost of the intersection planners: the default, plus a small pull toward the target
/// of Sec. VII-B (x^f), so that the target switching is part of J.
pub fn weights() -> CostWeights<f64> {
    CostWeights {
        target_position: 1e-3,
        ..CostWeights::default()
    }
}

/// Table I with vmax replaced by the intersection's speed limit vImax (SPEC §1).
pub fn params(v_limit: f64) -> Params<f64> {
    let spec = ParamsSpec {
        v_max: v_limit,
        ..ParamsSpec::table_i()
    };
    // vImax = vmax/2 keeps every Table I relation; a user layout is checked in `new`.
    Params::new(spec).unwrap_or_else(|_| Params::table_i())
}

/// One vehicle of an intersection run: its route, where it is, and its planner.
pub(crate) struct Car {
    pub(crate) id: u16,
    pub(crate) route: u8,
    pub(crate) s: f64,
    pub(crate) v: f64,
    v_before: f64,
    planner: Box<CrossingPlanner<f64, HORIZON, MANAGER_CAP>>,
    arrived_at: Option<f64>,
    left_as_at: Option<f64>,
}

/// What the monitor needs of a vehicle at one instant (ground truth).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct CarTruth {
    pub(crate) id: u16,
    pub(crate) route: u8,
    pub(crate) s: f64,
    pub(crate) v: f64,
    pub(crate) v_before: f64,
}

impl Car {
    /// Vehicle `p` with its own planner.
    pub(crate) fn new(params: &Params<f64>, p: &Placement, notify: f64) -> Self {
        let mut planner = CrossingPlanner::new(
            Planner::new(*params, weights())
                .unwrap_or_else(|_| unreachable!("the weights are valid")),
            p.id,
            p.route,
            LENGTH_M,
        );
        // A validated bus's bound is finite.
        let _ = planner.set_notify_latency(notify);
        Self {
            id: p.id,
            route: p.route,
            s: p.s,
            v: p.v,
            v_before: p.v,
            planner: Box::new(planner),
            arrived_at: None,
            left_as_at: None,
        }
    }

    /// Others' positions reach this vehicle rounded to `position` (m).
    pub(crate) fn set_bus_resolution(
        &mut self,
        position: f64,
    ) -> Result<(), planner_core::ConfigError> {
        self.planner.set_bus_resolution(position)
    }

    /// What it broadcasts about itself (V2V and V2I in one).
    pub(crate) fn report(&self) -> CrossingReport<f64> {
        CrossingReport {
            id: self.id,
            route: self.route,
            s: self.s,
            v: self.v,
            length: LENGTH_M,
        }
    }

    /// When it entered A_C (its own clock), if it has.
    pub(crate) fn arrived_at(&self) -> Option<f64> {
        self.arrived_at
    }

    /// Takes one message it heard.
    pub(crate) fn hear(&mut self, msg: &Message) {
        match *msg {
            Message::Grant { id, until } => self.planner.hear_grant(id, until),
            Message::Left { id, .. } => self.planner.hear_left(id),
            Message::Crossing(rep, stamp) => {
                // The view holds MANAGER_CAP vehicles, as many as the manager.
                let _ = self.planner.hear_report(&rep, stamp);
            }
            Message::State(_) => {}
        }
    }

    /// Plans at `t` from what it heard: the speed for the next period, and whether the
    /// certified fallback was applied for another reason than having no room.
    pub(crate) fn decide(
        &mut self,
        layout: &Layout<f64>,
        params: &Params<f64>,
        t: f64,
    ) -> (f64, bool) {
        let permitted = self.planner.permitted(layout, self.s, t);
        match self.planner.step(layout, self.s, self.v, t) {
            Ok(cmd) => match cmd.status {
                StepStatus::Fallback(why) if why != planner_core::FallbackReason::NoRoom => {
                    if std::env::var_os("HOST_SIM_DEBUG").is_some() {
                        eprintln!(
                            "t={t:.2} id={} route={} s={:.2} v={:.2} permitted={permitted} {why:?} gap={:.3}",
                            self.id, self.route, self.s, self.v, cmd.gap
                        );
                    }
                    (cmd.v, true)
                }
                _ => (cmd.v, false),
            },
            Err(_) => (
                planner_core::safety::max_braking_command(params, self.v),
                true,
            ),
        }
    }

    /// Drives at `v` for one period h along its path.
    pub(crate) fn advance(&mut self, v: f64, h: f64) {
        self.v_before = self.v;
        self.v = v;
        self.s += v * h;
    }

    /// Bookkeeping at `now`, after a move: arrival in A_C, leaving A_S; `Some(time from
    /// arrival)` once it has crossed (arrived, went through A_S, and left A_C on its
    /// outlet).
    pub(crate) fn crossed(&mut self, layout: &Layout<f64>, now: f64) -> Option<f64> {
        let route = layout.route(usize::from(self.route))?;
        let q = route.path.pose_at(self.s);
        let inside_ac = layout.in_comm_region(q.x, q.y);
        if inside_ac && self.arrived_at.is_none() {
            self.arrived_at = Some(now);
        }
        if self.s - 0.5 * LENGTH_M >= route.path.exit() && self.left_as_at.is_none() {
            self.left_as_at = Some(now);
        }
        match (self.arrived_at, self.left_as_at) {
            (Some(a), Some(_)) if !inside_ac => Some(now - a),
            _ => None,
        }
    }

    /// Ground truth for the monitor.
    pub(crate) fn truth(&self) -> CarTruth {
        CarTruth {
            id: self.id,
            route: self.route,
            s: self.s,
            v: self.v,
            v_before: self.v_before,
        }
    }
}

/// The manager's part of a period at `t`: takes the reports and departures it heard,
/// decides, and answers the vehicles that hold a permission now (each is sent a lease).
pub(crate) fn manage(
    manager: &mut Manager<f64, MANAGER_CAP>,
    heard: &[Received],
    t: f64,
) -> Vec<u16> {
    for r in heard {
        match r.msg {
            Message::Crossing(rep, _) => {
                let _ = manager.observe(&rep, t);
            }
            Message::Left { id, .. } => manager.forget(id),
            _ => {}
        }
    }
    manager.update();
    manager
        .entries()
        .iter()
        .filter(|e| e.permitted)
        .map(|e| e.id)
        .collect()
}

/// The independent checks of an intersection run, from ground truth and from what the
/// manager granted (never from a planner's view).
#[derive(Debug, Clone, Default)]
pub(crate) struct CrossingMonitor {
    pub(crate) collisions: u64,
    pub(crate) invariant_violations: u64,
    pub(crate) limit_violations: u64,
    pub(crate) unpermitted: u64,
    ever_permitted: Vec<u16>,
}

impl CrossingMonitor {
    /// The manager granted `ids` a permission.
    pub(crate) fn granted(&mut self, ids: &[u16]) {
        for &id in ids {
            if !self.ever_permitted.contains(&id) {
                self.ever_permitted.push(id);
            }
        }
    }

    /// Checks one instant: collisions, the invariant between vehicles sharing a path
    /// piece, speed and acceleration limits, and IC Protocol (ii) (nobody inside A_S who
    /// was never permitted).
    pub(crate) fn check(&mut self, layout: &Layout<f64>, lim: &Limits, cars: &[CarTruth]) {
        let path = |c: &CarTruth| {
            layout
                .route(usize::from(c.route))
                .map_or(layout.routes[0].path, |r| r.path)
        };
        let truths: Vec<Truth> = cars
            .iter()
            .map(|c| {
                let q = path(c).pose_at(c.s);
                Truth {
                    x: q.x,
                    y: q.y,
                    theta: q.theta,
                    length: LENGTH_M,
                    width: WIDTH_M,
                    lane: 0,
                    keeps_invariant: true,
                    v: c.v,
                    v_before: c.v_before,
                }
            })
            .collect();
        for (k, a) in truths.iter().enumerate() {
            for b in truths.iter().skip(k + 1) {
                if rectangles_overlap(a, b) {
                    self.collisions += 1;
                }
            }
        }
        // The invariant between vehicles sharing a path piece (same route; same inlet
        // while the leader is on it; same outlet once both are on it).
        for a in cars {
            for b in cars {
                if a.id == b.id {
                    continue;
                }
                let (Some(ra), Some(rb)) = (
                    layout.route(usize::from(a.route)),
                    layout.route(usize::from(b.route)),
                ) else {
                    continue;
                };
                let (fa, fb) = if a.route == b.route
                    || (ra.inlet == rb.inlet && b.s < rb.path.entry())
                {
                    (a.s, b.s)
                } else if ra.outlet == rb.outlet && a.s >= ra.path.exit() && b.s >= rb.path.exit() {
                    (a.s - ra.path.exit(), b.s - rb.path.exit())
                } else {
                    continue;
                };
                if fa < fb {
                    let gap = fb - fa - LENGTH_M;
                    if gap - lim.d0 <= lim.safe_distance(a.v) {
                        self.invariant_violations += 1;
                    }
                }
            }
        }
        for c in cars {
            let dv = c.v - c.v_before;
            if c.v < 0.0
                || c.v > lim.v_max + 1e-9
                || dv > lim.a_max * lim.h + 1e-9
                || dv < -lim.brake * lim.h - 1e-9
            {
                self.limit_violations += 1;
            }
        }
        for c in cars {
            let Some(r) = layout.route(usize::from(c.route)) else {
                continue;
            };
            let front = c.s + 0.5 * LENGTH_M;
            if front > r.path.entry()
                && c.s - 0.5 * LENGTH_M < r.path.exit()
                && !self.ever_permitted.contains(&c.id)
            {
                self.unpermitted += 1;
            }
        }
    }
}

/// A vehicle to place.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    /// Id (≥ 1; 0 is the manager).
    pub id: u16,
    /// Route index.
    pub route: u8,
    /// Centre distance along the route's path (m).
    pub s: f64,
    /// Speed (m/s).
    pub v: f64,
}

/// Results of an intersection run.
#[derive(Debug, Clone, Serialize)]
pub struct CrossingSummary {
    /// Algorithm.
    pub algorithm: &'static str,
    /// Simulated time (s).
    pub sim_seconds: f64,
    /// Vehicles that left A_C on their outlet.
    pub crossed: u64,
    /// Mean time from arrival (entering A_C) to leaving A_C (s).
    pub crossing_time_mean_s: f64,
    /// Longest such time (s).
    pub crossing_time_max_s: f64,
    /// Collisions (pairs × steps).
    pub collisions: u64,
    /// Invariant violations between vehicles sharing a path piece (pairs × steps).
    pub invariant_violations: u64,
    /// Speed or acceleration limit violations.
    pub limit_violations: u64,
    /// Steps × vehicles inside A_S without a permission having been granted.
    pub unpermitted_entries: u64,
    /// Planner steps that applied the certified fallback (not standstill).
    pub fallback_steps: u64,
    /// Vehicles still in the system at the end.
    pub in_system: usize,
}

/// The simulation.
pub struct CrossingSim {
    layout: Layout<f64>,
    params: Params<f64>,
    lim: Limits,
    manager: Manager<f64, MANAGER_CAP>,
    cars: Vec<Car>,
    bus: InProcessBus,
    inbox: Vec<Received>,
    t: f64,
    /// Closed system: respawn a vehicle when one leaves A_C.
    respawn: Option<Box<ChaCha8Rng>>,
    pending: Vec<(u16, u8)>,
    /// Vehicles that left, repeating `Left`: (id, when it left).
    departing: Vec<(u16, f64)>,
    /// Crossing times of the vehicles that crossed.
    times: Vec<f64>,
    fallback_steps: u64,
    monitor: CrossingMonitor,
    /// The bus's notification bound (s), for the planners of spawned vehicles.
    notify: f64,
}

impl CrossingSim {
    /// A simulation of `placements` on `layout` under `algorithm`; with `respawn_seed`,
    /// a closed system (SPEC §8 throughput): whenever a vehicle leaves A_C a new one with
    /// a random route is spawned at the start of its inlet track once the invariant holds
    /// for it there.
    pub fn new(
        layout: Layout<f64>,
        algorithm: Algorithm,
        placements: &[Placement],
        respawn_seed: Option<u64>,
    ) -> Self {
        Self::with_faults(layout, algorithm, placements, respawn_seed, Faults::NONE, 0)
    }

    /// As [`CrossingSim::new`], over a bus injecting `faults` (validated) drawn from
    /// `fault_seed`.
    pub fn with_faults(
        layout: Layout<f64>,
        algorithm: Algorithm,
        placements: &[Placement],
        respawn_seed: Option<u64>,
        faults: Faults,
        fault_seed: u64,
    ) -> Self {
        let params = params(layout.spec.v_limit);
        let mut nodes: Vec<u16> = placements.iter().map(|p| p.id).collect();
        nodes.push(MANAGER_NODE);
        let notify = faults.notify_bound(params.h());
        let cars = placements
            .iter()
            .map(|p| Car::new(&params, p, notify))
            .collect();
        let mut lim = Limits::table_i();
        lim.v_max = layout.spec.v_limit;
        Self {
            manager: Manager::new(layout.clone(), algorithm),
            layout,
            params,
            lim,
            cars,
            bus: InProcessBus::with_faults(&nodes, faults, fault_seed, lim.h),
            inbox: Vec::new(),
            t: 0.0,
            respawn: respawn_seed.map(|s| Box::new(crate::instances::rng(s ^ 0x1c))),
            pending: Vec::new(),
            departing: Vec::new(),
            times: Vec::new(),
            fallback_steps: 0,
            monitor: CrossingMonitor::default(),
            notify,
        }
    }

    /// Current time (s).
    pub fn time(&self) -> f64 {
        self.t
    }

    /// Poses of the vehicles now.
    pub fn poses(&self) -> Vec<PoseSample> {
        self.cars
            .iter()
            .map(|c| {
                let q = self.path(c).pose_at(c.s);
                (c.id, q.x, q.y, q.theta, c.v)
            })
            .collect()
    }

    fn path(&self, c: &Car) -> planner_core::intersection::Path<f64> {
        self.layout
            .route(usize::from(c.route))
            .map_or(self.layout.routes[0].path, |r| r.path)
    }

    /// One period h.
    pub fn step(&mut self) {
        let t = self.t;
        let h = self.lim.h;
        // 1. Vehicles report (V2V and V2I in one broadcast); those gone repeat `Left`.
        self.departing.retain(|&(_, at)| t < at + LEFT_REPEAT_S);
        for &(id, at) in &self.departing {
            let _ = self.bus.send(id, &Message::Left { id, at }, t);
        }
        for c in &self.cars {
            let _ = self.bus.send(c.id, &Message::Crossing(c.report(), t), t);
        }
        // 2. The manager hears them, decides, and grants leases.
        self.inbox.clear();
        let _ = self.bus.receive(MANAGER_NODE, t, &mut self.inbox);
        let granted = manage(&mut self.manager, &self.inbox, t);
        self.monitor.granted(&granted);
        for id in granted {
            // A lease must outlive its own delivery: LEASE_S beyond the bus's bound.
            let until = t + LEASE_S + (self.notify - h);
            let _ = self
                .bus
                .send(MANAGER_NODE, &Message::Grant { id, until }, t);
        }
        // 3. Every vehicle plans from what it heard.
        let mut commands = Vec::with_capacity(self.cars.len());
        for c in &mut self.cars {
            self.inbox.clear();
            let _ = self.bus.receive(c.id, t, &mut self.inbox);
            for r in &self.inbox {
                c.hear(&r.msg);
            }
            let (v, fell_back) = c.decide(&self.layout, &self.params, t);
            self.fallback_steps += u64::from(fell_back);
            commands.push(v);
        }
        // 4. Move along the paths; bookkeeping of arrivals and departures.
        for (c, v) in self.cars.iter_mut().zip(commands) {
            c.advance(v, h);
        }
        self.t = t + h;
        let mut leaving = Vec::new();
        for (i, c) in self.cars.iter_mut().enumerate() {
            if let Some(dt) = c.crossed(&self.layout, self.t) {
                self.times.push(dt);
                leaving.push(i);
            }
        }
        for &i in leaving.iter().rev() {
            let c = self.cars.remove(i);
            let _ = self.bus.send(
                c.id,
                &Message::Left {
                    id: c.id,
                    at: self.t,
                },
                self.t,
            );
            self.departing.push((c.id, self.t));
            if let Some(rng) = self.respawn.as_mut() {
                let route = rng.random_range(0..ROUTES as u8);
                self.pending.push((c.id, route));
            }
        }
        self.spawn_pending();
        let truths: Vec<CarTruth> = self.cars.iter().map(Car::truth).collect();
        self.monitor.check(&self.layout, &self.lim, &truths);
    }

    fn spawn_pending(&mut self) {
        let mut still = Vec::new();
        for (id, route) in std::mem::take(&mut self.pending) {
            let Some(r) = self.layout.route(usize::from(route)) else {
                continue;
            };
            let v = self.layout.spec.v_limit;
            let s0 = 0.5 * LENGTH_M;
            // Spawn only where the invariant holds toward the nearest vehicle ahead on
            // the same inlet (with the f64 start margin).
            let ok = self.cars.iter().all(|o| {
                let Some(or) = self.layout.route(usize::from(o.route)) else {
                    return true;
                };
                if or.inlet != r.inlet || o.s >= or.path.entry() + 0.5 * LENGTH_M {
                    return true;
                }
                let gap = o.s - s0 - LENGTH_M;
                gap - self.lim.d0 > self.lim.safe_distance(v) + crate::sim::START_MARGIN_M
            });
            if ok {
                let car = Car::new(
                    &self.params,
                    &Placement {
                        id,
                        route,
                        s: s0,
                        v,
                    },
                    self.notify,
                );
                // Back as a new vehicle: its old `Left` no longer applies.
                self.departing.retain(|&(d, _)| d != id);
                self.cars.push(car);
            } else {
                still.push((id, route));
            }
        }
        self.pending = still;
    }

    /// Every vehicle's (id, route, s, v, lease end) and the manager's entries, for
    /// diagnosing a run.
    pub fn describe(&self) -> String {
        let cars: Vec<String> = self
            .cars
            .iter()
            .map(|c| format!("id {} route {} s {:.2} v {:.2}", c.id, c.route, c.s, c.v))
            .collect();
        format!(
            "t {:.2}: cars [{}]; manager {:?}",
            self.t,
            cars.join("; "),
            self.manager.entries()
        )
    }

    /// Summary so far.
    pub fn summary(&self) -> CrossingSummary {
        summarize(
            self.manager.algorithm(),
            self.t,
            &self.times,
            self.fallback_steps,
            &self.monitor,
            self.cars.len(),
        )
    }
}

/// The summary of a run at `t`: crossing times of the vehicles that crossed, the
/// monitor's findings, vehicles still in the system.
pub(crate) fn summarize(
    algorithm: Algorithm,
    t: f64,
    times: &[f64],
    fallback_steps: u64,
    monitor: &CrossingMonitor,
    in_system: usize,
) -> CrossingSummary {
    let n = times.len().max(1) as f64;
    CrossingSummary {
        algorithm: algorithm.name(),
        sim_seconds: t,
        crossed: times.len() as u64,
        crossing_time_mean_s: times.iter().sum::<f64>() / n,
        crossing_time_max_s: times.iter().copied().fold(0.0, f64::max),
        collisions: monitor.collisions,
        invariant_violations: monitor.invariant_violations,
        limit_violations: monitor.limit_violations,
        unpermitted_entries: monitor.unpermitted,
        fallback_steps,
        in_system,
    }
}

/// The Fig. 8 start: one vehicle on each of the 8 inlets, random routes, at vImax,
/// staggered along their inlets.
pub fn fig8_placements(layout: &Layout<f64>, seed: u64) -> Vec<Placement> {
    let mut rng = crate::instances::rng(seed ^ 0xf18);
    let mut out = Vec::new();
    for heading in 0..4u8 {
        for lane in 0..2u8 {
            let movement = if rng.random_bool(0.5) {
                planner_core::intersection::Movement::Straight
            } else if lane == 0 {
                planner_core::intersection::Movement::Left
            } else {
                planner_core::intersection::Movement::Right
            };
            let route = layout.route_index(heading, lane, movement).unwrap_or(0) as u8;
            out.push(Placement {
                id: out.len() as u16 + 1,
                route,
                s: 0.5 * LENGTH_M + rng.random_range(0.0..30.0),
                v: layout.spec.v_limit,
            });
        }
    }
    out
}

/// The SPEC §8 layout.
pub fn spec8_layout() -> Layout<f64> {
    let p = Params::<f64>::table_i();
    // The SPEC §8 values satisfy every check (tested).
    Layout::new(&p, LayoutSpec::spec8(&p))
        .unwrap_or_else(|_| unreachable!("SPEC §8 layout is valid"))
}

/// Runs a closed system of 8 vehicles for `duration` s under `algorithm` (Fig. 9).
pub fn throughput_run(
    algorithm: Algorithm,
    seed: u64,
    duration: f64,
    faults: Faults,
) -> CrossingSummary {
    let layout = spec8_layout();
    let placements = fig8_placements(&layout, seed);
    let mut sim =
        CrossingSim::with_faults(layout, algorithm, &placements, Some(seed), faults, seed);
    let steps = (duration / 0.01).round() as u64;
    for _ in 0..steps {
        sim.step();
    }
    if std::env::var_os("HOST_SIM_DEBUG").is_some() {
        eprintln!("{}", sim.describe());
    }
    sim.summary()
}

/// One algorithm's row of the throughput experiment.
#[derive(Debug, Clone, Serialize)]
pub struct ThroughputRow {
    /// Algorithm.
    pub algorithm: &'static str,
    /// Mean over seeds of vehicles crossed.
    pub crossed_mean: f64,
    /// Standard deviation over seeds of vehicles crossed.
    pub crossed_std: f64,
    /// Mean time from arrival to leaving A_C (s), over all vehicles of all seeds.
    pub crossing_time_mean_s: f64,
    /// Longest such time (s).
    pub crossing_time_max_s: f64,
    /// Collisions over all seeds.
    pub collisions: u64,
    /// Invariant violations over all seeds.
    pub invariant_violations: u64,
    /// Limit violations over all seeds.
    pub limit_violations: u64,
    /// Entries into A_S without a permission.
    pub unpermitted_entries: u64,
    /// Certified-fallback steps.
    pub fallback_steps: u64,
}

/// The `experiment throughput` result.
#[derive(Debug, Clone, Serialize)]
pub struct ThroughputReport {
    /// Rows, one per algorithm.
    pub results: Vec<ThroughputRow>,
    /// Seeds.
    pub seeds: u64,
    /// Duration of each run (s).
    pub duration_s: f64,
    /// Faults the bus injected.
    pub faults: Faults,
    /// Wall-clock time (s).
    pub wall_seconds: f64,
}

/// Fig. 9: every algorithm on the same seeds.
pub fn throughput(
    seeds: u64,
    first_seed: u64,
    duration: f64,
    faults: Faults,
    threads: usize,
) -> ThroughputReport {
    let t0 = std::time::Instant::now();
    let jobs: Vec<(Algorithm, u64)> = Algorithm::ALL
        .iter()
        .flat_map(|&a| (0..seeds).map(move |k| (a, first_seed + k)))
        .collect();
    let runs = crate::par::map_indexed(jobs.len(), threads, |i| {
        let (a, s) = jobs[i];
        (a, throughput_run(a, s, duration, faults))
    });
    let results = Algorithm::ALL
        .iter()
        .map(|&a| {
            let mine: Vec<&CrossingSummary> = runs
                .iter()
                .filter(|(b, _)| *b == a)
                .map(|(_, s)| s)
                .collect();
            let n = mine.len().max(1) as f64;
            let mean = mine.iter().map(|s| s.crossed as f64).sum::<f64>() / n;
            let var = mine
                .iter()
                .map(|s| (s.crossed as f64 - mean).powi(2))
                .sum::<f64>()
                / (n - 1.0).max(1.0);
            let total: f64 = mine.iter().map(|s| s.crossed as f64).sum::<f64>().max(1.0);
            ThroughputRow {
                algorithm: a.name(),
                crossed_mean: mean,
                crossed_std: var.sqrt(),
                crossing_time_mean_s: mine
                    .iter()
                    .map(|s| s.crossing_time_mean_s * s.crossed as f64)
                    .sum::<f64>()
                    / total,
                crossing_time_max_s: mine
                    .iter()
                    .map(|s| s.crossing_time_max_s)
                    .fold(0.0, f64::max),
                collisions: mine.iter().map(|s| s.collisions).sum(),
                invariant_violations: mine.iter().map(|s| s.invariant_violations).sum(),
                limit_violations: mine.iter().map(|s| s.limit_violations).sum(),
                unpermitted_entries: mine.iter().map(|s| s.unpermitted_entries).sum(),
                fallback_steps: mine.iter().map(|s| s.fallback_steps).sum(),
            }
        })
        .collect();
    ThroughputReport {
        results,
        seeds,
        duration_s: duration,
        faults,
        wall_seconds: t0.elapsed().as_secs_f64(),
    }
}

/// The `[intersection]` table of a scenario file (SPEC §8 defaults).
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LayoutToml {
    /// Half-size a of A_S (m).
    #[serde(default = "d_half")]
    pub half_size: f64,
    /// A_C = A_S grown by this (m).
    #[serde(default = "d_comm")]
    pub comm_margin: f64,
    /// Inlet length before the stop line (m).
    #[serde(default = "d_inlet")]
    pub inlet_length: f64,
    /// Outlet length past A_S (m).
    #[serde(default = "d_outlet")]
    pub outlet_length: f64,
    /// Speed limit vImax (m/s).
    #[serde(default = "d_limit")]
    pub v_limit: f64,
}
fn d_half() -> f64 {
    12.0
}
fn d_comm() -> f64 {
    50.0
}
fn d_inlet() -> f64 {
    100.0
}
fn d_outlet() -> f64 {
    60.0
}
fn d_limit() -> f64 {
    13.9
}

/// A vehicle of an intersection scenario.
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CrossingVehicleToml {
    /// Id (≥ 1).
    pub id: u16,
    /// Inlet: the heading of travel, "east" | "north" | "west" | "south".
    pub heading: Heading,
    /// Inlet lane: 0 inner, 1 outer.
    pub lane: u8,
    /// "straight" | "left" (inner lane) | "right" (outer lane).
    pub movement: MovementToml,
    /// Centre distance from the start of the inlet track (m).
    pub s: f64,
    /// Speed (m/s).
    pub v: f64,
}

/// Heading of travel of an inlet.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Heading {
    /// From the west.
    East,
    /// From the south.
    North,
    /// From the east.
    West,
    /// From the north.
    South,
}

/// A manoeuvre.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MovementToml {
    /// Straight on.
    Straight,
    /// Left turn.
    Left,
    /// Right turn.
    Right,
}

/// The crossing algorithm, as written in a scenario file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AlgorithmToml {
    /// All-Way STOP.
    Stop,
    /// FIFO Crossing.
    Fifo,
    /// Concurrent Crossing as written.
    Concurrent,
    /// Starvation-free Concurrent Crossing.
    ConcurrentFair,
    /// Pipelined (ours).
    Pipelined,
}

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCrossing {
    name: String,
    duration_s: toml::Spanned<f64>,
    #[serde(default)]
    seed: u64,
    algorithm: AlgorithmToml,
    intersection: toml::Spanned<LayoutToml>,
    #[serde(rename = "vehicle")]
    vehicles: Vec<toml::Spanned<CrossingVehicleToml>>,
    #[serde(default)]
    faults: Option<toml::Spanned<Faults>>,
}

/// A validated intersection scenario.
#[derive(Debug, Clone)]
pub struct CrossingScenario {
    /// Name.
    pub name: String,
    /// Duration (s); every vehicle must have crossed by then.
    pub duration_s: f64,
    /// Seed (recorded).
    pub seed: u64,
    /// Algorithm.
    pub algorithm: Algorithm,
    /// Layout.
    pub layout: Layout<f64>,
    /// Vehicles.
    pub placements: Vec<Placement>,
    /// Faults the bus injects (`[faults]`; none by default).
    pub faults: Faults,
}

/// `true` if the TOML text is an intersection scenario (has an `[intersection]` table).
pub fn is_crossing_scenario(text: &str) -> bool {
    toml::from_str::<toml::Table>(text).is_ok_and(|t| t.contains_key("intersection"))
}

impl CrossingScenario {
    /// Parses and validates; `path` only names the file in errors.
    pub fn parse(
        text: &str,
        path: &std::path::Path,
    ) -> Result<Self, crate::scenario::ScenarioError> {
        let err = |span: Option<std::ops::Range<usize>>, problem: String| {
            crate::scenario::ScenarioError {
                file: path.to_path_buf(),
                line: span.map(|s| crate::scenario::line_of(text, s)),
                problem,
            }
        };
        let raw: RawCrossing =
            toml::from_str(text).map_err(|e| err(e.span(), e.message().to_string()))?;
        let duration_s = *raw.duration_s.get_ref();
        if !(duration_s > 0.0 && duration_s <= crate::scenario::MAX_DURATION_S) {
            return Err(err(
                Some(raw.duration_s.span()),
                format!("duration_s must be positive, got {duration_s}"),
            ));
        }
        let p = Params::<f64>::table_i();
        let span = raw.intersection.span();
        let lt = raw.intersection.into_inner();
        let spec = LayoutSpec {
            half_size: lt.half_size,
            comm_margin: lt.comm_margin,
            inlet_length: lt.inlet_length,
            outlet_length: lt.outlet_length,
            lane_width: crate::sim::LANE_WIDTH_M,
            v_limit: lt.v_limit,
            lanes: 2,
        };
        if !(lt.v_limit > 0.0 && lt.v_limit <= p.v_max()) {
            return Err(err(
                Some(span),
                format!("v_limit must be in (0, {}], got {}", p.v_max(), lt.v_limit),
            ));
        }
        let layout = Layout::new(&p, spec).map_err(|e| {
            let why = match e {
                planner_core::intersection::LayoutError::NotPositive => {
                    "every length must be positive and finite".to_string()
                }
                planner_core::intersection::LayoutError::LanesDoNotFit => {
                    "half_size must hold the two inlet lanes (2 × 3.6 m)".to_string()
                }
                planner_core::intersection::LayoutError::TurnTooTight { radius } => format!(
                    "the right turn's radius a − 1.5 Wl = {radius:.2} m is below ρmin = {} m",
                    p.rho_min()
                ),
                planner_core::intersection::LayoutError::NotSpacious { margin, needed } => format!(
                    "violates the Spaciousness Assumption (27): A_C is {margin:.2} m from A_S, \
                     needs at least dS(vImax) + vImax h = {needed:.2} m"
                ),
                planner_core::intersection::LayoutError::InletShorterThanCommRegion => {
                    "inlet_length must reach back to the edge of A_C (≥ comm_margin)".to_string()
                }
                planner_core::intersection::LayoutError::OutletShorterThanCommRegion {
                    length,
                    needed,
                } => format!(
                    "outlet_length {length} m ends inside A_C: vehicles leave the intersection \
                     once they are on their outlet outside A_C, so it must be at least \
                     comm_margin + L = {needed:.2} m"
                ),
            };
            err(Some(span.clone()), format!("intersection: {why}"))
        })?;
        let algorithm = match raw.algorithm {
            AlgorithmToml::Stop => Algorithm::AllWayStop,
            AlgorithmToml::Fifo => Algorithm::Fifo,
            AlgorithmToml::Concurrent => Algorithm::Concurrent,
            AlgorithmToml::ConcurrentFair => Algorithm::ConcurrentFair,
            AlgorithmToml::Pipelined => Algorithm::Pipelined,
        };
        if raw.vehicles.is_empty() || raw.vehicles.len() > MANAGER_CAP {
            return Err(err(
                None,
                format!("1 to {MANAGER_CAP} vehicles, got {}", raw.vehicles.len()),
            ));
        }
        let lim = {
            let mut l = Limits::table_i();
            l.v_max = lt.v_limit;
            l
        };
        let mut placements: Vec<(Placement, std::ops::Range<usize>)> = Vec::new();
        for sv in raw.vehicles {
            let span = sv.span();
            let v = sv.into_inner();
            let bad = |m: String| err(Some(span.clone()), format!("vehicle {}: {m}", v.id));
            if v.id == MANAGER_NODE {
                return Err(bad("id 0 is the intersection's".into()));
            }
            if placements.iter().any(|(o, _)| o.id == v.id) {
                return Err(bad("duplicate id".into()));
            }
            let movement = match (v.lane, v.movement) {
                (0 | 1, MovementToml::Straight) => planner_core::intersection::Movement::Straight,
                (0, MovementToml::Left) => planner_core::intersection::Movement::Left,
                (1, MovementToml::Right) => planner_core::intersection::Movement::Right,
                (l, m) if l > 1 => {
                    return Err(bad(format!(
                        "lane must be 0 (inner) or 1 (outer), got {l} ({m:?})"
                    )))
                }
                (l, m) => {
                    return Err(bad(format!(
                    "{m:?} is not a route from lane {l} (left: inner lane 0, right: outer lane 1)"
                )))
                }
            };
            let heading = match v.heading {
                Heading::East => 0,
                Heading::North => 1,
                Heading::West => 2,
                Heading::South => 3,
            };
            let route = layout.route_index(heading, v.lane, movement).unwrap_or(0) as u8;
            let entry = lt.inlet_length;
            if !(v.s >= 0.5 * LENGTH_M && v.s + 0.5 * LENGTH_M + lim.d0 < entry) {
                return Err(bad(format!(
                    "s must put the vehicle on its inlet before the stop line, got {}",
                    v.s
                )));
            }
            if !(v.v >= 0.0 && v.v <= lt.v_limit) {
                return Err(bad(format!(
                    "v must be in [0, {}], got {}",
                    lt.v_limit, v.v
                )));
            }
            let room = entry - v.s - 0.5 * LENGTH_M - lim.d0;
            if !(room > lim.safe_distance(v.v) + crate::sim::START_MARGIN_M) {
                return Err(bad(format!("cannot stop before the stop line: {room:.2} m of room, needs more than dS(v) = {:.2} m", lim.safe_distance(v.v))));
            }
            placements.push((
                Placement {
                    id: v.id,
                    route,
                    s: v.s,
                    v: v.v,
                },
                span,
            ));
        }
        // Same inlet: no overlap, and the invariant for every follower.
        for (a, span) in &placements {
            for (b, _) in &placements {
                let (Some(ra), Some(rb)) = (
                    layout.route(usize::from(a.route)),
                    layout.route(usize::from(b.route)),
                ) else {
                    continue;
                };
                if a.id != b.id && ra.inlet == rb.inlet && a.s <= b.s {
                    let gap = b.s - a.s - LENGTH_M;
                    if !(gap - lim.d0 > lim.safe_distance(a.v) + crate::sim::START_MARGIN_M) {
                        return Err(err(Some(span.clone()), format!(
                            "vehicle {} violates the safety invariant behind vehicle {} on its inlet (bumper gap {gap:.2} m)",
                            a.id, b.id
                        )));
                    }
                }
            }
        }
        let faults = match &raw.faults {
            None => Faults::NONE,
            Some(f) => {
                f.get_ref()
                    .validate()
                    .map_err(|e| crate::scenario::ScenarioError {
                        file: path.to_path_buf(),
                        line: Some(crate::scenario::line_of(text, f.span())),
                        problem: e,
                    })?;
                *f.get_ref()
            }
        };
        Ok(Self {
            name: raw.name,
            duration_s,
            seed: raw.seed,
            algorithm,
            layout,
            placements: placements.into_iter().map(|(p, _)| p).collect(),
            faults,
        })
    }

    /// Runs it; `sample` sees every vehicle's (t, id, x, y, θ, v) each step.
    pub fn run(&self, sample: &mut dyn FnMut(f64, &[PoseSample])) -> CrossingSummary {
        let mut sim = CrossingSim::with_faults(
            self.layout.clone(),
            self.algorithm,
            &self.placements,
            None,
            self.faults,
            self.seed,
        );
        let steps = (self.duration_s / 0.01).round() as u64;
        for _ in 0..steps {
            sample(sim.time(), &sim.poses());
            sim.step();
            if sim.cars.is_empty() {
                break;
            }
        }
        if std::env::var_os("HOST_SIM_DEBUG").is_some() {
            eprintln!("{}", sim.describe());
        }
        sim.summary()
    }
}
