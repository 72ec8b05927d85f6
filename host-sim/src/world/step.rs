//! The world's period: see the module docs of [`super`] for the order of things.

use super::at::At;
use super::junction::ManagerNode;
use super::junction::{manager_node, LEFT_REPEAT_S};
use super::network::{End, Network};
use super::sensor::{roadside, sense, Seen, Sensed};
use super::spawn::{entry_speed, start_at, trip_choices, Entry};
use super::vehicle::{Brain, Driver, PlannerSetup, StepCtx, Trip, Vehicle, VehicleTruth};
use super::DriverKind;
use super::{Arrivals, TraceRow, VehicleSpec, World, LENGTH_M, WIDTH_M};
use crate::bus::{Bus, BusError, Message, Received};
use crate::monitor::junction::{JunctionWatch, OnRoute};
use crate::monitor::{road, Findings, Limits, Truth};
use planner_core::intersection::Movement;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A vehicle of `spec` at t = 0, with planners set up as `setup`.
pub(crate) fn build_vehicle<const N: usize>(
    spec: &VehicleSpec,
    setup: PlannerSetup,
    seed: u64,
    net: &Network,
) -> Vehicle<N> {
    let driver = match spec.driver {
        DriverKind::Planner => Driver::Planner(Box::new(Brain::new(spec.id, setup))),
        DriverKind::Script => Driver::Script(spec.script.clone()),
        DriverKind::Random => Driver::Random {
            rng: Box::new(ChaCha8Rng::seed_from_u64(
                seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ u64::from(spec.id),
            )),
            accel: 0.0,
            until: 0.0,
        },
    };
    let mut v = Vehicle::new(spec.id, spec.at, spec.v, driver, spec.trip.clone(), 0.0);
    v.cooperative = spec.cooperative;
    v.note_free_flow(net);
    if let At::Lane { x, lane, .. } = spec.at {
        if spec.trip.target_lane == lane {
            v.log.in_target_at = Some(0.0);
        }
        if spec.trip.goal_x.is_some_and(|g| x >= g) {
            v.log.reached_at = Some(0.0);
        }
    }
    v
}

/// Junction `j`'s node, for a fleet's CAN addresses.
pub fn node_of(j: usize) -> u16 {
    manager_node(j)
}

/// Gives a vehicle's brain a new setup (its planners are built with it from now on).
pub(crate) fn set_setup<const N: usize>(v: &mut Vehicle<N>, setup: PlannerSetup) {
    if let Driver::Planner(b) = &mut v.driver {
        b.set_setup(setup);
    }
}

/// The world's monitor: safety findings from ground truth, per junction what its manager
/// granted.
#[derive(Debug, Clone)]
pub struct WorldMonitor {
    /// Findings so far.
    pub findings: Findings,
    watches: Vec<JunctionWatch>,
}

impl WorldMonitor {
    /// A fresh monitor for `net`.
    pub fn new(net: &Network) -> Self {
        Self {
            findings: Findings::new(),
            watches: vec![JunctionWatch::default(); net.junctions.len()],
        }
    }

    /// Junction `j`'s manager granted `ids`.
    pub fn granted(&mut self, j: usize, ids: &[u16]) {
        if let Some(w) = self.watches.get_mut(j) {
            w.granted(ids);
        }
    }

    /// Checks one instant: collisions of every pair in the world; per segment, its lanes
    /// (with the junction vehicles whose inlet or outlet lies on it); per junction, its
    /// shared paths and permissions; every vehicle's limits; and that no vehicle on a
    /// segment has passed a junction's stop line (only crossing vehicles may be in A_S).
    pub fn check(&mut self, lim: &Limits, net: &Network, vehicles: &[VehicleTruth]) {
        let world: Vec<Truth> = vehicles.iter().map(|v| world_truth(v, net)).collect();
        self.findings.collisions += road::collisions(&world);
        for (k, seg) in net.segments.iter().enumerate() {
            let on: Vec<Truth> = vehicles
                .iter()
                .filter_map(|v| segment_truth(v, net, k))
                .collect();
            if on.is_empty() {
                continue;
            }
            let end = match seg.end {
                End::DeadEnd(x) => Some(x),
                _ => None,
            };
            road::lanes(&mut self.findings, lim, &on, end, seg.lanes);
            if let End::Junction(_, x) = seg.end {
                let past = on.iter().filter(|c| !c.mapped && c.x + 0.5 * c.length > x);
                self.findings.unpermitted_entries += past.count() as u64;
            }
        }
        for (j, jn) in net.junctions.iter().enumerate() {
            let cars: Vec<OnRoute> = vehicles
                .iter()
                .filter_map(|v| match v.at {
                    At::Crossing { junction, route, s } if junction == j => Some(OnRoute {
                        id: v.id,
                        route,
                        s,
                        v: v.v,
                        length: LENGTH_M,
                        leader_aware: v.leader_aware,
                        brake: lim.brake,
                    }),
                    _ => None,
                })
                .collect();
            if let Some(w) = self.watches.get(j) {
                w.check(&mut self.findings, &jn.layout, lim, &cars);
            }
        }
        for v in vehicles {
            let mut l = *lim;
            l.v_max = speed_limit(v, net, lim.v_max);
            let theta = match v.at {
                At::Lane { theta, .. } => theta,
                At::Crossing { .. } => 0.0,
            };
            road::limits(
                &mut self.findings,
                &l,
                &Truth {
                    theta,
                    ..world_truth(v, net)
                },
            );
        }
    }
}

/// The speed limit where `v` is.
pub(crate) fn speed_limit(v: &VehicleTruth, net: &Network, default: f64) -> f64 {
    match v.at {
        At::Lane { seg, .. } => net.segments.get(seg).map_or(default, |s| s.v_max),
        At::Crossing { junction, .. } => net
            .junctions
            .get(junction)
            .map_or(default, |j| j.layout.spec.v_limit),
    }
}

/// A vehicle's rectangle in the world.
pub fn world_truth(v: &VehicleTruth, net: &Network) -> Truth {
    let (p, lane) = match v.at {
        At::Lane {
            seg,
            x,
            y,
            theta,
            lane,
            ..
        } => (
            net.segments
                .get(seg)
                .map_or(planner_core::Pose { x, y, theta }, |s| {
                    s.to_world(x, y, theta)
                }),
            lane,
        ),
        At::Crossing { junction, route, s } => (
            net.junctions
                .get(junction)
                .map_or(Default::default(), |j| j.pose(route, s)),
            0,
        ),
    };
    Truth {
        x: p.x,
        y: p.y,
        theta: p.theta,
        length: LENGTH_M,
        width: WIDTH_M,
        lane,
        keeps_invariant: v.planner,
        leader_aware: v.leader_aware,
        brake: crate::monitor::Limits::table_i().brake,
        v: v.v,
        v_before: v.v_before,
        mapped: false,
    }
}

/// A vehicle's rectangle in segment `k`'s frame, if it is on it (a junction vehicle on
/// an inlet or outlet track lying on it is `mapped`).
pub fn segment_truth(v: &VehicleTruth, net: &Network, k: usize) -> Option<Truth> {
    let (x, y, theta, lane, mapped) = match v.at {
        At::Lane {
            seg,
            x,
            y,
            theta,
            lane,
            ..
        } if seg == k => (x, y, theta, lane, false),
        At::Crossing { junction, route, s } => {
            let (sg, x, lane) = net.on_segment(junction, route, s)?;
            if sg != k {
                return None;
            }
            (
                x,
                (f64::from(lane) + 0.5) * super::LANE_WIDTH_M,
                0.0,
                lane,
                true,
            )
        }
        At::Lane { .. } => return None,
    };
    Some(Truth {
        x,
        y,
        theta,
        length: LENGTH_M,
        width: WIDTH_M,
        lane,
        keeps_invariant: v.planner,
        leader_aware: v.leader_aware,
        brake: crate::monitor::Limits::table_i().brake,
        v: v.v,
        v_before: v.v_before,
        mapped,
    })
}

impl<const N: usize, B: Bus> World<N, B> {
    /// Simulates one period h; `trace` sees a row per vehicle.
    pub fn step(&mut self, trace: &mut dyn FnMut(&TraceRow)) -> Result<(), BusError> {
        let t = self.t;
        let h = self.lim.h;
        self.broadcast(t)?;
        self.manage(t)?;
        let sensed = self.sense_all();
        let mut commands = Vec::with_capacity(self.vehicles.len());
        let mut inbox: Vec<Received> = Vec::new();
        for (i, v) in self.vehicles.iter_mut().enumerate() {
            inbox.clear();
            self.bus.receive(v.id, t, &mut inbox)?;
            let empty = Sensed::default();
            let ctx = StepCtx {
                t,
                now: self.clock.at_step(self.steps_done),
                clock: self.clock,
                steps_done: self.steps_done,
                net: &self.net,
                lim: self.lim,
                silent: self.spec.faults.silent,
                liar: self.spec.faults.liar,
                returns: sensed.get(i).unwrap_or(&empty),
            };
            let t0 = self.costs.is_some().then(std::time::Instant::now);
            let (cmd, row) = v.decide(&ctx, &inbox, &mut self.counters);
            if let (Some(c), Some(t0), true) = (&mut self.costs, t0, v.is_planner()) {
                c.add(t0.elapsed().as_nanos() as u64);
            }
            commands.push(cmd);
            trace(&row);
        }
        for (v, (speed, w)) in self.vehicles.iter_mut().zip(commands) {
            v.advance(speed, w, h);
        }
        self.steps_done += 1;
        self.t = self.steps_done as f64 * h;
        for v in self.vehicles.iter_mut() {
            v.check_goal(self.t);
        }
        self.hand_over()?;
        self.arrive()?;
        let truths: Vec<VehicleTruth> = self.vehicles.iter().map(|v| v.truth(&self.net)).collect();
        self.monitor.check(&self.lim, &self.net, &truths);
        self.watch_liveness();
        Ok(())
    }

    /// Phase 1: the vehicles that left a junction or the network repeat it; every vehicle
    /// broadcasts.
    fn broadcast(&mut self, t: f64) -> Result<(), BusError> {
        let bus = &mut self.bus;
        let live = &self.vehicles;
        self.departing.retain(|&(id, _, at)| {
            let keep = t < at + LEFT_REPEAT_S;
            // Its last word said, a vehicle gone from the world leaves the bus too.
            if !keep && !live.iter().any(|v| v.id == id) {
                bus.detach(id);
            }
            keep
        });
        for &(id, from, at) in &self.departing {
            let at = self.clock.at_secs(at);
            self.bus.send(id, &Message::departure(id, at, from), t)?;
        }
        let now = self.clock.at_step(self.steps_done);
        for v in &self.vehicles {
            let (x, y) = v.position(&self.net);
            self.bus.locate(v.id, x, y);
        }
        for v in &self.vehicles {
            let msg = self.spec.faults.told(v.id, v.message(now), t);
            self.bus.send(v.id, &msg, t)?;
        }
        self.messages_sent += self.vehicles.len() as u64;
        Ok(())
    }

    /// Phase 2: every manager hears its junction's reports, decides, and grants leases.
    fn manage(&mut self, t: f64) -> Result<(), BusError> {
        let mut inbox = Vec::new();
        let now = self.clock.at_step(self.steps_done);
        let seen: Vec<Seen> = if self.managers.iter().any(ManagerNode::has_roadside) {
            self.vehicles.iter().map(Vehicle::seen).collect()
        } else {
            Vec::new()
        };
        let error = self.spec.sensing.map_or(0.0, |s| s.position_error_m);
        for m in &mut self.managers {
            inbox.clear();
            self.bus.receive(m.node(), t, &mut inbox)?;
            if !m.is_up(&self.spec.faults, t) {
                continue;
            }
            let readings = if m.has_roadside() {
                roadside(&self.net, m.junction, &seen, error, &mut self.roadside_rng)
            } else {
                Vec::new()
            };
            let granted = m.manage(&inbox, &readings, now);
            self.monitor.granted(m.junction, &granted);
            for id in granted {
                let g = m.grant(id, now);
                self.bus.send(m.node(), &g, t)?;
            }
        }
        Ok(())
    }

    /// Phase 3: every vehicle's sensor returns (planners only with sensors; scripted and
    /// random drivers always see what is in their lane ahead).
    fn sense_all(&mut self) -> Vec<Sensed> {
        let any_script = self.vehicles.iter().any(|v| !v.is_planner());
        if self.spec.sensing.is_none() && !any_script {
            return Vec::new();
        }
        let all: Vec<Seen> = self.vehicles.iter().map(Vehicle::seen).collect();
        self.vehicles
            .iter()
            .zip(&all)
            .map(|(v, me)| {
                let s = if v.is_planner() {
                    self.spec.sensing.as_ref()
                } else {
                    None
                };
                if v.is_planner() && s.is_none() {
                    return Sensed::default();
                }
                sense(&self.net, me, &all, s, &mut self.rng)
            })
            .collect()
    }

    /// Phase 6: hand-overs between segments and junctions, and departures. A vehicle that
    /// leaves a junction says so at once (and repeats it for [`LEFT_REPEAT_S`]); one that
    /// leaves the world is kept for the summary and, in a closed system, comes back later.
    fn hand_over(&mut self) -> Result<(), BusError> {
        let now = self.t;
        let mut leaving = Vec::new();
        for (i, v) in self.vehicles.iter_mut().enumerate() {
            match step_place(v, &self.net, now) {
                Moved::Stays => {}
                Moved::LeftJunction(j) if v.log.left_at.is_none() => {
                    let id = v.id;
                    let at = self.clock.at_step(self.steps_done);
                    self.bus
                        .send(id, &Message::departure(id, at, Some(j)), now)?;
                    self.departing.push((id, Some(j), now));
                }
                Moved::LeftJunction(j) => leaving.push((i, Some(j))),
                Moved::LeftWorld => leaving.push((i, None)),
            }
        }
        // Last first, so that the indices stay valid.
        for &(i, junction) in leaving.iter().rev() {
            let v = self.vehicles.remove(i);
            // It says it left (a junction, or the network at an exit) and repeats it for
            // LEFT_REPEAT_S; then it leaves the bus.
            let id = v.id;
            let at = self.clock.at_step(self.steps_done);
            self.bus
                .send(id, &Message::departure(id, at, junction), now)?;
            self.departing.push((id, junction, now));
            if let Some(j) = junction {
                if self.spec.arrivals == Arrivals::Closed {
                    let routes = self
                        .net
                        .junctions
                        .get(j)
                        .map_or(1, |jn| jn.layout.routes.len());
                    let route = self.rng.random_range(0..routes as u8);
                    self.pending.push((id, route));
                }
            }
            self.gone.push(v);
        }
        Ok(())
    }

    /// Vehicles entering: those of a closed system coming back, and open arrivals, each
    /// once it keeps the invariant toward the vehicle ahead where it enters.
    fn arrive(&mut self) -> Result<(), BusError> {
        let now = self.t;
        let mut still = Vec::new();
        for (id, route) in std::mem::take(&mut self.pending) {
            let entry = self.stub_of(0, route);
            let v_max = self.entry_limit(&entry);
            // The paper's closed system spawns at vImax where the invariant allows it.
            match self.room(&entry) {
                r if entry_speed(&self.lim, r, v_max).is_some_and(|s| s >= v_max) => {
                    self.departing.retain(|&(d, _, _)| d != id);
                    self.enter(id, &entry, Some(route), Vec::new(), v_max, now)?;
                }
                _ => still.push((id, route)),
            }
        }
        self.pending = still;
        let mut streams = std::mem::take(&mut self.streams);
        for s in &mut streams {
            let net = &self.net;
            s.arrive(now, &mut self.rng, &mut |e, rng| draw_trip(net, e, rng));
            let Some(head) = s.queue.front() else {
                continue;
            };
            let v_max = self.entry_limit(&s.entry);
            if let Some(v) = entry_speed(&self.lim, self.room(&s.entry), v_max) {
                let Some(id) = self.free_id() else {
                    continue;
                };
                let (route, movements) = (head.route, head.movements.clone());
                let since = head.since;
                s.queue.pop_front();
                self.enter(id, &s.entry, route, movements, v, since)?;
            }
        }
        self.streams = streams;
        Ok(())
    }

    /// An id for a vehicle entering now ([`super::spawn::Ids`]).
    fn free_id(&mut self) -> Option<u16> {
        let used: std::collections::HashSet<u16> = self
            .vehicles
            .iter()
            .map(|v| v.id)
            .chain(self.departing.iter().map(|d| d.0))
            .chain(self.pending.iter().map(|p| p.0))
            .collect();
        self.ids.take(|id| used.contains(&id))
    }

    /// The stub entry of junction `j`'s route `route`.
    fn stub_of(&self, j: usize, route: u8) -> Entry {
        let inlet = self
            .net
            .junctions
            .get(j)
            .and_then(|jn| jn.layout.route(usize::from(route)))
            .map(|r| r.inlet)
            .unwrap_or(planner_core::intersection::Track {
                heading: 0,
                lane: 0,
            });
        Entry::Stub {
            junction: j,
            heading: inlet.heading,
            lane: inlet.lane,
        }
    }

    /// The speed limit at an entry.
    fn entry_limit(&self, e: &Entry) -> f64 {
        match *e {
            Entry::Stub { junction, .. } => self
                .net
                .junctions
                .get(junction)
                .map_or(self.lim.v_max, |j| j.layout.spec.v_limit),
            Entry::Segment { seg, .. } => self
                .net
                .segments
                .get(seg)
                .map_or(self.lim.v_max, |s| s.v_max),
        }
    }

    /// The room (bumper gap − d0, m) ahead of a vehicle entering at `e`, to the nearest
    /// vehicle on the same inlet track or lane (∞ if none).
    fn room(&self, e: &Entry) -> f64 {
        let start = 0.5 * LENGTH_M;
        let mut room = f64::INFINITY;
        for v in &self.vehicles {
            let ahead = match (*e, v.at) {
                (
                    Entry::Stub {
                        junction,
                        heading,
                        lane,
                    },
                    At::Crossing {
                        junction: j,
                        route,
                        s,
                    },
                ) if j == junction => {
                    let same = self
                        .net
                        .junctions
                        .get(j)
                        .and_then(|jn| jn.layout.route(usize::from(route)))
                        .filter(|r| r.inlet.heading == heading && r.inlet.lane == lane);
                    match same {
                        Some(r) if s < r.path.entry() + 0.5 * LENGTH_M => Some(s),
                        _ => None,
                    }
                }
                (Entry::Segment { seg, lane }, _) => {
                    segment_truth(&v.truth(&self.net), &self.net, seg)
                        .filter(|c| {
                            let (lo, hi) = crate::monitor::lateral_span(c);
                            let (a, b) = (
                                f64::from(lane) * super::LANE_WIDTH_M,
                                f64::from(lane + 1) * super::LANE_WIDTH_M,
                            );
                            hi > a && lo < b
                        })
                        .map(|c| c.x)
                }
                _ => None,
            };
            if let Some(x) = ahead {
                room = room.min(x - start - LENGTH_M - self.lim.d0);
            }
        }
        room
    }

    /// A vehicle `id` enters at `e` at speed `v` (it has waited since `since`).
    fn enter(
        &mut self,
        id: u16,
        e: &Entry,
        route: Option<u8>,
        movements: Vec<Movement>,
        v: f64,
        since: f64,
    ) -> Result<(), BusError> {
        let at = start_at(e, route, 0.5 * LENGTH_M);
        let movements = match (route, *e) {
            (Some(r), Entry::Stub { junction, .. }) => self
                .net
                .junctions
                .get(junction)
                .and_then(|j| j.layout.route(usize::from(r)))
                .map_or(movements, |r| vec![r.movement]),
            _ => movements,
        };
        let trip = Trip {
            target_lane: 0,
            goal_x: None,
            v_ref: None,
            movements,
        };
        let driver = Driver::Planner(Box::new(Brain::new(id, self.setup)));
        let mut car = Vehicle::new(id, at, v, driver, trip, since);
        car.note_free_flow(&self.net);
        car.retarget(&self.net);
        self.bus.attach(id)?;
        self.vehicles.push(car);
        Ok(())
    }

    /// Phase 7, liveness: the deadlock detector, and its report when it fires.
    fn watch_liveness(&mut self) {
        let truths: Vec<VehicleTruth> = self.vehicles.iter().map(|v| v.truth(&self.net)).collect();
        let waiting = self.streams.iter().any(|s| !s.queue.is_empty()) || !self.pending.is_empty();
        let holders = |j: usize| super::wait::holders(&self.managers, j);
        if let Some(d) = super::wait::watch(
            &mut self.detector,
            self.t,
            &truths,
            waiting,
            &self.net,
            &holders,
            &self.lim,
        ) {
            self.deadlock = Some(d);
        }
    }
}

/// A random trip from entry `e`, drawn evenly among its [`trip_choices`] (one draw, as
/// before they were listed: the same trips for the same seeds).
pub(crate) fn draw_trip(
    net: &Network,
    e: &Entry,
    rng: &mut ChaCha8Rng,
) -> (Vec<Movement>, Option<u8>) {
    let choices = trip_choices(net, e);
    if choices.is_empty() {
        return (Vec::new(), None);
    }
    let k = rng.random_range(0..choices.len());
    choices.into_iter().nth(k).unwrap_or_default()
}

/// What a vehicle's move did to its place.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Moved {
    Stays,
    /// It left junction (index) onto a segment, or out of the world (then it is still
    /// `At::Crossing`).
    LeftJunction(usize),
    /// It left the world at the end of an exit segment.
    LeftWorld,
}

/// Hand-overs of one vehicle after its move at `now`: onto a junction's inlet when its
/// centre enters A_C (it is then centred and straight in a serving lane, or its road
/// ended at A_C's edge); bookkeeping of its arrival in A_C and departure from A_S; off a
/// junction once it is on its outlet outside A_C, onto the next segment or out of the
/// world; out of the world past an exit.
pub(crate) fn step_place<const N: usize>(v: &mut Vehicle<N>, net: &Network, now: f64) -> Moved {
    match v.at {
        At::Lane { seg, x, lane, .. } => {
            let Some(sg) = net.segments.get(seg) else {
                return Moved::Stays;
            };
            match sg.end {
                End::Exit(end) if x - 0.5 * LENGTH_M >= end => {
                    v.log.left_at = Some(now);
                    Moved::LeftWorld
                }
                End::Junction(j, end) => {
                    let Some(jn) = net.junctions.get(j) else {
                        return Moved::Stays;
                    };
                    // Into A_C and onto the route's path once centred and straight in a
                    // lane serving its movement (until then it drives on in its lane).
                    if x < end - jn.layout.spec.comm_margin || !v.ready_to_cross(net) {
                        return Moved::Stays;
                    }
                    let movement = v
                        .trip
                        .movements
                        .first()
                        .copied()
                        .unwrap_or(Movement::Straight);
                    let route = net
                        .route_from(seg, lane, movement)
                        .or_else(|| net.route_from(seg, lane, Movement::Straight))
                        .unwrap_or(0);
                    let entry = jn
                        .layout
                        .route(usize::from(route))
                        .map_or(0.0, |r| r.path.entry());
                    v.enter_junction(j, route, entry - (end - x));
                    v.log.arrived_at = Some(now);
                    Moved::Stays
                }
                _ => Moved::Stays,
            }
        }
        At::Crossing { junction, route, s } => {
            let Some(jn) = net.junctions.get(junction) else {
                return Moved::Stays;
            };
            let Some(r) = jn.layout.route(usize::from(route)) else {
                return Moved::Stays;
            };
            let q = r.path.pose_at(s);
            let inside_ac = jn.layout.in_comm_region(q.x, q.y);
            if inside_ac && v.log.arrived_at.is_none() {
                v.log.arrived_at = Some(now);
            }
            if s - 0.5 * LENGTH_M >= r.path.exit() && v.log.left_as_at.is_none() {
                v.log.left_as_at = Some(now);
            }
            let (Some(a), Some(_)) = (v.log.arrived_at, v.log.left_as_at) else {
                return Moved::Stays;
            };
            if inside_ac {
                return Moved::Stays;
            }
            v.log.crossings.push(now - a);
            match jn
                .outlets
                .get(usize::from(r.outlet.heading))
                .copied()
                .flatten()
            {
                Some(seg) => {
                    let lane = net
                        .segments
                        .get(seg)
                        .map_or(0, |sg| sg.junction_lane(r.outlet.lane));
                    v.enter_segment(net, seg, s - r.path.exit(), lane);
                }
                None => v.log.left_at = Some(now),
            }
            Moved::LeftJunction(junction)
        }
    }
}
