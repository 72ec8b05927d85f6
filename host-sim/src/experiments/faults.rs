//! Issue 6's question: how much slower do the multi-lane and intersection experiments
//! complete on a faulty bus? Both are run on the same seeds over a perfect bus and over
//! one injecting the given faults, in one command, and compared.

use super::multilane::{experiment, MultilaneReport};
use super::throughput::{throughput, ThroughputReport};
use crate::bus::Faults;
use crate::world::SolverChoice;
use serde::Serialize;

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

/// Runs both experiments on both buses: `seeds` multi-lane runs and `throughput_seeds`
/// throughput runs of `duration` s per algorithm.
pub fn compare(
    faults: Faults,
    seeds: u64,
    throughput_seeds: u64,
    duration: f64,
    threads: usize,
) -> FaultComparison {
    let solver = SolverChoice::Ours;
    let multilane_clean = experiment(seeds, 1, solver, Faults::NONE, threads);
    let multilane_faulty = experiment(seeds, 1, solver, faults, threads);
    let throughput_clean = throughput(throughput_seeds, 1, duration, Faults::NONE, threads);
    let throughput_faulty = throughput(throughput_seeds, 1, duration, faults, threads);
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
    let faulty_unsafe_events = multilane_faulty.collisions
        + multilane_faulty.invariant_violations
        + multilane_faulty.limit_violations
        + throughput_faulty
            .results
            .iter()
            .map(|r| {
                r.collisions + r.invariant_violations + r.limit_violations + r.unpermitted_entries
            })
            .sum::<u64>();
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
