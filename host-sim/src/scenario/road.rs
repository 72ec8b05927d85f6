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
use crate::world::at::At;
use crate::world::network::Network;
use crate::world::vehicle::Trip;
use crate::world::{Arrivals, Body, Finish, WorldSpec, LANE_WIDTH_M, START_MARGIN_M, WIDTH_M};
use planner_core::free_space::FreeSpace;
use planner_core::lane_change::commitment_distance;
use planner_core::lanes::Band;
use planner_core::Pose;
use serde::{Deserialize, Serialize};
use std::ops::Range;
use std::path::Path;
use toml::Spanned;

/// Most vehicles a scenario may hold (the size of each planner's world view).
pub const MAX_VEHICLES: usize = crate::world::heard::VIEW_CAP;
/// Most lanes a road may have.
pub const MAX_LANES: u8 = 8;

pub use crate::world::{DriverKind, Phase};

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
    /// Its length (m; default Table I's 4.5 m).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub length: Option<f64>,
    /// Its braking limit |amin| (m/s²; default Table I's 7.9).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub brake: Option<f64>,
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
    #[serde(default)]
    invariant: Option<Spanned<String>>,
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
    /// Always named, so that the file replays under the invariant it ran under whatever
    /// the loader's default.
    invariant: &'static str,
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
        let raw: RawScenario = toml::from_str(text).map_err(|x| e.toml(&x))?;
        let header = RawHeader {
            duration_s: Some(raw.duration_s.clone()),
            horizon: raw.horizon.clone(),
            deadline_s: raw.deadline_s.clone(),
            faults: raw.faults.clone(),
            sensing: raw.sensing.clone(),
            deadlock_s: raw.deadlock_s.clone(),
            invariant: raw.invariant.clone(),
        }
        .validate(&e)?;
        let road_span = raw.road.span();
        let road = raw.road.into_inner();
        check_road(&road).map_err(|p| e.at(Some(road_span.clone()), p))?;
        if raw.vehicles.is_empty() {
            // Nothing to point at but the road the vehicles are missing from.
            return Err(e.at(Some(road_span), "a scenario needs at least one [[vehicle]]"));
        }
        if let Some(extra) = raw.vehicles.get(MAX_VEHICLES) {
            let n = raw.vehicles.len();
            return Err(e.at(
                Some(extra.span()),
                format!("at most {MAX_VEHICLES} vehicles, got {n}"),
            ));
        }
        let mut vehicles: Vec<(RoadVehicle, Range<usize>)> = Vec::new();
        for sv in raw.vehicles {
            let span = sv.span();
            let v = sv.into_inner();
            let dup = vehicles.iter().any(|(o, _)| o.id == v.id);
            let checked = if dup {
                Err("duplicate id".into())
            } else if !crate::bus::is_vehicle_id(v.id) {
                Err("ids are 1 to 65,279 (above are the junction managers' bus nodes)".into())
            } else {
                check_vehicle(&v, &road)
            };
            checked.map_err(|p| e.at(Some(span.clone()), format!("vehicle {}: {p}", v.id)))?;
            vehicles.push((v, span));
        }
        if let Some(end) = road.end_x {
            check_commitment(&vehicles, &road, end).map_err(|(span, p)| e.at(Some(span), p))?;
        }
        check_lanes(&vehicles, road.lanes, header.invariant)
            .map_err(|(span, p)| e.at(Some(span), p))?;
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
                invariant: planner_core::Invariant::Paper,
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
            clock_start: planner_core::Instant::EPOCH,
            precision: crate::world::precision::Precision::F64,
            invariant: self.header.invariant,
        }
    }

    /// The scenario as a file that `host-sim run` loads (a sweep's failing case).
    pub fn to_toml(&self) -> String {
        let sensing = Some(SensingToml::of(self.header.sensing));
        let file = RoadFile {
            name: &self.name,
            duration_s: self.header.duration_s,
            seed: self.seed,
            horizon: self.header.horizon,
            deadline_s: self.header.deadline_s,
            invariant: crate::world::invariant_name(self.header.invariant),
            road: &self.road,
            faults: self.header.faults,
            sensing,
            vehicles: &self.vehicles,
        };
        toml::to_string(&file).unwrap_or_else(|e| format!("# cannot write: {e}"))
    }
}

impl RoadVehicle {
    /// Its body: Table I's car unless `length` or `brake` say otherwise.
    pub fn body(&self) -> Body {
        body_of(self.length, self.brake)
    }

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
            body: self.body(),
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

/// The road table's limits.
fn check_road(road: &Road) -> Result<(), String> {
    if road.lanes == 0 || road.lanes > MAX_LANES {
        return Err(format!(
            "road.lanes must be 1..={MAX_LANES}, got {}",
            road.lanes
        ));
    }
    if road.end_x.is_some_and(|x| !coord_ok(x)) {
        return Err(format!(
            "road.end_x must be finite and within ±{MAX_COORD_M} m"
        ));
    }
    Ok(())
}

/// One vehicle on its own: coordinates, speeds, lanes, its driver, and room to stop
/// before a road end.
fn check_vehicle(v: &RoadVehicle, road: &Road) -> Result<(), String> {
    let lim = Limits::table_i();
    if !coord_ok(v.x) {
        return Err(format!(
            "x must be finite and within ±{MAX_COORD_M} m (where f64 keeps positions far \
             finer than the safety margins), got {}",
            v.x
        ));
    }
    if !(v.v >= 0.0 && v.v <= lim.v_max) {
        return Err(format!("v must be in [0, {}], got {}", lim.v_max, v.v));
    }
    check_body((v.length, v.brake), &lim)?;
    if v.lane >= road.lanes {
        return Err(format!(
            "lane {} does not exist (road has {})",
            v.lane, road.lanes
        ));
    }
    if let Some(t) = v.target_lane {
        if t >= road.lanes {
            return Err(format!("target_lane {t} does not exist"));
        }
        if t != v.lane && v.driver != DriverKind::Planner {
            let d = v.driver;
            return Err(format!(
                "only planner-driven vehicles change lanes (driver is {d:?})"
            ));
        }
    }
    if v.goal_x.is_some_and(|g| !coord_ok(g)) {
        return Err(format!("goal_x must be finite and within ±{MAX_COORD_M} m"));
    }
    if v.v_ref.is_some_and(|r| !(r >= 0.0 && r <= lim.v_max)) {
        return Err(format!("v_ref must be in [0, {}]", lim.v_max));
    }
    check_script(v, &lim)?;
    let Some(end) = road.end_x else { return Ok(()) };
    let body = v.body();
    if v.x + 0.5 * body.length >= end {
        return Err(format!("starts beyond the road end x = {end}"));
    }
    let room = end - v.x - 0.5 * body.length - lim.d0;
    let d_s = lim.safe_distance_at(v.v, body.brake);
    if v.driver == DriverKind::Planner && !(room > d_s + START_MARGIN_M) {
        return Err(format!(
            "cannot stop before the road end: {room:.3} m of room, needs more than dS(v) = \
             {d_s:.3} m"
        ));
    }
    Ok(())
}

/// A body, as a file writes it (`length`, `brake`), within what the bus can say of it (a
/// length of 25.5 m at most) and no stronger brakes than Table I's car (the fleet's
/// bound on braking).
pub(super) fn check_body(
    (length, brake): (Option<f64>, Option<f64>),
    lim: &Limits,
) -> Result<(), String> {
    if length.is_some_and(|l| !(MIN_LENGTH_M..=MAX_LENGTH_M).contains(&l)) {
        return Err(format!(
            "length must be in [{MIN_LENGTH_M}, {MAX_LENGTH_M}] m (what a V2V state can \
             declare)"
        ));
    }
    if brake.is_some_and(|b| !(b >= MIN_BRAKE_MPS2 && b <= lim.brake)) {
        return Err(format!(
            "brake must be in [{MIN_BRAKE_MPS2}, {}] m/s² (no vehicle brakes harder than \
             Table I's car)",
            lim.brake
        ));
    }
    Ok(())
}

/// The fleet a file's planners expect: the bodies of its `vehicles` (`fields` reads a
/// vehicle's id, length and brake), each checked and refused at its own table, and a
/// truck's if its `arrivals` bring trucks ([`crate::world::Fleet::with_arrivals`]).
pub(super) fn checked_fleet<V>(
    vehicles: &[Spanned<V>],
    fields: impl Fn(&V) -> (u16, Option<f64>, Option<f64>),
    arrivals: Option<&super::common::ArrivalsToml>,
    e: &Errors<'_>,
) -> Result<crate::world::Fleet, ScenarioError> {
    let lim = Limits::table_i();
    let mut bodies = Vec::with_capacity(vehicles.len());
    for sv in vehicles {
        let (id, length, brake) = fields(sv.get_ref());
        check_body((length, brake), &lim)
            .map_err(|m| e.at(Some(sv.span()), format!("vehicle {id}: {m}")))?;
        bodies.push(body_of(length, brake));
    }
    let trucks = arrivals.map_or(0, |a| a.trucks);
    Ok(crate::world::Fleet::with_arrivals(bodies, trucks))
}

/// The body a file's `length` and `brake` give: Table I's car where they are silent.
pub(super) fn body_of(length: Option<f64>, brake: Option<f64>) -> Body {
    Body {
        length: length.unwrap_or(Body::CAR.length),
        brake: brake.unwrap_or(Body::CAR.brake),
    }
}

/// The body as a file writes it: silent where it is Table I's car.
pub(super) fn body_fields(body: Body) -> (Option<f64>, Option<f64>) {
    let car = Body::CAR;
    (
        (body.length != car.length).then_some(body.length),
        (body.brake != car.brake).then_some(body.brake),
    )
}

/// The shortest vehicle a scenario may have (m): shorter than a moped is an error.
pub const MIN_LENGTH_M: f64 = 1.0;
/// The longest (m): the largest length a V2V state declares
/// ([`planner_core::BodyLength`]).
pub const MAX_LENGTH_M: f64 = 25.5;
/// The weakest braking limit a scenario may give (m/s²): below a loaded truck's on a
/// wet road is an error.
pub const MIN_BRAKE_MPS2: f64 = 1.0;

/// A scripted driver has increasing phases within the acceleration limits; nobody else
/// has a script.
fn check_script(v: &RoadVehicle, lim: &Limits) -> Result<(), String> {
    if v.driver != DriverKind::Script {
        return match v.script.is_empty() {
            true => Ok(()),
            false => Err("script given but driver is not \"script\"".into()),
        };
    }
    if v.script.is_empty() {
        return Err("driver = \"script\" needs a non-empty script".into());
    }
    let mut last = 0.0;
    for p in &v.script {
        if !(p.until_s > last && p.until_s.is_finite()) {
            return Err("script phases need increasing until_s > 0".into());
        }
        if !(p.accel >= -v.body().brake && p.accel <= lim.a_max) {
            let (lo, hi) = (-v.body().brake, lim.a_max);
            return Err(format!("script accel {} outside [{lo}, {hi}]", p.accel));
        }
        last = p.until_s;
    }
    Ok(())
}

/// Theorem 3 / (23): on a dead-end road a vehicle needing M lane changes must have
/// M (dS(vmax) + dC(vmax)) of road left, or its changes are not guaranteed.
fn check_commitment(
    vehicles: &[(RoadVehicle, Range<usize>)],
    road: &Road,
    end: f64,
) -> Result<(), (Range<usize>, String)> {
    let lim = Limits::table_i();
    let specs: Vec<RoadVehicle> = vehicles.iter().map(|(v, _)| v.clone()).collect();
    for (i, (v, span)) in vehicles.iter().enumerate() {
        let Some(b) = commitment_bound(&specs, road, i, lim.v_max) else {
            continue;
        };
        let room = end - v.x;
        if !(room >= b) {
            let m = v.lane.abs_diff(v.target_lane.unwrap_or(v.lane));
            return Err((
                span.clone(),
                format!(
                    "vehicle {}: needs {m} lane change(s) but starts {room:.1} m before the \
                     road end; the commitment distance (23) is {b:.1} m",
                    v.id
                ),
            ));
        }
    }
    Ok(())
}

/// Per lane, front to back: no overlap, the invariant in use for every planner-driven
/// follower (the leader-aware one credits a planner-driven leader with its least travel),
/// and scripted/random drivers only at the front of their lane (they do not keep the
/// invariant themselves).
fn check_lanes(
    vehicles: &[(RoadVehicle, Range<usize>)],
    lanes: u8,
    invariant: planner_core::Invariant,
) -> Result<(), (Range<usize>, String)> {
    let lim = Limits::table_i();
    for lane in 0..lanes {
        let mut in_lane: Vec<&(RoadVehicle, Range<usize>)> =
            vehicles.iter().filter(|(v, _)| v.lane == lane).collect();
        in_lane.sort_by(|a, b| b.0.x.total_cmp(&a.0.x));
        for pair in in_lane.windows(2) {
            let (lead, (follow, span)) = (&pair[0].0, (&pair[1].0, &pair[1].1));
            let fail = |p: String| Err((span.clone(), p));
            let gap = lead.x - follow.x - 0.5 * (lead.body().length + follow.body().length);
            if gap <= 0.0 {
                return fail(format!(
                    "vehicle {} overlaps vehicle {} in lane {lane}",
                    follow.id, lead.id
                ));
            }
            if follow.driver != DriverKind::Planner {
                return fail(format!(
                    "vehicle {}: a {:?} driver must lead its lane (vehicle {} is ahead)",
                    follow.id, follow.driver, lead.id
                ));
            }
            let p = crate::world::vehicle::params(lim.v_max, follow.body());
            let credit = match invariant {
                planner_core::Invariant::LeaderAware if lead.driver == DriverKind::Planner => {
                    planner_core::safety::leader_credit(&p, lead.v, lead.body().brake)
                }
                _ => 0.0,
            };
            let need =
                lim.safe_distance_at(follow.v, follow.body().brake) + START_MARGIN_M - credit;
            if !(gap - lim.d0 > need.max(START_MARGIN_M)) {
                return fail(format!(
                    "vehicle {} violates the safety invariant behind vehicle {}: bumper gap \
                     {gap:.3} m, needs more than d0 + dS(v) - credit = {:.3} m",
                    follow.id,
                    lead.id,
                    lim.d0 + need.max(START_MARGIN_M)
                ));
            }
        }
    }
    Ok(())
}

/// The commitment distance (23) for vehicle `index` at its start: M lane changes
/// times dS(v) + dC(v) at the paper's speed `v`, with ρ_t = max(ρ^{H+}, ρ^{H−}) of its
/// free space toward the first lane it has to enter. `None` if it needs no change.
pub fn commitment_bound(
    vehicles: &[RoadVehicle],
    road: &Road,
    index: usize,
    v: f64,
) -> Option<f64> {
    let spec = vehicles.get(index)?;
    let p = crate::world::vehicle::params(Limits::table_i().v_max, spec.body());
    let target = spec.target_lane.unwrap_or(spec.lane);
    let m = spec.lane.abs_diff(target);
    if m == 0 {
        return None;
    }
    let next = if target > spec.lane {
        spec.lane + 1
    } else {
        spec.lane - 1
    };
    let lo = f64::from(spec.lane.min(next)) * LANE_WIDTH_M + 0.5 * WIDTH_M;
    let hi = f64::from(spec.lane.max(next) + 1) * LANE_WIDTH_M - 0.5 * WIDTH_M;
    let pose = Pose {
        x: spec.x,
        y: (f64::from(spec.lane) + 0.5) * LANE_WIDTH_M,
        theta: 0.0,
    };
    // x̄ toward the nearest vehicle ahead in either lane (or the road end).
    let lim = Limits::table_i();
    let ahead = vehicles
        .iter()
        .filter(|o| o.x > spec.x && (o.lane == spec.lane || o.lane == next))
        .map(|o| o.x - 0.5 * (o.body().length + spec.body().length) - lim.d0)
        .chain(road.end_x.map(|e| e - 0.5 * spec.body().length - lim.d0))
        .fold(f64::INFINITY, f64::min);
    let gap = (ahead - spec.x).min(planner_core::planner::free_road_gap(&p, 20));
    let fs = FreeSpace::new(&p, pose, spec.v, 0.0, Band { lo, hi }, gap).ok()?;
    let rho = |k: f64| if k > 0.0 { 1.0 / k } else { f64::INFINITY };
    let rho_t = rho(fs.arc_h.kappa_plus).max(rho(fs.arc_h.kappa_minus));
    Some(commitment_distance(&p, m, v, rho_t, 0.0))
}
