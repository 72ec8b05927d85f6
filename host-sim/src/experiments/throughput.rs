//! Fig. 9 (Sec. VII-B, SPEC §8): a closed system of 8 vehicles at the SPEC §8
//! intersection — whenever one leaves, it comes back at the start of an inlet with a
//! random route — for 300 s under every algorithm, on the same seeds: vehicles crossed
//! and the mean time from entering A_C to leaving it.

use super::experiment::{duration_within, Experiment, RunError, SettingsError};
use super::flags::FaultFlags;
use super::shard::{MergeError, Runs};
use crate::bus::Faults;
use crate::scenario::junction::{placed, Placement};
use crate::verdict::{Judged, Safety, Verdict};
use crate::world::network::{Junction, Network};
use crate::world::summary::Summary;
use crate::world::{Arrivals, Finish, SolverChoice, World, WorldSpec, LENGTH_M};
use planner_core::crossing::Algorithm;
use planner_core::intersection::{Layout, LayoutSpec};
use planner_core::Invariant;
use planner_core::Params;
use rand::Rng;
use serde::{Deserialize, Serialize};

/// `experiment throughput`'s settings: what every run shares (its flags; a shard's
/// header carries them for `host-sim merge`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, clap::Args)]
pub struct ThroughputSettings {
    /// Runs per algorithm (seeds from --seed).
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..))]
    pub seeds: u64,
    /// First seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Simulated seconds per run.
    #[arg(long, default_value_t = 300.0)]
    pub duration: f64,
    /// Faults of the bus.
    #[command(flatten)]
    pub faults: FaultFlags,
    /// The invariant every planner keeps toward the vehicle ahead.
    // A shard header of an older version has none: the paper's.
    #[arg(long, default_value = crate::world::DEFAULT_INVARIANT_NAME, value_parser = super::flags::invariant())]
    #[serde(default, with = "crate::world::invariant_serde")]
    pub invariant: Invariant,
}

impl Experiment for ThroughputSettings {
    const NAME: &'static str = "throughput";
    type Part = Runs<ThroughputCase>;
    type Report = ThroughputReport;

    fn validate(&self) -> Result<(), SettingsError> {
        duration_within(self.duration, 3600.0)?;
        self.faults.validate()
    }

    fn cases(&self) -> u64 {
        self.seeds * Algorithm::ALL.len() as u64
    }

    fn run(&self, range: (u64, u64), threads: usize) -> Result<Self::Part, RunError> {
        Ok(Runs::timed(|| throughput_cases(self, range, threads)))
    }

    fn report(&self, parts: Vec<Self::Part>) -> Result<ThroughputReport, MergeError> {
        let all = Runs::concat(parts);
        Ok(throughput_report(&all.runs, self, all.wall_seconds))
    }
}

impl Judged for ThroughputReport {
    /// Every algorithm's findings; a closed system has no liveness goal of its own.
    fn verdict(&self) -> Verdict {
        let safety = self
            .results
            .iter()
            .map(|x| {
                Safety::of(
                    x.collisions,
                    x.invariant_violations,
                    x.limit_violations,
                    x.unpermitted_entries,
                )
            })
            .sum();
        Verdict::new(safety, true)
    }
}

/// The Fig. 8 start: one vehicle on each of the 8 inlets, random routes, at vImax,
/// staggered along their inlets.
pub fn fig8_placements(layout: &Layout<f64>, seed: u64) -> Vec<Placement> {
    let mut rng = crate::reference::instances::rng(seed ^ 0xf18);
    let mut out = Vec::new();
    for heading in 0..4u8 {
        for lane in 0..2u8 {
            let movement = if rng.random_bool(0.5) {
                planner_core::intersection::Movement::Straight
            } else if lane == 0 {
                planner_core::intersection::Movement::Left
            } else {
                planner_core::intersection::Movement::Right
            };
            let route = layout.route_index(heading, lane, movement).unwrap_or(0) as u8;
            out.push(Placement {
                id: out.len() as u16 + 1,
                route,
                s: 0.5 * LENGTH_M + rng.random_range(0.0..30.0),
                v: layout.spec.v_limit,
                body: crate::world::Body::CAR,
            });
        }
    }
    out
}

/// The SPEC §8 layout.
pub fn spec8_layout() -> Layout<f64> {
    let p = Params::<f64>::table_i();
    // The SPEC §8 values satisfy every check (tested).
    Layout::new(&p, LayoutSpec::spec8(&p))
        .unwrap_or_else(|_| unreachable!("SPEC §8 layout is valid"))
}

/// The world of a Fig. 9 run: the SPEC §8 junction under `algorithm`, the Fig. 8 start
/// of `seed`, a closed system, run for `s.duration` with `s.faults` and `s.invariant`.
pub fn closed_world(algorithm: Algorithm, seed: u64, s: &ThroughputSettings) -> WorldSpec {
    let (duration, faults) = (s.duration, s.faults.faults());
    let layout = spec8_layout();
    let placements = fig8_placements(&layout, seed);
    WorldSpec {
        name: format!("throughput-{}-{seed}", algorithm.name()),
        duration_s: duration,
        seed,
        horizon: 20,
        deadline_s: duration,
        vehicles: placements.iter().map(|p| placed(&layout, p)).collect(),
        network: Network {
            segments: Vec::new(),
            junctions: vec![Junction {
                id: 0,
                centre: (0.0, 0.0),
                layout,
                algorithm,
                inlets: [None; 4],
                outlets: [None; 4],
            }],
        },
        faults,
        sensing: (!faults.is_none()).then(planner_core::Sensing::radar),
        arrivals: Arrivals::Closed,
        deadlock_window_s: crate::monitor::liveness::DEADLOCK_WINDOW_S,
        finish: Finish::Duration,
        clock_start: planner_core::Instant::EPOCH,
        precision: crate::world::precision::Precision::F64,
        invariant: s.invariant,
    }
}

/// Runs a closed system of 8 vehicles for `s.duration` s under `algorithm` (Fig. 9).
pub fn throughput_run(algorithm: Algorithm, seed: u64, s: &ThroughputSettings) -> Summary {
    let mut w = World::<20>::new(
        closed_world(algorithm, seed, s),
        SolverChoice::Ours,
        Some(seed),
    );
    while !w.finished() {
        // The in-process bus cannot fail.
        if w.step(&mut |_| {}).is_err() {
            break;
        }
    }
    w.summary(0.0)
}

/// One algorithm's row of the throughput experiment.
#[derive(Debug, Clone, Serialize)]
pub struct ThroughputRow {
    /// Algorithm.
    pub algorithm: &'static str,
    /// Mean over seeds of vehicles crossed.
    pub crossed_mean: f64,
    /// Standard deviation over seeds of vehicles crossed.
    pub crossed_std: f64,
    /// Mean time from arrival to leaving A_C (s), over all vehicles of all seeds.
    pub crossing_time_mean_s: f64,
    /// Longest such time (s).
    pub crossing_time_max_s: f64,
    /// Collisions over all seeds.
    pub collisions: u64,
    /// Invariant violations over all seeds.
    pub invariant_violations: u64,
    /// Limit violations over all seeds.
    pub limit_violations: u64,
    /// Entries into A_S without a permission.
    pub unpermitted_entries: u64,
    /// Certified-fallback steps.
    pub fallback_steps: u64,
}

/// The `experiment throughput` result.
#[derive(Debug, Clone, Serialize)]
pub struct ThroughputReport {
    /// Rows, one per algorithm.
    pub results: Vec<ThroughputRow>,
    /// Seeds.
    pub seeds: u64,
    /// Duration of each run (s).
    pub duration_s: f64,
    /// Faults the bus injected.
    pub faults: Faults,
    /// The invariant every planner kept toward the vehicle ahead.
    #[serde(with = "crate::world::invariant_serde")]
    pub invariant: Invariant,
    /// Wall-clock time (s).
    pub wall_seconds: f64,
}

/// One throughput run (an algorithm on a seed): what [`throughput_report`] needs of it.
/// A shard of `experiment throughput` prints these; `host-sim merge` aggregates them as
/// the unsharded run does.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ThroughputCase {
    /// The algorithm's name ([`Algorithm::name`]).
    pub algorithm: String,
    /// The run's seed.
    pub seed: u64,
    /// Vehicles crossed.
    pub crossed: u64,
    /// Mean time through A_C (s).
    pub crossing_time_mean_s: f64,
    /// Longest time through A_C (s).
    pub crossing_time_max_s: f64,
    /// Collisions.
    pub collisions: u64,
    /// Invariant violations.
    pub invariant_violations: u64,
    /// Limit violations.
    pub limit_violations: u64,
    /// Entries into A_S without a permission.
    pub unpermitted_entries: u64,
    /// Certified-fallback steps.
    pub fallback_steps: u64,
}

/// The runs of the throughput experiment, algorithm by algorithm, seeds
/// `first_seed..first_seed + seeds` each: run i is `(ALL[i / seeds], first_seed + i % seeds)`.
pub fn throughput_jobs(seeds: u64, first_seed: u64) -> Vec<(Algorithm, u64)> {
    Algorithm::ALL
        .iter()
        .flat_map(|&a| (0..seeds).map(move |k| (a, first_seed + k)))
        .collect()
}

/// Runs the throughput runs `first..end` of [`throughput_jobs`].
pub fn throughput_cases(
    st: &ThroughputSettings,
    (first, end): (u64, u64),
    threads: usize,
) -> Vec<ThroughputCase> {
    let jobs = throughput_jobs(st.seeds, st.seed);
    let jobs = &jobs[(first as usize).min(jobs.len())..(end as usize).min(jobs.len())];
    super::par::map_indexed(jobs.len(), threads, |i| {
        let (a, seed) = jobs[i];
        let s = throughput_run(a, seed, st);
        ThroughputCase {
            algorithm: a.name().into(),
            seed,
            crossed: s.crossed(),
            crossing_time_mean_s: s.crossing_time_mean_s(),
            crossing_time_max_s: s.crossing_time_max_s(),
            collisions: s.collisions,
            invariant_violations: s.invariant_violations,
            limit_violations: s.limit_violations,
            unpermitted_entries: s.unpermitted_entries(),
            fallback_steps: s.fallback_steps,
        }
    })
}

/// One algorithm's row over its runs.
fn row(algorithm: &'static str, mine: &[&ThroughputCase]) -> ThroughputRow {
    let n = mine.len().max(1) as f64;
    let mean = mine.iter().map(|c| c.crossed as f64).sum::<f64>() / n;
    let var = mine
        .iter()
        .map(|c| (c.crossed as f64 - mean).powi(2))
        .sum::<f64>()
        / (n - 1.0).max(1.0);
    let total: f64 = mine.iter().map(|c| c.crossed as f64).sum::<f64>().max(1.0);
    ThroughputRow {
        algorithm,
        crossed_mean: mean,
        crossed_std: var.sqrt(),
        crossing_time_mean_s: mine
            .iter()
            .map(|c| c.crossing_time_mean_s * c.crossed as f64)
            .sum::<f64>()
            / total,
        crossing_time_max_s: mine
            .iter()
            .map(|c| c.crossing_time_max_s)
            .fold(0.0, f64::max),
        collisions: mine.iter().map(|c| c.collisions).sum(),
        invariant_violations: mine.iter().map(|c| c.invariant_violations).sum(),
        limit_violations: mine.iter().map(|c| c.limit_violations).sum(),
        unpermitted_entries: mine.iter().map(|c| c.unpermitted_entries).sum(),
        fallback_steps: mine.iter().map(|c| c.fallback_steps).sum(),
    }
}

/// The report over `cases` (in [`throughput_jobs`] order), one row per algorithm.
pub fn throughput_report(
    cases: &[ThroughputCase],
    s: &ThroughputSettings,
    wall_seconds: f64,
) -> ThroughputReport {
    let results = Algorithm::ALL
        .iter()
        .map(|a| {
            let mine: Vec<&ThroughputCase> =
                cases.iter().filter(|c| c.algorithm == a.name()).collect();
            row(a.name(), &mine)
        })
        .collect();
    ThroughputReport {
        results,
        seeds: s.seeds,
        duration_s: s.duration,
        faults: s.faults.faults(),
        invariant: s.invariant,
        wall_seconds,
    }
}

impl core::fmt::Display for ThroughputReport {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        writeln!(
            f,
            "throughput (Fig. 9): {} runs of {} s per algorithm, closed system, in {:.1} s",
            self.seeds, self.duration_s, self.wall_seconds
        )?;
        writeln!(
            f,
            "{:<10} {:>8} {:>6} {:>10} {:>9} {:>7}",
            "algorithm", "crossed", "±", "mean s", "max s", "unsafe"
        )?;
        for r in &self.results {
            writeln!(
                f,
                "{:<10} {:>8.1} {:>6.1} {:>10.2} {:>9.2} {:>7}",
                r.algorithm,
                r.crossed_mean,
                r.crossed_std,
                r.crossing_time_mean_s,
                r.crossing_time_max_s,
                r.collisions + r.invariant_violations + r.limit_violations + r.unpermitted_entries
            )?;
        }
        Ok(())
    }
}
