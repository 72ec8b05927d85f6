//! The verifier at its edge: a plan is accepted only if it keeps every
//! constraint of the exact (10) within the documented slack — safety within
//! `Real::VERIFY_SLACK_M` of the margin-tightened gap, the linear constraints within
//! `speed_slack` — in f32 and in f64, for each constraint kind. Each case sits at twice
//! the slack (rejected) and at half of it (accepted), so a slack made ten times looser, or
//! a check dropped, fails here.

use planner_core::mpc::{ConstraintKind, SingleLaneProblem};
use planner_core::planner::{speed_slack, verify, Vehicle};
use planner_core::{
    CostWeights, FallbackReason, Method, MpcSolver, Observation, Params, Planner, Real, Solution,
    SolveError, StepStatus,
};

const N: usize = 20;

/// A problem at 20 m/s with a wide speed range and a far obstacle.
fn problem<F: Real>() -> SingleLaneProblem<F, N> {
    let p = Params::<F>::table_i();
    let v0 = F::from_f64(20.0);
    SingleLaneProblem {
        h: p.h(),
        brake: p.brake(),
        dv_max: p.a_max() * p.h(),
        dv_min: -p.brake() * p.h(),
        gap: F::from_f64(1000.0),
        v_prev: v0,
        lo: [F::ZERO; N],
        hi: [p.v_max(); N],
        hi_exact: [p.v_max(); N],
        weights: CostWeights::default(),
        target: F::ZERO,
        v_ref: v0,
    }
}

/// The largest safety value (≤ 0 when kept) of plan `v`.
fn safety_excess<F: Real>(pr: &SingleLaneProblem<F, N>, v: &[F; N]) -> F {
    let mut worst = F::from_f64(-1e30);
    pr.for_each_constraint(v, |g, kind, _| {
        if kind == ConstraintKind::Safety && g > worst {
            worst = g;
        }
        true
    });
    worst
}

/// `pr` with its gap moved so that the constant plan at v_prev exceeds the safety
/// constraint by exactly `excess` (m).
fn at_safety_excess<F: Real>(
    mut pr: SingleLaneProblem<F, N>,
    excess: F,
) -> (SingleLaneProblem<F, N>, [F; N]) {
    let plan = [pr.v_prev; N];
    let now = safety_excess(&pr, &plan);
    pr.gap += now - excess;
    (pr, plan)
}

fn safety_edge<F: Real>() {
    let slack = F::VERIFY_SLACK_M;
    let (pr, plan) = at_safety_excess(problem::<F>(), F::TWO * slack);
    let p = Params::<F>::table_i();
    let err = verify(&p, &pr, plan).expect_err("twice the slack beyond the safety constraint");
    assert_eq!(err.kind, ConstraintKind::Safety);
    assert!(err.amount > slack, "{:?}", err.amount.to_f64());
    let (pr, plan) = at_safety_excess(problem::<F>(), F::HALF * slack);
    let ok = verify(&p, &pr, plan).expect("half the slack is within the tolerance");
    assert!(safety_excess(&pr, &ok) <= slack);
    // The exact (untightened) constraint is kept with margin − slack to spare: at least
    // three quarters of the margin (f32: 2 cm − 5 mm; f64: 1 µm − 0.1 µm).
    assert!(slack <= F::SAFETY_MARGIN_M / F::from_f64(4.0));
}

#[test]
fn safety_is_verified_to_its_slack_f32() {
    safety_edge::<f32>();
}

#[test]
fn safety_is_verified_to_its_slack_f64() {
    safety_edge::<f64>();
}

/// The linear constraints are clamped exactly; what cannot be clamped — an interval of
/// V^k_t emptied by more than the slack, by its own ends or by the acceleration bounds —
/// is refused.
fn linear_edges<F: Real>() {
    let p = Params::<F>::table_i();
    let slack = speed_slack(&p);
    // The documented slack: the rounding of one subtraction of speeds ≤ vmax (8 ulp).
    let documented = F::from_f64(8.0) * F::EPSILON * (p.v_max() + F::ONE);
    assert!(slack <= documented, "{}", slack.to_f64());
    let two = F::TWO * slack;
    let half = F::HALF * slack;
    let plan = [F::from_f64(20.0); N];
    type Edit<F> = fn(&mut SingleLaneProblem<F, N>, F);
    let cases: [(&str, Edit<F>); 3] = [
        // V^5_t: lower end above the upper end.
        ("speed interval", |pr, by| {
            pr.lo[5] = F::from_f64(20.0);
            pr.hi_exact[5] = F::from_f64(20.0) - by;
        }),
        // v_0 must rise above v_prev + amax h.
        ("acceleration", |pr, by| {
            pr.lo[0] = pr.v_prev + pr.dv_max + by;
            pr.hi_exact[0] = pr.lo[0] + F::ONE;
        }),
        // v_0 must fall below v_prev + amin h.
        ("deceleration", |pr, by| {
            pr.hi_exact[0] = pr.v_prev + pr.dv_min - by;
            pr.lo[0] = F::ZERO;
        }),
    ];
    for (name, edit) in cases {
        let mut pr = problem::<F>();
        edit(&mut pr, two);
        let err = verify(&p, &pr, plan).expect_err(name);
        assert_eq!(err.kind, ConstraintKind::SpeedUpper, "{name}");
        let mut pr = problem::<F>();
        edit(&mut pr, half);
        let v = verify(&p, &pr, plan).unwrap_or_else(|e| panic!("{name}: {e:?}"));
        // Within the slack, the lower (slower) end is taken.
        assert!(v.iter().all(|x| x.is_finite()), "{name}");
    }
    // A plan beyond the speed and acceleration limits by twice the slack, in an
    // interval that is not empty, is clamped into them exactly.
    let mut wild = plan;
    wild[0] = plan[0] + problem::<F>().dv_max + two;
    wild[7] = p.v_max() + two;
    let pr = problem::<F>();
    let v = verify(&p, &pr, wild).expect("clamped");
    let exact = SingleLaneProblem {
        hi: pr.hi_exact,
        ..pr.clone()
    };
    exact.for_each_constraint(&v, |g, kind, k| {
        if kind != ConstraintKind::Safety {
            assert!(g <= slack, "{kind:?} at {k}: {}", g.to_f64());
        }
        true
    });
    assert!(v[0] <= pr.v_prev + pr.dv_max + slack && v[7] <= p.v_max() + slack);
}

#[test]
fn linear_constraints_are_verified_to_their_slack_f32() {
    linear_edges::<f32>();
}

#[test]
fn linear_constraints_are_verified_to_their_slack_f64() {
    linear_edges::<f64>();
}

/// A solver that answers with the constant plan at the speed whose safety excess is
/// `excess`, found by bisection: the planner's own problem, at its edge.
struct EdgeSolver<F> {
    excess: F,
}

impl<F: Real> MpcSolver<F, N> for EdgeSolver<F> {
    fn solve(
        &mut self,
        problem: &SingleLaneProblem<F, N>,
        _warm: Option<&[F; N]>,
    ) -> Result<Solution<F, N>, SolveError> {
        // Speeds within one step's acceleration of v_prev; the excess grows with speed.
        let (mut lo, mut hi) = (
            problem.v_prev + problem.dv_min,
            problem.v_prev + problem.dv_max,
        );
        for _ in 0..200 {
            let mid = F::HALF * (lo + hi);
            if safety_excess(problem, &[mid; N]) > self.excess {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        let v = [lo; N];
        Ok(Solution {
            v,
            objective: problem.objective(&v),
            iterations: 1,
            method: Method::InteriorPoint,
        })
    }
}

/// Through the planner: a leader placed so that a constant speed near v_prev is on the
/// boundary of the tightened safety constraint; a solver answering twice the slack beyond
/// it gets the certified fallback, half the slack is applied.
fn planner_edge<F: Real>() {
    let p = Params::<F>::table_i();
    let v0 = F::from_f64(20.0);
    let slack = F::VERIFY_SLACK_M;
    // Constant v0 for N steps plus dS(v0): where the boundary is, give or take a step's
    // acceleration (the bisection finds the exact speed).
    let travel = F::from_usize(N) * p.h() * v0 + v0 * v0 / (F::TWO * p.brake());
    let leader = Vehicle::wall(
        travel + p.length() + p.d0() + F::SAFETY_MARGIN_M,
        p.length(),
    );
    let cars = [leader];
    let obs = Observation {
        x: F::ZERO,
        v_prev: v0,
        vehicles: &cars,
        stop_line: None,
        target_x: F::ZERO,
        v_ref: v0,
    };
    for (excess, accepted) in [(F::TWO * slack, false), (F::HALF * slack, true)] {
        let mut pl = Planner::with_solver(p, CostWeights::default(), EdgeSolver { excess })
            .expect("weights");
        let c = pl.step(&obs).expect("valid input");
        match (c.status, accepted) {
            (StepStatus::Solved { .. }, true) => {}
            (StepStatus::Fallback(FallbackReason::Verification(v)), false) => {
                assert_eq!(v.kind, ConstraintKind::Safety)
            }
            (s, _) => panic!("excess {}: {s:?}", excess.to_f64()),
        }
    }
}

#[test]
fn the_planner_applies_a_plan_only_within_the_slack_f32() {
    planner_edge::<f32>();
}

#[test]
fn the_planner_applies_a_plan_only_within_the_slack_f64() {
    planner_edge::<f64>();
}
