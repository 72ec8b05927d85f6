//! The solver's settings are private and checked (as Clarabel keeps its own): every
//! `with_…` takes each value of its range and refuses the values just outside it,
//! naming the setting; the defaults are in range; the solver runs on what it was given.

use planner_core::solver::{MAX_ACTIVE_SET_ITER, MAX_ITER_CAP, MAX_REFINEMENT_STEPS};
use planner_core::{Settings, SettingsError, SolveError};

type S = Settings<f64>;

#[test]
fn the_defaults_are_in_range_and_pass_through_every_setter_unchanged() {
    let d = S::default();
    assert_eq!(d.with_max_iter(d.max_iter()), Ok(d));
    assert_eq!(d.with_tol(d.tol()), Ok(d));
    assert_eq!(d.with_tol_dual(d.tol_dual()), Ok(d));
    assert_eq!(d.with_step_fraction(d.step_fraction()), Ok(d));
    assert_eq!(d.with_regularization(d.regularization()), Ok(d));
    assert_eq!(d.with_pivot_floor(d.pivot_floor()), Ok(d));
    assert_eq!(d.with_refinement_steps(d.refinement_steps()), Ok(d));
    assert_eq!(d.with_warm_barrier(d.warm_barrier()), Ok(d));
    assert_eq!(d.with_active_set_iter(d.active_set_iter()), Ok(d));
    assert_eq!(d.with_active_set_penalty(d.active_set_penalty()), Ok(d));
    assert_eq!(d.with_adaptive_warm_barrier(d.adaptive_warm_barrier()), d);
    // The values the solver was tuned with.
    assert_eq!(d.max_iter(), 60);
    assert!(d.adaptive_warm_barrier() && d.active_set_iter() > 0);
    let ipm = S::interior_point_only();
    assert!(!ipm.adaptive_warm_barrier() && ipm.active_set_iter() == 0);
}

/// `set` takes every value of `good` (and then reads it back) and refuses every value of
/// `bad` with `e`.
fn range<T: Copy + PartialEq + core::fmt::Debug>(
    set: impl Fn(S, T) -> Result<S, SettingsError>,
    get: impl Fn(&S) -> T,
    good: &[T],
    bad: &[T],
    e: SettingsError,
) {
    for &x in good {
        let s = set(S::default(), x).unwrap_or_else(|e| panic!("{x:?} refused: {e}"));
        assert_eq!(get(&s), x);
    }
    for &x in bad {
        assert_eq!(set(S::default(), x), Err(e), "{x:?} taken");
    }
}

#[test]
fn every_setting_takes_its_range_and_refuses_what_is_outside() {
    let nan = f64::NAN;
    let inf = f64::INFINITY;
    range(
        S::with_max_iter,
        S::max_iter,
        &[1, MAX_ITER_CAP],
        &[0, MAX_ITER_CAP + 1],
        SettingsError::MaxIter,
    );
    let open01_good = [1e-12, 0.5, 0.999_999];
    let open01_bad = [0.0, -1e-9, 1.0, 2.0, nan, inf];
    range(
        S::with_tol,
        S::tol,
        &open01_good,
        &open01_bad,
        SettingsError::Tolerance,
    );
    range(
        S::with_tol_dual,
        S::tol_dual,
        &open01_good,
        &open01_bad,
        SettingsError::DualTolerance,
    );
    range(
        S::with_step_fraction,
        S::step_fraction,
        &open01_good,
        &open01_bad,
        SettingsError::StepFraction,
    );
    range(
        S::with_pivot_floor,
        S::pivot_floor,
        &open01_good,
        &open01_bad,
        SettingsError::PivotFloor,
    );
    range(
        S::with_regularization,
        S::regularization,
        &[0.0, 1e-12, 0.999],
        &[-1e-12, 1.0, nan, inf],
        SettingsError::Regularization,
    );
    range(
        S::with_warm_barrier,
        S::warm_barrier,
        &[1e-9, 1.0],
        &[0.0, -1.0, 1.000_001, nan, inf],
        SettingsError::WarmBarrier,
    );
    range(
        S::with_active_set_penalty,
        S::active_set_penalty,
        &[1e-9, 1e9],
        &[0.0, -1.0, nan, inf],
        SettingsError::ActiveSetPenalty,
    );
    range(
        S::with_refinement_steps,
        S::refinement_steps,
        &[0, MAX_REFINEMENT_STEPS],
        &[MAX_REFINEMENT_STEPS + 1],
        SettingsError::RefinementSteps,
    );
    range(
        S::with_active_set_iter,
        S::active_set_iter,
        &[0, MAX_ACTIVE_SET_ITER],
        &[MAX_ACTIVE_SET_ITER + 1],
        SettingsError::ActiveSetIter,
    );
    assert!(!S::default()
        .with_adaptive_warm_barrier(false)
        .adaptive_warm_barrier());
}

#[test]
fn a_refusal_names_the_setting() {
    let d = S::default();
    let cases = [
        (d.with_max_iter(0), "max_iter"),
        (d.with_tol(0.0), "tol "),
        (d.with_tol_dual(0.0), "tol_dual"),
        (d.with_step_fraction(1.0), "step_fraction"),
        (d.with_regularization(-1.0), "regularization"),
        (d.with_pivot_floor(0.0), "pivot_floor"),
        (d.with_refinement_steps(99), "refinement_steps"),
        (d.with_warm_barrier(2.0), "warm_barrier"),
        (d.with_active_set_iter(999), "active_set_iter"),
        (d.with_active_set_penalty(0.0), "active_set_penalty"),
    ];
    for (r, name) in cases {
        let e = r.expect_err("out of range");
        assert!(e.to_string().starts_with(name.trim()), "{e}");
    }
}

#[test]
fn the_solver_runs_on_what_it_was_given() {
    use planner_core::mpc::SingleLaneProblem;
    use planner_core::{CostWeights, IpmSolver, MpcSolver, Params};
    let p = Params::<f64>::table_i();
    let pr =
        SingleLaneProblem::<f64, 20>::new(&p, 20.0, 30.0, 0.0, CostWeights::default(), 0.0, 27.8)
            .expect("valid");
    let capped = S::default().with_max_iter(2).expect("valid");
    let mut solver = IpmSolver::<f64, 20>::new(capped);
    assert_eq!(solver.settings().max_iter(), 2);
    match solver.solve(&pr, None) {
        Err(SolveError::IterationLimit { iterations }) => assert!(iterations <= 2 * 2),
        other => panic!("two iterations cannot solve a cold start: {other:?}"),
    }
}
