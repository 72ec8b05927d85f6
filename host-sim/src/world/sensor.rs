//! Onboard range sensors, modelled from ground truth (the planner side is planner-core's
//! [`sensing`](planner_core::sensing)): what each vehicle's own sensors return this step.
//!
//! - A planner on a segment sees every vehicle whose rectangle overlaps its lane or a
//!   lane next to it, ahead within `ahead_m` of its front bumper or behind within
//!   `behind_m` of its rear bumper, in its own frame: position and speed each with an
//!   error drawn uniformly within the stated bound, and the lanes the rectangle overlaps.
//!   Returns carry the true id: association of a return with a V2V record is assumed
//!   perfect (a documented simplification; a real tracker associates by position).
//! - A planner in a junction sees the vehicles on its own path ahead within `ahead_m`:
//!   their positions along its path, with the same error.
//! - A scripted or random driver sees the bumper gap to the nearest vehicle physically in
//!   its lane ahead, exactly (it brakes for it; see `Driver::Script`).
//! - A junction's roadside sensor (its manager's, when the world has sensors) sees every
//!   vehicle crossing there inside its communication region A_C: its position along its
//!   route's path, with the same error ([`roadside`]).

use super::at::At;
use super::network::Network;
use super::{LANE_WIDTH_M, WIDTH_M};
use planner_core::crossing::PathVehicle;
use planner_core::{Other, Sensing};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// One vehicle's sensor returns of one step.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Sensed {
    /// On a segment: the vehicles seen, as the multi-lane planner takes them.
    pub others: Vec<Other<f64>>,
    /// In a junction: the vehicles seen on its path, where along it and how long.
    pub on_path: Vec<PathVehicle<f64>>,
    /// A scripted driver: the bumper gap to the nearest vehicle in its lane ahead.
    pub gap_ahead: Option<f64>,
    /// A planner: every vehicle returned, by id, and where its sensors measured it in its
    /// own frame (x on its segment, or s along its path) — what [`seen_at`] says of a
    /// vehicle's claim, to check one against the other.
    pub ids: Vec<(u16, f64)>,
}

/// Ground truth of one vehicle, as the sensors see it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Seen {
    /// Id.
    pub id: u16,
    /// Where.
    pub at: At,
    /// Speed (m/s).
    pub v: f64,
    /// Length (m): range sensors measure a vehicle's extent.
    pub length: f64,
}

/// The lanes (lowest, highest) a rectangle `length` long at lateral position `y`,
/// heading `theta` overlaps on a road of `lanes` lanes.
fn lanes_overlapped((y, theta): (f64, f64), length: f64, lanes: u8) -> (u8, u8) {
    let ext = 0.5 * (length * theta.sin().abs() + WIDTH_M * theta.cos().abs());
    let lane = |v: f64| ((v / LANE_WIDTH_M).floor().max(0.0) as u8).min(lanes.saturating_sub(1));
    (lane(y - ext + 1e-9), lane(y + ext - 1e-9))
}

/// Where `c` is in segment `seg`'s frame, if it is physically on it: (x, y, θ).
fn on_segment(net: &Network, seg: usize, c: &Seen) -> Option<(f64, f64, f64)> {
    c.at.on_segment(net, seg).map(|p| (p.x, p.y, p.theta))
}

/// Sensor returns for each vehicle of `each` — what it shows of itself and whether its
/// own planners drive it, or `None` for one gone (no returns) — from what `all` show: a
/// planner senses with `sensing` (nothing without it); a scripted or random driver sees
/// what is in its lane ahead. The world's period and a fleet's harness both sense with
/// this, each drawing the noise from its own random stream.
pub fn sense_each(
    net: &Network,
    all: &[Seen],
    each: impl Iterator<Item = Option<(Seen, bool)>>,
    sensing: Option<&Sensing<f64>>,
    rng: &mut ChaCha8Rng,
) -> Vec<Sensed> {
    each.map(|me| match me {
        Some((_, true)) if sensing.is_none() => Sensed::default(),
        Some((me, planner)) => sense(net, &me, all, sensing.filter(|_| planner), rng),
        None => Sensed::default(),
    })
    .collect()
}

/// What the sensors of `me` (planner-driven: `sensing`; scripted: `None`) return.
pub fn sense(
    net: &Network,
    me: &Seen,
    all: &[Seen],
    sensing: Option<&Sensing<f64>>,
    rng: &mut ChaCha8Rng,
) -> Sensed {
    let mut out = Sensed::default();
    match (me.at, sensing) {
        (At::Lane { seg, x, lane, .. }, Some(s)) => {
            for c in all.iter().filter(|c| c.id != me.id) {
                let Some(cover) = lane_cover(net, (seg, x, lane), me.length, c, (s, 0.0)) else {
                    continue;
                };
                let (e, ev) = (s.position_error_m, s.speed_error_mps);
                let mx = cover.x + noise(rng, e);
                let mv = c.v + noise(rng, ev);
                out.ids.push((c.id, mx));
                out.others.push(Other {
                    alpha: (cover.hi != cover.lo).then_some(cover.hi),
                    cooperative: false,
                    sensed: true,
                    ..Other::v2v(c.id, mx, mv.max(0.0), c.length, cover.lo, 0.0)
                });
            }
        }
        (At::Crossing { junction, route, s }, Some(sn)) => {
            for c in all.iter().filter(|c| c.id != me.id) {
                if let Some(p) = path_cover(net, (junction, route, s), me.length, c, (sn, 0.0)) {
                    let measured = p + noise(rng, sn.position_error_m);
                    out.ids.push((c.id, measured));
                    out.on_path.push(PathVehicle {
                        s: measured,
                        length: c.length,
                    });
                }
            }
        }
        (At::Lane { seg, x, lane, .. }, None) => {
            let lanes = net.segments.get(seg).map_or(1, |g| g.lanes);
            out.gap_ahead = all
                .iter()
                .filter(|c| c.id != me.id)
                .filter_map(|c| on_segment(net, seg, c).map(|p| (p, c.length)))
                .filter(|&((cx, cy, cth), length)| {
                    let (lo, hi) = lanes_overlapped((cy, cth), length, lanes);
                    cx >= x && lo <= lane && lane <= hi
                })
                .map(|((cx, ..), length)| cx - x - 0.5 * (length + me.length))
                .reduce(f64::min);
        }
        (At::Crossing { .. }, None) => {}
    }
    out
}

/// A uniform draw within ± `e` (nothing drawn for an exact sensor).
fn noise(rng: &mut ChaCha8Rng, e: f64) -> f64 {
    if e > 0.0 {
        rng.random_range(-e..=e)
    } else {
        0.0
    }
}

/// Where a vehicle in a segment's cover is: its x in the frame and the lanes it overlaps.
#[derive(Debug, Clone, Copy, PartialEq)]
struct LaneCover {
    x: f64,
    lo: u8,
    hi: u8,
}

/// Where `c` is in the cover of sensors `sn` mounted on a vehicle `length` long at `x`
/// in lane `lane` of segment `seg`, if it is `margin` m inside it (0: the cover itself):
/// overlapping that lane or one next to it (by more than `margin` sideways), ahead within
/// the forward range of the front bumper or behind within the rear range of the rear one.
fn lane_cover(
    net: &Network,
    (seg, x, lane): (usize, f64, u8),
    length: f64,
    c: &Seen,
    (sn, margin): (&Sensing<f64>, f64),
) -> Option<LaneCover> {
    let lanes = net.segments.get(seg).map_or(1, |g| g.lanes);
    let (cx, cy, cth) = on_segment(net, seg, c)?;
    let (lo, hi) = lanes_overlapped((cy, cth), c.length, lanes);
    let near_lane = if margin > 0.0 {
        // Wholly within the covered lanes, so that no sideways move of the claim's age
        // takes it out of them.
        lo + 1 >= lane && hi <= lane + 1
    } else {
        hi + 1 >= lane && lo <= lane + 1
    };
    let half = 0.5 * (c.length + length);
    let ahead = cx - half - x <= sn.ahead_m - margin && cx >= x + margin;
    let behind = x - half - cx <= sn.behind_m - margin && cx < x - margin;
    (near_lane && (ahead || behind)).then_some(LaneCover { x: cx, lo, hi })
}

/// Where `c` is along junction `j`'s route `route` if it is in the forward cover of
/// sensors `sn` on a vehicle `length` long at `s` on that path, `margin` m inside it.
fn path_cover(
    net: &Network,
    (j, route, s): (usize, u8, f64),
    length: f64,
    c: &Seen,
    (sn, margin): (&Sensing<f64>, f64),
) -> Option<f64> {
    let p = along_route(net, (j, route), c, margin)?;
    (p > s + margin && p - s - 0.5 * (c.length + length) <= sn.ahead_m - margin).then_some(p)
}

/// Where the sensors `sn` of `me` would measure `c` in `me`'s frame, `margin` m inside
/// their cover, if they would: for checking a vehicle's claim (`c`, at its stamp) against
/// the returns ([`Sensed::ids`]) — a claim surely inside the cover by more than the
/// vehicle can have moved since, and the sensors' error, is belied by a return elsewhere
/// or by none.
pub fn seen_at(net: &Network, me: &Seen, c: &Seen, sn: &Sensing<f64>, margin: f64) -> Option<f64> {
    match me.at {
        At::Lane { seg, x, lane, .. } => {
            lane_cover(net, (seg, x, lane), me.length, c, (sn, margin)).map(|l| l.x)
        }
        At::Crossing { junction, route, s } => {
            path_cover(net, (junction, route, s), me.length, c, (sn, margin))
        }
    }
}

/// Where `c` is along junction `j`'s route `route`, if it is on that route's path: on
/// the route itself, on its inlet before the stop line or its outlet past A_S (through
/// another route sharing them, by any part of its body — on the inlet by more than
/// `margin` m, for a claim that must stay there whatever it did since), or on a road the
/// path joins.
fn along_route(net: &Network, (j, route): (usize, u8), c: &Seen, margin: f64) -> Option<f64> {
    let jn = net.junctions.get(j)?;
    let mine = jn.layout.route(usize::from(route))?;
    match c.at {
        At::Crossing {
            junction,
            route: r,
            s: cs,
        } if junction == j => {
            let other = jn.layout.route(usize::from(r))?;
            let (oe, ox) = (other.path.entry(), other.path.exit());
            let half = 0.5 * c.length;
            if r == route || (other.inlet == mine.inlet && cs - half + margin < oe) {
                Some(cs)
            } else if other.outlet == mine.outlet && cs + half > ox {
                // Positions only grow: a front past A_S stays past it.
                Some(mine.path.exit() + (cs - ox))
            } else {
                None
            }
        }
        At::Crossing {
            junction,
            route: r,
            s: cs,
        } => net
            .on_segment(junction, r, cs)
            .and_then(|(sg, x, lane)| net.on_route(sg, x, lane, j, route)),
        At::Lane { seg, x, lane, .. } => net.on_route(seg, x, lane, j, route),
    }
}

/// Mixed into a run's seed for the roadside sensors' noise (a stream of its own, drawn the
/// same way by the in-process world and the fleet).
pub const ROADSIDE_SEED: u64 = 0x00ad_51de;

/// What junction `j`'s roadside sensor (error bound `error`, m) measures this period: every
/// vehicle crossing there whose centre is inside A_C, as (id, position along its route's
/// path), each with an error drawn uniformly within the bound.
pub fn roadside(
    net: &Network,
    j: usize,
    all: &[Seen],
    error: f64,
    rng: &mut ChaCha8Rng,
) -> Vec<(u16, f64)> {
    let Some(jn) = net.junctions.get(j) else {
        return Vec::new();
    };
    all.iter()
        .filter_map(|c| match c.at {
            At::Crossing { junction, route, s } if junction == j => {
                let p = jn.layout.route(usize::from(route))?.path.pose_at(s);
                jn.layout
                    .in_comm_region(p.x, p.y)
                    .then(|| (c.id, s + noise(rng, error)))
            }
            _ => None,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::LENGTH_M;

    #[test]
    fn straddling_rectangles_are_in_both_lanes() {
        assert_eq!(lanes_overlapped((1.8, 0.0), LENGTH_M, 3), (0, 0));
        assert_eq!(lanes_overlapped((3.6, 0.0), LENGTH_M, 3), (0, 1));
        assert_eq!(lanes_overlapped((3.6 + 0.86, 0.0), LENGTH_M, 3), (1, 1));
        // Turned 0.3 rad, the rectangle reaches 1.48 m to either side of its centre.
        assert_eq!(lanes_overlapped((8.0, 0.3), LENGTH_M, 3), (1, 2));
        assert_eq!(lanes_overlapped((9.0, 0.3), LENGTH_M, 3), (2, 2));
    }
}
