//! The command line: one file per subcommand.

pub mod bench;
pub mod conduct;
pub mod experiment;
pub mod export;
pub mod fleet;
pub mod output;
pub mod run;

use clap::{Parser, Subcommand, ValueEnum};
use conduct::{conduct, whole, OneCmd, SweepCmd};
use host_sim::experiments as x;
use host_sim::world::SolverChoice;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "host-sim",
    version,
    about = "Runs planner-core instances on the host: traffic on roads and intersections, every \
             vehicle its own planner talking only over a bus; the paper's experiments; sweeps; \
             benchmarks",
    after_help = "Start here: host-sim run scenarios/corridor.toml --html corridor.html\n\n\
                  Exit codes: 0 ok, 1 collision or violation, 2 bad input, 3 liveness goal \
                  missed or deadlock, 4 CAN bus failure (--bus)."
)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Write what the command prints (its JSON or its summary) to FILE instead of
    /// stdout — whole or not at all: a refused or failed run leaves FILE as it was.
    #[arg(long, global = true, value_name = "FILE")]
    output: Option<PathBuf>,
}

/// The planners' solver.
#[derive(Clone, Copy, ValueEnum)]
pub enum SolverArg {
    /// planner-core's solver: the active-set step on warm starts, the interior-point
    /// method behind it.
    Ours,
    /// planner-core's solver as before its active-set step: the interior-point method alone.
    OursInteriorPoint,
    /// Clarabel, the reference solver.
    Clarabel,
}

impl SolverArg {
    pub(crate) fn choice(self) -> SolverChoice {
        match self {
            SolverArg::Ours => SolverChoice::Ours,
            SolverArg::OursInteriorPoint => SolverChoice::OursInteriorPoint,
            SolverArg::Clarabel => SolverChoice::Clarabel,
        }
    }
}

/// The planners' precision.
#[derive(Clone, Copy, ValueEnum)]
pub enum PrecisionArg {
    /// As on a host.
    F64,
    /// As on the Cortex-M4F.
    F32,
}

impl PrecisionArg {
    pub(crate) fn precision(self) -> host_sim::world::precision::Precision {
        match self {
            PrecisionArg::F64 => host_sim::world::precision::Precision::F64,
            PrecisionArg::F32 => host_sim::world::precision::Precision::F32,
        }
    }
}

/// The invariant kept toward the vehicle ahead.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum InvariantArg {
    /// Lemma 3 as the paper writes it: the leader may stop at once.
    Paper,
    /// A cooperating leader heard over V2V is credited with the least distance it still
    /// travels at its braking limit (docs/spec.md).
    LeaderAware,
}

impl InvariantArg {
    pub(crate) fn invariant(self) -> planner_core::Invariant {
        match self {
            InvariantArg::Paper => planner_core::Invariant::Paper,
            InvariantArg::LeaderAware => planner_core::Invariant::LeaderAware,
        }
    }
}

#[derive(Subcommand)]
enum Command {
    /// The main job: runs a scenario file — a road, an intersection or a network of
    /// them — every vehicle its own planner, talking only over the bus.
    Run {
        /// Scenario file (TOML).
        file: PathBuf,
        /// Overrides the scenario's seed.
        #[arg(long)]
        seed: Option<u64>,
        /// Cut the run to this many seconds (more than 0, at most the scenario's
        /// duration_s); a deadline_s past it comes forward to it.
        #[arg(long, value_name = "SECONDS")]
        duration: Option<f64>,
        /// Print one JSON summary object.
        #[arg(long)]
        json: bool,
        /// Write a CSV trace (t,id,x,y,theta,v,omega,lane,target_lane,mode,place,length,width,brake,invariant).
        #[arg(long, value_name = "out.csv")]
        trace: Option<PathBuf>,
        /// Draw trajectories and speeds to a .png or .svg file.
        #[arg(long, value_name = "out.png|out.svg")]
        plot: Option<PathBuf>,
        /// Write the viewer: one self-contained HTML page that plays the run (open it in
        /// a browser; no network needed).
        #[arg(long, value_name = "out.html")]
        html: Option<PathBuf>,
        /// The planners' solver.
        #[arg(long, value_enum, default_value = "ours")]
        solver: SolverArg,
        /// The bus: `in-process` (messages, one task), `can-hub` (CAN frames on an
        /// in-process hub, a task per vehicle and per intersection manager), or a
        /// SocketCAN interface such as `vcan0` (a task and a socket each).
        #[arg(
            long,
            default_value = "in-process",
            value_name = "in-process|can-hub|IFACE"
        )]
        bus: String,
        /// With `--bus`: every message carries a SecOC-style authenticator (AES-128-CMAC,
        /// time-based freshness) and every node accepts only those that verify; keys are
        /// derived from the public simulation master key (docs/security.md).
        #[arg(long)]
        auth: bool,
        /// With `--bus`: authenticate with the keys of this TOML file (`master = "32 hex
        /// digits"` and/or `[nodes]` "0xSA" = "32 hex digits"); implies --auth.
        #[arg(long, value_name = "keys.toml")]
        keys: Option<PathBuf>,
        /// With `--bus`: every message (its authenticator included) goes as one CAN FD
        /// frame instead of up to five classic ones; an interface must carry CAN FD
        /// (vcan: `ip link set vcan0 mtu 72`).
        #[arg(long)]
        can_fd: bool,
        /// Every planner, manager and codec in this precision: `f32` as on the Cortex-M4F
        /// (planner-core's solver), `f64` as on a host.
        #[arg(long, value_enum, default_value = "f64")]
        precision: PrecisionArg,
        /// Every node's clock starts at this uptime (s; 0 to 1e9): 5184000 is 60 days,
        /// 4294967.0 a moment before the wire's 32-bit milliseconds wrap. A run ends as it
        /// does from 0.
        #[arg(long, value_name = "SECONDS", default_value_t = 0.0)]
        clock_start: f64,
        /// The invariant every planner keeps toward the vehicle ahead, over the
        /// scenario's `invariant` key (default: the scenario's, else `paper`).
        #[arg(long, value_enum)]
        invariant: Option<InvariantArg>,
        /// Vehicle computers in the loop: the firmware's `sil` image (firmware-example,
        /// built for --firmware-board) is the computer of each of --firmware-vehicles,
        /// in QEMU, talking serial-line CAN on its UART (docs/firmware.md). A road, the
        /// in-process bus, the paper's invariant, no faults or sensors.
        #[arg(long, value_name = "ELF", requires = "firmware_vehicles")]
        firmware: Option<PathBuf>,
        /// The vehicles (ids) whose computers are --firmware.
        #[arg(
            long,
            value_name = "ID,ID,...",
            value_delimiter = ',',
            requires = "firmware"
        )]
        firmware_vehicles: Vec<u16>,
        /// The QEMU machine --firmware is built for: an386 (Cortex-M4F), an500 (M7) or
        /// an505 (M33).
        #[arg(long, value_name = "BOARD", default_value = "an386")]
        firmware_board: String,
    },
    /// Theorem 1 sweep: random single-lane platoons under adversarial leaders.
    Platoons(SweepCmd<x::platoon::Platoons>),
    /// Theorem 2 sweep: random multi-lane traffic (3–4 lanes, up to 30 vehicles, random
    /// target lanes), every vehicle its own planner.
    Traffic(SweepCmd<x::traffic::Traffic>),
    /// Theorem 3 sweep: random dead-end roads (2–5 lanes, 4–40 vehicles, random targets),
    /// every vehicle to reach its target lane and stop before the end.
    Deadends(SweepCmd<x::deadends::Deadends>),
    /// Theorems 4–5 sweep: random queues at the intersection under every algorithm, every
    /// vehicle to cross.
    Crossings(SweepCmd<x::crossings::Crossings>),
    /// Red team: random queues at the intersection with its manager down from a random
    /// moment for one period to 10 s, under every algorithm: no collision, every vehicle
    /// across.
    Outages(SweepCmd<x::redteam::Outages>),
    /// Red team: random queues with one vehicle lying about its position (±0.2 to ±40 m,
    /// from its first report or from a random moment), under every algorithm: no
    /// collision; what it costs in liveness is reported.
    Liars(SweepCmd<x::redteam::Liars>),
    /// Red team: open arrivals whose ids run through the junction managers' bus nodes:
    /// no vehicle ever gets a node's id, no collision.
    Ids(SweepCmd<x::redteam::Ids>),
    /// Red team: random network files, degenerate ones among them: each refused with its
    /// file and line, or run to its end with no collision, violation or deadlock.
    Layouts(SweepCmd<x::layouts::Layouts>),
    /// Random grids (2×2 to 4×4, 1 to 4 lanes, blocks from the commitment bound up,
    /// demand to saturation and past): no collision, no deadlock (each one reported with
    /// whom every vehicle waits on).
    Grids(SweepCmd<x::network::Grids>),
    /// One world of each size (vehicles placed on the smallest grid that holds them): the
    /// realtime factor, fallbacks and blind steps (a view that overflowed); with
    /// `--delay`, each again on a slow bus, its cost as a ratio to the clean bus's.
    Worlds(OneCmd<x::worlds::Worlds>),
    /// Combines the shards of one sweep or experiment (each run with `--shard I/N`) into
    /// exactly the unsharded result, judged as the unsharded run is: a sweep's counts
    /// add, maxima take the max, means are weighted by cases; an experiment's runs are
    /// aggregated once.
    Merge {
        /// The shards' JSON outputs, one per shard.
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// A scenario in another simulator's format: `export sumo SCENARIO OUTDIR` writes
    /// SUMO plain XML that netconvert builds into the same network.
    #[command(subcommand)]
    Export(export::Export),
    /// The paper's experiments.
    #[command(subcommand)]
    Experiment(experiment::Experiment),
    /// Many vehicles (parallel single-lane platoons) at h = 0.01 on all cores.
    Scale(bench::ScaleArgs),
    /// Our solver and Clarabel on identical instances of (10), N = 20 and 50, cold and warm.
    BenchPlanner(bench::BenchArgs),
    /// The CAN gateway's messages/s and frames/s: classic, classic + SecOC, CAN FD, CAN FD +
    /// SecOC, side by side.
    BenchCan(bench::CanBenchArgs),
}

/// Parses the command line and runs it; with `--output`, what it printed is put in place
/// only when the command ran to its end (exit 0, 1 or 3: a result, safe or not).
pub fn main() -> ExitCode {
    let cli = Cli::parse();
    let out = match cli
        .output
        .as_deref()
        .map(|p| output::staged(p, "--output"))
        .transpose()
    {
        Ok(o) => o,
        Err(code) => return code,
    };
    if out.is_some() {
        output::capture_stdout();
    }
    let code = dispatch(cli.command);
    let Some(mut out) = out else {
        return code;
    };
    let text = output::take_captured().unwrap_or_default();
    let ran = [
        ExitCode::SUCCESS,
        ExitCode::from(output::EXIT_UNSAFE),
        ExitCode::from(output::EXIT_NOT_LIVE),
    ]
    .contains(&code);
    if !ran {
        return code;
    }
    if let Err(e) = out.write_all(text.as_bytes()) {
        return output::bad_input(format!("--output {}: {e}", out.target().display()));
    }
    match output::commit(out, "--output") {
        Ok(()) => code,
        Err(c) => c,
    }
}

fn dispatch(command: Command) -> ExitCode {
    match command {
        Command::Run {
            file,
            seed,
            duration,
            json,
            trace,
            plot,
            html,
            solver,
            bus,
            auth,
            keys,
            can_fd,
            precision,
            clock_start,
            invariant,
            firmware,
            firmware_vehicles,
            firmware_board,
        } => run::run(run::RunArgs {
            file,
            seed,
            duration,
            json,
            trace,
            plot,
            html,
            solver: solver.choice(),
            bus,
            auth: auth || keys.is_some(),
            keys,
            can_fd,
            precision: precision.precision(),
            clock_start,
            invariant: invariant.map(InvariantArg::invariant),
            firmware: firmware.map(|elf| (elf, firmware_board, firmware_vehicles)),
        }),
        Command::Platoons(c) => conduct(&c.settings, c.answer, None),
        Command::Traffic(c) => conduct(&c.settings, c.answer, None),
        Command::Deadends(c) => conduct(&c.settings, c.answer, None),
        Command::Crossings(c) => conduct(&c.settings, c.answer, None),
        Command::Outages(c) => conduct(&c.settings, c.answer, None),
        Command::Liars(c) => conduct(&c.settings, c.answer, None),
        Command::Ids(c) => conduct(&c.settings, c.answer, None),
        Command::Layouts(c) => conduct(&c.settings, c.answer, None),
        Command::Grids(c) => conduct(&c.settings, c.answer, None),
        Command::Worlds(c) => whole(&c.settings, c.json, None),
        Command::Merge { files, json } => conduct::merge(&files, json),
        Command::Experiment(e) => experiment::run(e),
        Command::Export(e) => export::run(e),
        Command::Scale(a) => bench::scale(a),
        Command::BenchPlanner(a) => bench::bench(a),
        Command::BenchCan(a) => bench::bench_can(a),
    }
}
