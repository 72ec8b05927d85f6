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
use crate::world::{LENGTH_M, START_MARGIN_M};
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
            s.sweep.seed,
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

/// The vehicles of case `index` of the sweep seeded `seed` at `layout`.
pub fn placements(seed: u64, index: u64, layout: &Layout<f64>) -> Vec<Placement> {
    let mut rng = rng(case_seed(seed, index));
    let per_lane = [1usize, 2, 3, 5, 8, 16][rng.random_range(0..6)];
    queue_placements(&mut rng, layout, per_lane)
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
    let lim = Limits::table_i();
    let v_limit = layout.spec.v_limit;
    let line = layout.spec.inlet_length;
    let mut out: Vec<Placement> = Vec::new();
    for heading in 0..4u8 {
        for lane in 0..layout.spec.lanes {
            let k = rng.random_range(0..=per_lane);
            let mut ahead: Option<f64> = None;
            for _ in 0..k {
                if out.len() >= crate::world::junction::MANAGER_CAP {
                    break;
                }
                let v = if rng.random_bool(0.2) {
                    0.0
                } else {
                    rng.random_range(0.0..v_limit)
                };
                let front = match ahead {
                    None => line - 0.5 * LENGTH_M,
                    Some(a) => a - LENGTH_M,
                } - lim.d0
                    - lim.safe_distance(v)
                    - START_MARGIN_M
                    - 0.01;
                if front < 0.5 * LENGTH_M {
                    break;
                }
                let s = (front - rng.random_range(0.0..20.0)).max(0.5 * LENGTH_M);
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
                });
                ahead = Some(s);
            }
        }
    }
    if out.is_empty() {
        out.push(Placement {
            id: 1,
            route: 1,
            s: 10.0,
            v: 5.0,
        });
    }
    out
}

/// Case `index` under `algorithm`, the vehicles keeping the paper's invariant.
pub fn case(seed: u64, index: u64, algorithm: Algorithm) -> JunctionScenario {
    case_with(seed, index, algorithm, Invariant::Paper)
}

/// Case `index` under `algorithm`, the vehicles keeping `invariant`.
pub fn case_with(
    seed: u64,
    index: u64,
    algorithm: Algorithm,
    invariant: Invariant,
) -> JunctionScenario {
    let lt = LayoutToml::default();
    let layout = crate::scenario::junction::build_layout(&lt)
        .unwrap_or_else(|_| unreachable!("the SPEC §8 layout is valid"));
    let p = placements(seed, index, &layout);
    let mut sc = JunctionScenario::new(
        format!("crossings-{seed}-{index}-{}", algorithm.name()),
        300.0,
        case_seed(seed, index),
        algorithm,
        lt,
        p,
    )
    .unwrap_or_else(|_| unreachable!("the SPEC §8 layout is valid"));
    sc.header.invariant = invariant;
    sc
}

/// Runs `cases` cases from index `first` of the sweep seeded `seed`, each under every
/// algorithm, on `threads` threads, under the paper's invariant.
pub fn sweep(cases: u64, first: u64, seed: u64, threads: usize) -> CrossingsReport {
    sweep_with(cases, first, seed, threads, Invariant::Paper)
}

/// [`sweep()`] with every vehicle keeping `invariant`.
pub fn sweep_with(
    cases: u64,
    first: u64,
    seed: u64,
    threads: usize,
    invariant: Invariant,
) -> CrossingsReport {
    let t0 = std::time::Instant::now();
    let jobs: Vec<(u64, Algorithm)> = (0..cases)
        .flat_map(|i| ALGORITHMS.iter().map(move |&a| (first + i, a)))
        .collect();
    let results: Vec<Case> = super::par::map_indexed(jobs.len(), threads, |j| {
        let (index, algorithm) = jobs[j];
        let sc = case_with(seed, index, algorithm, invariant);
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
}
