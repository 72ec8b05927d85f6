//! `host-sim scale`: many vehicles at h = 0.01 on all cores, as parallel single-lane
//! roads, each a platoon behind a randomly driven leader on its own in-process bus (V2V
//! range is local: vehicles on different roads do not hear each other).

use crate::monitor::Limits;
use crate::scenario::road::{Road, RoadScenario, RoadVehicle};
use crate::scenario::DriverKind;
use crate::world::summary::Summary;
use crate::world::{SolverChoice, World, LENGTH_M, START_MARGIN_M};
use rand::Rng;
use serde::Serialize;

/// The `scale` summary.
#[derive(Debug, Clone, Serialize)]
pub struct ScaleReport {
    /// Vehicles simulated.
    pub vehicles: usize,
    /// Roads (platoons) they were split into.
    pub roads: usize,
    /// Worker threads.
    pub threads: usize,
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
    /// Planner fallback steps (excluding forced standstills).
    pub fallback_steps: u64,
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

/// Runs `vehicles` vehicles for `duration_s` on `threads` threads (0 = all cores).
pub fn run(
    vehicles: usize,
    duration_s: f64,
    platoon: usize,
    threads: usize,
    seed: u64,
) -> ScaleReport {
    let platoon = platoon.clamp(2, crate::scenario::road::MAX_VEHICLES);
    let roads: Vec<usize> = (0..vehicles.div_ceil(platoon))
        .map(|r| platoon.min(vehicles - r * platoon))
        .collect();
    let threads = super::par::threads(threads);
    let t0 = std::time::Instant::now();
    let sums = super::par::map_indexed(roads.len(), threads, |r| {
        let n = roads.get(r).copied().unwrap_or(0);
        let world = road(r, n, duration_s, seed).world();
        let mut sim = World::<20>::new(world, SolverChoice::Ours, None);
        while !sim.finished() {
            if sim.step(&mut |_| {}).is_err() {
                break;
            }
        }
        sim.summary(0.0)
    });
    let wall = t0.elapsed().as_secs_f64();
    let sum = |f: fn(&Summary) -> u64| sums.iter().map(f).sum::<u64>();
    let (steps, col, inv, lim, fb) = (
        sum(|s| s.planner_steps),
        sum(|s| s.collisions),
        sum(|s| s.invariant_violations),
        sum(|s| s.limit_violations),
        sum(|s| s.fallback_steps),
    );
    ScaleReport {
        vehicles,
        roads: roads.len(),
        threads,
        sim_seconds: duration_s,
        wall_seconds: wall,
        realtime_factor: duration_s / wall,
        planner_steps_per_second: steps as f64 / wall,
        collisions: col,
        invariant_violations: inv,
        limit_violations: lim,
        fallback_steps: fb,
    }
}

impl core::fmt::Display for ScaleReport {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "{} vehicles on {} roads, {} threads: {:.1} s simulated in {:.2} s = {:.2}x real time, \
             {:.0} planner steps/s\n  {} collisions, {} invariant violations, {} limit violations, \
             {} fallback steps",
            self.vehicles,
            self.roads,
            self.threads,
            self.sim_seconds,
            self.wall_seconds,
            self.realtime_factor,
            self.planner_steps_per_second,
            self.collisions,
            self.invariant_violations,
            self.limit_violations,
            self.fallback_steps
        )
    }
}
