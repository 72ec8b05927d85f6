//! Vehicles entering the world while it runs: the closed system of the paper's Fig. 9
//! (a vehicle that leaves comes back at the start of an inlet with a random route) and
//! open systems (arrivals at each entry lane as a Poisson process, SPEC §8 and the
//! literature's demand test). A vehicle enters only where it keeps the invariant toward
//! the vehicle ahead; until then it waits outside, and that wait counts as delay.

use super::at::At;
use super::network::Network;
use super::vehicle::{Brain, Role, Trip, Vehicle};
use super::watch::segment_truth;
use super::START_MARGIN_M;
use super::{Body, World};
use crate::bus::{Bus, BusError};
use crate::monitor::Limits;
use planner_core::intersection::Movement;
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use std::collections::VecDeque;

/// Where vehicles enter.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Entry {
    /// The start of a junction's own inlet track (crossing mode from the start).
    Stub {
        /// Junction index.
        junction: usize,
        /// Heading of travel of the inlet.
        heading: u8,
        /// Inlet lane (0 inner).
        lane: u8,
    },
    /// The start of a boundary segment, in one of its lanes.
    Segment {
        /// Segment index.
        seg: usize,
        /// Lane (0 rightmost).
        lane: u8,
    },
}

/// The trips an arrival at entry `e` may draw, each with its route when it starts on a
/// junction's own inlet: at a stub, each movement its lane serves; on a boundary
/// segment, the movements of a shortest path to each exit it leads to (the loader
/// refuses an entry that leads to none). The world draws among them evenly; the SUMO
/// export writes a flow for each.
pub fn trip_choices(net: &super::network::Network, e: &Entry) -> Vec<(Vec<Movement>, Option<u8>)> {
    match *e {
        Entry::Stub {
            junction,
            heading,
            lane,
        } => {
            let Some(jn) = net.junctions.get(junction) else {
                return Vec::new();
            };
            planner_core::intersection::lane_movements(lane, jn.layout.spec.lanes)
                .iter()
                .map(|&m| {
                    let route = jn
                        .layout
                        .route_index(heading, lane, m)
                        .and_then(|r| u8::try_from(r).ok());
                    (vec![m], route)
                })
                .collect()
        }
        Entry::Segment { seg, .. } => net
            .exits()
            .into_iter()
            .filter_map(|to| net.path(seg, to))
            .map(|ms| (ms, None))
            .collect(),
    }
}

/// Draws an arrival's trip at an entry: its movements, and at a stub its route.
pub type DrawTrip<'a> = dyn FnMut(&Entry, &mut ChaCha8Rng) -> (Vec<Movement>, Option<u8>) + 'a;

/// A vehicle waiting to enter: since when, and its trip (its id is given as it enters:
/// [`Ids`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Arrival {
    /// When it arrived at the entry (s).
    pub since: f64,
    /// Its movements, one per junction.
    pub movements: Vec<Movement>,
    /// At a stub entry: its route at that junction.
    pub route: Option<u8>,
    /// Its body.
    pub body: Body,
}

/// Arrivals at one entry: a Poisson process of `rate_vph` vehicles per hour.
#[derive(Debug, Clone)]
pub struct Stream {
    /// Where.
    pub entry: Entry,
    /// Vehicles per hour.
    pub rate_vph: f64,
    /// When the next one arrives (s).
    pub next_at: f64,
    /// Those waiting to enter, first first.
    pub queue: VecDeque<Arrival>,
    /// The longest queue seen.
    pub max_queue: usize,
    /// Percent of the arrivals that are trucks ([`Body::TRUCK`]).
    pub trucks_percent: u8,
}

impl Stream {
    /// A stream of `rate_vph` at `entry`, `trucks_percent` of it trucks, its first arrival
    /// drawn from `rng`.
    pub fn new(entry: Entry, (rate_vph, trucks_percent): (f64, u8), rng: &mut ChaCha8Rng) -> Self {
        let mut s = Self {
            entry,
            rate_vph,
            next_at: 0.0,
            queue: VecDeque::new(),
            max_queue: 0,
            trucks_percent,
        };
        s.next_at = s.gap(rng);
        s
    }

    /// An exponential inter-arrival time (s).
    fn gap(&self, rng: &mut ChaCha8Rng) -> f64 {
        if !(self.rate_vph > 0.0) {
            return f64::INFINITY;
        }
        let u: f64 = rng.random_range(f64::EPSILON..1.0);
        -u.ln() * 3600.0 / self.rate_vph
    }

    /// Queues every arrival up to `t`, each with a trip from `trip` and its body drawn
    /// from `bodies` (a stream of its own, so that trucks move no other draw; nothing is
    /// drawn without trucks).
    pub fn arrive(
        &mut self,
        t: f64,
        (rng, bodies): (&mut ChaCha8Rng, &mut ChaCha8Rng),
        trip: &mut DrawTrip<'_>,
    ) {
        while self.next_at <= t {
            let (movements, route) = trip(&self.entry, rng);
            let p = self.trucks_percent;
            let truck = p > 0 && bodies.random_range(0..100u8) < p;
            self.queue.push_back(Arrival {
                since: self.next_at,
                movements,
                route,
                body: if truck { Body::TRUCK } else { Body::CAR },
            });
            self.next_at += self.gap(rng);
            self.max_queue = self.max_queue.max(self.queue.len());
        }
    }
}

/// The speed (m/s) at which a vehicle braking at `brake` may enter `room` metres (bumper
/// gap minus d0) behind the vehicle ahead and keep the invariant with the start margin, at
/// most `v_max`; `None` if there is not room even standing.
pub fn entry_speed(lim: &Limits, room: f64, (v_max, brake): (f64, f64)) -> Option<f64> {
    if room.is_infinite() {
        return Some(v_max);
    }
    let r = room - START_MARGIN_M;
    if !(r > lim.safe_distance_at(0.0, brake)) {
        return None;
    }
    // dS(v) = (v + |amin| h)² / (2|amin|) < r, with a thousandth to spare.
    let v = (2.0 * brake * r).sqrt() - brake * lim.h - 1e-3;
    Some(v.clamp(0.0, v_max))
}

/// Where an arrival at `entry` starts.
pub fn start_at(entry: &Entry, route: Option<u8>, half_length: f64) -> At {
    match *entry {
        Entry::Stub { junction, .. } => At::Crossing {
            junction,
            route: route.unwrap_or(0),
            s: half_length,
        },
        Entry::Segment { seg, lane } => At::Lane {
            seg,
            x: half_length,
            y: (f64::from(lane) + 0.5) * super::LANE_WIDTH_M,
            theta: 0.0,
            lane,
            alpha: None,
            beta: None,
        },
    }
}

/// The ids given to vehicles entering while the world runs: in turn from after the
/// highest id at the start, wrapping around, never a junction manager's bus node
/// (0xFF00 on: [`crate::bus::is_vehicle_id`]) and never one still in use — a vehicle in
/// the world, one still repeating on the bus that it left, one of a closed system waiting
/// to come back.
///
/// Why: ids continued past 65,279 reached 0xFF00, junction 0's manager, and the bus
/// delivered that vehicle's messages as the manager's and the manager's grants to it (a
/// red team counted 3,572 collisions); wrapping past 65,535 reused the ids of vehicles
/// still on the road.
#[derive(Debug, Clone)]
pub struct Ids {
    next: u16,
}

impl Ids {
    /// Ids from `first` on.
    pub fn from(first: u16) -> Self {
        Self { next: first }
    }

    /// The next id that is a vehicle's and not `in_use`; `None` if every one is (65,279
    /// vehicles).
    pub fn take(&mut self, in_use: impl Fn(u16) -> bool) -> Option<u16> {
        for _ in 0..=u16::MAX {
            let id = self.next;
            self.next = id.wrapping_add(1);
            if crate::bus::is_vehicle_id(id) && !in_use(id) {
                return Some(id);
            }
        }
        None
    }
}

impl<const N: usize, B: Bus> World<N, B> {
    /// Vehicles entering: those of a closed system coming back, and open arrivals, each
    /// once it keeps the invariant toward the vehicle ahead where it enters.
    pub(super) fn arrive(&mut self) -> Result<(), BusError> {
        let now = self.time.t;
        let mut still = Vec::new();
        for (id, route) in std::mem::take(&mut self.insertion.pending) {
            let entry = self.stub_of(0, route);
            let v_max = self.entry_limit(&entry);
            // The paper's closed system spawns at vImax where the invariant allows it.
            let car = Body::CAR;
            match self.room(&entry, car) {
                r if entry_speed(&self.lim, r, (v_max, car.brake)).is_some_and(|s| s >= v_max) => {
                    self.insertion.departing.retain(|&(d, ..)| d != id);
                    let trip = (Some(route), Vec::new());
                    self.enter((id, car), &entry, trip, (v_max, now))?;
                }
                _ => still.push((id, route)),
            }
        }
        self.insertion.pending = still;
        let mut streams = std::mem::take(&mut self.insertion.streams);
        for s in &mut streams {
            let net = &self.net;
            let draws = (&mut *self.draws.rng, &mut *self.draws.bodies);
            s.arrive(now, draws, &mut |e, rng| draw_trip(net, e, rng));
            let Some(head) = s.queue.front() else {
                continue;
            };
            let (v_max, body) = (self.entry_limit(&s.entry), head.body);
            let room = self.room(&s.entry, body);
            if let Some(v) = entry_speed(&self.lim, room, (v_max, body.brake)) {
                let Some(id) = self.free_id() else {
                    continue;
                };
                let trip = (head.route, head.movements.clone());
                let since = head.since;
                s.queue.pop_front();
                self.enter((id, body), &s.entry, trip, (v, since))?;
            }
        }
        self.insertion.streams = streams;
        Ok(())
    }

    /// An id for a vehicle entering now ([`super::spawn::Ids`]).
    pub(super) fn free_id(&mut self) -> Option<u16> {
        let used: std::collections::HashSet<u16> = self
            .vehicles
            .iter()
            .map(|v| v.id)
            .chain(self.insertion.departing.iter().map(|d| d.0))
            .chain(self.insertion.pending.iter().map(|p| p.0))
            .collect();
        self.insertion.ids.take(|id| used.contains(&id))
    }

    /// The stub entry of junction `j`'s route `route`.
    pub(super) fn stub_of(&self, j: usize, route: u8) -> Entry {
        let inlet = self
            .net
            .junctions
            .get(j)
            .and_then(|jn| jn.layout.route(usize::from(route)))
            .map(|r| r.inlet)
            .unwrap_or(planner_core::intersection::Track {
                heading: 0,
                lane: 0,
            });
        Entry::Stub {
            junction: j,
            heading: inlet.heading,
            lane: inlet.lane,
        }
    }

    /// The speed limit at an entry.
    pub(super) fn entry_limit(&self, e: &Entry) -> f64 {
        match *e {
            Entry::Stub { junction, .. } => self
                .net
                .junctions
                .get(junction)
                .map_or(self.lim.v_max, |j| j.layout.spec.v_limit),
            Entry::Segment { seg, .. } => self
                .net
                .segments
                .get(seg)
                .map_or(self.lim.v_max, |s| s.v_max),
        }
    }

    /// The room (bumper gap − d0, m) ahead of a vehicle of `body` entering at `e`, to the
    /// nearest vehicle on the same inlet track or lane (∞ if none), as long as that one is.
    pub(super) fn room(&self, e: &Entry, body: Body) -> f64 {
        let start = 0.5 * body.length;
        let mut room = f64::INFINITY;
        for v in &self.vehicles {
            let ahead = match (*e, v.at()) {
                (
                    Entry::Stub {
                        junction,
                        heading,
                        lane,
                    },
                    At::Crossing {
                        junction: j,
                        route,
                        s,
                    },
                ) if j == junction => {
                    let same = self
                        .net
                        .junctions
                        .get(j)
                        .and_then(|jn| jn.layout.route(usize::from(route)))
                        .filter(|r| r.inlet.heading == heading && r.inlet.lane == lane);
                    match same {
                        Some(r) if s < r.path.entry() + 0.5 * v.body.length => Some(s),
                        _ => None,
                    }
                }
                (Entry::Segment { seg, lane }, _) => {
                    segment_truth(&v.truth(&self.net), &self.net, seg)
                        .filter(|c| {
                            let (lo, hi) = crate::monitor::lateral_span(c);
                            let (a, b) = (
                                f64::from(lane) * super::LANE_WIDTH_M,
                                f64::from(lane + 1) * super::LANE_WIDTH_M,
                            );
                            hi > a && lo < b
                        })
                        .map(|c| c.x)
                }
                _ => None,
            };
            if let Some(x) = ahead {
                let half_lengths = 0.5 * (v.body.length + body.length);
                room = room.min(x - start - half_lengths - self.lim.d0);
            }
        }
        room
    }

    /// Vehicle `id` of `body` enters at `e` on its trip (`route` at a stub entry,
    /// `movements`) at speed `v` (it has waited since `since`).
    pub(super) fn enter(
        &mut self,
        (id, body): (u16, Body),
        e: &Entry,
        (route, movements): (Option<u8>, Vec<Movement>),
        (v, since): (f64, f64),
    ) -> Result<(), BusError> {
        let at = start_at(e, route, 0.5 * body.length);
        let movements = match (route, *e) {
            (Some(r), Entry::Stub { junction, .. }) => self
                .net
                .junctions
                .get(junction)
                .and_then(|j| j.layout.route(usize::from(r)))
                .map_or(movements, |r| vec![r.movement]),
            _ => movements,
        };
        let trip = Trip {
            target_lane: 0,
            goal_x: None,
            v_ref: None,
            movements,
        };
        let role = Role::planner(at, Box::new(Brain::new(id, self.setup, body)));
        let mut car = Vehicle::new(id, role, v, trip, since);
        car.body = body;
        car.note_free_flow(&self.net);
        car.retarget(&self.net);
        self.bus.attach(id)?;
        self.vehicles.push(car);
        Ok(())
    }
}

/// A random trip from entry `e`, drawn evenly among its [`trip_choices`] (one draw, as
/// before they were listed: the same trips for the same seeds).
pub(crate) fn draw_trip(
    net: &Network,
    e: &Entry,
    rng: &mut ChaCha8Rng,
) -> (Vec<Movement>, Option<u8>) {
    let choices = trip_choices(net, e);
    if choices.is_empty() {
        return (Vec::new(), None);
    }
    let k = rng.random_range(0..choices.len());
    choices.into_iter().nth(k).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bus::{is_vehicle_id, manager_node};
    use std::collections::BTreeSet;

    #[test]
    fn entry_speed_keeps_the_invariant() {
        let lim = Limits::table_i();
        let car = (13.9, lim.brake);
        assert_eq!(entry_speed(&lim, f64::INFINITY, car), Some(13.9));
        assert_eq!(entry_speed(&lim, 0.02, car), None);
        let v = entry_speed(&lim, 5.0, car).unwrap();
        assert!(v > 0.0 && lim.safe_distance(v) + START_MARGIN_M < 5.0);
        assert_eq!(entry_speed(&lim, 100.0, car), Some(13.9));
    }

    #[test]
    fn arrivals_come_at_about_the_rate() {
        let mut rng = crate::reference::instances::rng(3);
        let mut bodies = crate::reference::instances::rng(4);
        let mut s = Stream::new(Entry::Segment { seg: 0, lane: 0 }, (600.0, 0), &mut rng);
        s.arrive(3600.0, (&mut rng, &mut bodies), &mut |_, _| {
            (Vec::new(), None)
        });
        let n = s.queue.len() as f64;
        assert!(
            (n - 600.0).abs() < 4.0 * 600f64.sqrt(),
            "{n} arrivals in an hour"
        );
        assert!(s.queue.iter().all(|a| a.body == Body::CAR));
        // Without trucks nothing was drawn for the bodies.
        assert_eq!(bodies, crate::reference::instances::rng(4));
    }

    /// A share of trucks comes at about its rate, from the bodies' own stream: the same
    /// arrival times and trips as without trucks.
    #[test]
    fn a_share_of_the_arrivals_are_trucks() {
        let entry = Entry::Segment { seg: 0, lane: 0 };
        let run = |trucks| {
            let mut rng = crate::reference::instances::rng(3);
            let mut bodies = crate::reference::instances::rng(4);
            let mut s = Stream::new(entry, (600.0, trucks), &mut rng);
            s.arrive(3600.0, (&mut rng, &mut bodies), &mut |_, _| {
                (Vec::new(), None)
            });
            s.queue
        };
        let (cars, mixed, all) = (run(0), run(30), run(100));
        let times = |q: &VecDeque<Arrival>| q.iter().map(|a| a.since).collect::<Vec<_>>();
        assert_eq!(times(&cars), times(&mixed));
        assert!(all.iter().all(|a| a.body == Body::TRUCK));
        let n = mixed.len() as f64;
        let t = mixed.iter().filter(|a| a.body == Body::TRUCK).count() as f64;
        assert!(
            (t - 0.3 * n).abs() < 4.0 * (0.21 * n).sqrt(),
            "{t} trucks of {n}"
        );
    }

    /// From every start near the managers' nodes and the wrap, 200,000 arrivals, each
    /// leaving again after a while: no id is a node's, none is given while in use.
    #[test]
    fn ids_never_meet_a_node_or_an_id_in_use() {
        let nodes: BTreeSet<u16> = (0..256).map(manager_node).collect();
        for first in [1u16, 0xFEF0, 0xFEFF, 0xFF00, 0xFFFF, 0] {
            let mut ids = Ids::from(first);
            let mut live: std::collections::VecDeque<u16> = Default::default();
            let mut set = BTreeSet::new();
            for k in 0..200_000u32 {
                let id = ids.take(|i| set.contains(&i)).expect("an id");
                assert!(
                    is_vehicle_id(id) && !nodes.contains(&id),
                    "{id:#x} from {first:#x}"
                );
                assert!(set.insert(id), "{id} given twice");
                live.push_back(id);
                // About 1,000 vehicles in the world at a time.
                if k % 7 != 0 || live.len() > 1_000 {
                    if let Some(gone) = live.pop_front() {
                        set.remove(&gone);
                    }
                }
            }
        }
        // Every id in use: none left.
        let mut ids = Ids::from(1);
        assert_eq!(ids.take(|_| true), None);
    }
}
