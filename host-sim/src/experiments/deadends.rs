//! `host-sim deadends`: Theorem 3 as a randomized sweep. Random dead-end roads — 2 to 5
//! lanes, 4 to 40 vehicles at random speeds (0 to vmax) and spacings (from the smallest
//! safe gap up), random target lanes (one or several lanes over in either direction, and
//! in a quarter of the cases everyone wanting the same lane) — with the road end placed
//! beyond every vehicle's commitment distance (23) at the start, as the loader requires.
//! A case ends once every vehicle is in its target lane and stopped; it fails on any
//! collision or violation, a vehicle not in its lane, or a deadlock.

use super::experiment::{Experiment, RunError};
use super::multilane::spacing;
use super::shard::{combine_all, MergeError};
use super::sweep::{self, case_seed, Case, CasesUnder, Failing, Totals};
use crate::monitor::Limits;
use crate::reference::instances::rng;
use crate::scenario::road::commitment_bound;
use crate::scenario::road::{Road, RoadScenario, RoadVehicle};
use crate::scenario::DriverKind;
use crate::verdict::{Judged, Verdict};
use crate::world::{Body, Finish, START_MARGIN_M};
use rand::Rng;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// `host-sim deadends`: its cases, seed and invariant.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, clap::Args)]
pub struct Deadends {
    /// Cases, seed, invariant.
    #[command(flatten)]
    #[serde(flatten)]
    pub sweep: CasesUnder,
    /// Percent of the vehicles that are trucks (16.5 m, braking at 4.5 m/s²), drawn per
    /// vehicle; 0 gives the cases as they always were.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u8).range(0..=100))]
    #[serde(default, skip_serializing_if = "super::flags::is_zero")]
    pub trucks: u8,
}

impl Experiment for Deadends {
    const NAME: &'static str = "deadends";
    type Part = DeadendsReport;
    type Report = DeadendsReport;

    fn cases(&self) -> u64 {
        self.sweep.sweep.cases
    }

    fn run(&self, (first, end): (u64, u64), threads: usize) -> Result<DeadendsReport, RunError> {
        let s = &self.sweep;
        Ok(sweep_with(
            end - first,
            first,
            (s.sweep.seed, self.trucks),
            threads,
            s.invariant,
        ))
    }

    fn report(&self, parts: Vec<DeadendsReport>) -> Result<DeadendsReport, MergeError> {
        combine_all(parts)
    }
}

impl Judged for DeadendsReport {
    fn verdict(&self) -> Verdict {
        self.totals.verdict()
    }
}

impl core::fmt::Display for DeadendsReport {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(&sweep::liveness_text(&self.totals, &self.failing))
    }
}

/// The `deadends` result.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct DeadendsReport {
    /// Collisions, violations, unfinished vehicles, deadlocks, finish times.
    #[serde(flatten)]
    pub totals: Totals,
    /// Lane changes completed over all cases.
    pub lane_changes: u64,
    /// The sweep's seed.
    pub seed: u64,
    /// Failing cases (at most 20), each as a scenario file.
    pub failing: Vec<Failing>,
    /// Wall-clock time (s).
    pub wall_seconds: f64,
}

/// Case `index` of the sweep seeded `seed`, as a scenario the loader accepts.
pub fn case(seed: u64, index: u64) -> RoadScenario {
    case_with(seed, index, 0)
}

/// [`case`] with `trucks_percent` of its vehicles trucks ([`Body::TRUCK`]), each drawn at
/// random (with 0 nothing is drawn: [`case`]'s own), every follower at least its own
/// safe spacing behind the vehicle ahead.
pub fn case_with(seed: u64, index: u64, trucks_percent: u8) -> RoadScenario {
    let lim = Limits::table_i();
    let mut rng = rng(case_seed(seed, index));
    let lanes: u8 = rng.random_range(2..=5);
    let n: usize = rng.random_range(4..=40);
    let common = rng.random_bool(0.25).then(|| rng.random_range(0..lanes));
    let mut back: Vec<Option<(f64, Body)>> = vec![None; usize::from(lanes)];
    let mut vehicles = Vec::with_capacity(n);
    for i in 0..n {
        let lane = rng.random_range(0..lanes);
        let v = rng.random_range(0.0..lim.v_max);
        let truck = trucks_percent > 0 && rng.random_range(0..100u8) < trucks_percent;
        let body = if truck { Body::TRUCK } else { Body::CAR };
        let x = match back[usize::from(lane)] {
            None => rng.random_range(0.0..40.0),
            Some((xl, lead)) => xl - spacing(v, lead, body) - rng.random_range(0.0..25.0),
        };
        back[usize::from(lane)] = Some((x, body));
        vehicles.push(RoadVehicle {
            cooperative: None,
            length: truck.then_some(body.length),
            brake: truck.then_some(body.brake),
            id: i as u16 + 1,
            x,
            lane,
            v,
            target_lane: Some(common.unwrap_or_else(|| rng.random_range(0..lanes))),
            driver: DriverKind::Planner,
            script: Vec::new(),
            goal_x: None,
            v_ref: Some(rng.random_range(10.0..lim.v_max)),
        });
    }
    let open = Road { lanes, end_x: None };
    // Beyond every vehicle's commitment distance and room to stop, by a random margin.
    let mut end = vehicles
        .iter()
        .enumerate()
        .map(|(i, v)| {
            let commit = commitment_bound(&vehicles, &open, i, lim.v_max).unwrap_or(0.0);
            let b = v.body();
            let stop =
                0.5 * b.length + lim.d0 + lim.safe_distance_at(v.v, b.brake) + START_MARGIN_M + 1.0;
            v.x + commit.max(stop)
        })
        .fold(0.0, f64::max)
        + rng.random_range(0.0..100.0);
    let lowest = vehicles.iter().map(|v| v.x).fold(f64::INFINITY, f64::min);
    let name = format!("deadend-{seed}-{index}");
    // The slowest reference speed covers the whole road and brakes to a stop in time.
    let duration = ((end - lowest) / 10.0 + 60.0).min(1200.0);
    for _ in 0..20 {
        let sc = RoadScenario::new(
            name.clone(),
            duration,
            case_seed(seed, index),
            Road {
                lanes,
                end_x: Some(end),
            },
            vehicles.clone(),
        );
        if RoadScenario::parse(&sc.to_toml(), Path::new("case.toml")).is_ok() {
            return sc;
        }
        end += 50.0;
    }
    RoadScenario::new(
        name,
        duration,
        case_seed(seed, index),
        Road {
            lanes,
            end_x: Some(end),
        },
        vehicles,
    )
}

/// [`case_with`] naming `invariant`, so that its file (a failing case's) replays under the
/// invariant it ran under, whatever the default.
pub fn case_under(
    seed: u64,
    index: u64,
    trucks_percent: u8,
    invariant: planner_core::Invariant,
) -> RoadScenario {
    let mut sc = case_with(seed, index, trucks_percent);
    sc.header.invariant = invariant;
    sc
}

/// Runs `cases` cases from index `first` of the sweep seeded `seed` on `threads` threads.
pub fn sweep(cases: u64, first: u64, seed: u64, threads: usize) -> DeadendsReport {
    sweep_with(
        cases,
        first,
        (seed, 0),
        threads,
        planner_core::Invariant::Paper,
    )
}

/// [`sweep()`] with its seed and `trucks` percent of trucks, every planner keeping
/// `invariant` (a failing case's scenario names it).
pub fn sweep_with(
    cases: u64,
    first: u64,
    (seed, trucks): (u64, u8),
    threads: usize,
    invariant: planner_core::Invariant,
) -> DeadendsReport {
    let t0 = std::time::Instant::now();
    let results: Vec<Case> = super::par::map_indexed(cases as usize, threads, |i| {
        let index = first + i as u64;
        let sc = case_under(seed, index, trucks, invariant);
        // The world takes the invariant from the scenario, as its file does.
        let mut world = sc.world();
        world.finish = Finish::GoalsMetAndStill;
        Case {
            index,
            seed: case_seed(seed, index),
            label: "deadend",
            summary: sweep::run(world),
            scenario: sc.to_toml(),
        }
    });
    DeadendsReport {
        totals: Totals::of(results.iter()),
        lane_changes: results
            .iter()
            .map(|c| c.summary.lane_changes.changes as u64)
            .sum(),
        seed,
        failing: sweep::failing(results.iter(), sweep::KEEP_FAILING),
        wall_seconds: t0.elapsed().as_secs_f64(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every case loads: the generator keeps to what the loader accepts.
    #[test]
    fn cases_are_valid_scenarios() {
        for i in 0..30 {
            let sc = case(7, i);
            RoadScenario::parse(&sc.to_toml(), Path::new("c.toml"))
                .unwrap_or_else(|e| panic!("{e}"));
            assert!((2..=5).contains(&sc.road.lanes));
            assert!((4..=40).contains(&sc.vehicles.len()));
        }
    }

    /// A case's file names the invariant it ran under, once (a file that named it twice,
    /// as the sweep printed before, does not load).
    #[test]
    fn a_case_file_replays_under_its_own_invariant() {
        use planner_core::Invariant::{LeaderAware, Paper};
        for invariant in [Paper, LeaderAware] {
            let text = case_under(3_712_032_153, 24, 0, invariant).to_toml();
            assert_eq!(text.matches("invariant =").count(), 1, "{text}");
            let back = RoadScenario::parse(&text, Path::new("c.toml")).expect("loads");
            assert_eq!(back.header.invariant, invariant);
        }
    }
}
