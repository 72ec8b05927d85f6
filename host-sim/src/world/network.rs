//! The road network: segments (straight multi-lane roads, each with its own frame) and
//! junctions (planner-core intersection layouts placed in the world), and how a position
//! on one maps onto the other (SPEC §10).
//!
//! A straight road is a network of one segment and no junction; the Fig. 8 intersection
//! is a junction whose inlet and outlet tracks are its own stubs; a corridor or a grid
//! joins junctions by segments. A segment's frame: x along its direction of travel, y
//! leftward from its right edge (lane j spans [j Wl, (j+1) Wl], 0 = rightmost), as the
//! multi-lane planner sees a road. A junction's frame is its layout's (centre at the
//! origin), shifted to its centre in the world.
//!
//! Where a segment meets a junction: a segment feeding junction J ends at J's stop line
//! (the edge of A_S) and its last `inlet_length` metres are J's inlet tracks; a segment
//! leaving J starts at the edge of A_S and its first `outlet_length` metres are J's
//! outlet tracks. Lanes are numbered from the right on a segment and from the inside at a
//! junction: segment lane j of n is junction lane n − 1 − j.

use super::LANE_WIDTH_M;
use planner_core::crossing::Algorithm;
use planner_core::intersection::{Layout, Movement, Track};
use planner_core::unicycle::Pose;

/// Where a vehicle is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Place {
    /// On segment (index).
    Segment(usize),
    /// In junction (index): on its inlet track, inside A_S, or on its outlet track.
    Junction(usize),
}

/// What is at a segment's end.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum End {
    /// The road goes on without end (x unbounded).
    Open,
    /// A dead end at x_R (22): vehicles stop before it.
    DeadEnd(f64),
    /// The network's boundary at this x: vehicles leave once their rear is past it.
    Exit(f64),
    /// Junction (index), whose stop line is at this x.
    Junction(usize, f64),
}

impl End {
    /// The x where the segment ends, if it does.
    pub fn x(&self) -> Option<f64> {
        match *self {
            End::Open => None,
            End::DeadEnd(x) | End::Exit(x) | End::Junction(_, x) => Some(x),
        }
    }
}

/// A straight multi-lane road in one direction.
#[derive(Debug, Clone, PartialEq)]
pub struct Segment {
    /// Id in the scenario.
    pub id: u16,
    /// Lanes (1 …).
    pub lanes: u8,
    /// Direction of travel: 0 east, 1 north, 2 west, 3 south.
    pub heading: u8,
    /// World position of the frame's origin (x = 0 on its right edge).
    pub origin: (f64, f64),
    /// What is at its end.
    pub end: End,
    /// The junction it leaves at x = 0, if any.
    pub from: Option<usize>,
    /// Speed limit (m/s): every planner on it plans with this vmax.
    pub v_max: f64,
}

/// A junction: an intersection layout placed at `centre`, with its manager's algorithm.
#[derive(Debug, Clone)]
pub struct Junction {
    /// Id in the scenario.
    pub id: u16,
    /// World position of the layout's origin.
    pub centre: (f64, f64),
    /// Geometry, routes and conflicts.
    pub layout: Layout<f64>,
    /// The crossing algorithm of its manager.
    pub algorithm: Algorithm,
    /// Per heading of travel: the segment whose end is this inlet (`None`: the layout's
    /// own inlet track, where vehicles start or are spawned in crossing mode).
    pub inlets: [Option<usize>; 4],
    /// Per heading of travel: the segment this outlet continues as (`None`: vehicles
    /// leave the network once they are on it outside A_C).
    pub outlets: [Option<usize>; 4],
}

/// The network.
#[derive(Debug, Clone, Default)]
pub struct Network {
    /// Segments.
    pub segments: Vec<Segment>,
    /// Junctions.
    pub junctions: Vec<Junction>,
}

/// The heading of travel after movement `m` from heading `h` (0 east, 1 north, 2 west,
/// 3 south; a left turn is a quarter turn counter-clockwise).
pub fn turned(h: u8, m: Movement) -> u8 {
    let turn = match m {
        Movement::Straight => 0,
        Movement::Left => 1,
        Movement::Right => 3,
    };
    (h + turn) % 4
}

/// (x, y) rotated by `quarter_turns` × 90° counter-clockwise.
pub fn rotate((x, y): (f64, f64), quarter_turns: u8) -> (f64, f64) {
    match quarter_turns % 4 {
        0 => (x, y),
        1 => (-y, x),
        2 => (-x, -y),
        _ => (y, -x),
    }
}

impl Segment {
    /// The centre line of lane `j` (segment frame y).
    pub fn lane_centre(&self, j: u8) -> f64 {
        (f64::from(j) + 0.5) * LANE_WIDTH_M
    }

    /// A pose in this segment's frame as a world pose.
    pub fn to_world(&self, x: f64, y: f64, theta: f64) -> Pose<f64> {
        let (dx, dy) = rotate((x, y), self.heading);
        Pose {
            x: self.origin.0 + dx,
            y: self.origin.1 + dy,
            theta: theta + f64::from(self.heading % 4) * std::f64::consts::FRAC_PI_2,
        }
    }

    /// Where A_C of the junction at its end begins (x), if it ends at one: a lane
    /// change must be over there (SPEC §10).
    pub fn comm_edge(&self, net: &Network) -> Option<f64> {
        let End::Junction(j, stop) = self.end else {
            return None;
        };
        Some(
            stop - net
                .junctions
                .get(j)
                .map_or(0.0, |jn| jn.layout.spec.comm_margin),
        )
    }

    /// The junction at its end, if any.
    pub fn into_junction(&self) -> Option<usize> {
        match self.end {
            End::Junction(j, _) => Some(j),
            _ => None,
        }
    }

    /// Segment lane `j` as a junction lane (from the inside), and back.
    pub fn junction_lane(&self, j: u8) -> u8 {
        self.lanes.saturating_sub(1).saturating_sub(j)
    }

    /// `true` if lane `j` serves `movement` at the junction at its end (SPEC §10: the
    /// innermost lane left and straight, the outermost straight and right, the others
    /// straight); every lane serves a segment without a junction.
    pub fn serves(&self, net: &Network, j: u8, movement: Option<Movement>) -> bool {
        match (self.into_junction(), movement) {
            (Some(k), Some(m)) => net.junctions.get(k).is_some_and(|jn| {
                planner_core::intersection::lane_movements(
                    self.junction_lane(j),
                    jn.layout.spec.lanes,
                )
                .contains(&m)
            }),
            _ => true,
        }
    }

    /// The lane serving `movement` nearest to lane `from`.
    pub fn nearest_serving(&self, net: &Network, from: u8, movement: Option<Movement>) -> u8 {
        (0..self.lanes)
            .filter(|&j| self.serves(net, j, movement))
            .min_by_key(|&j| j.abs_diff(from))
            .unwrap_or(from)
    }
}

impl Junction {
    /// A pose in this junction's frame as a world pose.
    pub fn to_world(&self, p: Pose<f64>) -> Pose<f64> {
        Pose {
            x: self.centre.0 + p.x,
            y: self.centre.1 + p.y,
            theta: p.theta,
        }
    }

    /// The world pose at `s` along route `route`'s path.
    pub fn pose(&self, route: u8, s: f64) -> Pose<f64> {
        let path = self
            .layout
            .route(usize::from(route))
            .map_or(Pose::default(), |r| r.path.pose_at(s));
        self.to_world(path)
    }
}

impl Network {
    /// A network of one unbounded straight road (the legacy `[road]` scenario): segment 0
    /// heading east with its frame at the world origin, ending at `end_x` if given.
    pub fn road(lanes: u8, end_x: Option<f64>, v_max: f64) -> Self {
        Self {
            segments: vec![Segment {
                id: 0,
                lanes,
                heading: 0,
                origin: (0.0, 0.0),
                end: end_x.map_or(End::Open, End::DeadEnd),
                from: None,
                v_max,
            }],
            junctions: Vec::new(),
        }
    }

    /// Where a vehicle on junction `j`'s route `route` at path position `s` is on a
    /// segment, if that part of its path lies on one: on the inlet track (before the stop
    /// line) on the segment feeding it, on the outlet track on the segment it continues
    /// as. Returns (segment, x, segment lane).
    pub fn on_segment(&self, j: usize, route: u8, s: f64) -> Option<(usize, f64, u8)> {
        let jn = self.junctions.get(j)?;
        let r = jn.layout.route(usize::from(route))?;
        let (entry, exit) = (r.path.entry(), r.path.exit());
        if s <= entry {
            let seg = (*jn.inlets.get(usize::from(r.inlet.heading))?)?;
            let sg = self.segments.get(seg)?;
            let end = sg.end.x()?;
            Some((seg, end - (entry - s), sg.junction_lane(r.inlet.lane)))
        } else if s >= exit {
            let seg = (*jn.outlets.get(usize::from(r.outlet.heading))?)?;
            let sg = self.segments.get(seg)?;
            Some((seg, s - exit, sg.junction_lane(r.outlet.lane)))
        } else {
            None
        }
    }

    /// The speed limit along junction `j`'s route `route`: the junction's, or that of the
    /// segment the route continues as, if slower — the outlet track lies on that segment,
    /// and a vehicle leaving at the junction's limit would be over the segment's (a red
    /// team's layouts sweep found 17.38 m/s leaving onto a 16.42 m/s segment).
    pub fn route_limit(&self, j: usize, route: u8) -> Option<f64> {
        let jn = self.junctions.get(j)?;
        let r = jn.layout.route(usize::from(route))?;
        let onto = jn
            .outlets
            .get(usize::from(r.outlet.heading))
            .copied()
            .flatten()
            .and_then(|k| self.segments.get(k))
            .map_or(f64::INFINITY, |s| s.v_max);
        Some(jn.layout.spec.v_limit.min(onto))
    }

    /// Where a vehicle on segment `seg` at `x` in lane `lane` is along junction `j`'s
    /// route `route`, if the segment carries that route's inlet (it feeds `j` in that
    /// lane) or outlet (it leaves `j` in that lane).
    pub fn on_route(&self, seg: usize, x: f64, lane: u8, j: usize, route: u8) -> Option<f64> {
        let sg = self.segments.get(seg)?;
        let jn = self.junctions.get(j)?;
        let r = jn.layout.route(usize::from(route))?;
        let track = Track {
            heading: sg.heading,
            lane: sg.junction_lane(lane),
        };
        if sg.into_junction() == Some(j) && r.inlet == track {
            let end = sg.end.x()?;
            Some(r.path.entry() - (end - x))
        } else if sg.from == Some(j) && r.outlet == track {
            Some(r.path.exit() + x)
        } else {
            None
        }
    }

    /// The route of junction `j` from inlet lane `lane` of the segment `seg` (which feeds
    /// it) with `movement`, if that lane serves it.
    pub fn route_from(&self, seg: usize, lane: u8, movement: Movement) -> Option<u8> {
        let sg = self.segments.get(seg)?;
        let j = sg.into_junction()?;
        let jn = self.junctions.get(j)?;
        jn.layout
            .route_index(sg.heading, sg.junction_lane(lane), movement)
            .and_then(|r| u8::try_from(r).ok())
    }
}

impl Network {
    /// The segments where vehicles leave the world (exits).
    pub fn exits(&self) -> Vec<usize> {
        (0..self.segments.len())
            .filter(|&k| matches!(self.segments[k].end, End::Exit(_)))
            .collect()
    }

    /// The segments where vehicles enter the world (no junction at their start, one at
    /// their end).
    pub fn entries(&self) -> Vec<usize> {
        (0..self.segments.len())
            .filter(|&k| {
                self.segments[k].from.is_none() && self.segments[k].into_junction().is_some()
            })
            .collect()
    }

    /// Where the movement `m` at the junction at segment `seg`'s end leads: the segment
    /// its outlet continues as, if any.
    pub fn after(&self, seg: usize, m: Movement) -> Option<usize> {
        let sg = self.segments.get(seg)?;
        let j = sg.into_junction()?;
        let out = turned(sg.heading, m);
        *self.junctions.get(j)?.outlets.get(usize::from(out))?
    }

    /// The free-flow time (s) of a trip from segment `seg` at centre `x` through
    /// `movements` to its exit: the length of road its centre covers until its rear is
    /// past the exit (a vehicle `length` long), each segment driven at its speed limit and
    /// each junction at its vImax, with no stop. `None` if the movements do not lead out
    /// of the network.
    pub fn free_flow_s(
        &self,
        (mut seg, mut x): (usize, f64),
        movements: &[Movement],
        length: f64,
    ) -> Option<f64> {
        let mut t = 0.0;
        for &m in movements {
            let sg = self.segments.get(seg)?;
            let End::Junction(j, stop) = sg.end else {
                return None;
            };
            let jn = self.junctions.get(j)?;
            let lane = sg.nearest_serving(self, 0, Some(m));
            let route = self.route_from(seg, lane, m)?;
            let r = jn.layout.route(usize::from(route))?;
            t += (stop - x).max(0.0) / sg.v_max;
            t += (r.path.exit() - r.path.entry()) / jn.layout.spec.v_limit;
            seg = self.after(seg, m)?;
            x = 0.0;
        }
        let sg = self.segments.get(seg)?;
        let End::Exit(end) = sg.end else {
            return None;
        };
        Some(t + (end + 0.5 * length - x).max(0.0) / sg.v_max)
    }

    /// The movements of a shortest path (by length of road) from segment `from` to
    /// segment `to`, one per junction; `None` if `to` cannot be reached.
    pub fn path(&self, from: usize, to: usize) -> Option<Vec<Movement>> {
        let n = self.segments.len();
        let len = |k: usize| self.segments.get(k).and_then(|s| s.end.x()).unwrap_or(0.0);
        let mut dist = vec![f64::INFINITY; n];
        let mut prev: Vec<Option<(usize, Movement)>> = vec![None; n];
        let mut done = vec![false; n];
        *dist.get_mut(from)? = 0.0;
        for _ in 0..n {
            let Some(u) = (0..n)
                .filter(|&k| !done[k] && dist[k].is_finite())
                .min_by(|&a, &b| dist[a].total_cmp(&dist[b]))
            else {
                break;
            };
            done[u] = true;
            if u == to {
                break;
            }
            for m in [Movement::Straight, Movement::Left, Movement::Right] {
                if let Some(w) = self.after(u, m) {
                    let d = dist[u] + len(u);
                    if d < dist[w] {
                        dist[w] = d;
                        prev[w] = Some((u, m));
                    }
                }
            }
        }
        if !dist.get(to)?.is_finite() {
            return None;
        }
        let mut moves = Vec::new();
        let mut k = to;
        while let Some((u, m)) = prev[k] {
            moves.push(m);
            k = u;
        }
        moves.reverse();
        Some(moves)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotations_are_quarter_turns() {
        assert_eq!(rotate((1.0, 2.0), 0), (1.0, 2.0));
        assert_eq!(rotate((1.0, 2.0), 1), (-2.0, 1.0));
        assert_eq!(rotate((1.0, 2.0), 2), (-1.0, -2.0));
        assert_eq!(rotate((1.0, 2.0), 3), (2.0, -1.0));
    }

    #[test]
    fn a_road_is_one_segment_in_world_coordinates() {
        let n = Network::road(3, Some(400.0), 27.8);
        let s = &n.segments[0];
        let p = s.to_world(12.0, 5.4, 0.1);
        assert_eq!((p.x, p.y, p.theta), (12.0, 5.4, 0.1));
        assert_eq!(s.end.x(), Some(400.0));
        assert!(
            s.serves(&n, 2, Some(Movement::Left)),
            "no junction: every lane serves"
        );
    }
}
