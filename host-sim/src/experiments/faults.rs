//! How much slower do the multi-lane and intersection experiments
//! complete on a faulty bus? Both are run on the same seeds over a perfect bus and over
//! one injecting the given faults, in one command, and compared.

use super::experiment::{duration_within, Experiment, RunError, SettingsError};
use super::flags::{flag_error, FaultFlags};
use super::multilane::{
    multilane_cases, multilane_report, MultilaneCase, MultilaneReport, MultilaneSettings,
};
use super::shard::{MergeError, Runs};
use super::throughput::{
    throughput_cases, throughput_report, ThroughputCase, ThroughputReport, ThroughputSettings,
};
use crate::bus::Faults;
use crate::verdict::{Judged, Verdict};
use crate::world::SolverChoice;
use planner_core::crossing::Algorithm;
use serde::{Deserialize, Serialize};

/// One algorithm's throughput, perfect vs faulty bus.
#[derive(Debug, Clone, Serialize)]
pub struct ThroughputDelta {
    /// Algorithm.
    pub algorithm: &'static str,
    /// Mean vehicles crossed, perfect bus.
    pub crossed_clean: f64,
    /// Mean vehicles crossed, faulty bus.
    pub crossed_faulty: f64,
    /// Mean crossing time, faulty / perfect.
    pub crossing_time_ratio: f64,
}

/// The comparison.
#[derive(Debug, Clone, Serialize)]
pub struct FaultComparison {
    /// The faults injected.
    pub faults: Faults,
    /// Multi-lane experiment, perfect bus.
    pub multilane_clean: MultilaneReport,
    /// Multi-lane experiment, faulty bus.
    pub multilane_faulty: MultilaneReport,
    /// Mean time until every vehicle is in its target lane, faulty / perfect.
    pub multilane_completion_ratio: f64,
    /// Throughput experiment, perfect bus.
    pub throughput_clean: ThroughputReport,
    /// Throughput experiment, faulty bus.
    pub throughput_faulty: ThroughputReport,
    /// Per algorithm.
    pub throughput: Vec<ThroughputDelta>,
    /// Collisions, invariant, limit violations and unpermitted entries on the faulty bus.
    pub faulty_unsafe_events: u64,
}

/// One run of the comparison: a multi-lane or a throughput run, on the perfect bus or the
/// faulty one. A shard of `experiment faults` prints these; `host-sim merge` aggregates
/// them as the unsharded run does.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum FaultCase {
    /// A multi-lane run.
    Multilane {
        /// On the faulty bus.
        faulty: bool,
        /// The run.
        run: MultilaneCase,
    },
    /// A throughput run.
    Throughput {
        /// On the faulty bus.
        faulty: bool,
        /// The run.
        run: ThroughputCase,
    },
}

/// The faulty bus of `experiment faults` (20 % loss and 50 ms delay unless told);
/// written in a shard's header as the [`Faults`] it makes.
#[derive(clap::Args, Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(from = "Faults", into = "Faults")]
pub struct FaultyBus {
    /// Probability that a receiver loses a message.
    #[arg(long, default_value_t = 0.2)]
    pub loss: f64,
    /// Delivery delay (s).
    #[arg(long, default_value_t = 0.05)]
    pub delay: f64,
    /// Extra delay drawn uniformly from [0, jitter] (s).
    #[arg(long, default_value_t = 0.0)]
    pub jitter: f64,
}

impl FaultyBus {
    /// The bus's faults.
    pub fn faults(&self) -> Faults {
        Faults {
            loss: self.loss,
            delay_s: self.delay,
            jitter_s: self.jitter,
            ..Faults::NONE
        }
    }
}

impl From<FaultyBus> for Faults {
    fn from(f: FaultyBus) -> Self {
        f.faults()
    }
}

impl From<Faults> for FaultyBus {
    fn from(f: Faults) -> Self {
        Self {
            loss: f.loss,
            delay: f.delay_s,
            jitter: f.jitter_s,
        }
    }
}

/// What the comparison runs: `seeds` multi-lane runs and `throughput_seeds` throughput
/// runs of `duration` s per algorithm, each on both buses (its flags; a shard's header
/// carries them for `host-sim merge`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, clap::Args)]
pub struct FaultSettings {
    /// The faulty bus's faults.
    #[command(flatten)]
    pub faults: FaultyBus,
    /// Multi-lane runs (seeds 1..=K).
    #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u64).range(1..))]
    pub seeds: u64,
    /// Throughput runs per algorithm (seeds 1..=K).
    #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u64).range(1..))]
    pub throughput_seeds: u64,
    /// Simulated seconds per throughput run.
    #[arg(long, default_value_t = 300.0)]
    pub duration: f64,
    /// The invariant every planner keeps toward the vehicle ahead (in both experiments,
    /// or in the grid).
    // A shard header of an older version has none: the paper's.
    #[arg(long, default_value = crate::world::DEFAULT_INVARIANT_NAME, value_parser = super::flags::invariant())]
    #[serde(default, with = "crate::world::invariant_serde")]
    pub invariant: planner_core::Invariant,
}

impl Experiment for FaultSettings {
    const NAME: &'static str = "faults";
    type Part = Runs<FaultCase>;
    type Report = FaultComparison;

    fn validate(&self) -> Result<(), SettingsError> {
        self.faults.faults().validate().map_err(flag_error)?;
        duration_within(self.duration, 3600.0)
    }

    /// Runs in all: the multi-lane runs, then the throughput runs, each block on the
    /// perfect bus first.
    fn cases(&self) -> u64 {
        2 * self.seeds + 2 * self.throughput_seeds * Algorithm::ALL.len() as u64
    }

    fn run(&self, range: (u64, u64), threads: usize) -> Result<Self::Part, RunError> {
        Ok(Runs::timed(|| self.runs(range, threads)))
    }

    fn report(&self, parts: Vec<Self::Part>) -> Result<FaultComparison, MergeError> {
        let all = Runs::concat(parts);
        Ok(self.comparison(&all.runs, all.wall_seconds))
    }
}

impl Judged for FaultComparison {
    /// The faulty bus's findings, both experiments; live when every multi-lane run on
    /// the faulty bus completed its lane changes.
    fn verdict(&self) -> Verdict {
        self.multilane_faulty
            .verdict()
            .and(self.throughput_faulty.verdict())
    }
}

impl FaultSettings {
    /// Runs `first..end` of [`Experiment::cases`]: run i is the same run whatever the
    /// range.
    fn runs(&self, (first, end): (u64, u64), threads: usize) -> Vec<FaultCase> {
        let m = self.seeds;
        let t = self.throughput_seeds * Algorithm::ALL.len() as u64;
        // Each block is the part of [first, end) that falls in it, shifted to its start.
        let part =
            |lo: u64, len: u64| (first.clamp(lo, lo + len) - lo, end.clamp(lo, lo + len) - lo);
        let mut out = Vec::new();
        for (k, faulty) in [false, true].into_iter().enumerate() {
            let range = part(k as u64 * m, m);
            let runs = multilane_cases(&self.multilane(faulty), range, threads);
            out.extend(
                runs.into_iter()
                    .map(|run| FaultCase::Multilane { faulty, run }),
            );
        }
        for (k, faulty) in [false, true].into_iter().enumerate() {
            let range = part(2 * m + k as u64 * t, t);
            let runs = throughput_cases(&self.throughput(faulty), range, threads);
            out.extend(
                runs.into_iter()
                    .map(|run| FaultCase::Throughput { faulty, run }),
            );
        }
        out
    }

    /// The comparison over `cases` (in [`Experiment::run`] order).
    fn comparison(&self, cases: &[FaultCase], wall_seconds: f64) -> FaultComparison {
        // [perfect, faulty] bus, each in run order.
        let mut multilane: [Vec<MultilaneCase>; 2] = Default::default();
        let mut throughput: [Vec<ThroughputCase>; 2] = Default::default();
        for c in cases {
            match c {
                FaultCase::Multilane { faulty, run } => {
                    multilane[usize::from(*faulty)].push(run.clone())
                }
                FaultCase::Throughput { faulty, run } => {
                    throughput[usize::from(*faulty)].push(run.clone())
                }
            }
        }
        // The four parts ran interleaved on one pool: each reports the whole comparison's time.
        let w = wall_seconds;
        comparison(
            self.faults.faults(),
            multilane_report(&multilane[0], &self.multilane(false), w),
            multilane_report(&multilane[1], &self.multilane(true), w),
            throughput_report(&throughput[0], &self.throughput(false), w),
            throughput_report(&throughput[1], &self.throughput(true), w),
        )
    }

    /// The multi-lane runs' settings on the perfect bus or the faulty one (seeds 1..=K).
    fn multilane(&self, faulty: bool) -> MultilaneSettings {
        MultilaneSettings {
            seeds: self.seeds,
            seed: 1,
            solver: SolverChoice::Ours,
            faults: if faulty {
                self.faults.faults().into()
            } else {
                FaultFlags::NONE
            },
            invariant: self.invariant,
        }
    }

    /// The throughput runs' settings on the perfect bus or the faulty one (seeds 1..=K).
    fn throughput(&self, faulty: bool) -> ThroughputSettings {
        ThroughputSettings {
            seeds: self.throughput_seeds,
            seed: 1,
            duration: self.duration,
            faults: if faulty {
                self.faults.faults().into()
            } else {
                FaultFlags::NONE
            },
            invariant: self.invariant,
        }
    }
}

/// The comparison of the four reports.
fn comparison(
    faults: Faults,
    multilane_clean: MultilaneReport,
    multilane_faulty: MultilaneReport,
    throughput_clean: ThroughputReport,
    throughput_faulty: ThroughputReport,
) -> FaultComparison {
    let ratio = |a: f64, b: f64| if b > 0.0 { a / b } else { f64::NAN };
    let rows = throughput_clean
        .results
        .iter()
        .zip(&throughput_faulty.results)
        .map(|(c, f)| ThroughputDelta {
            algorithm: c.algorithm,
            crossed_clean: c.crossed_mean,
            crossed_faulty: f.crossed_mean,
            crossing_time_ratio: ratio(f.crossing_time_mean_s, c.crossing_time_mean_s),
        })
        .collect();
    let faulty_unsafe_events = multilane_faulty
        .verdict()
        .and(throughput_faulty.verdict())
        .safety
        .events();
    FaultComparison {
        faults,
        multilane_completion_ratio: ratio(
            multilane_faulty.mean_completion_time_s,
            multilane_clean.mean_completion_time_s,
        ),
        multilane_clean,
        multilane_faulty,
        throughput_clean,
        throughput_faulty,
        throughput: rows,
        faulty_unsafe_events,
    }
}

impl core::fmt::Display for FaultComparison {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let fl = &self.faults;
        writeln!(
            f,
            "faulty bus (loss {}, delay {} s, jitter {} s) against a perfect one, same seeds:",
            fl.loss, fl.delay_s, fl.jitter_s
        )?;
        writeln!(
            f,
            "  multi-lane: {} of {} runs complete (perfect: {} of {}); completion time x{:.2}",
            self.multilane_faulty.completed,
            self.multilane_faulty.runs,
            self.multilane_clean.completed,
            self.multilane_clean.runs,
            self.multilane_completion_ratio
        )?;
        for t in &self.throughput {
            writeln!(
                f,
                "  {:<9} crossed {:.1} (perfect {:.1}); crossing time x{:.2}",
                t.algorithm, t.crossed_faulty, t.crossed_clean, t.crossing_time_ratio
            )?;
        }
        write!(
            f,
            "  unsafe events on the faulty bus: {}",
            self.faulty_unsafe_events
        )
    }
}
