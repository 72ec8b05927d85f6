//! `host-sim worlds`: worlds of each size (the theorems' sweeps go through
//! [`super::conduct`], as every shardable experiment does).

use super::output::{check_duration, exit, print_json, say, EXIT_BAD_INPUT};
use host_sim::verdict::Judged;
use std::process::ExitCode;

/// `host-sim worlds`.
#[derive(Debug, clap::Args)]
pub struct WorldsArgs {
    /// World sizes (vehicles, comma-separated; each 1 to the 8x8 grid's capacity).
    #[arg(long, value_delimiter = ',', default_value = "100,500,1000,2000,5000")]
    vehicles: Vec<usize>,
    /// Simulated seconds per world.
    #[arg(long, default_value_t = 5.0)]
    duration: f64,
    /// Also run each world with every message delayed by this many seconds and jittered
    /// by up to as many more (at most 10, the loader's bound).
    #[arg(long)]
    delay: Option<f64>,
    /// The invariant every planner keeps toward the vehicle ahead.
    #[arg(long, value_enum, default_value = "paper")]
    invariant: super::InvariantArg,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
}

/// Worlds of each size: no collision, no violation, no blind step.
pub fn worlds(a: WorldsArgs) -> ExitCode {
    if let Err(code) = check_duration(a.duration, 600.0) {
        return code;
    }
    if a.delay
        .is_some_and(|d| !(d.is_finite() && d > 0.0 && d <= 10.0))
    {
        return bad("--delay must be in (0, 10] s");
    }
    if a.vehicles.contains(&0) {
        return bad("--vehicles: every size must be at least 1");
    }
    let r = match host_sim::experiments::worlds::worlds(
        &a.vehicles,
        a.duration,
        a.delay,
        a.invariant.invariant(),
    ) {
        Ok(r) => r,
        Err(e) if e.starts_with("internal") => {
            eprintln!("error: {e}");
            return ExitCode::from(super::output::EXIT_INTERNAL);
        }
        Err(e) => return bad(&e),
    };
    let code = exit(r.verdict());
    let value = match serde_json::to_value(&r) {
        Ok(v) => v,
        Err(e) => return bad(&e.to_string()),
    };
    let printed = if a.json {
        print_json(&value)
    } else {
        let mut text = String::from(
            "| vehicles | grid | delay (s) | sim s | wall s | × real time | cost vs clean | fallback steps | blind | collisions |\n|---|---|---|---|---|---|---|---|---|---|\n",
        );
        for w in &r.worlds {
            text += &format!(
                "| {} | {} | {} | {:.1} | {:.1} | {:.3} | {:.2} | {} | {} | {} |\n",
                w.vehicles,
                w.grid,
                w.delay_s,
                w.sim_seconds,
                w.wall_seconds,
                w.realtime_factor,
                w.cost_vs_clean,
                w.fallback_steps,
                w.blind_steps,
                w.collisions
            );
        }
        say(text.trim_end())
    };
    match printed {
        Ok(()) => code,
        Err(c) => c,
    }
}

fn bad(msg: &str) -> ExitCode {
    eprintln!("error: {msg}");
    ExitCode::from(EXIT_BAD_INPUT)
}
