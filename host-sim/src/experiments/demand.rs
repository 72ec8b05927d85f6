//! `host-sim experiment demand`: the literature's standard test of an intersection
//! manager — an open system. Vehicles arrive at each of the SPEC §8 intersection's 8
//! inlet lanes as a Poisson process (vehicles per hour per lane) with a random movement
//! the lane serves; each enters the start of its inlet when it keeps the invariant toward
//! the vehicle ahead there, and waits outside until then. Per algorithm and rate:
//! throughput, delay and the longest queue outside.
//!
//! A vehicle's delay is the time from its arrival at the entry to leaving A_C, less the
//! free-flow time over the same distance on its route at vImax: waiting outside, queueing
//! on the inlet and waiting at the stop line all count. A rate is within an algorithm's
//! capacity when the queues stay bounded, in every run: delays do not grow over the run
//! ([`GROWTH_SLOPE`]: an overloaded junction's delays grow with the arrival time, a
//! stable one's are stationary), at most [`BOUNDED_QUEUE`] vehicles wait outside any
//! lane at the end, and at most [`UNFINISHED_SHARE`] of the arrivals have not crossed
//! [`GRACE_S`] after they arrived.

use super::crossings::spec_layout;
use super::experiment::{duration_within, Experiment, RunError, SettingsError};
use super::shard::{MergeError, Runs};
use super::sweep::case_seed;
use crate::monitor::Limits;
use crate::scenario::junction::build_layout_for;
use crate::verdict::{Judged, Safety, Verdict};
use crate::world::network::{Junction, Network};
use crate::world::{Finish, SolverChoice, World, WorldSpec, LENGTH_M};
use planner_core::crossing::Algorithm;
use planner_core::Invariant;
use serde::{Deserialize, Serialize};

/// Vehicles waiting outside one lane at the end beyond which its queue is unbounded.
pub const BOUNDED_QUEUE: usize = 5;
/// Share of the arrivals that may be unfinished (see [`GRACE_S`]) in a bounded run.
pub const UNFINISHED_SHARE: f64 = 0.01;
/// Arrivals less than this long before the end (s) are not required to have crossed.
pub const GRACE_S: f64 = 120.0;
/// Delays grow when they rise by more than this many seconds per second of arrival time
/// (10 % overload).
pub const GROWTH_SLOPE: f64 = 0.1;

/// One algorithm at one rate (over its seeds).
#[derive(Debug, Clone, Serialize)]
pub struct DemandRow {
    /// Algorithm.
    pub algorithm: &'static str,
    /// Arrivals per inlet lane (vehicles per hour).
    pub rate_vph_per_lane: f64,
    /// Vehicles that crossed, per hour (all 8 lanes).
    pub throughput_vph: f64,
    /// Vehicles offered, per hour (all 8 lanes).
    pub offered_vph: f64,
    /// Mean delay of the vehicles that crossed (s).
    pub mean_delay_s: f64,
    /// 95th percentile of their delays (s).
    pub p95_delay_s: f64,
    /// Longest queue waiting outside one lane (vehicles).
    pub max_queue: usize,
    /// Collisions (pairs × steps).
    pub collisions: u64,
    /// Invariant violations (pairs × steps).
    pub invariant_violations: u64,
    /// Limit violations (speed, acceleration, turn rate) and departures from the road.
    pub limit_violations: u64,
    /// Entries into A_S without a permission.
    pub unpermitted_entries: u64,
    /// Vehicles that arrived at least [`GRACE_S`] before the end and had not crossed.
    pub unfinished: u64,
    /// Runs that deadlocked.
    pub deadlocks: u64,
    /// The queues stayed bounded (see the module docs).
    pub bounded: bool,
}

/// One algorithm's capacity.
#[derive(Debug, Clone, Serialize)]
pub struct Capacity {
    /// Algorithm.
    pub algorithm: &'static str,
    /// Highest rate tested whose queues stayed bounded (vehicles per hour per lane).
    pub capacity_vph_per_lane: f64,
}

/// The `experiment demand` result.
#[derive(Debug, Clone, Serialize)]
pub struct DemandReport {
    /// Per algorithm and rate.
    pub results: Vec<DemandRow>,
    /// Per algorithm.
    pub capacity: Vec<Capacity>,
    /// One lane's physical limit at vImax: vImax / (L + d0 + dS(vImax)), per hour.
    pub lane_limit_vph: f64,
    /// Simulated time per run (s).
    pub duration_s: f64,
    /// Runs per algorithm and rate.
    pub seeds: u64,
    /// The invariant the vehicles keep toward the vehicle ahead.
    pub invariant: &'static str,
    /// Wall-clock time (s).
    pub wall_seconds: f64,
}

/// `experiment demand`'s settings (its flags; a shard's header carries them for
/// `host-sim merge`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, clap::Args)]
pub struct DemandSettings {
    /// Algorithms to run (comma-separated, of STOP, STOP-1, FIFO, CON, CON-fair, PIPE, PLATOON).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "STOP,FIFO,CON-fair,PIPE,PLATOON",
        value_parser = super::flags::algorithm
    )]
    #[serde(with = "super::flags::algorithm_names")]
    pub algorithms: Vec<Algorithm>,
    /// Arrivals per inlet lane, vehicles per hour (comma-separated).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "50,100,150,200,250,300,350,400"
    )]
    pub rates: Vec<f64>,
    /// Simulated seconds per run.
    #[arg(long, default_value_t = 600.0)]
    pub duration: f64,
    /// Runs per algorithm and rate.
    #[arg(long, default_value_t = 2, value_parser = clap::value_parser!(u64).range(1..))]
    pub seeds: u64,
    /// The invariant every vehicle keeps toward the vehicle ahead.
    // A shard header of an older version has none: the paper's.
    #[arg(long, default_value = crate::world::DEFAULT_INVARIANT_NAME, value_parser = super::flags::invariant())]
    #[serde(default, with = "crate::world::invariant_serde")]
    pub invariant: Invariant,
    /// Percent of the arrivals that are trucks (16.5 m, braking at 4.5 m/s²), at SPEC
    /// §8's junction built for a truck's swing; 0 gives the runs as they always were.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u8).range(0..=100))]
    #[serde(default, skip_serializing_if = "super::flags::is_zero")]
    pub trucks: u8,
}

impl DemandSettings {
    /// What it runs: the rates in order.
    pub fn plan(&self) -> Plan {
        let mut plan = Plan::new(&self.algorithms, &self.rates, self.duration, self.seeds);
        plan.invariant = self.invariant;
        plan.trucks = self.trucks;
        plan
    }
}

impl Experiment for DemandSettings {
    const NAME: &'static str = "demand";
    type Part = Runs<RunOutcome>;
    type Report = DemandReport;

    fn validate(&self) -> Result<(), SettingsError> {
        if self.rates.is_empty() || !self.rates.iter().all(|r| *r > 0.0 && *r <= 3600.0) {
            return Err(SettingsError::new(
                "--rates",
                "vehicles per hour per lane, each in (0, 3600]",
            ));
        }
        if self.algorithms.is_empty() {
            return Err(SettingsError::new("--algorithms", "at least one"));
        }
        for (i, a) in self.algorithms.iter().enumerate() {
            if self.algorithms[..i].contains(a) {
                let twice = format!("{} given twice", a.name());
                return Err(SettingsError::new("--algorithms", twice));
            }
        }
        duration_within(self.duration, 7200.0)
    }

    fn cases(&self) -> u64 {
        self.plan().run_count()
    }

    fn run(&self, range: (u64, u64), threads: usize) -> Result<Self::Part, RunError> {
        let plan = self.plan();
        Ok(Runs::timed(|| demand_runs(&plan, range, threads)))
    }

    fn report(&self, parts: Vec<Self::Part>) -> Result<DemandReport, MergeError> {
        let all = Runs::concat(parts);
        Ok(demand_report(&self.plan(), &all.runs, all.wall_seconds))
    }
}

impl Judged for DemandReport {
    /// Every row's findings; live when no run deadlocked (saturation is reported as the
    /// capacity, not judged).
    fn verdict(&self) -> Verdict {
        let safety = self
            .results
            .iter()
            .map(|x| {
                Safety::of(
                    x.collisions,
                    x.invariant_violations,
                    x.limit_violations,
                    x.unpermitted_entries,
                )
            })
            .sum();
        Verdict::new(safety, self.results.iter().all(|x| x.deadlocks == 0))
    }
}

/// What `experiment demand` runs.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// The algorithms, in report order.
    pub algorithms: Vec<Algorithm>,
    /// Arrivals per inlet lane (vehicles per hour): ascending, each once (a capacity is
    /// the last rate before the first saturated one).
    pub rates: Vec<f64>,
    /// Simulated seconds per run.
    pub duration: f64,
    /// Runs per algorithm and rate.
    pub seeds: u64,
    /// The invariant every vehicle keeps toward the vehicle ahead.
    pub invariant: Invariant,
    /// Percent of the arrivals that are trucks.
    pub trucks: u8,
}

impl Plan {
    /// A plan of `seeds` runs of `duration` s per algorithm and rate, the rates put in
    /// order, under the paper's invariant.
    pub fn new(algorithms: &[Algorithm], rates: &[f64], duration: f64, seeds: u64) -> Self {
        Self {
            algorithms: algorithms.to_vec(),
            rates: rates_in_order(rates),
            duration,
            seeds,
            invariant: Invariant::Paper,
            trucks: 0,
        }
    }

    /// The runs in report order: (algorithm, rate, run).
    fn jobs(&self) -> Vec<(Algorithm, f64, u64)> {
        let seeds = self.seeds;
        self.algorithms
            .iter()
            .flat_map(|&a| {
                self.rates
                    .iter()
                    .flat_map(move |&r| (0..seeds).map(move |k| (a, r, k)))
            })
            .collect()
    }

    /// How many runs: algorithms × rates × seeds.
    pub fn run_count(&self) -> u64 {
        self.algorithms.len() as u64 * self.rates.len() as u64 * self.seeds
    }
}

/// The world of one run: the SPEC §8 junction under `algorithm`, arrivals at `rate` per
/// inlet lane.
pub fn world(algorithm: Algorithm, rate: f64, duration: f64, seed: u64) -> WorldSpec {
    world_with(algorithm, (rate, 0), duration, seed)
}

/// [`world`] with `trucks` percent of the arrivals trucks: then the junction is built for
/// a truck's swing ([`spec_layout`]) and its conflicts swept by a truck's rectangle.
pub fn world_with(
    algorithm: Algorithm,
    (rate, trucks): (f64, u8),
    duration: f64,
    seed: u64,
) -> WorldSpec {
    let lt = spec_layout(trucks);
    let fleet = crate::world::Fleet::with_arrivals([], trucks);
    let layout = build_layout_for(&lt, fleet)
        .unwrap_or_else(|e| unreachable!("the SPEC §8 layout is valid for cars and trucks: {e}"));
    let arrivals = crate::scenario::junction::stub_arrivals(
        &layout,
        crate::scenario::common::ArrivalsToml {
            rate_vph: rate,
            trucks,
        },
    );
    WorldSpec {
        name: format!("demand-{}-{rate}-{seed}", algorithm.name()),
        duration_s: duration,
        seed,
        horizon: 20,
        deadline_s: duration,
        network: Network {
            segments: Vec::new(),
            junctions: vec![Junction {
                id: 0,
                centre: (0.0, 0.0),
                layout,
                algorithm,
                inlets: [None; 4],
                outlets: [None; 4],
            }],
        },
        vehicles: Vec::new(),
        faults: crate::bus::Faults::NONE,
        sensing: None,
        arrivals,
        deadlock_window_s: crate::monitor::liveness::DEADLOCK_WINDOW_S,
        finish: Finish::Duration,
        clock_start: planner_core::Instant::EPOCH,
        precision: crate::world::precision::Precision::F64,
        invariant: planner_core::Invariant::Paper,
    }
}

/// What one run gave (a shard prints these for `host-sim merge`).
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RunOutcome {
    delays: Vec<f64>,
    crossed: u64,
    offered: u64,
    unfinished: u64,
    max_queue: usize,
    queued_at_end: usize,
    growing: bool,
    collisions: u64,
    invariant_violations: u64,
    /// Absent in shards of older versions, which did not count them.
    #[serde(default)]
    limit_violations: u64,
    unpermitted: u64,
    deadlock: bool,
}

/// One arrival: when (s), its delay or, if it has not crossed, the least it will be (s).
struct Arrival {
    at: f64,
    delay: f64,
    crossed: bool,
}

/// Free-flow time from the start of the inlet (centre at L/2, `length` the vehicle's L)
/// to leaving A_C on route `route` at vImax (s).
fn free_flow(jn: Option<&Junction>, route: Option<u8>, length: f64) -> f64 {
    route
        .zip(jn)
        .and_then(|(r, j)| j.layout.route(usize::from(r)).map(|r| (r, j)))
        .map_or(0.0, |(r, j)| {
            (r.path.exit() + j.layout.spec.comm_margin - 0.5 * length) / j.layout.spec.v_limit
        })
}

/// Every arrival of a finished run: those that entered and those still waiting outside.
fn arrivals(w: &World<20>, jn: Option<&Junction>) -> Vec<Arrival> {
    let end = w.time();
    let mut out: Vec<Arrival> = w
        .all_vehicles()
        .map(|v| {
            let route = match v.at() {
                crate::world::at::At::Crossing { route, .. } => Some(route),
                _ => None,
            };
            let free = free_flow(jn, route, v.body.length);
            let out = v.log.left_at.unwrap_or(end);
            Arrival {
                at: v.log.entered_at,
                delay: (out - v.log.entered_at - free).max(0.0),
                crossed: v.log.left_at.is_some(),
            }
        })
        .collect();
    out.extend(w.waiting_since().into_iter().map(|at| Arrival {
        at,
        delay: end - at,
        crossed: false,
    }));
    out
}

/// `true` if delays grow: the least-squares slope of delay against arrival time, over
/// the arrivals from T/6 (past the warm-up) to T − [`GRACE_S`] (those still under way at
/// the end count with the least their delay will be), exceeds [`GROWTH_SLOPE`]. A stable
/// queue's delays are stationary (slope ≈ 0); an overloaded junction's grow by
/// 1 − capacity/demand seconds per second.
fn growing(arrivals: &[Arrival], end: f64) -> bool {
    let pts: Vec<(f64, f64)> = arrivals
        .iter()
        .filter(|a| a.at >= end / 6.0 && a.at < end - GRACE_S)
        .map(|a| (a.at, a.delay))
        .collect();
    let n = pts.len() as f64;
    if n < 10.0 {
        return false;
    }
    let (mx, my) = (
        pts.iter().map(|p| p.0).sum::<f64>() / n,
        pts.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    sxx > 0.0 && sxy / sxx > GROWTH_SLOPE
}

fn one(algorithm: Algorithm, rate: f64, plan: &Plan, seed: u64) -> RunOutcome {
    let mut spec = world_with(algorithm, (rate, plan.trucks), plan.duration, seed);
    spec.invariant = plan.invariant;
    let net = spec.network.clone();
    let mut w = World::<20>::new(spec, SolverChoice::Ours, None);
    while !w.finished() {
        if w.step(&mut |_| {}).is_err() {
            break;
        }
    }
    let s = w.summary(0.0);
    let end = w.time();
    let all = arrivals(&w, net.junctions.first());
    let (max_queue, queued) = w.queues();
    RunOutcome {
        delays: all.iter().filter(|a| a.crossed).map(|a| a.delay).collect(),
        crossed: all.iter().filter(|a| a.crossed).count() as u64,
        offered: all.len() as u64,
        // Arrived long enough before the end to have crossed even after a long wait.
        unfinished: all
            .iter()
            .filter(|a| !a.crossed && a.at + GRACE_S <= end)
            .count() as u64,
        max_queue,
        queued_at_end: queued,
        growing: growing(&all, end),
        collisions: s.collisions,
        invariant_violations: s.invariant_violations,
        limit_violations: s.limit_violations + s.road_end_overruns + s.off_road,
        unpermitted: s.unpermitted_entries(),
        deadlock: s.deadlock.is_some(),
    }
}

/// The rates as the experiment runs them: ascending, each once (a capacity is the last
/// rate before the first saturated one).
pub fn rates_in_order(rates: &[f64]) -> Vec<f64> {
    let mut rates = rates.to_vec();
    rates.sort_by(f64::total_cmp);
    rates.dedup();
    rates
}

/// The runs [first, end) of `plan` (of [`Plan::run_count`], in (algorithm, rate, run)
/// order), on `threads` threads. A run's seed depends on its rate and index alone, so an
/// algorithm's rows do not depend on which others run, nor a run on its shard.
pub fn demand_runs(plan: &Plan, (first, end): (u64, u64), threads: usize) -> Vec<RunOutcome> {
    let jobs = plan.jobs();
    let base = (first.min(end) as usize).min(jobs.len());
    let mine = &jobs[base..(end as usize).min(jobs.len())];
    super::par::map_indexed(mine.len(), threads, |i| {
        let (a, r, k) = mine[i];
        one(a, r, plan, case_seed(r.to_bits(), k))
    })
}

/// The report over every run of `plan`, `outs` in run order.
pub fn demand_report(plan: &Plan, outs: &[RunOutcome], wall_seconds: f64) -> DemandReport {
    let (duration, seeds) = (plan.duration, plan.seeds);
    let jobs = plan.jobs();
    let mut results = Vec::new();
    for &a in &plan.algorithms {
        for &r in &plan.rates {
            let mine: Vec<&RunOutcome> = jobs
                .iter()
                .zip(outs)
                .filter(|((b, q, _), _)| *b == a && *q == r)
                .map(|(_, o)| o)
                .collect();
            results.push(row(a, r, duration, &mine));
        }
    }
    let capacity = plan
        .algorithms
        .iter()
        .map(|&a| Capacity {
            algorithm: a.name(),
            // The highest rate tested below the first that saturates it.
            capacity_vph_per_lane: results
                .iter()
                .filter(|x| x.algorithm == a.name())
                .take_while(|x| x.bounded)
                .map(|x| x.rate_vph_per_lane)
                .fold(0.0, f64::max),
        })
        .collect();
    let lim = Limits::table_i();
    let v = 13.9;
    DemandReport {
        results,
        capacity,
        lane_limit_vph: 3600.0 * v / (LENGTH_M + lim.d0 + lim.safe_distance(v)),
        duration_s: duration,
        seeds,
        invariant: crate::world::invariant_name(plan.invariant),
        wall_seconds,
    }
}

fn row(a: Algorithm, rate: f64, duration: f64, runs: &[&RunOutcome]) -> DemandRow {
    let mut delays: Vec<f64> = runs.iter().flat_map(|o| o.delays.iter().copied()).collect();
    delays.sort_by(f64::total_cmp);
    let hours = duration / 3600.0 * runs.len().max(1) as f64;
    let crossed: u64 = runs.iter().map(|o| o.crossed).sum();
    let offered: u64 = runs.iter().map(|o| o.offered).sum();
    let p95 = delays
        .get(((delays.len() as f64 - 1.0) * 0.95).round().max(0.0) as usize)
        .copied()
        .unwrap_or(0.0);
    let bounded = runs.iter().all(|o| {
        !o.growing
            && o.queued_at_end <= BOUNDED_QUEUE
            && o.unfinished as f64 <= UNFINISHED_SHARE * o.offered as f64
    });
    DemandRow {
        algorithm: a.name(),
        rate_vph_per_lane: rate,
        throughput_vph: crossed as f64 / hours,
        offered_vph: offered as f64 / hours,
        mean_delay_s: delays.iter().sum::<f64>() / delays.len().max(1) as f64,
        p95_delay_s: p95,
        max_queue: runs.iter().map(|o| o.max_queue).max().unwrap_or(0),
        collisions: runs.iter().map(|o| o.collisions).sum(),
        invariant_violations: runs.iter().map(|o| o.invariant_violations).sum(),
        limit_violations: runs.iter().map(|o| o.limit_violations).sum(),
        unpermitted_entries: runs.iter().map(|o| o.unpermitted).sum(),
        unfinished: runs.iter().map(|o| o.unfinished).sum(),
        deadlocks: runs.iter().map(|o| u64::from(o.deadlock)).sum(),
        bounded,
    }
}

impl core::fmt::Display for DemandReport {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        writeln!(
            f,
            "open-system demand at the four-way intersection: {} run(s) of {} s per algorithm and rate, {} invariant",
            self.seeds, self.duration_s, self.invariant
        )?;
        writeln!(
            f,
            "{:<9} {:>9} {:>9} {:>10} {:>8} {:>8} {:>6} {:>7} {:>10}",
            "algorithm",
            "veh/h/ln",
            "offered",
            "through",
            "delay s",
            "p95 s",
            "queue",
            "unfin.",
            "collisions"
        )?;
        for r in &self.results {
            writeln!(
                f,
                "{:<9} {:>9.0} {:>9.0} {:>10.0} {:>8.1} {:>8.1} {:>6} {:>7} {:>10}{}",
                r.algorithm,
                r.rate_vph_per_lane,
                r.offered_vph,
                r.throughput_vph,
                r.mean_delay_s,
                r.p95_delay_s,
                r.max_queue,
                r.unfinished,
                r.collisions + r.invariant_violations + r.unpermitted_entries,
                if r.bounded { "" } else { "  saturated" }
            )?;
        }
        write!(f, "capacity (veh/h/lane, highest bounded rate tested):")?;
        for c in &self.capacity {
            write!(f, " {} {:.0};", c.algorithm, c.capacity_vph_per_lane)?;
        }
        writeln!(f, " one lane's physical limit {:.0}", self.lane_limit_vph)?;
        write!(f, "wall time {:.1} s", self.wall_seconds)
    }
}
