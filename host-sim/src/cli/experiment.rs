//! `host-sim experiment …`: the paper's figures and the fault experiment; each shardable
//! one's settings are its own type in `host_sim::experiments`, flattened here, and run
//! through [`conduct`].

use super::conduct::{conduct, Answer};
use super::output::{bad_input, finish, print_json};
use host_sim::experiments::demand::DemandSettings;
use host_sim::experiments::fault_grid::{GridCells, GridSettings};
use host_sim::experiments::faults::FaultSettings;
use host_sim::experiments::multilane::{MultilaneReport, MultilaneSettings};
use host_sim::experiments::throughput::ThroughputSettings;
use host_sim::output::plot::PlotData;
use host_sim::verdict::Judged;
use planner_core::crossing::Algorithm;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// The experiments.
#[derive(clap::Subcommand)]
pub enum Experiment {
    /// What one lane carries at a speed, flowing and discharging a standing queue, under
    /// the paper's invariant and the leader-aware one (bench/sumo/lane_capacity.py runs
    /// the same road in SUMO, side by side).
    LaneCapacity(LaneCapacityArgs),
    /// Fig. 9: closed system of 8 vehicles at the SPEC §8 intersection; every algorithm
    /// (STOP, STOP-1, FIFO, CON, CON-fair, PIPE, PLATOON) on identical seeds.
    Throughput(ThroughputCmd),
    /// The multi-lane and throughput experiments on a perfect bus and on a faulty one
    /// (default 20 % loss, 50 ms delay), same seeds, compared.
    Faults(FaultsCmd),
    /// Open-system demand at the SPEC §8 intersection: Poisson arrivals at every inlet
    /// lane; per algorithm and rate, throughput, delay and queues, and each algorithm's
    /// capacity.
    Demand(DemandCmd),
    /// Open-system traffic on a grid of intersections: Poisson arrivals at every boundary
    /// inlet with random boundary destinations; trips, delays, safety and the realtime
    /// factor.
    Network {
        /// Rows x columns of intersections, e.g. 3x3.
        #[arg(long, default_value = "3x3", value_parser = parse_grid)]
        grid: (u8, u8),
        /// Arrivals per boundary inlet, vehicles per hour (spread over its lanes).
        #[arg(long, default_value_t = 300.0)]
        rate: f64,
        /// Simulated seconds.
        #[arg(long, default_value_t = 600.0)]
        duration: f64,
        /// Seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Centre-to-centre distance of intersections (m).
        #[arg(long, default_value_t = 300.0)]
        block: f64,
        /// Lanes per direction.
        #[arg(long, default_value_t = 2)]
        lanes: u8,
        /// The invariant every planner keeps toward the vehicle ahead.
        #[arg(long, value_enum, default_value = "paper")]
        invariant: super::InvariantArg,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// The threat model's attacks on the Fig. 8 intersection and the multi-lane road, each a fleet
    /// on CAN with every node authenticating: forged grant, replayed grant, replayed
    /// state, spoofed id, flood, a lying vehicle, the manager's crash and restart (exit 1
    /// on a forgery or replay accepted, or an unsafe event).
    Attacks(AttacksArgs),
    /// Fig. 6/7: 3 lanes, 6 vehicles at 15 m/s, random target lanes, one run per seed.
    Multilane(MultilaneCmd),
}

/// `experiment multilane`.
#[derive(clap::Args)]
pub struct MultilaneCmd {
    #[command(flatten)]
    settings: MultilaneSettings,
    #[command(flatten)]
    answer: Answer,
    /// Draw the first run's trajectories (Fig. 7 style) to a .png or .svg file.
    #[arg(long, value_name = "out.png|out.svg", conflicts_with = "shard")]
    plot: Option<PathBuf>,
}

/// `experiment throughput`.
#[derive(clap::Args)]
pub struct ThroughputCmd {
    #[command(flatten)]
    settings: ThroughputSettings,
    #[command(flatten)]
    answer: Answer,
    /// Draw a Fig. 9-style bar chart to a .png or .svg file.
    #[arg(long, value_name = "out.png|out.svg", conflicts_with = "shard")]
    plot: Option<PathBuf>,
}

/// `experiment faults`: the comparison, or with `--grid` the fault grid.
#[derive(clap::Args)]
pub struct FaultsCmd {
    #[command(flatten)]
    settings: FaultSettings,
    /// Instead: the fault grid — loss × delay, then jitter, duplicates, reordering and
    /// a vehicle silent from t = 0, each cell over the multi-lane road, a fully braking
    /// platoon leader, drivers that do not cooperate and the intersection under every
    /// algorithm (exit 1 if any cell saw an unsafe event).
    #[arg(long, conflicts_with_all = ["loss", "delay", "jitter", "throughput_seeds", "duration"])]
    grid: bool,
    #[command(flatten)]
    cells: GridCells,
    /// With --grid: draw the heat maps (completion per cell and workload, unsafe
    /// events printed in each cell) to a .png or .svg.
    #[arg(
        long,
        value_name = "out.png|out.svg",
        requires = "grid",
        conflicts_with = "shard"
    )]
    plot: Option<PathBuf>,
    #[command(flatten)]
    answer: Answer,
}

/// `experiment demand`.
#[derive(clap::Args)]
pub struct DemandCmd {
    #[command(flatten)]
    settings: DemandSettings,
    #[command(flatten)]
    answer: Answer,
    /// Draw mean delay against demand, one curve per algorithm, to a .png or .svg.
    #[arg(long, value_name = "out.png|out.svg", conflicts_with = "shard")]
    plot: Option<PathBuf>,
}

/// Runs an experiment.
pub fn run(e: Experiment) -> ExitCode {
    match e {
        Experiment::Attacks(a) => attacks(a),
        Experiment::Multilane(c) => {
            let draw = |_: &MultilaneReport, p: &Path| fig7(&c.settings, p);
            conduct(
                &c.settings,
                c.answer,
                c.plot.as_ref().map(|p| (p, &draw as _)),
            )
        }
        Experiment::Faults(c) if c.grid => {
            let g = GridSettings::new(c.cells, c.settings.invariant);
            let draw = |r: &_, p: &Path| {
                host_sim::output::plot::fault_grid(r, p).map_err(|e| e.to_string())
            };
            conduct(&g, c.answer, c.plot.as_ref().map(|p| (p, &draw as _)))
        }
        Experiment::Faults(c) => conduct(&c.settings, c.answer, None),
        Experiment::LaneCapacity(a) => lane_capacity(&a),
        Experiment::Throughput(c) => {
            let draw =
                |r: &_, p: &Path| host_sim::output::plot::bars(r, p).map_err(|e| e.to_string());
            conduct(
                &c.settings,
                c.answer,
                c.plot.as_ref().map(|p| (p, &draw as _)),
            )
        }
        Experiment::Network {
            grid,
            rate,
            duration,
            seed,
            block,
            lanes,
            invariant,
            json,
        } => network(
            &host_sim::experiments::network::NetworkSettings {
                rows: grid.0,
                cols: grid.1,
                block_m: block,
                lanes,
                rate_vph: rate,
                duration_s: duration,
                seed,
                invariant: invariant.invariant(),
            },
            json,
        ),
        Experiment::Demand(c) => {
            let draw =
                |r: &_, p: &Path| host_sim::output::plot::demand(r, p).map_err(|e| e.to_string());
            conduct(
                &c.settings,
                c.answer,
                c.plot.as_ref().map(|p| (p, &draw as _)),
            )
        }
    }
}

/// Fig. 7: the first run's trajectories (seed `s.seed`), the manoeuvres' 12 s.
fn fig7(s: &MultilaneSettings, path: &Path) -> Result<(), String> {
    let sc = host_sim::experiments::multilane::paper_scenario(s.seed);
    let name = format!("{} (Fig. 7 style)", sc.name);
    let mut world = sc.world();
    world.invariant = s.invariant;
    // The manoeuvres are over well within 12 s (Fig. 7 shows the same window).
    let mut data = PlotData {
        until_s: Some(12.0),
        ..PlotData::of(&world.network)
    };
    host_sim::experiments::multilane::run_one(world, s.solver, &mut |r| data.add(r));
    host_sim::output::plot::write(&data, &name, path).map_err(|e| e.to_string())
}

/// "RxC" → (R, C), each 1..=8.
fn parse_grid(s: &str) -> Result<(u8, u8), String> {
    let bad = || format!("{s}: rows x columns, e.g. 3x3, each 1 to 8");
    let (r, c) = s.split_once(['x', 'X']).ok_or_else(bad)?;
    let (r, c): (u8, u8) = (
        r.trim().parse().map_err(|_| bad())?,
        c.trim().parse().map_err(|_| bad())?,
    );
    if (1..=8).contains(&r) && (1..=8).contains(&c) {
        Ok((r, c))
    } else {
        Err(bad())
    }
}

fn network(s: &host_sim::experiments::network::NetworkSettings, json: bool) -> ExitCode {
    if !(s.rate_vph > 0.0 && s.rate_vph <= 3600.0) {
        return bad_input("--rate: vehicles per hour per boundary inlet, in (0, 3600]");
    }
    if let Err(e) = host_sim::experiments::experiment::duration_within(s.duration_s, 7200.0) {
        return bad_input(e);
    }
    // The grid is checked by the scenario loader before anything runs.
    if let Err(e) = s.world() {
        return bad_input(e);
    }
    let r = match host_sim::experiments::network::run(s) {
        Ok(r) => r,
        Err(e) => return bad_input(e),
    };
    finish(&r, json)
}

/// `experiment attacks`: checks every flag, runs, prints; exit 1 when a forgery or replay
/// got through (authenticated runs only: without authentication they are expected to)
/// or a row saw an unsafe event, exit 3 when a row other than the liar's left a vehicle
/// undone.
/// `experiment attacks`.
#[derive(clap::Args)]
pub struct AttacksArgs {
    /// The fleets' medium: `can-hub` or a SocketCAN interface such as `vcan0`.
    #[arg(long, default_value = "can-hub")]
    bus: String,
    /// Run without authentication, to see what it keeps out.
    #[arg(long)]
    without_auth: bool,
    /// Every message as one CAN FD frame.
    #[arg(long)]
    can_fd: bool,
    /// The intersection's algorithm (STOP, STOP-1, FIFO, CON-fair, PIPE, PLATOON).
    #[arg(long, default_value = "FIFO")]
    algorithm: String,
    /// Only these rows (comma-separated): forged-grant, replayed-grant,
    /// replayed-state, spoofed-id, flood, lying-vehicle, manager-crash.
    #[arg(long, value_delimiter = ',')]
    only: Vec<String>,
    /// Only these worlds (comma-separated): intersection, multilane.
    #[arg(long, value_delimiter = ',')]
    world: Vec<String>,
    /// Skip each world's run without an attack (its `clean_*` figures are then null).
    #[arg(long)]
    no_baseline: bool,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
    /// The invariant every planner keeps toward the vehicle ahead.
    #[arg(long, value_enum, default_value = "paper")]
    invariant: super::InvariantArg,
}

fn attacks(a: AttacksArgs) -> ExitCode {
    use host_sim::experiments::attacks::{experiment, row_names, Settings, WORLDS};
    let (authenticated, algorithm, only, worlds) = (!a.without_auth, &a.algorithm, a.only, a.world);
    let medium = match super::fleet::medium(&a.bus) {
        Ok(m) => m,
        Err(e) => return bad_input(e),
    };
    let Some(&algorithm) = Algorithm::ALL
        .iter()
        .find(|a| a.name().eq_ignore_ascii_case(algorithm))
        .filter(|a| **a != Algorithm::Concurrent)
    else {
        return bad_input(format!(
            "--algorithm: {algorithm:?} is not a live algorithm (STOP, STOP-1, FIFO, CON-fair, PIPE, PLATOON)"
        ));
    };
    let names = row_names();
    if let Some(bad) = only.iter().find(|o| !names.contains(&o.as_str())) {
        return bad_input(format!(
            "--only: unknown row {bad:?} ({})",
            names.join(", ")
        ));
    }
    if let Some(bad) = worlds.iter().find(|w| !WORLDS.contains(&w.as_str())) {
        return bad_input(format!("--world: unknown {bad:?} ({})", WORLDS.join(", ")));
    }
    let settings = Settings {
        medium,
        authenticated,
        fd: a.can_fd,
        algorithm,
        only,
        worlds,
        baseline: !a.no_baseline,
        invariant: a.invariant.invariant(),
    };
    let report = match experiment(&settings) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::from(super::output::EXIT_BUS);
        }
    };
    // Forgeries, replays, spoofs and floods that got through count as breaches where the
    // nodes authenticate; a liar's cost in liveness is reported, not required away.
    finish(&AttacksText(&report), a.json)
}

/// `experiment attacks`'s table for a terminal.
struct AttacksText<'a>(&'a host_sim::experiments::attacks::AttackReport);

impl Judged for AttacksText<'_> {
    fn verdict(&self) -> host_sim::verdict::Verdict {
        self.0.verdict()
    }
}

impl serde::Serialize for AttacksText<'_> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        self.0.serialize(s)
    }
}

impl std::fmt::Display for AttacksText<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let r = self.0;
        writeln!(
            f,
            "attacks on {} (authenticated: {}, CAN FD: {}, intersection {})",
            r.medium, r.authenticated, r.can_fd, r.algorithm
        )?;
        writeln!(
            f,
            "{:<15} {:<13} {:>8} {:>8} {:>6} {:>6} {:>6} {:>5} {:>9} {:>9}",
            "attack",
            "world",
            "attempts",
            "accepted",
            "coll",
            "viol",
            "unperm",
            "done",
            "done at",
            "clean"
        )?;
        let s = |x: Option<f64>| x.map_or("-".into(), |v| format!("{v:.1} s"));
        for x in &r.results {
            writeln!(
                f,
                "{:<15} {:<13} {:>8} {:>8} {:>6} {:>6} {:>6} {:>5} {:>9} {:>9}",
                x.attack,
                x.scenario,
                x.attempts,
                x.accepted,
                x.collisions,
                x.invariant_violations,
                x.unpermitted_entries,
                format!("{}/{}", x.done, x.vehicles),
                s(x.done_at_s),
                s(x.clean_done_at_s)
            )?;
        }
        Ok(())
    }
}

/// `host-sim experiment lane-capacity`.
#[derive(clap::Args)]
pub struct LaneCapacityArgs {
    /// Speeds (m/s), comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "13.9,27.8")]
    speeds: Vec<f64>,
    /// The invariant (default: both, side by side).
    #[arg(long, value_enum)]
    invariant: Option<super::InvariantArg>,
    /// Vehicles per run (the first four are not counted).
    #[arg(long, default_value_t = 30, value_parser = clap::value_parser!(u16).range(6..=200))]
    vehicles: u16,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
}

/// `experiment lane-capacity`: every speed, both settings, the invariants asked for; the
/// exit code of its verdict.
fn lane_capacity(a: &LaneCapacityArgs) -> ExitCode {
    use host_sim::experiments::lane_capacity as lc;
    let (speeds, invariant, vehicles, json) = (&a.speeds, a.invariant, a.vehicles, a.json);
    if let Some(v) = speeds.iter().find(|v| !(**v > 0.0 && **v <= 27.8)) {
        return bad_input(format!("--speeds: each in (0, 27.8] m/s, got {v}"));
    }
    let invariants: Vec<planner_core::Invariant> = match invariant {
        Some(i) => vec![i.invariant()],
        None => vec![
            planner_core::Invariant::Paper,
            planner_core::Invariant::LeaderAware,
        ],
    };
    let report = match lc::lane_capacity(speeds, &invariants, usize::from(vehicles)) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("error: internal: lane-capacity: {e} (a bug: please report it)");
            return ExitCode::from(super::output::EXIT_INTERNAL);
        }
    };
    let printed = if json {
        print_json(&report)
    } else {
        super::output::say(&capacity_table(&report))
    };
    if let Err(code) = printed {
        return code;
    }
    let v = report.verdict();
    if !v.is_safe() {
        let runs = report.results.iter();
        let unsafe_runs = runs
            .filter(|r| r.collisions + r.invariant_violations + r.limit_violations > 0)
            .count();
        eprintln!("{unsafe_runs} run(s) with a collision or a violation");
    }
    super::output::exit(v)
}

/// `experiment lane-capacity`'s table (Markdown, as docs/capacity.md shows it).
fn capacity_table(report: &host_sim::experiments::lane_capacity::CapacityReport) -> String {
    let mut t = String::from(
        "| speed (m/s) | mode | invariant | veh/h | mean headway (s) | collisions | invariant violations | fallback steps |\n|---|---|---|---|---|---|---|---|",
    );
    for r in &report.results {
        t += &format!(
            "\n| {} | {} | {} | {:.0} | {:.3} | {} | {} | {} |",
            r.speed_mps,
            r.mode.name(),
            r.invariant,
            r.flow_vph,
            r.mean_headway_s,
            r.collisions,
            r.invariant_violations,
            r.fallback_steps
        );
    }
    t
}
