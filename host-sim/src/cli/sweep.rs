//! The theorems' sweeps: `platoons` (Theorem 1), `traffic` (Theorem 2), `deadends`
//! (Theorem 3), `crossings` (Theorems 4 and 5).

use super::output::{check_duration, finish};
use std::process::ExitCode;

/// `host-sim platoons`.
#[derive(clap::Args)]
pub struct PlatoonsArgs {
    /// Number of random platoons.
    #[arg(long, default_value_t = 200, value_parser = clap::value_parser!(u64).range(1..))]
    cases: u64,
    /// Seed of the sweep.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
}

/// `host-sim traffic`.
#[derive(clap::Args)]
pub struct TrafficArgs {
    /// Number of random cases.
    #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u64).range(1..))]
    cases: u64,
    /// Seed of the first case.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Simulated seconds per case.
    #[arg(long, default_value_t = 20.0)]
    duration: f64,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
}

/// Theorem 1 sweep.
pub fn platoons(a: PlatoonsArgs) -> ExitCode {
    let s = host_sim::experiments::platoon::sweep(a.cases, a.seed);
    let safe =
        s.collisions + s.invariant_violations + s.limit_violations == 0 && s.cases == a.cases;
    finish(&s, a.json, safe, true)
}

/// Theorem 2 sweep.
pub fn traffic(a: TrafficArgs) -> ExitCode {
    if let Err(code) = check_duration(a.duration, 3600.0) {
        return code;
    }
    let r = host_sim::experiments::multilane::traffic_sweep(a.cases, a.seed, a.duration, 0);
    finish(
        &r,
        a.json,
        r.collisions + r.invariant_violations + r.limit_violations == 0,
        true,
    )
}

/// `host-sim deadends` and `host-sim crossings`.
#[derive(clap::Args)]
pub struct LivenessArgs {
    /// Number of random cases.
    #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u64).range(1..))]
    cases: u64,
    /// Seed of the sweep (a case's own seed depends on this and its index alone).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
}

/// Theorem 3 sweep.
pub fn deadends(a: LivenessArgs) -> ExitCode {
    let r = host_sim::experiments::deadends::sweep(a.cases, 0, a.seed, 0);
    report(&r, a.json, &r.totals, &r.failing)
}

/// Theorems 4–5 sweep.
pub fn crossings(a: LivenessArgs) -> ExitCode {
    let r = host_sim::experiments::crossings::sweep(a.cases, 0, a.seed, 0);
    report(&r, a.json, &r.totals, &r.failing)
}

/// Prints a liveness sweep (the failing cases' scenario files after a human summary) and
/// picks the exit code.
fn report<T: serde::Serialize + std::fmt::Debug>(
    r: &T,
    json: bool,
    t: &host_sim::experiments::sweep::Totals,
    failing: &[host_sim::experiments::sweep::Failing],
) -> ExitCode {
    if json {
        if let Err(code) = super::output::print_json(r) {
            return code;
        }
    } else {
        println!(
            "{} cases, {} vehicles: {} collisions, {} invariant violations, {} limit violations, \
             {} unpermitted entries, {} unfinished vehicles, {} deadlocks; every goal met by \
             {:.1} s at the latest",
            t.cases,
            t.vehicles,
            t.collisions,
            t.invariant_violations,
            t.limit_violations,
            t.unpermitted_entries,
            t.unfinished,
            t.deadlocks,
            t.max_finish_time_s
        );
        for f in failing {
            println!(
                "\n# failing case {} ({}): {}\n{}",
                f.case, f.label, f.reason, f.scenario
            );
        }
    }
    let safe =
        t.collisions + t.invariant_violations + t.limit_violations + t.unpermitted_entries == 0;
    super::output::code(safe, t.unfinished + t.deadlocks == 0)
}
