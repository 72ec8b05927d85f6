//! `host-sim worlds`: one world of each size, its vehicles all placed at the start on a
//! city grid, run on one in-process bus with a radio of limited range — so that a view
//! that depended on how many vehicles the world holds (a red team found every vehicle
//! falling back once a world held 258) would show it. Per size: the realtime factor, the
//! certified-fallback steps and, among them, the *blind* ones (a view that could not hold
//! every vehicle that may matter to its plan, [`crate::world::heard::View`]), collisions and invariant
//! violations. With `--delay S` each size runs a second time with every message delayed
//! by S seconds and jittered by up to S more, side by side: the cost of a slow bus per
//! simulated second, as a ratio to the clean bus.
//!
//! The world of `n` vehicles is the smallest square grid (300 m blocks, 2 lanes each way)
//! that holds them standing [`SPACING_M`] apart on its segments, each going straight on
//! to the exit ahead of it ([`grid_fleet`], which the example `grid_fleet` prints).

use super::experiment::{duration_within, Experiment, RunError, SettingsError};
use super::shard::MergeError;
use crate::bus::Faults;
use crate::scenario;
use crate::verdict::{Judged, Safety, Verdict};
use crate::world::network::{End, Network};
use crate::world::{SolverChoice, World};
use planner_core::intersection::Movement;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::Path;

/// Centre to centre at a standstill: a 4.5 m vehicle, d0 = 0.5 m and 1 m to spare.
pub const SPACING_M: f64 = 6.0;
/// The grids' block (m).
pub const BLOCK_M: f64 = 300.0;
/// The largest grid side (the loader's 64 intersections).
const MAX_SIDE: u8 = 8;

/// A `[grid]` file of `rows` × `cols` blocks of `block_m`, running `duration_s`, with `n`
/// vehicles placed at the start (no arrivals); or why not. Every vehicle stands still in
/// one lane of a segment, [`SPACING_M`] behind the next, and goes straight to the exit
/// ahead; the lanes fill round robin. The file is checked by the loader before it is
/// returned.
pub fn grid_fleet(
    (rows, cols): (u8, u8),
    n: usize,
    block_m: f64,
    duration_s: f64,
) -> Result<String, String> {
    grid_fleet_with((rows, cols), (n, 0), block_m, duration_s)
}

/// What a grid of `trucks` percent trucks asks for: its junctions' turn inset (room for a
/// truck's swing), the spacing at a standstill (the longest vehicle, d0 and 1 m to
/// spare) and the longest vehicle.
fn fleet_room(trucks: u8) -> (f64, f64, f64) {
    if trucks == 0 {
        (0.0, SPACING_M, crate::world::LENGTH_M)
    } else {
        let truck = crate::world::Body::TRUCK.length;
        (super::crossings::TRUCK_TURN_INSET_M, truck + 1.5, truck)
    }
}

/// [`grid_fleet`] with `trucks` percent of the `n` vehicles trucks ([`Body::TRUCK`],
/// drawn at random from a stream of its own): then every junction holds a truck's swing
/// and every vehicle stands a truck's length apart.
///
/// [`Body::TRUCK`]: crate::world::Body::TRUCK
pub fn grid_fleet_with(
    (rows, cols): (u8, u8),
    (n, trucks): (usize, u8),
    block_m: f64,
    duration_s: f64,
) -> Result<String, String> {
    let grid = grid_table((rows, cols), block_m, trucks);
    let head = format!(
        "name = \"grid-{rows}x{cols}-{n}\"\nduration_s = {duration_s:.1}\nseed = 1\n\
         algorithm = \"pipelined\"\n\n{grid}"
    );
    let slots = slots(&network(&grid, trucks)?, trucks);
    if slots.len() < n {
        return Err(format!(
            "a {rows}x{cols} grid holds {} vehicles {} m apart, not {n}",
            slots.len(),
            fleet_room(trucks).1
        ));
    }
    let mut bodies = crate::reference::instances::rng(0x7472_7563_6b73);
    let mut out = head;
    for (i, (seg, x, lane, hops)) in slots.into_iter().take(n).enumerate() {
        let route = vec!["\"straight\""; hops].join(", ");
        let truck = trucks > 0 && rand::Rng::random_range(&mut bodies, 0..100u8) < trucks;
        let body = if truck {
            let t = crate::world::Body::TRUCK;
            format!("length = {:.1}\nbrake = {:.1}\n", t.length, t.brake)
        } else {
            String::new()
        };
        let _ = write!(
            out,
            "\n[[vehicle]]\nid = {}\nsegment = {seg}\nx = {x:.1}\nlane = {lane}\nv = 0.0\n\
             route = [{route}]\n{body}",
            i + 1
        );
    }
    scenario::parse(&out, Path::new("grid-fleet.toml")).map_err(|e| e.to_string())?;
    Ok(out)
}

/// The `[grid]` table: 2 lanes, and a truck's turn inset with trucks.
fn grid_table((rows, cols): (u8, u8), block_m: f64, trucks: u8) -> String {
    let inset = if trucks == 0 {
        String::new()
    } else {
        format!("turn_inset = {:.1}\n", fleet_room(trucks).0)
    };
    format!("[grid]\nrows = {rows}\ncols = {cols}\nblock_m = {block_m:.1}\nlanes = 2\n{inset}")
}

/// The smallest square grid of [`BLOCK_M`] blocks that holds `n` vehicles, if one does.
pub fn smallest_grid(n: usize) -> Option<u8> {
    smallest_grid_with(n, 0)
}

/// [`smallest_grid`] for a fleet of `trucks` percent trucks (spaced as trucks).
pub fn smallest_grid_with(n: usize, trucks: u8) -> Option<u8> {
    (2..=MAX_SIDE).find(|&k| {
        let table = grid_table((k, k), BLOCK_M, trucks);
        network(&table, trucks).is_ok_and(|net| slots(&net, trucks).len() >= n)
    })
}

/// The network of a `[grid]` table (arrivals make it loadable alone; with trucks among
/// them, its outlets take a truck out of A_C).
fn network(grid: &str, trucks: u8) -> Result<Network, String> {
    let probe = format!(
        "name = \"probe\"\nduration_s = 1.0\n{grid}\n[arrivals]\nrate_vph = 100.0\ntrucks = {trucks}\n"
    );
    scenario::parse(&probe, Path::new("grid.toml"))
        .map(|s| s.network)
        .map_err(|e| e.to_string())
}

/// Every place a vehicle can stand, round robin over the lanes of the segments that lead
/// straight on to an exit: (segment id, x, lane, intersections to its exit).
fn slots(net: &Network, trucks: u8) -> Vec<(u16, f64, u8, usize)> {
    let (_, spacing, longest) = fleet_room(trucks);
    let mut lanes: Vec<Vec<(u16, f64, u8, usize)>> = Vec::new();
    for (k, sg) in net.segments.iter().enumerate() {
        let (Some(hops), End::Junction(j, end)) = (hops_to_exit(net, k), sg.end) else {
            continue;
        };
        let margin = net
            .junctions
            .get(j)
            .map_or(0.0, |jn| jn.layout.spec.comm_margin);
        let start = sg
            .from
            .and_then(|a| net.junctions.get(a))
            .map_or(0.0, |a| a.layout.spec.outlet_length);
        // The front d0 and a metre before the edge of A_C; the rear a metre past the
        // outlet track.
        let last = end - margin - 0.5 * longest - 1.5;
        for lane in 0..sg.lanes {
            let placed = (0..)
                .map(|i| last - f64::from(i) * spacing)
                .take_while(|x| x - 0.5 * longest >= start + 1.0)
                .map(|x| (sg.id, x, lane, hops))
                .collect();
            lanes.push(placed);
        }
    }
    let longest = lanes.iter().map(Vec::len).max().unwrap_or(0);
    (0..longest)
        .flat_map(|i| lanes.iter().filter_map(move |l| l.get(i).copied()))
        .collect()
}

/// How many intersections segment `k` crosses going straight on to an exit, if it does.
fn hops_to_exit(net: &Network, mut k: usize) -> Option<usize> {
    for hops in 0..=net.segments.len() {
        match net.segments.get(k)?.end {
            End::Exit(_) => return Some(hops),
            End::Junction(..) => k = net.after(k, Movement::Straight)?,
            _ => return None,
        }
    }
    None
}

/// One world's run.
#[derive(Debug, Clone, Serialize)]
pub struct WorldRow {
    /// Vehicles in the world.
    pub vehicles: usize,
    /// Its grid (`rows x cols`).
    pub grid: String,
    /// The bus's delay and jitter bound (s); 0: a clean bus.
    pub delay_s: f64,
    /// Simulated seconds.
    pub sim_seconds: f64,
    /// Wall-clock seconds.
    pub wall_seconds: f64,
    /// sim_seconds / wall_seconds.
    pub realtime_factor: f64,
    /// Wall-clock seconds per simulated second, as a ratio to the clean bus's (1 for the
    /// clean run itself).
    pub cost_vs_clean: f64,
    /// Planner steps.
    pub planner_steps: u64,
    /// Certified-fallback steps.
    pub fallback_steps: u64,
    /// Of those, blind (the view could not hold every vehicle that may matter).
    pub blind_steps: u64,
    /// Collisions (pairs × steps).
    pub collisions: u64,
    /// Invariant violations (pairs × steps).
    pub invariant_violations: u64,
}

/// `host-sim worlds`'s settings (its flags).
#[derive(Debug, Clone, PartialEq, clap::Args)]
pub struct Worlds {
    /// World sizes (vehicles, comma-separated; each 1 to the 8x8 grid's capacity).
    #[arg(long, value_delimiter = ',', default_value = "100,500,1000,2000,5000")]
    pub vehicles: Vec<usize>,
    /// Simulated seconds per world.
    #[arg(long, default_value_t = 5.0)]
    pub duration: f64,
    /// Also run each world with every message delayed by this many seconds and jittered
    /// by up to as many more (at most 10, the loader's bound).
    #[arg(long)]
    pub delay: Option<f64>,
    /// The invariant every planner keeps toward the vehicle ahead.
    #[arg(long, default_value = crate::world::DEFAULT_INVARIANT_NAME, value_parser = super::flags::invariant())]
    pub invariant: planner_core::Invariant,
    /// Percent of the vehicles that are trucks (16.5 m, braking at 4.5 m/s²), drawn per
    /// vehicle: every junction then holds a truck's swing and every vehicle stands a
    /// truck's length apart.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u8).range(0..=100))]
    pub trucks: u8,
}

impl Experiment for Worlds {
    const NAME: &'static str = "worlds";
    type Part = WorldsReport;
    type Report = WorldsReport;

    fn validate(&self) -> Result<(), SettingsError> {
        duration_within(self.duration, 600.0)?;
        if self
            .delay
            .is_some_and(|d| !(d.is_finite() && d > 0.0 && d <= 10.0))
        {
            return Err(SettingsError::raw(
                "--delay",
                "--delay must be in (0, 10] s".into(),
            ));
        }
        if self.vehicles.contains(&0) {
            return Err(SettingsError::new(
                "--vehicles",
                "every size must be at least 1",
            ));
        }
        let fits = |n: usize| smallest_grid_with(n, self.trucks).is_some();
        match self.vehicles.iter().find(|&&n| !fits(n)) {
            Some(n) => Err(SettingsError::new(
                "--vehicles",
                format!("no grid up to 8x8 holds {n} vehicles"),
            )),
            None => Ok(()),
        }
    }

    /// One world per size (each run again on the slow bus, with `--delay`).
    fn cases(&self) -> u64 {
        self.vehicles.len() as u64
    }

    fn run(&self, _range: (u64, u64), _threads: usize) -> Result<WorldsReport, RunError> {
        let sizes = (self.vehicles.as_slice(), self.trucks);
        worlds_with(sizes, self.duration, self.delay, self.invariant).map_err(RunError::Internal)
    }

    fn report(&self, parts: Vec<WorldsReport>) -> Result<WorldsReport, MergeError> {
        super::experiment::only_part(parts, Self::NAME)
    }
}

impl core::fmt::Display for WorldsReport {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "| vehicles | grid | delay (s) | sim s | wall s | × real time | cost vs clean | fallback steps | blind | collisions |\n|---|---|---|---|---|---|---|---|---|---|"
        )?;
        for w in &self.worlds {
            write!(
                f,
                "\n| {} | {} | {} | {:.1} | {:.1} | {:.3} | {:.2} | {} | {} | {} |",
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
            )?;
        }
        Ok(())
    }
}

/// The `worlds` report.
#[derive(Debug, Clone, Serialize)]
pub struct WorldsReport {
    /// The invariant every planner kept toward the vehicle ahead (`paper` or
    /// `leader-aware`).
    pub invariant: &'static str,
    /// One row per size (and per bus, with a delay).
    pub worlds: Vec<WorldRow>,
    /// Blind steps over every run.
    pub blind_steps: u64,
    /// Collisions over every run.
    pub collisions: u64,
    /// Invariant violations over every run.
    pub invariant_violations: u64,
}

/// Runs a world of each of `sizes` vehicles for `duration_s`, and again with every
/// message delayed by `delay_s` (if given), every planner keeping `invariant`; or why a
/// size cannot be built.
pub fn worlds(
    sizes: &[usize],
    duration_s: f64,
    delay_s: Option<f64>,
    invariant: planner_core::Invariant,
) -> Result<WorldsReport, String> {
    worlds_with((sizes, 0), duration_s, delay_s, invariant)
}

/// [`worlds`] with `trucks` percent of each world's vehicles trucks
/// ([`grid_fleet_with`]).
pub fn worlds_with(
    (sizes, trucks): (&[usize], u8),
    duration_s: f64,
    delay_s: Option<f64>,
    invariant: planner_core::Invariant,
) -> Result<WorldsReport, String> {
    let mut rows = Vec::new();
    for &n in sizes {
        let side = smallest_grid_with(n, trucks)
            .ok_or_else(|| format!("no grid up to 8x8 holds {n} vehicles"))?;
        let text = grid_fleet_with((side, side), (n, trucks), BLOCK_M, duration_s)?;
        let clean = run(&text, (n, side), invariant, 0.0, None)?;
        let per_second = clean.wall_seconds / clean.sim_seconds.max(1e-9);
        rows.push(clean);
        if let Some(d) = delay_s {
            let mut slow = run(&text, (n, side), invariant, d, Some(per_second))?;
            slow.delay_s = d;
            rows.push(slow);
        }
    }
    Ok(WorldsReport {
        invariant: crate::world::invariant_name(invariant),
        blind_steps: rows.iter().map(|r| r.blind_steps).sum(),
        collisions: rows.iter().map(|r| r.collisions).sum(),
        invariant_violations: rows.iter().map(|r| r.invariant_violations).sum(),
        worlds: rows,
    })
}

/// One run of `text` (`n` vehicles on a `side` × `side` grid) under `invariant`, its
/// messages delayed and jittered by `delay_s` each; `clean`: the clean bus's wall seconds
/// per simulated second.
fn run(
    text: &str,
    (n, side): (usize, u8),
    invariant: planner_core::Invariant,
    delay_s: f64,
    clean: Option<f64>,
) -> Result<WorldRow, String> {
    let mut spec =
        scenario::parse(text, Path::new("grid-fleet.toml")).map_err(|e| e.to_string())?;
    spec.invariant = invariant;
    spec.faults = Faults {
        delay_s,
        jitter_s: delay_s,
        ..spec.faults
    };
    let t0 = std::time::Instant::now();
    let mut w = World::<20>::new(spec, SolverChoice::Ours, None);
    while !w.finished() {
        w.step(&mut |_| {}).map_err(|e| format!("internal: {e}"))?;
    }
    let wall = t0.elapsed().as_secs_f64();
    let s = w.summary(wall);
    let per_second = wall / s.sim_seconds.max(1e-9);
    Ok(WorldRow {
        vehicles: n,
        grid: format!("{side}x{side}"),
        delay_s,
        sim_seconds: s.sim_seconds,
        wall_seconds: wall,
        realtime_factor: s.sim_seconds / wall.max(1e-9),
        cost_vs_clean: clean.map_or(1.0, |c| per_second / c),
        planner_steps: s.planner_steps,
        fallback_steps: s.fallback_steps,
        blind_steps: s.blind_steps,
        collisions: s.collisions,
        invariant_violations: s.invariant_violations,
    })
}

impl Judged for WorldsReport {
    /// Collisions and invariant violations; live when no planner ever stepped blind.
    fn verdict(&self) -> Verdict {
        let s = Safety::of(self.collisions, self.invariant_violations, 0, 0);
        Verdict::new(s, self.blind_steps == 0)
    }
}
