//! The Theorem 2 sweep: random multi-lane traffic ([`super::multilane::random_traffic`]),
//! every vehicle its own planner on the bus, judged by the independent monitor — and,
//! with `--compare`, what the planner as configured gives up against solving every step.
//!
//! The comparison runs every case twice on the same seeds: once with the planner as
//! configured (the default solver, whose warm starts go through the active-set step, and
//! certified plan reuse if asked), once as the *every-step* baseline — the interior-point
//! method alone ([`planner_core::Settings::interior_point_only`]), a solve at every step,
//! no reuse: the planner as it was before its active-set step. Both are closed loops, so the two
//! runs' trajectories may part; what is compared is the closed-loop cost the planners
//! minimise, Σ over planner steps of w_v (v − v_ref)² + w_Δ (v − v_prev)² with the
//! default weights (Eq. 10's stage cost), per planner step. Without reuse both solvers
//! stop at the same tolerance, so the change is rounding; with reuse it is bounded per
//! reused step by the Lagrangian-dual certificate ([`planner_core::reuse`]).

use super::experiment::{duration_within, Experiment, RunError, SettingsError};
use super::multilane::{random_mixed_traffic, run_world};
use super::shard::{combine_all, MergeError};
use crate::verdict::{Judged, Safety, Verdict};
use crate::world::summary::Summary;
use crate::world::vehicle::Counters;
use crate::world::{SolverChoice, World};
use serde::{Deserialize, Serialize};

/// `host-sim traffic`: its cases, seed and duration, and how the planners solve (a
/// shard's header leaves out the paper's invariant and a plain run's `compare`, as
/// shards always had them).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, clap::Args)]
pub struct Traffic {
    /// Number of random cases.
    #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u64).range(1..))]
    pub cases: u64,
    /// Seed of the first case.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Simulated seconds per case.
    #[arg(long, default_value_t = 20.0)]
    pub duration: f64,
    /// The planners reuse their certified previous plan instead of solving every step
    /// (planner-core's `ReusePolicy::default()`).
    #[arg(long)]
    pub reuse: bool,
    /// The invariant every planner keeps toward the vehicle ahead.
    #[arg(long, default_value = crate::world::DEFAULT_INVARIANT_NAME, value_parser = super::flags::invariant())]
    #[serde(
        default,
        skip_serializing_if = "super::flags::is_paper",
        with = "crate::world::invariant_serde"
    )]
    pub invariant: planner_core::Invariant,
    /// Also run every case with the interior-point method alone, solving every step (the
    /// planner before the active-set step), and report the closed-loop cost given up against it.
    #[arg(long)]
    #[serde(default, skip_serializing_if = "core::ops::Not::not")]
    pub compare: bool,
    /// Percent of the vehicles that are trucks (16.5 m, braking at 4.5 m/s²), drawn per
    /// vehicle; 0 gives the cases as they always were.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u8).range(0..=100))]
    #[serde(default, skip_serializing_if = "super::flags::is_zero")]
    pub trucks: u8,
}

/// What `traffic` reports: the sweep, or with `--compare` the comparison (each written
/// as itself).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(untagged)]
pub enum TrafficOutcome {
    /// With `--compare`.
    Compared(TrafficComparison),
    /// The sweep.
    Plain(TrafficReport),
}

impl Experiment for Traffic {
    const NAME: &'static str = "traffic";
    type Part = TrafficOutcome;
    type Report = TrafficOutcome;

    fn validate(&self) -> Result<(), SettingsError> {
        duration_within(self.duration, 3600.0)
    }

    fn cases(&self) -> u64 {
        self.cases
    }

    fn run(&self, (first, end): (u64, u64), threads: usize) -> Result<TrafficOutcome, RunError> {
        let planning = Planning {
            reuse: self.reuse,
            leader_aware: self.invariant == planner_core::Invariant::LeaderAware,
            trucks_percent: self.trucks,
            ..Planning::DEFAULT
        };
        // Case i's seed is seed + i: it depends on the index alone.
        let (cases, seed) = (end - first, self.seed + first);
        if self.compare {
            let c = traffic_compare(cases, seed, self.duration, threads, planning);
            Ok(TrafficOutcome::Compared(c))
        } else {
            let r = traffic_sweep_with(cases, seed, self.duration, threads, planning);
            Ok(TrafficOutcome::Plain(r))
        }
    }

    /// Sums field by field; a comparison's ratios are computed once, from the sums (a sum
    /// of the parts' ratios would mean nothing).
    fn report(&self, parts: Vec<TrafficOutcome>) -> Result<TrafficOutcome, MergeError> {
        let mut plain = Vec::new();
        let (mut current, mut every_step) = (Vec::new(), Vec::new());
        for p in parts {
            match p {
                TrafficOutcome::Plain(r) => plain.push(r),
                TrafficOutcome::Compared(c) => {
                    current.push(c.current);
                    every_step.push(c.every_step);
                }
            }
        }
        match (self.compare, plain.is_empty(), current.is_empty()) {
            (false, _, true) => combine_all(plain).map(TrafficOutcome::Plain),
            (true, true, _) => Ok(TrafficOutcome::Compared(TrafficComparison::of(
                combine_all(current)?,
                combine_all(every_step)?,
            ))),
            _ => Err(MergeError::Shape(
                "traffic parts with and without --compare".into(),
            )),
        }
    }
}

impl Judged for TrafficOutcome {
    /// Collisions, invariant and limit violations (of both sweeps, compared); the sweep
    /// has no goal but safety.
    fn verdict(&self) -> Verdict {
        let safety = match self {
            TrafficOutcome::Plain(r) => r.safety(),
            TrafficOutcome::Compared(c) => c.current.safety() + c.every_step.safety(),
        };
        Verdict::new(safety, true)
    }
}

impl core::fmt::Display for TrafficOutcome {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            TrafficOutcome::Plain(r) => r.fmt(f),
            TrafficOutcome::Compared(c) => c.fmt(f),
        }
    }
}

/// A ratio written `null` (JSON has no NaN): undefined.
fn null_as_nan<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// How a sweep's planners solve.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Planning {
    /// The solver.
    pub solver: SolverChoice,
    /// Certified plan reuse ([`planner_core::ReusePolicy::default`]) on.
    pub reuse: bool,
    /// The leader-aware invariant ([`planner_core::Invariant::LeaderAware`]) instead of
    /// the paper's.
    #[serde(default)]
    pub leader_aware: bool,
    /// Percent of the vehicles that are trucks ([`crate::world::Body::TRUCK`]).
    #[serde(default)]
    pub trucks_percent: u8,
}

impl Planning {
    /// The planner as shipped: the default solver, every step solved.
    pub const DEFAULT: Self = Self {
        solver: SolverChoice::Ours,
        reuse: false,
        leader_aware: false,
        trucks_percent: 0,
    };
    /// The every-step baseline: the interior-point method alone, no reuse.
    pub const EVERY_STEP: Self = Self {
        solver: SolverChoice::OursInteriorPoint,
        reuse: false,
        leader_aware: false,
        trucks_percent: 0,
    };
}

/// The Theorem 2 sweep's result.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TrafficReport {
    /// Cases.
    pub cases: u64,
    /// Vehicles over all cases.
    pub vehicles: u64,
    /// Collisions.
    pub collisions: u64,
    /// Invariant violations.
    pub invariant_violations: u64,
    /// Limit violations and road departures.
    pub limit_violations: u64,
    /// Lane changes completed.
    pub lane_changes: u64,
    /// Vehicles in their target lane at the end.
    pub in_target_lane: u64,
    /// Certified-fallback steps (not yield, not standstill).
    pub fallback_steps: u64,
    /// Yield steps.
    pub yield_steps: u64,
    /// Planner steps.
    pub planner_steps: u64,
    /// Of those, steps that applied a certified previous plan without a solve.
    pub reused_steps: u64,
    /// Planner steps that solved.
    pub solved_steps: u64,
    /// Solver iterations of those (every Newton step).
    pub solver_iterations: u64,
    /// Of the solved steps, those the active-set step answered.
    pub active_set_solves: u64,
    /// The planners' closed-loop cost: Σ over planner steps of
    /// w_v (v − v_ref)² + w_Δ (v − v_prev)², default weights.
    pub tracking_cost: f64,
    /// Seeds of cases with a collision or violation (for replay).
    pub failing_seeds: Vec<u64>,
    /// Wall-clock time (s).
    pub wall_seconds: f64,
}

impl TrafficReport {
    /// Its findings: collisions, invariant and limit (or road) violations.
    pub fn safety(&self) -> Safety {
        Safety::of(
            self.collisions,
            self.invariant_violations,
            self.limit_violations,
            0,
        )
    }

    /// No collision, no invariant, limit or road violation.
    pub fn safe(&self) -> bool {
        self.safety().is_safe()
    }

    /// The closed-loop cost per planner step.
    pub fn tracking_cost_per_step(&self) -> f64 {
        self.tracking_cost / self.planner_steps.max(1) as f64
    }

    /// Solver iterations per solved step.
    pub fn iterations_per_solve(&self) -> f64 {
        self.solver_iterations as f64 / self.solved_steps.max(1) as f64
    }

    /// Solver iterations per planner step (reused and unsolved steps count as none).
    pub fn iterations_per_step(&self) -> f64 {
        self.solver_iterations as f64 / self.planner_steps.max(1) as f64
    }
}

/// One case run to its end: its summary and the planners' counters.
fn run_case(seed: u64, duration_s: f64, planning: Planning) -> (Summary, Counters) {
    let mut spec = random_mixed_traffic(seed, 30, duration_s, planning.trucks_percent).world();
    if planning.leader_aware {
        spec.invariant = planner_core::Invariant::LeaderAware;
    }
    let mut w = World::<20>::new(spec, planning.solver, None);
    w.set_reuse(planning.reuse.then(planner_core::ReusePolicy::default));
    let summary = run_world(&mut w, &mut |_| {});
    (summary, *w.counters())
}

/// Theorem 2 sweep with the planner as shipped; with `reuse`, the planners reuse
/// certified plans ([`planner_core::ReusePolicy::default`]).
pub fn traffic_sweep(
    cases: u64,
    first_seed: u64,
    duration_s: f64,
    threads: usize,
    reuse: bool,
) -> TrafficReport {
    let planning = Planning {
        reuse,
        ..Planning::DEFAULT
    };
    traffic_sweep_with(cases, first_seed, duration_s, threads, planning)
}

/// Theorem 2 sweep: `cases` random-traffic cases, case i on seed `first_seed + i`,
/// `threads` at once (0: one per core), every planner as `planning` says.
pub fn traffic_sweep_with(
    cases: u64,
    first_seed: u64,
    duration_s: f64,
    threads: usize,
    planning: Planning,
) -> TrafficReport {
    let t0 = std::time::Instant::now();
    let results = super::par::map_indexed(cases as usize, threads, |i| {
        let seed = first_seed + i as u64;
        let (s, c) = run_case(seed, duration_s, planning);
        (seed, s, c)
    });
    let sum =
        |f: fn(&Summary, &Counters) -> u64| results.iter().map(|(_, s, c)| f(s, c)).sum::<u64>();
    TrafficReport {
        cases,
        vehicles: sum(|s, _| s.vehicles as u64),
        collisions: sum(|s, _| s.collisions),
        invariant_violations: sum(|s, _| s.invariant_violations),
        limit_violations: sum(|s, _| s.limit_violations + s.off_road),
        lane_changes: sum(|s, _| s.lane_changes.changes as u64),
        in_target_lane: sum(|s, _| s.lane_changes.in_target_lane as u64),
        fallback_steps: sum(|s, _| s.fallback_steps),
        yield_steps: sum(|s, _| s.yield_steps),
        planner_steps: sum(|s, _| s.planner_steps),
        reused_steps: sum(|s, _| s.reused_steps),
        solved_steps: sum(|_, c| c.solved_steps),
        solver_iterations: sum(|_, c| c.solver_iterations),
        active_set_solves: sum(|_, c| c.active_set_solves),
        tracking_cost: results.iter().map(|(_, _, c)| c.tracking_cost).sum(),
        failing_seeds: results
            .iter()
            .filter(|(_, s, _)| s.collisions + s.invariant_violations > 0)
            .map(|(seed, _, _)| *seed)
            .collect(),
        wall_seconds: t0.elapsed().as_secs_f64(),
    }
}

/// `traffic --compare`: the same cases with the planner as configured and with the
/// every-step baseline, and what the first gives up against the second.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TrafficComparison {
    /// The planner as configured.
    pub current: TrafficReport,
    /// The interior-point method alone, every step solved, no reuse.
    pub every_step: TrafficReport,
    /// (current's closed-loop cost per step − every_step's) / every_step's.
    #[serde(deserialize_with = "null_as_nan")]
    pub cost_given_up: f64,
    /// current's solver iterations per planner step over every_step's.
    #[serde(deserialize_with = "null_as_nan")]
    pub iterations_ratio: f64,
}

impl TrafficComparison {
    /// The comparison of two sweeps over the same cases.
    pub fn of(current: TrafficReport, every_step: TrafficReport) -> Self {
        let base = every_step.tracking_cost_per_step();
        Self {
            cost_given_up: (current.tracking_cost_per_step() - base) / base,
            iterations_ratio: current.iterations_per_step() / every_step.iterations_per_step(),
            current,
            every_step,
        }
    }

    /// Both sweeps safe.
    pub fn safe(&self) -> bool {
        self.current.safe() && self.every_step.safe()
    }
}

/// Runs the every-step baseline and then `planning` over the same cases.
pub fn traffic_compare(
    cases: u64,
    first_seed: u64,
    duration_s: f64,
    threads: usize,
    planning: Planning,
) -> TrafficComparison {
    let every_step = traffic_sweep_with(
        cases,
        first_seed,
        duration_s,
        threads,
        Planning {
            leader_aware: planning.leader_aware,
            ..Planning::EVERY_STEP
        },
    );
    let current = traffic_sweep_with(cases, first_seed, duration_s, threads, planning);
    TrafficComparison::of(current, every_step)
}

impl core::fmt::Display for TrafficReport {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "Theorem 2: {} random multi-lane cases, {} vehicles in {:.1} s\n  \
             {} collisions, {} invariant violations, {} limit violations\n  \
             {} lane changes; {} of {} vehicles in their target lane at the end\n  \
             fallback steps {}, yield steps {}, certified plan reuses {} of {} planner steps\n  \
             {:.2} solver iterations per solve ({:.1} % by the active-set step); \
             closed-loop cost {:.4} per step",
            self.cases,
            self.vehicles,
            self.wall_seconds,
            self.collisions,
            self.invariant_violations,
            self.limit_violations,
            self.lane_changes,
            self.in_target_lane,
            self.vehicles,
            self.fallback_steps,
            self.yield_steps,
            self.reused_steps,
            self.planner_steps,
            self.iterations_per_solve(),
            100.0 * self.active_set_solves as f64 / self.solved_steps.max(1) as f64,
            self.tracking_cost_per_step(),
        )?;
        if !self.failing_seeds.is_empty() {
            write!(f, "\n  failing seeds: {:?}", self.failing_seeds)?;
        }
        Ok(())
    }
}

impl core::fmt::Display for TrafficComparison {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        writeln!(
            f,
            "every step solved (interior point alone, no reuse):\n  {}",
            self.every_step
        )?;
        writeln!(f, "as configured:\n  {}", self.current)?;
        write!(
            f,
            "cost given up against solving every step: {:+.4} % of the closed-loop cost; \
             {:.2}x the solver iterations per planner step",
            100.0 * self.cost_given_up,
            self.iterations_ratio
        )
    }
}
