//! Scenario files (TOML): roads, vehicles, duration, seed. Parsed strictly: unknown keys,
//! impossible layouts and initial states that violate the safety invariant are rejected
//! with a message naming the file, the line and the problem; nothing runs.
//!
//! ```toml
//! name = "platoon-emergency"
//! duration_s = 30.0
//! seed = 1            # optional, default 0
//! horizon = 20        # optional: 20 or 50
//! deadline_s = 30.0   # optional: liveness deadline, default duration_s
//!
//! [road]
//! lanes = 1
//! end_x = 900.0       # optional road end x_R (m)
//!
//! [[vehicle]]
//! id = 1
//! x = 100.0           # centre (m)
//! lane = 0            # 0 = rightmost
//! v = 20.0            # initial speed (m/s)
//! driver = "script"   # "planner" (default), "script" or "random"
//! script = [ { until_s = 5.0, accel = 0.0 }, { until_s = 9.0, accel = -7.9 } ]
//! goal_x = 400.0      # optional: liveness goal, centre x to reach by the deadline
//! v_ref = 27.8        # optional: reference speed of a planner, default vmax
//! ```

use crate::bus::Faults;
use crate::monitor::Limits;
use serde::Deserialize;
use std::fmt;
use std::ops::Range;
use std::path::{Path, PathBuf};
use toml::Spanned;

/// Most vehicles a scenario may hold (the size of each planner's world view).
pub const MAX_VEHICLES: usize = 128;
/// Most lanes a road may have.
pub const MAX_LANES: u8 = 8;
/// Longest scenario (s).
pub const MAX_DURATION_S: f64 = 86_400.0;

/// A scenario that failed to load: where, and what is wrong.
#[derive(Debug, Clone, PartialEq)]
pub struct ScenarioError {
    /// The file.
    pub file: PathBuf,
    /// 1-based line, when the problem has one.
    pub line: Option<usize>,
    /// What is wrong.
    pub problem: String,
}

impl fmt::Display for ScenarioError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.line {
            Some(l) => write!(f, "{}:{}: {}", self.file.display(), l, self.problem),
            None => write!(f, "{}: {}", self.file.display(), self.problem),
        }
    }
}

impl std::error::Error for ScenarioError {}

/// How a vehicle is driven.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum DriverKind {
    /// Its own planner-core instance.
    #[default]
    Planner,
    /// A fixed acceleration script (an adversarial but admissible driver).
    Script,
    /// Random admissible accelerations, seeded from the scenario seed and the id.
    Random,
}

/// One phase of a scripted driver: hold `accel` until `until_s`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Phase {
    /// End of the phase (s).
    pub until_s: f64,
    /// Acceleration (m/s²), within [amin, amax].
    pub accel: f64,
}

/// The road.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Road {
    /// Number of lanes (1–8).
    pub lanes: u8,
    /// Road end / stop line x_R (m), if any.
    #[serde(default)]
    pub end_x: Option<f64>,
}

/// One vehicle.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VehicleSpec {
    /// Unique id.
    pub id: u16,
    /// Initial centre x (m).
    pub x: f64,
    /// Lane (0 = rightmost).
    pub lane: u8,
    /// Initial speed (m/s).
    pub v: f64,
    /// Lane it wants to end in (default: its lane).
    #[serde(default)]
    pub target_lane: Option<u8>,
    /// Driver.
    #[serde(default)]
    pub driver: DriverKind,
    /// Script, for `driver = "script"`.
    #[serde(default)]
    pub script: Vec<Phase>,
    /// Liveness goal: centre x to reach by the deadline.
    #[serde(default)]
    pub goal_x: Option<f64>,
    /// Reference speed of a planner (default vmax).
    #[serde(default)]
    pub v_ref: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScenario {
    name: String,
    duration_s: Spanned<f64>,
    #[serde(default)]
    seed: u64,
    #[serde(default)]
    horizon: Option<Spanned<usize>>,
    #[serde(default)]
    deadline_s: Option<Spanned<f64>>,
    road: Spanned<Road>,
    #[serde(rename = "vehicle")]
    vehicles: Vec<Spanned<VehicleSpec>>,
    #[serde(default)]
    faults: Option<Spanned<Faults>>,
}

/// A validated scenario.
#[derive(Debug, Clone, PartialEq)]
pub struct Scenario {
    /// Name.
    pub name: String,
    /// Simulated time (s).
    pub duration_s: f64,
    /// Seed (random drivers).
    pub seed: u64,
    /// MPC horizon N (20 or 50).
    pub horizon: usize,
    /// Liveness deadline (s).
    pub deadline_s: f64,
    /// Road.
    pub road: Road,
    /// Vehicles, in file order.
    pub vehicles: Vec<VehicleSpec>,
    /// Faults the bus injects (`[faults]`; none by default).
    pub faults: Faults,
}

pub(crate) fn line_of(text: &str, span: Range<usize>) -> usize {
    let end = span.start.min(text.len());
    text.get(..end).map_or(1, |s| s.matches('\n').count() + 1)
}

impl Scenario {
    /// Reads and validates a scenario file.
    pub fn load(path: &Path) -> Result<Self, ScenarioError> {
        let text = std::fs::read_to_string(path).map_err(|e| ScenarioError {
            file: path.to_path_buf(),
            line: None,
            problem: format!("cannot read: {e}"),
        })?;
        Self::parse(&text, path)
    }

    /// Parses and validates scenario text; `path` only names it in errors.
    pub fn parse(text: &str, path: &Path) -> Result<Self, ScenarioError> {
        let err = |span: Option<Range<usize>>, problem: String| ScenarioError {
            file: path.to_path_buf(),
            line: span.map(|s| line_of(text, s)),
            problem,
        };
        let raw: RawScenario =
            toml::from_str(text).map_err(|e| err(e.span(), e.message().to_string()))?;
        let lim = Limits::table_i();
        let duration_s = *raw.duration_s.get_ref();
        if !(duration_s > 0.0 && duration_s <= MAX_DURATION_S) {
            return Err(err(
                Some(raw.duration_s.span()),
                format!("duration_s must be in (0, {MAX_DURATION_S}], got {duration_s}"),
            ));
        }
        let horizon = match &raw.horizon {
            None => 20,
            Some(h) if matches!(*h.get_ref(), 20 | 50) => *h.get_ref(),
            Some(h) => {
                return Err(err(
                    Some(h.span()),
                    format!("horizon must be 20 or 50, got {}", h.get_ref()),
                ))
            }
        };
        let deadline_s = match &raw.deadline_s {
            None => duration_s,
            Some(d) if *d.get_ref() > 0.0 && *d.get_ref() <= duration_s => *d.get_ref(),
            Some(d) => {
                return Err(err(
                    Some(d.span()),
                    format!("deadline_s must be in (0, duration_s], got {}", d.get_ref()),
                ))
            }
        };
        let faults = match &raw.faults {
            None => Faults::NONE,
            Some(f) => {
                f.get_ref().validate().map_err(|e| err(Some(f.span()), e))?;
                *f.get_ref()
            }
        };
        let road_span = raw.road.span();
        let road = raw.road.into_inner();
        if road.lanes == 0 || road.lanes > MAX_LANES {
            return Err(err(
                Some(road_span),
                format!("road.lanes must be 1..={MAX_LANES}, got {}", road.lanes),
            ));
        }
        if road.end_x.is_some_and(|x| !x.is_finite()) {
            return Err(err(Some(road_span), "road.end_x must be finite".into()));
        }
        if raw.vehicles.is_empty() {
            return Err(err(
                None,
                "a scenario needs at least one [[vehicle]]".into(),
            ));
        }
        if raw.vehicles.len() > MAX_VEHICLES {
            return Err(err(
                None,
                format!(
                    "at most {MAX_VEHICLES} vehicles, got {}",
                    raw.vehicles.len()
                ),
            ));
        }
        let mut vehicles: Vec<(VehicleSpec, Range<usize>)> = Vec::new();
        for sv in raw.vehicles {
            let span = sv.span();
            let v = sv.into_inner();
            let bad =
                |problem: String| err(Some(span.clone()), format!("vehicle {}: {problem}", v.id));
            if vehicles.iter().any(|(o, _)| o.id == v.id) {
                return Err(bad("duplicate id".into()));
            }
            if !v.x.is_finite() {
                return Err(bad(format!("x must be finite, got {}", v.x)));
            }
            if !(v.v >= 0.0 && v.v <= lim.v_max) {
                return Err(bad(format!("v must be in [0, {}], got {}", lim.v_max, v.v)));
            }
            if v.lane >= road.lanes {
                return Err(bad(format!(
                    "lane {} does not exist (road has {})",
                    v.lane, road.lanes
                )));
            }
            if let Some(t) = v.target_lane {
                if t >= road.lanes {
                    return Err(bad(format!("target_lane {t} does not exist")));
                }
                if t != v.lane && v.driver != DriverKind::Planner {
                    return Err(bad(format!(
                        "only planner-driven vehicles change lanes (driver is {:?})",
                        v.driver
                    )));
                }
            }
            if v.goal_x.is_some_and(|g| !g.is_finite()) {
                return Err(bad("goal_x must be finite".into()));
            }
            if v.v_ref.is_some_and(|r| !(r >= 0.0 && r <= lim.v_max)) {
                return Err(bad(format!("v_ref must be in [0, {}]", lim.v_max)));
            }
            match v.driver {
                DriverKind::Script => {
                    if v.script.is_empty() {
                        return Err(bad("driver = \"script\" needs a non-empty script".into()));
                    }
                    let mut last = 0.0;
                    for p in &v.script {
                        if !(p.until_s > last && p.until_s.is_finite()) {
                            return Err(bad("script phases need increasing until_s > 0".into()));
                        }
                        if !(p.accel >= -lim.brake && p.accel <= lim.a_max) {
                            return Err(bad(format!(
                                "script accel {} outside [{}, {}]",
                                p.accel, -lim.brake, lim.a_max
                            )));
                        }
                        last = p.until_s;
                    }
                }
                _ if !v.script.is_empty() => {
                    return Err(bad("script given but driver is not \"script\"".into()));
                }
                _ => {}
            }
            if let Some(end) = road.end_x {
                if v.x + 0.5 * crate::sim::LENGTH_M >= end {
                    return Err(bad(format!("starts beyond the road end x = {end}")));
                }
                if v.driver == DriverKind::Planner {
                    let room = end - v.x - 0.5 * crate::sim::LENGTH_M - lim.d0;
                    if !(room > lim.safe_distance(v.v) + crate::sim::START_MARGIN_M) {
                        return Err(bad(format!(
                            "cannot stop before the road end: {room:.3} m of room, needs more than \
                             dS(v) = {:.3} m",
                            lim.safe_distance(v.v)
                        )));
                    }
                }
            }
            vehicles.push((v, span));
        }
        // Theorem 3 / (23): on a dead-end road a vehicle needing M lane changes must have
        // M (dS(vmax) + dC(vmax)) of road left, or its changes are not guaranteed.
        if let Some(end) = road.end_x {
            let specs: Vec<VehicleSpec> = vehicles.iter().map(|(v, _)| v.clone()).collect();
            for (i, (v, span)) in vehicles.iter().enumerate() {
                let bound = crate::multilane::commitment_bound(&specs, &road, i, lim.v_max);
                if let Some(b) = bound {
                    let room = end - v.x;
                    if !(room >= b) {
                        return Err(err(
                            Some(span.clone()),
                            format!(
                                "vehicle {}: needs {} lane change(s) but starts {room:.1} m \
                                 before the road end; the commitment distance (23) is {b:.1} m",
                                v.id,
                                v.lane.abs_diff(v.target_lane.unwrap_or(v.lane))
                            ),
                        ));
                    }
                }
            }
        }
        // Per lane, front to back: no overlap, the invariant for every planner-driven
        // follower, and scripted/random drivers only at the front of their lane (they do
        // not keep the invariant themselves).
        for lane in 0..road.lanes {
            let mut in_lane: Vec<&(VehicleSpec, Range<usize>)> =
                vehicles.iter().filter(|(v, _)| v.lane == lane).collect();
            in_lane.sort_by(|a, b| b.0.x.total_cmp(&a.0.x));
            for pair in in_lane.windows(2) {
                let (lead, (follow, span)) = (&pair[0].0, (&pair[1].0, &pair[1].1));
                let gap = lead.x - follow.x - crate::sim::LENGTH_M;
                if gap <= 0.0 {
                    return Err(err(
                        Some(span.clone()),
                        format!(
                            "vehicle {} overlaps vehicle {} in lane {lane}",
                            follow.id, lead.id
                        ),
                    ));
                }
                if follow.driver != DriverKind::Planner {
                    return Err(err(
                        Some(span.clone()),
                        format!(
                            "vehicle {}: a {:?} driver must lead its lane (vehicle {} is ahead)",
                            follow.id, follow.driver, lead.id
                        ),
                    ));
                }
                let need = lim.safe_distance(follow.v) + crate::sim::START_MARGIN_M;
                if !(gap - lim.d0 > need) {
                    return Err(err(
                        Some(span.clone()),
                        format!(
                            "vehicle {} violates the safety invariant behind vehicle {}: bumper \
                             gap {gap:.3} m, needs more than d0 + dS(v) = {:.3} m",
                            follow.id,
                            lead.id,
                            lim.d0 + need
                        ),
                    ));
                }
            }
        }
        Ok(Self {
            name: raw.name,
            duration_s,
            seed: raw.seed,
            horizon,
            deadline_s,
            road,
            vehicles: vehicles.into_iter().map(|(v, _)| v).collect(),
            faults,
        })
    }
}
