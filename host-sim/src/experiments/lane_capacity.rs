//! What one lane carries: vehicles per hour at a speed, under either invariant, in two
//! settings a traffic engineer measures (and SUMO's benchmark runs the same way,
//! `bench/sumo/lane_capacity.py`):
//!
//! - **flowing** — a platoon at the speed, closed up: every vehicle at the speed, spaced
//!   as closely as its invariant lets it follow at that speed, plus [`SLACK_M`]. The
//!   planners must hold it (no fallback, no violation: the report says); the flow is
//!   counted 600 m on.
//! - **discharging** — a standing queue at a stop line that turns free at t = 0: the
//!   vehicles stand as close as they may (d0 and the start margin apart), all go, and the
//!   flow is counted at the stop line.
//!
//! Either way the flow is what the planners do, counted by a detector — nothing is
//! computed from a formula — over the vehicles after the first four (the start-up of a
//! queue, as saturation flow is measured), and the same world's monitor counts
//! collisions and invariant violations.

use super::experiment::{Experiment, RunError, SettingsError};
use super::shard::MergeError;
use crate::monitor::Limits;
use crate::verdict::{Judged, Safety, Verdict};
use crate::world::invariant_name;
use crate::world::summary::Summary;
use crate::world::{SolverChoice, World, LENGTH_M, START_MARGIN_M};
use planner_core::Invariant;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::Path;

/// Vehicles skipped at the start of a count (a queue's start-up).
pub const SKIPPED: usize = 4;
/// How far past the leader's start the flowing platoon is counted (m).
pub const FLOWING_DETECTOR_M: f64 = 600.0;
/// Room (m) a flowing platoon is given over the closest its invariant allows: more than
/// the (21) allowance a planner keeps toward the vehicle ahead (one period at the speed,
/// 0.28 m at 27.8 m/s).
pub const SLACK_M: f64 = 0.5;

/// The two settings.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// A closed-up platoon at the speed.
    Flowing,
    /// A standing queue leaving a stop line.
    Discharging,
}

impl Mode {
    /// Its name in reports.
    pub fn name(self) -> &'static str {
        match self {
            Mode::Flowing => "flowing",
            Mode::Discharging => "discharging",
        }
    }
}

/// One measurement.
#[derive(Debug, Clone, Serialize)]
pub struct CapacityRow {
    /// The speed (m/s): every vehicle's reference speed.
    pub speed_mps: f64,
    /// Flowing or discharging.
    pub mode: Mode,
    /// The invariant the planners kept.
    pub invariant: &'static str,
    /// Vehicles per hour past the detector (after the first [`SKIPPED`]).
    pub flow_vph: f64,
    /// Mean time between two vehicles' fronts at the detector (s).
    pub mean_headway_s: f64,
    /// Vehicles counted.
    pub counted: usize,
    /// Vehicles in the run.
    pub vehicles: usize,
    /// Collisions the monitor saw.
    pub collisions: u64,
    /// Invariant violations the monitor saw (of the invariant each vehicle keeps).
    pub invariant_violations: u64,
    /// Speed, acceleration and heading limit violations.
    pub limit_violations: u64,
    /// Steps on the certified fallback.
    pub fallback_steps: u64,
}

/// The scenario of one measurement, as a `[road]` file would say it.
pub fn scenario(speed: f64, mode: Mode, vehicles: usize, invariant: Invariant) -> String {
    let lim = Limits::table_i();
    let p = planner_core::Params::<f64>::table_i();
    let credit = match invariant {
        Invariant::LeaderAware => planner_core::safety::leader_credit(&p, speed, p.brake()),
        _ => 0.0,
    };
    let gap = match mode {
        // Bumper gap d0 + dS(v), less the leader's credit, and the slack.
        Mode::Flowing => lim.d0 + (lim.safe_distance(speed) - credit).max(0.0) + SLACK_M,
        // As close as standing vehicles may be.
        Mode::Discharging => lim.d0 + lim.safe_distance(0.0) + START_MARGIN_M + 0.01,
    };
    let spacing = LENGTH_M + gap;
    let front = 100.0 + spacing * vehicles as f64;
    let duration = duration_s(speed, mode, vehicles, spacing);
    let mut s = format!(
        "name = \"lane-capacity-{}-{speed}\"\nduration_s = {duration:.0}\ninvariant = \"{}\"\n\n[road]\nlanes = 1\n",
        mode.name(),
        invariant_name(invariant),
    );
    for i in 0..vehicles {
        let x = front - spacing * i as f64;
        let v = match mode {
            Mode::Flowing => speed,
            Mode::Discharging => 0.0,
        };
        let _ = write!(
            s,
            "\n[[vehicle]]\nid = {}\nx = {x:.4}\nlane = 0\nv = {v}\nv_ref = {speed}\n",
            i + 1
        );
    }
    s
}

/// Long enough for the last vehicle to pass the detector at a quarter of the speed.
fn duration_s(speed: f64, mode: Mode, vehicles: usize, spacing: f64) -> f64 {
    let way = spacing * vehicles as f64
        + match mode {
            Mode::Flowing => FLOWING_DETECTOR_M,
            Mode::Discharging => 0.0,
        };
    30.0 + 4.0 * way / speed.max(1.0)
}

/// Where the detector is, given the leader's starting centre.
fn detector_x(mode: Mode, leader_x: f64) -> f64 {
    let line = leader_x + 0.5 * LENGTH_M;
    match mode {
        Mode::Flowing => line + FLOWING_DETECTOR_M,
        Mode::Discharging => line,
    }
}

/// Runs one measurement: `vehicles` in one lane at `speed` (m/s).
pub fn measure(
    speed: f64,
    mode: Mode,
    vehicles: usize,
    invariant: Invariant,
) -> Result<CapacityRow, String> {
    let text = scenario(speed, mode, vehicles, invariant);
    let spec = crate::scenario::parse(&text, Path::new("lane-capacity.toml"))
        .map_err(|e| e.to_string())?;
    let leader_x = spec
        .vehicles
        .first()
        .map(|v| match v.at {
            crate::world::at::At::Lane { x, .. } => x,
            crate::world::at::At::Crossing { .. } => 0.0,
        })
        .unwrap_or(0.0);
    let at = detector_x(mode, leader_x);
    let mut passed: Vec<Option<f64>> = vec![None; vehicles + 1];
    let mut w = World::<20>::new(spec, SolverChoice::Ours, None);
    while !w.finished() && passed.iter().skip(1).any(Option::is_none) {
        let step = w.step(&mut |row| {
            let front = row.x + 0.5 * LENGTH_M;
            if let Some(slot @ None) = passed.get_mut(usize::from(row.id)) {
                if front >= at {
                    *slot = Some(row.t);
                }
            }
        });
        step.map_err(|e| e.to_string())?;
    }
    Ok(row(
        speed,
        mode,
        invariant,
        vehicles,
        &passed,
        &w.summary(0.0),
    ))
}

/// The row of a run whose vehicles passed the detector at `passed` (by id).
fn row(
    speed: f64,
    mode: Mode,
    invariant: Invariant,
    vehicles: usize,
    passed: &[Option<f64>],
    s: &Summary,
) -> CapacityRow {
    let times: Vec<f64> = passed.iter().skip(1 + SKIPPED).flatten().copied().collect();
    let (flow_vph, mean_headway_s) = match (times.first(), times.last()) {
        (Some(a), Some(b)) if times.len() > 1 && b > a => {
            let h = (b - a) / (times.len() - 1) as f64;
            (3600.0 / h, h)
        }
        _ => (0.0, f64::INFINITY),
    };
    CapacityRow {
        speed_mps: speed,
        mode,
        invariant: invariant_name(invariant),
        flow_vph,
        mean_headway_s,
        counted: times.len(),
        vehicles,
        collisions: s.collisions,
        invariant_violations: s.invariant_violations,
        limit_violations: s.limit_violations,
        fallback_steps: s.fallback_steps,
    }
}

/// `experiment lane-capacity`'s settings (its flags).
#[derive(Debug, Clone, PartialEq, clap::Args)]
pub struct LaneCapacity {
    /// Speeds (m/s), comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "13.9,27.8")]
    pub speeds: Vec<f64>,
    /// The invariant (default: both, side by side).
    #[arg(long, value_parser = super::flags::invariant())]
    pub invariant: Option<Invariant>,
    /// Vehicles per run (the first four are not counted).
    #[arg(long, default_value_t = 30, value_parser = clap::value_parser!(u16).range(6..=200))]
    pub vehicles: u16,
}

impl Experiment for LaneCapacity {
    const NAME: &'static str = "lane-capacity";
    type Part = CapacityReport;
    type Report = CapacityReport;

    fn validate(&self) -> Result<(), SettingsError> {
        match self.speeds.iter().find(|v| !(**v > 0.0 && **v <= 27.8)) {
            Some(v) => Err(SettingsError::new(
                "--speeds",
                format!("each in (0, 27.8] m/s, got {v}"),
            )),
            None => Ok(()),
        }
    }

    /// The runs: every speed, both settings, each invariant asked for.
    fn cases(&self) -> u64 {
        (self.speeds.len() * 2 * self.invariants().len()) as u64
    }

    fn run(&self, _range: (u64, u64), _threads: usize) -> Result<CapacityReport, RunError> {
        lane_capacity(&self.speeds, &self.invariants(), usize::from(self.vehicles))
            .map_err(RunError::Internal)
    }

    fn report(&self, parts: Vec<CapacityReport>) -> Result<CapacityReport, MergeError> {
        super::experiment::only_part(parts, Self::NAME)
    }
}

impl LaneCapacity {
    /// The invariants asked for: one, or both side by side.
    pub fn invariants(&self) -> Vec<Invariant> {
        match self.invariant {
            Some(i) => vec![i],
            None => vec![Invariant::Paper, Invariant::LeaderAware],
        }
    }
}

/// `experiment lane-capacity`'s table (Markdown, as docs/capacity.md shows it).
impl core::fmt::Display for CapacityReport {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "| speed (m/s) | mode | invariant | veh/h | mean headway (s) | collisions | invariant violations | fallback steps |\n|---|---|---|---|---|---|---|---|"
        )?;
        for r in &self.results {
            write!(
                f,
                "\n| {} | {} | {} | {:.0} | {:.3} | {} | {} | {} |",
                r.speed_mps,
                r.mode.name(),
                r.invariant,
                r.flow_vph,
                r.mean_headway_s,
                r.collisions,
                r.invariant_violations,
                r.fallback_steps
            )?;
        }
        Ok(())
    }
}

/// The `experiment lane-capacity` report.
#[derive(Debug, Clone, Serialize)]
pub struct CapacityReport {
    /// One row per speed, mode and invariant.
    pub results: Vec<CapacityRow>,
    /// Wall-clock time (s).
    pub wall_seconds: f64,
}

/// Every speed × mode × invariant, in that order.
pub fn lane_capacity(
    speeds: &[f64],
    invariants: &[Invariant],
    vehicles: usize,
) -> Result<CapacityReport, String> {
    let started = std::time::Instant::now();
    let mut results = Vec::new();
    for &speed in speeds {
        for mode in [Mode::Flowing, Mode::Discharging] {
            for &inv in invariants {
                results.push(measure(speed, mode, vehicles, inv)?);
            }
        }
    }
    Ok(CapacityReport {
        results,
        wall_seconds: started.elapsed().as_secs_f64(),
    })
}

impl Judged for CapacityReport {
    /// Every run's collisions and violations; capacity is measured, not judged.
    fn verdict(&self) -> Verdict {
        let s = self
            .results
            .iter()
            .map(|r| Safety::of(r.collisions, r.invariant_violations, r.limit_violations, 0))
            .sum();
        Verdict::new(s, true)
    }
}
