//! `host-sim experiment faults --grid`: safety off the ideal world, cell by cell.
//!
//! Every cell is a bus: loss × delay over [`LOSSES`] × [`DELAYS`], then the other faults
//! one at a time ([`VARIANTS`]: jitter, duplicates, reordering, a vehicle silent from
//! t = 0). Every cell runs the same workloads ([`Workload`]): the paper's multi-lane road,
//! a dense platoon at the smallest safe gap behind a leader that brakes fully, planners
//! changing lanes among drivers that do not cooperate, and queues at the SPEC §8
//! intersection under every algorithm. Every vehicle has the onboard radar
//! ([`Sensing::radar`]) in every cell, the clean one included, so that cells differ in
//! their bus alone.
//!
//! The target is safety in every cell: 0 collisions, 0 invariant violations, 0 limit
//! violations, 0 unpermitted entries. Liveness may degrade, and is reported: the share of
//! vehicles that met their goals and the mean time by which a run had met them.

use super::crossings::{queues_of, truck_layout};
use super::experiment::{Experiment, RunError, SettingsError};
use super::multilane::{paper_scenario, spacing};
use super::shard::{MergeError, Runs};
use super::sweep::{self, case_seed, Case, Totals};
use crate::bus::{Faults, Silent};
use crate::monitor::liveness::DEADLOCK_WINDOW_S;
use crate::monitor::Limits;
use crate::reference::instances::rng;
use crate::scenario::junction::{JunctionScenario, LayoutToml};
use crate::scenario::road::{Road, RoadScenario, RoadVehicle};
use crate::scenario::{DriverKind, Phase};
use crate::verdict::{Judged, Safety, Verdict};
use crate::world::{Body, Finish, WorldSpec};
use planner_core::crossing::Algorithm;
use planner_core::sensing::Sensing;
use rand::Rng;
use serde::{Deserialize, Serialize};

/// Loss probabilities of the grid.
pub const LOSSES: [f64; 5] = [0.0, 0.2, 0.5, 0.9, 0.99];
/// Delivery delays of the grid (s).
pub const DELAYS: [f64; 5] = [0.0, 0.01, 0.1, 0.5, 1.0];
/// The other faults, each alone (with a 50 ms delay so that there is something to
/// reorder and jitter).
pub const VARIANTS: [&str; 4] = ["jitter", "duplicates", "reordering", "silent"];

/// What runs in every cell.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Workload {
    /// The paper's multi-lane experiment (SPEC §8): 6 vehicles, 3 lanes, random targets.
    Multilane,
    /// Six vehicles in one lane at the smallest safe gap; the scripted leader brakes at
    /// amin to a stop after 2 s.
    Platoon,
    /// Four planners changing lanes among two drivers with random admissible
    /// accelerations that neither cooperate nor yield.
    NonCooperative,
    /// Up to three vehicles queued on each of the 8 inlet lanes under one algorithm.
    Intersection(Algorithm),
}

impl Workload {
    /// Every workload, in report order.
    pub fn all() -> Vec<Workload> {
        let mut w = vec![Self::Multilane, Self::Platoon, Self::NonCooperative];
        w.extend(
            super::crossings::ALGORITHMS
                .iter()
                .map(|&a| Self::Intersection(a)),
        );
        w
    }

    /// Its label.
    pub fn label(self) -> String {
        match self {
            Self::Multilane => "multilane".into(),
            Self::Platoon => "platoon".into(),
            Self::NonCooperative => "non-cooperative".into(),
            Self::Intersection(a) => format!("intersection {}", a.name()),
        }
    }

    /// Run `k`'s world, without faults yet, `trucks` percent of its planner-driven
    /// vehicles trucks ([`Body::TRUCK`]; drawn from a stream of their own, so that with 0
    /// every world is as it always was).
    fn world(self, seed: u64, k: u64, trucks: u8) -> WorldSpec {
        let s = case_seed(seed, k);
        let mut draw = Bodies::new(s, trucks);
        match self {
            Self::Multilane => {
                let mut sc = paper_scenario(s);
                respace_pairs(&mut sc.vehicles, &mut draw);
                let mut w = sc.world();
                w.duration_s = 60.0;
                w
            }
            Self::Platoon => platoon(s, &mut draw).world(),
            Self::NonCooperative => non_cooperative(s, &mut draw).world(),
            Self::Intersection(a) => intersection(a, s, trucks).world(),
        }
    }
}

/// Which vehicles are trucks: each drawn at `percent` from a stream of its own.
struct Bodies {
    rng: rand_chacha::ChaCha8Rng,
    percent: u8,
}

impl Bodies {
    fn new(seed: u64, percent: u8) -> Self {
        Self {
            rng: rng(seed ^ 0x7472_7563_6b73),
            percent,
        }
    }

    /// The next vehicle's body (nothing is drawn at 0 %).
    fn next(&mut self) -> Body {
        if self.percent > 0 && self.rng.random_range(0..100u8) < self.percent {
            Body::TRUCK
        } else {
            Body::CAR
        }
    }
}

/// `v` given `body`'s length and braking limit (a car's stay unset, as they always were).
fn with_body(v: &mut RoadVehicle, body: Body) {
    if body != Body::CAR {
        v.length = Some(body.length);
        v.brake = Some(body.brake);
    }
}

/// The paper's road (two vehicles per lane, the front one at x = its spacing, the rear
/// at 0) with drawn bodies, each front vehicle moved to the smallest safe spacing for its
/// follower's body.
fn respace_pairs(vehicles: &mut [RoadVehicle], draw: &mut Bodies) {
    for pair in vehicles.chunks_mut(2) {
        let bodies: Vec<Body> = pair.iter().map(|_| draw.next()).collect();
        for (v, &b) in pair.iter_mut().zip(&bodies) {
            with_body(v, b);
        }
        if let ([front, rear], [lead, body]) = (pair, bodies.as_slice()) {
            front.x = rear.x + spacing(front.v, *lead, *body);
        }
    }
}

/// One cell's bus.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Cell {
    /// Loss probability.
    pub loss: f64,
    /// Delay (s).
    pub delay_s: f64,
    /// `"grid"`, or the fault of [`VARIANTS`] this cell adds.
    pub variant: &'static str,
}

impl Cell {
    /// Every cell: the grid, then the variants.
    pub fn all() -> Vec<Cell> {
        Self::grid(&LOSSES, &DELAYS)
    }

    /// The cells of `losses` × `delays`, then the variants.
    pub fn grid(losses: &[f64], delays: &[f64]) -> Vec<Cell> {
        let mut cells: Vec<Cell> = losses
            .iter()
            .flat_map(|&loss| {
                delays.iter().map(move |&delay_s| Cell {
                    loss,
                    delay_s,
                    variant: "grid",
                })
            })
            .collect();
        cells.extend(VARIANTS.iter().map(|&variant| Cell {
            loss: 0.0,
            delay_s: 0.05,
            variant,
        }));
        cells
    }

    /// Its faults; `silent` is the vehicle that a "silent" cell silences.
    pub fn faults(&self, silent: u16) -> Faults {
        let mut f = Faults {
            loss: self.loss,
            delay_s: self.delay_s,
            ..Faults::NONE
        };
        match self.variant {
            "jitter" => f.jitter_s = 0.2,
            "duplicates" => f.duplicate = 0.5,
            "reordering" => {
                f.reorder = 0.5;
                f.reorder_s = 0.1;
            }
            "silent" => {
                f.silent = Some(Silent {
                    id: silent,
                    from_s: 0.0,
                })
            }
            _ => {}
        }
        f
    }
}

/// One workload in one cell, over its runs.
#[derive(Debug, Clone, Serialize)]
pub struct CellResult {
    /// The bus.
    #[serde(flatten)]
    pub cell: Cell,
    /// The workload.
    pub workload: String,
    /// Safety and liveness totals.
    #[serde(flatten)]
    pub totals: Totals,
    /// Share of vehicles that met their goals (1 = all).
    pub completion: f64,
}

impl CellResult {
    /// Its findings.
    pub fn safety(&self) -> Safety {
        self.totals.safety()
    }
}

/// The grid's result.
#[derive(Debug, Clone, Serialize)]
pub struct GridReport {
    /// The grid's losses (rows).
    pub losses: Vec<f64>,
    /// The grid's delays (columns, s).
    pub delays: Vec<f64>,
    /// Per cell and workload.
    pub cells: Vec<CellResult>,
    /// Cells (cell × workload) with an unsafe event: the target is 0.
    pub unsafe_cells: u64,
    /// Runs per workload and cell.
    pub runs: u64,
    /// The seed.
    pub seed: u64,
    /// The invariant every planner kept (`paper`, `leader-aware`).
    pub invariant: &'static str,
    /// Percent of the planner-driven vehicles drawn as trucks (`--trucks`).
    pub trucks: u8,
    /// Wall-clock time (s).
    pub wall_seconds: f64,
}

/// The grid's own flags (`experiment faults --grid`): its rows, columns and runs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, clap::Args)]
pub struct GridCells {
    /// With --grid: its losses (rows), comma-separated.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "0,0.2,0.5,0.9,0.99",
        requires = "grid"
    )]
    pub losses: Vec<f64>,
    /// With --grid: its delays in s (columns), comma-separated.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "0,0.01,0.1,0.5,1",
        requires = "grid"
    )]
    pub delays: Vec<f64>,
    /// Runs per workload and cell, with --grid.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u64).range(1..), requires = "grid")]
    pub runs: u64,
    /// With --grid: percent of the planner-driven vehicles that are trucks (16.5 m,
    /// braking at 4.5 m/s²), drawn per vehicle; 0 gives the grid as it always was.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u8).range(0..=100), requires = "grid")]
    #[serde(default, skip_serializing_if = "super::flags::is_zero")]
    pub trucks: u8,
}

/// `experiment faults --grid`'s settings (a shard's header carries them for `host-sim
/// merge`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GridSettings {
    /// Rows, columns and runs.
    #[serde(flatten)]
    pub cells: GridCells,
    /// Seed.
    pub seed: u64,
    /// The invariant every planner keeps ("paper" in shards of older versions).
    #[serde(default, with = "crate::world::invariant_serde")]
    pub invariant: planner_core::Invariant,
}

impl GridSettings {
    /// The grid of `cells` under `invariant`, seed 1.
    pub fn new(cells: GridCells, invariant: planner_core::Invariant) -> Self {
        Self {
            cells,
            seed: 1,
            invariant,
        }
    }

    /// Its cells, in report order.
    pub fn cell_list(&self) -> Vec<Cell> {
        Cell::grid(&self.cells.losses, &self.cells.delays)
    }

    /// Its plan over `cells` ([`GridSettings::cell_list`]).
    pub fn plan<'a>(&self, cells: &'a [Cell]) -> GridPlan<'a> {
        GridPlan {
            cells,
            runs: self.cells.runs,
            seed: self.seed,
            invariant: self.invariant,
            trucks: self.cells.trucks,
        }
    }
}

impl Experiment for GridSettings {
    const NAME: &'static str = "faults-grid";
    type Part = Runs<GridRun>;
    type Report = GridReport;

    fn validate(&self) -> Result<(), SettingsError> {
        for c in self.cell_list() {
            c.faults(1).validate().map_err(|e| {
                let e = e.replace("faults.loss", "--losses");
                let e = e.replace("faults.delay_s", "--delays");
                SettingsError::raw("--losses", e)
            })?;
        }
        Ok(())
    }

    fn cases(&self) -> u64 {
        run_count(&self.cell_list(), self.cells.runs)
    }

    fn run(&self, range: (u64, u64), threads: usize) -> Result<Self::Part, RunError> {
        let cells = self.cell_list();
        Ok(Runs::timed(|| {
            grid_runs(&self.plan(&cells), range, threads)
        }))
    }

    fn report(&self, parts: Vec<Self::Part>) -> Result<GridReport, MergeError> {
        let all = Runs::concat(parts);
        let cells = self.cell_list();
        Ok(grid_report(&self.plan(&cells), &all.runs, all.wall_seconds))
    }
}

impl Judged for GridReport {
    /// Every cell's findings; liveness is reported per cell, not judged (it may degrade
    /// off the ideal bus).
    fn verdict(&self) -> Verdict {
        Verdict::new(self.cells.iter().map(CellResult::safety).sum(), true)
    }
}

/// What the grid runs: its cells, the runs of each workload per cell, the seed and the
/// invariant every planner keeps.
#[derive(Debug, Clone, Copy)]
pub struct GridPlan<'a> {
    /// The cells, in report order ([`Cell::grid`]).
    pub cells: &'a [Cell],
    /// Runs per workload and cell.
    pub runs: u64,
    /// Seed.
    pub seed: u64,
    /// The invariant.
    pub invariant: planner_core::Invariant,
    /// Percent of the planner-driven vehicles that are trucks.
    pub trucks: u8,
}

/// The grid's runs in report order: (cell, workload, run). A run's seed depends on its
/// run index alone, so a shard of these ([`grid_runs`]) runs exactly what the whole grid
/// would for them.
fn jobs(cells: usize, workloads: usize, runs: u64) -> Vec<(usize, usize, u64)> {
    (0..cells)
        .flat_map(|c| (0..workloads).flat_map(move |w| (0..runs).map(move |k| (c, w, k))))
        .collect()
}

/// How many runs the grid has: cells × workloads × runs.
pub fn run_count(cells: &[Cell], runs: u64) -> u64 {
    cells.len() as u64 * Workload::all().len() as u64 * runs
}

/// One run of the grid: its index in [`run_count`] order and its totals.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct GridRun {
    /// Its index among the grid's runs.
    pub job: u64,
    /// Its safety and liveness totals (one case).
    pub totals: Totals,
}

/// The grid's runs [first, end) (of [`run_count`]), on `threads` threads.
pub fn grid_runs(plan: &GridPlan, (first, end): (u64, u64), threads: usize) -> Vec<GridRun> {
    let GridPlan {
        cells, runs, seed, ..
    } = *plan;
    let workloads = Workload::all();
    let jobs = jobs(cells.len(), workloads.len(), runs);
    let mine = first.min(end) as usize..end.min(jobs.len() as u64) as usize;
    let base = mine.start;
    super::par::map_indexed(mine.len(), threads, |i| {
        let (c, w, k) = jobs[base + i];
        let world = job_world(plan, (cells[c], workloads[w]), k);
        let case = Case {
            index: k,
            seed: case_seed(seed, k),
            label: "",
            summary: sweep::run(world),
            scenario: String::new(),
        };
        GridRun {
            job: (base + i) as u64,
            totals: Totals::of(std::iter::once(&case)),
        }
    })
}

/// Run `k` of `workload` in `cell` of the grid: its world, faults and all.
fn job_world(plan: &GridPlan, (cell, workload): (Cell, Workload), k: u64) -> WorldSpec {
    let mut world = workload.world(plan.seed, k, plan.trucks);
    world.faults = cell.faults(1);
    world.sensing = Some(Sensing::radar());
    world.finish = Finish::GoalsMetAndStill;
    world.invariant = plan.invariant;
    // The detector's window, stretched by the bus: where only a share 1 − loss of the
    // messages arrives, a request and its grant take 1 / (1 − loss) times as many periods
    // to get through, and 10 s without movement at 99 % loss is a queue waiting for its
    // next grant (FIFO under the paper's invariant at 1 s of delay stood 10 s and then
    // finished at 277 s). A stall that lasts is still found: the run ends with it, its
    // vehicles unfinished.
    world.deadlock_window_s = DEADLOCK_WINDOW_S / (1.0 - cell.loss).max(0.01);
    world.name = format!("{}-{}", world.name, cell_name(&cell));
    world
}

/// The world of the grid's run `job` (of [`run_count`], in report order), `None` past
/// the last.
pub fn grid_world(plan: &GridPlan, job: u64) -> Option<WorldSpec> {
    let workloads = Workload::all();
    let jobs = jobs(plan.cells.len(), workloads.len(), plan.runs);
    let &(c, w, k) = jobs.get(usize::try_from(job).ok()?)?;
    Some(job_world(plan, (plan.cells[c], workloads[w]), k))
}

/// The report over the grid's runs `outs` (every run once, in any order of shards).
pub fn grid_report(plan: &GridPlan, outs: &[GridRun], wall_seconds: f64) -> GridReport {
    let GridPlan {
        cells, runs, seed, ..
    } = *plan;
    let workloads = Workload::all();
    let jobs = jobs(cells.len(), workloads.len(), runs);
    let mut results = Vec::new();
    for (c, cell) in cells.iter().enumerate() {
        for (w, workload) in workloads.iter().enumerate() {
            let mine = outs
                .iter()
                .filter(|o| {
                    jobs.get(o.job as usize)
                        .is_some_and(|j| j.0 == c && j.1 == w)
                })
                .map(|o| &o.totals);
            let totals = Totals::sum(mine);
            let completion = if totals.vehicles == 0 {
                1.0
            } else {
                1.0 - totals.unfinished as f64 / totals.vehicles as f64
            };
            results.push(CellResult {
                cell: *cell,
                workload: workload.label(),
                totals,
                completion,
            });
        }
    }
    let axis = |f: fn(&Cell) -> f64| {
        let mut v: Vec<f64> = Vec::new();
        for c in cells.iter().filter(|c| c.variant == "grid") {
            if !v.contains(&f(c)) {
                v.push(f(c));
            }
        }
        v
    };
    GridReport {
        losses: axis(|c| c.loss),
        delays: axis(|c| c.delay_s),
        unsafe_cells: results.iter().filter(|r| !r.safety().is_safe()).count() as u64,
        cells: results,
        runs,
        seed,
        invariant: crate::world::invariant_name(plan.invariant),
        trucks: plan.trucks,
        wall_seconds,
    }
}

/// A short name of a cell (for scenario names).
pub fn cell_name(c: &Cell) -> String {
    match c.variant {
        "grid" => format!("loss{}-delay{}", c.loss, c.delay_s),
        v => v.to_owned(),
    }
}

/// Six vehicles in one lane at the smallest safe gap at a random speed; the scripted
/// leader cruises 2 s, then brakes at amin to a stop and stays.
fn platoon(seed: u64, draw: &mut Bodies) -> RoadScenario {
    let lim = Limits::table_i();
    let mut r = rng(seed ^ 0x706c_6174);
    let v = r.random_range(5.0..lim.v_max);
    let bodies: Vec<Body> = (0..6).map(|_| draw.next()).collect();
    // Each at the smallest safe spacing behind the one ahead, for its own body.
    let mut xs = vec![300.0];
    for w in bodies.windows(2) {
        let ahead = xs.last().copied().unwrap_or(300.0);
        xs.push(ahead - spacing(v, w[0], w[1]));
    }
    // The leader brakes at its own limit.
    let lead_brake = bodies.first().map_or(lim.brake, |b| b.brake);
    let stop_at = 2.0 + v / lead_brake;
    let mut vehicles: Vec<RoadVehicle> = (0..6u16)
        .map(|i| RoadVehicle {
            id: i + 1,
            x: xs[usize::from(i)],
            lane: 0,
            v,
            target_lane: None,
            driver: if i == 0 {
                DriverKind::Script
            } else {
                DriverKind::Planner
            },
            script: if i == 0 {
                vec![
                    Phase {
                        until_s: 2.0,
                        accel: 0.0,
                    },
                    Phase {
                        until_s: stop_at,
                        accel: -lead_brake,
                    },
                ]
            } else {
                Vec::new()
            },
            goal_x: None,
            v_ref: Some(v),
            length: None,
            brake: None,
            cooperative: None,
        })
        .collect();
    for (v, &b) in vehicles.iter_mut().zip(&bodies) {
        with_body(v, b);
    }
    RoadScenario::new(
        format!("grid-platoon-{seed}"),
        15.0,
        seed,
        Road {
            lanes: 1,
            end_x: None,
        },
        vehicles,
    )
}

/// Three lanes: four planners with random target lanes and two drivers with random
/// admissible accelerations that do not cooperate, at random safe spacings.
fn non_cooperative(seed: u64, draw: &mut Bodies) -> RoadScenario {
    let mut r = rng(seed ^ 0x6e6f_6e63);
    let mut back: [Option<(f64, Body)>; 3] = [None; 3];
    let mut vehicles = Vec::new();
    for i in 0..6u16 {
        let lane = r.random_range(0..3u8);
        let v = r.random_range(5.0..20.0);
        let slot = &mut back[usize::from(lane)];
        let planner = i % 3 != 2;
        // Planners are trucks at the drawn share; the random drivers stay cars.
        let body = if planner { draw.next() } else { Body::CAR };
        // A random driver may accelerate: leave it room for a second at amax.
        let x = match *slot {
            None => r.random_range(100.0..160.0),
            Some((ahead, lead)) => {
                ahead - spacing(Limits::table_i().v_max, lead, body) - r.random_range(0.0..20.0)
            }
        };
        *slot = Some((x, body));
        let mut vehicle = RoadVehicle {
            id: i + 1,
            x,
            lane,
            v,
            target_lane: planner.then(|| r.random_range(0..3u8)),
            driver: if planner {
                DriverKind::Planner
            } else {
                DriverKind::Random
            },
            script: Vec::new(),
            goal_x: None,
            v_ref: None,
            length: None,
            brake: None,
            cooperative: None,
        };
        with_body(&mut vehicle, body);
        vehicles.push(vehicle);
    }
    RoadScenario::new(
        format!("grid-non-cooperative-{seed}"),
        60.0,
        seed,
        Road {
            lanes: 3,
            end_x: None,
        },
        vehicles,
    )
}

/// Up to three vehicles on each inlet lane of the SPEC §8 intersection.
fn intersection(algorithm: Algorithm, seed: u64, trucks: u8) -> JunctionScenario {
    let mut lt = LayoutToml::default();
    if trucks > 0 {
        // A_S around the same turns made to take a truck's swing (as `crossings`).
        lt = truck_layout(lt);
    }
    let layout = crate::scenario::junction::build_layout(&lt)
        .unwrap_or_else(|_| unreachable!("the SPEC §8 layout is valid"));
    let placements = queues_of(&mut rng(seed), &layout, (3, trucks));
    JunctionScenario::new(
        format!("grid-intersection-{}-{seed}", algorithm.name()),
        600.0,
        seed,
        algorithm,
        lt,
        placements,
    )
    .unwrap_or_else(|_| unreachable!("queue placements are valid for cars and trucks"))
}

impl core::fmt::Display for GridReport {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        writeln!(
            f,
            "fault grid: {} runs per workload and cell; every vehicle with the onboard radar; \
             {} % of the planners' vehicles trucks; {} invariant",
            self.runs, self.trucks, self.invariant
        )?;
        writeln!(
            f,
            "{:<22} {:<22} {:>5} {:>7} {:>9} {:>9} {:>10} {:>12}",
            "cell",
            "workload",
            "runs",
            "unsafe",
            "complete",
            "finish s",
            "deadlocks",
            "own silence"
        )?;
        for r in &self.cells {
            writeln!(
                f,
                "{:<22} {:<22} {:>5} {:>7} {:>8.0}% {:>9.1} {:>10} {:>12}",
                cell_name(&r.cell),
                r.workload,
                r.totals.cases,
                r.safety().events(),
                100.0 * r.completion,
                r.totals.mean_finish_time_s,
                r.totals.deadlocks,
                r.totals.own_silence
            )?;
        }
        write!(
            f,
            "cells with an unsafe event: {} of {}; wall time {:.1} s",
            self.unsafe_cells,
            self.cells.len(),
            self.wall_seconds
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn workloads_are_valid_and_the_platoon_is_at_the_smallest_safe_gap() {
        for k in 0..5 {
            for w in Workload::all() {
                let world = w.world(1, k, 0);
                assert!(!world.vehicles.is_empty(), "{}", w.label());
            }
            let p = platoon(k, &mut Bodies::new(k, 0));
            let lim = Limits::table_i();
            let gap = p.vehicles[0].x - p.vehicles[1].x;
            assert!((gap - super::super::multilane::safe_spacing(p.vehicles[0].v)).abs() < 1e-9);
            assert!(
                gap - crate::world::LENGTH_M - lim.d0 < lim.safe_distance(p.vehicles[0].v) + 1.0
            );
        }
        assert_eq!(Cell::all().len(), 29);
        let silent = Cell::all()[28].faults(1);
        assert_eq!(silent.silent.map(|s| s.id), Some(1));
        for c in Cell::all() {
            c.faults(1).validate().unwrap_or_else(|e| panic!("{e}"));
        }
    }

    /// With trucks: every workload has some (and cars still), every follower at least
    /// its own smallest safe spacing behind the one ahead, the platoon's leader braking at
    /// its own limit; with none, the bodies are the cars the grid always had.
    #[test]
    fn workloads_with_trucks_draw_them_and_space_them() {
        let mut trucks = 0;
        let mut all = 0;
        for k in 0..4 {
            for w in Workload::all() {
                for v in &w.world(1, k, 0).vehicles {
                    assert_eq!(v.body, Body::CAR, "{}", w.label());
                }
                let world = w.world(1, k, 50);
                all += world.vehicles.len();
                trucks += world
                    .vehicles
                    .iter()
                    .filter(|v| v.body == Body::TRUCK)
                    .count();
            }
            let p = platoon(k, &mut Bodies::new(k, 50));
            for pair in p.vehicles.windows(2) {
                let (a, b) = (&pair[0], &pair[1]);
                let want = spacing(a.v, a.body(), b.body());
                assert!((a.x - b.x - want).abs() < 1e-9, "{k}: {} {}", a.x, b.x);
            }
            let lead = &p.vehicles[0];
            let brake = lead.script.last().map(|ph| -ph.accel);
            assert_eq!(brake, Some(lead.body().brake), "{k}");
        }
        assert!(
            trucks * 5 > all && trucks * 5 < 4 * all,
            "{trucks} of {all}"
        );
    }
}
