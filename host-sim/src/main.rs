//! `host-sim`: command-line front end.
//!
//! Exit codes: 0 success; 1 a collision or a safety/limit violation was seen; 2 bad
//! input (arguments, scenario file, output file); 3 a liveness goal was missed.

use clap::{Parser, Subcommand, ValueEnum};
use host_sim::bus::Faults;
use host_sim::fleet::{self, Medium};
use host_sim::plot::PlotData;
use host_sim::scenario::Scenario;
use host_sim::sim::{run_scenario, SolverChoice};
use host_sim::trace::TraceWriter;
use std::io::{BufWriter, IsTerminal};
use std::path::PathBuf;
use std::process::ExitCode;

const EXIT_UNSAFE: u8 = 1;
const EXIT_BAD_INPUT: u8 = 2;
const EXIT_NOT_LIVE: u8 = 3;
const EXIT_BUS: u8 = 4;

#[derive(Parser)]
#[command(
    name = "host-sim",
    version,
    about = "Runs planner-core instances on the host: simulations over a bus, benchmarks",
    after_help = "Exit codes: 0 ok, 1 collision or violation, 2 bad input, 3 liveness goal missed, 4 CAN bus failure (--bus)."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Clone, Copy, ValueEnum)]
enum SolverArg {
    /// planner-core's interior-point solver.
    Ours,
    /// Clarabel, the reference solver.
    Clarabel,
}

#[derive(Subcommand)]
enum Command {
    /// Runs a scenario file: every vehicle its own planner, talking only over the bus.
    Run {
        /// Scenario file (TOML).
        file: PathBuf,
        /// Overrides the scenario's seed.
        #[arg(long)]
        seed: Option<u64>,
        /// Print one JSON summary object.
        #[arg(long)]
        json: bool,
        /// Write a CSV trace (t,id,x,y,theta,v,omega,lane,target_lane,mode).
        #[arg(long, value_name = "out.csv")]
        trace: Option<PathBuf>,
        /// Draw trajectories and speeds to a .png or .svg file.
        #[arg(long, value_name = "out.png|out.svg")]
        plot: Option<PathBuf>,
        /// The planners' solver.
        #[arg(long, value_enum, default_value = "ours")]
        solver: SolverArg,
        /// The bus: `in-process` (messages, one task), `can-hub` (CAN frames on an
        /// in-process hub, a task per vehicle), or a SocketCAN interface such as `vcan0`
        /// (a task and a socket per vehicle).
        #[arg(
            long,
            default_value = "in-process",
            value_name = "in-process|can-hub|IFACE"
        )]
        bus: String,
    },
    /// Many vehicles (parallel single-lane platoons) at h = 0.01 on all cores.
    Scale {
        /// Number of vehicles.
        #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(1..=1_000_000))]
        vehicles: u64,
        /// Simulated seconds.
        #[arg(long, default_value_t = 10.0)]
        duration: f64,
        /// Vehicles per road (platoon).
        #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u64).range(2..=128))]
        platoon: u64,
        /// Worker threads (0 = all cores).
        #[arg(long, default_value_t = 0)]
        threads: usize,
        /// Seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
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
    /// The paper's experiments.
    #[command(subcommand)]
    Experiment(Experiment),
    /// Theorem 2 sweep: random multi-lane traffic (3–4 lanes, up to 30 vehicles, random
    /// target lanes), every vehicle its own planner.
    Traffic {
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

fn print_json<T: serde::Serialize>(value: &T) -> Result<(), ExitCode> {
    match serde_json::to_string(value) {
        Ok(s) => {
            println!("{s}");
            Ok(())
        }
        Err(e) => {
            eprintln!("error: {e}");
            Err(ExitCode::from(EXIT_BAD_INPUT))
        }
    }
}

/// Whether a scenario file can run as a fleet on `medium`: no `[faults]` (a fleet
/// carries frames as they are) and every vehicle id a CAN source address.
fn fits_the_bus(
    file: &std::path::Path,
    medium: &Medium,
    no_faults: bool,
    mut ids: impl Iterator<Item = u16>,
) -> Result<(), String> {
    if !no_faults {
        return Err(format!(
            "{}: [faults] are injected by the in-process bus; `--bus {medium}` carries frames as they are",
            file.display()
        ));
    }
    match ids.find_map(|id| host_sim::can::vehicle_address(id).err()) {
        Some(e) => Err(format!("{}: {e}", file.display())),
        None => Ok(()),
    }
}

/// `--bus`: `None` for the in-process message bus, else the CAN medium of a fleet.
fn parse_bus(bus: &str) -> Result<Option<Medium>, String> {
    match bus {
        "in-process" => Ok(None),
        "can-hub" => Ok(Some(Medium::Hub)),
        // Linux interface names: 1 to 15 bytes (IFNAMSIZ − 1), no '/', no white space.
        iface
            if (1..=15).contains(&iface.len())
                && iface
                    .bytes()
                    .all(|b| b.is_ascii_alphanumeric() || b"-_.".contains(&b)) =>
        {
            Ok(Some(Medium::SocketCan(iface.to_string())))
        }
        other => Err(format!(
            "--bus {other:?}: expected in-process, can-hub or a network interface name (1–15 of a-z A-Z 0-9 - _ .)"
        )),
    }
}

fn bad_input(msg: impl std::fmt::Display) -> ExitCode {
    eprintln!("error: {msg}");
    ExitCode::from(EXIT_BAD_INPUT)
}

#[allow(clippy::too_many_arguments)]
fn run(
    file: PathBuf,
    seed: Option<u64>,
    json: bool,
    trace: Option<PathBuf>,
    plot: Option<PathBuf>,
    solver: SolverArg,
    bus: &str,
) -> ExitCode {
    // Every input is checked before anything runs.
    let medium = match parse_bus(bus) {
        Ok(m) => m,
        Err(e) => return bad_input(e),
    };
    if let Some(p) = &plot {
        if !matches!(p.extension().and_then(|e| e.to_str()), Some("png" | "svg")) {
            return bad_input(format!("--plot {}: must end in .png or .svg", p.display()));
        }
    }
    let text = match std::fs::read_to_string(&file) {
        Ok(t) => t,
        Err(e) => return bad_input(format!("{}: cannot read: {e}", file.display())),
    };
    if host_sim::intersection::is_crossing_scenario(&text) {
        return run_crossing(&file, &text, json, plot, trace.is_some(), medium.as_ref());
    }
    let scenario = match Scenario::parse(&text, &file) {
        Ok(s) => s,
        Err(e) => return bad_input(e),
    };
    if let Some(m) = &medium {
        let ids = scenario.vehicles.iter().map(|v| v.id);
        if let Err(e) = fits_the_bus(&file, m, scenario.faults.is_none(), ids) {
            return bad_input(e);
        }
    }
    let mut writer = match &trace {
        Some(p) => match std::fs::File::create(p).and_then(|f| TraceWriter::new(BufWriter::new(f)))
        {
            Ok(w) => Some(w),
            Err(e) => return bad_input(format!("--trace {}: {e}", p.display())),
        },
        None => None,
    };
    let mut plot_data = PlotData {
        lanes: scenario.road.lanes,
        end_x: scenario.road.end_x,
        ..PlotData::default()
    };
    let want_plot = plot.is_some();
    let bar = std::io::stderr().is_terminal().then(|| {
        let b = indicatif::ProgressBar::new(1000);
        b.set_style(
            indicatif::ProgressStyle::with_template(
                "{bar:40} {percent:>3}% {elapsed} / ~{eta} {msg}",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        b
    });
    let name = scenario.name.clone();
    let solver = match solver {
        SolverArg::Ours => SolverChoice::Ours,
        SolverArg::Clarabel => SolverChoice::Clarabel,
    };
    let mut on_row = |row: &host_sim::sim::TraceRow| {
        if let Some(w) = writer.as_mut() {
            w.row(row);
        }
        if want_plot {
            plot_data.add(row);
        }
    };
    let mut on_progress = |done: u64, total: u64| {
        if let Some(b) = &bar {
            b.set_position(done * 1000 / total.max(1));
        }
    };
    let (summary, fleet) = match &medium {
        None => match run_scenario(scenario, solver, seed, &mut on_row, &mut on_progress) {
            Ok(s) => (s, None),
            Err(e) => return bad_input(format!("bus: {e}")),
        },
        Some(m) => match fleet::run(scenario, solver, seed, m, &mut on_row, &mut on_progress) {
            Ok(f) => (f.run.clone(), Some(f)),
            Err(e) => {
                eprintln!("error: --bus {m}: {e}");
                return ExitCode::from(EXIT_BUS);
            }
        },
    };
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    if let Some(w) = writer {
        if let Err(e) = w.finish() {
            return bad_input(format!("--trace: {e}"));
        }
    }
    if let Some(p) = &plot {
        if let Err(e) = host_sim::plot::write(&plot_data, &name, p) {
            return bad_input(e);
        }
    }
    if json {
        let printed = match &fleet {
            Some(f) => print_json(f),
            None => print_json(&summary),
        };
        if let Err(code) = printed {
            return code;
        }
    } else {
        if let Some(f) = &fleet {
            println!(
                "{}: {} tasks, {} SYNC periods; frames sent {}, received {}, rejected {}; \
                 state latency p50 {:.0} µs, p99 {:.0} µs, max {:.0} µs ({} messages)",
                f.medium,
                f.tasks,
                f.periods,
                f.can.frames_sent,
                f.can.frames_received,
                f.can.rejected_total(),
                f.state_latency.p50_us,
                f.state_latency.p99_us,
                f.state_latency.max_us,
                f.state_latency.count
            );
        }
        println!(
            "{}: {} vehicles, {:.2} s simulated in {:.2} s; collisions {}, invariant violations {}, \
             limit violations {}, road-end overruns {}, min gap {:.3} m, fallback steps {}, waiting steps {}, goals {}/{}{}",
            summary.scenario,
            summary.vehicles,
            summary.sim_seconds,
            summary.wall_seconds,
            summary.collisions,
            summary.invariant_violations,
            summary.limit_violations,
            summary.road_end_overruns,
            summary.min_gap_m,
            summary.fallback_steps,
            summary.waiting_steps,
            summary.goals_reached,
            summary.goals,
            if summary.completed { " (completed)" } else { " (NOT completed)" }
        );
    }
    if summary.collisions
        + summary.invariant_violations
        + summary.limit_violations
        + summary.road_end_overruns
        > 0
    {
        ExitCode::from(EXIT_UNSAFE)
    } else if !summary.completed {
        ExitCode::from(EXIT_NOT_LIVE)
    } else {
        ExitCode::SUCCESS
    }
}

#[derive(Subcommand)]
enum Experiment {
    /// Fig. 9: closed system of 8 vehicles at the SPEC §8 intersection; STOP, FIFO, CON,
    /// the starvation-free CON and the pipelined algorithm on identical seeds.
    Throughput {
        /// Simulated seconds per run.
        #[arg(long, default_value_t = 300.0)]
        duration: f64,
        /// Runs per algorithm (seeds from --seed).
        #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..))]
        seeds: u64,
        /// First seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
        /// Draw a Fig. 9-style bar chart to a .png or .svg file.
        #[arg(long, value_name = "out.png|out.svg")]
        plot: Option<PathBuf>,
        #[command(flatten)]
        faults: FaultArgs,
    },
    /// Issue 6: the multi-lane and throughput experiments on a perfect bus and on a
    /// faulty one (default 20 % loss, 50 ms delay), same seeds, compared.
    Faults {
        /// Multi-lane runs (seeds 1..=K).
        #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u64).range(1..))]
        seeds: u64,
        /// Throughput runs per algorithm (seeds 1..=K).
        #[arg(long, default_value_t = 4, value_parser = clap::value_parser!(u64).range(1..))]
        throughput_seeds: u64,
        /// Simulated seconds per throughput run.
        #[arg(long, default_value_t = 300.0)]
        duration: f64,
        /// Probability that a receiver loses a message.
        #[arg(long, default_value_t = 0.2)]
        loss: f64,
        /// Delivery delay (s).
        #[arg(long, default_value_t = 0.05)]
        delay: f64,
        /// Extra delay drawn uniformly from [0, jitter] (s).
        #[arg(long, default_value_t = 0.0)]
        jitter: f64,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Fig. 6/7: 3 lanes, 6 vehicles at 15 m/s, random target lanes, one run per seed.
    Multilane {
        /// Number of runs (seeds 1..=K, or from --seed).
        #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u64).range(1..))]
        seeds: u64,
        /// First seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
        /// Draw the first run's trajectories (Fig. 7 style) to a .png or .svg file.
        #[arg(long, value_name = "out.png|out.svg")]
        plot: Option<PathBuf>,
        /// The planners' solver.
        #[arg(long, value_enum, default_value = "ours")]
        solver: SolverArg,
        #[command(flatten)]
        faults: FaultArgs,
    },
}

/// Faults for an experiment's bus (none by default).
#[derive(clap::Args, Debug, Clone, Copy)]
struct FaultArgs {
    /// Probability that a receiver loses a message.
    #[arg(long, default_value_t = 0.0)]
    loss: f64,
    /// Delivery delay (s).
    #[arg(long, default_value_t = 0.0)]
    delay: f64,
    /// Extra delay drawn uniformly from [0, jitter] (s).
    #[arg(long, default_value_t = 0.0)]
    jitter: f64,
    /// Probability that a receiver gets a message twice.
    #[arg(long, default_value_t = 0.0)]
    duplicate: f64,
    /// Probability that a message is held back 20 ms (later ones overtake it).
    #[arg(long, default_value_t = 0.0)]
    reorder: f64,
}

impl FaultArgs {
    fn faults(&self) -> Result<Faults, String> {
        let f = Faults {
            loss: self.loss,
            delay_s: self.delay,
            jitter_s: self.jitter,
            duplicate: self.duplicate,
            reorder: self.reorder,
            ..Faults::NONE
        };
        f.validate().map(|()| f).map_err(|e| {
            // Name the flags, not the scenario keys.
            e.replace("faults.", "--").replace("_s ", " ")
        })
    }
}

/// Prints a result (one JSON object, or its debug form) and picks the exit code.
fn finish<T: serde::Serialize + std::fmt::Debug>(
    r: &T,
    json: bool,
    safe: bool,
    live: bool,
) -> ExitCode {
    if json {
        if let Err(code) = print_json(r) {
            return code;
        }
    } else {
        println!("{r:#?}");
    }
    if !safe {
        ExitCode::from(EXIT_UNSAFE)
    } else if !live {
        ExitCode::from(EXIT_NOT_LIVE)
    } else {
        ExitCode::SUCCESS
    }
}

/// `host-sim run` on an intersection scenario (a file with an `[intersection]` table),
/// on the in-process bus or, with `medium`, as a fleet of tasks on CAN.
fn run_crossing(
    file: &std::path::Path,
    text: &str,
    json: bool,
    plot: Option<PathBuf>,
    trace: bool,
    medium: Option<&Medium>,
) -> ExitCode {
    if trace {
        return bad_input("--trace is not available for intersection scenarios (yet)");
    }
    let sc = match host_sim::intersection::CrossingScenario::parse(text, file) {
        Ok(s) => s,
        Err(e) => return bad_input(e),
    };
    if let Some(m) = medium {
        let ids = sc.placements.iter().map(|p| p.id);
        if let Err(e) = fits_the_bus(file, m, sc.faults.is_none(), ids) {
            return bad_input(e);
        }
    }
    let mut data = PlotData::default();
    let t0 = std::time::Instant::now();
    let mut sample = |t: f64, poses: &[host_sim::intersection::PoseSample]| {
        if plot.is_some() && ((t * 100.0).round() as i64) % 10 == 0 {
            for &(id, x, y, th, v) in poses {
                data.series.entry(id).or_default().push((t, x, y, th, v));
            }
        }
    };
    let (summary, fleet) = match medium {
        None => (sc.run(&mut sample), None),
        Some(m) => match host_sim::crossing_fleet::run(&sc, m, &mut sample, &mut |_, _| {}) {
            Ok(f) => (f.run.clone(), Some(f)),
            Err(e) => {
                eprintln!("error: --bus {m}: {e}");
                return ExitCode::from(EXIT_BUS);
            }
        },
    };
    if let Some(path) = &plot {
        if let Err(e) = host_sim::plot::crossing(&data, &sc.layout, &sc.name, path) {
            eprintln!("error: {e}");
            return ExitCode::from(EXIT_UNSAFE);
        }
    }
    let completed = summary.in_system == 0;
    if json {
        /// The run (in-process, or the fleet's with its CAN figures) and the scenario.
        #[derive(serde::Serialize)]
        struct Out<'a, S: serde::Serialize> {
            scenario: &'a str,
            vehicles: usize,
            completed: bool,
            #[serde(flatten)]
            run: &'a S,
            wall_seconds: f64,
        }
        let (scenario, vehicles) = (sc.name.as_str(), sc.placements.len());
        let wall_seconds = t0.elapsed().as_secs_f64();
        let printed = match &fleet {
            Some(f) => print_json(&Out {
                scenario,
                vehicles,
                completed,
                run: f,
                wall_seconds,
            }),
            None => print_json(&Out {
                scenario,
                vehicles,
                completed,
                run: &summary,
                wall_seconds,
            }),
        };
        if let Err(code) = printed {
            return code;
        }
    } else {
        if let Some(f) = &fleet {
            println!(
                "{}: {} tasks (vehicles and the manager), {} periods of 2 SYNC ticks; {} requests, \
                 {} grants, {} exits; frames sent {}, received {}, rejected {}; request latency \
                 p50 {:.0} µs, p99 {:.0} µs, max {:.0} µs; grant latency p50 {:.0} µs, p99 {:.0} µs",
                f.medium,
                f.tasks,
                f.periods,
                f.messages.requests,
                f.messages.grants,
                f.messages.exits,
                f.can.frames_sent,
                f.can.frames_received,
                f.can.rejected_total(),
                f.request_latency.p50_us,
                f.request_latency.p99_us,
                f.request_latency.max_us,
                f.grant_latency.p50_us,
                f.grant_latency.p99_us,
            );
        }
        println!(
            "{}: {} vehicles, {} crossed in {:.2} s ({}); collisions {}, invariant violations {}, \
             entries without permission {}",
            sc.name,
            sc.placements.len(),
            summary.crossed,
            summary.sim_seconds,
            summary.algorithm,
            summary.collisions,
            summary.invariant_violations,
            summary.unpermitted_entries
        );
    }
    if summary.collisions
        + summary.invariant_violations
        + summary.limit_violations
        + summary.unpermitted_entries
        > 0
    {
        ExitCode::from(EXIT_UNSAFE)
    } else if !completed {
        ExitCode::from(EXIT_NOT_LIVE)
    } else {
        ExitCode::SUCCESS
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Command::Run {
            file,
            seed,
            json,
            trace,
            plot,
            solver,
            bus,
        } => run(file, seed, json, trace, plot, solver, &bus),
        Command::Scale {
            vehicles,
            duration,
            platoon,
            threads,
            seed,
            json,
        } => {
            if !(duration > 0.0 && duration <= 86_400.0) {
                return bad_input(format!("--duration must be in (0, 86400], got {duration}"));
            }
            let r =
                host_sim::scale::run(vehicles as usize, duration, platoon as usize, threads, seed);
            finish(
                &r,
                json,
                r.collisions + r.invariant_violations + r.limit_violations == 0,
                true,
            )
        }
        Command::BenchPlanner {
            json,
            problems,
            reps,
            seed,
        } => {
            let report = host_sim::bench::run(problems as usize, seed, reps as usize);
            if json {
                if let Err(code) = print_json(&report) {
                    return code;
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
                        r.horizon,
                        r.mode,
                        r.problems,
                        r.planner_median_us,
                        r.planner_p99_us,
                        r.clarabel_median_us,
                        r.speedup,
                        r.max_rel_objective_gap,
                        r.max_constraint_violation,
                        r.planner_median_iterations
                    );
                }
            }
            ExitCode::SUCCESS
        }
        Command::Experiment(Experiment::Multilane {
            seeds,
            seed,
            json,
            plot,
            solver,
            faults,
        }) => {
            let faults = match faults.faults() {
                Ok(f) => f,
                Err(e) => return bad_input(e),
            };
            let solver = match solver {
                SolverArg::Ours => SolverChoice::Ours,
                SolverArg::Clarabel => SolverChoice::Clarabel,
            };
            if let Some(p) = &plot {
                if !matches!(p.extension().and_then(|e| e.to_str()), Some("png" | "svg")) {
                    return bad_input(format!("--plot {}: must end in .png or .svg", p.display()));
                }
            }
            let r = host_sim::multilane::experiment(seeds, seed, solver, faults, 0);
            if let Some(path) = plot {
                let sc = host_sim::multilane::paper_scenario(seed);
                let name = format!("{} (Fig. 7 style)", sc.name);
                // The manoeuvres are over well within 12 s (Fig. 7 shows the same window).
                let mut data = PlotData {
                    lanes: sc.road.lanes,
                    end_x: sc.road.end_x,
                    until_s: Some(12.0),
                    ..PlotData::default()
                };
                host_sim::multilane::run_one(sc, solver, &mut |r| data.add(r));
                if let Err(e) = host_sim::plot::write(&data, &name, &path) {
                    eprintln!("error: {e}");
                    return ExitCode::from(EXIT_UNSAFE);
                }
            }
            finish(
                &r,
                json,
                r.collisions + r.invariant_violations + r.limit_violations == 0,
                r.completed == r.runs,
            )
        }
        Command::Experiment(Experiment::Faults {
            seeds,
            throughput_seeds,
            duration,
            loss,
            delay,
            jitter,
            json,
        }) => {
            let args = FaultArgs {
                loss,
                delay,
                jitter,
                duplicate: 0.0,
                reorder: 0.0,
            };
            let faults = match args.faults() {
                Ok(f) => f,
                Err(e) => return bad_input(e),
            };
            if !(duration > 0.0 && duration <= 3600.0) {
                return bad_input(format!("--duration must be in (0, 3600], got {duration}"));
            }
            let r = host_sim::faulty::compare(faults, seeds, throughput_seeds, duration, 0);
            let live = r.multilane_faulty.completed == r.multilane_faulty.runs;
            finish(&r, json, r.faulty_unsafe_events == 0, live)
        }
        Command::Experiment(Experiment::Throughput {
            duration,
            seeds,
            seed,
            json,
            plot,
            faults,
        }) => {
            let faults = match faults.faults() {
                Ok(f) => f,
                Err(e) => return bad_input(e),
            };
            if !(duration > 0.0 && duration <= 3600.0) {
                return bad_input(format!("--duration must be in (0, 3600], got {duration}"));
            }
            if let Some(p) = &plot {
                if !matches!(p.extension().and_then(|e| e.to_str()), Some("png" | "svg")) {
                    return bad_input(format!("--plot {}: must end in .png or .svg", p.display()));
                }
            }
            let r = host_sim::intersection::throughput(seeds, seed, duration, faults, 0);
            if let Some(path) = plot {
                if let Err(e) = host_sim::plot::bars(&r, &path) {
                    eprintln!("error: {e}");
                    return ExitCode::from(EXIT_UNSAFE);
                }
            }
            finish(
                &r,
                json,
                r.results.iter().all(|x| {
                    x.collisions
                        + x.invariant_violations
                        + x.limit_violations
                        + x.unpermitted_entries
                        == 0
                }),
                true,
            )
        }
        Command::Traffic {
            cases,
            seed,
            duration,
            json,
        } => {
            if !(duration > 0.0 && duration <= 3600.0) {
                return bad_input(format!("--duration must be in (0, 3600], got {duration}"));
            }
            let r = host_sim::multilane::traffic_sweep(cases, seed, duration, 0);
            finish(
                &r,
                json,
                r.collisions + r.invariant_violations + r.limit_violations == 0,
                true,
            )
        }
        Command::Platoons { cases, seed, json } => {
            let s = host_sim::platoon::sweep(cases, seed);
            finish(
                &s,
                json,
                s.collisions + s.invariant_violations + s.limit_violations == 0 && s.cases == cases,
                true,
            )
        }
    }
}
