//! The world's adapter to the independent monitors: each vehicle's ground truth as a
//! rectangle (in the world, and in a segment's frame), and the monitor that judges them
//! every period — collisions, lanes, junctions and limits ([`crate::monitor`]). Nothing
//! here reads a planner's view.

use super::at::At;
use super::network::{End, Network};
use super::vehicle::VehicleTruth;
use super::WIDTH_M;
use crate::monitor::junction::{JunctionWatch, OnRoute};
use crate::monitor::{road, Findings, Limits, Truth};

/// The world's monitor: safety findings from ground truth, per junction what its manager
/// granted.
#[derive(Debug, Clone)]
pub struct WorldMonitor {
    /// Findings so far.
    pub findings: Findings,
    watches: Vec<JunctionWatch>,
}

impl WorldMonitor {
    /// A fresh monitor for `net`.
    pub fn new(net: &Network) -> Self {
        Self {
            findings: Findings::new(),
            watches: vec![JunctionWatch::default(); net.junctions.len()],
        }
    }

    /// Junction `j`'s manager granted `ids`.
    pub fn granted(&mut self, j: usize, ids: &[u16]) {
        if let Some(w) = self.watches.get_mut(j) {
            w.granted(ids);
        }
    }

    /// Checks one instant: collisions of every pair in the world; per segment, its lanes
    /// (with the junction vehicles whose inlet or outlet lies on it); per junction, its
    /// shared paths and permissions; every vehicle's limits; and that no vehicle on a
    /// segment has passed a junction's stop line (only crossing vehicles may be in A_S).
    pub fn check(&mut self, lim: &Limits, net: &Network, vehicles: &[VehicleTruth]) {
        let world: Vec<Truth> = vehicles.iter().map(|v| world_truth(v, net)).collect();
        self.findings.collisions += road::collisions(&world);
        for (k, seg) in net.segments.iter().enumerate() {
            let on: Vec<Truth> = vehicles
                .iter()
                .filter_map(|v| segment_truth(v, net, k))
                .collect();
            if on.is_empty() {
                continue;
            }
            let end = match seg.end {
                End::DeadEnd(x) => Some(x),
                _ => None,
            };
            road::lanes(&mut self.findings, lim, &on, end, seg.lanes);
            if let End::Junction(_, x) = seg.end {
                let past = on.iter().filter(|c| !c.mapped && c.x + 0.5 * c.length > x);
                self.findings.unpermitted_entries += past.count() as u64;
            }
        }
        for (j, jn) in net.junctions.iter().enumerate() {
            let cars: Vec<OnRoute> = vehicles
                .iter()
                .filter_map(|v| match v.at {
                    At::Crossing { junction, route, s } if junction == j => Some(OnRoute {
                        id: v.id,
                        route,
                        s,
                        v: v.v,
                        length: v.body.length,
                        leader_aware: v.leader_aware,
                        brake: v.body.brake,
                    }),
                    _ => None,
                })
                .collect();
            if let Some(w) = self.watches.get(j) {
                w.check(&mut self.findings, &jn.layout, lim, &cars);
            }
        }
        for v in vehicles {
            let mut l = *lim;
            l.v_max = speed_limit(v, net, lim.v_max);
            let theta = match v.at {
                At::Lane { theta, .. } => theta,
                At::Crossing { .. } => 0.0,
            };
            road::limits(
                &mut self.findings,
                &l,
                &Truth {
                    theta,
                    ..world_truth(v, net)
                },
            );
        }
    }
}

/// The speed limit where `v` is.
pub(crate) fn speed_limit(v: &VehicleTruth, net: &Network, default: f64) -> f64 {
    match v.at {
        At::Lane { seg, .. } => net.segments.get(seg).map_or(default, |s| s.v_max),
        At::Crossing { junction, .. } => net
            .junctions
            .get(junction)
            .map_or(default, |j| j.layout.spec.v_limit),
    }
}

/// A vehicle's rectangle in the world.
pub fn world_truth(v: &VehicleTruth, net: &Network) -> Truth {
    let (p, lane) = match v.at {
        At::Lane {
            seg,
            x,
            y,
            theta,
            lane,
            ..
        } => (
            net.segments
                .get(seg)
                .map_or(planner_core::Pose { x, y, theta }, |s| {
                    s.to_world(x, y, theta)
                }),
            lane,
        ),
        At::Crossing { junction, route, s } => (
            net.junctions
                .get(junction)
                .map_or(Default::default(), |j| j.pose(route, s)),
            0,
        ),
    };
    rectangle(v, p, lane, false)
}

/// A vehicle's rectangle in segment `k`'s frame, if it is on it (a junction vehicle on
/// an inlet or outlet track lying on it is `mapped`).
pub fn segment_truth(v: &VehicleTruth, net: &Network, k: usize) -> Option<Truth> {
    let p = v.at.on_segment(net, k)?;
    let pose = planner_core::Pose {
        x: p.x,
        y: p.y,
        theta: p.theta,
    };
    Some(rectangle(v, pose, p.lane, p.mapped))
}

/// `v`'s rectangle at `pose` in lane `lane` of some frame (the world's or a segment's):
/// what it is and claims, wherever it is.
fn rectangle(v: &VehicleTruth, pose: planner_core::Pose<f64>, lane: u8, mapped: bool) -> Truth {
    Truth {
        x: pose.x,
        y: pose.y,
        theta: pose.theta,
        length: v.body.length,
        width: WIDTH_M,
        lane,
        keeps_invariant: v.planner,
        leader_aware: v.leader_aware,
        brake: v.body.brake,
        v: v.v,
        v_before: v.v_before,
        mapped,
    }
}
