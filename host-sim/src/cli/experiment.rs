//! `host-sim experiment …`: the paper's figures and the fault experiment; each shardable
//! one's settings are its own type in `host_sim::experiments`, flattened here, and run
//! through [`conduct`].

use super::conduct::{conduct, whole, Answer, OneCmd};
use host_sim::experiments::demand::DemandSettings;
use host_sim::experiments::fault_grid::{GridCells, GridSettings};
use host_sim::experiments::faults::FaultSettings;
use host_sim::experiments::multilane::{MultilaneReport, MultilaneSettings};
use host_sim::experiments::throughput::ThroughputSettings;
use host_sim::output::plot::PlotData;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// The experiments.
#[derive(clap::Subcommand)]
pub enum Experiment {
    /// What one lane carries at a speed, flowing and discharging a standing queue, under
    /// the paper's invariant and the leader-aware one (bench/sumo/lane_capacity.py runs
    /// the same road in SUMO, side by side).
    LaneCapacity(OneCmd<host_sim::experiments::lane_capacity::LaneCapacity>),
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
    Network(OneCmd<host_sim::experiments::network::NetworkSettings>),
    /// The threat model's attacks on the Fig. 8 intersection and the multi-lane road, each a fleet
    /// on CAN with every node authenticating: forged grant, replayed grant, replayed
    /// state, spoofed id, flood, a lying vehicle, the manager's crash and restart (exit 1
    /// on a forgery or replay accepted, or an unsafe event).
    Attacks(OneCmd<host_sim::experiments::attacks::Settings>),
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
        Experiment::Attacks(c) => whole(&c.settings, c.json, None),
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
        Experiment::LaneCapacity(c) => whole(&c.settings, c.json, None),
        Experiment::Throughput(c) => {
            let draw =
                |r: &_, p: &Path| host_sim::output::plot::bars(r, p).map_err(|e| e.to_string());
            conduct(
                &c.settings,
                c.answer,
                c.plot.as_ref().map(|p| (p, &draw as _)),
            )
        }
        Experiment::Network(c) => whole(&c.settings, c.json, None),
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
