//! `host-sim`: command-line front end.

use clap::{Parser, Subcommand};
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "host-sim",
    version,
    about = "Runs planner-core on the host: benchmarks and simulations"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Our solver and Clarabel on identical instances of (10), N = 20 and 50, cold and warm.
    BenchPlanner {
        /// Print one JSON object instead of a table.
        #[arg(long)]
        json: bool,
        /// Problems per row (cold: random instances; warm: steps of a simulated drive).
        #[arg(long, default_value_t = 300, value_parser = clap::value_parser!(u64).range(1..=100_000))]
        problems: u64,
        /// Repetitions per problem; the fastest is kept.
        #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u64).range(1..=1000))]
        reps: u64,
        /// Seed of the instances.
        #[arg(long, default_value_t = 7)]
        seed: u64,
    },
    /// Theorem 1 sweep: random single-lane platoons under adversarial leaders.
    Platoons {
        /// Number of random platoons.
        #[arg(long, default_value_t = 200, value_parser = clap::value_parser!(u64).range(1..))]
        cases: u64,
        /// Seed of the sweep.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Command::BenchPlanner {
            json,
            problems,
            reps,
            seed,
        } => {
            let report = host_sim::bench::run(problems as usize, seed, reps as usize);
            if json {
                match serde_json::to_string(&report) {
                    Ok(s) => println!("{s}"),
                    Err(e) => {
                        eprintln!("error: {e}");
                        return ExitCode::FAILURE;
                    }
                }
            } else {
                println!(
                    "{:>3} {:>5} {:>8} {:>12} {:>10} {:>14} {:>8} {:>10} {:>10} {:>6}",
                    "N",
                    "mode",
                    "problems",
                    "ours med µs",
                    "ours p99",
                    "clarabel med",
                    "speedup",
                    "max gap",
                    "max viol",
                    "iters"
                );
                for r in &report.results {
                    println!(
                        "{:>3} {:>5} {:>8} {:>12.2} {:>10.2} {:>14.1} {:>8.1} {:>10.1e} {:>10.1e} {:>6}",
                        r.horizon, r.mode, r.problems, r.planner_median_us, r.planner_p99_us,
                        r.clarabel_median_us, r.speedup, r.max_rel_objective_gap,
                        r.max_constraint_violation, r.planner_median_iterations
                    );
                }
            }
            ExitCode::SUCCESS
        }
        Command::Platoons { cases, seed, json } => host_sim::platoon::sweep_cli(cases, seed, json),
    }
}
