//! Who is around and how far (Sec. IV–V): the front set (15) and the yield set (21) from
//! what was heard and sensed, the gap x̄ to the nearest constraint ahead, and what a
//! cooperating leader is credited under the leader-aware invariant; vehicles behind in
//! a target lane, fused from V2V and the range sensors, for the start check (17).

use super::{round_to, LaneObservation, LanePlanner, StartBlock};
use crate::lanes::{in_front_set, in_yield_set, may_occupy, Key, Other};
use crate::params::Params;
use crate::real::Real;
use crate::safety::{self, Invariant};
use crate::sensing::still_unheard;
use crate::solver::MpcSolver;

/// Membership in the yield set (21), with ≺ decided on where the other vehicle is now by
/// its data (x + v·age): on a bus with latency two vehicles side by side each see the
/// other behind by its data's age, and neither would yield. Exact with age 0.
/// Positions are rounded to the bus's step (`step`), as the ego's own key is.
pub(super) fn yields_to<F: Real>(
    ego: &Key<F>,
    alpha: Option<u8>,
    beta: Option<u8>,
    c: &Other<F>,
    step: F,
) -> bool {
    let now = Other {
        x: round_to(c.x + c.v * c.age, step),
        ..*c
    };
    in_yield_set(ego, alpha, beta, &now)
}

/// The smaller of two optional gaps (`None`: no obstacle).
pub(super) fn min_gap<F: Real>(a: Option<F>, b: Option<F>) -> Option<F> {
    match (a, b) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    }
}

/// How far a vehicle last seen at speed `v` may have gone in `tau` and how fast it may be
/// by then (SPEC §9: at most amax faster per second, never above vmax).
pub(super) fn unaware_reach<F: Real>(p: &Params<F>, v: F, tau: F) -> (F, F) {
    let accel = v * tau + F::HALF * p.a_max() * tau * tau;
    let reach = accel.min(p.v_max() * tau);
    (reach, (v + tau * p.a_max()).min(p.v_max()))
}

impl<F: Real, const N: usize, S: MpcSolver<F, N>> LanePlanner<F, N, S> {
    /// x̄_t − x_t over the vehicles selected by `select` and the road end (22),
    /// extent-adjusted, and over space the ego cannot vouch for (see
    /// [`LanePlanner::unknown_ahead`]); `None` if there is no obstacle.
    pub(super) fn gap_over(
        &self,
        obs: &LaneObservation<'_, F>,
        select: impl Fn(&Other<F>) -> bool,
    ) -> Option<F> {
        let p = self.params();
        let end = obs
            .road
            .end_x
            .map(|xr| xr - F::HALF * p.length() - p.d0() - obs.pose.x);
        let known = min_gap(end, self.leader_gap(obs, select, |_| true));
        min_gap(known, self.unknown_ahead())
    }

    /// Where space ahead stops being known (as x̄_t − x_t), if it does. With sensors:
    /// the end of the forward range, as if a stopped vehicle stood just beyond it. Without
    /// (the paper's world): nowhere, except until the notification bound has passed since
    /// the first step — a vehicle may then not yet have heard of one just ahead (off the ideal world:
    /// a follower at the smallest safe gap accelerated for a period of bus delay before
    /// it first heard its braking leader), so it takes the road ahead as blocked at once
    /// and brakes, which is safe whatever is there.
    pub(super) fn unknown_ahead(&self) -> Option<F> {
        let p = self.params();
        match &self.sensing {
            Some(s) => Some(s.ahead_m - p.d0()),
            None => still_unheard(self.steps, p.h(), self.notify).then_some(F::ZERO),
        }
    }

    /// The sensing error bounds (position m, speed m/s); zero without sensors.
    pub(super) fn errors(&self) -> (F, F) {
        self.sensing.map_or((F::ZERO, F::ZERO), |s| {
            (s.position_error_m, s.speed_error_mps)
        })
    }

    /// The least x a vehicle ahead can have: a sensor return may be `position_error_m`
    /// further back than measured; a V2V position only grows after its stamp (v ≥ 0), so
    /// it is used as stamped, never extrapolated.
    pub(super) fn nearest_x(&self, c: &Other<F>) -> F {
        if c.sensed {
            c.x - self.errors().0
        } else {
            c.x
        }
    }

    /// x̄_t − x_t over the vehicles selected by `select` alone, extent-adjusted.
    pub(super) fn vehicle_gap(
        &self,
        obs: &LaneObservation<'_, F>,
        select: impl Fn(&Other<F>) -> bool,
    ) -> Option<F> {
        let p = self.params();
        // Half a position step at each end: the true rear of a vehicle heard at c.x.
        let len = p.length() + self.resolution.position;
        obs.others
            .iter()
            .filter(|c| select(c))
            .map(|c| self.nearest_x(c) - F::HALF * (c.length + len) - p.d0() - obs.pose.x)
            .reduce(|a, b| a.min(b))
    }

    /// x̄_t − x_t toward the vehicles selected by `select` under the invariant in use:
    /// [`LanePlanner::vehicle_gap`], those of them `credited` selects credited under
    /// [`Invariant::LeaderAware`] with [`LanePlanner::credit`].
    pub(super) fn leader_gap(
        &self,
        obs: &LaneObservation<'_, F>,
        select: impl Fn(&Other<F>) -> bool,
        credited: impl Fn(&Other<F>) -> bool,
    ) -> Option<F> {
        if self.invariant == Invariant::Paper {
            return self.vehicle_gap(obs, select);
        }
        let p = self.params();
        let len = p.length() + self.resolution.position;
        obs.others
            .iter()
            .filter(|c| select(c))
            .map(|c| {
                let raw = self.nearest_x(c) - F::HALF * (c.length + len) - p.d0() - obs.pose.x;
                if credited(c) {
                    raw + self.credit(c, raw)
                } else {
                    raw
                }
            })
            .reduce(|a, b| a.min(b))
    }

    /// What a vehicle ahead at wall distance `raw` is credited with under the
    /// leader-aware invariant: the least distance it still travels from its stamped
    /// speed (the speed taken half a bus step lower, as the bus may have rounded it up),
    /// if it is known over V2V with a braking limit (one a cooperating vehicle declared,
    /// from its last trusted message: [`Other::brake`]) and it leads ([`safety::leads`]
    /// with its [`LanePlanner::ghost`]: a vehicle beside or behind the ego's front is no
    /// leader, and its stop point says nothing about the ego's way to it). However old
    /// the message: the bound stays valid, and a follower that used it may be past the
    /// stamped position by now (docs/spec.md §11, "A credit is never withdrawn").
    pub(super) fn credit(&self, c: &Other<F>, raw: F) -> F {
        let p = self.params();
        match c.brake {
            Some(b) if !c.sensed => {
                let v = c.v - F::HALF * self.resolution.speed;
                safety::credit_if_leads(p, v, b.mps2(), raw, c.age)
            }
            _ => F::ZERO,
        }
    }

    /// Under the leader-aware invariant, how far past its stamped position a vehicle
    /// that may be credited is at the least by now ([`safety::ghost_advance`]); 0 under
    /// the paper's invariant, for sensor returns and for vehicles without a limit.
    pub(super) fn ghost(&self, c: &Other<F>) -> F {
        match c.brake {
            Some(b) if self.invariant == Invariant::LeaderAware && !c.sensed => {
                let v = c.v - F::HALF * self.resolution.speed;
                safety::ghost_advance(self.params(), v, b.mps2(), c.age)
            }
            _ => F::ZERO,
        }
    }

    /// Extra room a vehicle at speed `v` needs so that, after `tau` of moving unseen, it
    /// still satisfies the invariant: the distance it may cover plus its stopping
    /// distance's growth.
    pub(super) fn unaware_margin(&self, v: F, tau: F) -> F {
        let p = self.params();
        let (reach, v_up) = unaware_reach(p, v, tau);
        reach + safety::d_s(p, v_up) - safety::d_s(p, v)
    }

    /// The room this vehicle keeps, beyond the invariant, toward a vehicle that is
    /// entering or wants to enter one of its lanes, so that the other's entry check
    /// ([`LanePlanner::entry_ok`]) passes: that check takes this vehicle at its worst
    /// case — measured with the sensing error bounds, and moving unaware for the age of
    /// the other's data of it plus a period. Aware vehicles keep that much more room, or
    /// the other could never enter in front of one that follows it closely.
    /// τ = max(h, 2(notify − h)) covers data up to the notification bound old.
    pub(super) fn entry_allowance(&self, v: F) -> F {
        let p = self.params();
        let (e, ev) = self.errors();
        let tau = p.h().max(F::TWO * (self.notify - p.h()));
        F::TWO * e + self.unaware_margin(v + ev, tau) + safety::d_s(p, v + ev) - safety::d_s(p, v)
    }

    /// This vehicle in ≺, as the others hear it (rounded to the bus's steps).
    pub(super) fn key(&self, obs: &LaneObservation<'_, F>) -> Key<F> {
        let r = self.resolution;
        Key {
            x: round_to(obs.pose.x, r.position),
            v: round_to(obs.v_prev, r.speed),
            lane: self.lane,
            id: u16::MAX,
        }
    }

    /// The gaps toward (15) alone and toward (15) ∪ (21), for lanes {ℓ, α} and intention β.
    pub(super) fn gaps(
        &self,
        obs: &LaneObservation<'_, F>,
        alpha: Option<u8>,
        beta: Option<u8>,
    ) -> (Option<F>, Option<F>) {
        let key = self.key(obs);
        let x = obs.pose.x;
        let lane = self.lane;
        let mine = |j: u8| j == lane || Some(j) == alpha;
        // A return up to `e` behind the ego may be ahead of it.
        let e = self.errors().0;
        // A vehicle that may be credited is ahead by its ghost: the least it has moved
        // since its stamp (a leader this vehicle follows closely is past its old stamp).
        let ahead = |c: &Other<F>| Other {
            x: if c.sensed {
                c.x + e
            } else {
                c.x + self.ghost(c)
            },
            ..*c
        };
        // (15). While changing into α, also whatever may be entering α unheard of.
        let front = |c: &Other<F>| {
            in_front_set(x, lane, alpha, &ahead(c))
                || alpha
                    .is_some_and(|m| x <= ahead(c).x && may_occupy(m, c, self.intent_known(obs, c)))
        };
        let safe = self.gap_over(obs, front);
        // Vehicles entering one of my lanes (α, or β under (21)) get the entry allowance.
        let entering = |c: &Other<F>| {
            !mine(c.lane)
                && (in_front_set(x, lane, alpha, &ahead(c))
                    || yields_to(&key, alpha, beta, c, self.resolution.position))
        };
        let allowance = self.entry_allowance(obs.v_prev);
        // A vehicle ahead in ≺ that is in one of my lanes is a leader like any other;
        // one entering them is checked by its own entry check, which takes me at the
        // wall: it is not credited.
        let yielding = self
            .leader_gap(
                obs,
                |c| entering(c) || yields_to(&key, alpha, beta, c, self.resolution.position),
                |c| !entering(c),
            )
            .map(|g| g - allowance);
        let all = min_gap(safe, yielding);
        (safe, all)
    }

    /// The V2V record of vehicle `id`, if any.
    pub(super) fn heard<'a>(obs: &'a LaneObservation<'_, F>, id: u16) -> Option<&'a Other<F>> {
        obs.others.iter().find(|o| o.id == id && !o.sensed)
    }

    /// `true` if c's intention is known: it cooperates and its V2V data is younger than
    /// the notification bound (a change into a lane must have been declared that long
    /// before it starts, so nothing newer can be under way), whichever record c is.
    pub(super) fn intent_known(&self, obs: &LaneObservation<'_, F>, c: &Other<F>) -> bool {
        let v2v = if c.sensed {
            Self::heard(obs, c.id)
        } else {
            Some(c)
        };
        v2v.is_some_and(|v| !v.cooperative || v.age < self.notify)
    }

    /// Every vehicle that may be in lane `m` behind the ego, fused per vehicle: a sensor
    /// return (fresh, within the error bounds) is used in place of a V2V record of the same
    /// vehicle, with that record's declared change and cooperation, and, if it
    /// cooperates, its declared braking limit (trusted, as on V2V alone: without it a car
    /// seen by the radar was taken to brake like the weakest truck, needed 25 m behind a
    /// truck changing in front of it where it keeps 15 m itself, and the truck never
    /// changed lanes); a vehicle known only from the sensor is taken as one that does not
    /// cooperate, at the weakest braking limit. With sensors, a vehicle
    /// closing in at vmax from just beyond the rear range is added. Each is handed to `f`
    /// with its worst-case position and speed and whether it cooperates.
    pub(super) fn for_each_behind(
        &self,
        obs: &LaneObservation<'_, F>,
        m: u8,
        mut f: impl FnMut(&Other<F>, F, F, bool) -> Result<(), StartBlock>,
    ) -> Result<(), StartBlock> {
        let x = obs.pose.x;
        let (e, ev) = self.errors();
        for c in obs.others.iter() {
            let heard = if c.sensed {
                Self::heard(obs, c.id)
            } else {
                None
            };
            if !c.sensed && obs.others.iter().any(|o| o.sensed && o.id == c.id) {
                continue;
            }
            let cooperative = if c.sensed {
                heard.is_some_and(|h| h.cooperative)
            } else {
                c.cooperative
            };
            let declared = heard.is_some_and(|h| h.alpha == Some(m));
            let brake = match heard {
                Some(h) if cooperative => h.brake,
                _ => c.brake,
            };
            let occupant = Other {
                cooperative,
                brake,
                ..*c
            };
            // A return up to `e` ahead of the ego may be behind it.
            let behind = if c.sensed { c.x - e <= x } else { c.x <= x };
            if !(behind && (declared || may_occupy(m, &occupant, self.intent_known(obs, c)))) {
                continue;
            }
            let (cx, cv) = if c.sensed {
                (c.x + e, c.v + ev)
            } else {
                (c.x, c.v)
            };
            f(&occupant, cx, cv, cooperative)?;
        }
        if let Some(s) = &self.sensing {
            let p = self.params();
            let phantom = Other::v2v(
                u16::MAX,
                x - p.length() - s.behind_m,
                p.v_max(),
                p.length(),
                m,
                F::ZERO,
            );
            // Handed on as a vehicle that does not cooperate (the last argument, which is
            // what the checks read): nothing is known of it.
            f(&phantom, phantom.x, phantom.v, false)?;
        }
        Ok(())
    }

    /// (17) toward one vehicle behind, taken at worst-case position `cx` and speed `cv`
    /// and moving unaware for `tau`: it can still stop behind the ego, braking at its own
    /// limit ([`LanePlanner::set_weakest_brake`] for one that declares none).
    pub(super) fn clear_of(
        &self,
        obs: &LaneObservation<'_, F>,
        c: &Other<F>,
        cx: F,
        cv: F,
        tau: F,
    ) -> bool {
        let p = self.params();
        // Half a step on the bus's rounding: the true front and speed at their worst.
        let r = self.resolution;
        let (reach, v) = unaware_reach(p, cv + F::HALF * r.speed, tau);
        let room = obs.pose.x
            - F::HALF * (c.length + p.length() + r.position)
            - p.d0()
            - cx
            - reach
            - F::SAFETY_MARGIN_M;
        // It stops at its own limit: declared (a cooperating vehicle's, trusted), else
        // the weakest any vehicle here may have.
        let brake = c.brake.map_or(self.weakest_brake, |b| b.mps2());
        safety::d_s_braking(p, v, brake) < room
    }
}
