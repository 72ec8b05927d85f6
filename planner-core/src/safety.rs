//! The paper's safety quantities (Sec. III, SPEC §3): braking distances, the speed bounds
//! (3)(4), the shortest stopping time tH (5)(6), the speed region V^k_t (7), dS (8)(9),
//! the operational invariant of Lemma 3 and the certified max-braking sequence of Lemma 2.
//!
//! All functions are pure and total: a precondition that does not hold gives `None`,
//! never a panic.

use crate::params::Params;
use crate::real::Real;

/// dMB(v) = v² / (2|amin|): minimum braking distance from speed `v`.
#[inline]
pub fn d_mb<F: Real>(p: &Params<F>, v: F) -> F {
    v * v / (F::TWO * p.brake())
}

/// tL(v) = v / |amin|: minimum stopping time from speed `v`.
#[inline]
pub fn t_l<F: Real>(p: &Params<F>, v: F) -> F {
    v / p.brake()
}

/// dh(v) = v h + |amin| h² / 2, eq. (9): the distance covered in one sampling period at
/// speed `v`, plus the braking distance lost by reacting one period late.
#[inline]
pub fn d_h<F: Real>(p: &Params<F>, v: F) -> F {
    let h = p.h();
    v * h + F::HALF * p.brake() * h * h
}

/// dS(v) = dMB(v) + dh(v), eq. (8). Equals dMB(v + |amin| h) (tested).
#[inline]
pub fn d_s<F: Real>(p: &Params<F>, v: F) -> F {
    d_mb(p, v) + d_h(p, v)
}

/// dS(v) of (8) for a vehicle braking at `brake` (m/s², > 0) instead of |amin|:
/// (v + brake h)² / (2 brake), the room a vehicle of another braking limit needs to stop
/// reacting one period late — a truck behind a car that changes in front of it (17).
#[inline]
pub fn d_s_braking<F: Real>(p: &Params<F>, v: F, brake: F) -> F {
    let w = v + brake * p.h();
    w * w / (F::TWO * brake)
}

/// The per-step speed bounds of eqs. (3)(4) for the current step.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SpeedBounds<F> {
    /// v̲_t = max{0, v_{t−h} + amin h}, eq. (3).
    pub lower: F,
    /// v̄_t = min{vmax, v_{t−h} + amax h, sqrt(2|amin| (x̄_t − x_t))}, eq. (4).
    pub upper: F,
}

/// Eqs. (3)(4). `gap` = x̄_t − x_t (m); a negative gap counts as 0 (then v̄ = 0).
pub fn speed_bounds<F: Real>(p: &Params<F>, v_prev: F, gap: F) -> SpeedBounds<F> {
    let h = p.h();
    let lower = (v_prev + p.a_min() * h).max(F::ZERO);
    let stop_limited = (F::TWO * p.brake() * gap.max(F::ZERO)).sqrt();
    let upper = p.v_max().min(v_prev + p.a_max() * h).min(stop_limited);
    SpeedBounds { lower, upper }
}

/// tH(v), eqs. (5)(6) in closed form: the shortest time to cover `gap` starting at speed
/// `v` and be stopped at its end, accelerating at amax (capped at vmax), then braking at
/// amin. `None` if the gap is shorter than dMB(v) (the profile does not exist) or the
/// inputs are outside their domain (v < 0 or v > vmax).
pub fn t_h<F: Real>(p: &Params<F>, v: F, gap: F) -> Option<F> {
    if !(v >= F::ZERO && v <= p.v_max() && gap >= d_mb(p, v)) {
        return None;
    }
    let a = p.a_max();
    let b = p.brake();
    let vm = p.v_max();
    // Peak speed where the accelerating and braking branches meet.
    let vp = ((gap + v * v / (F::TWO * a)) / (F::HALF / a + F::HALF / b)).sqrt();
    if vp <= vm {
        Some((vp - v) / a + vp / b)
    } else {
        let cruise = (gap - (vm * vm - v * v) / (F::TWO * a) - vm * vm / (F::TWO * b)) / vm;
        Some((vm - v) / a + cruise.max(F::ZERO) + vm / b)
    }
}

/// The upper boundary of the polygon V_t (Fig. 3) at time `tau` after t: the profile (5)
/// from v̄_t, i.e. max{0, min{v̄ + amax τ, vmax, |amin| (tH(v̄) − τ)}}.
#[inline]
pub fn upper_profile<F: Real>(p: &Params<F>, v_bar: F, t_h_bar: F, tau: F) -> F {
    (v_bar + p.a_max() * tau)
        .min(p.v_max())
        .min(p.brake() * (t_h_bar - tau))
        .max(F::ZERO)
}

/// The interval V^k_t of eq. (7) for every k in 0..N: `lo[k] ≤ v_k ≤ hi[k]`.
///
/// `gap` = x̄_t − x_t. Lower line: max(0, v̲_t + amin kh); upper: [`upper_profile`].
/// `None` when tH(v̄_t) does not exist (non-finite or negative inputs).
pub fn speed_region<F: Real, const N: usize>(
    p: &Params<F>,
    v_prev: F,
    gap: F,
) -> Option<([F; N], [F; N])> {
    let bounds = speed_bounds(p, v_prev, gap);
    // v̄ ≤ sqrt(2 b gap) makes gap ≥ dMB(v̄), so tH exists whenever the inputs are sane.
    let th = t_h(p, bounds.upper.max(F::ZERO), gap.max(F::ZERO))?;
    let mut lo = [F::ZERO; N];
    let mut hi = [F::ZERO; N];
    let h = p.h();
    for (k, (l, u)) in lo.iter_mut().zip(hi.iter_mut()).enumerate() {
        let tau = F::from_usize(k) * h;
        *l = (bounds.lower + p.a_min() * tau).max(F::ZERO);
        *u = upper_profile(p, bounds.upper, th, tau);
    }
    Some((lo, hi))
}

/// The operational form of the safety relation c_i S_t c_j (Lemma 3):
/// x_t(c_i) < x̄ − dS(v_{t−h}(c_i)), written with the gap x̄ − x_t. Strict, as in the paper.
#[inline]
pub fn invariant_holds<F: Real>(p: &Params<F>, v_prev: F, gap: F) -> bool {
    d_s(p, v_prev) < gap
}

/// Which safety invariant a vehicle keeps toward the vehicle ahead of it.
///
/// Both are the relation S_t of Lemma 3 — "the follower can stop without hitting the
/// leader whatever the leader does" — and differ in what the leader is credited with.
/// See docs/spec.md, "The leader-aware invariant", for the proof.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum Invariant {
    /// Lemma 3 as the paper writes it: the leader is a wall that may stop at once.
    #[default]
    Paper,
    /// The leader, when it is known over V2V, cooperates and declared its braking limit,
    /// is credited with the least distance it can still travel: it never reverses and
    /// never brakes harder than its limit ([`leader_credit`]). Everywhere else — a
    /// vehicle known only from the range sensor, stale, not cooperating, a road end, a
    /// stop line — the wall, as in [`Invariant::Paper`].
    LeaderAware,
}

/// A vehicle's braking limit |amin| as it declares it over V2V: in steps of 0.1 m/s²,
/// from 0.1 to 25.5 m/s² — one byte, as a CAN signal carries it, and the state message
/// stays the size it was (the firmware's stack is counted).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct BrakeLimit(u8);

impl BrakeLimit {
    /// The step (m/s²).
    pub const STEP_MPS2: f64 = 0.1;

    /// `b` m/s² rounded *up* to the next step (within 1e-5 m/s², so that 7.9 in f32 stays
    /// 7.9): a follower credits a leader less the harder it says it brakes, so rounding
    /// up never credits more than the truth. `None` unless 0 < b ≤ 25.5 m/s².
    pub fn from_mps2<F: Real>(b: F) -> Option<Self> {
        let tenths = b.to_f64() / Self::STEP_MPS2;
        if !(tenths > 0.0 && tenths <= 255.0 + 1e-4) {
            return None;
        }
        // Truncation toward zero, then up unless already (all but) on a step.
        let down = tenths as u32;
        let up = if tenths - f64::from(down) > 1e-4 {
            down + 1
        } else {
            down
        };
        u8::try_from(up).ok().filter(|&t| t > 0).map(Self)
    }

    /// From its wire value, tenths of m/s²; `None` for 0 (no limit declared).
    pub fn from_tenths(tenths: u8) -> Option<Self> {
        (tenths > 0).then_some(Self(tenths))
    }

    /// Its wire value, tenths of m/s² (1–255).
    pub fn tenths(self) -> u8 {
        self.0
    }

    /// In m/s².
    pub fn mps2<F: Real>(self) -> F {
        F::from_f64(f64::from(self.0) * Self::STEP_MPS2)
    }
}

/// The least distance (m) a vehicle of this plant still travels once it has applied
/// speed `v` over a period, braking at most `brake` (m/s², > 0) from then on: the exact
/// sum h Σ_{k≥1} max(0, v − brake k h) is v²/(2 brake) − v h / 2 + brake h² r(1−r)/2 with
/// r the fractional part of v / (brake h), so v²/(2 brake) − v h / 2 bounds it from below
/// (tight when r = 0). A speed or limit that is not positive gives 0.
pub fn least_travel<F: Real>(p: &Params<F>, v: F, brake: F) -> F {
    if !(v > F::ZERO && brake > F::ZERO) {
        return F::ZERO;
    }
    (v * v / (F::TWO * brake) - F::HALF * v * p.h()).max(F::ZERO)
}

/// The leader-aware credit (m): how far along the road beyond where it was at its stamp
/// a cooperating leader still travels, at the least — [`least_travel`] from its stamped
/// speed `v_leader`, braking at b' = max(its limit, the follower's own |amin|), times
/// cos θmax: its speed is along its heading, and a vehicle changing lanes (or about to)
/// advances along the road only v cos θ, with |θ| ≤ θmax (a leader turning away at
/// π/6 is 13 % slower along the road than along its path).
///
/// Why the larger of the two: a follower that stops before the leader's stopping point
/// can still run into it on the way when it brakes harder than the leader and is faster
/// (a car behind a truck). Taking the leader to brake at b' ≥ the follower's limit
/// places its stop earlier than it can be, never later, and then a follower that can
/// stop before that point never reaches the leader while both move: at a first contact
/// the follower is at least as fast, so its own stopping point would be past the
/// leader's (docs/spec.md, "The leader-aware invariant").
pub fn leader_credit<F: Real>(p: &Params<F>, v_leader: F, leader_brake: F) -> F {
    least_travel(p, v_leader, leader_brake.max(p.brake())) * p.theta_max().cos()
}

/// How far (m) along its path a cooperating vehicle driving straight has come, at the
/// least, `age` seconds after a stamp at which it had applied speed `v` over a period,
/// braking at most `brake` (m/s², its own declared limit) from then on:
/// h Σ_{k=1}^{m} max(0, v − `brake` k h) over the m whole periods in `age`. Its *ghost*.
///
/// Why it is needed: a follower that credits its leader comes closer to the leader's
/// stamped position than the paper's wall allows, and once the stamp is old (a silent
/// leader, a suspect whose later words are refused, a delayed bus) the follower's front
/// may be past it. Judged by the stamped position alone, that leader is then "beside or
/// behind", its credit and its wall are dropped, and the follower runs into it. Judged
/// by its ghost ([`leads`]) it stays ahead. The ghost decides only *whether* a vehicle
/// leads; the wall stays where the stamp puts it, so an optimistic ghost (a vehicle that
/// is turning advances along the road only v cos θ) can at worst take a vehicle that is
/// really behind for a leader, which only adds a wall. A pessimistic one would drop a
/// real leader's wall: it brakes at the leader's own limit, not at b' of
/// [`leader_credit`], and without cos θmax (the property tests find a follower level
/// with either).
///
/// A speed, limit or age that is not positive gives 0; the count of periods is capped
/// at the number in which the speed reaches 0, so the sum has a closed form and no loop.
pub fn ghost_advance<F: Real>(p: &Params<F>, v: F, brake: F, age: F) -> F {
    if !(brake > F::ZERO) {
        return F::ZERO;
    }
    // Whole periods since the stamp, and those in which v − b k h is still positive: a
    // negative or NaN age or speed counts none (float → integer casts saturate, NaN → 0).
    let h = p.h();
    let elapsed = (age / h).to_f64() as u64;
    let moving = (v / (brake * h)).to_f64() as u64;
    let k = elapsed.min(moving);
    if k == 0 {
        return F::ZERO;
    }
    let k = F::from_f64(k as f64);
    (h * (v * k - F::HALF * brake * h * k * (k + F::ONE))).max(F::ZERO)
}

/// Whether a vehicle on the ego's lane or path leads it, for the leader-aware credit:
/// `wall` is x̄ − x from its stamped position (its rear less d0, less the ego's front),
/// `ghost` its [`ghost_advance`] since the stamp. A fresh stamp leads when x̄ − x > 0 (a
/// vehicle beside the ego is no leader), as always; an old one also when its ghost's
/// rear is ahead of the ego's front. A follower that keeps the invariant stays more than
/// d0 behind its leader's ghost (property-tested in `planner-core/tests/leader_aware.rs`),
/// so d0 is to spare.
pub fn leads<F: Real>(p: &Params<F>, wall: F, ghost: F) -> bool {
    wall > F::ZERO || (ghost > F::ZERO && wall + ghost + p.d0() > F::ZERO)
}

/// The leader-aware credit (m) of a vehicle heard at speed `v` (already taken half a bus
/// step lower), braking limit `brake` (m/s²), `age` seconds ago, whose wall is `wall`
/// (x̄ − x from its stamped position): [`leader_credit`] if it [`leads`] judged by its
/// [`ghost_advance`], else 0. The one rule the crossing, lane and single-lane planners
/// each apply to the vehicles they may credit.
pub fn credit_if_leads<F: Real>(p: &Params<F>, v: F, brake: F, wall: F, age: F) -> F {
    if leads(p, wall, ghost_advance(p, v, brake, age)) {
        leader_credit(p, v, brake)
    } else {
        F::ZERO
    }
}

/// The certified fallback of Lemma 2: v_{t+kh} = max(0, v_{t−h} + amin (k+1) h).
/// While the invariant holds it satisfies every constraint of (10) and reaches 0.
pub fn max_braking<F: Real, const N: usize>(p: &Params<F>, v_prev: F) -> [F; N] {
    let mut out = [F::ZERO; N];
    let step = p.a_min() * p.h();
    let mut v = v_prev;
    for o in out.iter_mut() {
        v = (v + step).max(F::ZERO);
        *o = v;
    }
    out
}

/// The first input of [`max_braking`]: the command to apply when nothing else is certified.
#[inline]
pub fn max_braking_command<F: Real>(p: &Params<F>, v_prev: F) -> F {
    (v_prev + p.a_min() * p.h()).max(F::ZERO)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p() -> Params<f64> {
        Params::table_i()
    }

    /// The ghost by hand, and what it makes of values that are not positive.
    #[test]
    fn the_ghost_by_hand_and_at_the_edges() {
        let p = p();
        // 10 m/s braking at 5: after 0.025 s two whole periods, 0.01 (9.95 + 9.9) m.
        let two = ghost_advance(&p, 10.0, 5.0, 0.025);
        assert!((two - 0.1985).abs() < 1e-12, "{two}");
        // Long after it stopped: the whole sum, h Σ_{k=1}^{199} (10 − 0.05 k) = 9.95 m.
        let all = ghost_advance(&p, 10.0, 5.0, 1e6);
        assert!((all - 9.95).abs() < 1e-9, "{all}");
        // Less than a period, no speed, no limit, a limit or an age that is not a number:
        // nothing is known to have been covered.
        for (v, b, age) in [
            (10.0, 5.0, 0.009),
            (0.0, 5.0, 1.0),
            (-3.0, 5.0, 1.0),
            (f64::NAN, 5.0, 1.0),
            (10.0, 0.0, 1.0),
            (10.0, -5.0, 1.0),
            (10.0, f64::NAN, 1.0),
            (10.0, 5.0, -1.0),
            (10.0, 5.0, f64::NAN),
        ] {
            assert_eq!(ghost_advance(&p, v, b, age), 0.0, "{v} {b} {age}");
        }
    }

    /// `leads`: a fresh stamp by its wall alone; an old one by its ghost's rear.
    #[test]
    fn who_leads() {
        let p = p();
        let d0 = p.d0();
        assert!(leads(&p, 0.01, 0.0));
        assert!(!leads(&p, 0.0, 0.0), "level with the wall, fresh: beside");
        assert!(!leads(&p, -0.01, 0.0));
        // An old stamp: its ghost's rear (wall + ghost + d0) ahead of the front.
        assert!(leads(&p, -3.0, 3.0 - d0 + 0.01));
        assert!(!leads(&p, -3.0, 3.0 - d0 - 0.01));
        assert!(!leads(&p, -3.0, 3.0 - d0), "rear level with the front");
        assert!(leads(&p, 0.5, 1.0), "either way");
    }

    #[test]
    fn hand_computed_values() {
        let p = p();
        // dMB(15) = 225 / 15.8
        assert!((d_mb(&p, 15.0) - 14.240_506_329_113_924).abs() < 1e-12);
        assert!((t_l(&p, 15.0) - 1.898_734_177_215_19).abs() < 1e-12);
        // dh(15) = 0.15 + 7.9 * 1e-4 / 2
        assert!((d_h(&p, 15.0) - 0.150_395).abs() < 1e-12);
        assert!((d_s(&p, 15.0) - (14.240_506_329_113_924 + 0.150_395)).abs() < 1e-12);
        // dS(0) = amin h² / 2
        assert!((d_s(&p, 0.0) - 0.000_395).abs() < 1e-15);
    }

    #[test]
    fn speed_bounds_hand_computed() {
        let p = p();
        let b = speed_bounds(&p, 10.0, 1000.0);
        assert!((b.lower - 9.921).abs() < 1e-12);
        assert!((b.upper - 10.038).abs() < 1e-12);
        // Near an obstacle: sqrt(2 * 7.9 * 2) = 5.621...
        let b = speed_bounds(&p, 10.0, 2.0);
        assert!((b.upper - (31.6f64).sqrt()).abs() < 1e-12);
        // At vmax the cap binds.
        let b = speed_bounds(&p, 27.8, 1000.0);
        assert!((b.upper - 27.8).abs() < 1e-12);
    }

    #[test]
    fn t_h_hand_computed() {
        let p = p();
        // From rest over 100 m without reaching vmax:
        // vp = sqrt(100 / (1/7.6 + 1/15.8)) = 22.6604..., tH = vp/3.8 + vp/7.9.
        let vp = (100.0f64 / (1.0 / 7.6 + 1.0 / 15.8)).sqrt();
        let expect = vp / 3.8 + vp / 7.9;
        assert!((t_h(&p, 0.0, 100.0).unwrap() - expect).abs() < 1e-12);
        // From vmax over 1000 m: cruise.
        let vm = 27.8f64;
        let expect = (1000.0 - vm * vm / 15.8) / vm + vm / 7.9;
        assert!((t_h(&p, vm, 1000.0).unwrap() - expect).abs() < 1e-12);
        // Exactly the braking distance: tH = tL.
        let t = t_h(&p, 15.0, d_mb(&p, 15.0)).unwrap();
        assert!((t - t_l(&p, 15.0)).abs() < 1e-9);
        // Too short: no profile.
        assert_eq!(t_h(&p, 15.0, 1.0), None);
        assert_eq!(t_h(&p, f64::NAN, 1.0), None);
    }

    #[test]
    fn speed_region_contains_max_braking() {
        let p = p();
        let (lo, hi) = speed_region::<f64, 50>(&p, 20.0, 200.0).unwrap();
        let mb = max_braking::<f64, 50>(&p, 20.0);
        for k in 0..50 {
            assert!(lo[k] <= mb[k] + 1e-12 && mb[k] <= hi[k]);
        }
        assert!((lo[0] - 19.921).abs() < 1e-12);
        assert!((hi[0] - 20.038).abs() < 1e-12);
    }

    #[test]
    fn max_braking_reaches_zero() {
        let p = p();
        let mb = max_braking::<f64, 300>(&p, 20.0);
        assert_eq!(mb[299], 0.0);
        assert!((mb[0] - 19.921).abs() < 1e-12);
        assert_eq!(max_braking_command(&p, 0.05), 0.0);
    }

    #[test]
    fn a_braking_limit_is_declared_in_tenths_rounded_up() {
        assert_eq!(
            BrakeLimit::from_mps2(7.9f32).map(BrakeLimit::tenths),
            Some(79)
        );
        assert_eq!(
            BrakeLimit::from_mps2(7.9f64).map(BrakeLimit::tenths),
            Some(79)
        );
        assert_eq!(
            BrakeLimit::from_mps2(7.91).map(BrakeLimit::tenths),
            Some(80)
        );
        assert_eq!(BrakeLimit::from_mps2(4.5).map(BrakeLimit::tenths), Some(45));
        assert_eq!(BrakeLimit::from_mps2(0.01).map(BrakeLimit::tenths), Some(1));
        assert_eq!(
            BrakeLimit::from_mps2(25.5).map(BrakeLimit::tenths),
            Some(255)
        );
        for bad in [0.0, -1.0, 25.6, f64::NAN, f64::INFINITY] {
            assert_eq!(BrakeLimit::from_mps2(bad), None, "{bad}");
        }
        assert_eq!(BrakeLimit::from_tenths(0), None);
        let b = BrakeLimit::from_tenths(45).expect("valid");
        assert!((b.mps2::<f64>() - 4.5).abs() < 1e-12);
    }
}
