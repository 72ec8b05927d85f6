//! Independent monitors: safety from ground truth, and liveness.
//!
//! Written from the paper's definitions with its own formulas (it does not call
//! planner-core's safety functions), so that a bug there cannot hide itself here:
//! dS(v) is computed as (v + |amin| h)² / (2|amin|), the closed form of (8)(9).
//!
//! - [`geometry`]: rectangles and their overlap;
//! - [`road`]: collisions, and per lane of a road the invariant of Lemma 3, the road end,
//!   departures and limits;
//! - [`junction`]: the invariant along shared paths and IC Protocol (ii) at a junction;
//! - [`liveness`]: goals and the deadlock detector with its wait-for relation.

pub mod geometry;
pub mod junction;
pub mod liveness;
pub mod road;

pub use geometry::{lateral_span, rectangles_overlap};

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
        self.safe_distance_at(v, self.brake)
    }

    /// dS(v) for a vehicle braking at `brake` (m/s²): (v + brake h)² / (2 brake).
    pub fn safe_distance_at(&self, v: f64, brake: f64) -> f64 {
        let w = v + brake * self.h;
        w * w / (2.0 * brake)
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
    /// It keeps the leader-aware invariant toward a leader that keeps one too (a
    /// cooperating vehicle); else the paper's.
    pub leader_aware: bool,
    /// Its braking limit |amin| (m/s²).
    pub brake: f64,
    /// Speed applied over the last period, v_{t−h} (m/s).
    pub v: f64,
    /// Speed applied over the period before, v_{t−2h} (m/s).
    pub v_before: f64,
    /// A vehicle of a junction whose path lies on this road here (its inlet or outlet
    /// track): in the lanes it occupies like any other, but a pair of two such vehicles
    /// is the junction monitor's to judge (so no pair is counted twice).
    pub mapped: bool,
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
    /// Steps × vehicles inside A_S without a permission ever granted (IC Protocol (ii)).
    pub unpermitted_entries: u64,
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

    /// Checks every vehicle of one straight road at one instant (any order): collisions
    /// between every pair, the lanes (see [`road::lanes`]) and each vehicle's limits.
    pub fn check(&mut self, lim: &Limits, all: &[Truth], end_x: Option<f64>, lanes: u8) {
        self.collisions += road::collisions(all);
        road::lanes(self, lim, all, end_x, lanes);
        for c in all {
            road::limits(self, lim, c);
        }
    }
}
