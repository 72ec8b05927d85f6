//! Independent safety monitor.
//!
//! Written from the paper's definitions with its own formulas (it does not call
//! planner-core's safety functions), so that a bug there cannot hide itself here:
//! dS(v) is computed as (v + |amin| h)² / (2|amin|), the closed form of (8)(9).

/// Limits the monitor checks against (raw Table I values).
#[derive(Debug, Clone, Copy)]
pub struct Limits {
    /// vmax (m/s).
    pub v_max: f64,
    /// amax (m/s²).
    pub a_max: f64,
    /// |amin| (m/s²).
    pub brake: f64,
    /// h (s).
    pub h: f64,
    /// d0 (m).
    pub d0: f64,
    /// Heading bound |θ| ≤ θmax relative to the road (rad).
    pub theta_max: f64,
    /// Lane width Wl (m): lane j spans y ∈ [j Wl, (j+1) Wl].
    pub lane_width: f64,
}

impl Limits {
    /// Table I / SPEC §1.
    pub fn table_i() -> Self {
        Self {
            v_max: 27.8,
            a_max: 3.8,
            brake: 7.9,
            h: 0.01,
            d0: 0.5,
            theta_max: std::f64::consts::FRAC_PI_6,
            lane_width: 3.6,
        }
    }

    /// dS(v) by the identity dS(v) = (v + |amin| h)² / (2|amin|).
    pub fn safe_distance(&self, v: f64) -> f64 {
        let w = v + self.brake * self.h;
        w * w / (2.0 * self.brake)
    }
}

/// One vehicle as the simulator knows it (ground truth).
#[derive(Debug, Clone, Copy)]
pub struct Truth {
    /// Centre position along the road (m).
    pub x: f64,
    /// Lateral centre position (m).
    pub y: f64,
    /// Heading relative to the road (rad).
    pub theta: f64,
    /// Length (m).
    pub length: f64,
    /// Width (m).
    pub width: f64,
    /// Lane the vehicle says it is in (informational: the monitor judges lanes by the
    /// rectangle's own footprint).
    pub lane: u8,
    /// Whether this vehicle is responsible for the invariant toward its leader (planner
    /// driven); scripted drivers lead their lanes and are not.
    pub keeps_invariant: bool,
    /// Speed applied over the last period, v_{t−h} (m/s).
    pub v: f64,
    /// Speed applied over the period before, v_{t−2h} (m/s).
    pub v_before: f64,
}

/// What the monitor found so far.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Findings {
    /// Steps × pairs where the rectangles overlapped (bumper gap ≤ 0).
    pub collisions: u64,
    /// Steps × pairs where x_t(follower) < x̄ − dS(v_{t−h}) failed.
    pub invariant_violations: u64,
    /// Steps × vehicles with speed outside [0, vmax] or acceleration outside its limits.
    pub limit_violations: u64,
    /// Steps × vehicles whose front bumper was past the road end x_R.
    pub road_end_overruns: u64,
    /// Smallest bumper-to-bumper gap seen (m).
    pub min_gap_m: f64,
    /// Steps × vehicles whose rectangle left the road (y outside [0, lanes · Wl]).
    pub off_road: u64,
}

/// Tolerance on speed and acceleration limits: rounding of one f32 speed (2⁻²⁴ × 28 m/s),
/// so that f32 planners are judged fairly.
pub const LIMIT_TOL: f64 = 4e-6;

impl Findings {
    /// A fresh record.
    pub fn new() -> Self {
        Self {
            min_gap_m: f64::INFINITY,
            ..Self::default()
        }
    }

    /// Checks every vehicle at one instant (any order): collisions between every pair
    /// (oriented rectangles); the invariant between consecutive vehicles of each lane —
    /// a vehicle is in every lane its rectangle overlaps, whatever it says — and, for
    /// each lane's front vehicle, toward the road end `end_x` (22); road departures on
    /// a road of `lanes` lanes; and each vehicle's limits.
    pub fn check(&mut self, lim: &Limits, all: &[Truth], end_x: Option<f64>, lanes: u8) {
        for (i, a) in all.iter().enumerate() {
            for b in all.iter().skip(i + 1) {
                if rectangles_overlap(a, b) {
                    self.collisions += 1;
                }
            }
        }
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
                let (f, l) = (pair[0], pair[1]);
                let gap = l.x - f.x - 0.5 * (l.length + f.length);
                self.min_gap_m = self.min_gap_m.min(gap);
                // Lemma 3's invariant, extent-adjusted (SPEC §1): x_f < x̄ − dS(v_{t−h}(f)).
                if f.keeps_invariant && gap - lim.d0 <= lim.safe_distance(f.v) {
                    self.invariant_violations += 1;
                }
            }
            if let (Some(end), Some(c)) = (end_x, order.last()) {
                let room = end - c.x - 0.5 * c.length;
                if c.keeps_invariant && room - lim.d0 <= lim.safe_distance(c.v) {
                    self.invariant_violations += 1;
                }
            }
        }
        for c in all {
            if let Some(end) = end_x {
                if end - c.x - 0.5 * c.length < 0.0 {
                    self.road_end_overruns += 1;
                }
            }
            let (bottom, top) = lateral_span(c);
            if bottom < 0.0 || top > road_top {
                self.off_road += 1;
            }
            if c.theta.abs() > lim.theta_max + 1e-12 {
                self.limit_violations += 1;
            }
            let dv = c.v - c.v_before;
            if c.v < -LIMIT_TOL
                || c.v > lim.v_max + LIMIT_TOL
                || dv > lim.a_max * lim.h + LIMIT_TOL
                || dv < -lim.brake * lim.h - LIMIT_TOL
            {
                self.limit_violations += 1;
            }
        }
    }
}

/// The y-range [bottom, top] the rectangle covers.
pub fn lateral_span(c: &Truth) -> (f64, f64) {
    let ext = 0.5 * (c.length * c.theta.sin().abs() + c.width * c.theta.cos().abs());
    (c.y - ext, c.y + ext)
}

/// Separating-axis test for two oriented L × W rectangles (touching counts as overlap).
pub fn rectangles_overlap(a: &Truth, b: &Truth) -> bool {
    let reach = 0.5 * (a.length.hypot(a.width) + b.length.hypot(b.width));
    if (a.x - b.x).abs() > reach || (a.y - b.y).abs() > reach {
        return false;
    }
    let corners = |t: &Truth| {
        let (s, c) = t.theta.sin_cos();
        let (hl, hw) = (0.5 * t.length, 0.5 * t.width);
        [(hl, hw), (hl, -hw), (-hl, -hw), (-hl, hw)]
            .map(|(u, w)| (t.x + u * c - w * s, t.y + u * s + w * c))
    };
    let (ca, cb) = (corners(a), corners(b));
    let axes = |t: &Truth| {
        let (s, c) = t.theta.sin_cos();
        [(c, s), (-s, c)]
    };
    for (ax, ay) in axes(a).into_iter().chain(axes(b)) {
        let project = |cs: &[(f64, f64); 4]| {
            cs.iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &(x, y)| {
                    let p = x * ax + y * ay;
                    (lo.min(p), hi.max(p))
                })
        };
        let (a0, a1) = project(&ca);
        let (b0, b1) = project(&cb);
        if a1 < b0 || b1 < a0 {
            return false;
        }
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    fn car(x: f64, y: f64, theta: f64) -> Truth {
        Truth {
            x,
            y,
            theta,
            length: 4.5,
            width: 1.7,
            lane: 0,
            keeps_invariant: true,
            v: 0.0,
            v_before: 0.0,
        }
    }

    #[test]
    fn rectangle_overlap_cases() {
        assert!(rectangles_overlap(&car(0.0, 0.0, 0.0), &car(4.4, 0.0, 0.0)));
        assert!(!rectangles_overlap(
            &car(0.0, 0.0, 0.0),
            &car(4.6, 0.0, 0.0)
        ));
        assert!(!rectangles_overlap(
            &car(0.0, 0.0, 0.0),
            &car(0.0, 1.8, 0.0)
        ));
        assert!(rectangles_overlap(&car(0.0, 0.0, 0.0), &car(0.0, 1.6, 0.0)));
        // Rotated 90°: B spans 1.7 m in x, so they touch while |dx| ≤ 2.25 + 0.85 = 3.1.
        let r = car(3.0, 0.0, std::f64::consts::FRAC_PI_2);
        assert!(rectangles_overlap(&car(0.0, 0.0, 0.0), &r));
        let r = car(3.2, 0.0, std::f64::consts::FRAC_PI_2);
        assert!(!rectangles_overlap(&car(0.0, 0.0, 0.0), &r));
        // 45°: at (3.6, 2.2) B's edge crosses A near (2.25, 0.37); at (4.0, 2.6) it misses
        // A although the bounding boxes still overlap, so only B's own axes separate them.
        let d = car(3.6, 2.2, std::f64::consts::FRAC_PI_4);
        assert!(rectangles_overlap(&car(0.0, 0.0, 0.0), &d));
        let d = car(4.0, 2.6, std::f64::consts::FRAC_PI_4);
        assert!(!rectangles_overlap(&car(0.0, 0.0, 0.0), &d));
    }
}
