//! `host-sim crossings`: Theorems 4 and 5 as a randomized sweep. Random queues at the
//! SPEC §8 intersection — on each of the 8 inlet lanes from none to as many vehicles as
//! the inlet holds (up to the manager's 64 in all), at random speeds, on random routes,
//! starting inside and outside A_C — each case run under every algorithm. A run ends once
//! every vehicle has crossed; it fails on any collision, violation or entry into A_S
//! without a permission, on a vehicle that has not crossed, or on a deadlock.
//!
//! The paper's Concurrent Crossing as written is run and reported too, but it is not live
//! (SPEC §7: it admits a later vehicle ahead of an earlier waiting one it conflicts with,
//! and a follower ahead of its own leader) and is left out of the totals.

use super::experiment::{Experiment, RunError};
use super::shard::{combine_all, MergeError};
use super::sweep::{self, case_seed, Case, CasesUnder, Failing, Totals};
use crate::monitor::Limits;
use crate::reference::instances::rng;
use crate::scenario::junction::{JunctionScenario, LayoutToml, Placement};
use crate::verdict::{Judged, Verdict};
use crate::world::{Body, START_MARGIN_M};
use planner_core::crossing::Algorithm;
use planner_core::intersection::{lane_movements, Layout};
use planner_core::Invariant;
use rand::Rng;
use serde::{Deserialize, Serialize};

/// `host-sim crossings`: its cases, seed and invariant.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, clap::Args)]
pub struct Crossings {
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

impl Experiment for Crossings {
    const NAME: &'static str = "crossings";
    type Part = CrossingsReport;
    type Report = CrossingsReport;

    fn cases(&self) -> u64 {
        self.sweep.sweep.cases
    }

    fn run(&self, (first, end): (u64, u64), threads: usize) -> Result<CrossingsReport, RunError> {
        let s = &self.sweep;
        Ok(sweep_with(
            end - first,
            first,
            (s.sweep.seed, self.trucks),
            threads,
            s.invariant,
        ))
    }

    fn report(&self, parts: Vec<CrossingsReport>) -> Result<CrossingsReport, MergeError> {
        combine_all(parts)
    }
}

impl Judged for CrossingsReport {
    /// Over the live algorithms (the paper's Concurrent Crossing is reported apart).
    fn verdict(&self) -> Verdict {
        self.totals.verdict()
    }
}

impl core::fmt::Display for CrossingsReport {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(&sweep::liveness_text(&self.totals, &self.failing))
    }
}

/// The live algorithms (the targets), then the paper's as written.
pub const ALGORITHMS: [Algorithm; 6] = [
    Algorithm::AllWayStop,
    Algorithm::Fifo,
    Algorithm::ConcurrentFair,
    Algorithm::Pipelined,
    Algorithm::Platoon,
    Algorithm::Concurrent,
];

/// One algorithm's row.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct AlgorithmRow {
    /// The algorithm.
    pub algorithm: String,
    /// `false` for the paper's Concurrent Crossing as written (not live; not in the
    /// totals).
    pub live: bool,
    /// Its totals.
    #[serde(flatten)]
    pub totals: Totals,
}

/// The `crossings` result.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct CrossingsReport {
    /// Over every case and every live algorithm.
    #[serde(flatten)]
    pub totals: Totals,
    /// Per algorithm.
    pub algorithms: Vec<AlgorithmRow>,
    /// The sweep's seed.
    pub seed: u64,
    /// Failing runs of the live algorithms (at most 20), each as a scenario file.
    pub failing: Vec<Failing>,
    /// Wall-clock time (s).
    pub wall_seconds: f64,
}

/// The vehicles of case `index` of the sweep seeded `seed` at `layout`, `trucks_percent`
/// of them trucks.
pub fn placements(
    (seed, trucks_percent): (u64, u8),
    index: u64,
    layout: &Layout<f64>,
) -> Vec<Placement> {
    let mut rng = rng(case_seed(seed, index));
    let per_lane = [1usize, 2, 3, 5, 8, 16][rng.random_range(0..6)];
    queues_of(&mut rng, layout, (per_lane, trucks_percent))
}

/// Random queues at `layout`: on each inlet lane from none to `per_lane` vehicles (as
/// many as the inlet holds, up to the manager's capacity in all), each at a random speed
/// (a fifth standing) on a random route its lane serves, placed at random behind the
/// frontmost place it can be — able to stop before the line, or behind the vehicle ahead
/// with the invariant.
pub fn queue_placements(
    rng: &mut impl Rng,
    layout: &Layout<f64>,
    per_lane: usize,
) -> Vec<Placement> {
    queues_of(rng, layout, (per_lane, 0))
}

/// [`queue_placements`] with `trucks_percent` of the vehicles trucks ([`Body::TRUCK`]),
/// each drawn at random (with 0 nothing is drawn: the queues are
/// [`queue_placements`]'), every follower its own braking distance behind the rear of
/// the vehicle ahead.
pub fn queues_of(
    rng: &mut impl Rng,
    layout: &Layout<f64>,
    (per_lane, trucks_percent): (usize, u8),
) -> Vec<Placement> {
    let lim = Limits::table_i();
    let v_limit = layout.spec.v_limit;
    let line = layout.spec.inlet_length;
    let mut out: Vec<Placement> = Vec::new();
    for heading in 0..4u8 {
        for lane in 0..layout.spec.lanes {
            let k = rng.random_range(0..=per_lane);
            let mut ahead: Option<(f64, Body)> = None;
            for _ in 0..k {
                if out.len() >= crate::world::junction::MANAGER_CAP {
                    break;
                }
                let v = if rng.random_bool(0.2) {
                    0.0
                } else {
                    rng.random_range(0.0..v_limit)
                };
                let truck = trucks_percent > 0 && rng.random_range(0..100u8) < trucks_percent;
                let body = if truck { Body::TRUCK } else { Body::CAR };
                let half = 0.5 * body.length;
                let front = match ahead {
                    None => line - half,
                    Some((a, lead)) => a - 0.5 * (lead.length + body.length),
                } - lim.d0
                    - lim.safe_distance_at(v, body.brake)
                    - START_MARGIN_M
                    - 0.01;
                if front < half {
                    break;
                }
                let s = (front - rng.random_range(0.0..20.0)).max(half);
                let ms = lane_movements(lane, layout.spec.lanes);
                let m = ms[rng.random_range(0..ms.len())];
                let Some(route) = layout.route_index(heading, lane, m) else {
                    continue;
                };
                out.push(Placement {
                    id: out.len() as u16 + 1,
                    route: route as u8,
                    s,
                    v,
                    body,
                });
                ahead = Some((s, body));
            }
        }
    }
    if out.is_empty() {
        out.push(Placement {
            id: 1,
            route: 1,
            s: 10.0,
            v: 5.0,
            body: Body::CAR,
        });
    }
    out
}

/// Case `index` under `algorithm`, the vehicles keeping the paper's invariant.
pub fn case(seed: u64, index: u64, algorithm: Algorithm) -> JunctionScenario {
    case_with((seed, 0), index, algorithm, Invariant::Paper)
}

/// Case `index` of the sweep seeded `seed` with `trucks_percent` of trucks, under
/// `algorithm`, the vehicles keeping `invariant`. The queues are placed at the SPEC §8
/// layout; the scenario's layout is built for its fleet (with a truck in it, every
/// conflict is swept by the truck's rectangle).
pub fn case_with(
    (seed, trucks_percent): (u64, u8),
    index: u64,
    algorithm: Algorithm,
    invariant: Invariant,
) -> JunctionScenario {
    let lt = spec_layout(trucks_percent);
    let layout = crate::scenario::junction::build_layout(&lt)
        .unwrap_or_else(|_| unreachable!("the SPEC §8 layout is valid"));
    let p = placements((seed, trucks_percent), index, &layout);
    let mut sc = JunctionScenario::new(
        format!("crossings-{seed}-{index}-{}", algorithm.name()),
        300.0,
        case_seed(seed, index),
        algorithm,
        lt,
        p,
    )
    .unwrap_or_else(|e| unreachable!("the SPEC §8 layout is valid for cars and trucks: {e}"));
    sc.header.invariant = invariant;
    sc
}

/// SPEC §8's layout as written, made to take trucks ([`truck_layout`]) when
/// `trucks_percent` of the vehicles may be trucks: the junction of every sweep that
/// draws them at SPEC §8's intersection.
pub fn spec_layout(trucks_percent: u8) -> LayoutToml {
    let lt = LayoutToml::default();
    if trucks_percent > 0 {
        truck_layout(lt)
    } else {
        lt
    }
}

/// `lt` made to take trucks: A_S [`TRUCK_TURN_INSET_M`] larger all round around the same
/// turns (a 16.5 m rectangle's swing stays inside it), and outlets that take a truck out
/// of A_C (a vehicle leaves once it is on its outlet outside A_C: 50 m + 16.5 m; SPEC §8's
/// 60 m takes a car).
pub fn truck_layout(mut lt: LayoutToml) -> LayoutToml {
    lt.half_size += TRUCK_TURN_INSET_M;
    lt.turn_inset += TRUCK_TURN_INSET_M;
    lt.outlet_length = lt.outlet_length.max(lt.comm_margin + Body::TRUCK.length);
    lt
}

/// How much larger A_S is around SPEC §8's turns in the sweep with trucks (m): the least
/// whole metre planner-core's swept-area check takes for a 16.5 m truck (7.5 m).
pub const TRUCK_TURN_INSET_M: f64 = 8.0;

/// Runs `cases` cases from index `first` of the sweep seeded `seed`, each under every
/// algorithm, on `threads` threads, under the paper's invariant.
pub fn sweep(cases: u64, first: u64, seed: u64, threads: usize) -> CrossingsReport {
    sweep_with(cases, first, (seed, 0), threads, Invariant::Paper)
}

/// [`sweep()`] with its seed and `trucks` percent of trucks, every vehicle keeping
/// `invariant`.
pub fn sweep_with(
    cases: u64,
    first: u64,
    (seed, trucks): (u64, u8),
    threads: usize,
    invariant: Invariant,
) -> CrossingsReport {
    let t0 = std::time::Instant::now();
    let jobs: Vec<(u64, Algorithm)> = (0..cases)
        .flat_map(|i| ALGORITHMS.iter().map(move |&a| (first + i, a)))
        .collect();
    let results: Vec<Case> = super::par::map_indexed(jobs.len(), threads, |j| {
        let (index, algorithm) = jobs[j];
        let sc = case_with((seed, trucks), index, algorithm, invariant);
        Case {
            index,
            seed: case_seed(seed, index),
            label: algorithm.name(),
            summary: sweep::run(sc.world()),
            scenario: sc.to_toml(),
        }
    });
    let live = |c: &&Case| c.label != Algorithm::Concurrent.name();
    let algorithms = ALGORITHMS
        .iter()
        .map(|&a| AlgorithmRow {
            algorithm: a.name().into(),
            live: a != Algorithm::Concurrent,
            totals: Totals::of(results.iter().filter(|c| c.label == a.name())),
        })
        .collect();
    CrossingsReport {
        totals: Totals::of(results.iter().filter(live)),
        algorithms,
        seed,
        failing: sweep::failing(results.iter().filter(live), sweep::KEEP_FAILING),
        wall_seconds: t0.elapsed().as_secs_f64(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    /// Every case loads, queues are real (several per lane in some cases), and a case's
    /// vehicles are the same under every algorithm.
    #[test]
    fn cases_are_valid_scenarios() {
        let mut most = 0;
        for i in 0..40 {
            let sc = case(3, i, Algorithm::Fifo);
            JunctionScenario::parse(&sc.to_toml(), Path::new("c.toml"))
                .unwrap_or_else(|e| panic!("{e}"));
            most = most.max(sc.placements.len());
            assert_eq!(sc.placements, case(3, i, Algorithm::Pipelined).placements);
        }
        assert!(most >= 30, "{most}");
    }

    /// With trucks: every case loads (its failing file reproduces it), a share of the
    /// vehicles are trucks, each truck has its own braking distance behind the vehicle
    /// ahead, and a small sweep under both invariants is safe and live (CI runs more).
    #[test]
    fn cases_with_trucks_load_and_a_small_sweep_is_clean() {
        let (mut trucks, mut all) = (0, 0);
        for i in 0..20 {
            let sc = case_with((3, 30), i, Algorithm::Fifo, Invariant::LeaderAware);
            let back = JunctionScenario::parse(&sc.to_toml(), Path::new("c.toml"))
                .unwrap_or_else(|e| panic!("{e}"));
            assert_eq!(back.placements, sc.placements, "case {i} round-trips");
            all += sc.placements.len();
            trucks += sc
                .placements
                .iter()
                .filter(|p| p.body == Body::TRUCK)
                .count();
        }
        assert!(
            trucks * 100 > all * 20 && trucks * 100 < all * 40,
            "{trucks} of {all}"
        );
        for invariant in [Invariant::Paper, Invariant::LeaderAware] {
            let r = sweep_with(2, 0, (5, 30), 2, invariant);
            let t = &r.totals;
            let found = (t.collisions, t.invariant_violations, t.unpermitted_entries);
            assert_eq!(found, (0, 0, 0), "{invariant:?}: {:?}", r.failing);
            assert_eq!((t.unfinished, t.deadlocks), (0, 0), "{invariant:?}");
        }
    }
}
