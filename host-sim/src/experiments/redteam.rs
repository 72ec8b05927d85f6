//! The red team's findings as randomized sweeps, each over cases drawn so that it would
//! have found them: `host-sim outages`, `host-sim liars` and `host-sim ids`.
//!
//! - **outages**: random queues at the SPEC §8 intersection (as `crossings` draws them),
//!   the manager down from a random start (0 to 30 s) for a random length — one period
//!   (10 ms) in a quarter of the cases, else log-uniform from 10 ms to 10 s — under every
//!   algorithm. A case fails on any collision, violation or unpermitted entry, and (the
//!   live algorithms) on a vehicle that has not crossed or a deadlock.
//! - **liars**: the same queues, one vehicle lying about its position by a random offset,
//!   under every algorithm, in two worlds. Half the cases are the paper's world (V2V
//!   alone): the lie starts at a random moment (0.1 to 20 s) and is at least 1 m, a jump
//!   that the physical bounds catch — a lie that never jumps (from the first report on)
//!   or hides within them cannot be told from the truth by anything that only hears
//!   reports, and is no case for this world. The other half have onboard sensors and the
//!   junction's roadside sensor, and any lie: ±0.2 to ±40 m, from the first report on (a
//!   third of them) or from a random moment. A case fails on any collision, violation or
//!   unpermitted entry; what the lie costs in liveness is reported, not judged, with
//!   sensors apart (`with_sensors`): without them no manager or vehicle that only hears
//!   reports can keep every vehicle live (docs/spec.md §9), and with them a few kinds of
//!   lie still cost liveness (docs/redteam.md).
//! - **ids**: a row of 1 to 3 intersections with open Poisson arrivals (600 to 1,800
//!   vehicles per hour per entry lane) whose ids start just below the managers' bus nodes
//!   (0xFF00 − 1 to 8), so that the ids given out run through them. A case fails on any
//!   collision or violation, on a vehicle whose id is a node's, or if no id wrapped.
//!
//! The paper's Concurrent Crossing as written is run for safety too; it is not live
//! (SPEC §7), so its unfinished vehicles are left out of the totals, as in `crossings`.

use super::crossings::{queues_of, spec_layout, ALGORITHMS};
use super::experiment::{Experiment, RunError};
use super::shard::{combine_all, MergeError};
use super::sweep::{self, case_seed, Case, Cases, CasesUnder, Failing, Totals};
use crate::bus::{is_vehicle_id, Faults, Liar, ManagerDown};
use crate::reference::instances::rng;
use crate::scenario::junction::{build_layout, JunctionScenario};
use crate::scenario::network::NetworkScenario;
use crate::verdict::{Judged, Safety, Verdict};
use crate::world::{SolverChoice, World};
use planner_core::crossing::Algorithm;
use rand::Rng;
use serde::{Deserialize, Serialize};

/// Which red-team sweep.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// A manager down for a while.
    Outages,
    /// A vehicle lying about where it is.
    Liars,
}

impl Kind {
    /// Its name.
    pub const fn name(self) -> &'static str {
        match self {
            Kind::Outages => "outages",
            Kind::Liars => "liars",
        }
    }
}

/// `host-sim outages`: cases, seed, invariant and trucks.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, clap::Args)]
pub struct Outages {
    /// Cases, seed, invariant.
    #[command(flatten)]
    #[serde(flatten)]
    pub sweep: CasesUnder,
    /// Percent of the vehicles that are trucks (16.5 m, braking at 4.5 m/s²), drawn per
    /// vehicle at a junction built for a truck's swing; 0 gives the cases as they always
    /// were.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u8).range(0..=100))]
    #[serde(default, skip_serializing_if = "super::flags::is_zero")]
    pub trucks: u8,
}

/// `host-sim liars`: cases, seed, invariant and trucks.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, clap::Args)]
pub struct Liars {
    /// Cases, seed, invariant.
    #[command(flatten)]
    #[serde(flatten)]
    pub sweep: CasesUnder,
    /// Percent of the vehicles that are trucks (16.5 m, braking at 4.5 m/s²), drawn per
    /// vehicle at a junction built for a truck's swing; 0 gives the cases as they always
    /// were.
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u8).range(0..=100))]
    #[serde(default, skip_serializing_if = "super::flags::is_zero")]
    pub trucks: u8,
}

/// `host-sim ids`: cases and seed (each case is a network file, whose invariant is the
/// paper's).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, clap::Args)]
pub struct Ids {
    /// Cases and seed.
    #[command(flatten)]
    #[serde(flatten)]
    pub sweep: Cases,
}

/// The outages and liars sweeps, as one experiment of their kind.
macro_rules! junction_sweep {
    ($t:ty, $kind:expr) => {
        impl Experiment for $t {
            const NAME: &'static str = $kind.name();
            type Part = JunctionFaultsReport;
            type Report = JunctionFaultsReport;

            fn cases(&self) -> u64 {
                self.sweep.sweep.cases
            }

            fn run(
                &self,
                (first, end): (u64, u64),
                threads: usize,
            ) -> Result<JunctionFaultsReport, RunError> {
                let s = &self.sweep;
                let range = (end - first, first);
                Ok(junction_faults(
                    $kind,
                    range,
                    (s.sweep.seed, s.invariant, self.trucks),
                    threads,
                ))
            }

            fn report(
                &self,
                parts: Vec<JunctionFaultsReport>,
            ) -> Result<JunctionFaultsReport, MergeError> {
                combine_all(parts)
            }
        }
    };
}

junction_sweep!(Outages, Kind::Outages);
junction_sweep!(Liars, Kind::Liars);

impl Judged for JunctionFaultsReport {
    /// Over every run; live as [`JunctionFaultsReport::live`] judges.
    fn verdict(&self) -> Verdict {
        Verdict::new(self.totals.safety(), self.live())
    }
}

impl core::fmt::Display for JunctionFaultsReport {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let text = sweep::text(&self.sweep, self.totals.cases, self, "", &self.failing);
        f.write_str(&text)
    }
}

impl Experiment for Ids {
    const NAME: &'static str = "ids";
    type Part = IdsReport;
    type Report = IdsReport;

    fn cases(&self) -> u64 {
        self.sweep.cases
    }

    fn run(&self, (first, end): (u64, u64), threads: usize) -> Result<IdsReport, RunError> {
        Ok(ids(end - first, first, self.sweep.seed, threads))
    }

    fn report(&self, parts: Vec<IdsReport>) -> Result<IdsReport, MergeError> {
        combine_all(parts)
    }
}

impl Judged for IdsReport {
    /// Collisions, violations and node ids given to vehicles (a breach); live when every
    /// case's ids wrapped past the managers' nodes.
    fn verdict(&self) -> Verdict {
        let safety = Safety {
            breaches: self.node_ids,
            ..Safety::of(self.collisions, self.invariant_violations, 0, 0)
        };
        Verdict::new(safety, self.wrapped == self.cases)
    }
}

impl core::fmt::Display for IdsReport {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(&sweep::text("ids", self.cases, self, "", &self.failing))
    }
}

/// One algorithm's row.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct AlgorithmRow {
    /// The algorithm.
    pub algorithm: String,
    /// `false` for the paper's Concurrent Crossing as written (not live).
    pub live: bool,
    /// Its totals.
    #[serde(flatten)]
    pub totals: Totals,
}

/// An `outages` or `liars` result.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct JunctionFaultsReport {
    /// The sweep.
    pub sweep: String,
    /// Over every run (safety) — and, for outages, liveness of the live algorithms.
    #[serde(flatten)]
    pub totals: Totals,
    /// Runs: cases × algorithms.
    pub runs: u64,
    /// Per algorithm.
    pub algorithms: Vec<AlgorithmRow>,
    /// Liveness of the live algorithms in the cases with onboard and roadside sensors
    /// (liars; none for outages), apart from the paper's world's.
    pub with_sensors: Liveness,
    /// The sweep's seed.
    pub seed: u64,
    /// Failing runs (at most 20), each as a scenario file.
    pub failing: Vec<Failing>,
    /// Wall-clock time (s).
    pub wall_seconds: f64,
}

/// What some runs of the live algorithms left undone.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Liveness {
    /// Runs.
    pub runs: u64,
    /// Vehicles not across at the end.
    pub unfinished: u64,
    /// Runs that ended in a deadlock.
    pub deadlocks: u64,
}

impl JunctionFaultsReport {
    /// No collision, violation or unpermitted entry.
    pub fn safe(&self) -> bool {
        self.totals.safety().is_safe()
    }

    /// Every vehicle crossed and nothing deadlocked (judged for outages only: what a liar
    /// costs is reported, with sensors apart — `with_sensors` — and without).
    pub fn live(&self) -> bool {
        self.sweep == Kind::Liars.name() || self.totals.unfinished + self.totals.deadlocks == 0
    }
}

/// The faults of case `index` of `kind` in the sweep seeded `seed`, with the ids of the
/// case's vehicles (for the liar).
pub fn faults(kind: Kind, seed: u64, index: u64, ids: &[u16]) -> Faults {
    // Its own stream, apart from the queues'.
    let mut r = rng(case_seed(seed ^ 0x5eed_fa17, index));
    match kind {
        Kind::Outages => {
            let from_s = r.random_range(0.0..30.0);
            let length = if r.random_bool(0.25) {
                0.01
            } else {
                10f64.powf(r.random_range(-2.0..1.0))
            };
            Faults {
                manager_down: Some(ManagerDown {
                    junction: 0,
                    from_s,
                    until_s: from_s + length,
                }),
                ..Faults::NONE
            }
        }
        Kind::Liars => {
            let id = ids
                .get(r.random_range(0..ids.len().max(1)))
                .copied()
                .unwrap_or(1);
            let sign = if r.random_bool(0.5) { 1.0 } else { -1.0 };
            let (offset, from_s) = if sensed(seed, index) {
                let from_s = if r.random_bool(1.0 / 3.0) {
                    0.0
                } else {
                    r.random_range(0.0..20.0)
                };
                (r.random_range(0.2..40.0), from_s)
            } else {
                (r.random_range(1.0..40.0), r.random_range(0.1..20.0))
            };
            Faults {
                liar: Some(Liar {
                    id,
                    from_s,
                    offset_m: sign * offset,
                }),
                ..Faults::NONE
            }
        }
    }
}

/// `true` if liar case `index` has sensors (onboard and roadside): every other case.
pub fn sensed(seed: u64, index: u64) -> bool {
    case_seed(seed ^ 0x5e25, index).is_multiple_of(2)
}

/// Case `index` of `kind` under `algorithm`: random queues and the case's fault.
pub fn case(kind: Kind, seed: u64, index: u64, algorithm: Algorithm) -> JunctionScenario {
    case_with(kind, (seed, 0), index, algorithm)
}

/// [`case()`] with `trucks_percent` of the vehicles trucks, at SPEC §8's junction built
/// for a truck's swing ([`spec_layout`]); with 0 the case is [`case()`]'s. The fault is
/// drawn from its own stream, so trucks change no fault.
pub fn case_with(
    kind: Kind,
    (seed, trucks_percent): (u64, u8),
    index: u64,
    algorithm: Algorithm,
) -> JunctionScenario {
    let lt = spec_layout(trucks_percent);
    let layout = build_layout(&lt).unwrap_or_else(|_| unreachable!("the SPEC §8 layout is valid"));
    let mut r = rng(case_seed(seed, index));
    let per_lane = [1usize, 2, 3, 5, 8][r.random_range(0..5)];
    let placements = queues_of(&mut r, &layout, (per_lane, trucks_percent));
    let ids: Vec<u16> = placements.iter().map(|p| p.id).collect();
    let mut sc = JunctionScenario::new(
        format!("{}-{seed}-{index}-{}", kind.name(), algorithm.name()),
        300.0,
        case_seed(seed, index),
        algorithm,
        lt,
        placements,
    )
    .unwrap_or_else(|e| unreachable!("the SPEC §8 layout is valid for cars and trucks: {e}"));
    sc.header.faults = faults(kind, seed, index, &ids);
    if kind == Kind::Liars && sensed(seed, index) {
        sc.header.sensing = Some(planner_core::Sensing::radar());
    }
    sc
}

/// Runs `cases` cases of `kind` from index `first` of the sweep seeded `seed`, each under
/// every algorithm with every vehicle keeping `invariant`, `trucks` percent of them
/// trucks, on `threads` threads.
pub fn junction_faults(
    kind: Kind,
    (cases, first): (u64, u64),
    (seed, invariant, trucks): (u64, planner_core::Invariant, u8),
    threads: usize,
) -> JunctionFaultsReport {
    let t0 = std::time::Instant::now();
    let jobs: Vec<(u64, Algorithm)> = (0..cases)
        .flat_map(|i| ALGORITHMS.iter().map(move |&a| (first + i, a)))
        .collect();
    let results: Vec<Case> = super::par::map_indexed(jobs.len(), threads, |j| {
        let (index, algorithm) = jobs[j];
        let mut sc = case_with(kind, (seed, trucks), index, algorithm);
        sc.header.invariant = invariant;
        Case {
            index,
            seed: case_seed(seed, index),
            label: algorithm.name(),
            summary: sweep::run(sc.world()),
            scenario: sc.to_toml(),
        }
    });
    let row = |a: Algorithm| AlgorithmRow {
        algorithm: a.name().into(),
        live: a != Algorithm::Concurrent,
        totals: Totals::of(results.iter().filter(|c| c.label == a.name())),
    };
    // Safety over every run; liveness (outages) over the live algorithms.
    let live = |c: &&Case| c.label != Algorithm::Concurrent.name();
    let mut totals = Totals::of(results.iter());
    let of_live = Totals::of(results.iter().filter(live));
    totals.unfinished = of_live.unfinished;
    totals.deadlocks = of_live.deadlocks;
    // Cases drawn (each run under every algorithm: `runs`), as the other sweeps count.
    totals.cases = cases;
    let failed = |c: &&Case| {
        let s = &c.summary;
        let not_live =
            live(c) && kind == Kind::Outages && (c.unfinished() > 0 || s.deadlock.is_some());
        s.unsafe_events() > 0 || not_live
    };
    let with_sensors = results
        .iter()
        .filter(|c| kind == Kind::Liars && live(c) && sensed(seed, c.index))
        .fold(Liveness::default(), |w, c| Liveness {
            runs: w.runs + 1,
            unfinished: w.unfinished + c.unfinished(),
            deadlocks: w.deadlocks + u64::from(c.summary.deadlock.is_some()),
        });
    let failing: Vec<&Case> = results.iter().filter(failed).collect();
    JunctionFaultsReport {
        sweep: kind.name().into(),
        totals,
        runs: results.len() as u64,
        algorithms: ALGORITHMS.iter().map(|&a| row(a)).collect(),
        with_sensors,
        seed,
        failing: sweep::failing(failing.into_iter(), sweep::KEEP_FAILING),
        wall_seconds: t0.elapsed().as_secs_f64(),
    }
}

/// The `ids` result.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct IdsReport {
    /// Cases run.
    pub cases: u64,
    /// Vehicles that entered, over all cases.
    pub vehicles: u64,
    /// Collisions (pairs × steps).
    pub collisions: u64,
    /// Invariant, limit and entry violations.
    pub invariant_violations: u64,
    /// Vehicles whose id was a junction manager's bus node (or 0).
    pub node_ids: u64,
    /// Cases in which the ids given out wrapped past the managers' nodes.
    pub wrapped: u64,
    /// The sweep's seed.
    pub seed: u64,
    /// Failing cases (at most 20), each as a scenario file.
    pub failing: Vec<Failing>,
    /// Wall-clock time (s).
    pub wall_seconds: f64,
}

impl IdsReport {
    /// Safe, and every case went through the managers' nodes without landing on one.
    pub fn clean(&self) -> bool {
        self.collisions + self.invariant_violations + self.node_ids == 0
            && self.wrapped == self.cases
    }
}

/// Case `index` of `ids` in the sweep seeded `seed`: a network file.
pub fn ids_case(seed: u64, index: u64) -> String {
    let mut r = rng(case_seed(seed, index));
    let cols: u8 = r.random_range(1..=3);
    let lanes: u8 = r.random_range(1..=2);
    let rate: f64 = r.random_range(600.0..1800.0);
    let first = 0xFF00 - r.random_range(1..=8u16);
    // The grid's segments are numbered from 1001 (network.rs `grid`): the eastbound
    // entry of the first column is the first with one column, the third with more.
    let entry = if cols == 1 { 1001 } else { 1003 };
    format!(
        "name = \"ids-{seed}-{index}\"\nduration_s = 30.0\nseed = {s}\nalgorithm = \"pipelined\"\n\n\
         [grid]\nrows = 1\ncols = {cols}\nblock_m = 400.0\nlanes = {lanes}\n\n\
         [[vehicle]]\nid = {first}\nsegment = {entry}\nx = 60.0\nlane = 0\nv = 10.0\n\
         route = [{route}]\n\n[arrivals]\nrate_vph = {rate:.0}\n",
        s = case_seed(seed, index),
        route = vec!["\"straight\""; usize::from(cols)].join(", "),
    )
}

/// One `ids` case: (vehicles, collisions, violations, node ids, wrapped).
fn ids_run(text: &str) -> Result<(u64, u64, u64, u64, bool), String> {
    let sc = NetworkScenario::parse(text, std::path::Path::new("ids.toml"))
        .map_err(|e| e.to_string())?;
    let spec = sc.world();
    let first = spec.vehicles.first().map_or(0, |v| v.id);
    let mut w = World::<20>::new(spec, SolverChoice::Ours, None);
    let mut seen = std::collections::BTreeSet::new();
    while !w.finished() {
        w.step(&mut |row| {
            seen.insert(row.id);
        })
        .map_err(|e| e.to_string())?;
    }
    let s = w.summary(0.0);
    let node_ids = seen.iter().filter(|&&id| !is_vehicle_id(id)).count() as u64;
    let wrapped = seen.iter().any(|&id| id < first);
    let violations = s.invariant_violations + s.limit_violations + s.unpermitted_entries();
    Ok((
        seen.len() as u64,
        s.collisions,
        violations,
        node_ids,
        wrapped,
    ))
}

/// Runs `cases` `ids` cases from index `first` of the sweep seeded `seed`.
pub fn ids(cases: u64, first: u64, seed: u64, threads: usize) -> IdsReport {
    let t0 = std::time::Instant::now();
    let runs = super::par::map_indexed(cases as usize, threads, |i| {
        let index = first + i as u64;
        let text = ids_case(seed, index);
        (index, ids_run(&text), text)
    });
    let mut r = IdsReport {
        cases,
        vehicles: 0,
        collisions: 0,
        invariant_violations: 0,
        node_ids: 0,
        wrapped: 0,
        seed,
        failing: Vec::new(),
        wall_seconds: 0.0,
    };
    for (index, run, text) in runs {
        let reason = match run {
            Ok((n, c, v, nodes, wrapped)) => {
                r.vehicles += n;
                r.collisions += c;
                r.invariant_violations += v;
                r.node_ids += nodes;
                r.wrapped += u64::from(wrapped);
                let why = [
                    (c > 0, format!("{c} collisions")),
                    (v > 0, format!("{v} violations")),
                    (nodes > 0, format!("{nodes} vehicles with a node's id")),
                    (!wrapped, "no id wrapped".to_string()),
                ];
                why.into_iter()
                    .filter(|(bad, _)| *bad)
                    .map(|(_, w)| w)
                    .collect::<Vec<_>>()
                    .join(", ")
            }
            Err(e) => format!("did not run: {e}"),
        };
        if !reason.is_empty() {
            sweep::keep_failing(&mut r.failing, || Failing {
                case: index,
                label: "ids".into(),
                reason,
                scenario: text,
            });
        }
    }
    r.wall_seconds = t0.elapsed().as_secs_f64();
    r
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    /// Every case loads as its scenario file; the faults are the ones described; the
    /// vehicles are the same under every algorithm.
    #[test]
    fn cases_are_valid_scenarios_with_their_faults() {
        let mut one_period = 0;
        let mut from_start = 0;
        for i in 0..40 {
            let o = case(Kind::Outages, 5, i, Algorithm::Fifo);
            JunctionScenario::parse(&o.to_toml(), Path::new("o.toml"))
                .unwrap_or_else(|e| panic!("{e}"));
            let d = o.header.faults.manager_down.expect("an outage");
            assert!((0.0..30.0).contains(&d.from_s) && d.until_s - d.from_s <= 10.0 + 1e-9);
            one_period += usize::from((d.until_s - d.from_s - 0.01).abs() < 1e-12);
            let l = case(Kind::Liars, 5, i, Algorithm::Pipelined);
            let liar = l.header.faults.liar.expect("a liar");
            assert!(l.placements.iter().any(|p| p.id == liar.id));
            assert!((0.2..=40.0).contains(&liar.offset_m.abs()));
            // Without sensors only lies that jump: from a moment on, 1 m at least.
            if !sensed(5, i) {
                assert!(l.header.sensing.is_none());
                assert!(liar.from_s > 0.0 && liar.offset_m.abs() >= 1.0);
            }
            from_start += usize::from(liar.from_s == 0.0);
            assert_eq!(
                l.placements,
                case(Kind::Liars, 5, i, Algorithm::Fifo).placements
            );
            NetworkScenario::parse(&ids_case(5, i), Path::new("i.toml"))
                .unwrap_or_else(|e| panic!("{e}"));
        }
        assert!(
            one_period > 3 && from_start > 3,
            "{one_period} {from_start}"
        );
    }

    /// With trucks: every case loads, at the junction built for a truck's swing, with
    /// trucks and cars among its vehicles over the sweep, and the same outage as without.
    #[test]
    fn cases_with_trucks_are_valid_and_keep_their_faults() {
        use super::super::crossings::truck_layout;
        use crate::scenario::junction::LayoutToml;
        use crate::world::Body;
        let (mut trucks, mut cars) = (0, 0);
        // A truck's junction takes a while to build (its swept area is checked along
        // every route): a few cases.
        for i in 0..5 {
            for kind in [Kind::Outages, Kind::Liars] {
                let t = case_with(kind, (5, 40), i, Algorithm::Platoon);
                JunctionScenario::parse(&t.to_toml(), Path::new("t.toml"))
                    .unwrap_or_else(|e| panic!("{e}"));
                trucks += t
                    .placements
                    .iter()
                    .filter(|p| p.body == Body::TRUCK)
                    .count();
                cars += t.placements.iter().filter(|p| p.body == Body::CAR).count();
                assert_eq!(t.layout_toml, truck_layout(LayoutToml::default()));
            }
            assert_eq!(
                case_with(Kind::Outages, (5, 40), i, Algorithm::Fifo)
                    .header
                    .faults,
                case(Kind::Outages, 5, i, Algorithm::Fifo).header.faults
            );
            assert_eq!(
                case_with(Kind::Liars, (5, 0), i, Algorithm::Fifo).to_toml(),
                case(Kind::Liars, 5, i, Algorithm::Fifo).to_toml()
            );
        }
        assert!(trucks > 10 && cars > 10, "{trucks} trucks, {cars} cars");
    }
}
