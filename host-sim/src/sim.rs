//! The simulation engine: every vehicle is its own planner-core instance (or a scripted
//! driver) that learns about the others only from messages the bus delivers; the
//! simulator integrates the exact vehicle model (SPEC §2) and runs the independent
//! monitor every step.
//!
//! One step at time t: every vehicle broadcasts its state; every vehicle drains what the
//! bus delivered into its world view and decides its command for [t, t+h); then all move.

use crate::bus::{Bus, InProcessBus, Message, Received};
use crate::monitor::{Findings, Limits, Truth};
use crate::reference::ClarabelSolver;
use crate::scenario::{DriverKind, Phase, Scenario, MAX_VEHICLES};
use planner_core::lane_change::LaneEvent;
use planner_core::{
    ConfigError, CostWeights, FallbackReason, IpmSolver, LaneObservation, LanePlanner, MpcSolver,
    Other, Params, Pose, Road, SingleLaneProblem, Solution, SolveError, StepStatus, VehicleState,
    WorldView,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

/// Vehicle length L (Table I).
pub const LENGTH_M: f64 = 4.5;
/// Vehicle width W (Table I).
pub const WIDTH_M: f64 = 1.7;
/// Lane width Wl (Table I).
pub const LANE_WIDTH_M: f64 = 3.6;
/// Extra room scenario starts need over the invariant: the f32 planner margin (2 cm)
/// plus 1 cm, so that planners of either precision start with (10) feasible.
pub const START_MARGIN_M: f64 = 0.03;
/// Capacity of each planner's world view.
pub const WORLD_CAP: usize = MAX_VEHICLES;

/// What a vehicle is doing (the trace's `mode` column).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Mode {
    /// Driving on its verified plan (or its script).
    Cruise,
    /// Changing lanes.
    LaneChange,
    /// Yielding to a vehicle that wants its lane.
    Yield,
    /// The certified max-braking fallback (solver failure, failed verification, or the
    /// invariant not holding).
    Fallback,
    /// Stopped with no room to move (behind a stopped vehicle or at the road end).
    Waiting,
    /// Crossing an intersection.
    Crossing,
    /// Its liveness goal is reached.
    Done,
}

impl Mode {
    /// The name used in traces.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Cruise => "cruise",
            Self::LaneChange => "lane_change",
            Self::Yield => "yield",
            Self::Fallback => "fallback",
            Self::Waiting => "waiting",
            Self::Crossing => "crossing",
            Self::Done => "done",
        }
    }
}

/// Which solver the planners use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum SolverChoice {
    /// planner-core's interior-point solver.
    Ours,
    /// Clarabel (the reference), for comparing plans.
    Clarabel,
}

/// Either solver behind one type, so that a planner can be built with either.
#[derive(Debug, Clone)]
pub enum AnySolver<const N: usize> {
    /// Ours.
    Ours(IpmSolver<f64, N>),
    /// Clarabel.
    Clarabel(ClarabelSolver),
}

impl<const N: usize> MpcSolver<f64, N> for AnySolver<N> {
    fn solve(
        &mut self,
        problem: &SingleLaneProblem<f64, N>,
        warm: Option<&[f64; N]>,
    ) -> Result<Solution<f64, N>, SolveError> {
        match self {
            Self::Ours(s) => s.solve(problem, warm),
            Self::Clarabel(s) => MpcSolver::<f64, N>::solve(s, problem, warm),
        }
    }
}

/// One row of the trace: the state at `t` and the speed commanded for [t, t+h).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TraceRow {
    /// Time (s).
    pub t: f64,
    /// Vehicle id.
    pub id: u16,
    /// Centre x (m).
    pub x: f64,
    /// Centre y (m).
    pub y: f64,
    /// Heading (rad).
    pub theta: f64,
    /// Speed commanded for [t, t+h) (m/s).
    pub v: f64,
    /// Yaw rate commanded for [t, t+h) (rad/s).
    pub omega: f64,
    /// Lane.
    pub lane: u8,
    /// Target lane.
    pub target_lane: u8,
    /// Mode.
    pub mode: Mode,
}

pub(crate) enum Driver<const N: usize> {
    Planner {
        planner: Box<LanePlanner<f64, N, AnySolver<N>>>,
        world: Box<WorldView<f64, WORLD_CAP>>,
        others: Box<heapless::Vec<Other<f64>, WORLD_CAP>>,
    },
    Script(Vec<Phase>),
    Random {
        rng: Box<ChaCha8Rng>,
        accel: f64,
        until: f64,
    },
}

pub(crate) struct Agent<const N: usize> {
    id: u16,
    x: f64,
    y: f64,
    theta: f64,
    v: f64,
    v_before: f64,
    omega: f64,
    lane: u8,
    alpha: Option<u8>,
    beta: Option<u8>,
    target_lane: u8,
    goal_x: Option<f64>,
    reached_at: Option<f64>,
    v_ref: f64,
    driver: Driver<N>,
    mode: Mode,
    /// x where the current intention was declared.
    declared_x: Option<f64>,
    /// Lane changes completed: (x driven from declaration to completion, time completed).
    changes: Vec<(f64, f64)>,
    /// When the vehicle was last seen in its target lane with no change pending.
    in_target_at: Option<f64>,
}

impl<const N: usize> Agent<N> {
    pub(crate) fn state(&self, t: f64) -> VehicleState<f64> {
        VehicleState {
            id: self.id,
            x: self.x,
            y: self.y,
            theta: self.theta,
            v: self.v,
            omega: self.omega,
            lane: self.lane,
            alpha: self.alpha,
            beta: self.beta,
            stamp: t,
            // Scripted and random drivers neither hear intentions nor yield.
            cooperative: matches!(self.driver, Driver::Planner { .. }),
        }
    }

    pub(crate) fn truth(&self) -> Truth {
        Truth {
            x: self.x,
            y: self.y,
            theta: self.theta,
            length: LENGTH_M,
            width: WIDTH_M,
            lane: self.lane,
            keeps_invariant: matches!(self.driver, Driver::Planner { .. }),
            v: self.v,
            v_before: self.v_before,
        }
    }
}

/// Per-step counters, summed over vehicles (and over tasks, in a fleet).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct Counters {
    pub fallback_steps: u64,
    pub waiting_steps: u64,
    pub yield_steps: u64,
    pub lateral_iterations: u64,
    pub planner_steps: u64,
    pub solved_steps: u64,
    pub solver_iterations: u64,
    pub rejected: u64,
}

impl Counters {
    pub(crate) fn add(&mut self, o: &Counters) {
        self.fallback_steps += o.fallback_steps;
        self.waiting_steps += o.waiting_steps;
        self.yield_steps += o.yield_steps;
        self.lateral_iterations += o.lateral_iterations;
        self.planner_steps += o.planner_steps;
        self.solved_steps += o.solved_steps;
        self.solver_iterations += o.solver_iterations;
        self.rejected += o.rejected;
    }
}

/// What one vehicle's decision at time t needs besides its own state and inbox.
pub(crate) struct StepCtx {
    pub t: f64,
    pub steps_done: u64,
    pub road: Road<f64>,
    pub lim: Limits,
    pub silent: Option<crate::bus::Silent>,
}

/// Lane changes of a run.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LaneChangeStats {
    /// Planner-driven vehicles.
    pub vehicles: usize,
    /// How many are in their target lane with no change pending.
    pub in_target_lane: usize,
    /// Lane changes completed.
    pub changes: usize,
    /// When the last vehicle reached its target lane (s), if all did.
    pub all_done_at_s: Option<f64>,
    /// Longest x-distance driven from declaring an intention to completing the change (m).
    pub max_distance_m: f64,
}

/// What a run produced (the `--json` summary).
#[derive(Debug, Clone, Serialize)]
pub struct RunSummary {
    /// Scenario name.
    pub scenario: String,
    /// Vehicles.
    pub vehicles: usize,
    /// Simulated time (s).
    pub sim_seconds: f64,
    /// Collision findings (vehicle pairs × steps).
    pub collisions: u64,
    /// Invariant violations (pairs × steps).
    pub invariant_violations: u64,
    /// Speed, acceleration or heading limit violations (vehicles × steps).
    pub limit_violations: u64,
    /// Steps × vehicles past the road end.
    pub road_end_overruns: u64,
    /// Steps × vehicles with their rectangle off the road.
    pub off_road: u64,
    /// Smallest bumper-to-bumper gap between consecutive vehicles of a lane (m).
    pub min_gap_m: f64,
    /// Planner steps that applied the certified fallback (solver, verification or
    /// invariant).
    pub fallback_steps: u64,
    /// Planner steps standing still with no room (forced, not a failure).
    pub waiting_steps: u64,
    /// Planner steps braking under the Yield Protocol (not a failure).
    pub yield_steps: u64,
    /// Lane changes.
    pub lane_changes: LaneChangeStats,
    /// Lateral-QP iterations over the run.
    pub lateral_iterations_total: u64,
    /// Planner steps.
    pub planner_steps: u64,
    /// Mean interior-point iterations of the planner steps that solved.
    pub solver_iterations_mean: f64,
    /// Every vehicle with a goal reached it by the deadline (true when none has a goal),
    /// and every planner-driven vehicle is in its target lane.
    pub completed: bool,
    /// Vehicles with a goal, and how many reached it by the deadline.
    pub goals: usize,
    /// Goals reached by the deadline.
    pub goals_reached: usize,
    /// Latest time a goal was reached (s), if any.
    pub last_goal_time_s: Option<f64>,
    /// Messages broadcast.
    pub messages_sent: u64,
    /// Messages a world view rejected (stale, invalid).
    pub messages_rejected: u64,
    /// What the bus's injected faults did.
    pub bus_faults: crate::bus::FaultStats,
    /// Solver used by the planners.
    pub solver: SolverChoice,
    /// Seed used.
    pub seed: u64,
    /// Wall-clock time (s).
    pub wall_seconds: f64,
}

/// A running simulation with horizon `N` over bus `B`.
pub struct Simulation<const N: usize, B: Bus = InProcessBus> {
    scenario: Scenario,
    agents: Vec<Agent<N>>,
    bus: B,
    lim: Limits,
    findings: Findings,
    t: f64,
    steps_done: u64,
    total_steps: u64,
    inbox: Vec<Received>,
    truths: Vec<Truth>,
    counters: Counters,
    solver: SolverChoice,
    seed: u64,
}

impl<const N: usize> Simulation<N, InProcessBus> {
    /// A simulation of `scenario` on the in-process bus.
    pub fn new(scenario: Scenario, solver: SolverChoice, seed: Option<u64>) -> Self {
        let ids: Vec<u16> = scenario.vehicles.iter().map(|v| v.id).collect();
        let bus = InProcessBus::with_faults(
            &ids,
            scenario.faults,
            seed.unwrap_or(scenario.seed),
            Limits::table_i().h,
        );
        Self::with_bus(scenario, solver, seed, bus)
    }
}

impl<const N: usize, B: Bus> Simulation<N, B> {
    /// A simulation of `scenario` over `bus` (every vehicle id must be attached).
    pub fn with_bus(scenario: Scenario, solver: SolverChoice, seed: Option<u64>, bus: B) -> Self {
        let lim = Limits::table_i();
        let seed = seed.unwrap_or(scenario.seed);
        let agents = build_agents(&scenario, solver, seed, scenario.faults.notify_bound(lim.h));
        let total_steps = (scenario.duration_s / lim.h).round() as u64;
        Self {
            scenario,
            agents,
            bus,
            lim,
            findings: Findings::new(),
            t: 0.0,
            steps_done: 0,
            total_steps,
            inbox: Vec::new(),
            truths: Vec::new(),
            counters: Counters::default(),
            solver,
            seed,
        }
    }

    /// Tells the planners the steps to which the bus rounds positions and speeds (a CAN
    /// bus: [`crate::can::RESOLUTION`]); see `LanePlanner::set_bus_resolution`.
    pub fn set_bus_resolution(&mut self, resolution: (f64, f64)) -> Result<(), ConfigError> {
        set_bus_resolution(&mut self.agents, resolution)
    }

    /// Steps in the whole run.
    pub fn total_steps(&self) -> u64 {
        self.total_steps
    }

    /// `true` once the scenario's duration has been simulated.
    pub fn finished(&self) -> bool {
        self.steps_done >= self.total_steps
    }

    /// Simulates one period h; `trace` sees a row per vehicle.
    pub fn step(&mut self, trace: &mut dyn FnMut(&TraceRow)) -> Result<(), crate::bus::BusError> {
        let t = self.t;
        let h = self.lim.h;
        for a in &self.agents {
            self.bus.send(a.id, &Message::State(a.state(t)), t)?;
        }
        let ctx = StepCtx {
            t,
            steps_done: self.steps_done,
            road: road_of(&self.scenario),
            lim: self.lim,
            silent: self.scenario.faults.silent,
        };
        let mut commands = Vec::with_capacity(self.agents.len());
        for a in self.agents.iter_mut() {
            self.inbox.clear();
            self.bus.receive(a.id, t, &mut self.inbox)?;
            let (cmd, row) = a.decide(&ctx, &self.inbox, &mut self.counters);
            commands.push(cmd);
            trace(&row);
        }
        for (a, (v, w)) in self.agents.iter_mut().zip(commands) {
            a.advance(v, w, h);
        }
        self.steps_done += 1;
        self.t = self.steps_done as f64 * h;
        for a in self.agents.iter_mut() {
            a.check_goal(self.t);
        }
        self.truths.clear();
        self.truths.extend(self.agents.iter().map(Agent::truth));
        self.findings.check(
            &self.lim,
            &self.truths,
            self.scenario.road.end_x,
            self.scenario.road.lanes,
        );
        Ok(())
    }

    /// Lane-change statistics so far.
    pub fn lane_changes(&self) -> LaneChangeStats {
        lane_changes(&self.agents)
    }

    /// The summary so far.
    pub fn summary(&self, wall_seconds: f64) -> RunSummary {
        summarize(
            &self.scenario,
            &self.agents,
            &Outcome {
                findings: &self.findings,
                counters: &self.counters,
                t: self.t,
                steps_done: self.steps_done,
                bus_faults: self.bus.fault_stats(),
                solver: self.solver,
                seed: self.seed,
                wall_seconds,
            },
        )
    }
}

/// Sets every planner's bus resolution (position m, speed m/s); scripted drivers have none.
pub(crate) fn set_bus_resolution<const N: usize>(
    agents: &mut [Agent<N>],
    (position, speed): (f64, f64),
) -> Result<(), ConfigError> {
    for a in agents {
        a.set_bus_resolution(position, speed)?;
    }
    Ok(())
}

/// The road of a scenario, as the planners see it.
pub(crate) fn road_of(scenario: &Scenario) -> Road<f64> {
    Road {
        lanes: scenario.road.lanes,
        lane_width: LANE_WIDTH_M,
        end_x: scenario.road.end_x,
    }
}

/// The vehicles of `scenario` at t = 0, each with its driver; planners wait `notify` (s)
/// after declaring an intention (SPEC §9; h on a perfect bus).
pub(crate) fn build_agents<const N: usize>(
    scenario: &Scenario,
    solver: SolverChoice,
    seed: u64,
    notify: f64,
) -> Vec<Agent<N>> {
    let params = Params::<f64>::table_i();
    let lim = Limits::table_i();
    scenario
        .vehicles
        .iter()
        .map(|spec| {
            let driver = match spec.driver {
                DriverKind::Planner => {
                    let s = match solver {
                        SolverChoice::Ours => AnySolver::Ours(IpmSolver::default()),
                        SolverChoice::Clarabel => AnySolver::Clarabel(ClarabelSolver {
                            accept_almost_solved: true,
                            ..ClarabelSolver::default()
                        }),
                    };
                    // Default weights are valid by construction, and the latency bound
                    // of validated faults is finite.
                    let mut planner =
                        LanePlanner::with_solver(params, CostWeights::default(), s, spec.lane)
                            .unwrap_or_else(|_| unreachable!("default cost weights are valid"));
                    let _ = planner.set_notify_latency(notify);
                    Driver::Planner {
                        planner: Box::new(planner),
                        world: Box::new(WorldView::new(spec.id)),
                        others: Box::new(heapless::Vec::new()),
                    }
                }
                DriverKind::Script => Driver::Script(spec.script.clone()),
                DriverKind::Random => Driver::Random {
                    rng: Box::new(ChaCha8Rng::seed_from_u64(
                        seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ u64::from(spec.id),
                    )),
                    accel: 0.0,
                    until: 0.0,
                },
            };
            Agent {
                id: spec.id,
                x: spec.x,
                y: (f64::from(spec.lane) + 0.5) * LANE_WIDTH_M,
                theta: 0.0,
                v: spec.v,
                v_before: spec.v,
                omega: 0.0,
                lane: spec.lane,
                alpha: None,
                beta: None,
                target_lane: spec.target_lane.unwrap_or(spec.lane),
                goal_x: spec.goal_x,
                reached_at: spec.goal_x.filter(|g| spec.x >= *g).map(|_| 0.0),
                v_ref: spec.v_ref.unwrap_or(lim.v_max),
                driver,
                mode: Mode::Cruise,
                declared_x: None,
                changes: Vec::new(),
                in_target_at: (spec.target_lane.unwrap_or(spec.lane) == spec.lane).then_some(0.0),
            }
        })
        .collect()
}

impl<const N: usize> Agent<N> {
    /// The vehicle's id.
    pub(crate) fn id(&self) -> u16 {
        self.id
    }

    /// Sets its planner's bus resolution (nothing for a scripted driver).
    pub(crate) fn set_bus_resolution(
        &mut self,
        position: f64,
        speed: f64,
    ) -> Result<(), ConfigError> {
        match &mut self.driver {
            Driver::Planner { planner, .. } => planner.set_bus_resolution(position, speed),
            Driver::Script(_) | Driver::Random { .. } => Ok(()),
        }
    }

    /// Decides the command for [t, t+h) from what the bus delivered (`inbox`), and the
    /// trace row of this step.
    pub(crate) fn decide(
        &mut self,
        ctx: &StepCtx,
        inbox: &[Received],
        counters: &mut Counters,
    ) -> ((f64, f64), TraceRow) {
        let t = ctx.t;
        let lim = &ctx.lim;
        let a = self;
        // A vehicle whose transmitter has failed knows it (bus-off) and gives up lane
        // changes it has not started: the others could not hear its intention.
        if ctx.silent.is_some_and(|s| s.id == a.id && t >= s.from_s) && a.alpha.is_none() {
            a.target_lane = a.lane;
        }
        let (v_cmd, w_cmd) = match &mut a.driver {
            Driver::Planner {
                planner,
                world,
                others,
            } => {
                for r in inbox {
                    if let Message::State(s) = r.msg {
                        if world.update(&s, r.at).is_err() {
                            counters.rejected += 1;
                        }
                    }
                }
                world.others(t, LENGTH_M, others);
                let obs = LaneObservation {
                    pose: Pose {
                        x: a.x,
                        y: a.y,
                        theta: a.theta,
                    },
                    v_prev: a.v,
                    omega_prev: a.omega,
                    others,
                    road: ctx.road,
                    target_lane: a.target_lane,
                    target: a.goal_x.map_or(0.0, |g| g - a.x),
                    v_ref: a.v_ref,
                };
                counters.planner_steps += 1;
                if let Some(m) = planner.beta() {
                    // The cheap test first: the environment is read every 50th step only.
                    if ctx.steps_done % 50 == 0 && std::env::var_os("HOST_SIM_DEBUG").is_some() {
                        eprintln!(
                            "t={t:.2} id={} wants lane {m}: {:?}",
                            a.id,
                            planner.start_check(&obs, m)
                        );
                    }
                }
                match planner.step(&obs) {
                    Ok(c) => {
                        a.lane = c.lane;
                        a.alpha = c.alpha;
                        a.beta = c.beta;
                        match c.event {
                            Some(LaneEvent::Declared(_)) => {
                                a.declared_x.get_or_insert(a.x);
                            }
                            Some(LaneEvent::Completed(_)) => {
                                let from = a.declared_x.take().unwrap_or(a.x);
                                a.changes.push((a.x - from, t));
                            }
                            Some(LaneEvent::Started(_)) | None => {}
                        }
                        if c.lane == a.target_lane && c.alpha.is_none() {
                            a.in_target_at.get_or_insert(t);
                        }
                        counters.lateral_iterations += u64::from(c.lateral_iterations);
                        a.mode = match c.status {
                            StepStatus::Solved { iterations } => {
                                counters.solved_steps += 1;
                                counters.solver_iterations += u64::from(iterations);
                                if c.alpha.is_some() {
                                    Mode::LaneChange
                                } else {
                                    Mode::Cruise
                                }
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
                                if std::env::var_os("HOST_SIM_DEBUG").is_some() {
                                    eprintln!("t={t:.2} id={} fallback {why:?}", a.id);
                                }
                                counters.fallback_steps += 1;
                                Mode::Fallback
                            }
                        };
                        (c.v, c.omega)
                    }
                    Err(_) => {
                        counters.fallback_steps += 1;
                        a.mode = Mode::Fallback;
                        planner.braking_command(a.theta, a.v)
                    }
                }
            }
            Driver::Script(phases) => {
                let accel = phases
                    .iter()
                    .find(|p| t < p.until_s)
                    .map_or(0.0, |p| p.accel);
                a.mode = Mode::Cruise;
                (admissible(lim, a.v, accel), 0.0)
            }
            Driver::Random { rng, accel, until } => {
                if t >= *until {
                    *accel = rng.random_range(-lim.brake..lim.a_max);
                    *until = t + rng.random_range(0.2..2.0);
                }
                a.mode = Mode::Cruise;
                (admissible(lim, a.v, *accel), 0.0)
            }
        };
        if a.reached_at.is_some() && a.mode == Mode::Cruise {
            a.mode = Mode::Done;
        }
        let row = TraceRow {
            t,
            id: a.id,
            x: a.x,
            y: a.y,
            theta: a.theta,
            v: v_cmd,
            omega: w_cmd,
            lane: a.lane,
            target_lane: a.target_lane,
            mode: a.mode,
        };
        ((v_cmd, w_cmd), row)
    }

    /// Applies (v, ω) for one period h: the exact unicycle (1), integrated here
    /// independently of planner-core.
    pub(crate) fn advance(&mut self, v: f64, w: f64, h: f64) {
        self.v_before = self.v;
        self.v = v;
        self.omega = w;
        if w.abs() > 1e-12 {
            let th1 = self.theta + w * h;
            self.x += v / w * (th1.sin() - self.theta.sin());
            self.y -= v / w * (th1.cos() - self.theta.cos());
            self.theta = th1;
        } else {
            self.x += v * h * self.theta.cos();
            self.y += v * h * self.theta.sin();
        }
    }

    /// Records reaching the goal by `t`.
    pub(crate) fn check_goal(&mut self, t: f64) {
        if self.reached_at.is_none() && self.goal_x.is_some_and(|g| self.x >= g) {
            self.reached_at = Some(t);
        }
    }
}

/// Lane-change statistics of `agents`.
pub(crate) fn lane_changes<const N: usize>(agents: &[Agent<N>]) -> LaneChangeStats {
    let wanted: Vec<&Agent<N>> = agents
        .iter()
        .filter(|a| matches!(a.driver, Driver::Planner { .. }))
        .collect();
    let done: Vec<f64> = wanted.iter().filter_map(|a| a.in_target_at).collect();
    LaneChangeStats {
        vehicles: wanted.len(),
        in_target_lane: done.len(),
        changes: wanted.iter().map(|a| a.changes.len()).sum(),
        all_done_at_s: (done.len() == wanted.len())
            .then(|| done.iter().copied().fold(0.0, f64::max)),
        max_distance_m: wanted
            .iter()
            .flat_map(|a| a.changes.iter().map(|c| c.0))
            .fold(0.0, f64::max),
    }
}

/// What a run produced besides its vehicles.
pub(crate) struct Outcome<'a> {
    pub findings: &'a Findings,
    pub counters: &'a Counters,
    pub t: f64,
    pub steps_done: u64,
    pub bus_faults: crate::bus::FaultStats,
    pub solver: SolverChoice,
    pub seed: u64,
    pub wall_seconds: f64,
}

/// The summary of a run of `scenario` that ended with `agents`.
pub(crate) fn summarize<const N: usize>(
    scenario: &Scenario,
    agents: &[Agent<N>],
    o: &Outcome<'_>,
) -> RunSummary {
    let deadline = scenario.deadline_s;
    let with_goal: Vec<&Agent<N>> = agents.iter().filter(|a| a.goal_x.is_some()).collect();
    let reached: Vec<f64> = with_goal
        .iter()
        .filter_map(|a| a.reached_at)
        .filter(|&t| t <= deadline + 1e-9)
        .collect();
    let lane_changes = lane_changes(agents);
    let c = o.counters;
    RunSummary {
        scenario: scenario.name.clone(),
        vehicles: agents.len(),
        sim_seconds: o.t,
        collisions: o.findings.collisions,
        invariant_violations: o.findings.invariant_violations,
        limit_violations: o.findings.limit_violations,
        road_end_overruns: o.findings.road_end_overruns,
        off_road: o.findings.off_road,
        min_gap_m: o.findings.min_gap_m,
        fallback_steps: c.fallback_steps,
        waiting_steps: c.waiting_steps,
        yield_steps: c.yield_steps,
        lane_changes,
        lateral_iterations_total: c.lateral_iterations,
        planner_steps: c.planner_steps,
        solver_iterations_mean: c.solver_iterations as f64 / c.solved_steps.max(1) as f64,
        completed: reached.len() == with_goal.len()
            && lane_changes.in_target_lane == lane_changes.vehicles,
        goals: with_goal.len(),
        goals_reached: reached.len(),
        last_goal_time_s: reached.iter().copied().reduce(f64::max),
        messages_sent: agents.len() as u64 * o.steps_done,
        messages_rejected: c.rejected,
        bus_faults: o.bus_faults,
        solver: o.solver,
        seed: o.seed,
        wall_seconds: o.wall_seconds,
    }
}

/// The speed reached from `v` by `accel` over one period, kept admissible.
fn admissible(lim: &Limits, v: f64, accel: f64) -> f64 {
    (v + accel * lim.h).clamp(
        (v - lim.brake * lim.h).max(0.0),
        (v + lim.a_max * lim.h).min(lim.v_max),
    )
}

/// Runs `scenario` to the end on the in-process bus, dispatching on its horizon.
pub fn run_scenario(
    scenario: Scenario,
    solver: SolverChoice,
    seed: Option<u64>,
    trace: &mut dyn FnMut(&TraceRow),
    progress: &mut dyn FnMut(u64, u64),
) -> Result<RunSummary, crate::bus::BusError> {
    match scenario.horizon {
        50 => run_n::<50, _>(Simulation::new(scenario, solver, seed), trace, progress),
        _ => run_n::<20, _>(Simulation::new(scenario, solver, seed), trace, progress),
    }
}

fn run_n<const N: usize, B: Bus>(
    mut sim: Simulation<N, B>,
    trace: &mut dyn FnMut(&TraceRow),
    progress: &mut dyn FnMut(u64, u64),
) -> Result<RunSummary, crate::bus::BusError> {
    let t0 = std::time::Instant::now();
    let total = sim.total_steps();
    let every = (total / 200).max(1);
    while !sim.finished() {
        sim.step(trace)?;
        if sim.steps_done % every == 0 {
            progress(sim.steps_done, total);
        }
    }
    Ok(sim.summary(t0.elapsed().as_secs_f64()))
}
