//! Who waits on whom, for the deadlock report (see [`crate::monitor::liveness`]): from
//! ground truth, each vehicle's intention, and the managers' records.

use super::at::At;
use super::junction::ManagerNode;
use super::network::{End, Network};
use super::vehicle::VehicleTruth;
use crate::monitor::liveness::{Deadlock, DeadlockDetector, Status, WaitsOn, MOVING_MPS};
use crate::monitor::Limits;

/// Who holds a permission at junction `j`, by id and route.
pub type Holders<'a> = dyn Fn(usize) -> Vec<(u16, u8)> + 'a;

/// The permissions junction `j`'s manager holds out, among `managers`.
pub fn holders(managers: &[ManagerNode], j: usize) -> Vec<(u16, u8)> {
    managers
        .iter()
        .filter(|m| m.junction == j)
        .flat_map(|m| m.manager.holders())
        .collect()
}

/// One instant of the deadlock detector over `truths` (`waiting`: vehicles wait to enter
/// the world); the report when it fires.
pub fn watch(
    detector: &mut DeadlockDetector,
    t: f64,
    truths: &[VehicleTruth],
    waiting: bool,
    net: &Network,
    holders: &Holders<'_>,
    lim: &Limits,
) -> Option<Deadlock> {
    let moving = truths.iter().any(|v| v.v > MOVING_MPS);
    let goals = truths.iter().any(|v| v.unmet) || waiting;
    if !detector.tick(t, moving, goals) {
        return None;
    }
    let statuses: Vec<Status> = truths
        .iter()
        .map(|v| Status {
            id: v.id,
            moving: v.v > MOVING_MPS,
            unmet: v.unmet,
            waits_on: waits_on(v, truths, net, holders, lim),
        })
        .collect();
    Some(detector.report(t, &statuses))
}

/// How close (m, bumper to bumper) a stopped vehicle must be to what stops it for that to
/// count as what it waits on.
pub const NEAR_M: f64 = 5.0;

/// What stopped vehicle `v` waits on, among `all`: never nothing — when nothing within
/// [`NEAR_M`] stops it, its own planner does, and the nearest vehicle ahead is named.
pub fn waits_on(
    v: &VehicleTruth,
    all: &[VehicleTruth],
    net: &Network,
    holders: &Holders<'_>,
    lim: &Limits,
) -> Vec<WaitsOn> {
    let out = match v.at {
        At::Lane { .. } => on_segment(v, all, net, lim),
        At::Crossing { junction, route, s } => {
            at_junction(v, all, net, holders, junction, route, s)
        }
    };
    if out.is_empty() {
        return vec![WaitsOn::Planner {
            nearest: nearest_ahead(v, all, net),
        }];
    }
    out
}

/// The nearest vehicle ahead of `v` on its lane (on a segment) or on its route's path
/// (in a junction), however far; `None` if there is none.
fn nearest_ahead(v: &VehicleTruth, all: &[VehicleTruth], net: &Network) -> Option<u16> {
    let ahead = |o: &VehicleTruth| -> Option<f64> {
        match (v.at, o.at) {
            (
                At::Lane { seg, x, lane, .. },
                At::Lane {
                    seg: s,
                    x: ox,
                    lane: l,
                    alpha,
                    ..
                },
            ) => (s == seg && (l == lane || alpha == Some(lane)) && ox > x).then_some(ox - x),
            (At::Lane { seg, x, lane, .. }, At::Crossing { junction, route, s }) => net
                .on_segment(junction, route, s)
                .filter(|&(sg, ox, l)| sg == seg && l == lane && ox > x)
                .map(|(_, ox, _)| ox - x),
            (
                At::Crossing { junction, route, s },
                At::Crossing {
                    junction: j,
                    route: r,
                    s: os,
                },
            ) => (j == junction && r == route && os > s).then_some(os - s),
            _ => None,
        }
    };
    all.iter()
        .filter(|o| o.id != v.id)
        .filter_map(|o| ahead(o).map(|d| (o.id, d)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(id, _)| id)
}

/// On a segment: the vehicle ahead in its lane, the vehicles next to it in the lane it
/// wants, the end of its road.
fn on_segment(v: &VehicleTruth, all: &[VehicleTruth], net: &Network, lim: &Limits) -> Vec<WaitsOn> {
    let At::Lane {
        seg,
        x,
        lane,
        beta,
        alpha,
        ..
    } = v.at
    else {
        return Vec::new();
    };
    let mut out = Vec::new();
    let in_lane = |o: &VehicleTruth, j: u8| match o.at {
        At::Lane {
            seg: s,
            lane: l,
            alpha: a,
            ..
        } => s == seg && (l == j || a == Some(j)),
        At::Crossing { junction, route, s } => net
            .on_segment(junction, route, s)
            .is_some_and(|(sg, _, l)| sg == seg && l == j),
    };
    let x_of = |o: &VehicleTruth| match o.at {
        At::Lane { x, .. } => Some(x),
        At::Crossing { junction, route, s } => {
            net.on_segment(junction, route, s).map(|(_, x, _)| x)
        }
    };
    let ahead = all
        .iter()
        .filter(|o| o.id != v.id && in_lane(o, lane))
        .filter_map(|o| {
            let half = 0.5 * (o.body.length + v.body.length);
            x_of(o).map(|ox| (o.id, ox - x - half, half))
        })
        // Its centre not behind mine (the gap is then at least minus both half-lengths).
        .filter(|&(_, gap, half)| gap >= -half && gap <= NEAR_M + lim.d0)
        .map(|(id, gap, _)| (id, gap))
        .min_by(|a, b| a.1.total_cmp(&b.1));
    if let Some((id, _)) = ahead {
        out.push(WaitsOn::Vehicle { id });
    }
    if let Some(m) = alpha.or(beta).or((lane != v.target_lane).then(|| {
        if v.target_lane > lane {
            lane + 1
        } else {
            lane.saturating_sub(1)
        }
    })) {
        // Who may be behind in the target lane: as far as the longest, weakest-braking
        // vehicle at vmax needs.
        let fleet = crate::world::Fleet::of(all.iter().map(|o| o.body));
        let reach = fleet.longest_m + lim.d0 + lim.safe_distance_at(lim.v_max, fleet.weakest_brake);
        let ids: Vec<u16> = all
            .iter()
            .filter(|o| o.id != v.id && in_lane(o, m))
            .filter(|o| x_of(o).is_some_and(|ox| (ox - x).abs() <= reach))
            .map(|o| o.id)
            .collect();
        out.push(WaitsOn::LaneChange { ids });
    }
    let end = net.segments.get(seg).and_then(|s| match s.end {
        End::DeadEnd(e) => Some(e),
        End::Junction(j, e) => Some(
            e - net
                .junctions
                .get(j)
                .map_or(0.0, |jn| jn.layout.spec.comm_margin),
        ),
        _ => None,
    });
    if end.is_some_and(|e| e - x - 0.5 * v.body.length <= NEAR_M + lim.d0) && ahead.is_none() {
        out.push(WaitsOn::RoadEnd);
    }
    out
}

/// At a junction: its manager's grant (and who holds conflicting permissions) when it
/// stands at its stop line unpermitted; else the vehicle ahead on its path.
fn at_junction(
    v: &VehicleTruth,
    all: &[VehicleTruth],
    net: &Network,
    holders: &Holders<'_>,
    junction: usize,
    route: u8,
    s: f64,
) -> Vec<WaitsOn> {
    let Some(jn) = net.junctions.get(junction) else {
        return Vec::new();
    };
    let Some(mine) = jn.layout.route(usize::from(route)) else {
        return Vec::new();
    };
    let held = holders(junction);
    let permitted = held.iter().any(|&(id, _)| id == v.id);
    let ahead = all
        .iter()
        .filter(|o| o.id != v.id)
        .filter_map(|o| match o.at {
            At::Crossing {
                junction: j,
                route: r,
                s: os,
            } if j == junction => {
                let other = jn.layout.route(usize::from(r))?;
                let half = 0.5 * o.body.length;
                let on_mine = r == route
                    || (other.inlet == mine.inlet && os - half < other.path.entry())
                    || (other.outlet == mine.outlet && os + half > other.path.exit());
                // Ahead (its centre past mine), and its rear within reach of my front.
                let rear = os - half;
                (on_mine && os > s && rear - (s + 0.5 * v.body.length) <= NEAR_M + 1.0)
                    .then_some((o.id, rear))
            }
            _ => None,
        })
        .min_by(|a, b| a.1.total_cmp(&b.1));
    let mut out = Vec::new();
    if let Some((id, _)) = ahead {
        out.push(WaitsOn::Vehicle { id });
    }
    // At its stop line: its front within NEAR_M of the entry to A_S, not past it (a
    // vehicle past the line has its grant or has released it, and what holds it is ahead).
    let to_line = mine.path.entry() - (s + 0.5 * v.body.length);
    let at_line = (-NEAR_M..=NEAR_M).contains(&to_line);
    if !permitted && at_line && ahead.is_none() {
        let holders = held
            .iter()
            .filter(|&&(_, r)| jn.layout.conflict(usize::from(r), usize::from(route)))
            .map(|&(id, _)| id)
            .collect();
        out.push(WaitsOn::Grant {
            junction: jn.id,
            holders,
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stopped(id: u16, x: f64, lane: u8) -> VehicleTruth {
        VehicleTruth {
            id,
            at: At::Lane {
                seg: 0,
                x,
                y: 0.0,
                theta: 0.0,
                lane,
                alpha: None,
                beta: None,
            },
            v: 0.0,
            v_before: 0.0,
            planner: true,
            unmet: true,
            target_lane: lane,
            leader_aware: false,
            body: crate::world::Body::CAR,
        }
    }

    /// A deadlock report never says a vehicle waits on nothing: one with nothing within
    /// reach waits on its own planner, and the nearest vehicle ahead is named.
    #[test]
    fn a_stopped_vehicle_always_waits_on_something() {
        let net = Network::road(2, None, 27.8);
        let lim = Limits::table_i();
        let none = |_: usize| Vec::new();
        let far = [stopped(1, 0.0, 0), stopped(2, 80.0, 0), stopped(3, 40.0, 1)];
        assert_eq!(
            waits_on(&far[0], &far, &net, &none, &lim),
            [WaitsOn::Planner { nearest: Some(2) }]
        );
        assert_eq!(
            waits_on(&far[1], &far, &net, &none, &lim),
            [WaitsOn::Planner { nearest: None }]
        );
        let near = [stopped(1, 0.0, 0), stopped(2, 6.0, 0)];
        assert_eq!(
            waits_on(&near[0], &near, &net, &none, &lim),
            [WaitsOn::Vehicle { id: 2 }]
        );
    }

    /// Only a vehicle at its stop line waits on a grant: one stopped past it, on its
    /// outlet track, has had its grant (the fault grid at 99 % loss had one reported as
    /// waiting on a grant there, stopped behind a vehicle that had left the world).
    #[test]
    fn only_a_vehicle_at_its_stop_line_waits_on_a_grant() {
        use crate::world::network::Junction;
        use planner_core::intersection::{Layout, LayoutSpec};
        let p = planner_core::Params::<f64>::table_i();
        let layout = Layout::new(&p, LayoutSpec::spec8(&p)).expect("SPEC §8 is valid");
        let entry = layout.route(0).map(|r| r.path.entry()).expect("route 0");
        let net = Network {
            segments: Vec::new(),
            junctions: vec![Junction {
                id: 0,
                centre: (0.0, 0.0),
                layout,
                algorithm: planner_core::crossing::Algorithm::Pipelined,
                inlets: [None; 4],
                outlets: [None; 4],
            }],
        };
        let lim = Limits::table_i();
        let none = |_: usize| Vec::new();
        let half = 0.5 * crate::world::Body::CAR.length;
        let at = |s: f64| VehicleTruth {
            at: At::Crossing {
                junction: 0,
                route: 0,
                s,
            },
            ..stopped(1, 0.0, 0)
        };
        let line = [at(entry - half - 0.5)];
        assert_eq!(
            waits_on(&line[0], &line, &net, &none, &lim),
            [WaitsOn::Grant {
                junction: 0,
                holders: Vec::new()
            }]
        );
        let back = [at(entry - half - 20.0)];
        assert_eq!(
            waits_on(&back[0], &back, &net, &none, &lim),
            [WaitsOn::Planner { nearest: None }]
        );
        let past = [at(entry + 30.0)];
        assert_eq!(
            waits_on(&past[0], &past, &net, &none, &lim),
            [WaitsOn::Planner { nearest: None }]
        );
    }
}
