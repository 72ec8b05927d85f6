//! A turn given up: a vehicle that can no longer reach a lane serving its next movement
//! before the edge of A_C takes a movement its own lane serves, and the shortest path
//! from there to its destination, as a driver who missed a turn does.
//!
//! Why: a lane change must end before the edge of A_C (SPEC §10, no change inside A_C),
//! and a unicycle does not move sideways at rest. A vehicle whose change is held up by
//! its neighbours (a gap that opens only late, a change of a vehicle beside it the other
//! way) and that starts it a few metres before the edge stops there mid-change, turned
//! and off the centre line: it can neither finish the change nor hand over to its
//! crossing planner, and its lane stands behind it for good. In the 3 × 3 grid at 800
//! vehicles per hour per boundary inlet one such vehicle, 2.8 m before the edge at 5°,
//! held its segment's queue from t = 175 s to the end of the run and the queues spilled
//! back through two junctions upstream. Giving the turn up while there is still room
//! to brake in the lane keeps every lane moving; it changes only the vehicle's target
//! lane, never what its planners may do, so nothing it does is less safe.

use super::at::At;
use super::network::Network;
use crate::monitor::Limits;
use planner_core::intersection::{lane_movements, Movement};

/// Room (m) beyond twice its stopping distance that a vehicle gives itself for a lane
/// change before the edge of A_C: a change from rest takes at least 8 m of travel
/// (Lemma 12's S-curve at the smallest turning radius), and a vehicle 20 m from the edge
/// at walking pace can still make one.
pub const CHANGE_ROOM_M: f64 = 20.0;

/// How close to the edge of A_C (m) a vehicle at `v` with braking limit `brake` may come,
/// not yet changing toward a lane serving its next movement, before it gives that
/// movement up: twice its stopping distance (one period's travel, then braking) and
/// [`CHANGE_ROOM_M`]. 44.7 m at 13.9 m/s and 7.9 m/s², 20.5 m at 2 m/s.
pub fn give_up_distance(lim: &Limits, v: f64, brake: f64) -> f64 {
    2.0 * (v * v / (2.0 * brake) + v * lim.h) + CHANGE_ROOM_M
}

/// The segment a trip ends on: `seg`, followed through `movements`.
pub fn destination(net: &Network, seg: usize, movements: &[Movement]) -> Option<usize> {
    movements.iter().try_fold(seg, |s, &m| net.after(s, m))
}

/// The movements of a new trip from segment `seg` in lane `lane` that starts with a
/// movement the lane serves: the fewest junctions to `dest`, else to the nearest exit
/// (the vehicle then leaves elsewhere); `None` if the lane leads nowhere.
pub fn detour(net: &Network, seg: usize, lane: u8, dest: usize) -> Option<Vec<Movement>> {
    let sg = net.segments.get(seg)?;
    let jn = net.junctions.get(sg.into_junction()?)?;
    let served = lane_movements(sg.junction_lane(lane), jn.layout.spec.lanes);
    let via = |m: Movement, to: usize| -> Option<Vec<Movement>> {
        let w = net.after(seg, m)?;
        let rest = if w == to {
            Vec::new()
        } else {
            net.path(w, to)?
        };
        Some(core::iter::once(m).chain(rest).collect())
    };
    let shortest = |to: usize| {
        served
            .iter()
            .filter_map(|&m| via(m, to))
            .min_by_key(Vec::len)
    };
    shortest(dest).or_else(|| {
        net.exits()
            .into_iter()
            .filter_map(shortest)
            .min_by_key(Vec::len)
    })
}

/// `true` if a vehicle at `at`, going `v` with braking limit `brake` and next movement
/// `next`, should give that movement up now: on a segment ending at a junction, in a
/// lane that does not serve it, no change under way, and nearer the edge of A_C than
/// [`give_up_distance`].
pub fn must_give_up(
    net: &Network,
    lim: &Limits,
    at: At,
    (v, brake): (f64, f64),
    next: Option<Movement>,
) -> bool {
    let At::Lane {
        seg,
        x,
        lane,
        alpha: None,
        ..
    } = at
    else {
        return false;
    };
    let Some(sg) = net.segments.get(seg) else {
        return false;
    };
    sg.comm_edge(net).is_some_and(|edge| {
        !sg.serves(net, lane, next) && edge - x < give_up_distance(lim, v, brake)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::network::{End, Network};
    use std::path::Path;

    fn grid() -> Network {
        let text = "name = \"g\"\nduration_s = 10.0\n[grid]\nrows = 3\ncols = 3\nblock_m = 300.0\nlanes = 2\n[arrivals]\nrate_vph = 100.0\n";
        crate::scenario::parse(text, Path::new("g.toml"))
            .expect("a grid")
            .network
    }

    /// The segment into the centre junction from the west, and its stop line.
    fn into_centre(net: &Network) -> (usize, f64) {
        let centre = net
            .junctions
            .iter()
            .position(|j| j.id == 5)
            .expect("junction 5");
        net.segments
            .iter()
            .enumerate()
            .find_map(|(k, s)| match s.end {
                End::Junction(j, stop) if j == centre && s.from.is_some() => Some((k, stop)),
                _ => None,
            })
            .expect("a segment into the centre")
    }

    fn on(seg: usize, x: f64, lane: u8, alpha: Option<u8>) -> At {
        At::Lane {
            seg,
            x,
            y: 0.0,
            theta: 0.0,
            lane,
            alpha,
            beta: None,
        }
    }

    #[test]
    fn the_distance_is_twice_the_stop_and_room_for_a_change() {
        let lim = Limits::table_i();
        let at = |v: f64| give_up_distance(&lim, v, 7.9);
        assert!((at(13.9) - (2.0 * (13.9 * 13.9 / 15.8 + 13.9 * lim.h) + 20.0)).abs() < 1e-12);
        assert!((at(0.0) - CHANGE_ROOM_M).abs() < 1e-12);
        assert!(at(13.9) > at(2.0) && at(2.0) > at(0.0));
    }

    /// Only a vehicle in a lane that does not serve its next movement, with no change
    /// under way, near the edge of A_C gives its movement up.
    #[test]
    fn only_a_late_vehicle_in_the_wrong_lane_gives_up() {
        let (net, lim) = (grid(), Limits::table_i());
        let (seg, stop) = into_centre(&net);
        let sg = &net.segments[seg];
        let edge = sg.comm_edge(&net).expect("a junction at its end");
        assert!(edge < stop);
        // Lane 1 (inner) serves a left turn; lane 0 (outer) does not.
        let (inner, outer) = (1, 0);
        assert!(sg.serves(&net, inner, Some(Movement::Left)));
        assert!(!sg.serves(&net, outer, Some(Movement::Left)));
        let left = Some(Movement::Left);
        let v = (13.9, 7.9);
        let d = give_up_distance(&lim, v.0, v.1);
        let late = edge - d + 0.5;
        let gives_up = |x: f64, lane: u8, alpha: Option<u8>, next: Option<Movement>| {
            must_give_up(&net, &lim, on(seg, x, lane, alpha), v, next)
        };
        assert!(gives_up(late, outer, None, left));
        assert!(!gives_up(edge - d - 0.5, outer, None, left));
        assert!(!gives_up(late, inner, None, left));
        assert!(!gives_up(late, outer, Some(inner), left));
        // Straight is served by both lanes.
        assert!(!gives_up(late, outer, None, Some(Movement::Straight)));
    }

    /// The detour starts with a movement the lane serves and ends where the trip did.
    #[test]
    fn the_detour_starts_in_the_lane_and_ends_at_the_destination() {
        let net = grid();
        let (seg, _) = into_centre(&net);
        let planned = [Movement::Left, Movement::Straight];
        let dest = destination(&net, seg, &planned).expect("a destination");
        assert!(matches!(net.segments[dest].end, End::Exit(_)));
        let sg = &net.segments[seg];
        for lane in [0, 1] {
            let d = detour(&net, seg, lane, dest).expect("a detour");
            assert!(
                sg.serves(&net, lane, d.first().copied()),
                "lane {lane}: {d:?}"
            );
            assert_eq!(destination(&net, seg, &d), Some(dest), "lane {lane}: {d:?}");
        }
    }
}
