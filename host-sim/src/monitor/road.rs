//! A straight road's checks at one instant (SPEC §1, §5): collisions of oriented
//! rectangles; per lane, the invariant of Lemma 3 between consecutive vehicles — a vehicle
//! is in every lane its rectangle overlaps, whatever it says — and toward the road end
//! (22); overruns of the end; rectangles leaving the road; speed, acceleration and
//! heading limits.

use super::{lateral_span, rectangles_overlap, Findings, Limits, Truth, LIMIT_TOL};

/// Pairs of `all` whose rectangles overlap (touching counts).
///
/// Swept along x: two rectangles whose centres are farther apart in x than the sum of
/// their half-diagonals cannot overlap, so each vehicle is tested against those after it
/// in x order up to the largest such sum (1 mm added against rounding) — every pair that
/// can overlap is tested, by the same test, and a world of thousands of vehicles costs
/// about n log n, not n² (tests/monitor.rs compares it with every pair).
pub fn collisions(all: &[Truth]) -> u64 {
    let half_diagonal = |c: &Truth| 0.5 * (c.length * c.length + c.width * c.width).sqrt();
    let widest = all.iter().map(half_diagonal).fold(0.0, f64::max);
    let reach = 2.0 * widest + 1e-3;
    let mut order: Vec<&Truth> = all.iter().collect();
    order.sort_by(|a, b| a.x.total_cmp(&b.x));
    let mut n = 0;
    for (i, a) in order.iter().enumerate() {
        for b in order.iter().skip(i + 1) {
            // Beyond reach: no later one is nearer in x. (A position that is not finite
            // is tested against every other, as before: it sorts last.)
            if b.x - a.x > reach && b.x.is_finite() {
                break;
            }
            if rectangles_overlap(a, b) {
                n += 1;
            }
        }
    }
    n
}

/// Whether follower `b`, `gap` (m, bumper to bumper) behind `a`, keeps its invariant
/// toward it. Lemma 3's, extent-adjusted: x_f < x̄ − dS(v_{t−h}(f)), dS at `b`'s own
/// braking limit. The leader-aware
/// one, when `b` keeps it and `a` is a cooperating vehicle: the same with x̄ moved ahead
/// by the exact least distance `a` still travels braking at the larger of the two limits
/// ([`least_travel`]) times cos θmax (along the road), and `b` behind `a` by more than
/// d0.
pub fn keeps_invariant(lim: &Limits, b: &Truth, a: &Truth, gap: f64) -> bool {
    let room = gap - lim.d0;
    let credit = if b.leader_aware && a.keeps_invariant && room > 0.0 {
        // Along the road: its heading stays within θmax.
        least_travel(a.v, a.brake.max(b.brake), lim.h) * lim.theta_max.cos()
    } else {
        0.0
    };
    room + credit > lim.safe_distance_at(b.v, b.brake)
}

/// The least distance a vehicle of this plant (speed constant over each period) still
/// travels once it has applied speed `v` over a period, braking at `brake` at most:
/// h Σ_{k≥1} max(0, v − brake k h), summed in closed form. Exact, where the planners
/// use a lower bound of it (planner_core::safety::least_travel): the monitor judges
/// the guarantee itself, not the planners' arithmetic.
pub fn least_travel(v: f64, brake: f64, h: f64) -> f64 {
    if !(v > 0.0 && brake > 0.0 && h > 0.0) {
        return 0.0;
    }
    let u = v / (brake * h);
    let n = u.floor();
    brake * h * h * (n * u - n * (n + 1.0) / 2.0)
}

/// The lanes of a road of `lanes` lanes ending at `end_x` (if it does), with its
/// vehicles `all` in its frame: the invariant between consecutive vehicles of each lane
/// (unless both are `mapped`: the junction's monitor judges those), the smallest gap,
/// the invariant of each lane's front vehicle toward the end, overruns of the end and
/// departures from the road.
pub fn lanes(f: &mut Findings, lim: &Limits, all: &[Truth], end_x: Option<f64>, lanes: u8) {
    let road_top = f64::from(lanes) * lim.lane_width;
    for lane in 0..lanes {
        let (lo, hi) = (
            f64::from(lane) * lim.lane_width,
            f64::from(lane + 1) * lim.lane_width,
        );
        let mut order: Vec<&Truth> = all
            .iter()
            .filter(|c| {
                let (bottom, top) = lateral_span(c);
                top > lo && bottom < hi
            })
            .collect();
        order.sort_by(|a, b| a.x.total_cmp(&b.x));
        for pair in order.windows(2) {
            let (b, a) = (pair[0], pair[1]);
            if b.mapped && a.mapped {
                continue;
            }
            let gap = a.x - b.x - 0.5 * (a.length + b.length);
            f.min_gap_m = f.min_gap_m.min(gap);
            if b.keeps_invariant && !keeps_invariant(lim, b, a, gap) {
                f.invariant_violations += 1;
            }
        }
        if let (Some(end), Some(c)) = (end_x, order.last()) {
            let room = end - c.x - 0.5 * c.length;
            if c.keeps_invariant && room - lim.d0 <= lim.safe_distance_at(c.v, c.brake) {
                f.invariant_violations += 1;
            }
        }
    }
    for c in all.iter().filter(|c| !c.mapped) {
        if let Some(end) = end_x {
            if end - c.x - 0.5 * c.length < 0.0 {
                f.road_end_overruns += 1;
            }
        }
        let (bottom, top) = lateral_span(c);
        if bottom < 0.0 || top > road_top {
            f.off_road += 1;
        }
    }
}

/// One vehicle's limits: heading within ±θmax of the road, speed in [0, vmax],
/// acceleration in [−its own braking limit, amax] (to [`LIMIT_TOL`]).
pub fn limits(f: &mut Findings, lim: &Limits, c: &Truth) {
    if c.theta.abs() > lim.theta_max + 1e-12 {
        f.limit_violations += 1;
    }
    let dv = c.v - c.v_before;
    if c.v < -LIMIT_TOL
        || c.v > lim.v_max + LIMIT_TOL
        || dv > lim.a_max * lim.h + LIMIT_TOL
        || dv < -c.brake * lim.h - LIMIT_TOL
    {
        f.limit_violations += 1;
    }
}
