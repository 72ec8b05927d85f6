//! The Lane Change Protocol's bookkeeping (16)–(18): the current lane ℓ, the intention α
//! and the change under way β — when a change is declared, when it may start (17), when
//! it completes, and re-centring afterwards.

use super::certify::{braking_tail_ok, pose_ok};
use super::reference::{recentre_length, Reference};
use super::{
    LaneEvent, LaneObservation, LanePlanner, StartBlock, CENTRED_M, MIN_CHANGE_LENGTH_M,
    NOTIFY_SLACK_S, RECENTRE_M, STALE_AFTER_S, STRAIGHT_HEADING_RAD,
};
use crate::free_space::{FreeSpace, D_TURN_M};
use crate::planner::free_road_gap;
use crate::real::Real;
use crate::safety;
use crate::solver::MpcSolver;

impl<F: Real, const N: usize, S: MpcSolver<F, N>> LanePlanner<F, N, S> {
    /// The entry check (RSS-style: the ego, changing into `m`, may put its
    /// rectangle into lane `m` at `lead` from now only if every vehicle that may be in `m`
    /// behind it could stop behind it then even had it never heard of the change — moving
    /// unaware, at up to amax, for the age of the ego's data of it plus `lead`. The
    /// paper's (17) at the start assumes the others hear the ego's α within a period and
    /// yield; on a bus that loses or delays messages without bound, or toward a vehicle
    /// that does not cooperate, nothing else keeps it safe. Aware vehicles keep room for
    /// this check ([`LanePlanner::entry_allowance`]), so on a working bus it passes.
    pub(super) fn entry_ok(&self, obs: &LaneObservation<'_, F>, m: u8, lead: F) -> bool {
        self.for_each_behind(obs, m, |c, cx, cv, _| {
            if self.clear_of(obs, c, cx, cv, c.age + lead) {
                Ok(())
            } else {
                Err(StartBlock::Behind(c.id))
            }
        })
        .is_ok()
    }

    /// The Lane Change Protocol (16)(17) for a change into `m`, with (17) tested against
    /// every vehicle of C⁻_t (18) (SPEC's choice), each inflated for the age of its data
    /// plus the notification latency beyond one period (SPEC §9: at most amax faster, see
    /// `unaware_reach`), and the free-space condition of Lemma 8 for the widened band.
    /// A vehicle that does not cooperate will not hear the change: toward it (17) must
    /// hold as if the ego entered its lane now (the test of the private
    /// `LanePlanner::entry_ok`).
    /// `Ok` when a change into `m` may start now; otherwise the first condition that fails.
    pub fn start_check(&self, obs: &LaneObservation<'_, F>, m: u8) -> Result<(), StartBlock> {
        let p = self.params();
        if !(obs.pose.theta.abs() <= F::from_f64(STRAIGHT_HEADING_RAD)) {
            return Err(StartBlock::Heading);
        }
        let (_, all) = self.gaps(obs, Some(m), None);
        let free = free_road_gap(p, N);
        let gap = all.map_or(free, |g| g.min(free));
        // (16): x_t < x̄_t − dS(v_{t−h}) with the planner's margin.
        if !safety::invariant_holds(p, obs.v_prev, gap - F::SAFETY_MARGIN_M) {
            return Err(StartBlock::Ahead);
        }
        // (17) for every c ∈ C⁻_t; stale data behind blocks the start (SPEC §9).
        let unaware = self.notify - p.h();
        let stale_after = unaware + F::from_f64(STALE_AFTER_S);
        self.for_each_behind(obs, m, |c, cx, cv, cooperative| {
            if !(c.age <= stale_after) {
                return Err(StartBlock::Stale(c.id));
            }
            let tau = c.age + if cooperative { unaware } else { p.h() };
            if self.clear_of(obs, c, cx, cv, tau) {
                Ok(())
            } else {
                Err(StartBlock::Behind(c.id))
            }
        })?;
        // Lemma 8 (i)(ii) in the widened band.
        let band = obs
            .road
            .band(self.lane, Some(m))
            .shrunk(F::HALF * p.width());
        match FreeSpace::new(p, obs.pose, obs.v_prev, obs.omega_prev, band, gap) {
            Ok(fs) if fs.d_h > fs.d_l && fs.lemma5_angles() => Ok(()),
            _ => Err(StartBlock::FreeSpace),
        }
    }

    /// A change under way whose S-curve has been driven but that has not come within
    /// [`CENTRED_M`] of lane `m`'s centre (a fallback or a yield bent it off its curve):
    /// a new S-curve from where the vehicle is to the centre, over [`recentre_length`].
    /// Without it the lateral QP alone closes the rest only over hundreds of metres, and
    /// a vehicle near a road end stops there short of the centre, unable to steer at
    /// standstill (the dead-end sweep's sweep, case 536 of 2,000).
    pub(super) fn rejoin(&mut self, obs: &LaneObservation<'_, F>, m: u8) {
        let centre = obs.road.lane_centre(m);
        let driven = self.reference.is_none_or(|r| obs.pose.x >= r.x0 + r.len);
        if driven && (obs.pose.y - centre).abs() > F::HALF * F::from_f64(CENTRED_M) {
            self.reference = Some(Reference {
                x0: obs.pose.x,
                y0: obs.pose.y,
                y1: centre,
                len: recentre_length(obs.v_prev),
            });
        }
    }

    /// With no change under way: the S-curve back to the centre line ([`RECENTRE_M`]),
    /// dropped once driven.
    pub(super) fn recentre(&mut self, obs: &LaneObservation<'_, F>) {
        if self.alpha.is_some() {
            return;
        }
        if self.reference.is_some_and(|r| obs.pose.x >= r.x0 + r.len) {
            self.reference = None;
        }
        let centre = obs.road.lane_centre(self.lane);
        if self.reference.is_none() && (obs.pose.y - centre).abs() > F::from_f64(RECENTRE_M) {
            self.reference = Some(Reference {
                x0: obs.pose.x,
                y0: obs.pose.y,
                y1: centre,
                len: recentre_length(obs.v_prev),
            });
        }
    }

    /// Protocol bookkeeping at the start of a step: completes, declares or starts a change.
    pub(super) fn update_lanes(&mut self, obs: &LaneObservation<'_, F>) -> Option<LaneEvent> {
        let p = *self.params();
        if let Some(m) = self.alpha {
            let lane_m = obs.road.band(m, None);
            let centre = obs.road.lane_centre(m);
            let centred = (obs.pose.y - centre).abs() <= F::from_f64(CENTRED_M);
            // The tail's certificate starts with the pose itself: the rectangle inside
            // lane m, with its heading in bounds.
            let straight = obs.pose.theta.abs() <= F::from_f64(STRAIGHT_HEADING_RAD);
            if (centred && straight && braking_tail_ok(&p, obs.pose, obs.v_prev, lane_m))
                || stopped_inside(&p, obs, lane_m, centre)
            {
                self.lane = m;
                self.alpha = None;
                self.reference = None;
                return Some(LaneEvent::Completed(m));
            }
            self.rejoin(obs, m);
            return None;
        }
        if obs.target_lane == self.lane {
            self.beta = None;
            self.beta_steps = 0;
            return None;
        }
        let want = if obs.target_lane > self.lane {
            self.lane + 1
        } else {
            self.lane.saturating_sub(1)
        };
        if self.beta != Some(want) {
            self.beta = Some(want);
            self.beta_steps = 0;
            return Some(LaneEvent::Declared(want));
        }
        // Start only once the intention has been out for the notification bound (one
        // broadcast period on the paper's bus), so that every vehicle that could start a
        // conflicting change this step already treats the ego by (21).
        let held = F::from_f64(f64::from(self.beta_steps)) * p.h();
        if self.beta_steps >= 1
            && held >= self.notify - F::from_f64(NOTIFY_SLACK_S)
            && self.start_check(obs, want).is_ok()
        {
            self.alpha = Some(want);
            self.beta = None;
            self.beta_steps = 0;
            let dy = obs.road.lane_centre(want) - obs.pose.y;
            // Length of Lemma 12's manoeuvre at the allowed radius: a quintic's peak
            // curvature is 5.77 Δy / len², so len = sqrt(5.77 |Δy| ρ).
            let band = obs
                .road
                .band(self.lane, Some(want))
                .shrunk(F::HALF * p.width());
            let free = safety::d_s(&p, obs.v_prev) + F::from_f64(D_TURN_M);
            let kappa = FreeSpace::new(&p, obs.pose, obs.v_prev, obs.omega_prev, band, free)
                .map(|fs| {
                    if dy > F::ZERO {
                        fs.arc_h.kappa_plus
                    } else {
                        fs.arc_h.kappa_minus
                    }
                })
                .unwrap_or(F::ZERO);
            let rho = if kappa > F::ZERO {
                F::ONE / kappa
            } else {
                p.rho_min()
            };
            let len = (F::from_f64(5.77) * dy.abs() * rho.max(p.rho_min()))
                .sqrt()
                .max(F::from_f64(MIN_CHANGE_LENGTH_M));
            self.reference = Some(Reference {
                x0: obs.pose.x,
                y0: obs.pose.y,
                y1: obs.road.lane_centre(want),
                len,
            });
            return Some(LaneEvent::Started(want));
        }
        None
    }
}

/// A change that stopped short of the centre line ends where it stands, if the rectangle
/// is already inside lane `m` (`lane_m`, edges not shrunk) with its heading in bounds and
/// pointing toward `centre`. A unicycle cannot turn at standstill ((31) bounds the yaw
/// rate by v over the radius), so a vehicle whose leader in lane `m` stopped at a road
/// end stands there half-way through its S-curve for good: not centred, not straight,
/// still counted in both lanes, and the queue behind it in the lane it left stops
/// behind a vehicle that is no longer there (the dead-end sweep's case 24 of seed
/// 3,712,032,153 under the leader-aware invariant). Safe, as standstill is: the braking
/// tail from v = 0 is the pose itself, which is inside lane `m`. Live: heading toward
/// the centre, the first metres it drives take it away from the edge it is nearest and
/// straightening swings its rear corner inward too, so the re-centring S-curve
/// ([`RECENTRE_M`]) can always start — unlike a straight vehicle stopped by an edge,
/// which the [`CENTRED_M`] rule keeps in its change.
fn stopped_inside<F: Real>(
    p: &crate::params::Params<F>,
    obs: &LaneObservation<'_, F>,
    lane_m: crate::lanes::Band<F>,
    centre: F,
) -> bool {
    !(obs.v_prev > F::ZERO)
        && (centre - obs.pose.y) * obs.pose.theta > F::ZERO
        && pose_ok(p, obs.pose, lane_m)
}
