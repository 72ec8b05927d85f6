//! Multi-lane traffic (Sec. IV–V): the paper's experiment of Fig. 6/7 (SPEC §8), random
//! traffic for Theorem 2 (its sweep: [`super::traffic`]), and the dead-end layout of
//! Theorem 3.

use super::experiment::{Experiment, RunError, SettingsError};
use super::flags::{self, FaultFlags};
use super::shard::{MergeError, Runs};
use crate::bus::Faults;
use crate::monitor::Limits;
use crate::scenario::road::{commitment_bound, Road, RoadScenario, RoadVehicle};
use crate::scenario::DriverKind;
use crate::verdict::{Judged, Safety, Verdict};
use crate::world::summary::Summary;
use crate::world::{Body, SolverChoice, TraceRow, World, START_MARGIN_M};
use planner_core::Invariant;
use rand::Rng;
use serde::{Deserialize, Serialize};

/// `experiment multilane`'s settings: what every run shares (its flags; a shard's header
/// carries them for `host-sim merge`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, clap::Args)]
pub struct MultilaneSettings {
    /// Number of runs (seeds from --seed).
    #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u64).range(1..))]
    pub seeds: u64,
    /// First seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The planners' solver.
    #[arg(long, default_value = "ours", value_parser = flags::solver())]
    pub solver: SolverChoice,
    /// Faults of the bus.
    #[command(flatten)]
    pub faults: FaultFlags,
    /// The invariant every planner keeps toward the vehicle ahead.
    // A shard header of an older version has none: the paper's.
    #[arg(long, default_value = crate::world::DEFAULT_INVARIANT_NAME, value_parser = flags::invariant())]
    #[serde(default, with = "crate::world::invariant_serde")]
    pub invariant: Invariant,
}

impl Experiment for MultilaneSettings {
    const NAME: &'static str = "multilane";
    type Part = Runs<MultilaneCase>;
    type Report = MultilaneReport;

    fn validate(&self) -> Result<(), SettingsError> {
        self.faults.validate()
    }

    fn cases(&self) -> u64 {
        self.seeds
    }

    fn run(&self, range: (u64, u64), threads: usize) -> Result<Self::Part, RunError> {
        Ok(Runs::timed(|| multilane_cases(self, range, threads)))
    }

    fn report(&self, parts: Vec<Self::Part>) -> Result<MultilaneReport, MergeError> {
        let all = Runs::concat(parts);
        Ok(multilane_report(&all.runs, self, all.wall_seconds))
    }
}

impl Judged for MultilaneReport {
    /// Collisions, invariant and limit violations; live when every run completed its
    /// lane changes.
    fn verdict(&self) -> Verdict {
        let safety = Safety::of(
            self.collisions,
            self.invariant_violations,
            self.limit_violations,
            0,
        );
        Verdict::new(safety, self.completed == self.runs)
    }
}

/// The paper's speed v0 in the multi-lane experiment (m/s).
pub const V0: f64 = 15.0;
/// How long each multi-lane run is simulated (s).
pub const EXPERIMENT_DURATION_S: f64 = 30.0;

/// The smallest extent-adjusted spacing at which a follower at `v` keeps the invariant
/// with the scenario start margin: L + d0 + dS(v) + margin (centre to centre).
pub fn safe_spacing(v: f64) -> f64 {
    spacing(v, Body::CAR, Body::CAR)
}

/// [`safe_spacing`] for a follower of `body` at `v` behind a leader of `lead`: half of
/// each length, d0, dS at the follower's own limit, the margin.
pub fn spacing(v: f64, lead: Body, body: Body) -> f64 {
    let lim = Limits::table_i();
    0.5 * (lead.length + body.length)
        + lim.d0
        + lim.safe_distance_at(v, body.brake)
        + START_MARGIN_M
}

/// The paper's multi-lane experiment (SPEC §8): 3 lanes, 2 vehicles per lane spaced by
/// the smallest safe gap, all at v0 = 15 m/s, each with a random target lane.
pub fn paper_scenario(seed: u64) -> RoadScenario {
    let mut rng = crate::reference::instances::rng(seed ^ 0x6d75_6c74_696c_616e);
    let spacing = safe_spacing(V0);
    let mut vehicles = Vec::new();
    for lane in 0..3u8 {
        for (i, x) in [spacing, 0.0].into_iter().enumerate() {
            vehicles.push(RoadVehicle {
                cooperative: None,
                length: None,
                brake: None,
                id: u16::from(lane) * 2 + i as u16 + 1,
                x,
                lane,
                v: V0,
                target_lane: Some(rng.random_range(0..3u8)),
                driver: DriverKind::Planner,
                script: Vec::new(),
                goal_x: None,
                v_ref: Some(V0),
            });
        }
    }
    RoadScenario::new(
        format!("multilane-{seed}"),
        EXPERIMENT_DURATION_S,
        seed,
        Road {
            lanes: 3,
            end_x: None,
        },
        vehicles,
    )
}

/// Random traffic for Theorem 2: 3–4 lanes, 5–`max_vehicles` planner-driven vehicles at
/// random safe spacings and speeds, random reference speeds and random target lanes.
pub fn random_traffic(seed: u64, max_vehicles: usize, duration_s: f64) -> RoadScenario {
    random_mixed_traffic(seed, max_vehicles, duration_s, 0)
}

/// [`random_traffic`] with `trucks_percent` of its vehicles trucks
/// ([`crate::world::Body::TRUCK`]), each drawn at random; each follower starts at the
/// smallest safe spacing behind its leader for both bodies and its own braking limit, or
/// up to 30 m more. With 0 the cases are [`random_traffic`]'s as they always were (no
/// draw is added).
pub fn random_mixed_traffic(
    seed: u64,
    max_vehicles: usize,
    duration_s: f64,
    trucks_percent: u8,
) -> RoadScenario {
    let lim = Limits::table_i();
    let mut rng = crate::reference::instances::rng(seed ^ 0x7468_656f_7265_6d32);
    let lanes: u8 = rng.random_range(3..=4);
    let n = rng.random_range(5..=max_vehicles.max(5));
    // Per lane, the last placed vehicle (x, its body): new ones go behind it.
    let mut back: Vec<Option<(f64, Body)>> = vec![None; usize::from(lanes)];
    let mut vehicles = Vec::with_capacity(n);
    for i in 0..n {
        let lane = rng.random_range(0..lanes);
        let v = rng.random_range(0.0..0.9 * lim.v_max);
        let truck = trucks_percent > 0 && rng.random_range(0..100u8) < trucks_percent;
        let body = if truck { Body::TRUCK } else { Body::CAR };
        let slot = &mut back[usize::from(lane)];
        let x = match *slot {
            None => rng.random_range(0.0..60.0),
            Some((xl, lead)) => xl - spacing(v, lead, body) - rng.random_range(0.0..30.0),
        };
        *slot = Some((x, body));
        vehicles.push(RoadVehicle {
            cooperative: None,
            id: i as u16 + 1,
            x,
            lane,
            v,
            target_lane: Some(rng.random_range(0..lanes)),
            driver: DriverKind::Planner,
            script: Vec::new(),
            goal_x: None,
            v_ref: Some(rng.random_range(3.0..lim.v_max)),
            length: truck.then_some(body.length),
            brake: truck.then_some(body.brake),
        });
    }
    RoadScenario::new(
        format!("random-traffic-{seed}"),
        duration_s,
        seed,
        Road { lanes, end_x: None },
        vehicles,
    )
}

/// The `experiment multilane` result.
#[derive(Debug, Clone, Serialize)]
pub struct MultilaneReport {
    /// Runs (seeds).
    pub runs: u64,
    /// Collisions over all runs (pairs × steps).
    pub collisions: u64,
    /// Invariant violations over all runs.
    pub invariant_violations: u64,
    /// Runs in which every vehicle reached its target lane.
    pub completed: u64,
    /// Latest time by which all lane changes of a run were done (s).
    pub max_completion_time_s: f64,
    /// Mean over runs of that time (s).
    pub mean_completion_time_s: f64,
    /// Longest x-distance from declaring an intention to completing the change (m).
    pub max_lane_change_distance_m: f64,
    /// The commitment distance (23) for the vehicle needing the most changes, at v0,
    /// largest over runs (m).
    pub bound_m: f64,
    /// Lane changes completed.
    pub lane_changes: u64,
    /// Limit violations (speed, acceleration, heading) and road departures.
    pub limit_violations: u64,
    /// Planner steps that applied the certified fallback (not yield, not standstill).
    pub fallback_steps: u64,
    /// Planner steps braking under the Yield Protocol.
    pub yield_steps: u64,
    /// Planner steps.
    pub planner_steps: u64,
    /// Solver.
    pub solver: SolverChoice,
    /// Faults the bus injected.
    pub faults: Faults,
    /// The invariant every planner kept toward the vehicle ahead.
    #[serde(with = "crate::world::invariant_serde")]
    pub invariant: Invariant,
    /// Wall-clock time (s).
    pub wall_seconds: f64,
}

/// Runs one world to the end (horizon 20) on the in-process bus and returns its summary.
pub fn run_one(
    world: crate::world::WorldSpec,
    solver: SolverChoice,
    trace: &mut dyn FnMut(&TraceRow),
) -> Summary {
    run_world(&mut World::<20>::new(world, solver, None), trace)
}

/// Runs `w` to its end and returns its summary (its counters stay in `w`).
pub fn run_world(w: &mut World<20>, trace: &mut dyn FnMut(&TraceRow)) -> Summary {
    let t0 = std::time::Instant::now();
    while !w.finished() {
        // The in-process bus cannot fail.
        if w.step(trace).is_err() {
            break;
        }
    }
    w.summary(t0.elapsed().as_secs_f64())
}

/// One multi-lane run: what [`multilane_report`] needs of it. A shard of
/// `experiment multilane` prints these, and `host-sim merge` aggregates them as the
/// unsharded run does, so the merged report is the unsharded one.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct MultilaneCase {
    /// The run's seed.
    pub seed: u64,
    /// Collisions (pairs × steps).
    pub collisions: u64,
    /// Invariant violations.
    pub invariant_violations: u64,
    /// When every lane change was done, if all were (s).
    pub done_at_s: Option<f64>,
    /// Longest x-distance from intention to completed change (m).
    pub max_distance_m: f64,
    /// The commitment distance (23) of the vehicle needing most changes, at v0 (m).
    pub bound_m: f64,
    /// Lane changes completed.
    pub lane_changes: u64,
    /// Limit violations and road departures.
    pub limit_violations: u64,
    /// Certified-fallback steps.
    pub fallback_steps: u64,
    /// Yield steps.
    pub yield_steps: u64,
    /// Planner steps.
    pub planner_steps: u64,
}

/// Runs the paper's experiment for the runs `first..end` (seed `s.seed + i` for run i:
/// a run depends on its index alone).
pub fn multilane_cases(
    s: &MultilaneSettings,
    (first, end): (u64, u64),
    threads: usize,
) -> Vec<MultilaneCase> {
    let (solver, faults) = (s.solver, s.faults.faults());
    super::par::map_indexed(end.saturating_sub(first) as usize, threads, |i| {
        let seed = s.seed + first + i as u64;
        let sc = paper_scenario(seed);
        let bound_m = (0..sc.vehicles.len())
            .filter_map(|k| commitment_bound(&sc.vehicles, &sc.road, k, V0))
            .fold(0.0, f64::max);
        let mut world = sc.world();
        world.faults = faults;
        world.sensing = (!faults.is_none()).then(planner_core::Sensing::radar);
        world.invariant = s.invariant;
        let s = run_one(world, solver, &mut |_| {});
        MultilaneCase {
            seed,
            collisions: s.collisions,
            invariant_violations: s.invariant_violations,
            done_at_s: s.lane_changes.all_done_at_s,
            max_distance_m: s.lane_changes.max_distance_m,
            bound_m,
            lane_changes: s.lane_changes.changes as u64,
            limit_violations: s.limit_violations + s.off_road,
            fallback_steps: s.fallback_steps,
            yield_steps: s.yield_steps,
            planner_steps: s.planner_steps,
        }
    })
}

/// The report over `cases` (in run order).
pub fn multilane_report(
    cases: &[MultilaneCase],
    s: &MultilaneSettings,
    wall_seconds: f64,
) -> MultilaneReport {
    let times: Vec<f64> = cases.iter().filter_map(|c| c.done_at_s).collect();
    let sum = |f: fn(&MultilaneCase) -> u64| cases.iter().map(f).sum::<u64>();
    let max = |f: fn(&MultilaneCase) -> f64| cases.iter().map(f).fold(0.0, f64::max);
    MultilaneReport {
        runs: cases.len() as u64,
        collisions: sum(|c| c.collisions),
        invariant_violations: sum(|c| c.invariant_violations),
        completed: times.len() as u64,
        max_completion_time_s: times.iter().copied().fold(0.0, f64::max),
        mean_completion_time_s: times.iter().fold(0.0, |a, t| a + t) / times.len().max(1) as f64,
        max_lane_change_distance_m: max(|c| c.max_distance_m),
        bound_m: max(|c| c.bound_m),
        lane_changes: sum(|c| c.lane_changes),
        limit_violations: sum(|c| c.limit_violations),
        fallback_steps: sum(|c| c.fallback_steps),
        yield_steps: sum(|c| c.yield_steps),
        planner_steps: sum(|c| c.planner_steps),
        solver: s.solver,
        faults: s.faults.faults(),
        invariant: s.invariant,
        wall_seconds,
    }
}

impl core::fmt::Display for MultilaneReport {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "multi-lane experiment (Fig. 6/7): {} runs, {} lane changes in {:.1} s ({:?} solver)\n  \
             {} collisions, {} invariant violations, {} limit violations\n  \
             {} of {} runs with every vehicle in its target lane; all done by {:.2} s at the latest \
             (mean {:.2} s); longest change {:.1} m against the commitment distance (23) {:.1} m\n  \
             fallback steps {}, yield steps {} of {} planner steps",
            self.runs,
            self.lane_changes,
            self.wall_seconds,
            self.solver,
            self.collisions,
            self.invariant_violations,
            self.limit_violations,
            self.completed,
            self.runs,
            self.max_completion_time_s,
            self.mean_completion_time_s,
            self.max_lane_change_distance_m,
            self.bound_m,
            self.fallback_steps,
            self.yield_steps,
            self.planner_steps
        )
    }
}
