//! Yaw rates: the linearised lateral QP of [`crate::lateral`] along the reference, inside
//! the band and Ω, and the straightening plan when the QP has nothing better.

use super::certify::{first_overlap, overlaps, straighten};
use super::{LaneObservation, LanePlanner, HEADING_MARGIN_RAD, LATERAL_MARGIN_M};
use crate::free_space::FreeSpace;
use crate::lanes::Band;
use crate::lateral::{solve_lateral_in, LateralInput};
use crate::params::Params;
use crate::real::Real;
use crate::solver::MpcSolver;
use crate::unicycle::{lateral_half_extent, step, Pose};

/// ω_k clamped into Ω^k_t (31) exactly.
pub(super) fn clamp_to_omega<F: Real, const N: usize>(
    fs: &FreeSpace<F>,
    v: &[F; N],
    mut w: [F; N],
) -> [F; N] {
    for (wk, &vk) in w.iter_mut().zip(v.iter()) {
        let (lo, hi) = fs.omega_bounds(vk);
        *wk = wk.max(lo).min(hi);
    }
    w
}

/// Straightening yaw rates along a speed plan (used when the lateral QP has no answer).
pub(super) fn straightening_plan<F: Real, const N: usize>(
    p: &Params<F>,
    theta: F,
    v: &[F; N],
) -> [F; N] {
    let mut th = theta;
    let mut out = [F::ZERO; N];
    for (o, &vk) in out.iter_mut().zip(v.iter()) {
        *o = straighten(p, th, vk);
        th += *o * p.h();
    }
    out
}

/// The band the lateral QP keeps the rectangle in: `lanes` tightened by
/// [`LATERAL_MARGIN_M`] on each side, but never by more than the clearance the rectangle
/// has there now. A vehicle closer to an edge than the margin would otherwise make the
/// QP's own start state infeasible; the QP then fails every step and the straightening
/// plan pins θ at 0 (the dead-end sweep's failures). The exact check
/// ([`verify_lateral`]) is on the untightened lanes.
pub(super) fn qp_band<F: Real>(p: &Params<F>, pose: Pose<F>, lanes: Band<F>) -> (F, F) {
    let margin = F::from_f64(LATERAL_MARGIN_M);
    let ext = lateral_half_extent(p.length(), p.width(), pose.theta);
    let below = (pose.y - ext - lanes.lo).max(F::ZERO);
    let above = (lanes.hi - pose.y - ext).max(F::ZERO);
    (lanes.lo + margin.min(below), lanes.hi - margin.min(above))
}

impl<F: Real, const N: usize, S: MpcSolver<F, N>> LanePlanner<F, N, S> {
    /// The yaw rates for the speed plan `v_plan`: the lateral QP about the previous plan,
    /// clamped into Ω^k_t (31), or the straightening plan if the QP has no answer; and the
    /// QP's iterations. Not inlined into [`LanePlanner::step`]: its references and the
    /// QP then take stack only while the lateral part runs, not beside the speed solve
    ///.
    #[inline(never)]
    pub(super) fn plan_lateral(
        &mut self,
        obs: &LaneObservation<'_, F>,
        fs: &FreeSpace<F>,
        v_plan: &[F; N],
        lanes: Band<F>,
    ) -> ([F; N], u32) {
        let p = *self.params();
        let centre = obs.road.lane_centre(self.lane);
        let mut y_ref = [F::ZERO; N];
        let mut th_ref = [F::ZERO; N];
        let mut lo = [F::ZERO; N];
        let mut hi = [F::ZERO; N];
        let mut x = obs.pose.x;
        for (k, &vk) in v_plan.iter().enumerate() {
            x += vk * p.h();
            let (y, th) = match self.reference {
                Some(r) => r.at(x),
                None => (centre, F::ZERO),
            };
            let (l, u) = fs.omega_bounds(vk);
            if let (Some(a), Some(b), Some(c), Some(d)) = (
                y_ref.get_mut(k),
                th_ref.get_mut(k),
                lo.get_mut(k),
                hi.get_mut(k),
            ) {
                *a = y;
                *b = th;
                *c = l;
                *d = u;
            }
        }
        let nominal = crate::planner::shifted(&self.omega_plan);
        let tm = F::from_f64(HEADING_MARGIN_RAD);
        let input = LateralInput {
            h: p.h(),
            y: obs.pose.y,
            theta: obs.pose.theta,
            omega_prev: obs.omega_prev,
            v: v_plan,
            omega_nominal: &nominal,
            y_ref: &y_ref,
            theta_ref: &th_ref,
            omega_lo: &lo,
            omega_hi: &hi,
            theta_bounds: (p.theta_min() + tm, p.theta_max() - tm),
            band: qp_band(&p, obs.pose, lanes),
            half_length: F::HALF * p.length(),
            half_width: F::HALF * p.width(),
            weights: self.lateral_weights,
        };
        match solve_lateral_in(&mut self.lateral, &input) {
            Ok((w, it)) => (clamp_to_omega(fs, v_plan, w), it),
            Err(_) => (straightening_plan(&p, obs.pose.theta, v_plan), 0),
        }
    }

    /// The entry check ([`LanePlanner::entry_ok`]) for a plan: while a change into m has
    /// not yet put the ego's rectangle into lane m, a plan is accepted only if neither its
    /// first step nor the certified fallback from there (the braking tail) enters m before
    /// the vehicles that may be there behind could stop for it. So the fallback, applied
    /// when a later step finds no plan, is safe here too.
    pub(super) fn entering_ok(
        &self,
        obs: &LaneObservation<'_, F>,
        v: &[F; N],
        omega: &[F; N],
    ) -> bool {
        let Some(m) = self.alpha else {
            return true;
        };
        let p = self.params();
        let lane_m = obs.road.band(m, None);
        if overlaps(p, obs.pose, lane_m) {
            return true;
        }
        let (Some(&v0), Some(&w0)) = (v.first(), omega.first()) else {
            return true;
        };
        let q1 = step(obs.pose, v0, w0, p.h());
        match first_overlap(p, q1, v0, lane_m) {
            None => true,
            Some(j) => self.entry_ok(obs, m, p.h() * F::from_usize(j + 1)),
        }
    }
}
