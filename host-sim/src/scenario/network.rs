//! The network format: intersections joined by multi-lane segments (SPEC §10).
//!
//! ```toml
//! name = "corridor"
//! duration_s = 120.0
//! algorithm = "pipelined"       # every intersection's, unless it says otherwise
//!
//! [grid]                        # rows × cols intersections, block_m apart, joined by
//! rows = 1                      # segments both ways, with entry and exit segments of
//! cols = 3                      # boundary_m on the outer sides
//! block_m = 300.0
//! lanes = 3
//!
//! # … or explicitly:
//! [[intersection]]
//! id = 1
//! x = 0.0                       # centre (m)
//! y = 0.0
//! lanes = 2                     # and half_size, comm_margin, v_limit, algorithm
//!
//! [[segment]]
//! id = 10
//! to = 1                        # the intersection it feeds (absent: an exit)
//! from = 2                      # the intersection it leaves (absent: an entry)
//! heading = "east"              # direction of travel (needed when an end is open)
//! length = 200.0                # (needed when an end is open; else the distance)
//!
//! [[vehicle]]
//! id = 1
//! segment = 10
//! x = 30.0
//! lane = 0
//! v = 10.0
//! route = ["left", "straight"]  # one movement per intersection ahead; or
//! destination = 12              # an exit segment, by the shortest path
//!
//! [arrivals]                    # an open system: Poisson arrivals at every entry lane
//! rate_vph = 300.0
//! ```
//!
//! At every intersection its inlet track is the last `comm_margin` metres of the segment
//! feeding it and its outlet track the first `comm_margin + L` of the segment leaving it;
//! a vehicle changes lanes between, toward a lane serving its next movement. A segment
//! too short for the changes a route through it needs is refused with the reason.

pub use super::common::ArrivalsToml;
use super::common::{coord_ok, Header, RawHeader, SensingToml, MAX_COORD_M};
use super::error::{Errors, ScenarioError};
use super::junction::{build_layout_for, AlgorithmToml, Heading, LayoutToml, MovementToml};
use crate::bus::Faults;
use crate::monitor::Limits;
use crate::world::at::At;
use crate::world::network::{rotate, End, Junction, Network, Segment};
use crate::world::spawn::Entry;
use crate::world::vehicle::Trip;
use crate::world::{
    Arrivals, Finish, Fleet, Poisson, VehicleSpec, WorldSpec, LANE_WIDTH_M, LENGTH_M,
    START_MARGIN_M,
};
use planner_core::intersection::Movement;
use serde::Deserialize;
use std::ops::Range;
use std::path::Path;
use toml::Spanned;

/// Most intersections.
pub const MAX_JUNCTIONS: usize = 64;
/// Most vehicles at t = 0.
pub const MAX_VEHICLES: usize = 5000;

/// `[grid]`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GridToml {
    /// Rows of intersections.
    pub rows: u8,
    /// Columns of intersections.
    pub cols: u8,
    /// Centre-to-centre distance (m).
    pub block_m: f64,
    /// Lanes per direction.
    #[serde(default = "two")]
    pub lanes: u8,
    /// Length of the entry and exit segments on the outer sides (m; default block_m).
    #[serde(default)]
    pub boundary_m: Option<f64>,
    /// Every intersection's turn inset (m; default 0): A_S this much larger around the
    /// same turns, room for a truck's swing (see `[[intersection]]`).
    #[serde(default)]
    pub turn_inset: f64,
}

fn two() -> u8 {
    2
}

/// `[[intersection]]`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IntersectionToml {
    /// Id.
    pub id: u16,
    /// Centre x (m).
    pub x: f64,
    /// Centre y (m).
    pub y: f64,
    /// Lanes per approach.
    #[serde(default = "two")]
    pub lanes: u8,
    /// Half-size a of A_S (m; default: the least that fits the lanes and ρmin, at least
    /// 12).
    #[serde(default)]
    pub half_size: Option<f64>,
    /// A_C = A_S grown by this (m).
    #[serde(default = "comm")]
    pub comm_margin: f64,
    /// vImax (m/s), also every segment's speed limit.
    #[serde(default = "limit")]
    pub v_limit: f64,
    /// Its manager's algorithm (default: the file's).
    #[serde(default)]
    pub algorithm: Option<AlgorithmToml>,
    /// How far inside A_S the turns begin and end (m; default 0); the default half-size
    /// grows by as much, so the turns stay those of the least half-size.
    #[serde(default)]
    pub turn_inset: f64,
}

fn comm() -> f64 {
    50.0
}
fn limit() -> f64 {
    13.9
}

/// `[[segment]]`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SegmentToml {
    /// Id.
    pub id: u16,
    /// The intersection it leaves (absent: it enters the network).
    #[serde(default)]
    pub from: Option<u16>,
    /// The intersection it feeds (absent: it leaves the network).
    #[serde(default)]
    pub to: Option<u16>,
    /// Direction of travel (needed when an end is open).
    #[serde(default)]
    pub heading: Option<Heading>,
    /// Length (m; needed when an end is open).
    #[serde(default)]
    pub length: Option<f64>,
}

/// `[[vehicle]]` of a network.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NetVehicleToml {
    /// Id.
    pub id: u16,
    /// Segment.
    pub segment: u16,
    /// Centre x along it (m).
    pub x: f64,
    /// Lane (0 rightmost).
    pub lane: u8,
    /// Speed (m/s).
    pub v: f64,
    /// Movements, one per intersection ahead.
    #[serde(default)]
    pub route: Option<Vec<MovementToml>>,
    /// An exit segment, reached by the shortest path.
    #[serde(default)]
    pub destination: Option<u16>,
    /// Its length (m; default Table I's 4.5 m).
    #[serde(default)]
    pub length: Option<f64>,
    /// Its braking limit |amin| (m/s²; default Table I's 7.9).
    #[serde(default)]
    pub brake: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawNetwork {
    name: String,
    duration_s: Spanned<f64>,
    #[serde(default)]
    seed: u64,
    #[serde(default)]
    horizon: Option<Spanned<usize>>,
    #[serde(default = "pipelined")]
    algorithm: AlgorithmToml,
    #[serde(default)]
    grid: Option<Spanned<GridToml>>,
    #[serde(default, rename = "intersection")]
    intersections: Vec<Spanned<IntersectionToml>>,
    #[serde(default, rename = "segment")]
    segments: Vec<Spanned<SegmentToml>>,
    #[serde(default, rename = "vehicle")]
    vehicles: Vec<Spanned<NetVehicleToml>>,
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

fn pipelined() -> AlgorithmToml {
    AlgorithmToml::Pipelined
}

/// A validated network scenario.
#[derive(Debug, Clone)]
pub struct NetworkScenario {
    /// Name.
    pub name: String,
    /// Seed.
    pub seed: u64,
    /// Duration, faults, sensing, deadlock window.
    pub header: Header,
    /// The network.
    pub network: Network,
    /// Vehicles at t = 0.
    pub vehicles: Vec<VehicleSpec>,
    /// Arrivals at every entry lane, if an open system.
    pub arrivals: Option<ArrivalsToml>,
}

impl NetworkScenario {
    /// Parses and validates; `path` only names the file in errors.
    pub fn parse(text: &str, path: &Path) -> Result<Self, ScenarioError> {
        let e = Errors::new(text, path);
        let raw: RawNetwork = toml::from_str(text).map_err(|x| e.toml(&x))?;
        let header = RawHeader {
            duration_s: Some(raw.duration_s.clone()),
            horizon: raw.horizon.clone(),
            faults: raw.faults.clone(),
            sensing: raw.sensing.clone(),
            deadlock_s: raw.deadlock_s.clone(),
            invariant: raw.invariant.clone(),
            ..RawHeader::default()
        }
        .validate(&e)?;
        let (juncs, segs) = match &raw.grid {
            Some(g) => {
                if !raw.intersections.is_empty() || !raw.segments.is_empty() {
                    return Err(e.at(
                        Some(g.span()),
                        "[grid] stands for the intersections and segments: give one or the other",
                    ));
                }
                grid(g.get_ref()).map_err(|m| e.at(Some(g.span()), format!("grid: {m}")))?
            }
            None => (
                raw.intersections
                    .iter()
                    .map(|s| (s.get_ref().to_owned(), Some(s.span())))
                    .collect(),
                raw.segments
                    .iter()
                    .map(|s| (s.get_ref().to_owned(), Some(s.span())))
                    .collect(),
            ),
        };
        // What a grid stands for was not written: its problems are the [grid] table's.
        let grid_span = raw.grid.as_ref().map(Spanned::span);
        let (arrivals, fleet) = fleet_of(&raw, &e)?;
        let network = build(&juncs, &segs, (raw.algorithm, grid_span.clone()), fleet, &e)?;
        let junction_span = |j: usize| {
            juncs
                .get(j)
                .and_then(|(_, s)| s.clone())
                .or(grid_span.clone())
        };
        let segment_span = |k: usize| {
            segs.get(k)
                .and_then(|(_, s)| s.clone())
                .or(grid_span.clone())
        };
        check_apart(&network).map_err(|(j, m)| e.at(junction_span(j), m))?;
        check_clear(&network).map_err(|(k, m)| e.at(segment_span(k), m))?;
        check_blocks(&network).map_err(|(k, m)| e.at(segment_span(k), m))?;
        check_ends(&network, fleet).map_err(|(k, m)| e.at(segment_span(k), m))?;
        let mut vehicles = Vec::new();
        for sv in &raw.vehicles {
            let v = sv.get_ref();
            let spec = vehicle(v, &network, &segs)
                .map_err(|m| e.at(Some(sv.span()), format!("vehicle {}: {m}", v.id)))?;
            if vehicles.iter().any(|o: &VehicleSpec| o.id == v.id) {
                return Err(e.at(Some(sv.span()), format!("vehicle {}: duplicate id", v.id)));
            }
            vehicles.push(spec);
        }
        if vehicles.len() > MAX_VEHICLES {
            let span = raw.vehicles.get(MAX_VEHICLES).map(Spanned::span);
            return Err(e.at(span, format!("at most {MAX_VEHICLES} vehicles")));
        }
        check_spacing(&vehicles, &network)
            .map_err(|(i, m)| e.at(raw.vehicles.get(i).map(Spanned::span), m))?;
        if vehicles.is_empty() && arrivals.is_none() {
            return Err(e.at(
                Some(raw.duration_s.span()),
                "a network needs [[vehicle]]s or [arrivals]",
            ));
        }
        Ok(Self {
            name: raw.name,
            seed: raw.seed,
            header,
            network,
            vehicles,
            arrivals,
        })
    }

    /// The world it describes.
    pub fn world(&self) -> WorldSpec {
        let arrivals = match self.arrivals {
            None => Arrivals::None,
            Some(a) => Arrivals::Poisson(Poisson {
                entries: self
                    .network
                    .entries()
                    .into_iter()
                    .flat_map(|seg| {
                        let lanes = self.network.segments.get(seg).map_or(0, |s| s.lanes);
                        (0..lanes).map(move |lane| (Entry::Segment { seg, lane }, a.rate_vph))
                    })
                    .collect(),
                trucks_percent: a.trucks,
            }),
        };
        WorldSpec {
            name: self.name.clone(),
            duration_s: self.header.duration_s,
            seed: self.seed,
            horizon: self.header.horizon,
            deadline_s: self.header.duration_s,
            network: self.network.clone(),
            vehicles: self.vehicles.clone(),
            faults: self.header.faults,
            sensing: self.header.sensing,
            arrivals,
            deadlock_window_s: self.header.deadlock_window_s,
            finish: Finish::Duration,
            clock_start: planner_core::Instant::EPOCH,
            precision: crate::world::precision::Precision::F64,
            invariant: self.header.invariant,
        }
    }
}

type Spans = Option<Range<usize>>;
/// Intersections and segments as written, with where each was written.
type Tables = (Vec<(IntersectionToml, Spans)>, Vec<(SegmentToml, Spans)>);

/// The intersections and segments of a grid: junction (r, c) has id r·cols + c + 1 at
/// (c·block, r·block); segments both ways between neighbours, and an entry and an exit
/// on every outer side.
fn grid(g: &GridToml) -> Result<Tables, String> {
    if !(g.rows >= 1 && g.cols >= 1 && usize::from(g.rows) * usize::from(g.cols) <= MAX_JUNCTIONS) {
        return Err(format!("rows × cols must be 1 to {MAX_JUNCTIONS}"));
    }
    if !(g.block_m > 0.0 && coord_ok(g.block_m * f64::from(g.rows.max(g.cols)))) {
        return Err("block_m must be positive and the grid within range".into());
    }
    let boundary = g.boundary_m.unwrap_or(g.block_m);
    let id = |r: u8, c: u8| u16::from(r) * u16::from(g.cols) + u16::from(c) + 1;
    let mut juncs = Vec::new();
    for r in 0..g.rows {
        for c in 0..g.cols {
            juncs.push((
                IntersectionToml {
                    id: id(r, c),
                    x: f64::from(c) * g.block_m,
                    y: f64::from(r) * g.block_m,
                    lanes: g.lanes,
                    half_size: None,
                    comm_margin: comm(),
                    v_limit: limit(),
                    algorithm: None,
                    turn_inset: g.turn_inset,
                },
                None,
            ));
        }
    }
    let mut segs = Vec::new();
    let mut next = 1000u16;
    let mut seg = |from: Option<u16>, to: Option<u16>, heading: Heading, length: Option<f64>| {
        next += 1;
        (
            SegmentToml {
                id: next,
                from,
                to,
                heading: Some(heading),
                length,
            },
            None,
        )
    };
    for r in 0..g.rows {
        for c in 0..g.cols {
            let j = id(r, c);
            if c + 1 < g.cols {
                segs.push(seg(Some(j), Some(id(r, c + 1)), Heading::East, None));
                segs.push(seg(Some(id(r, c + 1)), Some(j), Heading::West, None));
            }
            if r + 1 < g.rows {
                segs.push(seg(Some(j), Some(id(r + 1, c)), Heading::North, None));
                segs.push(seg(Some(id(r + 1, c)), Some(j), Heading::South, None));
            }
            let b = Some(boundary);
            if c == 0 {
                segs.push(seg(None, Some(j), Heading::East, b));
                segs.push(seg(Some(j), None, Heading::West, b));
            }
            if c + 1 == g.cols {
                segs.push(seg(None, Some(j), Heading::West, b));
                segs.push(seg(Some(j), None, Heading::East, b));
            }
            if r == 0 {
                segs.push(seg(None, Some(j), Heading::North, b));
                segs.push(seg(Some(j), None, Heading::South, b));
            }
            if r + 1 == g.rows {
                segs.push(seg(None, Some(j), Heading::South, b));
                segs.push(seg(Some(j), None, Heading::North, b));
            }
        }
    }
    Ok((juncs, segs))
}

/// `[arrivals]` checked, and the fleet the file's planners expect: its vehicles' bodies
/// (each checked, refused at its table) and a truck's if arrivals bring trucks.
fn fleet_of(
    raw: &RawNetwork,
    e: &Errors<'_>,
) -> Result<(Option<ArrivalsToml>, Fleet), ScenarioError> {
    let arrivals = ArrivalsToml::checked(raw.arrivals.as_ref(), e)?;
    let fleet = super::road::checked_fleet(
        &raw.vehicles,
        |v| (v.id, v.length, v.brake),
        arrivals.as_ref(),
        e,
    )?;
    Ok((arrivals, fleet))
}

/// The shortest `block_m` a `[grid]` of `lanes` lanes at the default communication
/// margin and speed limit takes (what `check_blocks` requires between junctions).
pub fn min_block_m(lanes: u8) -> f64 {
    min_block_m_for(lanes, 0.0, LENGTH_M)
}

/// [`min_block_m`] for a grid whose `turn_inset` is `inset` and whose longest vehicle is
/// `longest` m (an outlet takes it out of A_C).
pub fn min_block_m_for(lanes: u8, inset: f64, longest: f64) -> f64 {
    let a = half_size_for(lanes) + inset;
    let margin = comm();
    2.0 * a
        + (margin + longest.max(LENGTH_M))
        + margin
        + f64::from(lanes.saturating_sub(1)) * change_distance(limit())
}

/// The least A_S half-size for `lanes` lanes: the right turn's radius a − (n − ½) Wl at
/// least ρmin, and never below the SPEC §8 12 m.
fn half_size_for(lanes: u8) -> f64 {
    let p = planner_core::Params::<f64>::table_i();
    ((f64::from(lanes) - 0.5) * LANE_WIDTH_M + p.rho_min())
        .max(12.0)
        .ceil()
}

/// Builds the network of `juncs` and `segs`, or says what is wrong with which.
fn build(
    juncs: &[(IntersectionToml, Spans)],
    segs: &[(SegmentToml, Spans)],
    (default, fallback): (AlgorithmToml, Spans),
    fleet: Fleet,
    e: &Errors<'_>,
) -> Result<Network, ScenarioError> {
    // A grid's generated tables were not written: their problems are the [grid] table's.
    let at = |span: &Spans| span.clone().or(fallback.clone());
    if juncs.len() > MAX_JUNCTIONS {
        let span = juncs.get(MAX_JUNCTIONS).and_then(|(_, s)| at(s));
        return Err(e.at(span, format!("at most {MAX_JUNCTIONS} intersections")));
    }
    let mut net = Network::default();
    // A layout is a function of its table and the fleet alone, and building one (its
    // conflict map, a truck's swept area) dominates loading a network: a grid's
    // identical junctions share the first one's.
    let mut built: Vec<(LayoutToml, usize)> = Vec::new();
    for (j, span) in juncs {
        if net.junctions.iter().any(|o| o.id == j.id) {
            return Err(e.at(at(span), format!("intersection {}: duplicate id", j.id)));
        }
        if !(coord_ok(j.x) && coord_ok(j.y)) {
            return Err(e.at(
                span.clone(),
                format!("intersection {}: x, y within ±{MAX_COORD_M} m", j.id),
            ));
        }
        // The outlet track takes the longest vehicle out of A_C.
        let lt = LayoutToml {
            half_size: j
                .half_size
                .unwrap_or_else(|| half_size_for(j.lanes) + j.turn_inset),
            comm_margin: j.comm_margin,
            inlet_length: j.comm_margin,
            outlet_length: j.comm_margin + fleet.longest_m,
            v_limit: j.v_limit,
            lanes: j.lanes,
            turn_inset: j.turn_inset,
        };
        let same = built.iter().find(|(b, _)| *b == lt).map(|&(_, k)| k);
        let layout = match same.and_then(|k| net.junctions.get(k)) {
            Some(twin) => twin.layout.clone(),
            None => {
                built.push((lt, net.junctions.len()));
                build_layout_for(&lt, fleet)
                    .map_err(|m| e.field(at(span), &format!("intersection {}", j.id), &m))?
            }
        };
        net.junctions.push(Junction {
            id: j.id,
            centre: (j.x, j.y),
            layout,
            algorithm: j.algorithm.unwrap_or(default).algorithm(),
            inlets: [None; 4],
            outlets: [None; 4],
        });
    }
    for (k, (s, span)) in segs.iter().enumerate() {
        let seg = segment(s, &net).map_err(|m| e.at(at(span), format!("segment {}: {m}", s.id)))?;
        if net.segments.iter().any(|o| o.id == s.id) {
            return Err(e.at(at(span), format!("segment {}: duplicate id", s.id)));
        }
        let d = usize::from(seg.heading);
        if let Some(j) = seg.into_junction() {
            let slot = net.junctions.get_mut(j).and_then(|jn| jn.inlets.get_mut(d));
            match slot {
                Some(slot @ None) => *slot = Some(k),
                _ => return Err(e.at(at(span), format!("segment {}: that inlet is taken", s.id))),
            }
        }
        if let Some(j) = seg.from {
            let slot = net
                .junctions
                .get_mut(j)
                .and_then(|jn| jn.outlets.get_mut(d));
            match slot {
                Some(slot @ None) => *slot = Some(k),
                _ => return Err(e.at(at(span), format!("segment {}: that outlet is taken", s.id))),
            }
        }
        net.segments.push(seg);
    }
    Ok(net)
}

/// The index of the intersection with `id`.
fn junction_index(net: &Network, id: u16) -> Result<usize, String> {
    net.junctions
        .iter()
        .position(|j| j.id == id)
        .ok_or_else(|| format!("no intersection {id}"))
}

/// One segment, placed: between two intersections (aligned along an axis) its heading and
/// length follow from them; with an open end both must be given.
fn segment(s: &SegmentToml, net: &Network) -> Result<Segment, String> {
    let from = s.from.map(|id| junction_index(net, id)).transpose()?;
    let to = s.to.map(|id| junction_index(net, id)).transpose()?;
    let jn = |i: Option<usize>| i.and_then(|i| net.junctions.get(i));
    let (a, b) = (jn(from), jn(to));
    let (heading, length) = match (a, b) {
        (Some(a), Some(b)) => {
            let (dx, dy) = (b.centre.0 - a.centre.0, b.centre.1 - a.centre.1);
            let heading = match (dx.abs() < 1e-9, dy.abs() < 1e-9) {
                (false, true) if dx > 0.0 => 0,
                (true, false) if dy > 0.0 => 1,
                (false, true) => 2,
                (true, false) => 3,
                _ => return Err("its intersections must lie on a line along x or y".into()),
            };
            let length = dx.abs().max(dy.abs()) - a.layout.spec.half_size - b.layout.spec.half_size;
            if let Some(h) = s.heading.map(Heading::index).filter(|&h| h != heading) {
                return Err(format!(
                    "heading {h} disagrees with its intersections' positions"
                ));
            }
            (heading, length)
        }
        (None, None) => return Err("needs an intersection at one end at least".into()),
        _ => {
            let heading = s.heading.ok_or("an open end needs `heading`")?.index();
            let length = s.length.ok_or("an open end needs `length`")?;
            (heading, length)
        }
    };
    if !(length > 0.0 && coord_ok(length)) {
        return Err(format!(
            "length must be positive and within range, got {length:.1} m"
        ));
    }
    let lanes = a.or(b).map_or(2, |j| j.layout.spec.lanes);
    if a.is_some_and(|j| j.layout.spec.lanes != lanes)
        || b.is_some_and(|j| j.layout.spec.lanes != lanes)
    {
        return Err("its intersections must have as many lanes per approach".into());
    }
    let n_wl = f64::from(lanes) * LANE_WIDTH_M;
    let origin = match (a, b) {
        (_, Some(b)) => {
            let (ox, oy) = rotate((-b.layout.spec.half_size - length, -n_wl), heading);
            (b.centre.0 + ox, b.centre.1 + oy)
        }
        (Some(a), None) => {
            let (ox, oy) = rotate((a.layout.spec.half_size, -n_wl), heading);
            (a.centre.0 + ox, a.centre.1 + oy)
        }
        (None, None) => (0.0, 0.0),
    };
    // The slower of its two junctions': a vehicle reaches the next junction's A_C at no
    // more than its vImax (Spaciousness (27) assumes it), and the block's lane changes are
    // planned at the speed it drives (a segment that kept a fast junction's limit into a
    // slow one's A_C had vehicles enter it at 27.8 m/s under a limit of 1).
    let v_max = [a, b]
        .iter()
        .flatten()
        .map(|j| j.layout.spec.v_limit)
        .fold(f64::INFINITY, f64::min)
        .min(Limits::table_i().v_max);
    Ok(Segment {
        id: s.id,
        lanes,
        heading,
        origin,
        end: match to {
            Some(j) => End::Junction(j, length),
            None => End::Exit(length),
        },
        from,
        v_max,
    })
}

/// An axis-aligned rectangle [x0, x1] × [y0, y1] (m).
type Rect = (f64, f64, f64, f64);

/// `true` if the rectangles share interior (touching edges do not count).
fn overlap(a: Rect, b: Rect) -> bool {
    const EPS: f64 = 1e-6;
    a.0 < b.1 - EPS && b.0 < a.1 - EPS && a.2 < b.3 - EPS && b.2 < a.3 - EPS
}

/// Junction `j`'s communication region A_C in the world.
fn comm_region(j: &Junction) -> Rect {
    let r = j.layout.spec.half_size + j.layout.spec.comm_margin;
    (
        j.centre.0 - r,
        j.centre.0 + r,
        j.centre.1 - r,
        j.centre.1 + r,
    )
}

/// The world rectangle of segment `s`'s lanes from x = `from` to x = `to` in its frame.
fn segment_rect(s: &Segment, from: f64, to: f64) -> Rect {
    let w = f64::from(s.lanes) * LANE_WIDTH_M;
    let corners = [(from, 0.0), (to, 0.0), (from, w), (to, w)].map(|(x, y)| {
        let (dx, dy) = rotate((x, y), s.heading);
        (s.origin.0 + dx, s.origin.1 + dy)
    });
    let xs = corners.map(|c| c.0);
    let ys = corners.map(|c| c.1);
    let lo = |v: [f64; 4]| v.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = |v: [f64; 4]| v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    (lo(xs), hi(xs), lo(ys), hi(ys))
}

/// No two intersections' communication regions overlap: a vehicle is in at most one
/// junction's A_C, under at most one manager (two intersections at the same place were
/// accepted before, each manager granting into the other's A_S: 39 collisions). Returns
/// the second junction's index and why.
fn check_apart(net: &Network) -> Result<(), (usize, String)> {
    for (b, jb) in net.junctions.iter().enumerate() {
        for ja in net.junctions.iter().take(b) {
            if overlap(comm_region(ja), comm_region(jb)) {
                let need = comm_region(ja).1 - ja.centre.0 + comm_region(jb).1 - jb.centre.0;
                return Err((
                    b,
                    format!(
                        "intersection {}: its communication region overlaps that of intersection {}; their centres must be at least {need:.1} m apart along x or y",
                        jb.id, ja.id
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// Every segment lies within the coordinate range, crosses no other segment, and passes
/// through no intersection's communication region but those of its own two ends (where
/// its first and last stretches are their outlet and inlet tracks). Returns the segment's
/// index and why.
fn check_clear(net: &Network) -> Result<(), (usize, String)> {
    let rects: Vec<Rect> = net
        .segments
        .iter()
        .map(|s| segment_rect(s, 0.0, s.end.x().unwrap_or(0.0)))
        .collect();
    for (k, (s, r)) in net.segments.iter().zip(&rects).enumerate() {
        if ![r.0, r.1, r.2, r.3].iter().all(|&c| coord_ok(c)) {
            return Err((
                k,
                format!("segment {}: reaches beyond ±{MAX_COORD_M} m", s.id),
            ));
        }
        let own = |j: usize| s.from == Some(j) || s.into_junction() == Some(j);
        for (j, jn) in net.junctions.iter().enumerate() {
            if !own(j) && overlap(*r, comm_region(jn)) {
                return Err((
                    k,
                    format!(
                        "segment {}: passes through the communication region of intersection {}",
                        s.id, jn.id
                    ),
                ));
            }
        }
        for (o, ro) in net.segments.iter().zip(&rects).take(k) {
            // Segments meeting at a junction do so inside its A_C; elsewhere a road that
            // crosses another is an intersection no manager coordinates.
            let at_junction = net.junctions.iter().any(|jn| {
                let c = comm_region(jn);
                let inside = |r: &Rect| r.0 >= c.0 && r.1 <= c.1 && r.2 >= c.2 && r.3 <= c.3;
                let shared = (r.0.max(ro.0), r.1.min(ro.1), r.2.max(ro.2), r.3.min(ro.3));
                inside(&shared)
            });
            if overlap(*r, *ro) && !at_junction {
                return Err((
                    k,
                    format!(
                        "segment {}: crosses segment {} outside any intersection",
                        s.id, o.id
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// Per segment leaving an intersection and feeding another: the lane changes a route
/// through it may need (from the outlet lane a movement arrives in, to a lane serving the
/// next movement) must fit between the end of the outlet track and the edge of the next
/// A_C, at the commitment distance (23) per change at the segment's speed limit
/// (SPEC §10). Returns the offending segment's index and why.
fn check_blocks(net: &Network) -> Result<(), (usize, String)> {
    for (k, s) in net.segments.iter().enumerate() {
        let (Some(a), Some(j)) = (s.from, s.into_junction()) else {
            continue;
        };
        let (Some(ja), Some(jb)) = (net.junctions.get(a), net.junctions.get(j)) else {
            continue;
        };
        let length = s.end.x().unwrap_or(0.0);
        let room = length - ja.layout.spec.outlet_length - jb.layout.spec.comm_margin;
        let worst = u8::from(s.lanes > 1) * s.lanes.saturating_sub(1);
        let need = f64::from(worst) * change_distance(s.v_max);
        if !(room >= need) {
            return Err((
                k,
                format!(
                    "segment {}: {room:.1} m between the outlet of intersection {} and the \
                     communication region of intersection {} cannot hold the {worst} lane \
                     change(s) a route may need there ({need:.1} m at the commitment distance \
                     (23) of {:.1} m each); lengthen the block",
                    s.id,
                    ja.id,
                    jb.id,
                    change_distance(s.v_max)
                ),
            ));
        }
    }
    Ok(())
}

/// Every road into and out of the network long enough for what happens on it, and a way
/// out from every way in. Returns the offending segment's index and why.
///
/// - An entry carries the junction's inlet track (its last `comm_margin` metres, inside
///   A_C) and, before it, where arrivals appear (a vehicle length and d0) and change lanes
///   toward their first movement (up to lanes − 1 changes at the commitment distance (23)
///   each, as between junctions). A shorter one put arrivals inside A_C at full speed (a
///   red team's `boundary_m = 1`: 26 colliding pairs).
/// - An exit carries the junction's outlet track (its first `comm_margin + L` metres): a
///   vehicle is off the junction only once it is on its outlet outside A_C, so the road
///   must reach a vehicle length beyond that (a shorter one ended the run with a bus error).
/// - Every entry leads to an exit: arrivals draw their destinations among the exits they
///   can reach, and one that can reach none would wait forever.
fn check_ends(net: &Network, fleet: Fleet) -> Result<(), (usize, String)> {
    let longest = fleet.longest_m;
    let lim = Limits::table_i();
    let exits = net.exits();
    for (k, s) in net.segments.iter().enumerate() {
        let length = s.end.x().unwrap_or(f64::INFINITY);
        if let (None, Some(j)) = (s.from, s.into_junction()) {
            let jn = net.junctions.get(j).map(|j| &j.layout.spec);
            let margin = jn.map_or(0.0, |l| l.comm_margin);
            let changes = s.lanes.saturating_sub(1);
            let need = margin + longest + lim.d0 + f64::from(changes) * change_distance(s.v_max);
            if !(length >= need) {
                return Err((
                    k,
                    format!(
                        "segment {}: an entry of {length:.1} m cannot hold the inlet track \
                         ({margin:.1} m), where arrivals appear ({:.1} m) and the {changes} lane \
                         change(s) they may need ({:.1} m at the commitment distance (23)); it \
                         needs {need:.1} m",
                        s.id,
                        longest + lim.d0,
                        f64::from(changes) * change_distance(s.v_max)
                    ),
                ));
            }
            if !exits.iter().any(|&x| net.path(k, x).is_some()) {
                return Err((
                    k,
                    format!("segment {}: no exit can be reached from this entry", s.id),
                ));
            }
        }
        if let (Some(a), End::Exit(_)) = (s.from, s.end) {
            let outlet = net
                .junctions
                .get(a)
                .map_or(0.0, |j| j.layout.spec.outlet_length);
            if !(length >= outlet + longest) {
                return Err((
                    k,
                    format!(
                        "segment {}: an exit of {length:.1} m must reach a vehicle length \
                         beyond the outlet track ({outlet:.1} m): at least {:.1} m",
                        s.id,
                        outlet + longest
                    ),
                ));
            }
        }
    }
    Ok(())
}

/// dS(v) + dC(v) of (23)(24) for one lane change at `v` on an open road.
pub fn change_distance(v: f64) -> f64 {
    use crate::scenario::road::{Road, RoadVehicle};
    let spec = RoadVehicle {
        id: 1,
        x: 0.0,
        lane: 0,
        v,
        target_lane: Some(1),
        driver: crate::scenario::DriverKind::Planner,
        script: Vec::new(),
        cooperative: None,
        length: None,
        brake: None,
        goal_x: None,
        v_ref: None,
    };
    let road = Road {
        lanes: 2,
        end_x: None,
    };
    super::road::commitment_bound(&[spec], &road, 0, v).unwrap_or(f64::INFINITY)
}

/// A vehicle of the file: on its segment's lane-change stretch, with its movements.
fn vehicle(
    v: &NetVehicleToml,
    net: &Network,
    segs: &[(SegmentToml, Spans)],
) -> Result<VehicleSpec, String> {
    let seg = segs
        .iter()
        .position(|(s, _)| s.id == v.segment)
        .ok_or_else(|| format!("no segment {}", v.segment))?;
    let sg = net.segments.get(seg).ok_or("no such segment")?;
    if v.lane >= sg.lanes {
        return Err(format!(
            "lane {} does not exist (segment has {})",
            v.lane, sg.lanes
        ));
    }
    if !(v.v >= 0.0 && v.v <= sg.v_max) {
        return Err(format!("v must be in [0, {}]", sg.v_max));
    }
    if !crate::bus::is_vehicle_id(v.id) {
        return Err("ids are 1 to 65,279 (above are the junction managers' bus nodes)".into());
    }
    let movements: Vec<Movement> = match (&v.route, v.destination) {
        (Some(r), None) => r.iter().map(|m| m.movement()).collect(),
        (None, Some(d)) => {
            let to = segs
                .iter()
                .position(|(s, _)| s.id == d)
                .ok_or_else(|| format!("no segment {d}"))?;
            net.path(seg, to)
                .ok_or_else(|| format!("no way to segment {d}"))?
        }
        (None, None) => Vec::new(),
        (Some(_), Some(_)) => return Err("give `route` or `destination`, not both".into()),
    };
    check_route(net, seg, &movements)?;
    let start = sg
        .from
        .and_then(|a| net.junctions.get(a))
        .map_or(0.0, |a| a.layout.spec.outlet_length);
    let end = sg.end.x().unwrap_or(f64::INFINITY)
        - sg.into_junction()
            .and_then(|j| net.junctions.get(j))
            .map_or(0.0, |j| j.layout.spec.comm_margin);
    let lim = Limits::table_i();
    let body = super::road::body_of(v.length, v.brake);
    let half = 0.5 * body.length;
    if !(v.x - half >= start && v.x + half + lim.d0 < end && coord_ok(v.x)) {
        return Err(format!(
            "x must be between the end of the outlet track ({start:.1} m) and the edge of the \
             next communication region ({end:.1} m)"
        ));
    }
    let mut spec = VehicleSpec {
        id: v.id,
        at: At::Lane {
            seg,
            x: v.x,
            y: (f64::from(v.lane) + 0.5) * LANE_WIDTH_M,
            theta: 0.0,
            lane: v.lane,
            alpha: None,
            beta: None,
        },
        v: v.v,
        driver: crate::scenario::DriverKind::Planner,
        script: Vec::new(),
        cooperative: true,
        body,
        trip: Trip {
            target_lane: v.lane,
            goal_x: None,
            v_ref: None,
            movements,
        },
    };
    let next = spec.trip.movements.first().copied();
    spec.trip.target_lane = sg.nearest_serving(net, v.lane, next);
    let changes = spec.trip.target_lane.abs_diff(v.lane);
    let room = end - v.x;
    let need = f64::from(changes) * change_distance(sg.v_max);
    if !(room >= need) {
        return Err(format!(
            "needs {changes} lane change(s) but starts {room:.1} m before the communication \
             region; the commitment distance (23) is {need:.1} m"
        ));
    }
    if !(end - v.x - half - lim.d0 > lim.safe_distance_at(v.v, body.brake) + START_MARGIN_M) {
        return Err("cannot stop before the communication region".into());
    }
    Ok(spec)
}

/// Every movement of `route` from segment `seg` leads somewhere, and the last one out.
fn check_route(net: &Network, seg: usize, route: &[Movement]) -> Result<(), String> {
    let mut k = seg;
    for (i, &m) in route.iter().enumerate() {
        k = net
            .after(k, m)
            .ok_or_else(|| format!("movement {} ({m:?}) leads nowhere", i + 1))?;
    }
    match net.segments.get(k).map(|s| s.end) {
        Some(End::Exit(_)) | None => Ok(()),
        Some(_) => Err("the route must end on an exit segment".into()),
    }
}

/// Per lane of each segment: no overlap, and the invariant for every follower. Returns
/// the offending vehicle's index and why.
fn check_spacing(vehicles: &[VehicleSpec], _net: &Network) -> Result<(), (usize, String)> {
    let lim = Limits::table_i();
    for (i, a) in vehicles.iter().enumerate() {
        let At::Lane { seg, x, lane, .. } = a.at else {
            continue;
        };
        for b in vehicles {
            let At::Lane {
                seg: s2,
                x: x2,
                lane: l2,
                ..
            } = b.at
            else {
                continue;
            };
            if a.id != b.id && seg == s2 && lane == l2 && x <= x2 {
                let gap = x2 - x - 0.5 * (a.body.length + b.body.length);
                if !(gap - lim.d0 > lim.safe_distance_at(a.v, a.body.brake) + START_MARGIN_M) {
                    return Err((
                        i,
                        format!(
                            "vehicle {} violates the safety invariant behind vehicle {} \
                             (bumper gap {gap:.2} m)",
                            a.id, b.id
                        ),
                    ));
                }
            }
        }
    }
    Ok(())
}

/// The network format's tables and their keys (see [`super::keys`]).
pub fn keys() -> Vec<(&'static str, &'static [&'static str])> {
    use super::keys::fields;
    vec![
        ("network file", fields::<RawNetwork>()),
        ("[grid]", fields::<GridToml>()),
        ("[[intersection]]", fields::<IntersectionToml>()),
        ("[[segment]]", fields::<SegmentToml>()),
        ("[[vehicle]] in a network", fields::<NetVehicleToml>()),
        ("[arrivals]", fields::<ArrivalsToml>()),
    ]
}
