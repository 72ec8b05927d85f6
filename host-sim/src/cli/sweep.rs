//! The theorems' sweeps: `platoons` (Theorem 1), `traffic` (Theorem 2).

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
