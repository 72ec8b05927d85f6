//! Survivors of `cargo mutants -f planner-core/src/safety.rs -f planner-core/src/planner.rs`
//! (docs/mutants.md), each killed here by a check of what the code is for: tH against an
//! independent integration of the bang-bang profile, the polygon's upper edge, the
//! invariant's strictness, the planner's input checks and configuration, the verifier's
//! clamp and its report, the warm start, and the standstill fallback.

use planner_core::mpc::{ConstraintKind, SingleLaneProblem};
use planner_core::planner::{
    free_road_gap, in_range, obstacle_position, shifted, speed_slack, verify,
};
use planner_core::safety::{d_s, invariant_holds, max_braking, t_h, upper_profile};
use planner_core::{
    CostWeights, FallbackReason, InputError, Observation, Params, Planner, Real, StepStatus,
    Vehicle,
};

const N: usize = 20;

fn p() -> Params<f64> {
    Params::table_i()
}

/// The time to cover `gap` from speed `v` and stop at its end, by integrating the profile
/// with a small step: accelerate at amax (up to vmax) while the braking distance from the
/// next speed still fits, cruise, brake at |amin|.
fn t_h_by_integration(p: &Params<f64>, v0: f64, gap: f64) -> f64 {
    let (a, b, vm) = (p.a_max(), p.brake(), p.v_max());
    let dt = 1e-5;
    let (mut x, mut v, mut t) = (0.0, v0, 0.0);
    loop {
        let rest = gap - x;
        let stop = v * v / (2.0 * b);
        if stop >= rest - 1e-9 {
            // Brake from here: the remaining time is v / b.
            return t + v / b;
        }
        let up = (v + a * dt).min(vm);
        let next = if (up * up) / (2.0 * b) + 0.5 * (v + up) * dt <= rest {
            up
        } else {
            v
        };
        x += 0.5 * (v + next) * dt;
        v = next;
        t += dt;
    }
}

#[test]
fn t_h_is_the_bang_bang_profile_in_closed_form() {
    let p = p();
    // Short gaps (the peak below vmax) and long ones (a cruise at vmax), from rest and
    // from speed.
    for (v, gap) in [
        (0.0, 30.0),
        (5.0, 60.0),
        (10.0, 200.0),
        (0.0, 900.0),
        (25.0, 600.0),
    ] {
        let got = t_h(&p, v, gap).expect("exists");
        let want = t_h_by_integration(&p, v, gap);
        assert!(
            (got - want).abs() < 2e-3,
            "v {v} gap {gap}: {got} against {want}"
        );
    }
    assert!(t_h(&p, 10.0, 1.0).is_none(), "shorter than dMB");
}

#[test]
fn the_upper_edge_of_v_t_falls_at_the_braking_rate_toward_t_h() {
    let p = p();
    let (v_bar, th) = (10.0, 4.0);
    // Near tH the braking branch binds: |amin| (tH − τ).
    for tau in [3.0, 3.5, 3.9] {
        let want = p.brake() * (th - tau);
        assert!(
            (upper_profile(&p, v_bar, th, tau) - want).abs() < 1e-12,
            "{tau}"
        );
    }
    assert_eq!(upper_profile(&p, v_bar, th, 5.0), 0.0);
    // Early the accelerating branch does.
    assert!((upper_profile(&p, v_bar, th, 0.1) - (v_bar + 0.1 * p.a_max())).abs() < 1e-12);
}

#[test]
fn the_invariant_is_strict() {
    let p = p();
    for v in [0.0, 7.0, 25.0] {
        let ds = d_s(&p, v);
        assert!(!invariant_holds(&p, v, ds), "at exactly dS({v})");
        assert!(invariant_holds(&p, v, ds + 1e-6));
    }
}

#[test]
fn helpers_are_what_their_docs_say() {
    let p = p();
    let want = N as f64 * p.h() * p.v_max() + d_s(&p, p.v_max()) + 1.0;
    assert!((free_road_gap(&p, N) - want).abs() < 1e-9);
    assert_eq!(speed_slack(&p), 8.0 * f64::EPSILON * (p.v_max() + 1.0));
    assert!(in_range(&[0.0, -f64::MAX_COORD_M, f64::MAX_COORD_M]));
    assert!(!in_range(&[0.0, 2.0 * f64::MAX_COORD_M]));
    assert!(!in_range(&[f64::NAN]));
    assert_eq!(shifted(&[1.0, 2.0, 3.0]), [2.0, 3.0, 3.0]);
    // A vehicle level with the ego is not ahead of it.
    let level = [Vehicle::wall(10.0, 4.5)];
    assert_eq!(obstacle_position(&p, 10.0, &level, None), None);
    let ahead = [Vehicle::wall(10.001, 4.5)];
    assert!(obstacle_position(&p, 10.0, &ahead, None).is_some());
}

#[test]
fn weights_are_validated() {
    let p = p();
    let w = |t: f64, r: f64, s: f64| CostWeights {
        target_position: t,
        reference_speed: r,
        smoothness: s,
    };
    for bad in [
        w(-1.0, 1.0, 1.0),
        w(1.0, -1.0, 1.0),
        w(1.0, 1.0, -1.0),
        w(1.0, 0.0, 0.0),
    ] {
        assert!(Planner::<f64, N>::new(p, bad).is_err(), "{bad:?}");
    }
    for good in [w(0.0, 1.0, 0.0), w(0.0, 0.0, 1.0), w(1.0, 1.0, 1.0)] {
        assert!(Planner::<f64, N>::new(p, good).is_ok(), "{good:?}");
    }
}

fn planner() -> Planner<f64, N> {
    Planner::new(p(), CostWeights::default()).expect("default weights")
}

fn obs<'a>(
    x: f64,
    v: f64,
    vehicles: &'a [Vehicle<f64>],
    stop: Option<f64>,
) -> Observation<'a, f64> {
    Observation {
        x,
        v_prev: v,
        vehicles,
        stop_line: stop,
        target_x: x + 100.0,
        v_ref: 15.0,
    }
}

#[test]
fn inputs_out_of_range_are_refused() {
    let mut pl = planner();
    let far = 2.0 * f64::MAX_COORD_M;
    let err = |o: &Observation<'_, f64>, pl: &mut Planner<f64, N>| pl.step(o).err();
    assert_eq!(
        err(&obs(far, 5.0, &[], None), &mut pl),
        Some(InputError::OutOfRange)
    );
    assert_eq!(
        err(&obs(0.0, 5.0, &[], Some(far)), &mut pl),
        Some(InputError::OutOfRange)
    );
    let v = [Vehicle::wall(far, 4.5)];
    assert_eq!(
        err(&obs(0.0, 5.0, &v, None), &mut pl),
        Some(InputError::OutOfRange)
    );
    let long = [Vehicle::wall(50.0, far)];
    assert_eq!(
        err(&obs(0.0, 5.0, &long, None), &mut pl),
        Some(InputError::OutOfRange)
    );
    // step_gap checks its speed both ways.
    assert_eq!(
        pl.step_gap(-0.1, 50.0, 0.0, 10.0).err(),
        Some(InputError::SpeedOutOfRange)
    );
    let over = pl.params().v_max() + 0.1;
    assert_eq!(
        pl.step_gap(over, 50.0, 0.0, 10.0).err(),
        Some(InputError::SpeedOutOfRange)
    );
}

#[test]
fn the_gap_is_measured_from_the_ego_to_the_obstacle() {
    let p = p();
    let mut pl = planner();
    let v = [Vehicle::wall(160.0, 4.5)];
    let c = pl.step(&obs(100.0, 5.0, &v, None)).expect("valid");
    let want = 160.0 - 0.5 * (4.5 + p.length()) - p.d0() - 100.0;
    assert!((c.gap - want).abs() < 1e-9, "{} against {want}", c.gap);
}

#[test]
fn standing_at_the_invariant_boundary_is_a_no_room_fallback() {
    // Stopped behind a stopped vehicle: the feasible set is (nearly) one point.
    let p = p();
    let mut pl = planner();
    // 0.45 mm of room beyond d0: the invariant holds, yet less than MIN_ROOM_M (0.5 mm)
    // is left, so max braking (standing still) is the answer without a solve.
    let x_other = 0.5 * (4.5 + p.length()) + p.d0() + 4.5e-4;
    let v = [Vehicle::wall(x_other, 4.5)];
    let c = pl.step(&obs(0.0, 0.0, &v, None)).expect("valid");
    assert_eq!(c.status, StepStatus::Fallback(FallbackReason::NoRoom));
    assert_eq!(c.v, 0.0);
}

#[test]
fn reset_and_braking_plans_set_the_warm_start() {
    let p = p();
    let mut pl = planner();
    pl.step(&obs(0.0, 10.0, &[], None)).expect("valid");
    assert!(pl.plan().is_some());
    pl.reset();
    assert!(pl.plan().is_none(), "reset forgets the plan");
    pl.set_braking_plan(10.0);
    assert_eq!(pl.plan(), Some(&max_braking::<f64, N>(&p, 10.0)));
}

/// A problem at 20 m/s on a free road (hi = hi_exact = vmax).
fn problem() -> SingleLaneProblem<f64, N> {
    let p = p();
    SingleLaneProblem {
        h: p.h(),
        brake: p.brake(),
        dv_max: p.a_max() * p.h(),
        dv_min: -p.brake() * p.h(),
        gap: 1000.0,
        v_prev: 20.0,
        lo: [0.0; N],
        hi: [p.v_max(); N],
        hi_exact: [p.v_max(); N],
        weights: CostWeights::default(),
        target: 0.0,
        v_ref: 20.0,
    }
}

#[test]
fn an_empty_clamp_interval_is_reported_with_its_width() {
    let p = p();
    let mut pr = problem();
    // V^0_t's upper end far below what braking from v_prev reaches: empty by 1 m/s.
    let lower = pr.v_prev + pr.dv_min;
    pr.hi_exact[0] = lower - 1.0;
    pr.hi[0] = pr.hi_exact[0];
    let err = verify(&p, &pr, [20.0; N]).expect_err("empty interval");
    assert_eq!((err.kind, err.step), (ConstraintKind::SpeedUpper, 0));
    assert!((err.amount - 1.0).abs() < 1e-9, "{}", err.amount);
}

#[test]
fn an_interval_empty_by_rounding_takes_its_lower_end() {
    let p = p();
    let mut pr = problem();
    let lower = pr.v_prev + pr.dv_min;
    // Empty by a quarter of the slack: the verifier takes the lower (slower) end.
    pr.hi_exact[0] = lower - 0.25 * speed_slack(&p);
    pr.hi[0] = pr.hi_exact[0];
    let mut plan = [lower; N];
    plan[0] = 25.0;
    let ok = verify(&p, &pr, plan).expect("within the slack");
    assert_eq!(ok[0], lower);
}
