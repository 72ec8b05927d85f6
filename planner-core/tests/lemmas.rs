//! Property tests of the paper's single-lane lemmas (Sec. III) and the dS identity.

use planner_core::safety::{d_mb, d_s, max_braking, speed_bounds, t_h, t_l};
use planner_core::{CostWeights, Params, SingleLaneProblem};
use proptest::prelude::*;

fn p() -> Params<f64> {
    Params::table_i()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(10_000))]

    /// dS(v) = dMB(v) + dh(v) = (v + |amin| h)² / (2|amin|) = dMB(v + |amin| h).
    #[test]
    fn ds_identity(v in 0.0f64..27.8) {
        let p = p();
        let b = p.brake();
        let lhs = d_s(&p, v);
        prop_assert!((lhs - (v + b * p.h()).powi(2) / (2.0 * b)).abs() <= 1e-12 * (1.0 + lhs));
        prop_assert!((lhs - d_mb(&p, v + b * p.h())).abs() <= 1e-12 * (1.0 + lhs));
    }

    /// Lemma 1: if x_t < x̄_t − dS(v_{t−h}) then tH(v̄_t) > tL(v_{t−h}) + h.
    #[test]
    fn lemma_1(v_prev in 0.0f64..27.8, extra in 1e-9f64..500.0) {
        let p = p();
        let gap = d_s(&p, v_prev) + extra;
        let vb = speed_bounds(&p, v_prev, gap).upper;
        let th = t_h(&p, vb, gap).expect("tH exists under the invariant");
        prop_assert!(th > t_l(&p, v_prev) + p.h(), "tH {th} vs tL+h {}", t_l(&p, v_prev) + p.h());
    }

    /// Lemma 2: under the invariant the max-braking sequence satisfies every constraint
    /// of (10) (exact V^k_t, acceleration, safety) and reaches 0.
    #[test]
    fn lemma_2(v_prev in 0.0f64..27.8, extra in 1e-6f64..200.0) {
        let p = p();
        let gap = d_s(&p, v_prev) + extra;
        // 400 steps = 4 s > tL(vmax) + h: long enough to reach 0 from any speed.
        let pr = SingleLaneProblem::<f64, 400>::new(
            &p, v_prev, gap, 0.0, CostWeights::default(), 0.0, 0.0,
        ).expect("invariant holds");
        let mb = max_braking::<f64, 400>(&p, v_prev);
        let exact = SingleLaneProblem { hi: pr.hi_exact, ..pr.clone() };
        let viol = exact.max_violation(&mb);
        // Tolerance: rounding of sums of ≤ 400 speeds ≤ 28 m/s.
        prop_assert!(viol.amount <= 1e-9, "{viol:?}");
        prop_assert_eq!(mb[399], 0.0);
    }
}
