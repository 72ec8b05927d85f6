//! Independent safety monitor for single-lane traffic.
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
    /// Centre position (m).
    pub x: f64,
    /// Length (m).
    pub length: f64,
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
    /// Smallest bumper-to-bumper gap seen (m).
    pub min_gap_m: f64,
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

    /// Checks one lane at one instant. `lane` may be in any order.
    pub fn check_lane(&mut self, lim: &Limits, lane: &[Truth]) {
        let mut order: Vec<&Truth> = lane.iter().collect();
        order.sort_by(|a, b| a.x.total_cmp(&b.x));
        for pair in order.windows(2) {
            let (f, l) = (pair[0], pair[1]);
            let gap = l.x - f.x - 0.5 * (l.length + f.length);
            self.min_gap_m = self.min_gap_m.min(gap);
            if gap <= 0.0 {
                self.collisions += 1;
            }
            // Lemma 3's invariant, extent-adjusted (SPEC §1): x_f < x̄ − dS(v_{t−h}(f)).
            if gap - lim.d0 <= lim.safe_distance(f.v) {
                self.invariant_violations += 1;
            }
        }
        for c in lane {
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
