//! Benchmarks: `scale` (vehicles in real time), `bench-planner` (our solver vs
//! Clarabel) and `bench-can` (the CAN gateway with and without SecOC).

use super::output::{bad_input, finish, out, print_json};
use host_sim::reference::bench::BenchReport;
use std::process::ExitCode;

/// `host-sim scale`.
#[derive(clap::Args)]
pub struct ScaleArgs {
    /// Number of vehicles.
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(1..=1_000_000))]
    vehicles: u64,
    /// Simulated seconds.
    #[arg(long, default_value_t = 10.0)]
    duration: f64,
    /// Vehicles per road (a platoon, or a traffic road's three lanes).
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u64).range(2..=128))]
    platoon: u64,
    /// Three-lane roads of planners changing lanes to random targets at dense spacing,
    /// instead of platoons.
    #[arg(long)]
    traffic: bool,
    /// Instead: platoons and traffic at each of --sweep-vehicles on each of
    /// --sweep-threads, one Markdown table row (or JSON record) each.
    #[arg(long, conflicts_with_all = ["vehicles", "threads", "traffic"])]
    sweep: bool,
    /// With --sweep: vehicle counts (comma-separated).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "500,1000,2000,5000",
        requires = "sweep"
    )]
    sweep_vehicles: Vec<u64>,
    /// With --sweep: thread counts (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "1,2", requires = "sweep")]
    sweep_threads: Vec<usize>,
    /// With --sweep: draw planner steps/s against vehicles (and the real-time line) to a
    /// .png or .svg file.
    #[arg(long, value_name = "out.png|out.svg", requires = "sweep")]
    plot: Option<std::path::PathBuf>,
    /// Worker threads (0 = all cores).
    #[arg(long, default_value_t = 0)]
    threads: usize,
    /// Seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Certified plan reuse: a planner applies its previous plan, shifted, without
    /// solving when it verifies and duality proves it within --reuse-tolerance of the
    /// optimum.
    #[arg(long)]
    reuse: bool,
    /// The planners' speed solver.
    #[arg(long, value_enum, default_value = "ours")]
    solver: super::SolverArg,
    /// The same world twice in one run: with the planner as before its active-set step (the
    /// interior-point solver alone, every step solved) and as set here (--solver,
    /// --reuse), side by side with their ratios.
    #[arg(long, conflicts_with = "sweep")]
    compare: bool,
    /// With --reuse: certified relative sub-optimality allowed per step.
    #[arg(long, default_value_t = planner_core::ReusePolicy::<f64>::default().tolerance)]
    reuse_tolerance: f64,
    /// With --reuse: most consecutive steps without a solve.
    #[arg(long, default_value_t = planner_core::ReusePolicy::<f64>::default().max_age)]
    reuse_max_age: u8,
    /// The invariant every planner keeps toward the vehicle ahead.
    #[arg(long, value_enum, default_value = host_sim::world::DEFAULT_INVARIANT_NAME)]
    pub invariant: super::InvariantArg,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
}

/// `host-sim bench-planner`.
#[derive(clap::Args)]
pub struct BenchArgs {
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
}

/// `host-sim bench-can`.
#[derive(clap::Args)]
pub struct CanBenchArgs {
    /// Messages per configuration (vehicle states, 40 vehicles per 10 ms period).
    #[arg(long, default_value_t = 200_000, value_parser = clap::value_parser!(u64).range(1..=100_000_000))]
    messages: u64,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    json: bool,
}

/// `bench-can`: the four configurations in one run, each against plain classic CAN.
pub fn bench_can(a: CanBenchArgs) -> ExitCode {
    use host_sim::fleet::throughput::measure;
    let mut rows = Vec::new();
    for (fd, secured) in [(false, false), (false, true), (true, false), (true, true)] {
        match measure(a.messages, fd, secured) {
            Ok(r) if r.received == r.messages => rows.push(r),
            Ok(r) => {
                eprintln!(
                    "error: {}: {} of {} messages arrived",
                    r.config, r.received, r.messages
                );
                return ExitCode::FAILURE;
            }
            Err(e) => {
                eprintln!("error: {e}");
                return ExitCode::FAILURE;
            }
        }
    }
    if a.json {
        return match print_json(&serde_json::json!({ "results": rows })) {
            Ok(()) => ExitCode::SUCCESS,
            Err(code) => code,
        };
    }
    let base = rows.first().map_or(1.0, |r| r.messages_per_s);
    out!(
        "{:<14} {:>10} {:>10} {:>14} {:>14} {:>16}",
        "config",
        "messages",
        "frames",
        "messages/s",
        "frames/s",
        "msg/s vs classic"
    );
    for r in &rows {
        out!(
            "{:<14} {:>10} {:>10} {:>14.0} {:>14.0} {:>16.2}",
            r.config,
            r.messages,
            r.frames,
            r.messages_per_s,
            r.frames_per_s,
            r.messages_per_s / base
        );
    }
    ExitCode::SUCCESS
}

/// `scale`.
pub fn scale(a: ScaleArgs) -> ExitCode {
    if !(a.duration > 0.0 && a.duration <= 86_400.0) {
        return bad_input(format!(
            "--duration must be in (0, 86400], got {}",
            a.duration
        ));
    }
    use host_sim::experiments::scale::{compare, run, sweep, Kind, ScaleSettings};
    if !(a.reuse_tolerance.is_finite() && a.reuse_tolerance >= 0.0) {
        return bad_input(format!(
            "--reuse-tolerance must be a finite number ≥ 0, got {}",
            a.reuse_tolerance
        ));
    }
    let policy = planner_core::ReusePolicy {
        tolerance: a.reuse_tolerance,
        max_age: a.reuse_max_age,
    };
    let plot = match super::output::plot_output(a.plot.as_deref()) {
        Ok(p) => p,
        Err(code) => return code,
    };
    if a.sweep_vehicles.iter().any(|&v| v == 0 || v > 1_000_000)
        || a.sweep_threads.iter().any(|&t| t == 0 || t > 1024)
    {
        return bad_input("--sweep-vehicles in 1..=1000000, --sweep-threads in 1..=1024");
    }
    let settings = ScaleSettings {
        kind: if a.traffic {
            Kind::Traffic
        } else {
            Kind::Platoons
        },
        vehicles: a.vehicles as usize,
        duration_s: a.duration,
        per_road: a.platoon as usize,
        threads: a.threads,
        seed: a.seed,
        reuse: a.reuse.then_some(policy),
        solver: a.solver.choice(),
        invariant: a.invariant.invariant(),
    };
    if a.compare {
        let r = compare(&settings);
        return finish(&r, a.json);
    }
    if a.sweep {
        let vehicles: Vec<usize> = a.sweep_vehicles.iter().map(|&v| v as usize).collect();
        let r = sweep(&settings, &vehicles, &a.sweep_threads);
        if let Some(out) = plot {
            if let Err(code) =
                super::output::draw_plot(out, |p| host_sim::output::plot::scale(&r, p))
            {
                return code;
            }
        }
        return finish(&r, a.json);
    }
    let r = run(&settings);
    finish(&r, a.json)
}

/// `bench-planner`.
pub fn bench(a: BenchArgs) -> ExitCode {
    let report = host_sim::reference::bench::run(a.problems as usize, a.seed, a.reps as usize);
    if a.json {
        if let Err(code) = print_json(&report) {
            return code;
        }
        return ExitCode::SUCCESS;
    }
    print_against_clarabel(&report);
    print_against_interior_point(&report);
    print_reuse(&report);
    ExitCode::SUCCESS
}

/// The first table: ours against Clarabel three ways.
fn print_against_clarabel(report: &BenchReport) {
    // Clarabel three ways: setup + solve ("clarabel"), resident with the data updated in
    // place ("resident"), and solve() alone ("solve only"); each speedup is its median over
    // ours, in the same run.
    out!(
        "{:>3} {:>5} {:>8} {:>12} {:>10} {:>14} {:>8} {:>12} {:>8} {:>12} {:>8} {:>10} {:>10} {:>6}",
        "N",
        "mode",
        "problems",
        "ours med µs",
        "ours p99",
        "clarabel med",
        "speedup",
        "resident med",
        "speedup",
        "solve-only",
        "speedup",
        "max gap",
        "max viol",
        "iters"
    );
    for r in &report.results {
        out!(
            "{:>3} {:>5} {:>8} {:>12.2} {:>10.2} {:>14.1} {:>8.1} {:>12.1} {:>8.1} {:>12.1} {:>8.1} {:>10.1e} {:>10.1e} {:>6}",
            r.horizon,
            r.mode,
            r.problems,
            r.planner_median_us,
            r.planner_p99_us,
            r.clarabel_median_us,
            r.speedup,
            r.clarabel_persistent_median_us,
            r.speedup_persistent,
            r.clarabel_solve_only_median_us,
            r.speedup_solve_only,
            r.max_rel_objective_gap.max(r.max_rel_objective_gap_persistent),
            r.max_constraint_violation,
            r.planner_median_iterations
        );
    }
}

/// The second table: ours against our interior-point method alone, same problems.
fn print_against_interior_point(report: &BenchReport) {
    out!(
        "\nours against the interior-point method alone (the solver before its active-set step), same problems:"
    );
    out!(
        "{:>3} {:>5} {:>11} {:>10} {:>8} {:>10} {:>10} {:>8} {:>8} {:>10} {:>6} {:>9}",
        "N",
        "mode",
        "ours med µs",
        "ours p99",
        "p99/med",
        "ipm med µs",
        "ipm p99",
        "p99/med",
        "speedup",
        "act. set",
        "iters",
        "ipm iters"
    );
    for r in &report.results {
        out!(
            "{:>3} {:>5} {:>11.2} {:>10.2} {:>7.2}x {:>10.2} {:>10.2} {:>7.2}x {:>7.2}x {:>9.0}% {:>6} {:>9}",
            r.horizon,
            r.mode,
            r.planner_median_us,
            r.planner_p99_us,
            r.planner_p99_us / r.planner_median_us,
            r.interior_point_median_us,
            r.interior_point_p99_us,
            r.interior_point_p99_us / r.interior_point_median_us,
            r.speedup_vs_interior_point,
            100.0 * r.active_set_share,
            r.planner_median_iterations,
            r.interior_point_median_iterations
        );
    }
}

/// The third table: certified plan reuse against solving every step.
fn print_reuse(report: &BenchReport) {
    out!(
        "\ncertified plan reuse on the warm drive (tolerance {}, at most {} steps without a solve), \
         against solving every step:",
        report.reuse.first().map_or(0.0, |r| r.tolerance),
        report.reuse.first().map_or(0, |r| r.max_age)
    );
    out!(
        "{:>3} {:>6} {:>8} {:>12} {:>12} {:>12} {:>12} {:>8} {:>12} {:>12}",
        "N",
        "steps",
        "reused",
        "iters/step",
        "with reuse",
        "step µs",
        "with reuse",
        "speedup",
        "cost change",
        "max cert."
    );
    for r in &report.reuse {
        out!(
            "{:>3} {:>6} {:>7.1}% {:>12.2} {:>12.2} {:>12.2} {:>12.2} {:>7.2}x {:>11.4}% {:>12.1e}",
            r.horizon,
            r.steps,
            100.0 * r.reused_share,
            r.iterations_per_step,
            r.iterations_per_step_reuse,
            r.step_mean_us,
            r.step_mean_us_reuse,
            r.speedup,
            100.0 * r.closed_loop_cost_change,
            r.max_certified_gap
        );
    }
}
