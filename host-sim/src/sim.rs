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
use planner_core::planner::Vehicle;
use planner_core::{
    CostWeights, FallbackReason, IpmSolver, MpcSolver, Observation, Params, Planner,
    SingleLaneProblem, Solution, SolveError, StepStatus, VehicleState, WorldView,
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

enum Driver<const N: usize> {
    Planner {
        planner: Box<Planner<f64, N, AnySolver<N>>>,
        world: Box<WorldView<f64, WORLD_CAP>>,
        lane_buf: Box<heapless::Vec<Vehicle<f64>, WORLD_CAP>>,
    },
    Script(Vec<Phase>),
    Random {
        rng: Box<ChaCha8Rng>,
        accel: f64,
        until: f64,
    },
}

struct Agent<const N: usize> {
    id: u16,
    x: f64,
    y: f64,
    theta: f64,
    v: f64,
    v_before: f64,
    omega: f64,
    lane: u8,
    target_lane: u8,
    goal_x: Option<f64>,
    reached_at: Option<f64>,
    v_ref: f64,
    driver: Driver<N>,
    mode: Mode,
}

impl<const N: usize> Agent<N> {
    fn state(&self, t: f64) -> VehicleState<f64> {
        VehicleState {
            id: self.id,
            x: self.x,
            y: self.y,
            theta: self.theta,
            v: self.v,
            omega: self.omega,
            lane: self.lane,
            alpha: None,
            beta: None,
            stamp: t,
        }
    }

    fn truth(&self) -> Truth {
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
    /// Smallest bumper-to-bumper gap between consecutive vehicles of a lane (m).
    pub min_gap_m: f64,
    /// Planner steps that applied the certified fallback (solver, verification or
    /// invariant).
    pub fallback_steps: u64,
    /// Planner steps standing still with no room (forced, not a failure).
    pub waiting_steps: u64,
    /// Planner steps.
    pub planner_steps: u64,
    /// Mean interior-point iterations of the planner steps that solved.
    pub solver_iterations_mean: f64,
    /// Every vehicle with a goal reached it by the deadline (true when none has a goal).
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
    params: Params<f64>,
    findings: Findings,
    t: f64,
    steps_done: u64,
    total_steps: u64,
    inbox: Vec<Received>,
    truths: Vec<Truth>,
    fallback_steps: u64,
    waiting_steps: u64,
    planner_steps: u64,
    solved_steps: u64,
    solver_iterations: u64,
    rejected: u64,
    solver: SolverChoice,
    seed: u64,
}

impl<const N: usize> Simulation<N, InProcessBus> {
    /// A simulation of `scenario` on the in-process bus.
    pub fn new(scenario: Scenario, solver: SolverChoice, seed: Option<u64>) -> Self {
        let ids: Vec<u16> = scenario.vehicles.iter().map(|v| v.id).collect();
        Self::with_bus(scenario, solver, seed, InProcessBus::new(&ids))
    }
}

impl<const N: usize, B: Bus> Simulation<N, B> {
    /// A simulation of `scenario` over `bus` (every vehicle id must be attached).
    pub fn with_bus(scenario: Scenario, solver: SolverChoice, seed: Option<u64>, bus: B) -> Self {
        let params = Params::<f64>::table_i();
        let lim = Limits::table_i();
        let seed = seed.unwrap_or(scenario.seed);
        let agents = scenario
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
                        // Default weights are valid by construction.
                        let planner = Planner::with_solver(params, CostWeights::default(), s)
                            .unwrap_or_else(|_| unreachable!("default cost weights are valid"));
                        Driver::Planner {
                            planner: Box::new(planner),
                            world: Box::new(WorldView::new(spec.id)),
                            lane_buf: Box::new(heapless::Vec::new()),
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
                    target_lane: spec.target_lane.unwrap_or(spec.lane),
                    goal_x: spec.goal_x,
                    reached_at: spec.goal_x.filter(|g| spec.x >= *g).map(|_| 0.0),
                    v_ref: spec.v_ref.unwrap_or(lim.v_max),
                    driver,
                    mode: Mode::Cruise,
                }
            })
            .collect();
        let total_steps = (scenario.duration_s / lim.h).round() as u64;
        Self {
            scenario,
            agents,
            bus,
            lim,
            params,
            findings: Findings::new(),
            t: 0.0,
            steps_done: 0,
            total_steps,
            inbox: Vec::new(),
            truths: Vec::new(),
            fallback_steps: 0,
            waiting_steps: 0,
            planner_steps: 0,
            solved_steps: 0,
            solver_iterations: 0,
            rejected: 0,
            solver,
            seed,
        }
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
        let mut commands = Vec::with_capacity(self.agents.len());
        for a in self.agents.iter_mut() {
            self.inbox.clear();
            self.bus.receive(a.id, t, &mut self.inbox)?;
            let v_cmd = match &mut a.driver {
                Driver::Planner {
                    planner,
                    world,
                    lane_buf,
                } => {
                    for r in &self.inbox {
                        let Message::State(s) = r.msg;
                        if world.update(&s, r.at).is_err() {
                            self.rejected += 1;
                        }
                    }
                    world.lane_vehicles(a.lane, LENGTH_M, lane_buf);
                    let obs = Observation {
                        x: a.x,
                        v_prev: a.v,
                        vehicles: lane_buf,
                        stop_line: self.scenario.road.end_x,
                        target_x: a.goal_x.unwrap_or(0.0),
                        v_ref: a.v_ref,
                    };
                    self.planner_steps += 1;
                    match planner.step(&obs) {
                        Ok(c) => {
                            a.mode = match c.status {
                                StepStatus::Solved { iterations } => {
                                    self.solved_steps += 1;
                                    self.solver_iterations += u64::from(iterations);
                                    Mode::Cruise
                                }
                                StepStatus::Fallback(FallbackReason::NoRoom) => {
                                    self.waiting_steps += 1;
                                    Mode::Waiting
                                }
                                StepStatus::Fallback(_) => {
                                    self.fallback_steps += 1;
                                    Mode::Fallback
                                }
                            };
                            c.v
                        }
                        Err(_) => {
                            self.fallback_steps += 1;
                            a.mode = Mode::Fallback;
                            planner_core::safety::max_braking_command(&self.params, a.v)
                        }
                    }
                }
                Driver::Script(phases) => {
                    let accel = phases
                        .iter()
                        .find(|p| t < p.until_s)
                        .map_or(0.0, |p| p.accel);
                    a.mode = Mode::Cruise;
                    admissible(&self.lim, a.v, accel)
                }
                Driver::Random { rng, accel, until } => {
                    if t >= *until {
                        *accel = rng.random_range(-self.lim.brake..self.lim.a_max);
                        *until = t + rng.random_range(0.2..2.0);
                    }
                    a.mode = Mode::Cruise;
                    admissible(&self.lim, a.v, *accel)
                }
            };
            if a.reached_at.is_some() && a.mode == Mode::Cruise {
                a.mode = Mode::Done;
            }
            commands.push(v_cmd);
            trace(&TraceRow {
                t,
                id: a.id,
                x: a.x,
                y: a.y,
                theta: a.theta,
                v: v_cmd,
                omega: 0.0,
                lane: a.lane,
                target_lane: a.target_lane,
                mode: a.mode,
            });
        }
        // Exact single-lane model (SPEC §2): x⁺ = x + v h.
        for (a, v) in self.agents.iter_mut().zip(commands) {
            a.v_before = a.v;
            a.v = v;
            a.x += v * h;
        }
        self.steps_done += 1;
        self.t = self.steps_done as f64 * h;
        for a in self.agents.iter_mut() {
            if a.reached_at.is_none() && a.goal_x.is_some_and(|g| a.x >= g) {
                a.reached_at = Some(self.t);
            }
        }
        self.truths.clear();
        self.truths.extend(self.agents.iter().map(Agent::truth));
        self.findings
            .check(&self.lim, &self.truths, self.scenario.road.end_x);
        Ok(())
    }

    /// The summary so far.
    pub fn summary(&self, wall_seconds: f64) -> RunSummary {
        let deadline = self.scenario.deadline_s;
        let with_goal: Vec<&Agent<N>> = self.agents.iter().filter(|a| a.goal_x.is_some()).collect();
        let reached: Vec<f64> = with_goal
            .iter()
            .filter_map(|a| a.reached_at)
            .filter(|&t| t <= deadline + 1e-9)
            .collect();
        RunSummary {
            scenario: self.scenario.name.clone(),
            vehicles: self.agents.len(),
            sim_seconds: self.t,
            collisions: self.findings.collisions,
            invariant_violations: self.findings.invariant_violations,
            limit_violations: self.findings.limit_violations,
            road_end_overruns: self.findings.road_end_overruns,
            min_gap_m: self.findings.min_gap_m,
            fallback_steps: self.fallback_steps,
            waiting_steps: self.waiting_steps,
            planner_steps: self.planner_steps,
            solver_iterations_mean: self.solver_iterations as f64 / self.solved_steps.max(1) as f64,
            completed: reached.len() == with_goal.len(),
            goals: with_goal.len(),
            goals_reached: reached.len(),
            last_goal_time_s: reached.iter().copied().reduce(f64::max),
            messages_sent: self.agents.len() as u64 * self.steps_done,
            messages_rejected: self.rejected,
            solver: self.solver,
            seed: self.seed,
            wall_seconds,
        }
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
