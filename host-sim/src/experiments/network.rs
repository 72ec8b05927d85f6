//! `host-sim experiment network`: open-system traffic on a grid of intersections.
//!
//! Vehicles arrive at every boundary inlet of a rows × cols grid (Poisson, `rate`
//! vehicles per hour per inlet, spread evenly over its lanes) with a random boundary
//! destination, routed by the shortest path; they change lanes toward each turn, cross
//! with the IC Protocol and leave at their destination. A trip's delay is its time from
//! arrival (waiting outside included) to leaving the network, less the free-flow time of
//! the same route ([`crate::world::network::Network::free_flow_s`]).
//!
//! Targets: 0 collisions, 0 invariant violations, 0 unpermitted entries, no
//! deadlock, and at least 95 % of the trips that arrived at least free flow + [`GRACE_S`]
//! before the end completed.

use super::crossings::TRUCK_TURN_INSET_M;
use super::experiment::{duration_within, Experiment, RunError, SettingsError};
use super::shard::{combine_all, MergeError};
use crate::scenario::junction::AlgorithmToml;
use crate::scenario::network::NetworkScenario;
use crate::verdict::{Judged, Safety, Verdict};
use crate::world::{SolverChoice, World, WorldSpec};
use planner_core::crossing::Algorithm;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Trips that arrived less than their free-flow time plus this before the end (s) are
/// not required to have completed.
pub const GRACE_S: f64 = 120.0;

/// Rows × columns of intersections (`RxC` on the command line, each 1 to 8).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct GridSize {
    /// Rows.
    pub rows: u8,
    /// Columns.
    pub cols: u8,
}

impl std::str::FromStr for GridSize {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let bad = || format!("{s}: rows x columns, e.g. 3x3, each 1 to 8");
        let (r, c) = s.split_once(['x', 'X']).ok_or_else(bad)?;
        let (rows, cols): (u8, u8) = (
            r.trim().parse().map_err(|_| bad())?,
            c.trim().parse().map_err(|_| bad())?,
        );
        if (1..=8).contains(&rows) && (1..=8).contains(&cols) {
            Ok(Self { rows, cols })
        } else {
            Err(bad())
        }
    }
}

/// `experiment network`'s settings (its flags).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, clap::Args)]
pub struct NetworkSettings {
    /// Rows x columns of intersections, e.g. 3x3.
    #[arg(long, default_value = "3x3", value_parser = clap::value_parser!(GridSize))]
    pub grid: GridSize,
    /// Centre-to-centre distance of intersections (m).
    #[arg(long = "block", default_value_t = 300.0)]
    pub block_m: f64,
    /// Lanes per direction.
    #[arg(long, default_value_t = 2)]
    pub lanes: u8,
    /// Arrivals per boundary inlet, vehicles per hour (spread over its lanes).
    #[arg(long = "rate", default_value_t = 300.0)]
    pub rate_vph: f64,
    /// Simulated seconds.
    #[arg(long = "duration", default_value_t = 600.0)]
    pub duration_s: f64,
    /// Seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The invariant every planner keeps toward the vehicle ahead.
    #[arg(long, default_value = crate::world::DEFAULT_INVARIANT_NAME, value_parser = super::flags::invariant())]
    #[serde(with = "crate::world::invariant_serde")]
    pub invariant: planner_core::Invariant,
    /// Every intersection's crossing algorithm (STOP, STOP-1, FIFO, CON, CON-fair, PIPE,
    /// PLATOON).
    #[arg(long, default_value = "PIPE", value_parser = super::flags::algorithm)]
    #[serde(default = "pipelined", with = "super::flags::algorithm_name")]
    pub algorithm: Algorithm,
    /// Percent of the arrivals that are trucks (16.5 m, braking at 4.5 m/s²); every
    /// intersection is then built for a truck's swing (`turn_inset`).
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u8).range(0..=100))]
    #[serde(default, skip_serializing_if = "super::flags::is_zero")]
    pub trucks: u8,
}

/// The grid's algorithm before it could be chosen (a shard header without one).
fn pipelined() -> Algorithm {
    Algorithm::Pipelined
}

impl Default for NetworkSettings {
    fn default() -> Self {
        Self {
            grid: GridSize { rows: 3, cols: 3 },
            block_m: 300.0,
            lanes: 2,
            rate_vph: 300.0,
            duration_s: 600.0,
            seed: 1,
            invariant: planner_core::Invariant::Paper,
            algorithm: Algorithm::Pipelined,
            trucks: 0,
        }
    }
}

impl Experiment for NetworkSettings {
    const NAME: &'static str = "network";
    type Part = NetworkReport;
    type Report = NetworkReport;

    /// The rate, the duration, and the grid as the scenario loader checks it.
    fn validate(&self) -> Result<(), SettingsError> {
        if !(self.rate_vph > 0.0 && self.rate_vph <= 3600.0) {
            return Err(SettingsError::raw(
                "--rate",
                "--rate: vehicles per hour per boundary inlet, in (0, 3600]".into(),
            ));
        }
        duration_within(self.duration_s, 7200.0)?;
        self.world()
            .map(|_| ())
            .map_err(|e| SettingsError::raw("--grid", e))
    }

    /// One open-system simulation: one case.
    fn cases(&self) -> u64 {
        1
    }

    fn run(&self, _range: (u64, u64), _threads: usize) -> Result<NetworkReport, RunError> {
        run(self).map_err(RunError::Internal)
    }

    fn report(&self, parts: Vec<NetworkReport>) -> Result<NetworkReport, MergeError> {
        super::experiment::only_part(parts, Self::NAME)
    }
}

impl NetworkSettings {
    /// The scenario file of this grid (what `host-sim run` would load).
    pub fn to_toml(&self) -> String {
        // Always named: the file replays under this invariant whatever the default.
        let invariant = format!(
            "invariant = \"{}\"\n",
            crate::world::invariant_name(self.invariant)
        );
        // Trucks: junctions that hold a truck's swing, and the share among the arrivals.
        let (inset, trucks) = match self.trucks {
            0 => (String::new(), String::new()),
            p => (
                format!("turn_inset = {TRUCK_TURN_INSET_M:.1}\n"),
                format!("trucks = {p}\n"),
            ),
        };
        format!(
            "name = \"grid-{r}x{c}\"\nduration_s = {d}\nseed = {seed}\nalgorithm = \"{a}\"\n{invariant}\n\
             [grid]\nrows = {r}\ncols = {c}\nblock_m = {b}\nlanes = {l}\n{inset}\n\
             [arrivals]\nrate_vph = {rate}\n{trucks}",
            r = self.grid.rows,
            c = self.grid.cols,
            a = AlgorithmToml::of(self.algorithm).key(),
            d = self.duration_s,
            seed = self.seed,
            b = self.block_m,
            l = self.lanes,
            rate = self.rate_vph / f64::from(self.lanes.max(1)),
        )
    }

    /// The world, or why the grid is refused (the scenario loader's reason).
    pub fn world(&self) -> Result<WorldSpec, String> {
        NetworkScenario::parse(&self.to_toml(), Path::new("experiment-network.toml"))
            .map(|s| s.world())
            .map_err(|e| e.to_string())
    }
}

/// The `experiment network` result.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct NetworkReport {
    /// "RxC".
    pub grid: String,
    /// Arrivals per boundary inlet (vehicles per hour).
    pub rate_vph: f64,
    /// The invariant every planner kept (`paper`, `leader-aware`).
    pub invariant: String,
    /// Every intersection's crossing algorithm (`PIPE`, `PLATOON`, …).
    pub algorithm: String,
    /// Vehicles that entered the network.
    pub vehicles_spawned: u64,
    /// Trips completed (left at their destination).
    pub trips_completed: u64,
    /// Vehicles still in the network at the end.
    pub trips_in_progress: u64,
    /// Arrivals still waiting outside at the end.
    pub waiting_outside: u64,
    /// Trips that arrived at least free flow + [`GRACE_S`] before the end.
    pub trips_due: u64,
    /// Of those, the share completed (target ≥ 0.95).
    pub due_completed_share: f64,
    /// Mean time of the completed trips, from arrival to leaving (s).
    pub mean_trip_time_s: f64,
    /// Mean of their delays against the free-flow time of the same route (s).
    pub mean_delay_s: f64,
    /// Lane changes completed.
    pub lane_changes: u64,
    /// Movements given up by vehicles that could not reach a lane serving them before the
    /// edge of A_C (each took a detour: [`crate::world::reroute`]).
    pub turns_given_up: u64,
    /// Junction crossings completed.
    pub crossings: u64,
    /// Collisions (pairs × steps).
    pub collisions: u64,
    /// Invariant violations (pairs × steps).
    pub invariant_violations: u64,
    /// Limit violations, road-end overruns and departures from the road.
    pub limit_violations: u64,
    /// Steps × vehicles inside A_S without a permission.
    pub unpermitted_entries: u64,
    /// Runs that deadlocked (0 or 1).
    pub deadlocks: u64,
    /// Mean and largest number of vehicles in the network at once.
    pub mean_vehicles: f64,
    /// Largest number of vehicles in the network at once.
    pub max_vehicles: u64,
    /// Simulated seconds.
    pub sim_seconds: f64,
    /// Wall-clock seconds.
    pub wall_seconds: f64,
    /// Simulated per wall-clock second.
    pub realtime_factor: f64,
}

impl NetworkReport {
    /// The due trips completed (the share is what the report keeps).
    pub fn due_completed(&self) -> u64 {
        (self.due_completed_share * self.trips_due as f64).round() as u64
    }
}

/// Runs the grid of `s` to its end.
pub fn run(s: &NetworkSettings) -> Result<NetworkReport, String> {
    run_with(s, &mut |_| {})
}

/// [`run`], handing a deadlock, if one ends the run, to `deadlock`.
pub fn run_with(
    s: &NetworkSettings,
    deadlock: &mut dyn FnMut(&crate::monitor::liveness::Deadlock),
) -> Result<NetworkReport, String> {
    let spec = s.world()?;
    let t0 = std::time::Instant::now();
    let mut w = World::<20>::new(spec, SolverChoice::Ours, None);
    let (mut sum, mut steps, mut most) = (0u64, 0u64, 0u64);
    while !w.finished() {
        w.step(&mut |_| {}).map_err(|e| e.to_string())?;
        let n = w.vehicles().len() as u64;
        sum += n;
        steps += 1;
        most = most.max(n);
    }
    let wall = t0.elapsed().as_secs_f64();
    let end = w.time();
    if let Some(d) = w.deadlock() {
        deadlock(d);
    }
    let summary = w.summary(wall);
    let trips = Trips::of(&w, end);
    Ok(NetworkReport {
        grid: format!("{}x{}", s.grid.rows, s.grid.cols),
        rate_vph: s.rate_vph,
        invariant: crate::world::invariant_name(s.invariant).into(),
        algorithm: s.algorithm.name().into(),
        vehicles_spawned: trips.spawned,
        trips_completed: trips.completed,
        trips_in_progress: w.vehicles().len() as u64,
        waiting_outside: w.waiting_since().len() as u64,
        trips_due: trips.due,
        due_completed_share: if trips.due == 0 {
            1.0
        } else {
            trips.due_completed as f64 / trips.due as f64
        },
        mean_trip_time_s: trips.mean_time,
        mean_delay_s: trips.mean_delay,
        lane_changes: summary.lane_changes.changes as u64,
        turns_given_up: trips.turns_given_up,
        crossings: summary.crossed(),
        collisions: summary.collisions,
        invariant_violations: summary.invariant_violations,
        limit_violations: summary.limit_violations + summary.road_end_overruns + summary.off_road,
        unpermitted_entries: summary.unpermitted_entries(),
        deadlocks: u64::from(summary.deadlock.is_some()),
        mean_vehicles: sum as f64 / steps.max(1) as f64,
        max_vehicles: most,
        sim_seconds: end,
        wall_seconds: wall,
        realtime_factor: end / wall.max(1e-9),
    })
}

/// The trips of a finished run.
struct Trips {
    spawned: u64,
    completed: u64,
    due: u64,
    due_completed: u64,
    mean_time: f64,
    mean_delay: f64,
    turns_given_up: u64,
}

impl Trips {
    fn of(w: &World<20>, end: f64) -> Self {
        let mut t = Trips {
            spawned: 0,
            completed: 0,
            due: 0,
            due_completed: 0,
            mean_time: 0.0,
            mean_delay: 0.0,
            turns_given_up: 0,
        };
        let (mut time, mut delay) = (0.0, 0.0);
        for v in w.all_vehicles() {
            t.spawned += 1;
            t.turns_given_up += u64::from(v.log.turns_given_up);
            let free = v.log.free_flow_s.unwrap_or(0.0);
            let is_due = v.log.entered_at + free + GRACE_S <= end;
            t.due += u64::from(is_due);
            if let Some(out) = v.log.left_at {
                t.completed += 1;
                t.due_completed += u64::from(is_due);
                time += out - v.log.entered_at;
                delay += (out - v.log.entered_at - free).max(0.0);
            }
        }
        // Arrivals waiting outside since long before the end are due and not completed.
        t.due += w
            .waiting_since()
            .iter()
            .filter(|&&a| a + GRACE_S <= end)
            .count() as u64;
        t.mean_time = time / t.completed.max(1) as f64;
        t.mean_delay = delay / t.completed.max(1) as f64;
        t
    }
}

impl core::fmt::Display for NetworkReport {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        writeln!(
            f,
            "grid {} at {:.0} veh/h per boundary inlet, {}, {} invariant, {:.0} s simulated in {:.1} s ({:.1}x realtime)",
            self.grid, self.rate_vph, self.algorithm, self.invariant, self.sim_seconds, self.wall_seconds, self.realtime_factor
        )?;
        writeln!(
            f,
            "  vehicles: {} entered, {} trips completed, {} in progress, {} waiting outside; \
             {:.0} in the network on average, {} at most",
            self.vehicles_spawned,
            self.trips_completed,
            self.trips_in_progress,
            self.waiting_outside,
            self.mean_vehicles,
            self.max_vehicles
        )?;
        writeln!(
            f,
            "  trips due: {}, {:.1} % completed; mean trip {:.1} s, mean delay {:.1} s",
            self.trips_due,
            100.0 * self.due_completed_share,
            self.mean_trip_time_s,
            self.mean_delay_s
        )?;
        writeln!(
            f,
            "  {} lane changes, {} crossings, {} turns given up (detours)",
            self.lane_changes, self.crossings, self.turns_given_up
        )?;
        write!(
            f,
            "  safety: {} collisions, {} invariant violations, {} limit violations, {} unpermitted entries; {} deadlocks",
            self.collisions,
            self.invariant_violations,
            self.limit_violations,
            self.unpermitted_entries,
            self.deadlocks
        )
    }
}

/// `host-sim grids`: random grids — 2 × 2 to 4 × 4 intersections, 1 to 4 lanes, blocks
/// from the shortest the loader takes (the commitment distance (23) for the lane changes
/// a block may need) to 1.8 times that, boundary roads as long as a block, and demand from
/// 100 to 1,500 vehicles per hour per boundary inlet, past saturation — each run for
/// `duration_s`. A case fails on any collision or violation, or a deadlock (with the
/// wait-for relation as its reason); trips that cannot finish in time are reported.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct GridsReport {
    /// Cases run.
    pub cases: u64,
    /// The invariant every planner kept (`paper`, `leader-aware`).
    pub invariant: String,
    /// Vehicles that entered, over all cases.
    pub vehicles: u64,
    /// Trips completed.
    pub trips_completed: u64,
    /// Trips due (arrived at least free flow + [`GRACE_S`] before the end).
    pub trips_due: u64,
    /// Of those, completed.
    pub trips_due_completed: u64,
    /// Collisions (pairs × steps).
    pub collisions: u64,
    /// Invariant violations (pairs × steps).
    pub invariant_violations: u64,
    /// Limit violations, road-end overruns and departures from the road.
    pub limit_violations: u64,
    /// Steps × vehicles inside A_S without a permission.
    pub unpermitted_entries: u64,
    /// Cases that deadlocked.
    pub deadlocks: u64,
    /// Simulated seconds over all cases.
    pub sim_seconds: f64,
    /// The largest number of vehicles in one network at once.
    pub max_vehicles: u64,
    /// The sweep's seed.
    pub seed: u64,
    /// Failing cases (at most 20), each as its file and the reason.
    pub failing: Vec<super::sweep::Failing>,
    /// Every case whose due trips did not all finish, with where those vehicles were.
    pub unfinished: Vec<Unfinished>,
    /// Wall-clock time (s).
    pub wall_seconds: f64,
}

/// A grid whose due trips did not all finish. A deadlock fails the case (its wait-for
/// relation is the reason); this is the other way trips stay unfinished in an open
/// network: every vehicle's wait ends in one that moves, but demand outran what the grid
/// carried in the time, and the vehicles that arrived were still queued in the network
/// or at its entries when the run ended.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Unfinished {
    /// Case index.
    pub case: u64,
    /// Rows × columns.
    pub grid: String,
    /// Lanes per direction.
    pub lanes: u8,
    /// Arrivals per boundary inlet (vehicles per hour).
    pub rate_vph: f64,
    /// Trips due, and of those completed.
    pub due: u64,
    /// Of the due trips, completed.
    pub due_completed: u64,
    /// Trips completed per hour (all of them, due or not).
    pub carried_vph: f64,
    /// Vehicles in the network at the end.
    pub in_network: u64,
    /// Arrivals waiting to enter at the end.
    pub waiting_outside: u64,
    /// Why, in words.
    pub reason: String,
}

impl Unfinished {
    /// The account of case `case` (settings `s`, report `r`), if due trips are unfinished
    /// and it did not deadlock.
    fn of(case: u64, s: &NetworkSettings, r: &NetworkReport) -> Option<Self> {
        let completed = r.due_completed();
        if completed >= r.trips_due || r.deadlocks > 0 {
            return None;
        }
        let carried_vph = r.trips_completed as f64 * 3600.0 / r.sim_seconds.max(1e-9);
        Some(Self {
            case,
            grid: r.grid.clone(),
            lanes: s.lanes,
            rate_vph: s.rate_vph,
            due: r.trips_due,
            due_completed: completed,
            carried_vph,
            in_network: r.trips_in_progress,
            waiting_outside: r.waiting_outside,
            reason: format!(
                "no deadlock: demand of {:.0} veh/h per inlet outran the {carried_vph:.0} \
                 veh/h the grid carried; at the end {} vehicles were in the network and {} \
                 waiting to enter",
                s.rate_vph, r.trips_in_progress, r.waiting_outside
            ),
        })
    }
}

/// `host-sim grids`: its cases, seed, duration and invariant (a shard's header leaves out
/// the paper's invariant, as shards always had it).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, clap::Args)]
pub struct Grids {
    /// Number of random grids.
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u64).range(1..))]
    pub cases: u64,
    /// Seed of the sweep.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Simulated seconds per grid.
    #[arg(long, default_value_t = 180.0)]
    pub duration: f64,
    /// The invariant every planner keeps toward the vehicle ahead.
    #[arg(long, default_value = crate::world::DEFAULT_INVARIANT_NAME, value_parser = super::flags::invariant())]
    #[serde(
        default,
        skip_serializing_if = "super::flags::is_paper",
        with = "crate::world::invariant_serde"
    )]
    pub invariant: planner_core::Invariant,
    /// Percent of the arrivals that are trucks (16.5 m, braking at 4.5 m/s²), at
    /// junctions built for a truck's swing; 0 gives the grids as they always were.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u8).range(0..=100))]
    #[serde(default, skip_serializing_if = "super::flags::is_zero")]
    pub trucks: u8,
}

impl Experiment for Grids {
    const NAME: &'static str = "grids";
    type Part = GridsReport;
    type Report = GridsReport;

    fn validate(&self) -> Result<(), SettingsError> {
        duration_within(self.duration, 3600.0)
    }

    fn cases(&self) -> u64 {
        self.cases
    }

    fn run(&self, (first, end): (u64, u64), threads: usize) -> Result<GridsReport, RunError> {
        let cases = (end - first, first);
        Ok(grids(
            cases,
            (self.seed, self.trucks),
            self.duration,
            self.invariant,
            threads,
        ))
    }

    fn report(&self, parts: Vec<GridsReport>) -> Result<GridsReport, MergeError> {
        combine_all(parts)
    }
}

impl Judged for GridsReport {
    /// Collisions, violations, unpermitted entries; live when no grid deadlocked
    /// (trips demand outran are reported, not judged).
    fn verdict(&self) -> Verdict {
        let safety = Safety::of(
            self.collisions,
            self.invariant_violations,
            self.limit_violations,
            self.unpermitted_entries,
        );
        Verdict::new(safety, self.deadlocks == 0)
    }
}

impl core::fmt::Display for GridsReport {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let notes: String = self
            .unfinished
            .iter()
            .map(|u| {
                format!(
                    "\n  case {} ({}, {} lanes): {} of {} due trips done; {}",
                    u.case, u.grid, u.lanes, u.due_completed, u.due, u.reason
                )
            })
            .collect();
        let text = super::sweep::text("grids", self.cases, self, &notes, &self.failing);
        f.write_str(&text)
    }
}

/// Case `index` of the grids sweep seeded `seed`, `duration_s` long (the paper's
/// invariant, cars only).
pub fn grid_case(seed: u64, index: u64, duration_s: f64) -> NetworkSettings {
    grid_case_with((seed, 0), index, duration_s)
}

/// [`grid_case`] with `trucks` percent of the arrivals trucks: the same draws, each
/// junction built for a truck's swing and each block at least as long as that takes.
pub fn grid_case_with((seed, trucks): (u64, u8), index: u64, duration_s: f64) -> NetworkSettings {
    use rand::Rng;
    let mut r = crate::reference::instances::rng(super::sweep::case_seed(seed, index));
    let lanes: u8 = r.random_range(1..=4);
    let min = if trucks == 0 {
        crate::scenario::network::min_block_m(lanes)
    } else {
        let truck = crate::world::Body::TRUCK.length;
        crate::scenario::network::min_block_m_for(lanes, TRUCK_TURN_INSET_M, truck)
    };
    NetworkSettings {
        grid: GridSize {
            rows: r.random_range(2..=4),
            cols: r.random_range(2..=4),
        },
        block_m: (min * r.random_range(1.0..1.8)).ceil(),
        lanes,
        rate_vph: r.random_range(100.0f64..1500.0).round(),
        duration_s,
        seed: super::sweep::case_seed(seed, index),
        invariant: planner_core::Invariant::Paper,
        algorithm: Algorithm::Pipelined,
        trucks,
    }
}

/// Runs `cases` grids from index `first` of the sweep seeded `seed`, `trucks` percent of
/// the arrivals trucks, each for `duration_s` with every planner keeping `invariant`, on
/// `threads` threads.
pub fn grids(
    (cases, first): (u64, u64),
    (seed, trucks): (u64, u8),
    duration_s: f64,
    invariant: planner_core::Invariant,
    threads: usize,
) -> GridsReport {
    let t0 = std::time::Instant::now();
    let runs = super::par::map_indexed(cases as usize, threads, |i| {
        let index = first + i as u64;
        let s = NetworkSettings {
            invariant,
            ..grid_case_with((seed, trucks), index, duration_s)
        };
        let deadlock = std::cell::RefCell::new(None);
        let r = run_with(&s, &mut |d| *deadlock.borrow_mut() = Some(d.to_string()));
        (index, s, r, deadlock.into_inner())
    });
    let mut g = GridsReport {
        cases,
        invariant: crate::world::invariant_name(invariant).into(),
        vehicles: 0,
        trips_completed: 0,
        trips_due: 0,
        trips_due_completed: 0,
        collisions: 0,
        invariant_violations: 0,
        limit_violations: 0,
        unpermitted_entries: 0,
        deadlocks: 0,
        sim_seconds: 0.0,
        max_vehicles: 0,
        seed,
        failing: Vec::new(),
        unfinished: Vec::new(),
        wall_seconds: 0.0,
    };
    for (index, s, r, deadlock) in runs {
        let reason = match r {
            Err(e) => Some(format!("did not run: {e}")),
            Ok(r) => {
                g.unfinished.extend(Unfinished::of(index, &s, &r));
                g.vehicles += r.vehicles_spawned;
                g.trips_completed += r.trips_completed;
                g.trips_due += r.trips_due;
                g.trips_due_completed += r.due_completed();
                g.collisions += r.collisions;
                g.invariant_violations += r.invariant_violations;
                g.limit_violations += r.limit_violations;
                g.unpermitted_entries += r.unpermitted_entries;
                g.deadlocks += r.deadlocks;
                g.sim_seconds += r.sim_seconds;
                g.max_vehicles = g.max_vehicles.max(r.max_vehicles);
                let unsafe_events = r.collisions
                    + r.invariant_violations
                    + r.limit_violations
                    + r.unpermitted_entries;
                match (unsafe_events, deadlock) {
                    (0, None) => None,
                    (n, d) => Some(format!(
                        "{n} unsafe events{}",
                        d.map(|d| format!("; {d}")).unwrap_or_default()
                    )),
                }
            }
        };
        if let Some(reason) = reason {
            super::sweep::keep_failing(&mut g.failing, || super::sweep::Failing {
                case: index,
                label: "grid".into(),
                reason,
                scenario: s.to_toml(),
            });
        }
    }
    g.wall_seconds = t0.elapsed().as_secs_f64();
    g
}

impl Judged for NetworkReport {
    /// Collisions, violations, unpermitted entries; live when nothing deadlocked and at
    /// least 95 % of the trips due finished.
    fn verdict(&self) -> Verdict {
        let safety = Safety::of(
            self.collisions,
            self.invariant_violations,
            self.limit_violations,
            self.unpermitted_entries,
        );
        Verdict::new(
            safety,
            self.deadlocks == 0 && self.due_completed_share >= 0.95,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `--algorithm` reaches every junction of the grid, through the file the grid is
    /// loaded from, and a shard header written before the flag reads as the pipelined
    /// grid it ran.
    #[test]
    fn the_grid_runs_the_algorithm_asked_for() {
        for a in [Algorithm::Platoon, Algorithm::Fifo, Algorithm::Pipelined] {
            let s = NetworkSettings {
                algorithm: a,
                ..NetworkSettings::default()
            };
            let w = s.world().expect("a valid grid");
            assert_eq!(w.network.junctions.len(), 9);
            assert!(
                w.network.junctions.iter().all(|j| j.algorithm == a),
                "{a:?}"
            );
        }
        let mut old = serde_json::to_value(NetworkSettings {
            algorithm: Algorithm::Platoon,
            ..NetworkSettings::default()
        })
        .expect("json");
        assert_eq!(old["algorithm"], "PLATOON");
        old.as_object_mut().expect("an object").remove("algorithm");
        let read: NetworkSettings = serde_json::from_value(old).expect("an old header");
        assert_eq!(read.algorithm, Algorithm::Pipelined);
    }
}
