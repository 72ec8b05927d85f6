//! The `[road]` format: one straight multi-lane road (a network of one segment, heading
//! east, its frame the world's), its vehicles by x and lane. Parsed strictly: unknown
//! keys, impossible layouts and initial states that violate the safety invariant are
//! rejected with a message naming the file, the line and the problem; nothing runs.
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

use super::common::{coord_ok, Header, RawHeader, SensingToml, MAX_COORD_M};
use super::error::{Errors, ScenarioError};
use crate::bus::Faults;
use crate::monitor::Limits;
use crate::world::network::Network;
use crate::world::vehicle::{At, Trip};
use crate::world::{Arrivals, Finish, WorldSpec, LANE_WIDTH_M, LENGTH_M, START_MARGIN_M};
use planner_core::Sensing;
use serde::{Deserialize, Serialize};
use std::ops::Range;
use std::path::Path;
use toml::Spanned;

/// Most vehicles a scenario may hold (the size of each planner's world view).
pub const MAX_VEHICLES: usize = crate::world::heard::VIEW_CAP;
/// Most lanes a road may have.
pub const MAX_LANES: u8 = 8;

/// How a vehicle is driven.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize, Default)]
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
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Phase {
    /// End of the phase (s).
    pub until_s: f64,
    /// Acceleration (m/s²), within [amin, amax].
    pub accel: f64,
}

/// The road.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Road {
    /// Number of lanes (1–8).
    pub lanes: u8,
    /// Road end / stop line x_R (m), if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub end_x: Option<f64>,
}

/// One vehicle.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct RoadVehicle {
    /// Unique id.
    pub id: u16,
    /// Initial centre x (m).
    pub x: f64,
    /// Lane (0 = rightmost).
    pub lane: u8,
    /// Initial speed (m/s).
    pub v: f64,
    /// Lane it wants to end in (default: its lane).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target_lane: Option<u8>,
    /// Driver.
    #[serde(default)]
    pub driver: DriverKind,
    /// Script, for `driver = "script"`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub script: Vec<Phase>,
    /// Liveness goal: centre x to reach by the deadline.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub goal_x: Option<f64>,
    /// Reference speed of a planner (default vmax).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub v_ref: Option<f64>,
    /// It cooperates (yields, keeps its declared intentions): by default a planner does
    /// and a scripted or random driver does not. Others assume a vehicle that does not
    /// may accelerate at amax and never yield (RSS-style); `true` on a script makes it a
    /// cooperating leader (the paper's platoon experiments), `false` on a planner a legacy
    /// vehicle the others must not count on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cooperative: Option<bool>,
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
    #[serde(default)]
    deadlock_s: Option<Spanned<f64>>,
    road: Spanned<Road>,
    #[serde(rename = "vehicle")]
    vehicles: Vec<Spanned<RoadVehicle>>,
    #[serde(default)]
    faults: Option<Spanned<Faults>>,
    #[serde(default)]
    sensing: Option<Spanned<SensingToml>>,
}

/// A validated road scenario.
#[derive(Debug, Clone, PartialEq)]
pub struct RoadScenario {
    /// Name.
    pub name: String,
    /// Seed (random drivers).
    pub seed: u64,
    /// Duration, horizon, deadline, faults, sensing, deadlock window.
    pub header: Header,
    /// Road.
    pub road: Road,
    /// Vehicles, in file order.
    pub vehicles: Vec<RoadVehicle>,
}

/// The file form of a road scenario (what a sweep prints for a failing case).
#[derive(Debug, Clone, Serialize)]
struct RoadFile<'a> {
    name: &'a str,
    duration_s: f64,
    seed: u64,
    horizon: usize,
    deadline_s: f64,
    road: &'a Road,
    #[serde(skip_serializing_if = "Faults::is_none")]
    faults: Faults,
    #[serde(skip_serializing_if = "Option::is_none")]
    sensing: Option<SensingToml>,
    #[serde(rename = "vehicle")]
    vehicles: &'a [RoadVehicle],
}

impl RoadScenario {
    /// Parses and validates scenario text; `path` only names it in errors.
    pub fn parse(text: &str, path: &Path) -> Result<Self, ScenarioError> {
        let e = Errors::new(text, path);
        let err = |span: Option<Range<usize>>, problem: String| e.at(span, problem);
        let raw: RawScenario = toml::from_str(text).map_err(|x| e.toml(&x))?;
        let lim = Limits::table_i();
        let header = RawHeader {
            duration_s: Some(raw.duration_s.clone()),
            horizon: raw.horizon.clone(),
            deadline_s: raw.deadline_s.clone(),
            faults: raw.faults.clone(),
            sensing: raw.sensing.clone(),
            deadlock_s: raw.deadlock_s.clone(),
        }
        .validate(&e)?;
        let road_span = raw.road.span();
        let road = raw.road.into_inner();
        if road.lanes == 0 || road.lanes > MAX_LANES {
            return Err(err(
                Some(road_span),
                format!("road.lanes must be 1..={MAX_LANES}, got {}", road.lanes),
            ));
        }
        if road.end_x.is_some_and(|x| !coord_ok(x)) {
            return Err(err(
                Some(road_span),
                format!("road.end_x must be finite and within ±{MAX_COORD_M} m"),
            ));
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
        let mut vehicles: Vec<(RoadVehicle, Range<usize>)> = Vec::new();
        for sv in raw.vehicles {
            let span = sv.span();
            let v = sv.into_inner();
            let bad =
                |problem: String| err(Some(span.clone()), format!("vehicle {}: {problem}", v.id));
            if vehicles.iter().any(|(o, _)| o.id == v.id) {
                return Err(bad("duplicate id".into()));
            }
            if !coord_ok(v.x) {
                return Err(bad(format!(
                    "x must be finite and within ±{MAX_COORD_M} m (where f64 keeps positions \
                     far finer than the safety margins), got {}",
                    v.x
                )));
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
            if v.goal_x.is_some_and(|g| !coord_ok(g)) {
                return Err(bad(format!(
                    "goal_x must be finite and within ±{MAX_COORD_M} m"
                )));
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
                if v.x + 0.5 * LENGTH_M >= end {
                    return Err(bad(format!("starts beyond the road end x = {end}")));
                }
                if v.driver == DriverKind::Planner {
                    let room = end - v.x - 0.5 * LENGTH_M - lim.d0;
                    if !(room > lim.safe_distance(v.v) + START_MARGIN_M) {
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
            let specs: Vec<RoadVehicle> = vehicles.iter().map(|(v, _)| v.clone()).collect();
            for (i, (v, span)) in vehicles.iter().enumerate() {
                let bound =
                    crate::experiments::multilane::commitment_bound(&specs, &road, i, lim.v_max);
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
            let mut in_lane: Vec<&(RoadVehicle, Range<usize>)> =
                vehicles.iter().filter(|(v, _)| v.lane == lane).collect();
            in_lane.sort_by(|a, b| b.0.x.total_cmp(&a.0.x));
            for pair in in_lane.windows(2) {
                let (lead, (follow, span)) = (&pair[0].0, (&pair[1].0, &pair[1].1));
                let gap = lead.x - follow.x - LENGTH_M;
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
                let need = lim.safe_distance(follow.v) + START_MARGIN_M;
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
            seed: raw.seed,
            header,
            road,
            vehicles: vehicles.into_iter().map(|(v, _)| v).collect(),
        })
    }

    /// A scenario of `vehicles` on `road` in the paper's world (no faults, no sensors).
    pub fn new(
        name: String,
        duration_s: f64,
        seed: u64,
        road: Road,
        vehicles: Vec<RoadVehicle>,
    ) -> Self {
        Self {
            name,
            seed,
            header: Header {
                duration_s,
                horizon: 20,
                deadline_s: duration_s,
                faults: Faults::NONE,
                sensing: None,
                deadlock_window_s: crate::monitor::liveness::DEADLOCK_WINDOW_S,
            },
            road,
            vehicles,
        }
    }

    /// The world it describes.
    pub fn world(&self) -> WorldSpec {
        let lim = Limits::table_i();
        WorldSpec {
            name: self.name.clone(),
            duration_s: self.header.duration_s,
            seed: self.seed,
            horizon: self.header.horizon,
            deadline_s: self.header.deadline_s,
            network: Network::road(self.road.lanes, self.road.end_x, lim.v_max),
            vehicles: self.vehicles.iter().map(|v| v.spec(lim.v_max)).collect(),
            faults: self.header.faults,
            sensing: self.header.sensing,
            arrivals: Arrivals::None,
            deadlock_window_s: self.header.deadlock_window_s,
            finish: Finish::Duration,
        }
    }

    /// The scenario as a file that `host-sim run` loads (a sweep's failing case).
    pub fn to_toml(&self) -> String {
        let sensing = self.header.sensing.map(|s: Sensing<f64>| SensingToml {
            enabled: Some(true),
            ahead_m: s.ahead_m,
            behind_m: s.behind_m,
            position_error_m: s.position_error_m,
            speed_error_mps: s.speed_error_mps,
        });
        let file = RoadFile {
            name: &self.name,
            duration_s: self.header.duration_s,
            seed: self.seed,
            horizon: self.header.horizon,
            deadline_s: self.header.deadline_s,
            road: &self.road,
            faults: self.header.faults,
            sensing,
            vehicles: &self.vehicles,
        };
        toml::to_string(&file).unwrap_or_else(|e| format!("# cannot write: {e}"))
    }
}

impl RoadVehicle {
    /// The world's vehicle: on segment 0 at (x, centre of its lane), straight.
    pub fn spec(&self, v_max: f64) -> crate::world::VehicleSpec {
        crate::world::VehicleSpec {
            id: self.id,
            at: At::Lane {
                seg: 0,
                x: self.x,
                y: (f64::from(self.lane) + 0.5) * LANE_WIDTH_M,
                theta: 0.0,
                lane: self.lane,
                alpha: None,
                beta: None,
            },
            v: self.v,
            driver: self.driver,
            script: self.script.clone(),
            trip: Trip {
                target_lane: self.target_lane.unwrap_or(self.lane),
                goal_x: self.goal_x,
                v_ref: Some(self.v_ref.unwrap_or(v_max)),
                movements: Vec::new(),
            },
            cooperative: self
                .cooperative
                .unwrap_or(self.driver == DriverKind::Planner),
        }
    }
}

/// The road format's tables and their keys (see [`super::keys`]).
pub fn keys() -> Vec<(&'static str, &'static [&'static str])> {
    use super::keys::fields;
    vec![
        ("road file", fields::<RawScenario>()),
        ("[road]", fields::<Road>()),
        ("[[vehicle]] on a road", fields::<RoadVehicle>()),
        ("script phase", fields::<Phase>()),
    ]
}
