//! A junction's checks at one instant (Sec. VI), from ground truth and from what its
//! manager granted, never from a planner's view: the invariant between vehicles sharing a
//! piece of path (the same route; the same inlet while the one ahead is on it; the same
//! outlet once both are on it), and IC Protocol (ii): nobody inside A_S who was never
//! permitted.

use super::road::least_travel;
use super::{Findings, Limits};
use planner_core::intersection::Layout;
use std::collections::HashSet;

/// A vehicle at a junction: where it is along its route's path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OnRoute {
    /// Id.
    pub id: u16,
    /// Route.
    pub route: u8,
    /// Centre's distance along the route's path (m).
    pub s: f64,
    /// v_{t−h} (m/s).
    pub v: f64,
    /// Its length (m).
    pub length: f64,
    /// It keeps the leader-aware invariant toward the vehicle ahead (every vehicle at a
    /// junction is planner-driven and reports itself, so every leader cooperates).
    pub leader_aware: bool,
    /// Its braking limit |amin| (m/s²).
    pub brake: f64,
}

/// Whether follower `a`, `ahead` (m, centre to centre along their shared piece of path)
/// behind `b`, keeps its invariant toward it: Lemma 3's, x̄ − dS(v_{t−h}) beyond it; the
/// leader-aware one, when `a` keeps it, with x̄ moved along the path by the exact least
/// distance `b` still travels braking at the larger of the two limits ([`least_travel`];
/// positions here are along the path, so no cos θmax), and `a` behind `b` by more than
/// d0.
pub fn keeps_invariant(lim: &Limits, a: &OnRoute, b: &OnRoute, ahead: f64) -> bool {
    let room = ahead - 0.5 * (a.length + b.length) - lim.d0;
    let credit = if a.leader_aware && room > 0.0 {
        least_travel(b.v, b.brake.max(a.brake), lim.h)
    } else {
        0.0
    };
    room + credit > lim.safe_distance_at(a.v, a.brake)
}

/// What a junction's monitor remembers: who was ever granted a permission.
#[derive(Debug, Clone, Default)]
pub struct JunctionWatch {
    ever_permitted: HashSet<u16>,
}

impl JunctionWatch {
    /// The manager granted `ids` a permission.
    pub fn granted(&mut self, ids: &[u16]) {
        self.ever_permitted.extend(ids.iter().copied());
    }

    /// Checks the vehicles `cars` at the junction with `layout` (pairs of them on an inlet
    /// or outlet that lies on a segment are judged here, not by that road's monitor).
    pub fn check(&self, f: &mut Findings, layout: &Layout<f64>, lim: &Limits, cars: &[OnRoute]) {
        for a in cars {
            for b in cars {
                if a.id == b.id {
                    continue;
                }
                let (Some(ra), Some(rb)) = (
                    layout.route(usize::from(a.route)),
                    layout.route(usize::from(b.route)),
                ) else {
                    continue;
                };
                let (fa, fb) = if a.route == b.route
                    || (ra.inlet == rb.inlet && b.s < rb.path.entry())
                {
                    (a.s, b.s)
                } else if ra.outlet == rb.outlet && a.s >= ra.path.exit() && b.s >= rb.path.exit() {
                    (a.s - ra.path.exit(), b.s - rb.path.exit())
                } else {
                    continue;
                };
                if fa < fb && !keeps_invariant(lim, a, b, fb - fa) {
                    f.invariant_violations += 1;
                }
            }
        }
        for c in cars {
            let Some(r) = layout.route(usize::from(c.route)) else {
                continue;
            };
            let front = c.s + 0.5 * c.length;
            if front > r.path.entry()
                && c.s - 0.5 * c.length < r.path.exit()
                && !self.ever_permitted.contains(&c.id)
            {
                f.unpermitted_entries += 1;
            }
        }
    }
}
