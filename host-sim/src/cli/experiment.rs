//! `host-sim experiment …`: the paper's figures and the fault experiment.

use super::output::{bad_input, check_duration, draw_plot, finish, plot_output, print_json};
use super::SolverArg;
use host_sim::bus::Faults;
use host_sim::experiments::demand::Plan;
use host_sim::experiments::faults::{compare, FaultSettings};
use host_sim::experiments::multilane::{MultilaneCase, MultilaneSettings};
use host_sim::experiments::shard::{DemandSettings, GridSettings, Runs, Shard};
use host_sim::experiments::throughput::{ThroughputCase, ThroughputSettings};
use host_sim::output::plot::PlotData;
use planner_core::crossing::Algorithm;
use std::path::PathBuf;
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
    Throughput(ThroughputArgs),
    /// The multi-lane and throughput experiments on a perfect bus and on a faulty one
    /// (default 20 % loss, 50 ms delay), same seeds, compared.
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
        /// Instead: the fault grid — loss × delay, then jitter, duplicates, reordering and
        /// a vehicle silent from t = 0, each cell over the multi-lane road, a fully braking
        /// platoon leader, drivers that do not cooperate and the intersection under every
        /// algorithm (exit 1 if any cell saw an unsafe event).
        #[arg(long, conflicts_with_all = ["loss", "delay", "jitter", "throughput_seeds", "duration"])]
        grid: bool,
        /// With --grid: its losses (rows), comma-separated.
        #[arg(
            long,
            value_delimiter = ',',
            default_value = "0,0.2,0.5,0.9,0.99",
            requires = "grid"
        )]
        losses: Vec<f64>,
        /// With --grid: its delays in s (columns), comma-separated.
        #[arg(
            long,
            value_delimiter = ',',
            default_value = "0,0.01,0.1,0.5,1",
            requires = "grid"
        )]
        delays: Vec<f64>,
        /// Runs per workload and cell, with --grid.
        #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u64).range(1..), requires = "grid")]
        runs: u64,
        /// With --grid: draw the heat maps (completion per cell and workload, unsafe
        /// events printed in each cell) to a .png or .svg.
        #[arg(long, value_name = "out.png|out.svg", requires = "grid")]
        plot: Option<PathBuf>,
        /// Run only shard I of N (0-based) of the runs (both buses, both experiments) and
        /// print them as JSON for `host-sim merge`; with --grid, of the grid's runs.
        #[arg(long, value_name = "I/N", conflicts_with = "plot")]
        shard: Option<Shard>,
        /// The invariant every planner keeps toward the vehicle ahead (in both experiments,
        /// or in the grid).
        #[arg(long, value_enum, default_value = "paper")]
        invariant: super::InvariantArg,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
    /// Open-system demand at the SPEC §8 intersection: Poisson arrivals at every inlet
    /// lane; per algorithm and rate, throughput, delay and queues, and each algorithm's
    /// capacity.
    Demand {
        /// Arrivals per inlet lane, vehicles per hour (comma-separated).
        #[arg(
            long,
            value_delimiter = ',',
            default_value = "50,100,150,200,250,300,350,400"
        )]
        rates: Vec<f64>,
        /// Simulated seconds per run.
        #[arg(long, default_value_t = 600.0)]
        duration: f64,
        /// Runs per algorithm and rate.
        #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u64).range(1..))]
        seeds: u64,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
        /// Draw mean delay against demand, one curve per algorithm, to a .png or .svg.
        #[arg(long, value_name = "out.png|out.svg")]
        plot: Option<PathBuf>,
        /// Algorithms to run (comma-separated, of STOP, STOP-1, FIFO, CON, CON-fair, PIPE, PLATOON).
        #[arg(
            long,
            value_delimiter = ',',
            default_value = "STOP,FIFO,CON-fair,PIPE,PLATOON"
        )]
        algorithms: Vec<String>,
        /// The invariant every vehicle keeps toward the vehicle ahead.
        #[arg(long, value_enum, default_value = "paper")]
        invariant: super::InvariantArg,
        /// Run only shard I of N (0-based) of the runs and print them as JSON for
        /// `host-sim merge`.
        #[arg(long, value_name = "I/N", conflicts_with = "plot")]
        shard: Option<Shard>,
    },
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
    Multilane(MultilaneArgs),
}

/// `experiment multilane`'s flags.
#[derive(clap::Args)]
pub struct MultilaneArgs {
    /// Number of runs (seeds 1..=K, or from --seed).
    #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u64).range(1..))]
    pub(crate) seeds: u64,
    /// First seed.
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
    /// Print one JSON object.
    #[arg(long)]
    pub(crate) json: bool,
    /// Draw the first run's trajectories (Fig. 7 style) to a .png or .svg file.
    #[arg(long, value_name = "out.png|out.svg")]
    pub(crate) plot: Option<PathBuf>,
    /// Run only shard I of N (0-based) of the runs and print them as JSON for
    /// `host-sim merge`.
    #[arg(long, value_name = "I/N", conflicts_with = "plot")]
    pub(crate) shard: Option<Shard>,
    /// The planners' solver.
    #[arg(long, value_enum, default_value = "ours")]
    pub(crate) solver: SolverArg,
    #[command(flatten)]
    pub(crate) faults: FaultArgs,
    /// The invariant every planner keeps toward the vehicle ahead.
    #[arg(long, value_enum, default_value = "paper")]
    pub(crate) invariant: super::InvariantArg,
}

impl MultilaneArgs {
    fn settings(&self) -> Result<MultilaneSettings, String> {
        Ok(MultilaneSettings {
            seeds: self.seeds,
            seed: self.seed,
            solver: self.solver.choice(),
            faults: self.faults.faults()?,
            invariant: self.invariant.invariant(),
        })
    }
}

/// `experiment throughput`'s flags.
#[derive(clap::Args)]
pub struct ThroughputArgs {
    /// Simulated seconds per run.
    #[arg(long, default_value_t = 300.0)]
    pub(crate) duration: f64,
    /// Runs per algorithm (seeds from --seed).
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..))]
    pub(crate) seeds: u64,
    /// First seed.
    #[arg(long, default_value_t = 1)]
    pub(crate) seed: u64,
    /// Print one JSON object.
    #[arg(long)]
    pub(crate) json: bool,
    /// Draw a Fig. 9-style bar chart to a .png or .svg file.
    #[arg(long, value_name = "out.png|out.svg")]
    pub(crate) plot: Option<PathBuf>,
    /// Run only shard I of N (0-based) of the runs and print them as JSON for
    /// `host-sim merge`.
    #[arg(long, value_name = "I/N", conflicts_with = "plot")]
    pub(crate) shard: Option<Shard>,
    #[command(flatten)]
    pub(crate) faults: FaultArgs,
    /// The invariant every planner keeps toward the vehicle ahead.
    #[arg(long, value_enum, default_value = "paper")]
    pub(crate) invariant: super::InvariantArg,
}

impl ThroughputArgs {
    fn settings(&self) -> Result<ThroughputSettings, String> {
        Ok(ThroughputSettings {
            seeds: self.seeds,
            seed: self.seed,
            duration: self.duration,
            faults: self.faults.faults()?,
            invariant: self.invariant.invariant(),
        })
    }
}

/// Faults for an experiment's bus (none by default).
#[derive(clap::Args, Debug, Clone, Copy)]
pub struct FaultArgs {
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

/// Runs an experiment.
pub fn run(e: Experiment) -> ExitCode {
    match e {
        Experiment::Attacks(a) => attacks(a),
        Experiment::Multilane(a) => match a.settings() {
            Ok(s) => multilane(&s, a.json, a.plot, a.shard),
            Err(e) => bad_input(e),
        },
        Experiment::Faults {
            seeds,
            throughput_seeds,
            duration,
            loss,
            delay,
            jitter,
            grid,
            losses,
            delays,
            runs,
            plot,
            json,
            shard,
            invariant,
        } => {
            if grid {
                let g = GridRequest {
                    losses,
                    delays,
                    runs,
                    invariant: invariant.invariant(),
                };
                return fault_grid(&g, json, plot, shard);
            }
            let args = FaultArgs {
                loss,
                delay,
                jitter,
                duplicate: 0.0,
                reorder: 0.0,
            };
            let counts = (seeds, throughput_seeds, duration);
            faults(args, counts, invariant.invariant(), json, shard)
        }
        Experiment::LaneCapacity(a) => lane_capacity(&a).err().unwrap_or(ExitCode::SUCCESS),
        Experiment::Throughput(a) => match a.settings() {
            Ok(s) => throughput(&s, a.json, a.plot, a.shard),
            Err(e) => bad_input(e),
        },
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
        Experiment::Demand {
            rates,
            duration,
            seeds,
            json,
            plot,
            algorithms,
            invariant,
            shard,
        } => match demand_plan(&rates, duration, seeds, &algorithms, invariant) {
            Ok(plan) => demand(&plan, (json, plot), shard),
            Err(code) => code,
        },
    }
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
    if let Err(code) = check_duration(s.duration_s, 7200.0) {
        return code;
    }
    // The grid is checked by the scenario loader before anything runs.
    if let Err(e) = s.world() {
        return bad_input(e);
    }
    let r = match host_sim::experiments::network::run(s) {
        Ok(r) => r,
        Err(e) => return bad_input(e),
    };
    let safe =
        r.collisions + r.invariant_violations + r.limit_violations + r.unpermitted_entries == 0;
    finish(
        &r,
        json,
        safe,
        r.deadlocks == 0 && r.due_completed_share >= 0.95,
    )
}

/// `experiment faults --grid`: what it runs.
struct GridRequest {
    losses: Vec<f64>,
    delays: Vec<f64>,
    runs: u64,
    invariant: planner_core::Invariant,
}

impl GridRequest {
    /// The grid's plan over `cells` (built from its losses and delays), seed 1.
    fn plan<'a>(
        &self,
        cells: &'a [host_sim::experiments::fault_grid::Cell],
    ) -> host_sim::experiments::fault_grid::GridPlan<'a> {
        host_sim::experiments::fault_grid::GridPlan {
            cells,
            runs: self.runs,
            seed: 1,
            invariant: self.invariant,
        }
    }
}

fn fault_grid(
    g: &GridRequest,
    json: bool,
    plot: Option<PathBuf>,
    shard: Option<Shard>,
) -> ExitCode {
    use host_sim::experiments::fault_grid::{grid, Cell};
    let cells = Cell::grid(&g.losses, &g.delays);
    for c in &cells {
        if let Err(e) = c.faults(1).validate() {
            return bad_input(
                e.replace("faults.loss", "--losses")
                    .replace("faults.delay_s", "--delays"),
            );
        }
    }
    let plot = match plot_output(plot.as_deref()) {
        Ok(p) => p,
        Err(code) => return code,
    };
    if let Some(sh) = shard {
        return fault_grid_shard(g, &g.plan(&cells), sh);
    }
    let r = grid(&g.plan(&cells), 0);
    if let Some(out) = plot {
        let shown = out.target().display().to_string();
        if let Err(code) = draw_plot(out, |p| host_sim::output::plot::fault_grid(&r, p)) {
            return code;
        }
        eprintln!("wrote {shown}");
    }
    finish(&r, json, r.unsafe_cells == 0, true)
}

/// A shard of the fault grid: its runs, for `host-sim merge`.
fn fault_grid_shard(
    g: &GridRequest,
    plan: &host_sim::experiments::fault_grid::GridPlan,
    sh: Shard,
) -> ExitCode {
    use host_sim::experiments::fault_grid::{grid_runs, run_count, GridRun};
    let settings = GridSettings {
        losses: g.losses.clone(),
        delays: g.delays.clone(),
        runs: g.runs,
        seed: plan.seed,
        invariant: host_sim::world::invariant_name(g.invariant).to_string(),
    };
    shard_of(
        "faults-grid",
        settings,
        run_count(plan.cells, g.runs),
        sh,
        |r| grid_runs(plan, r, 0),
        |g: &GridRun| {
            let t = &g.totals;
            t.collisions + t.invariant_violations + t.limit_violations + t.unpermitted_entries
        },
    )
}

/// A shard of the demand experiment: its runs, for `host-sim merge`.
fn demand_shard(plan: &Plan, sh: Shard) -> ExitCode {
    use host_sim::experiments::demand::{demand_runs, RunOutcome};
    let settings = DemandSettings {
        algorithms: plan
            .algorithms
            .iter()
            .map(|a| a.name().to_string())
            .collect(),
        rates: plan.rates.clone(),
        duration: plan.duration,
        seeds: plan.seeds,
        invariant: host_sim::world::invariant_name(plan.invariant).to_string(),
    };
    shard_of(
        "demand",
        settings,
        plan.run_count(),
        sh,
        |r| demand_runs(plan, r, 0),
        RunOutcome::unsafe_events,
    )
}

/// The demand experiment's plan from its flags, or the exit code of a refusal.
fn demand_plan(
    rates: &[f64],
    duration: f64,
    seeds: u64,
    algorithms: &[String],
    invariant: super::InvariantArg,
) -> Result<Plan, ExitCode> {
    if rates.is_empty() || !rates.iter().all(|r| *r > 0.0 && *r <= 3600.0) {
        return Err(bad_input(
            "--rates: vehicles per hour per lane, each in (0, 3600]",
        ));
    }
    let mut chosen = Vec::new();
    for name in algorithms {
        match Algorithm::ALL
            .iter()
            .find(|a| a.name().eq_ignore_ascii_case(name))
        {
            Some(a) if !chosen.contains(a) => chosen.push(*a),
            Some(_) => return Err(bad_input(format!("--algorithms: {name} given twice"))),
            None => {
                return Err(bad_input(format!(
                "--algorithms: unknown {name:?} (STOP, STOP-1, FIFO, CON, CON-fair, PIPE, PLATOON)"
            )))
            }
        }
    }
    if chosen.is_empty() {
        return Err(bad_input("--algorithms: at least one"));
    }
    check_duration(duration, 7200.0)?;
    let mut plan = Plan::new(&chosen, rates, duration, seeds);
    plan.invariant = invariant.invariant();
    Ok(plan)
}

fn demand(plan: &Plan, (json, plot): (bool, Option<PathBuf>), shard: Option<Shard>) -> ExitCode {
    let plot = match plot_output(plot.as_deref()) {
        Ok(p) => p,
        Err(code) => return code,
    };
    if let Some(sh) = shard {
        return demand_shard(plan, sh);
    }
    let r = host_sim::experiments::demand::run(plan, 0);
    if let Some(out) = plot {
        if let Err(code) = draw_plot(out, |p| host_sim::output::plot::demand(&r, p)) {
            return code;
        }
    }
    let safe = r
        .results
        .iter()
        .all(|x| x.collisions + x.invariant_violations + x.unpermitted_entries == 0);
    let live = r.results.iter().all(|x| x.deadlocks == 0);
    finish(&r, json, safe, live)
}

fn multilane(
    s: &MultilaneSettings,
    json: bool,
    plot: Option<PathBuf>,
    shard: Option<Shard>,
) -> ExitCode {
    let plot = match plot_output(plot.as_deref()) {
        Ok(p) => p,
        Err(code) => return code,
    };
    if let Some(sh) = shard {
        return multilane_shard(s, sh);
    }
    let r = host_sim::experiments::multilane::experiment(s, 0);
    if let Some(out) = plot {
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
        if let Err(code) = draw_plot(out, |p| host_sim::output::plot::write(&data, &name, p)) {
            return code;
        }
    }
    finish(
        &r,
        json,
        r.collisions + r.invariant_violations + r.limit_violations == 0,
        r.completed == r.runs,
    )
}

fn throughput(
    s: &ThroughputSettings,
    json: bool,
    plot: Option<PathBuf>,
    shard: Option<Shard>,
) -> ExitCode {
    if let Err(code) = check_duration(s.duration, 3600.0) {
        return code;
    }
    if let Some(sh) = shard {
        return throughput_shard(s, sh);
    }
    let plot = match plot_output(plot.as_deref()) {
        Ok(p) => p,
        Err(code) => return code,
    };
    let r = host_sim::experiments::throughput::throughput(s, 0);
    if let Some(out) = plot {
        if let Err(code) = draw_plot(out, |p| host_sim::output::plot::bars(&r, p)) {
            return code;
        }
    }
    finish(
        &r,
        json,
        r.results.iter().all(|x| {
            x.collisions + x.invariant_violations + x.limit_violations + x.unpermitted_entries == 0
        }),
        true,
    )
}

/// Runs `f` on a shard's range of `cases` runs and prints them for `host-sim merge`;
/// exits as the sweep would (unsafe → 1) on the shard's runs.
fn shard_of<T: serde::Serialize>(
    name: &str,
    settings: impl serde::Serialize,
    cases: u64,
    sh: Shard,
    f: impl FnOnce((u64, u64)) -> Vec<T>,
    unsafe_events: impl Fn(&T) -> u64,
) -> ExitCode {
    let settings = match serde_json::to_value(settings) {
        Ok(v) => v,
        Err(e) => return bad_input(e.to_string()),
    };
    let t0 = std::time::Instant::now();
    let range = sh.range(cases);
    let runs = f(range);
    let safe = runs.iter().map(&unsafe_events).sum::<u64>() == 0;
    let out = Runs {
        runs,
        wall_seconds: t0.elapsed().as_secs_f64(),
    };
    super::sweep::emit(
        name,
        settings,
        sh,
        range,
        &out,
        super::output::code(safe, true),
    )
}

fn multilane_shard(s: &MultilaneSettings, sh: Shard) -> ExitCode {
    shard_of(
        "multilane",
        s,
        s.seeds,
        sh,
        |r| host_sim::experiments::multilane::multilane_cases(s, r, 0),
        MultilaneCase::unsafe_events,
    )
}

fn throughput_shard(s: &ThroughputSettings, sh: Shard) -> ExitCode {
    use host_sim::experiments::throughput::throughput_cases;
    let cases = s.seeds * planner_core::crossing::Algorithm::ALL.len() as u64;
    shard_of(
        "throughput",
        s,
        cases,
        sh,
        |r| throughput_cases(s, r, 0),
        ThroughputCase::unsafe_events,
    )
}

fn faults_shard(s: &FaultSettings, sh: Shard) -> ExitCode {
    use host_sim::experiments::faults::FaultCase;
    shard_of(
        "faults",
        s,
        s.cases(),
        sh,
        |r| s.run(r, 0),
        // Only the faulty bus's events count, as in the unsharded comparison.
        |c| match c {
            FaultCase::Multilane { faulty: true, run } => run.unsafe_events(),
            FaultCase::Throughput { faulty: true, run } => run.unsafe_events(),
            _ => 0,
        },
    )
}

fn faults(
    args: FaultArgs,
    (seeds, throughput_seeds, duration): (u64, u64, f64),
    invariant: planner_core::Invariant,
    json: bool,
    shard: Option<Shard>,
) -> ExitCode {
    let faults = match args.faults() {
        Ok(f) => f,
        Err(e) => return bad_input(e),
    };
    if let Err(code) = check_duration(duration, 3600.0) {
        return code;
    }
    let settings = FaultSettings {
        faults,
        seeds,
        throughput_seeds,
        duration,
        invariant,
    };
    match shard {
        Some(sh) => faults_shard(&settings, sh),
        None => {
            let r = compare(&settings, 0);
            let live = r.multilane_faulty.completed == r.multilane_faulty.runs;
            finish(&r, json, r.faulty_unsafe_events == 0, live)
        }
    }
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
    use host_sim::fleet::intruder::Attack;
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
    // The intruder's rows: forgeries, replays, spoofs and the flood.
    let intruder = |name: &str| Attack::ALL.iter().any(|a| a.name() == name);
    let kept_out = !authenticated
        || report
            .results
            .iter()
            .all(|r| !intruder(&r.attack) || r.accepted == 0);
    let safe = report.results.iter().all(|r| r.unsafe_events() == 0);
    // A liar's cost in liveness is reported, not required away: the others stop taking
    // its word and plan around the worst case of it.
    let done = report
        .results
        .iter()
        .all(|r| r.completed || r.attack == "lying-vehicle");
    finish(&AttacksText(&report), a.json, safe && kept_out, done)
}

/// `experiment attacks`'s table for a terminal.
struct AttacksText<'a>(&'a host_sim::experiments::attacks::AttackReport);

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

/// `experiment lane-capacity`: every speed, both settings, the invariants asked for.
fn lane_capacity(a: &LaneCapacityArgs) -> Result<(), ExitCode> {
    use host_sim::experiments::lane_capacity as lc;
    let (speeds, invariant, vehicles, json) = (&a.speeds, a.invariant, a.vehicles, a.json);
    if let Some(v) = speeds.iter().find(|v| !(**v > 0.0 && **v <= 27.8)) {
        return Err(bad_input(format!(
            "--speeds: each in (0, 27.8] m/s, got {v}"
        )));
    }
    let invariants: Vec<planner_core::Invariant> = match invariant {
        Some(i) => vec![i.invariant()],
        None => vec![
            planner_core::Invariant::Paper,
            planner_core::Invariant::LeaderAware,
        ],
    };
    let report = lc::lane_capacity(speeds, &invariants, usize::from(vehicles)).map_err(|e| {
        eprintln!("error: internal: lane-capacity: {e} (a bug: please report it)");
        ExitCode::from(super::output::EXIT_INTERNAL)
    })?;
    if json {
        return print_json(&report);
    }
    println!("| speed (m/s) | mode | invariant | veh/h | mean headway (s) | collisions | invariant violations | fallback steps |");
    println!("|---|---|---|---|---|---|---|---|");
    for r in &report.results {
        println!(
            "| {} | {} | {} | {:.0} | {:.3} | {} | {} | {} |",
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
    let unsafe_runs = report
        .results
        .iter()
        .filter(|r| r.collisions + r.invariant_violations + r.limit_violations > 0)
        .count();
    if unsafe_runs > 0 {
        eprintln!("{unsafe_runs} run(s) with a collision or a violation");
        return Err(ExitCode::from(super::output::EXIT_UNSAFE));
    }
    Ok(())
}
