//! Behaviour of the planner step: obstacles, verification, fallback, bad input.

use planner_core::mpc::SingleLaneProblem;
use planner_core::planner::{obstacle_position, Vehicle};
use planner_core::safety::{d_s, max_braking_command};
use planner_core::{
    CostWeights, FallbackReason, InputError, Method, MpcSolver, Observation, Params, Planner,
    Solution, SolveError, StepStatus,
};

const N: usize = 20;

fn planner() -> Planner<f64, N> {
    Planner::new(Params::table_i(), CostWeights::default()).expect("valid weights")
}

fn obs<'a>(x: f64, v: f64, vehicles: &'a [Vehicle<f64>]) -> Observation<'a, f64> {
    Observation {
        x,
        v_prev: v,
        vehicles,
        stop_line: None,
        target_x: 0.0,
        v_ref: 27.8,
    }
}

#[test]
fn obstacle_is_nearest_vehicle_ahead_extent_adjusted() {
    let p = Params::<f64>::table_i();
    let cars = [
        Vehicle::wall(50.0, 4.5),
        Vehicle::wall(30.0, 6.0),
        Vehicle::wall(-10.0, 4.5),
    ];
    // 30 − (6 + 4.5)/2 − 0.5 = 24.25
    assert_eq!(obstacle_position(&p, 0.0, &cars, None), Some(24.25));
    // A stop line nearer than any vehicle: 20 − 4.5/2 − 0.5.
    assert_eq!(obstacle_position(&p, 0.0, &cars, Some(20.0)), Some(17.25));
    assert_eq!(obstacle_position(&p, 100.0, &cars, None), None);
    // A vehicle exactly at the ego's position is not ahead (eq. (2) takes x(c) > x_t).
    assert_eq!(obstacle_position(&p, 30.0, &cars, None), Some(45.0));
}

#[test]
fn free_road_accelerates_within_limits() {
    let mut pl = planner();
    let c = pl.step(&obs(0.0, 10.0, &[])).expect("valid input");
    assert!(matches!(c.status, StepStatus::Solved { .. }), "{c:?}");
    assert!(
        (c.v - 10.038).abs() < 1e-6,
        "full acceleration toward v_ref: {}",
        c.v
    );
}

#[test]
fn closes_on_stopped_leader_keeping_the_invariant() {
    let mut pl = planner();
    let p = Params::<f64>::table_i();
    // Gap just above dS(20) + extents, leader stopped: the planner must stop behind it,
    // keeping x_t < x̄ − dS(v_{t−h}) at every step (Theorem 1's induction).
    let leader_x = 4.5 + 0.5 + d_s(&p, 20.0) + 0.3;
    let cars = [Vehicle::wall(leader_x, 4.5)];
    let (mut x, mut v) = (0.0, 20.0);
    for _ in 0..600 {
        let c = pl.step(&obs(x, v, &cars)).expect("valid input");
        // Solved all the way; max braking is forced only once (nearly) stopped.
        match c.status {
            StepStatus::Solved { .. } => {}
            StepStatus::Fallback(FallbackReason::NoRoom) => assert!(v < 0.1, "{c:?} at v={v}"),
            other => panic!("{other:?} at x = {x}, v = {v}"),
        }
        assert!(c.v >= v - 0.079 - 1e-12 && c.v <= v + 0.038 + 1e-12);
        v = c.v;
        x += v * 0.01;
        assert!(
            x < leader_x - 5.0 - d_s(&p, v),
            "invariant at x = {x}, v = {v}"
        );
    }
    assert!(v < 1e-9, "stopped: {v}");
}

#[test]
fn invariant_violation_gives_certified_fallback() {
    let mut pl = planner();
    let cars = [Vehicle::wall(8.0, 4.5)];
    let c = pl.step(&obs(0.0, 20.0, &cars)).expect("valid input");
    assert_eq!(
        c.status,
        StepStatus::Fallback(FallbackReason::InvariantViolated)
    );
    assert_eq!(c.v, max_braking_command(pl.params(), 20.0));
}

#[test]
fn bad_input_is_rejected_and_changes_nothing() {
    let mut pl = planner();
    pl.step(&obs(0.0, 10.0, &[])).expect("valid input");
    let before = *pl.plan().expect("a plan");
    let nan_car = [Vehicle::wall(f64::NAN, 4.5)];
    assert_eq!(
        pl.step(&obs(0.0, 10.0, &nan_car)),
        Err(InputError::NotFinite)
    );
    assert_eq!(
        pl.step(&obs(f64::INFINITY, 10.0, &[])),
        Err(InputError::NotFinite)
    );
    assert_eq!(
        pl.step(&obs(0.0, -1.0, &[])),
        Err(InputError::SpeedOutOfRange)
    );
    assert_eq!(
        pl.step(&obs(0.0, 30.0, &[])),
        Err(InputError::SpeedOutOfRange)
    );
    let bad_len = [Vehicle::wall(10.0, 0.0)];
    assert_eq!(
        pl.step(&obs(0.0, 10.0, &bad_len)),
        Err(InputError::BadLength)
    );
    assert_eq!(pl.plan(), Some(&before));
}

#[test]
fn invalid_weights_are_rejected() {
    let w = CostWeights {
        target_position: 1.0,
        reference_speed: 0.0,
        smoothness: 0.0,
    };
    assert!(Planner::<f64, N>::new(Params::table_i(), w).is_err());
    let w = CostWeights {
        target_position: f64::NAN,
        ..CostWeights::default()
    };
    assert!(Planner::<f64, N>::new(Params::table_i(), w).is_err());
}

/// A solver that returns whatever plan it is told to: the verifier must catch unsafe ones.
struct Scripted(Result<[f64; N], SolveError>);

impl MpcSolver<f64, N> for Scripted {
    fn solve(
        &mut self,
        problem: &SingleLaneProblem<f64, N>,
        _warm: Option<&[f64; N]>,
    ) -> Result<Solution<f64, N>, SolveError> {
        self.0.map(|v| Solution {
            v,
            objective: problem.objective(&v),
            iterations: 1,
            method: Method::InteriorPoint,
        })
    }
}

#[test]
fn verifier_rejects_unsafe_plan_and_falls_back() {
    let p = Params::<f64>::table_i();
    let leader_x = 4.5 + 0.5 + d_s(&p, 20.0) + 0.5;
    let cars = [Vehicle::wall(leader_x, 4.5)];
    // Keeps accelerating into the leader: within the speed and acceleration limits only
    // for a few steps, and violating the safety constraint of (10).
    let reckless: [f64; N] = core::array::from_fn(|k| 20.0 + 0.038 * (k as f64 + 1.0));
    let mut pl =
        Planner::with_solver(p, CostWeights::default(), Scripted(Ok(reckless))).expect("weights");
    let c = pl.step(&obs(0.0, 20.0, &cars)).expect("valid input");
    match c.status {
        StepStatus::Fallback(FallbackReason::Verification(_)) => {}
        other => panic!("expected verification fallback, got {other:?}"),
    }
    assert_eq!(c.v, max_braking_command(&p, 20.0));

    let mut pl = Planner::with_solver(
        p,
        CostWeights::default(),
        Scripted(Err(SolveError::IterationLimit { iterations: 60 })),
    )
    .expect("weights");
    let c = pl.step(&obs(0.0, 20.0, &cars)).expect("valid input");
    assert_eq!(
        c.status,
        StepStatus::Fallback(FallbackReason::Solver(SolveError::IterationLimit {
            iterations: 60
        }))
    );
}

#[test]
fn stop_line_is_respected() {
    let mut pl = planner();
    let mut x = 0.0;
    let mut v = 15.0;
    for _ in 0..1500 {
        let o = Observation {
            stop_line: Some(60.0),
            ..obs(x, v, &[])
        };
        let c = pl.step(&o).expect("valid input");
        v = c.v;
        x += v * 0.01;
    }
    assert!(v < 1e-6, "stopped: {v}");
    assert!(
        x + 4.5 / 2.0 <= 60.0,
        "front bumper before the line: {}",
        x + 2.25
    );
    assert!(x + 2.25 > 59.0, "and close to it: {}", x + 2.25);
}

/// The bus's position step: every vehicle ahead is taken half a step nearer (its position
/// was heard rounded), the stop line is not; bad steps are refused and change nothing.
#[test]
fn a_bus_resolution_takes_each_vehicle_half_a_step_nearer() {
    let car = [Vehicle::wall(60.0, 4.5)];
    let mut exact = planner();
    let mut rounded = planner();
    rounded.set_bus_resolution(0.25, 0.02).expect("valid");
    assert_eq!(rounded.bus_resolution(), 0.25);
    let a = exact.step(&obs(0.0, 10.0, &car)).expect("valid");
    let b = rounded.step(&obs(0.0, 10.0, &car)).expect("valid");
    assert!((a.gap - b.gap - 0.125).abs() < 1e-12, "{} {}", a.gap, b.gap);
    // A stop line alone: the planner's own, so no step applies.
    let mut line = obs(0.0, 10.0, &[]);
    line.stop_line = Some(60.0);
    let a = exact.step(&line).expect("valid");
    let b = rounded.step(&line).expect("valid");
    assert_eq!(a.gap, b.gap);
    for (pos, speed) in [
        (-0.1, 0.0),
        (0.0, 1.0),
        (f64::NAN, 0.0),
        (0.1, f64::INFINITY),
    ] {
        assert_eq!(
            rounded.set_bus_resolution(pos, speed),
            Err(planner_core::ConfigError::InvalidResolution)
        );
        assert_eq!(rounded.bus_resolution(), 0.25, "a refusal changes nothing");
    }
}
