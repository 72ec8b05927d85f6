//! The single `[intersection]` format: one junction (the SPEC §8 layout or a configured
//! one) with its own inlet and outlet tracks, its vehicles by inlet, lane, movement and
//! position along the inlet; a network of one junction and no segment.

use super::common::{ArrivalsToml, Header, RawHeader, SensingToml};
use super::error::{Errors, FieldError, ScenarioError};
use crate::bus::Faults;
use crate::monitor::Limits;
use crate::world::at::At;
use crate::world::junction::MANAGER_CAP;
use crate::world::network::{Junction, Network};
use crate::world::vehicle::Trip;
use crate::world::{
    Arrivals, Body, Finish, Fleet, VehicleSpec, WorldSpec, LANE_WIDTH_M, START_MARGIN_M,
};
use planner_core::crossing::Algorithm;
use planner_core::intersection::{Layout, LayoutError, LayoutSpec, Movement};
use planner_core::Params;
use serde::{Deserialize, Serialize};
use std::ops::Range;
use std::path::Path;
use toml::Spanned;

/// An intersection's layout as written (SPEC §8 defaults).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct LayoutToml {
    /// Half-size a of A_S (m).
    #[serde(default = "d_half")]
    pub half_size: f64,
    /// A_C = A_S grown by this (m).
    #[serde(default = "d_comm")]
    pub comm_margin: f64,
    /// Inlet length before the stop line (m).
    #[serde(default = "d_inlet")]
    pub inlet_length: f64,
    /// Outlet length past A_S (m).
    #[serde(default = "d_outlet")]
    pub outlet_length: f64,
    /// Speed limit vImax (m/s).
    #[serde(default = "d_limit")]
    pub v_limit: f64,
    /// Inlet (and outlet) lanes per approach.
    #[serde(default = "d_lanes")]
    pub lanes: u8,
    /// How far inside A_S the turns begin and end (m; default 0): the turns of a square
    /// `turn_inset` smaller, run straight to and from A_S's edge — room for a long
    /// vehicle's swing.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub turn_inset: f64,
}

fn is_zero(x: &f64) -> bool {
    *x == 0.0
}

impl Default for LayoutToml {
    fn default() -> Self {
        Self {
            half_size: d_half(),
            comm_margin: d_comm(),
            inlet_length: d_inlet(),
            outlet_length: d_outlet(),
            v_limit: d_limit(),
            lanes: d_lanes(),
            turn_inset: 0.0,
        }
    }
}

fn d_half() -> f64 {
    12.0
}
fn d_comm() -> f64 {
    50.0
}
fn d_inlet() -> f64 {
    100.0
}
fn d_outlet() -> f64 {
    60.0
}
fn d_limit() -> f64 {
    13.9
}
fn d_lanes() -> u8 {
    2
}

/// Heading of travel.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Heading {
    /// From the west.
    East,
    /// From the south.
    North,
    /// From the east.
    West,
    /// From the north.
    South,
}

impl Heading {
    /// planner-core's heading index.
    pub fn index(self) -> u8 {
        match self {
            Heading::East => 0,
            Heading::North => 1,
            Heading::West => 2,
            Heading::South => 3,
        }
    }

    /// From planner-core's heading index.
    pub fn of(i: u8) -> Self {
        match i % 4 {
            0 => Heading::East,
            1 => Heading::North,
            2 => Heading::West,
            _ => Heading::South,
        }
    }
}

/// A manoeuvre.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum MovementToml {
    /// Straight on.
    Straight,
    /// Left turn.
    Left,
    /// Right turn.
    Right,
}

impl MovementToml {
    /// planner-core's movement.
    pub fn movement(self) -> Movement {
        match self {
            MovementToml::Straight => Movement::Straight,
            MovementToml::Left => Movement::Left,
            MovementToml::Right => Movement::Right,
        }
    }

    /// From planner-core's movement.
    pub fn of(m: Movement) -> Self {
        match m {
            Movement::Straight => MovementToml::Straight,
            Movement::Left => MovementToml::Left,
            Movement::Right => MovementToml::Right,
        }
    }
}

/// The crossing algorithm, as written in a scenario file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum AlgorithmToml {
    /// All-Way STOP: stopped vehicles go in the order they stopped, together when their
    /// routes do not conflict.
    Stop,
    /// All-Way STOP one vehicle at a time.
    StopSingle,
    /// FIFO Crossing.
    Fifo,
    /// Concurrent Crossing as written in the paper (not live; see SPEC §7).
    Concurrent,
    /// Starvation-free Concurrent Crossing.
    ConcurrentFair,
    /// Pipelined (ours).
    Pipelined,
    /// Pipelined with platoons (ours).
    Platoon,
}

impl AlgorithmToml {
    /// planner-core's algorithm.
    pub fn algorithm(self) -> Algorithm {
        match self {
            AlgorithmToml::Stop => Algorithm::AllWayStop,
            AlgorithmToml::StopSingle => Algorithm::AllWayStopSingle,
            AlgorithmToml::Fifo => Algorithm::Fifo,
            AlgorithmToml::Concurrent => Algorithm::Concurrent,
            AlgorithmToml::ConcurrentFair => Algorithm::ConcurrentFair,
            AlgorithmToml::Pipelined => Algorithm::Pipelined,
            AlgorithmToml::Platoon => Algorithm::Platoon,
        }
    }

    /// Its name in a scenario file (`"platoon"`): what serde writes, asked of serde so
    /// that it is spelled once.
    pub fn key(self) -> String {
        match serde_json::to_value(self) {
            Ok(serde_json::Value::String(s)) => s,
            // A unit variant always serializes as its name.
            other => unreachable!("{other:?}"),
        }
    }

    /// From planner-core's algorithm.
    pub fn of(a: Algorithm) -> Self {
        match a {
            Algorithm::AllWayStop => AlgorithmToml::Stop,
            Algorithm::AllWayStopSingle => AlgorithmToml::StopSingle,
            Algorithm::Fifo => AlgorithmToml::Fifo,
            Algorithm::Concurrent => AlgorithmToml::Concurrent,
            Algorithm::ConcurrentFair => AlgorithmToml::ConcurrentFair,
            Algorithm::Pipelined => AlgorithmToml::Pipelined,
            Algorithm::Platoon => AlgorithmToml::Platoon,
            // planner-core's algorithms grow (`#[non_exhaustive]`); each gets its
            // scenario name here when host-sim learns it (a test walks Algorithm::ALL).
            other => unreachable!("{} has no scenario name", other.name()),
        }
    }
}

/// A vehicle of an intersection scenario.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct JunctionVehicle {
    /// Id (1 to 65,279; above is the managers').
    pub id: u16,
    /// Inlet: the heading of travel.
    pub heading: Heading,
    /// Inlet lane: 0 inner … lanes − 1 outer.
    pub lane: u8,
    /// What it does at the junction (left: inner lane, right: outer lane).
    pub movement: MovementToml,
    /// Centre distance from the start of the inlet track (m).
    pub s: f64,
    /// Speed (m/s).
    pub v: f64,
    /// Its length (m; default Table I's 4.5 m).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub length: Option<f64>,
    /// Its braking limit |amin| (m/s²; default Table I's 7.9).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub brake: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawJunction {
    name: String,
    duration_s: Spanned<f64>,
    #[serde(default)]
    seed: u64,
    algorithm: AlgorithmToml,
    intersection: Spanned<LayoutToml>,
    #[serde(default, rename = "vehicle")]
    vehicles: Vec<Spanned<JunctionVehicle>>,
    #[serde(default)]
    arrivals: Option<Spanned<ArrivalsToml>>,
    #[serde(default)]
    faults: Option<Spanned<Faults>>,
    #[serde(default)]
    sensing: Option<Spanned<SensingToml>>,
    #[serde(default)]
    deadlock_s: Option<Spanned<f64>>,
    #[serde(default)]
    invariant: Option<Spanned<String>>,
}

/// A vehicle placed on a route.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    /// Id.
    pub id: u16,
    /// Route index.
    pub route: u8,
    /// Centre distance along the route's path (m).
    pub s: f64,
    /// Speed (m/s).
    pub v: f64,
    /// Its body.
    pub body: Body,
}

/// A validated intersection scenario.
#[derive(Debug, Clone)]
pub struct JunctionScenario {
    /// Name.
    pub name: String,
    /// Seed (recorded; faults and sensor noise draw from it).
    pub seed: u64,
    /// Duration, faults, sensing, deadlock window.
    pub header: Header,
    /// Algorithm.
    pub algorithm: Algorithm,
    /// The layout as written.
    pub layout_toml: LayoutToml,
    /// Layout.
    pub layout: Layout<f64>,
    /// Vehicles.
    pub placements: Vec<Placement>,
    /// Poisson arrivals at every inlet lane, if any: the open system of `experiment
    /// demand`, as a file.
    pub arrivals: Option<ArrivalsToml>,
}

/// Why a layout is refused: the field at fault and what is wrong, in words.
pub fn layout_error_text(e: LayoutError<f64>, p: &Params<f64>) -> FieldError {
    match e {
        LayoutError::NotPositive => {
            FieldError::new("half_size", "every length must be positive and finite")
        }
        LayoutError::LanesDoNotFit => FieldError::new(
            "half_size",
            format!("must hold the inlet lanes (lanes × {LANE_WIDTH_M} m) and the outlet lanes"),
        ),
        LayoutError::TurnTooTight { radius } => FieldError::new(
            "half_size",
            format!(
                "the right turn's radius a − (lanes − ½) Wl = {radius:.2} m is below ρmin = {} m",
                p.rho_min()
            ),
        ),
        LayoutError::NotSpacious { margin, needed } => FieldError::new(
            "comm_margin",
            format!(
                "violates the Spaciousness Assumption (27): A_C is {margin:.2} m from A_S, \
                 needs at least dS(vImax) + vImax h = {needed:.2} m"
            ),
        ),
        LayoutError::InletShorterThanCommRegion => FieldError::new(
            "inlet_length",
            "must reach back to the edge of A_C (≥ comm_margin)",
        ),
        LayoutError::OutletShorterThanCommRegion { length, needed } => FieldError::new(
            "outlet_length",
            format!(
                "{length} m ends inside A_C: vehicles leave the intersection once they are on \
                 their outlet outside A_C, so it must be at least comm_margin + L = {needed:.2} m"
            ),
        ),
        LayoutError::BadTurnInset => FieldError::new(
            "turn_inset",
            format!(
                "must be finite, at least 0, and leave the lanes room: lanes × {LANE_WIDTH_M} m \
                 within half_size − turn_inset"
            ),
        ),
        LayoutError::SweepLeavesItsLanes { route, by } => FieldError::new(
            "turn_inset",
            format!(
                "a {:.1} m vehicle swings {by:.2} m out of A_S and its own lanes on route {route} \
                 (into a lane where others wait, or over the kerb): make A_S larger around the \
                 same turns (raise half_size and turn_inset together; 8 m each takes a 16.5 m \
                 truck at SPEC §8's turns)",
                p.length()
            ),
        ),
        // A refusal planner-core learns later: its own words.
        other => FieldError::new("half_size", other.to_string()),
    }
}

/// The layout of `lt`, or which field is wrong and why.
pub fn build_layout(lt: &LayoutToml) -> Result<Layout<f64>, FieldError> {
    build_layout_for(lt, Fleet::default())
}

/// [`build_layout`] for a `fleet` with trucks: the routes' conflicts (γ_i ⊗ γ_j) are swept
/// by the longest vehicle, whatever crosses (a conflict found for a car's rectangle is
/// too small for a truck's), and Spaciousness (27) is checked at the weakest braking
/// limit with the longest vehicle's half length.
pub fn build_layout_for(lt: &LayoutToml, fleet: Fleet) -> Result<Layout<f64>, FieldError> {
    let p = Params::<f64>::table_i();
    if !(lt.v_limit > 0.0 && lt.v_limit <= p.v_max()) {
        return Err(FieldError::new(
            "v_limit",
            format!("must be in (0, {}], got {}", p.v_max(), lt.v_limit),
        ));
    }
    let max_lanes = planner_core::intersection::MAX_LANES;
    if !(1..=max_lanes).contains(&lt.lanes) {
        return Err(FieldError::new(
            "lanes",
            format!("must be 1 to {max_lanes}, got {}", lt.lanes),
        ));
    }
    let lengths = [
        ("half_size", lt.half_size),
        ("comm_margin", lt.comm_margin),
        ("inlet_length", lt.inlet_length),
        ("outlet_length", lt.outlet_length),
    ];
    for (field, x) in lengths {
        if !(x > 0.0 && super::common::coord_ok(x)) {
            return Err(FieldError::new(
                field,
                format!(
                    "must be positive, finite and within {} m, got {x}",
                    super::common::MAX_COORD_M
                ),
            ));
        }
    }
    let spec = LayoutSpec {
        half_size: lt.half_size,
        comm_margin: lt.comm_margin,
        inlet_length: lt.inlet_length,
        outlet_length: lt.outlet_length,
        lane_width: LANE_WIDTH_M,
        v_limit: lt.v_limit,
        lanes: lt.lanes,
        turn_inset: lt.turn_inset,
    };
    let longest = Body {
        length: fleet.longest_m,
        brake: fleet.weakest_brake,
    };
    let fleet_p = crate::world::vehicle::params(p.v_max(), longest);
    let layout = Layout::new(&fleet_p, spec).map_err(|e| layout_error_text(e, &fleet_p))?;
    // Spaciousness (27) with the vehicles' extent: a vehicle hands over to its crossing
    // planner once its centre is in A_C, and must then still be able to stop with its
    // front d0 before the line. A margin below that left vehicles waiting outside A_C
    // for ever (a red team's v_limit 1.0 with a 0.2 m margin).
    let lim = crate::monitor::Limits::table_i();
    let handover = lim.safe_distance_at(lt.v_limit, fleet.weakest_brake)
        + lt.v_limit * lim.h
        + 0.5 * fleet.longest_m
        + lim.d0;
    if !(lt.comm_margin >= handover) {
        return Err(FieldError::new(
            "comm_margin",
            format!(
                "{:.2} m is too short to hand a vehicle over inside A_C and still stop before \
                 A_S: at {} m/s it needs dS(v) + v h + L/2 + d0 = {handover:.2} m",
                lt.comm_margin, lt.v_limit
            ),
        ));
    }
    Ok(layout)
}

impl JunctionScenario {
    /// Parses and validates; `path` only names the file in errors.
    pub fn parse(text: &str, path: &Path) -> Result<Self, ScenarioError> {
        let e = Errors::new(text, path);
        let raw: RawJunction = toml::from_str(text).map_err(|x| e.toml(&x))?;
        let header = RawHeader {
            duration_s: Some(raw.duration_s.clone()),
            faults: raw.faults.clone(),
            sensing: raw.sensing.clone(),
            deadlock_s: raw.deadlock_s.clone(),
            invariant: raw.invariant.clone(),
            ..RawHeader::default()
        }
        .validate(&e)?;
        let span = raw.intersection.span();
        let lt = raw.intersection.into_inner();
        let arrivals = ArrivalsToml::checked(raw.arrivals.as_ref(), &e)?;
        let fleet = super::road::checked_fleet(
            &raw.vehicles,
            |v| (v.id, v.length, v.brake),
            arrivals.as_ref(),
            &e,
        )?;
        let layout = build_layout_for(&lt, fleet)
            .map_err(|m| e.field(Some(span.clone()), "intersection", &m))?;
        let fewest = usize::from(arrivals.is_none());
        if raw.vehicles.len() < fewest || raw.vehicles.len() > MANAGER_CAP {
            // The first vehicle too many, or the intersection none is at.
            let at = raw.vehicles.get(MANAGER_CAP).map_or(span, Spanned::span);
            return Err(e.at(
                Some(at),
                format!(
                    "{fewest} to {MANAGER_CAP} vehicles (at least one without [arrivals]), got {}",
                    raw.vehicles.len()
                ),
            ));
        }
        let mut placements: Vec<(Placement, Range<usize>)> = Vec::new();
        for sv in raw.vehicles {
            let span = sv.span();
            let v = sv.into_inner();
            if placements.iter().any(|(o, _)| o.id == v.id) {
                return Err(e.at(Some(span), format!("vehicle {}: duplicate id", v.id)));
            }
            let p = place(&v, &layout, &lt)
                .map_err(|m| e.at(Some(span.clone()), format!("vehicle {}: {m}", v.id)))?;
            placements.push((p, span));
        }
        check_spacing(&placements, &layout, &e)?;
        Ok(Self {
            name: raw.name,
            seed: raw.seed,
            header,
            algorithm: raw.algorithm.algorithm(),
            layout_toml: lt,
            layout,
            placements: placements.into_iter().map(|(p, _)| p).collect(),
            arrivals,
        })
    }

    /// A scenario of `placements` at the layout `lt` under `algorithm`, in the paper's
    /// world (no faults, no sensors); `Err` if the layout is refused.
    pub fn new(
        name: String,
        duration_s: f64,
        seed: u64,
        algorithm: Algorithm,
        lt: LayoutToml,
        placements: Vec<Placement>,
    ) -> Result<Self, String> {
        Ok(Self {
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
            algorithm,
            layout: build_layout_for(&lt, Fleet::of(placements.iter().map(|p| p.body)))
                .map_err(|m| m.to_string())?,
            layout_toml: lt,
            placements,
            arrivals: None,
        })
    }

    /// The world it describes: one junction at the origin, its own inlet and outlet
    /// tracks, every vehicle crossing from the start.
    pub fn world(&self) -> WorldSpec {
        let jn = Junction {
            id: 0,
            centre: (0.0, 0.0),
            layout: self.layout.clone(),
            algorithm: self.algorithm,
            inlets: [None; 4],
            outlets: [None; 4],
        };
        WorldSpec {
            name: self.name.clone(),
            duration_s: self.header.duration_s,
            seed: self.seed,
            horizon: 20,
            deadline_s: self.header.duration_s,
            network: Network {
                segments: Vec::new(),
                junctions: vec![jn],
            },
            vehicles: self
                .placements
                .iter()
                .map(|p| placed(&self.layout, p))
                .collect(),
            faults: self.header.faults,
            sensing: self.header.sensing,
            arrivals: self
                .arrivals
                .map_or(Arrivals::None, |a| stub_arrivals(&self.layout, a)),
            deadlock_window_s: self.header.deadlock_window_s,
            finish: Finish::Duration,
            clock_start: planner_core::Instant::EPOCH,
            precision: crate::world::precision::Precision::F64,
            invariant: self.header.invariant,
        }
    }

    /// The scenario as a file that `host-sim run` loads (a sweep's failing case).
    pub fn to_toml(&self) -> String {
        #[derive(Serialize)]
        struct File<'a> {
            name: &'a str,
            duration_s: f64,
            seed: u64,
            algorithm: AlgorithmToml,
            #[serde(skip_serializing_if = "Option::is_none")]
            invariant: Option<&'static str>,
            intersection: LayoutToml,
            #[serde(skip_serializing_if = "Faults::is_none")]
            faults: Faults,
            #[serde(skip_serializing_if = "Option::is_none")]
            sensing: Option<SensingToml>,
            #[serde(skip_serializing_if = "Option::is_none")]
            arrivals: Option<ArrivalsToml>,
            #[serde(rename = "vehicle")]
            vehicles: Vec<JunctionVehicle>,
        }
        let vehicles = self
            .placements
            .iter()
            .filter_map(|p| {
                let r = self.layout.route(usize::from(p.route))?;
                let (length, brake) = super::road::body_fields(p.body);
                Some(JunctionVehicle {
                    id: p.id,
                    heading: Heading::of(r.inlet.heading),
                    lane: r.inlet.lane,
                    movement: MovementToml::of(r.movement),
                    s: p.s,
                    v: p.v,
                    length,
                    brake,
                })
            })
            .collect();
        let file = File {
            name: &self.name,
            duration_s: self.header.duration_s,
            seed: self.seed,
            algorithm: AlgorithmToml::of(self.algorithm),
            // Always named: the file replays under the invariant it ran under, whatever
            // the loader's default.
            invariant: Some(crate::world::invariant_name(self.header.invariant)),
            intersection: self.layout_toml,
            faults: self.header.faults,
            sensing: Some(SensingToml::of(self.header.sensing)),
            arrivals: self.arrivals,
            vehicles,
        };
        toml::to_string(&file).unwrap_or_else(|e| format!("# cannot write: {e}"))
    }
}

/// Poisson arrivals as `a` says (its rate, its share of trucks) at the start of every
/// inlet lane of junction 0.
pub fn stub_arrivals(layout: &Layout<f64>, a: ArrivalsToml) -> Arrivals {
    let rate_vph = a.rate_vph;
    let entries = (0..4u8)
        .flat_map(|heading| {
            (0..layout.spec.lanes).map(move |lane| {
                let entry = crate::world::spawn::Entry::Stub {
                    junction: 0,
                    heading,
                    lane,
                };
                (entry, rate_vph)
            })
        })
        .collect();
    Arrivals::Poisson(crate::world::Poisson {
        entries,
        trucks_percent: a.trucks,
    })
}

/// The world's vehicle of a placement at junction 0.
pub fn placed(layout: &Layout<f64>, p: &Placement) -> VehicleSpec {
    let r = layout.route(usize::from(p.route));
    VehicleSpec {
        id: p.id,
        at: At::Crossing {
            junction: 0,
            route: p.route,
            s: p.s,
        },
        v: p.v,
        driver: super::DriverKind::Planner,
        script: Vec::new(),
        cooperative: true,
        body: p.body,
        trip: Trip {
            target_lane: r.map_or(0, |r| r.inlet.lane),
            goal_x: None,
            v_ref: None,
            movements: r.map_or(Vec::new(), |r| vec![r.movement]),
        },
    }
}

/// The placement of vehicle `v`, or why it is refused: an id the managers do not use, a
/// movement its lane serves, on its inlet before the line, a speed within the limit,
/// room to stop before the line.
fn place(v: &JunctionVehicle, layout: &Layout<f64>, lt: &LayoutToml) -> Result<Placement, String> {
    let lim = Limits::table_i();
    if !crate::bus::is_vehicle_id(v.id) {
        return Err("ids are 1 to 65,279 (above are the junction managers')".into());
    }
    let route = layout
        .route_index(v.heading.index(), v.lane, v.movement.movement())
        .ok_or_else(|| {
            format!(
                "{:?} is not a route from lane {} of {} (left: inner lane 0, right: outer lane {})",
                v.movement,
                v.lane,
                lt.lanes,
                lt.lanes.saturating_sub(1)
            )
        })?;
    let entry = lt.inlet_length;
    let body = super::road::body_of(v.length, v.brake);
    let half = 0.5 * body.length;
    if !(v.s >= half && v.s + half + lim.d0 < entry) {
        return Err(format!(
            "s must put the vehicle on its inlet before the stop line, got {}",
            v.s
        ));
    }
    if !(v.v >= 0.0 && v.v <= lt.v_limit) {
        return Err(format!("v must be in [0, {}], got {}", lt.v_limit, v.v));
    }
    let room = entry - v.s - half - lim.d0;
    let d_s = lim.safe_distance_at(v.v, body.brake);
    if !(room > d_s + START_MARGIN_M) {
        return Err(format!(
            "cannot stop before the stop line: {room:.2} m of room, needs more than dS(v) = {d_s:.2} m"
        ));
    }
    Ok(Placement {
        id: v.id,
        route: route as u8,
        s: v.s,
        v: v.v,
        body,
    })
}

/// Same inlet: no overlap, and the invariant for every follower.
fn check_spacing(
    placements: &[(Placement, Range<usize>)],
    layout: &Layout<f64>,
    e: &Errors<'_>,
) -> Result<(), ScenarioError> {
    let lim = Limits::table_i();
    for (a, span) in placements {
        for (b, _) in placements {
            let (Some(ra), Some(rb)) = (
                layout.route(usize::from(a.route)),
                layout.route(usize::from(b.route)),
            ) else {
                continue;
            };
            if a.id != b.id && ra.inlet == rb.inlet && a.s <= b.s {
                let gap = b.s - a.s - 0.5 * (a.body.length + b.body.length);
                if !(gap - lim.d0 > lim.safe_distance_at(a.v, a.body.brake) + START_MARGIN_M) {
                    return Err(e.at(
                        Some(span.clone()),
                        format!(
                            "vehicle {} violates the safety invariant behind vehicle {} on its \
                             inlet (bumper gap {gap:.2} m)",
                            a.id, b.id
                        ),
                    ));
                }
            }
        }
    }
    Ok(())
}

/// The intersection format's tables and their keys (see [`super::keys`]).
pub fn keys() -> Vec<(&'static str, &'static [&'static str])> {
    use super::keys::fields;
    vec![
        ("intersection file", fields::<RawJunction>()),
        ("[intersection]", fields::<LayoutToml>()),
        (
            "[[vehicle]] at an intersection",
            fields::<JunctionVehicle>(),
        ),
        ("[arrivals] at an intersection", fields::<ArrivalsToml>()),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every algorithm planner-core has can be written in a scenario file and read back:
    /// `AlgorithmToml::of` knows them all (planner-core's enum is `#[non_exhaustive]`, so
    /// the compiler no longer says so).
    #[test]
    fn every_algorithm_has_a_scenario_name() {
        for a in Algorithm::ALL {
            assert_eq!(AlgorithmToml::of(a).algorithm(), a, "{}", a.name());
            let key = AlgorithmToml::of(a).key();
            let read: AlgorithmToml =
                serde_json::from_value(serde_json::Value::String(key)).expect("its own key");
            assert_eq!(read.algorithm(), a, "{}", a.name());
        }
    }
}
