//! Verification on the exact model: a command is applied only if the vehicle's L × W
//! rectangle stays in its band with its heading in bounds, now and along the certified
//! fallback's braking tail (max braking with maximal straightening) until it stops.

use super::MAX_TAIL_STEPS;
use crate::lanes::Band;
use crate::params::Params;
use crate::real::Real;
use crate::safety;
use crate::unicycle::{lateral_half_extent, step, Pose};

/// The fallback's yaw rate at speed v: turn toward θ = 0 as fast as ρmin allows.
#[inline]
pub fn straighten<F: Real>(p: &Params<F>, theta: F, v: F) -> F {
    let limit = v / p.rho_min();
    (-theta / p.h()).max(-limit).min(limit)
}

/// `true` if the rectangle at `pose` is inside the lanes `band` and its heading within
/// bounds.
#[inline]
pub(super) fn pose_ok<F: Real>(p: &Params<F>, pose: Pose<F>, band: Band<F>) -> bool {
    let ext = lateral_half_extent(p.length(), p.width(), pose.theta);
    band.lo <= pose.y - ext
        && pose.y + ext <= band.hi
        && p.theta_min() <= pose.theta
        && pose.theta <= p.theta_max()
}

/// `true` if the rectangle at `pose` overlaps the lane `band` (its interior).
pub(super) fn overlaps<F: Real>(p: &Params<F>, pose: Pose<F>, lane: Band<F>) -> bool {
    let ext = lateral_half_extent(p.length(), p.width(), pose.theta);
    pose.y + ext > lane.lo && pose.y - ext < lane.hi
}

/// The first step (0 = `pose` itself) of the braking tail from `pose` with v_{t−h} =
/// `v_prev` (max braking with maximal straightening, as [`braking_tail_ok`] simulates)
/// at which the rectangle overlaps `lane`; `None` if it stops first.
pub(super) fn first_overlap<F: Real>(
    p: &Params<F>,
    pose: Pose<F>,
    v_prev: F,
    lane: Band<F>,
) -> Option<usize> {
    let mut q = pose;
    let mut v = v_prev;
    for j in 0..MAX_TAIL_STEPS {
        if overlaps(p, q, lane) {
            return Some(j);
        }
        if !(v > F::ZERO) {
            return None;
        }
        if q.theta == F::ZERO {
            // Straight: y and θ stay as they are (see [`stops_within`]), so it never
            // overlaps; what is left is whether it stops within the cap.
            return if stops_within(p, v, MAX_TAIL_STEPS - j) {
                None
            } else {
                Some(MAX_TAIL_STEPS)
            };
        }
        v = safety::max_braking_command(p, v);
        q = step(q, v, straighten(p, q.theta, v), p.h());
    }
    // Not stopped within the cap: assume it enters at the end of it.
    Some(MAX_TAIL_STEPS)
}

/// Whether max braking from v_{t−h} = `v` reaches standstill within `steps` steps: what
/// the braking tail's loops decide once the heading is exactly 0. From θ = 0 the
/// straightening yaw rate is (−0/h) clamped = ±0, so the unicycle step adds d·sin(±0) = ±0
/// to y and ±0·h to θ: y and θ never change again, and neither do the pose checks. The
/// loops below skip the transcendental functions of those steps (they were ~95 % of the
/// certificate's cost during a lane change) and still return exactly what the full
/// simulation returns, cap included.
pub(super) fn stops_within<F: Real>(p: &Params<F>, mut v: F, steps: usize) -> bool {
    for _ in 0..steps {
        if !(v > F::ZERO) {
            return true;
        }
        v = safety::max_braking_command(p, v);
    }
    // As the loops do when their cap runs out (even on the step that reached 0).
    false
}

/// The certificate of the fallback: from `pose` with v_{t−h} = `v_prev`, max braking
/// with maximal straightening keeps the exact rectangle in the lanes `band` (edges, not
/// shrunk) and the heading within bounds at every step until standstill.
pub fn braking_tail_ok<F: Real>(p: &Params<F>, pose: Pose<F>, v_prev: F, band: Band<F>) -> bool {
    if !pose_ok(p, pose, band) {
        return false;
    }
    if pose.theta == F::ZERO {
        // Straight: y never changes.
        return true;
    }
    let mut q = pose;
    let mut v = v_prev;
    for i in 0..MAX_TAIL_STEPS {
        if !(v > F::ZERO) {
            return true;
        }
        v = safety::max_braking_command(p, v);
        let w = straighten(p, q.theta, v);
        q = step(q, v, w, p.h());
        if !pose_ok(p, q, band) {
            return false;
        }
        if q.theta == F::ZERO {
            // Straight from here on: the pose checks cannot change ([`stops_within`]).
            return stops_within(p, v, MAX_TAIL_STEPS - 1 - i);
        }
    }
    false
}

/// Verifies a plan (v_k, ω_k) of (13) on the exact unicycle: every state of the horizon
/// inside the lanes with its heading in bounds, and the fallback certificate from the
/// state after the first step. (The longitudinal constraints were verified on the speeds
/// with x_{k+1} − x_t ≤ h Σ v_j, which bounds the exact x since |cos θ| ≤ 1.)
pub fn verify_lateral<F: Real, const N: usize>(
    p: &Params<F>,
    pose: Pose<F>,
    v: &[F; N],
    omega: &[F; N],
    band: Band<F>,
) -> bool {
    let mut q = pose;
    let mut first = None;
    for (k, (&vk, &wk)) in v.iter().zip(omega.iter()).enumerate() {
        if !(wk.is_finite() && wk.abs() * p.rho_min() <= vk * (F::ONE + F::EPSILON)) {
            return false;
        }
        q = step(q, vk, wk, p.h());
        if !pose_ok(p, q, band) {
            return false;
        }
        if k == 0 {
            first = Some((q, vk));
        }
    }
    match first {
        Some((q1, v0)) => braking_tail_ok(p, q1, v0, band),
        None => true,
    }
}
