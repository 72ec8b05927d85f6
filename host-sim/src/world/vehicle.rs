//! One vehicle of the world: where it is (a segment or a junction), how it is driven (its
//! own planners, or a script), and its trip. Where a vehicle decides is here:
//! [`Vehicle::decide`] turns what it heard into the command for the next period —
//! messages → its view → the planner for where it is → command.
//!
//! On a segment it plans with the multi-lane planner (Sec. IV–V) toward a lane serving
//! its next movement; the stop line of a junction is the road end (22) for lanes that
//! serve that movement, and the edge of A_C is for those that do not (no lane change
//! inside A_C, IC Protocol (i)). Inside A_C, centred and straight in a serving lane, it
//! hands over to the crossing planner along its route (Sec. VI); once outside A_C on its
//! outlet it hands back to the multi-lane planner on the next segment, or leaves.

use super::at::At;
pub use super::driver::{params, Brain, Driver, PlannerSetup, Role};
use super::heard::Reject;
use super::network::{End, Network, Place};
use super::sensor::Sensed;
use super::{DriverKind, VehicleSpec};
use super::{Mode, TraceRow, LANE_WIDTH_M};
use crate::bus::{Clock, Message, Received};
use crate::monitor::Limits;
use can_gateway::wire::CommandStatus;
use planner_core::crossing::CrossingReport;
use planner_core::intersection::Movement;
use planner_core::lane_change::LaneEvent;
use planner_core::{
    CostWeights, FallbackReason, Instant, LaneObservation, Method, Pose, Road, StepStatus,
    VehicleState,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// How far (m) from its lane's centre line, and how far from straight (rad), a vehicle
/// may be when it hands over from the multi-lane planner to the crossing planner, which
/// drives the lane's centre line: the difference is where the vehicle is taken to be
/// from then on (a modelling step well inside the conflict margin of 0.1 m).
pub const HANDOVER_Y_M: f64 = 0.1;
/// See [`HANDOVER_Y_M`].
pub const HANDOVER_THETA_RAD: f64 = 0.02;

/// What a vehicle is to do besides staying safe.
#[derive(Debug, Clone, PartialEq)]
pub struct Trip {
    /// Lane to be in on the current segment (a road's mission; at a junction, a lane
    /// serving the next movement).
    pub target_lane: u8,
    /// Centre x to reach on a road by the deadline, if any.
    pub goal_x: Option<f64>,
    /// Reference speed on a road (a network's vehicles use the segment's limit).
    pub v_ref: Option<f64>,
    /// The movements still to make, one per junction ahead.
    pub movements: Vec<Movement>,
}

/// What happened to a vehicle over a run (for the summary and the liveness checks).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Log {
    /// x where the current intention was declared.
    pub declared_x: Option<f64>,
    /// Lane changes completed: (x driven from declaration to completion, time).
    pub changes: Vec<(f64, f64)>,
    /// When last seen in its target lane with no change pending.
    pub in_target_at: Option<f64>,
    /// When its goal x was reached.
    pub reached_at: Option<f64>,
    /// When it entered the current junction's A_C.
    pub arrived_at: Option<f64>,
    /// When its rear left the current junction's A_S.
    pub left_as_at: Option<f64>,
    /// Junctions crossed: time from entering A_C to leaving it, each.
    pub crossings: Vec<f64>,
    /// When it entered the network and when it left it (open systems).
    pub entered_at: f64,
    /// When it left the network, if it did.
    pub left_at: Option<f64>,
    /// Its trip's free-flow time from where it entered (s), if it drives out of a
    /// network ([`Network::free_flow_s`]).
    pub free_flow_s: Option<f64>,
    /// Movements it gave up, unable to reach a lane serving them in time
    /// ([`super::reroute`]).
    pub turns_given_up: u32,
}

/// One vehicle.
pub struct Vehicle<const N: usize> {
    /// Id.
    pub id: u16,
    /// Where it is and who drives it.
    role: Role<N>,
    /// v_{t−h}: the speed applied over the last period (m/s).
    pub v: f64,
    /// The speed applied over the period before (m/s).
    pub v_before: f64,
    /// ω_{t−h} (rad/s).
    pub omega: f64,
    /// Its trip.
    pub trip: Trip,
    /// What it did this step.
    pub mode: Mode,
    /// Its history.
    pub log: Log,
    /// The status of its last planner step (for the deadlock report).
    pub last_status: Option<StepStatus<f64>>,
    /// It says it cooperates ([`crate::world::VehicleSpec::cooperative`]).
    pub cooperative: bool,
    /// At a junction, whether it held its manager's permission at its last step.
    pub granted: Option<bool>,
    /// Its body: length and braking limit.
    pub body: super::Body,
}

/// What the monitors and the other vehicles' sensors know of a vehicle at an instant:
/// ground truth, never a planner's view.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleTruth {
    /// Id.
    pub id: u16,
    /// Where it is.
    pub at: At,
    /// v_{t−h} (m/s).
    pub v: f64,
    /// v_{t−2h} (m/s).
    pub v_before: f64,
    /// Driven by its own planners (keeps the invariant; has goals).
    pub planner: bool,
    /// It still has a goal.
    pub unmet: bool,
    /// Its target lane (for the wait-for relation).
    pub target_lane: u8,
    /// It keeps the leader-aware invariant toward a cooperating leader.
    pub leader_aware: bool,
    /// Its body.
    pub body: super::Body,
}

impl VehicleTruth {
    /// What sensors see of it (as [`Vehicle::seen`] gives for a vehicle of the world).
    pub fn seen(&self) -> super::sensor::Seen {
        super::sensor::Seen {
            id: self.id,
            at: self.at,
            v: self.v,
            length: self.body.length,
        }
    }
}

/// What vehicle `id` of `body` at `at`, moving at (v, ω) = `vw`, broadcasts at `now` (its
/// clock): its state on a segment, its crossing report in a junction. Every vehicle of
/// this world says how long it is and how hard it can brake.
pub fn announce(
    (id, body): (u16, super::Body),
    at: At,
    (v, omega): (f64, f64),
    cooperative: bool,
    now: Instant,
) -> Message {
    let brake = planner_core::safety::BrakeLimit::from_mps2(body.brake);
    match at {
        At::Lane {
            seg,
            x,
            y,
            theta,
            lane,
            alpha,
            beta,
        } => Message::State {
            state: VehicleState {
                id,
                x,
                y,
                theta,
                v,
                omega,
                lane,
                alpha,
                beta,
                stamp: now,
                cooperative,
                brake,
                length: planner_core::BodyLength::from_m(body.length),
            },
            segment: seg,
        },
        At::Crossing {
            junction, route, s, ..
        } => Message::Crossing {
            report: CrossingReport {
                id,
                route,
                s,
                v,
                length: body.length,
                brake,
            },
            stamp: now,
            junction,
        },
    }
}

/// What a vehicle's decision at time t needs besides its own state and inbox.
pub struct StepCtx<'a> {
    /// The world's time (s since the run began): logs, scripts and fault schedules.
    pub t: f64,
    /// The vehicle's clock now: what its planners compare stamps and leases with.
    pub now: Instant,
    /// Every node's clock (to read a stamp in the world's time).
    pub clock: Clock,
    /// Steps done.
    pub steps_done: u64,
    /// The network.
    pub net: &'a Network,
    /// Limits.
    pub lim: Limits,
    /// A vehicle whose transmitter fails, and from when.
    pub silent: Option<crate::bus::Silent>,
    /// A vehicle that lies about its position: only to count the lies heard and taken
    /// (ground truth, as the monitors have it; no decision reads it).
    pub liar: Option<crate::bus::Liar>,
    /// This vehicle's sensor returns (empty without sensors).
    pub returns: &'a Sensed,
}

/// Per-step counters, summed over vehicles (and over tasks, in a fleet).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Counters {
    /// Certified-fallback steps (not standstill, not yield).
    pub fallback_steps: u64,
    /// Of those, steps whose view could not hold every vehicle that may matter (it
    /// overflowed within the relevance radius): spurious, had the view been bigger.
    pub blind_steps: u64,
    /// Standing with no room.
    pub waiting_steps: u64,
    /// Braking under the Yield Protocol.
    pub yield_steps: u64,
    /// Lateral-QP iterations.
    pub lateral_iterations: u64,
    /// Planner steps.
    pub planner_steps: u64,
    /// Planner steps that solved.
    pub solved_steps: u64,
    /// Solver iterations of those (Newton steps, every one).
    pub solver_iterations: u64,
    /// Of the solved steps, those the active-set step answered
    /// ([`planner_core::solver::active_set`]).
    pub active_set_solves: u64,
    /// Planner steps that applied the previous plan, certified, without solving
    /// ([`planner_core::reuse`]; only with a reuse policy).
    pub reused_steps: u64,
    /// Sum of those steps' certified bounds on J(plan) − J*: the cost given up, at most.
    pub certified_gap: f64,
    /// The multi-lane planners' closed-loop cost: Σ over their steps of
    /// w_v (v − v_ref)² + w_Δ (v − v_prev)² with the default weights, for comparing runs
    /// with and without plan reuse.
    pub tracking_cost: f64,
    /// Messages a view rejected.
    pub rejected: u64,
    /// Of those, states and reports refused as physically implausible.
    pub implausible: u64,
    /// A liar's states and reports heard by planners (`[faults.liar]`).
    pub lies_heard: u64,
    /// Of those, taken into a planner's view.
    pub lies_taken: u64,
}

impl Counters {
    /// Counts a solved planner step.
    fn count_solve(&mut self, iterations: u32, method: Method) {
        self.solved_steps += 1;
        self.solver_iterations += u64::from(iterations);
        if method == Method::ActiveSet {
            self.active_set_solves += 1;
        }
    }

    /// Adds `o`.
    pub fn add(&mut self, o: &Counters) {
        self.fallback_steps += o.fallback_steps;
        self.blind_steps += o.blind_steps;
        self.waiting_steps += o.waiting_steps;
        self.yield_steps += o.yield_steps;
        self.lateral_iterations += o.lateral_iterations;
        self.planner_steps += o.planner_steps;
        self.solved_steps += o.solved_steps;
        self.solver_iterations += o.solver_iterations;
        self.active_set_solves += o.active_set_solves;
        self.reused_steps += o.reused_steps;
        self.certified_gap += o.certified_gap;
        self.tracking_cost += o.tracking_cost;
        self.rejected += o.rejected;
        self.implausible += o.implausible;
        self.lies_heard += o.lies_heard;
        self.lies_taken += o.lies_taken;
    }
}

impl<const N: usize> Vehicle<N> {
    /// A vehicle where `role` says and driven as it says, at speed `v`, entering the
    /// network at `t`.
    pub fn new(id: u16, role: Role<N>, v: f64, trip: Trip, t: f64) -> Self {
        let at = role.at();
        Self {
            cooperative: role.brain().is_some(),
            granted: None,
            id,
            role,
            v,
            v_before: v,
            omega: 0.0,
            trip,
            mode: Mode::Cruise,
            log: Log {
                entered_at: t,
                // A vehicle at a junction is in the lane of its route.
                in_target_at: matches!(at, At::Crossing { .. }).then_some(t),
                ..Log::default()
            },
            last_status: None,
            body: super::Body::CAR,
        }
    }

    /// Notes its trip's free-flow time from where it is now (at its entry).
    pub fn note_free_flow(&mut self, net: &Network) {
        if let At::Lane { seg, x, .. } = self.at() {
            self.log.free_flow_s =
                net.free_flow_s((seg, x), &self.trip.movements, self.body.length);
        }
    }

    /// Where it is.
    pub fn at(&self) -> At {
        self.role.at()
    }

    /// `true` if its own planners drive it.
    pub fn is_planner(&self) -> bool {
        self.role.brain().is_some()
    }

    /// What sensors see of it now.
    pub fn seen(&self) -> super::sensor::Seen {
        super::sensor::Seen {
            id: self.id,
            at: self.at(),
            v: self.v,
            length: self.body.length,
        }
    }

    /// Its ground truth now.
    pub fn truth(&self, net: &Network) -> VehicleTruth {
        VehicleTruth {
            id: self.id,
            at: self.at(),
            v: self.v,
            v_before: self.v_before,
            planner: self.is_planner(),
            unmet: self.unmet(net),
            target_lane: self.trip.target_lane,
            leader_aware: self
                .role
                .brain()
                .is_some_and(|b| b.setup.invariant == planner_core::Invariant::LeaderAware),
            body: self.body,
        }
    }

    /// Its computer is a firmware image in the loop.
    pub fn in_the_loop(&self) -> bool {
        self.role.brain().is_some_and(|b| b.computer.is_some())
    }

    /// Makes a firmware image in the loop its computer.
    pub(crate) fn set_computer(&mut self, c: crate::firmware::Computer) {
        if let Some(b) = self.role.brain_mut() {
            b.computer = Some(Box::new(c));
        }
    }

    /// The lanes and speed limit of the segment it is on, if it is on one.
    pub fn road_limits(&self, net: &Network) -> Option<(u8, f64)> {
        match self.at() {
            At::Lane { seg, .. } => net.segments.get(seg).map(|s| (s.lanes, s.v_max)),
            At::Crossing { .. } => None,
        }
    }

    /// Its computer in the loop, if it has one.
    fn computer_mut(&mut self) -> Option<&mut crate::firmware::Computer> {
        self.role
            .brain_mut()
            .and_then(|b| b.computer.as_deref_mut())
    }

    /// Its computer in the loop, taken away (at the end of a run).
    pub(crate) fn take_computer(&mut self) -> Option<Box<crate::firmware::Computer>> {
        self.role.brain_mut().and_then(|b| b.computer.take())
    }

    /// What its sensors and route tell a computer in the loop at `now` on a road of
    /// `lanes` lanes with speed limit `v_max`, if it is on a road.
    pub fn ego(&self, now: Instant, (lanes, v_max): (u8, f64)) -> Option<crate::firmware::Ego> {
        let Message::State { state, .. } = self.message(now) else {
            return None;
        };
        Some(crate::firmware::Ego {
            // Its route's lane, as the vehicle's own intention layer would say.
            state: VehicleState {
                beta: Some(self.trip.target_lane),
                ..state
            },
            lanes,
            v_ref: self.trip.v_ref.unwrap_or(v_max),
        })
    }

    /// A computer in the loop told where the vehicle is at `now` on `net` (its answer is
    /// [`Vehicle::broadcast`]'s); nothing for another vehicle.
    pub fn tell_computer(&mut self, now: Instant, net: &Network) {
        // Checked first: the ego state is built only for a computer (every vehicle,
        // every period, passes here).
        if !self.in_the_loop() {
            return;
        }
        let ego = self.road_limits(net).and_then(|r| self.ego(now, r));
        if let (Some(c), Some(ego)) = (self.computer_mut(), ego) {
            // A failure is remembered by the computer, and fails its run.
            let _ = c.tell(&ego);
        }
    }

    /// What it broadcasts at `now`: a computer in the loop's own V2V state (told by
    /// [`Vehicle::tell_computer`]), else [`Vehicle::message`] — also when the computer
    /// does not answer (it remembers that, and its run fails).
    pub fn broadcast(&mut self, now: Instant) -> Message {
        let At::Lane { seg, .. } = self.at() else {
            return self.message(now);
        };
        match self.computer_mut().map(|c| c.state()) {
            Some(Ok(state)) => Message::State {
                state,
                segment: seg,
            },
            _ => self.message(now),
        }
    }

    /// A computer in the loop given what the vehicle heard (`inbox`) and the tick (its
    /// command is read in [`Vehicle::decide`]); nothing for another vehicle.
    pub fn tick_computer(&mut self, inbox: &[Received]) {
        let Some(c) = self.computer_mut() else {
            return;
        };
        let heard: Vec<VehicleState<f64>> = inbox
            .iter()
            .filter_map(|r| match r.msg {
                Message::State { state, .. } => Some(state),
                _ => None,
            })
            .collect();
        let _ = c.tick(&heard, false);
    }

    /// What it broadcasts about itself at `now` (its clock): its state on a segment, its
    /// crossing report in a junction.
    pub fn message(&self, now: Instant) -> Message {
        // Scripted and random drivers neither hear intentions nor yield.
        announce(
            (self.id, self.body),
            self.at(),
            (self.v, self.omega),
            self.cooperative,
            now,
        )
    }

    /// Takes the messages the bus delivered into its view (counting those rejected), and
    /// its grants; `false` if its view overflowed (it may miss a vehicle near it).
    fn hear(&mut self, ctx: &StepCtx<'_>, inbox: &[Received], counters: &mut Counters) -> bool {
        let net = ctx.net;
        let me = super::heard::Here {
            at: self.position(net),
            v: self.v,
        };
        let (at, seen) = (self.at(), self.seen());
        let Some(b) = self.role.brain_mut() else {
            return true;
        };
        b.view.forget_silent(ctx.now, (b.setup.notify, ctx.lim.h));
        let mut whole = true;
        for r in inbox {
            let taken = b.view.take(&r.msg, net, me);
            if ctx.liar.is_some_and(|l| l.lied(&r.msg, &ctx.clock)) {
                counters.lies_heard += 1;
                counters.lies_taken += u64::from(taken.is_ok());
            }
            match taken {
                Err(Reject::Full) => whole = false,
                Err(Reject::Far) => {}
                Err(Reject::Stale | Reject::Invalid) => {
                    if matches!(r.msg, Message::State { .. }) {
                        counters.rejected += 1;
                    }
                }
                Err(Reject::Implausible(_)) => {
                    counters.rejected += 1;
                    counters.implausible += 1;
                }
                Err(Reject::Distrusted) => counters.rejected += 1,
                Err(Reject::Own) | Ok(()) => {}
            }
            if let (Some(c), At::Crossing { junction, .. }) = (&mut b.crossing, at) {
                if let Message::Grant {
                    junction: j,
                    id,
                    until,
                } = r.msg
                {
                    if j == junction {
                        c.hear_grant(id, until);
                    }
                }
            }
        }
        // What its own sensors returned belies a claim that stays within the physical
        // bounds (View::belied).
        if let Some(sn) = &b.setup.sensing {
            let now = (ctx.now, ctx.lim.v_max);
            b.view.belied(net, (&seen, sn), ctx.returns, now);
        }
        whole && !b.view.take_overflow()
    }

    /// Its centre in the world.
    pub fn position(&self, net: &Network) -> (f64, f64) {
        let p = match self.at() {
            At::Lane { seg, x, y, .. } => net
                .segments
                .get(seg)
                .map_or(Pose { x, y, theta: 0.0 }, |s| s.to_world(x, y, 0.0)),
            At::Crossing { junction, route, s } => net
                .junctions
                .get(junction)
                .map_or(Pose::default(), |j| j.pose(route, s)),
        };
        (p.x, p.y)
    }

    /// Decides the command (v, ω) for [t, t+h) from what the bus delivered, and the
    /// trace row of this step.
    pub fn decide(
        &mut self,
        ctx: &StepCtx<'_>,
        inbox: &[Received],
        counters: &mut Counters,
    ) -> ((f64, f64), TraceRow) {
        // A vehicle whose transmitter has failed knows it (bus-off) and gives up lane
        // changes it has not started: the others could not hear its intention.
        if let At::Lane {
            alpha: None, lane, ..
        } = self.at()
        {
            if ctx
                .silent
                .is_some_and(|s| s.id == self.id && ctx.t >= s.from_s)
            {
                self.trip.target_lane = lane;
            }
        }
        let whole = self.hear(ctx, inbox, counters);
        // Where it is and who drives it, matched once: each decider gets its place.
        let cmd = match self.at() {
            At::Lane { x, .. } if self.in_the_loop() => self.decide_in_loop(x, ctx, counters),
            _ if !whole => self.blind(ctx, counters),
            At::Lane { .. } if !self.is_planner() => self.decide_script(ctx),
            At::Lane {
                seg,
                x,
                y,
                theta,
                lane,
                ..
            } => self.decide_lane((seg, Pose { x, y, theta }, lane), ctx, counters),
            // Scripted and random drivers are built on roads only; were one in a junction,
            // it would brake.
            At::Crossing { .. } if !self.is_planner() => self.fallback(ctx, counters),
            At::Crossing {
                junction, route, s, ..
            } => self.decide_crossing((junction, route, s), ctx, counters),
        };
        if self.log.reached_at.is_some() && self.mode == Mode::Cruise {
            self.mode = Mode::Done;
        }
        (cmd, self.row(ctx, cmd))
    }

    /// A step whose view overflowed: the vehicle may not know of one near it, so it applies
    /// the certified fallback (max braking with straightening), safe whatever is there.
    fn blind(&mut self, ctx: &StepCtx<'_>, counters: &mut Counters) -> (f64, f64) {
        counters.blind_steps += 1;
        self.fallback(ctx, counters)
    }

    /// The certified fallback (max braking with straightening, Lemma 2): for a blind step,
    /// and for a vehicle whose place and driver do not fit together (a junction the
    /// network does not have; a scripted driver in a junction) — never an instant stop.
    fn fallback(&mut self, ctx: &StepCtx<'_>, counters: &mut Counters) -> (f64, f64) {
        counters.fallback_steps += 1;
        self.mode = Mode::Fallback;
        let p = params(self.speed_limit(ctx.net), self.body);
        let v = planner_core::safety::max_braking_command(&p, self.v);
        let w = match self.at() {
            At::Lane { theta, .. } => planner_core::lane_change::straighten(&p, theta, v),
            At::Crossing { .. } => 0.0,
        };
        (v, w)
    }

    /// The speed limit where it is.
    fn speed_limit(&self, net: &Network) -> f64 {
        match self.at() {
            At::Lane { seg, .. } => net.segments.get(seg).map_or(27.8, |s| s.v_max),
            At::Crossing {
                junction, route, ..
            } => net.route_limit(junction, route).unwrap_or(13.9),
        }
    }

    /// The road as the multi-lane planner on segment `seg` sees it: its lanes, and where
    /// it ends — a dead end; or at a junction, the edge of A_C (the commitment point of
    /// SPEC §10: no lane change inside A_C), until the vehicle is in a lane serving its
    /// next movement with no change declared or under way; then the stop line. It hands
    /// over to its crossing planner once also centred and straight
    /// ([`Vehicle::ready_to_cross`]): a change completes within 0.6 m of the centre line
    /// (Lemma 12's manoeuvre converges there), and a vehicle that had to stop at the edge
    /// of A_C before it was centred could never centre (a unicycle does not move sideways
    /// at rest) — it finishes centring on its way to the stop line.
    fn road(&self, net: &Network, seg: usize) -> Road<f64> {
        let Some(sg) = net.segments.get(seg) else {
            return Road {
                lanes: 1,
                lane_width: LANE_WIDTH_M,
                end_x: None,
            };
        };
        let end_x = match sg.end {
            End::Open | End::Exit(_) => None,
            End::DeadEnd(x) => Some(x),
            End::Junction(_, x) if self.in_serving_lane(net) => Some(x),
            End::Junction(..) => sg.comm_edge(net),
        };
        Road {
            lanes: sg.lanes,
            lane_width: LANE_WIDTH_M,
            end_x,
        }
    }

    /// `true` if, on a segment ending at a junction, it is in a lane serving its next
    /// movement with no lane change declared or under way.
    pub fn in_serving_lane(&self, net: &Network) -> bool {
        let At::Lane {
            seg,
            lane,
            alpha,
            beta,
            ..
        } = self.at()
        else {
            return false;
        };
        net.segments.get(seg).is_some_and(|sg| {
            sg.serves(net, lane, self.trip.movements.first().copied())
                && alpha.is_none()
                && beta.is_none()
        })
    }

    /// `true` if it still has a goal: a lane change to make, a goal x to reach, or a trip
    /// through a junction to finish (a vehicle at or past a junction, or heading for one).
    /// Scripted and random drivers have none.
    pub fn unmet(&self, net: &Network) -> bool {
        if !self.is_planner() {
            return false;
        }
        match self.at() {
            At::Crossing { .. } => true,
            At::Lane {
                seg, lane, alpha, ..
            } => {
                let towards_junction = net
                    .segments
                    .get(seg)
                    .is_some_and(|s| matches!(s.end, End::Junction(..) | End::Exit(_)));
                towards_junction
                    || lane != self.trip.target_lane
                    || alpha.is_some()
                    || (self.trip.goal_x.is_some() && self.log.reached_at.is_none())
            }
        }
    }

    /// `true` if, on a segment ending at a junction, the vehicle may hand over to its
    /// crossing planner: in a lane serving its next movement, no change
    /// declared or under way, within [`HANDOVER_Y_M`] of the lane's centre line and
    /// [`HANDOVER_THETA_RAD`] of straight.
    pub fn ready_to_cross(&self, net: &Network) -> bool {
        let At::Lane {
            seg,
            y,
            theta,
            lane,
            ..
        } = self.at()
        else {
            return false;
        };
        self.is_planner()
            && self.in_serving_lane(net)
            && net.segments.get(seg).is_some_and(|sg| {
                (y - sg.lane_centre(lane)).abs() <= HANDOVER_Y_M
                    && theta.abs() <= HANDOVER_THETA_RAD
            })
    }

    /// A planner on segment `seg` at `pose` in lane `lane`: messages → its view → the
    /// multi-lane planner → command, and what it did logged and counted.
    fn decide_lane(
        &mut self,
        (seg, pose, lane): (usize, Pose<f64>, u8),
        ctx: &StepCtx<'_>,
        counters: &mut Counters,
    ) -> (f64, f64) {
        let Pose { x, y, theta } = pose;
        self.give_up_turn_if_late(ctx);
        let road = self.road(ctx.net, seg);
        let v_max = ctx.net.segments.get(seg).map_or(ctx.lim.v_max, |s| s.v_max);
        let Some(b) = self.role.brain_mut() else {
            return self.fallback(ctx, counters);
        };
        if b.lane.is_none() {
            b.lane = Some(b.lane_planner(lane, v_max));
        }
        b.view.others_on(
            ctx.net,
            seg,
            ctx.now,
            b.setup.fleet.longest_m,
            &mut b.others,
        );
        for r in &ctx.returns.others {
            let _ = b.others.push(*r);
        }
        let (v_prev, v_ref) = (self.v, self.trip.v_ref.unwrap_or(v_max));
        let obs = LaneObservation {
            pose: Pose { x, y, theta },
            v_prev: self.v,
            omega_prev: self.omega,
            others: &b.others,
            road,
            target_lane: self.trip.target_lane,
            target: self.trip.goal_x.map_or(0.0, |g| g - x),
            v_ref: self.trip.v_ref.unwrap_or(v_max),
        };
        let Some(planner) = b.lane.as_mut() else {
            return self.fallback(ctx, counters);
        };
        counters.planner_steps += 1;
        match planner.step(&obs) {
            Ok(c) => {
                self.role.set_lane_state(c.lane, c.alpha, c.beta);
                match c.event {
                    Some(LaneEvent::Declared(_)) => {
                        self.log.declared_x.get_or_insert(x);
                    }
                    Some(LaneEvent::Completed(_)) => {
                        let from = self.log.declared_x.take().unwrap_or(x);
                        self.log.changes.push((x - from, ctx.t));
                    }
                    // A start, or no event: nothing to log.
                    _ => {}
                }
                if c.lane == self.trip.target_lane && c.alpha.is_none() {
                    self.log.in_target_at.get_or_insert(ctx.t);
                }
                counters.lateral_iterations += u64::from(c.lateral_iterations);
                counters.tracking_cost += CostWeights::default().stage_cost(c.v, v_prev, v_ref);
                self.mode = mode_of(c.status, c.alpha.is_some(), counters, ctx.t, self.id);
                self.last_status = Some(c.status);
                (c.v, c.omega)
            }
            Err(_) => {
                counters.fallback_steps += 1;
                self.mode = Mode::Fallback;
                planner.braking_command(theta, self.v)
            }
        }
    }

    /// A computer in the loop at `x` on a road (what it heard was relayed to it with the
    /// tick, [`Vehicle::tick_computer`]): its command applied and its lanes taken; a
    /// computer that does not answer is braked (the certified fallback) and its run fails
    /// at its end.
    fn decide_in_loop(&mut self, x: f64, ctx: &StepCtx<'_>, counters: &mut Counters) -> (f64, f64) {
        let answer = self.computer_mut().map(|c| c.answer());
        // The computer remembers that it failed; its run's report says so.
        let Some(Ok(c)) = answer else {
            return self.fallback(ctx, counters);
        };
        counters.planner_steps += 1;
        let before = self.at();
        self.role.set_lane_state(c.lane, c.alpha, c.beta);
        self.log_lanes(before, x, ctx.t);
        let changing = c.alpha.is_some();
        self.mode = match c.status {
            CommandStatus::Solved | CommandStatus::Reused => Mode::moving(changing),
            CommandStatus::NoRoom => Mode::Waiting,
            CommandStatus::Yield => Mode::Yield,
            _ => {
                counters.fallback_steps += 1;
                Mode::Fallback
            }
        };
        self.last_status = None;
        (c.v, c.omega)
    }

    /// The lane changes a computer in the loop made, from its lanes `before` this step
    /// and now (it reports lanes, not events), at `x` and time `t`.
    fn log_lanes(&mut self, before: At, x: f64, t: f64) {
        let (
            At::Lane {
                alpha: a0,
                beta: b0,
                ..
            },
            At::Lane {
                lane, alpha, beta, ..
            },
        ) = (before, self.at())
        else {
            return;
        };
        if (a0.is_none() && b0.is_none()) && (alpha.is_some() || beta.is_some()) {
            self.log.declared_x.get_or_insert(x);
        }
        if a0 == Some(lane) && alpha.is_none() {
            let from = self.log.declared_x.take().unwrap_or(x);
            self.log.changes.push((x - from, t));
        }
        if lane == self.trip.target_lane && alpha.is_none() {
            self.log.in_target_at.get_or_insert(t);
        }
    }

    /// A scripted or random driver: its acceleration, kept admissible, unless a vehicle is
    /// physically in its lane ahead closer than its stopping distance allows after the
    /// step — then it brakes fully (a one-step safety filter: what any driver does when
    /// something is in the way, without hearing anyone's intentions).
    fn decide_script(&mut self, ctx: &StepCtx<'_>) -> (f64, f64) {
        let t = ctx.t;
        let lim = &ctx.lim;
        let accel = match &mut self.role {
            Role::Road {
                driver: Driver::Script(phases),
                ..
            } => phases
                .iter()
                .find(|p| t < p.until_s)
                .map_or(0.0, |p| p.accel),
            Role::Road {
                driver: Driver::Random { rng, accel, until },
                ..
            } => {
                if t >= *until {
                    *accel = rng.random_range(-lim.brake..lim.a_max);
                    *until = t + rng.random_range(0.2..2.0);
                }
                *accel
            }
            Role::Road { .. } | Role::Junction { .. } => 0.0,
        };
        self.mode = Mode::Cruise;
        let v = admissible(lim, self.v, accel);
        let braking = admissible(lim, self.v, -lim.brake);
        match ctx.returns.gap_ahead {
            // x_{t+h} + dS(v_t) ≤ x̄: (10)'s first constraint toward what it sees.
            Some(gap) if v * lim.h + lim.safe_distance(v) > gap - lim.d0 => (braking, 0.0),
            _ => (v, 0.0),
        }
    }

    /// A planner at `junction` on `route`, `s` along its path: reports and grants → the
    /// crossing planner → command.
    fn decide_crossing(
        &mut self,
        (junction, route, s): (usize, u8, f64),
        ctx: &StepCtx<'_>,
        counters: &mut Counters,
    ) -> (f64, f64) {
        let Some(jn) = ctx.net.junctions.get(junction) else {
            return self.fallback(ctx, counters);
        };
        let layout = &jn.layout;
        let v_limit = ctx
            .net
            .route_limit(junction, route)
            .unwrap_or(layout.spec.v_limit);
        let Some(b) = self.role.brain_mut() else {
            return self.fallback(ctx, counters);
        };
        if b.crossing.is_none() {
            b.crossing = Some(b.crossing_planner((self.id, route), layout, v_limit));
        }
        let on_path = b
            .view
            .on_path(ctx.net, (junction, route), b.setup.fleet.longest_m);
        let Some(c) = b.crossing.as_mut() else {
            return self.fallback(ctx, counters);
        };
        // Its view of the junction, as it stands this period.
        c.clear_reports();
        for (report, stamp) in b.view.reports_at(junction).chain(on_path.leaders) {
            c.hear_report(&report, stamp);
        }
        c.hear_paths(&ctx.returns.on_path, &on_path.walls);
        let permitted = c.permitted(layout, s, ctx.now);
        self.granted = Some(permitted);
        counters.planner_steps += 1;
        let (v, why) = match c.step(layout, (s, self.v), ctx.now) {
            Ok(cmd) => {
                self.last_status = Some(cmd.status);
                match cmd.status {
                    StepStatus::Solved { iterations, method } => {
                        counters.count_solve(iterations, method);
                        (cmd.v, None)
                    }
                    // The crossing planners solve every step (no reuse policy is set).
                    StepStatus::Reused { .. } => (cmd.v, None),
                    StepStatus::Fallback(FallbackReason::NoRoom) => {
                        counters.waiting_steps += 1;
                        (cmd.v, Some(FallbackReason::NoRoom))
                    }
                    StepStatus::Fallback(why) => {
                        if debug_fallbacks() {
                            eprintln!(
                                "t={:.2} id={} route={route} s={s:.2} v={:.2} permitted={permitted} {why:?} gap={:.3}",
                                ctx.t, self.id, self.v, cmd.gap
                            );
                        }
                        counters.fallback_steps += 1;
                        (cmd.v, Some(why))
                    }
                    // A status planner-core adds later: its command was verified.
                    _ => (cmd.v, None),
                }
            }
            Err(_) => {
                counters.fallback_steps += 1;
                let p = params(v_limit, self.body);
                (
                    planner_core::safety::max_braking_command(&p, self.v),
                    Some(FallbackReason::Lateral),
                )
            }
        };
        self.mode = match why {
            None => Mode::Crossing,
            Some(FallbackReason::NoRoom) => Mode::Waiting,
            Some(_) => Mode::Fallback,
        };
        (v, 0.0)
    }

    /// The trace row of this step's decision.
    fn row(&self, ctx: &StepCtx<'_>, (v, omega): (f64, f64)) -> TraceRow {
        let (pose, lane, place) = match self.at() {
            At::Lane {
                seg,
                x,
                y,
                theta,
                lane,
                ..
            } => {
                let p = ctx
                    .net
                    .segments
                    .get(seg)
                    .map_or(Pose { x, y, theta }, |s| s.to_world(x, y, theta));
                (p, lane, Place::Segment(seg))
            }
            At::Crossing { junction, route, s } => {
                let jn = ctx.net.junctions.get(junction);
                let p = jn.map_or(Pose::default(), |j| j.pose(route, s));
                let lane = jn
                    .and_then(|j| j.layout.route(usize::from(route)))
                    .map_or(0, |r| r.inlet.lane);
                (p, lane, Place::Junction(junction))
            }
        };
        TraceRow {
            t: ctx.t,
            id: self.id,
            x: pose.x,
            y: pose.y,
            theta: pose.theta,
            v,
            omega,
            lane,
            target_lane: match self.at() {
                At::Lane { .. } => self.trip.target_lane,
                At::Crossing { .. } => lane,
            },
            mode: self.mode,
            place,
            granted: match self.at() {
                At::Crossing { .. } => self.granted,
                At::Lane { .. } => None,
            },
            length: self.body.length,
            width: super::WIDTH_M,
            brake: self.body.brake,
            invariant: self.role.brain().map(|b| b.setup.invariant),
        }
    }

    /// Applies (v, ω) for one period h: the exact unicycle (1) on a segment, integrated
    /// here independently of planner-core; along the path in a junction.
    pub fn advance(&mut self, v: f64, w: f64, h: f64) {
        self.v_before = self.v;
        self.v = v;
        self.omega = w;
        match &mut self.role {
            Role::Road { x, y, theta, .. } => {
                if w.abs() > 1e-12 {
                    let th1 = *theta + w * h;
                    *x += v / w * (th1.sin() - theta.sin());
                    *y -= v / w * (th1.cos() - theta.cos());
                    *theta = th1;
                } else {
                    *x += v * h * theta.cos();
                    *y += v * h * theta.sin();
                }
            }
            Role::Junction { s, .. } => *s += v * h,
        }
    }

    /// Records reaching the goal x by `t`.
    pub fn check_goal(&mut self, t: f64) {
        if let At::Lane { x, .. } = self.at() {
            if self.log.reached_at.is_none() && self.trip.goal_x.is_some_and(|g| x >= g) {
                self.log.reached_at = Some(t);
            }
        }
    }

    /// Moves into junction `junction` on `route` at path position `s` (hand-over); `false`,
    /// and nothing changed, for a driver other than its own planners (only planners cross:
    /// [`Vehicle::ready_to_cross`] is never true for the others).
    pub fn enter_junction(&mut self, junction: usize, route: u8, s: f64) -> bool {
        if !self.role.enter_junction(junction, route, s) {
            return false;
        }
        self.omega = 0.0;
        self.log.arrived_at = None;
        self.log.left_as_at = None;
        self.forget_planners();
        true
    }

    /// Its planners are built afresh for the place it has just entered.
    fn forget_planners(&mut self) {
        if let Some(b) = self.role.brain_mut() {
            b.lane = None;
            b.crossing = None;
        }
    }

    /// Moves onto segment `seg` at `x` in `lane`, centred and straight, with target lane
    /// `target` (hand-back after a junction).
    pub fn enter_segment(&mut self, net: &Network, seg: usize, x: f64, lane: u8) {
        let y = (f64::from(lane) + 0.5) * LANE_WIDTH_M;
        self.role.enter_segment(seg, (x, y), lane);
        self.omega = 0.0;
        if !self.trip.movements.is_empty() {
            self.trip.movements.remove(0);
        }
        self.retarget(net);
        self.forget_planners();
    }

    /// Takes a detour if it can no longer reach a lane serving its next movement before
    /// the edge of A_C ([`super::reroute`]).
    fn give_up_turn_if_late(&mut self, ctx: &StepCtx<'_>) {
        use super::reroute::{destination, detour, must_give_up};
        let next = self.trip.movements.first().copied();
        if !must_give_up(
            ctx.net,
            &ctx.lim,
            self.at(),
            (self.v, self.body.brake),
            next,
        ) {
            return;
        }
        let At::Lane { seg, lane, .. } = self.at() else {
            return;
        };
        let new = destination(ctx.net, seg, &self.trip.movements)
            .and_then(|dest| detour(ctx.net, seg, lane, dest));
        if let Some(movements) = new {
            self.trip.movements = movements;
            self.retarget(ctx.net);
            self.log.turns_given_up += 1;
        }
    }

    /// Sets the target lane on the current segment: the nearest lane serving the next
    /// movement (SPEC §10).
    pub fn retarget(&mut self, net: &Network) {
        if let At::Lane { seg, lane, .. } = self.at() {
            if let Some(sg) = net.segments.get(seg) {
                let next = self.trip.movements.first().copied();
                self.trip.target_lane = sg.nearest_serving(net, lane, next);
                self.log.in_target_at = None;
            }
        }
    }
}

/// The mode of a multi-lane step, counting it.
fn mode_of(
    status: StepStatus<f64>,
    changing: bool,
    counters: &mut Counters,
    t: f64,
    id: u16,
) -> Mode {
    match status {
        StepStatus::Solved { iterations, method } => {
            counters.count_solve(iterations, method);
            Mode::moving(changing)
        }
        StepStatus::Reused { certified_gap, .. } => {
            counters.reused_steps += 1;
            counters.certified_gap += certified_gap;
            Mode::moving(changing)
        }
        StepStatus::Fallback(FallbackReason::NoRoom) => {
            counters.waiting_steps += 1;
            Mode::Waiting
        }
        StepStatus::Fallback(FallbackReason::Yield) => {
            counters.yield_steps += 1;
            Mode::Yield
        }
        StepStatus::Fallback(why) => {
            if debug_fallbacks() {
                eprintln!("t={t:.2} id={id} fallback {why:?}");
            }
            counters.fallback_steps += 1;
            Mode::Fallback
        }
        // A status planner-core adds later: its command was verified all the same.
        _ => Mode::moving(changing),
    }
}

/// `HOST_SIM_DEBUG` is set: print every certified-fallback step (docs/architecture.md,
/// "Diagnostics"). Read from the environment once per process, not in the loop.
fn debug_fallbacks() -> bool {
    static DEBUG: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *DEBUG.get_or_init(|| std::env::var_os("HOST_SIM_DEBUG").is_some())
}

/// The speed reached from `v` by `accel` over one period, kept admissible.
pub fn admissible(lim: &Limits, v: f64, accel: f64) -> f64 {
    (v + accel * lim.h).clamp(
        (v - lim.brake * lim.h).max(0.0),
        (v + lim.a_max * lim.h).min(lim.v_max),
    )
}

/// A vehicle of `spec` at t = 0, with planners set up as `setup`.
pub(crate) fn build_vehicle<const N: usize>(
    spec: &VehicleSpec,
    setup: PlannerSetup,
    seed: u64,
    net: &Network,
) -> Vehicle<N> {
    let role = match spec.driver {
        DriverKind::Planner => None,
        DriverKind::Script => Role::new(spec.at, Driver::Script(spec.script.clone())),
        DriverKind::Random => Role::new(
            spec.at,
            Driver::Random {
                rng: Box::new(ChaCha8Rng::seed_from_u64(
                    seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ u64::from(spec.id),
                )),
                accel: 0.0,
                until: 0.0,
            },
        ),
    }
    // Only planners cross junctions: one that starts in a junction is its planners' (no
    // loader writes another driver there; see `VehicleSpec::driver`).
    .unwrap_or_else(|| Role::planner(spec.at, Box::new(Brain::new(spec.id, setup, spec.body))));
    let mut v = Vehicle::new(spec.id, role, spec.v, spec.trip.clone(), 0.0);
    v.cooperative = spec.cooperative;
    v.body = spec.body;
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

/// Gives a vehicle's brain a new setup (its planners are built with it from now on).
pub(crate) fn set_setup<const N: usize>(v: &mut Vehicle<N>, setup: PlannerSetup) {
    if let Some(b) = v.role.brain_mut() {
        b.set_setup(setup);
    }
}
