//! A world as SUMO plain XML (`host-sim export sumo`): nodes, edges, connections and
//! routes that SUMO's `netconvert` turns into the same network, so that SUMO's junction
//! controls and drivers run on the layout and demand our planners run on.
//!
//! How the network maps (SPEC §10, [`crate::world::network`]):
//! - a junction is one node at its centre whose shape is A_S (the ±half-size square), so
//!   netconvert cuts every edge at the stop line, as our inlets end; its control is the
//!   export's [`Control`];
//! - a segment is one edge from its start (a junction, or a boundary node on the road's
//!   centre line) to its end (a junction, its exit or dead end, or 1 km past its last
//!   vehicle when it is open); opposite directions share their nodes and netconvert lays
//!   each to the right of the line between them, as right-hand traffic drives;
//! - a junction's own inlet and outlet tracks (where no segment feeds or continues it)
//!   are stub edges of `inlet_length` and `outlet_length`;
//! - lanes are counted from the right in SUMO and on our segments (junction lane l of n is
//!   SUMO lane n − 1 − l), and every route of a junction's layout is one connection, so a
//!   lane serves exactly the movements it serves here ([`lane_movements`]);
//! - vehicles at t = 0 depart at their position (front bumper) and speed, in their lane,
//!   on the route their movements make; arrivals are Poisson flows (`period="exp(λ)"`),
//!   one per route an arrival may draw, each at its share of the entry's rate.
//!
//! Every vehicle has the plant's figures (4.5 m, 3.8 m/s² up, 7.9 m/s² down, d0 as the
//! minimum gap, no speed deviation); the drivers' model is left to the scenario that runs
//! it (`bench/sumo/`). What SUMO cannot hold is said, not approximated silently: a
//! vehicle already inside A_S at t = 0 departs at its inlet's end.

use crate::world::at::At;
use crate::world::network::{turned, Junction, Network, Segment};
use crate::world::{Arrivals, Body, VehicleSpec, WorldSpec, LANE_WIDTH_M};
use planner_core::intersection::{lane_movements, Movement};
use std::fmt::Write as _;

/// How SUMO controls each junction (netconvert's node type).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Control {
    /// A traffic light whose phases extend while vehicles keep arriving (`tlType`
    /// actuated).
    Actuated,
    /// A fixed-time traffic light (`tlType` static).
    Static,
    /// All-way stop.
    AllwayStop,
    /// Right of way by road priority (no signal, no stop).
    Priority,
}

impl Control {
    /// The node attributes for this control.
    fn node_attributes(self) -> &'static str {
        match self {
            Self::Actuated => r#"type="traffic_light" tlType="actuated""#,
            Self::Static => r#"type="traffic_light" tlType="static""#,
            Self::AllwayStop => r#"type="allway_stop""#,
            Self::Priority => r#"type="priority""#,
        }
    }
}

/// The plain-XML files of one world, by extension.
#[derive(Debug, Clone, PartialEq)]
pub struct SumoFiles {
    /// `NAME.nod.xml`.
    pub nodes: String,
    /// `NAME.edg.xml`.
    pub edges: String,
    /// `NAME.con.xml`.
    pub connections: String,
    /// `NAME.rou.xml`.
    pub routes: String,
    /// `NAME.netccfg`: `netconvert -c NAME.netccfg` writes `NAME.net.xml`.
    pub netconvert_config: String,
    /// `NAME.sumocfg`: `sumo -c NAME.sumocfg` (or `sumo-gui`) runs it.
    pub sumo_config: String,
    /// What the export could not carry exactly (one line each).
    pub notes: Vec<String>,
}

impl SumoFiles {
    /// Every file as (file name, text), named after `name`.
    pub fn named(&self, name: &str) -> Vec<(String, &str)> {
        vec![
            (format!("{name}.nod.xml"), self.nodes.as_str()),
            (format!("{name}.edg.xml"), self.edges.as_str()),
            (format!("{name}.con.xml"), self.connections.as_str()),
            (format!("{name}.rou.xml"), self.routes.as_str()),
            (format!("{name}.netccfg"), self.netconvert_config.as_str()),
            (format!("{name}.sumocfg"), self.sumo_config.as_str()),
        ]
    }
}

/// Unit vector of heading `h` (0 east, 1 north, 2 west, 3 south).
fn unit(h: u8) -> (f64, f64) {
    crate::world::network::rotate((1.0, 0.0), h)
}

/// The edge a junction's own inlet (`inlet`) or outlet track of heading `h` is.
fn stub_edge(jn: &Junction, inlet: bool, h: u8) -> String {
    let side = if inlet { "in" } else { "out" };
    format!("J{}_{side}{h}", jn.id)
}

/// The edge vehicles of heading `h` take into junction `jn`.
fn inlet_edge(net: &Network, jn: &Junction, h: u8) -> String {
    match jn.inlets[usize::from(h % 4)].and_then(|k| net.segments.get(k)) {
        Some(sg) => format!("s{}", sg.id),
        None => stub_edge(jn, true, h),
    }
}

/// The edge vehicles leaving junction `jn` with heading `h` take.
fn outlet_edge(net: &Network, jn: &Junction, h: u8) -> String {
    match jn.outlets[usize::from(h % 4)].and_then(|k| net.segments.get(k)) {
        Some(sg) => format!("s{}", sg.id),
        None => stub_edge(jn, false, h),
    }
}

/// A point of segment `sg` on the line between its direction and the opposite one (its
/// left edge), `x` along it.
fn centre_line(sg: &Segment, x: f64) -> (f64, f64) {
    let (dx, dy) =
        crate::world::network::rotate((x, f64::from(sg.lanes) * LANE_WIDTH_M), sg.heading);
    (sg.origin.0 + dx, sg.origin.1 + dy)
}

/// Where an open segment ends in SUMO: 1 km past the farthest vehicle on it, or 1 km.
fn open_end(spec: &WorldSpec, k: usize) -> f64 {
    let far = spec
        .vehicles
        .iter()
        .filter_map(|v| match v.at {
            At::Lane { seg, x, .. } if seg == k => Some(x),
            _ => None,
        })
        .fold(0.0, f64::max);
    far + 1_000.0
}

/// Converts `spec`'s network and vehicles, every junction under `control`.
pub fn export(spec: &WorldSpec, control: Control) -> SumoFiles {
    let net = &spec.network;
    let mut notes = Vec::new();
    let (nodes, edges) = nodes_and_edges(spec, control);
    let connections = connections(net);
    let routes = routes(spec, &mut notes);
    let name = xml_attr(&spec.name);
    SumoFiles {
        nodes,
        edges,
        connections,
        routes,
        netconvert_config: format!(
            "<configuration>\n    <input>\n        <node-files value=\"{name}.nod.xml\"/>\n        \
             <edge-files value=\"{name}.edg.xml\"/>\n        <connection-files value=\"{name}.con.xml\"/>\n    \
             </input>\n    <output>\n        <output-file value=\"{name}.net.xml\"/>\n    </output>\n    \
             <processing>\n        <no-turnarounds value=\"true\"/>\n    </processing>\n</configuration>\n"
        ),
        sumo_config: format!(
            "<configuration>\n    <input>\n        <net-file value=\"{name}.net.xml\"/>\n        \
             <route-files value=\"{name}.rou.xml\"/>\n    </input>\n    <time>\n        \
             <begin value=\"0\"/>\n        <end value=\"{}\"/>\n        <step-length value=\"0.01\"/>\n    \
             </time>\n</configuration>\n",
            spec.duration_s
        ),
        notes,
    }
}

/// `s` with XML's five special characters escaped, for an attribute value.
fn xml_attr(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
        .replace('\'', "&apos;")
}

/// The node and edge files.
fn nodes_and_edges(spec: &WorldSpec, control: Control) -> (String, String) {
    let net = &spec.network;
    let mut nodes = String::from("<nodes>\n");
    let mut edges = String::from("<edges>\n");
    let mut node = |id: &str, (x, y): (f64, f64), extra: &str| {
        let _ = writeln!(
            nodes,
            r#"    <node id="{id}" x="{x:.3}" y="{y:.3}"{extra}/>"#
        );
    };
    for jn in &net.junctions {
        let (cx, cy) = jn.centre;
        let a = jn.layout.spec.half_size;
        let shape = format!(
            "{:.3},{:.3} {:.3},{:.3} {:.3},{:.3} {:.3},{:.3}",
            cx - a,
            cy - a,
            cx + a,
            cy - a,
            cx + a,
            cy + a,
            cx - a,
            cy + a
        );
        let attrs = format!(r#" {} shape="{shape}""#, control.node_attributes());
        node(&format!("J{}", jn.id), jn.centre, &attrs);
        let spec = &jn.layout.spec;
        for h in 0..4u8 {
            let (ux, uy) = unit(h);
            if jn.inlets[usize::from(h)].is_none() {
                let d = a + spec.inlet_length;
                node(
                    &format!("{}_a", stub_edge(jn, true, h)),
                    (cx - ux * d, cy - uy * d),
                    "",
                );
            }
            if jn.outlets[usize::from(h)].is_none() {
                let d = a + spec.outlet_length;
                node(
                    &format!("{}_b", stub_edge(jn, false, h)),
                    (cx + ux * d, cy + uy * d),
                    "",
                );
            }
        }
    }
    for (k, sg) in net.segments.iter().enumerate() {
        if sg.from.is_none() {
            node(&format!("s{}_a", sg.id), centre_line(sg, 0.0), "");
        }
        if sg.into_junction().is_none() {
            let x = sg.end.x().unwrap_or_else(|| open_end(spec, k));
            node(&format!("s{}_b", sg.id), centre_line(sg, x), "");
        }
    }
    nodes.push_str("</nodes>\n");
    let mut edge = |id: &str, (from, to): (String, String), lanes: u8, speed: f64| {
        let _ = writeln!(
            edges,
            r#"    <edge id="{id}" from="{from}" to="{to}" numLanes="{lanes}" speed="{speed:.3}" priority="1" spreadType="right"/>"#
        );
    };
    let junction_node = |j: usize| net.junctions.get(j).map(|jn| format!("J{}", jn.id));
    for sg in &net.segments {
        let id = format!("s{}", sg.id);
        let from = sg.from.and_then(junction_node).unwrap_or(format!("{id}_a"));
        let to = sg
            .into_junction()
            .and_then(junction_node)
            .unwrap_or(format!("{id}_b"));
        edge(&id, (from, to), sg.lanes, sg.v_max);
    }
    for jn in &net.junctions {
        let (n, v) = (jn.layout.spec.lanes, jn.layout.spec.v_limit);
        let j = format!("J{}", jn.id);
        for h in 0..4u8 {
            if jn.inlets[usize::from(h)].is_none() {
                let id = stub_edge(jn, true, h);
                edge(&id, (format!("{id}_a"), j.clone()), n, v);
            }
            if jn.outlets[usize::from(h)].is_none() {
                let id = stub_edge(jn, false, h);
                edge(&id, (j.clone(), format!("{id}_b")), n, v);
            }
        }
    }
    edges.push_str("</edges>\n");
    (nodes, edges)
}

/// Every route of every junction's layout as one lane-to-lane connection.
fn connections(net: &Network) -> String {
    let mut out = String::from("<connections>\n");
    for jn in &net.junctions {
        let n = jn.layout.spec.lanes;
        for h in 0..4u8 {
            for l in 0..n {
                for &m in lane_movements(l, n) {
                    let Some(route) = jn
                        .layout
                        .route_index(h, l, m)
                        .and_then(|r| jn.layout.routes.get(r))
                    else {
                        continue;
                    };
                    let _ = writeln!(
                        out,
                        r#"    <connection from="{}" to="{}" fromLane="{}" toLane="{}"/>"#,
                        inlet_edge(net, jn, h),
                        outlet_edge(net, jn, route.outlet.heading),
                        n - 1 - l,
                        n - 1 - route.outlet.lane,
                    );
                }
            }
        }
    }
    out.push_str("</connections>\n");
    out
}

/// The edges from segment `seg` on through `movements`, one per junction, until they
/// leave the network or run out.
fn edges_from(net: &Network, mut seg: usize, movements: &[Movement]) -> Vec<String> {
    let mut out = Vec::new();
    let Some(first) = net.segments.get(seg) else {
        return out;
    };
    out.push(format!("s{}", first.id));
    for &m in movements {
        let Some(sg) = net.segments.get(seg) else {
            break;
        };
        let Some(jn) = sg.into_junction().and_then(|j| net.junctions.get(j)) else {
            break;
        };
        out.push(outlet_edge(net, jn, turned(sg.heading, m)));
        match net.after(seg, m) {
            Some(next) => seg = next,
            None => break,
        }
    }
    out
}

/// The edges from junction `j`'s inlet of heading `h` through `movements` (the first at
/// `j`).
fn edges_through(net: &Network, j: usize, h: u8, movements: &[Movement]) -> Vec<String> {
    let Some(jn) = net.junctions.get(j) else {
        return Vec::new();
    };
    let Some(&m) = movements.first() else {
        return vec![inlet_edge(net, jn, h)];
    };
    let out_h = turned(h, m);
    let mut out = vec![inlet_edge(net, jn, h)];
    match jn.outlets[usize::from(out_h)] {
        Some(next) => out.extend(edges_from(net, next, &movements[1..])),
        None => out.push(stub_edge(jn, false, out_h)),
    }
    out
}

/// The SUMO vehicle type of `body`: `car` (Table I's), `truck`, or one named by its
/// length and limit.
fn type_of(body: Body) -> String {
    if body == Body::CAR {
        "car".into()
    } else if body == Body::TRUCK {
        "truck".into()
    } else {
        format!("body_{}_{}", body.length, body.brake)
    }
}

/// The routes file: the vehicle types, the vehicles at t = 0, the arrivals as flows.
fn routes(spec: &WorldSpec, notes: &mut Vec<String>) -> String {
    let lim = crate::monitor::Limits::table_i();
    let mut out = String::from("<routes>\n");
    // Table I's car (arrivals' cars), the truck if arrivals bring trucks, then every other
    // body a vehicle has, each once.
    let mut bodies = vec![Body::CAR];
    for b in crate::world::arriving_truck(spec.trucks_percent())
        .into_iter()
        .chain(spec.vehicles.iter().map(|v| v.body))
    {
        if !bodies.contains(&b) {
            bodies.push(b);
        }
    }
    for b in bodies {
        let _ = writeln!(
            out,
            r#"    <vType id="{}" length="{}" width="{}" accel="{}" decel="{}" emergencyDecel="{}" maxSpeed="{}" minGap="{}" speedDev="0"/>"#,
            type_of(b),
            b.length,
            crate::world::WIDTH_M,
            lim.a_max,
            b.brake,
            b.brake,
            lim.v_max,
            lim.d0,
        );
    }
    let mut departures: Vec<(&VehicleSpec, Vec<String>, u8, f64)> = spec
        .vehicles
        .iter()
        .filter_map(|v| departure(&spec.network, v, notes).map(|(e, l, p)| (v, e, l, p)))
        .collect();
    departures.sort_by_key(|d| d.0.id);
    for (v, edges, lane, pos) in departures {
        let _ = writeln!(
            out,
            r#"    <vehicle id="v{}" type="{}" depart="0" departLane="{lane}" departPos="{pos:.3}" departSpeed="{:.3}"><route edges="{}"/></vehicle>"#,
            v.id,
            type_of(v.body),
            v.v,
            edges.join(" ")
        );
    }
    if let Arrivals::Poisson(p) = &spec.arrivals {
        flows(&spec.network, p, spec.duration_s, &mut out);
    }
    if spec.arrivals == Arrivals::Closed {
        notes.push(
            "a closed system (vehicles that leave come back) has no SUMO form: its vehicles leave"
                .into(),
        );
    }
    out.push_str("</routes>\n");
    out
}

/// A vehicle's route edges, SUMO lane and front position on its first edge, or `None`
/// (with a note) if it has no route in SUMO.
fn departure(
    net: &Network,
    v: &VehicleSpec,
    notes: &mut Vec<String>,
) -> Option<(Vec<String>, u8, f64)> {
    match v.at {
        At::Lane { seg, x, lane, .. } => {
            let edges = edges_from(net, seg, &v.trip.movements);
            let l = v.body.length;
            Some((edges, lane, (x + 0.5 * l).max(l)))
        }
        At::Crossing { junction, route, s } => {
            let jn = net.junctions.get(junction)?;
            let r = jn.layout.routes.get(usize::from(route))?;
            let (h, n) = (r.inlet.heading, jn.layout.spec.lanes);
            let inlet = jn.layout.spec.inlet_length;
            let l = v.body.length;
            let mut front = s + 0.5 * l;
            if front > inlet {
                notes.push(format!(
                    "vehicle {} is inside A_S at t = 0: it departs at its inlet's end",
                    v.id
                ));
                front = inlet;
            }
            // On a segment, the inlet track is its last `inlet_length` metres.
            let offset = jn.inlets[usize::from(h)]
                .and_then(|k| net.segments.get(k))
                .and_then(|sg| sg.end.x())
                .map_or(0.0, |end| end - inlet);
            let mut movements = v.trip.movements.clone();
            if movements.is_empty() {
                movements.push(r.movement);
            }
            let edges = edges_through(net, junction, h, &movements);
            Some((edges, n - 1 - r.inlet.lane, (offset + front).max(l)))
        }
    }
}

/// One Poisson flow per route an arrival at each entry may draw (the entry's rate split
/// evenly, as host-sim draws it: a movement its lane serves at a junction's own inlet, a
/// shortest path to one of the exits it leads to on a boundary segment).
fn flows(net: &Network, p: &crate::world::Poisson, duration_s: f64, out: &mut String) {
    use crate::world::spawn::{trip_choices, Entry};
    // Trucks as a flow of their own beside the cars', each a thinned Poisson process
    // (a share of a Poisson process is one).
    let truck = f64::from(p.trucks_percent) / 100.0;
    let kinds = [(Body::CAR, 1.0 - truck), (Body::TRUCK, truck)];
    for (k, (entry, rate_vph)) in p.entries.iter().enumerate() {
        let trips = trip_choices(net, entry);
        let (routes, lane): (Vec<Vec<String>>, u8) = match *entry {
            Entry::Stub {
                junction,
                heading,
                lane,
            } => {
                let Some(jn) = net.junctions.get(junction) else {
                    continue;
                };
                let rs = trips
                    .iter()
                    .map(|(ms, _)| edges_through(net, junction, heading, ms))
                    .collect();
                (rs, jn.layout.spec.lanes - 1 - lane)
            }
            Entry::Segment { seg, lane } => {
                let rs = trips
                    .iter()
                    .map(|(ms, _)| edges_from(net, seg, ms))
                    .collect();
                (rs, lane)
            }
        };
        for (body, part) in kinds.into_iter().filter(|&(_, part)| part > 0.0) {
            let share = part * rate_vph / 3600.0 / routes.len().max(1) as f64;
            let (kind, suffix) = (type_of(body), if body == Body::CAR { "" } else { "t" });
            for (i, edges) in routes.iter().enumerate() {
                let _ = writeln!(
                    out,
                    r#"    <flow id="f{k}_{i}{suffix}" type="{kind}" begin="0" end="{duration_s}" period="exp({share:.6})" departLane="{lane}" departSpeed="max" departPos="base"><route edges="{}"/></flow>"#,
                    edges.join(" ")
                );
            }
        }
    }
}
