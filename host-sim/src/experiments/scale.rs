//! `host-sim scale`: many vehicles at h = 0.01 on all cores, as parallel roads, each on
//! its own in-process bus (V2V range is local: vehicles on different roads do not hear
//! each other). Two kinds of road:
//!
//! - platoons (the default): one lane, a randomly driven leader and planner followers;
//! - traffic (`--traffic`): three lanes, every vehicle a planner with a
//!   random target lane and reference speed, packed at the smallest safe spacing plus
//!   0.5–5 m — lane changes among dense neighbours, the planners' expensive case.
//!
//! Besides the realtime factor, the report gives what a planner step costs in wall-clock
//! time (percentiles over every step of every vehicle) and solves and solver iterations
//! per step. `--sweep` runs the grid of vehicles × threads × kinds for README's table.

use crate::monitor::Limits;
use crate::scenario::road::{Road, RoadScenario, RoadVehicle};
use crate::scenario::DriverKind;
use crate::verdict::{Judged, Safety, Verdict};
use crate::world::cost::{StepCosts, StepPercentiles};
use crate::world::summary::Summary;
use crate::world::vehicle::Counters;
use crate::world::{SolverChoice, World, LENGTH_M, START_MARGIN_M};
use planner_core::ReusePolicy;
use rand::Rng;
use serde::Serialize;

/// The kind of road a scale run is made of.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Kind {
    /// Single-lane platoons behind random leaders.
    Platoons,
    /// Three-lane roads of planners changing lanes to random targets.
    Traffic,
}

/// Lanes of a traffic road.
pub const TRAFFIC_LANES: u8 = 3;

/// The `scale` summary.
#[derive(Debug, Clone, Serialize)]
pub struct ScaleReport {
    /// The kind of road.
    pub kind: Kind,
    /// Vehicles simulated.
    pub vehicles: usize,
    /// Roads (platoons) they were split into.
    pub roads: usize,
    /// Worker threads.
    pub threads: usize,
    /// The planners' speed solver.
    pub solver: SolverChoice,
    /// The invariant every planner keeps toward the vehicle ahead (`paper` or
    /// `leader-aware`).
    pub invariant: &'static str,
    /// Simulated time (s).
    pub sim_seconds: f64,
    /// Wall-clock time (s).
    pub wall_seconds: f64,
    /// sim_seconds / wall_seconds.
    pub realtime_factor: f64,
    /// Planner steps per wall-clock second.
    pub planner_steps_per_second: f64,
    /// Collisions seen by the monitors.
    pub collisions: u64,
    /// Invariant violations seen by the monitors.
    pub invariant_violations: u64,
    /// Limit violations seen by the monitors.
    pub limit_violations: u64,
    /// Smallest bumper-to-bumper gap between two vehicles of a lane (m): how close the
    /// invariant lets followers come.
    pub min_gap_m: f64,
    /// Planner fallback steps (excluding forced standstills).
    pub fallback_steps: u64,
    /// Wall-clock time of one planner step (a vehicle's decide: hear, plan, verify).
    pub step: StepPercentiles,
    /// Steps whose MPC was solved (the rest: standstill, fallback), per planner step.
    pub solves_per_step: f64,
    /// Solver iterations (Newton steps) per planner step.
    pub solver_iterations_per_step: f64,
    /// Of the solved steps, the share the active-set step answered (0 with the
    /// interior-point solver alone).
    pub active_set_share: f64,
    /// Lateral-QP iterations per planner step (lane changes; 0 on platoons).
    pub lateral_iterations_per_step: f64,
    /// Lane changes completed.
    pub lane_changes: u64,
    /// Steps braking under the Yield Protocol (certified braking, no solve).
    pub yield_steps: u64,
    /// Steps standing with no room (no solve).
    pub waiting_steps: u64,
    /// The plan-reuse policy of the run (`null`: every step solved).
    pub reuse: Option<ReuseSettings>,
    /// Steps that applied the previous plan, certified, without a solve, per planner step.
    pub reuses_per_step: f64,
    /// Mean certified bound on the cost given up at a reused step (J(plan) − J* ≤ this).
    pub certified_gap_per_reuse: f64,
    /// The planners' closed-loop cost w_v (v − v_ref)² + w_Δ (v − v_prev)², per planner
    /// step: what reuse gives up, compared across runs.
    pub tracking_cost_per_step: f64,
}

/// A [`ReusePolicy`] as reported.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ReuseSettings {
    /// Certified relative sub-optimality allowed per reused step.
    pub tolerance: f64,
    /// Most consecutive steps without a solve.
    pub max_age: u8,
}

impl From<ReusePolicy<f64>> for ReuseSettings {
    fn from(p: ReusePolicy<f64>) -> Self {
        Self {
            tolerance: p.tolerance,
            max_age: p.max_age,
        }
    }
}

/// One road of the scale run: `n` vehicles, a random leader, planner followers.
pub fn road(index: usize, n: usize, duration_s: f64, seed: u64) -> RoadScenario {
    let lim = Limits::table_i();
    let mut rng = crate::reference::instances::rng(seed ^ (index as u64).wrapping_mul(0x9E37_79B9));
    let mut vehicles = Vec::with_capacity(n);
    let mut x = 0.0;
    for i in 0..n {
        let v = rng.random_range(5.0..lim.v_max);
        if i > 0 {
            x -= LENGTH_M
                + lim.d0
                + lim.safe_distance(v)
                + START_MARGIN_M
                + rng.random_range(0.5..15.0);
        }
        vehicles.push(RoadVehicle {
            cooperative: None,
            length: None,
            brake: None,
            id: i as u16 + 1,
            x,
            lane: 0,
            v,
            target_lane: None,
            driver: if i == 0 {
                DriverKind::Random
            } else {
                DriverKind::Planner
            },
            script: Vec::new(),
            goal_x: None,
            v_ref: None,
        });
    }
    RoadScenario::new(
        format!("scale-road-{index}"),
        duration_s,
        seed.wrapping_add(index as u64),
        Road {
            lanes: 1,
            end_x: None,
        },
        vehicles,
    )
}

/// One road of the traffic run: `n` planners on [`TRAFFIC_LANES`] lanes, dealt to the
/// lanes in turn, each behind the one ahead in its lane at the smallest safe spacing plus
/// 0.5–5 m, at random speeds and reference speeds, each with a random target lane.
pub fn traffic_road(index: usize, n: usize, duration_s: f64, seed: u64) -> RoadScenario {
    let lim = Limits::table_i();
    let mut rng = crate::reference::instances::rng(seed ^ (index as u64).wrapping_mul(0x7AFF_1C5D));
    let mut back = [0.0f64; TRAFFIC_LANES as usize];
    let mut vehicles = Vec::with_capacity(n);
    for i in 0..n {
        let lane = (i % usize::from(TRAFFIC_LANES)) as u8;
        let v = rng.random_range(5.0..0.9 * lim.v_max);
        let slot = &mut back[usize::from(lane)];
        let x = if i < usize::from(TRAFFIC_LANES) {
            rng.random_range(0.0..10.0)
        } else {
            *slot - super::multilane::safe_spacing(v) - rng.random_range(0.5..5.0)
        };
        *slot = x;
        vehicles.push(RoadVehicle {
            cooperative: None,
            length: None,
            brake: None,
            id: i as u16 + 1,
            x,
            lane,
            v,
            target_lane: Some(rng.random_range(0..TRAFFIC_LANES)),
            driver: DriverKind::Planner,
            script: Vec::new(),
            goal_x: None,
            v_ref: Some(rng.random_range(5.0..lim.v_max)),
        });
    }
    RoadScenario::new(
        format!("scale-traffic-{index}"),
        duration_s,
        seed.wrapping_add(index as u64),
        Road {
            lanes: TRAFFIC_LANES,
            end_x: None,
        },
        vehicles,
    )
}

/// A scale run's settings.
#[derive(Debug, Clone, Copy)]
pub struct ScaleSettings {
    /// The kind of road.
    pub kind: Kind,
    /// Vehicles in all.
    pub vehicles: usize,
    /// Simulated seconds.
    pub duration_s: f64,
    /// Vehicles per road.
    pub per_road: usize,
    /// Worker threads (0 = all cores).
    pub threads: usize,
    /// Seed.
    pub seed: u64,
    /// Certified plan reuse in every planner (`None`: solve every step, as before).
    pub reuse: Option<ReusePolicy<f64>>,
    /// The planners' speed solver.
    pub solver: SolverChoice,
    /// The invariant every planner keeps toward the vehicle ahead.
    pub invariant: planner_core::Invariant,
}

/// One road's world run to its end: its summary, counters and step costs.
fn run_road(s: &ScaleSettings, r: usize, n: usize) -> (Summary, Counters, StepCosts) {
    let road = match s.kind {
        Kind::Platoons => road(r, n, s.duration_s, s.seed),
        Kind::Traffic => traffic_road(r, n, s.duration_s, s.seed),
    };
    let mut spec = road.world();
    spec.invariant = s.invariant;
    let mut sim = World::<20>::new(spec, s.solver, None);
    sim.set_reuse(s.reuse);
    sim.measure_step_costs();
    let summary = super::multilane::run_world(&mut sim, &mut |_| {});
    let costs = sim.step_costs().cloned().unwrap_or_default();
    (summary, *sim.counters(), costs)
}

/// Runs the vehicles of `s` on its roads, on its threads.
pub fn run(s: &ScaleSettings) -> ScaleReport {
    let per_road = s.per_road.clamp(2, crate::scenario::road::MAX_VEHICLES);
    let vehicles = s.vehicles;
    let roads: Vec<usize> = (0..vehicles.div_ceil(per_road))
        .map(|r| per_road.min(vehicles - r * per_road))
        .collect();
    let threads = super::par::threads(s.threads);
    let t0 = std::time::Instant::now();
    let runs = super::par::map_indexed(roads.len(), threads, |r| {
        run_road(s, r, roads.get(r).copied().unwrap_or(0))
    });
    let wall = t0.elapsed().as_secs_f64();
    let (mut costs, mut counters) = (StepCosts::default(), Counters::default());
    for (_, c, k) in &runs {
        costs.merge(k);
        counters.add(c);
    }
    let sum = |f: fn(&Summary) -> u64| runs.iter().map(|(s, _, _)| f(s)).sum::<u64>();
    let steps = counters.planner_steps;
    let per_step = |x: u64| x as f64 / steps.max(1) as f64;
    ScaleReport {
        kind: s.kind,
        vehicles,
        roads: roads.len(),
        threads,
        solver: s.solver,
        invariant: crate::world::invariant_name(s.invariant),
        sim_seconds: s.duration_s,
        wall_seconds: wall,
        realtime_factor: s.duration_s / wall,
        planner_steps_per_second: steps as f64 / wall,
        collisions: sum(|s| s.collisions),
        invariant_violations: sum(|s| s.invariant_violations),
        limit_violations: sum(|s| s.limit_violations),
        min_gap_m: runs
            .iter()
            .map(|(s, _, _)| s.min_gap_m)
            .fold(f64::INFINITY, f64::min),
        fallback_steps: sum(|s| s.fallback_steps),
        step: costs.percentiles(),
        solves_per_step: per_step(counters.solved_steps),
        solver_iterations_per_step: per_step(counters.solver_iterations),
        active_set_share: counters.active_set_solves as f64 / counters.solved_steps.max(1) as f64,
        lateral_iterations_per_step: per_step(counters.lateral_iterations),
        lane_changes: sum(|s| s.lane_changes.changes as u64),
        yield_steps: counters.yield_steps,
        waiting_steps: counters.waiting_steps,
        reuse: s.reuse.map(ReuseSettings::from),
        reuses_per_step: per_step(counters.reused_steps),
        certified_gap_per_reuse: counters.certified_gap / counters.reused_steps.max(1) as f64,
        tracking_cost_per_step: counters.tracking_cost / steps.max(1) as f64,
    }
}

impl core::fmt::Display for ScaleReport {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "{} vehicles on {} roads ({:?}, {} invariant), {} threads: {:.1} s simulated in {:.2} s = {:.2}x real time, \
             {:.0} planner steps/s\n  step p50 {:.1} µs, p90 {:.1} µs, p99 {:.1} µs, max {:.0} µs; \
             {:.2} solves ({:.0} % by the active-set step), {:.2} reuses, {:.1} solver iterations, {:.1} lateral iterations per step; {} lane changes\n  \
             closed-loop cost {:.4} per step; certified gap {:.2e} per reuse\n  \
             {} collisions, {} invariant violations, {} limit violations, {} fallback steps; \
             smallest gap {:.3} m",
            self.vehicles,
            self.roads,
            self.kind,
            self.invariant,
            self.threads,
            self.sim_seconds,
            self.wall_seconds,
            self.realtime_factor,
            self.planner_steps_per_second,
            self.step.p50_us,
            self.step.p90_us,
            self.step.p99_us,
            self.step.max_us,
            self.solves_per_step,
            100.0 * self.active_set_share,
            self.reuses_per_step,
            self.solver_iterations_per_step,
            self.lateral_iterations_per_step,
            self.lane_changes,
            self.tracking_cost_per_step,
            self.certified_gap_per_reuse,
            self.collisions,
            self.invariant_violations,
            self.limit_violations,
            self.fallback_steps,
            self.min_gap_m
        )
    }
}

/// `scale --compare`: one world run twice in one process — with the planner as it was
/// before the active-set step (the interior-point method alone, solving every step) and as set up
/// here (its solver, its reuse policy) — and the ratios of the second to the first.
#[derive(Debug, Clone, Serialize)]
pub struct ScaleComparison {
    /// The interior-point solver alone, every step solved.
    pub baseline: ScaleReport,
    /// The run as set up.
    pub current: ScaleReport,
    /// current.planner_steps_per_second / baseline.planner_steps_per_second.
    pub speedup: f64,
    /// current.solver_iterations_per_step / baseline.solver_iterations_per_step.
    pub iterations_ratio: f64,
    /// (current.tracking_cost_per_step − baseline's) / baseline's: the closed-loop cost
    /// given up (negative: none).
    pub tracking_cost_change: f64,
}

/// Runs the baseline and then `base`, on the same roads and seed.
pub fn compare(base: &ScaleSettings) -> ScaleComparison {
    let baseline = run(&ScaleSettings {
        reuse: None,
        solver: SolverChoice::OursInteriorPoint,
        ..*base
    });
    let current = run(base);
    let ratio = |a: f64, b: f64| a / b.max(f64::MIN_POSITIVE);
    ScaleComparison {
        speedup: ratio(
            current.planner_steps_per_second,
            baseline.planner_steps_per_second,
        ),
        iterations_ratio: ratio(
            current.solver_iterations_per_step,
            baseline.solver_iterations_per_step,
        ),
        tracking_cost_change: ratio(
            current.tracking_cost_per_step - baseline.tracking_cost_per_step,
            baseline.tracking_cost_per_step,
        ),
        baseline,
        current,
    }
}

impl core::fmt::Display for ScaleComparison {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        writeln!(
            f,
            "baseline (interior point alone, every step solved):\n  {}",
            self.baseline
        )?;
        writeln!(
            f,
            "current ({:?}):\n  {}",
            self.current.solver, self.current
        )?;
        write!(
            f,
            "current / baseline: {:.2}x planner steps/s, {:.2}x solver iterations per step, \
             closed-loop cost {:+.3} %",
            self.speedup,
            self.iterations_ratio,
            100.0 * self.tracking_cost_change
        )
    }
}

/// `scale --sweep`: every kind of road at each count of vehicles on each count of
/// threads, in one run (README's table and plot).
#[derive(Debug, Clone, Serialize)]
pub struct ScaleSweep {
    /// Simulated seconds per run.
    pub sim_seconds: f64,
    /// Planner steps per second that real time needs per vehicle (1 / h).
    pub steps_per_vehicle_second: f64,
    /// One report per kind, vehicle count and thread count.
    pub runs: Vec<ScaleReport>,
}

/// Runs `base` for each kind, each of `vehicles` and each of `threads`.
pub fn sweep(base: &ScaleSettings, vehicles: &[usize], threads: &[usize]) -> ScaleSweep {
    let mut runs = Vec::new();
    for kind in [Kind::Platoons, Kind::Traffic] {
        for &n in vehicles {
            for &t in threads {
                runs.push(run(&ScaleSettings {
                    kind,
                    vehicles: n,
                    threads: t,
                    ..*base
                }));
            }
        }
    }
    ScaleSweep {
        sim_seconds: base.duration_s,
        steps_per_vehicle_second: 1.0 / Limits::table_i().h,
        runs,
    }
}

impl core::fmt::Display for ScaleSweep {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        writeln!(
            f,
            "| roads | vehicles | threads | planner steps/s | × real time | step p50 µs | step p99 µs | solves/step | iterations/step |"
        )?;
        writeln!(f, "|---|---|---|---|---|---|---|---|---|")?;
        for r in &self.runs {
            writeln!(
                f,
                "| {:?} | {} | {} | {:.0} | {:.2} | {:.1} | {:.1} | {:.2} | {:.1} |",
                r.kind,
                r.vehicles,
                r.threads,
                r.planner_steps_per_second,
                r.realtime_factor,
                r.step.p50_us,
                r.step.p99_us,
                r.solves_per_step,
                r.solver_iterations_per_step
            )?;
        }
        Ok(())
    }
}

impl Judged for ScaleReport {
    /// Collisions, invariant and limit violations; a scale run has no goal but safety.
    fn verdict(&self) -> Verdict {
        let s = Safety::of(
            self.collisions,
            self.invariant_violations,
            self.limit_violations,
            0,
        );
        Verdict::new(s, true)
    }
}

impl Judged for ScaleComparison {
    /// Both runs'.
    fn verdict(&self) -> Verdict {
        self.baseline.verdict().and(self.current.verdict())
    }
}

impl Judged for ScaleSweep {
    /// Every run's.
    fn verdict(&self) -> Verdict {
        self.runs
            .iter()
            .map(Judged::verdict)
            .fold(Verdict::new(Safety::default(), true), Verdict::and)
    }
}
