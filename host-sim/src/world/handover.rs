//! Where a vehicle is after it moved (phase 6): onto a junction's inlet, off a junction
//! onto the next segment, out of the world; and what the world does when one leaves.

use super::at::At;
use super::network::{End, Network};
use super::vehicle::Vehicle;
use super::{Arrivals, World};
use crate::bus::{Bus, BusError, Message};
use planner_core::intersection::Movement;
use rand::Rng;

/// What a vehicle's move did to its place.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Moved {
    /// Where it was: on its segment, or in its junction.
    Stays,
    /// It left junction (index) onto a segment, or out of the world (then it is still
    /// `At::Crossing`).
    LeftJunction(usize),
    /// It left the world at the end of an exit segment.
    LeftWorld,
}

/// Hand-overs of one vehicle after its move at `now`: onto a junction's inlet when its
/// centre enters A_C (it is then centred and straight in a serving lane, or its road
/// ended at A_C's edge); bookkeeping of its arrival in A_C and departure from A_S; off a
/// junction once it is on its outlet outside A_C, onto the next segment or out of the
/// world; out of the world past an exit.
pub(super) fn step_place<const N: usize>(v: &mut Vehicle<N>, net: &Network, now: f64) -> Moved {
    match v.at() {
        At::Lane { seg, x, lane, .. } => {
            let Some(sg) = net.segments.get(seg) else {
                return Moved::Stays;
            };
            match sg.end {
                End::Exit(end) if x - 0.5 * v.body.length >= end => {
                    v.log.left_at = Some(now);
                    Moved::LeftWorld
                }
                End::Junction(j, end) => {
                    let Some(jn) = net.junctions.get(j) else {
                        return Moved::Stays;
                    };
                    // Into A_C and onto the route's path once centred and straight in a
                    // lane serving its movement (until then it drives on in its lane).
                    if x < end - jn.layout.spec.comm_margin || !v.ready_to_cross(net) {
                        return Moved::Stays;
                    }
                    let movement = v
                        .trip
                        .movements
                        .first()
                        .copied()
                        .unwrap_or(Movement::Straight);
                    let route = net
                        .route_from(seg, lane, movement)
                        .or_else(|| net.route_from(seg, lane, Movement::Straight))
                        .unwrap_or(0);
                    let entry = jn
                        .layout
                        .route(usize::from(route))
                        .map_or(0.0, |r| r.path.entry());
                    // Only planners cross (`ready_to_cross`), so the hand-over is taken.
                    if v.enter_junction(j, route, entry - (end - x)) {
                        v.log.arrived_at = Some(now);
                    }
                    Moved::Stays
                }
                _ => Moved::Stays,
            }
        }
        At::Crossing { junction, route, s } => {
            let Some(jn) = net.junctions.get(junction) else {
                return Moved::Stays;
            };
            let Some(r) = jn.layout.route(usize::from(route)) else {
                return Moved::Stays;
            };
            let q = r.path.pose_at(s);
            let inside_ac = jn.layout.in_comm_region(q.x, q.y);
            if inside_ac && v.log.arrived_at.is_none() {
                v.log.arrived_at = Some(now);
            }
            if s - 0.5 * v.body.length >= r.path.exit() && v.log.left_as_at.is_none() {
                v.log.left_as_at = Some(now);
            }
            let (Some(a), Some(_)) = (v.log.arrived_at, v.log.left_as_at) else {
                return Moved::Stays;
            };
            if inside_ac {
                return Moved::Stays;
            }
            v.log.crossings.push(now - a);
            match jn
                .outlets
                .get(usize::from(r.outlet.heading))
                .copied()
                .flatten()
            {
                Some(seg) => {
                    let lane = net
                        .segments
                        .get(seg)
                        .map_or(0, |sg| sg.junction_lane(r.outlet.lane));
                    v.enter_segment(net, seg, s - r.path.exit(), lane);
                }
                None => v.log.left_at = Some(now),
            }
            Moved::LeftJunction(junction)
        }
    }
}

impl<const N: usize, B: Bus> World<N, B> {
    /// Phase 5: departures, from what each vehicle's move did (`moves`, in vehicle order,
    /// from its period). A vehicle that leaves a junction says so at once (and repeats it
    /// for [`super::junction::LEFT_REPEAT_S`], or [`super::junction::EXIT_REPEAT_S`] if it
    /// left the world); one that leaves the world is kept for the summary and, in a
    /// closed system, comes back later.
    pub(super) fn hand_over(&mut self, moves: &[Moved]) -> Result<(), BusError> {
        let now = self.time.t;
        let mut leaving = Vec::new();
        for (i, (v, moved)) in self.vehicles.iter_mut().zip(moves).enumerate() {
            match *moved {
                Moved::Stays => {}
                Moved::LeftJunction(j) if v.log.left_at.is_none() => {
                    let id = v.id;
                    let at = self.time.clock.at_step(self.time.steps_done);
                    self.bus
                        .send(id, &Message::departure(id, at, Some(j)), now)?;
                    let until = now + super::junction::left_repeat_s(false);
                    self.insertion.departing.push((id, Some(j), now, until));
                }
                Moved::LeftJunction(j) => leaving.push((i, Some(j))),
                Moved::LeftWorld => leaving.push((i, None)),
            }
        }
        // Last first, so that the indices stay valid.
        for &(i, junction) in leaving.iter().rev() {
            let v = self.vehicles.remove(i);
            // It says it left (the network at an exit, from a junction or a segment) and
            // repeats it for EXIT_REPEAT_S; then it leaves the bus.
            let id = v.id;
            let at = self.time.clock.at_step(self.time.steps_done);
            self.bus
                .send(id, &Message::departure(id, at, junction), now)?;
            let until = now + super::junction::left_repeat_s(true);
            self.insertion.departing.push((id, junction, now, until));
            if let Some(j) = junction {
                if self.spec.arrivals == Arrivals::Closed {
                    let routes = self
                        .net
                        .junctions
                        .get(j)
                        .map_or(1, |jn| jn.layout.routes.len());
                    let route = self.draws.rng.random_range(0..routes as u8);
                    self.insertion.pending.push((id, route));
                }
            }
            self.gone.push(v);
        }
        Ok(())
    }
}
