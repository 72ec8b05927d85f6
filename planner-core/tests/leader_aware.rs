//! Property tests of the leader-aware invariant (docs/spec.md, "The leader-aware
//! invariant"): a follower that keeps it toward a cooperating leader never reaches the
//! leader, whatever the leader does within its limits (it never reverses and never brakes
//! harder than its own limit), for any pair of braking limits — a car behind a truck, a
//! truck behind a car.
//!
//! The plant is the simulator's: a speed is applied over a whole period (x += v h). The
//! follower reacts one period late (it keeps its speed for the period that was already
//! commanded), then applies the certified fallback, max braking at its own limit.

use planner_core::safety::{d_s, leader_credit, least_travel};
use planner_core::{Params, ParamsSpec};
use proptest::prelude::*;

/// Table I with braking limit `brake` (m/s²).
fn with_brake(brake: f64) -> Params<f64> {
    Params::new(ParamsSpec {
        a_min: -brake,
        ..ParamsSpec::table_i()
    })
    .expect("a braking limit in [3, 10] m/s² is valid")
}

/// The exact least travel, summed period by period.
fn summed(v: f64, brake: f64, h: f64) -> f64 {
    let mut s = 0.0;
    let mut u = v;
    for _ in 0..100_000 {
        u = (u - brake * h).max(0.0);
        if u == 0.0 {
            break;
        }
        s += u * h;
    }
    s
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(10_000))]

    /// [`least_travel`] never claims more than a vehicle braking at its limit travels.
    #[test]
    fn least_travel_is_a_lower_bound(v in 0.0f64..27.8, brake in 3.0f64..10.0) {
        let p = with_brake(7.9);
        let lower = least_travel(&p, v, brake);
        let exact = summed(v, brake, p.h());
        prop_assert!(lower <= exact + 1e-9, "{lower} > {exact}");
        // And it is close: within |amin| h² / 8 of the exact sum.
        prop_assert!(exact - lower <= brake * p.h() * p.h() / 8.0 + 1e-9);
    }

    /// The lemma: from any state that keeps the leader-aware invariant, the follower's
    /// fallback never reaches the leader (bumper gap stays above d0 at every instant),
    /// while the leader does anything its limits allow.
    #[test]
    fn a_follower_keeping_the_invariant_never_reaches_its_leader(
        b_f in 3.0f64..10.0,
        b_l in 3.0f64..10.0,
        v_f in 0.0f64..27.8,
        v_l in 0.0f64..27.8,
        extra in 1e-6f64..5.0,
        moves in proptest::collection::vec(0.0f64..1.0, 1..1200),
    ) {
        let p = with_brake(b_f);
        let (h, d0) = (p.h(), p.d0());
        // The smallest room the invariant allows, plus `extra`: room + credit > dS.
        let credit = leader_credit(&p, v_l, b_l);
        let room = (d_s(&p, v_f) - credit).max(0.0) + extra;
        let (mut xf, mut xl) = (0.0, room + d0);
        let (mut uf, mut ul) = (v_f, v_l);
        for k in 0..moves.len().max(1200) {
            // The follower: its committed speed for one period, then max braking.
            if k > 0 {
                uf = (uf - b_f * h).max(0.0);
            }
            // The leader: any change from braking at its limit to accelerating at amax.
            let m = moves.get(k).copied().unwrap_or(0.0);
            let accel = -b_l + m * (b_l + p.a_max());
            ul = (ul + accel * h).clamp(0.0, p.v_max());
            xf += uf * h;
            xl += ul * h;
            // Both move linearly within the period: the gap is smallest at its ends.
            prop_assert!(xl - xf > d0 - 1e-9, "step {k}: gap {} ≤ d0", xl - xf);
        }
    }
}

/// The credit takes the harder of the two limits: a car (7.9) behind a truck (4.5) is
/// credited the truck's travel at the car's limit, which is less than at the truck's.
#[test]
fn the_credit_takes_the_harder_of_the_two_limits() {
    let car = with_brake(7.9);
    let truck = with_brake(4.5);
    let v = 20.0;
    assert!(leader_credit(&car, v, 4.5) < leader_credit(&truck, v, 4.5));
    assert_eq!(leader_credit(&car, v, 4.5), leader_credit(&car, v, 7.9));
    assert_eq!(leader_credit(&truck, v, 7.9), leader_credit(&car, v, 7.9));
    // Along the road: cos θmax of the least travel along the path.
    let along = least_travel(&car, v, 7.9) * car.theta_max().cos();
    assert!((leader_credit(&car, v, 7.9) - along).abs() < 1e-12);
}
