//! Certified plan reuse (`planner_core::reuse`): the dual bound is a lower
//! bound on J* for any multipliers ≥ 0 and is tight at the solver's own; a reusing
//! planner applies only verified plans, whose certified gap bounds what they really give
//! up, decides exactly by its stated rule, and does reuse.

use planner_core::lane_change::{LaneObservation, LanePlanner};
use planner_core::lanes::Road;
use planner_core::planner::{free_road_gap, shifted, speed_slack, verify};
use planner_core::reuse::{certified_gap, dual_bound, lagrangian, Duals};
use planner_core::{
    ConfigError, CostWeights, FallbackReason, IpmSolver, MpcSolver, Params, Planner, Pose, Real,
    ReusePolicy, Settings, SingleLaneProblem, StepStatus,
};
use proptest::prelude::*;

const N: usize = 20;

fn p() -> Params<f64> {
    Params::table_i()
}

fn problem(
    v: f64,
    gap: f64,
    v_ref: f64,
    w_x: f64,
    target: f64,
) -> Option<SingleLaneProblem<f64, N>> {
    let w = CostWeights {
        target_position: w_x,
        ..CostWeights::default()
    };
    weighted(v, gap, v_ref, w, target)
}

fn weighted(
    v: f64,
    gap: f64,
    v_ref: f64,
    w: CostWeights<f64>,
    target: f64,
) -> Option<SingleLaneProblem<f64, N>> {
    let gap = gap.min(free_road_gap(&p(), N));
    SingleLaneProblem::new(&p(), v, gap, f64::SAFETY_MARGIN_M, w, target, v_ref).ok()
}

/// Cost weights with each term's weight apart from 1, so that a term's factor shows.
fn weight_choices() -> impl Strategy<Value = CostWeights<f64>> {
    (
        prop::sample::select(vec![0.0, 1e-3, 0.3]),
        prop::sample::select(vec![0.4, 1.0, 2.5]),
        prop::sample::select(vec![0.0, 3.0, 10.0]),
    )
        .prop_map(
            |(target_position, reference_speed, smoothness)| CostWeights {
                target_position,
                reference_speed,
                smoothness,
            },
        )
}

fn duals(a: [[f64; N]; 5]) -> Duals<f64, N> {
    let [upper, lower, accel, decel, safety] = a;
    Duals {
        upper,
        lower,
        accel,
        decel,
        safety,
    }
}

fn rel(j: f64) -> f64 {
    1.0 + j.abs()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 400, ..ProptestConfig::default() })]

    /// Weak duality: for any λ ≥ 0, q(λ) ≤ J*; and q does not depend on the point the
    /// Newton step starts from (L is quadratic: one step reaches its minimiser).
    #[test]
    fn the_dual_bound_is_a_lower_bound_from_anywhere(
        v in 0.0f64..27.8, extra in 0.0f64..150.0, v_ref in 0.0f64..27.8,
        w in weight_choices(), target in 0.0f64..80.0,
        lam in prop::array::uniform5(prop::array::uniform20(0.0f64..5.0)),
        a in prop::array::uniform20(0.0f64..27.8), b in prop::array::uniform20(0.0f64..27.8),
    ) {
        let gap = planner_core::safety::d_s(&p(), v) + 0.05 + extra;
        let Some(pr) = weighted(v, gap, v_ref, w, target) else { return Ok(()) };
        let Ok(sol) = IpmSolver::<f64, N>::default().solve(&pr, None) else { return Ok(()) };
        let d = duals(lam);
        let qa = dual_bound(&pr, &d, &a).unwrap();
        let qb = dual_bound(&pr, &d, &b).unwrap();
        let j = sol.objective;
        prop_assert!(qa <= j + 1e-7 * rel(j), "q = {qa} > J* = {j}");
        prop_assert!((qa - qb).abs() <= 1e-7 * rel(qa), "q from a {qa}, from b {qb}");
        // The minimiser beats the points it started from.
        prop_assert!(qa <= lagrangian(&pr, &d, &a) + 1e-9 * rel(qa));
        prop_assert!(qa <= lagrangian(&pr, &d, &b) + 1e-9 * rel(qa));
    }

    /// At the solver's optimum and with its own multipliers the bound closes: the
    /// certified gap of the optimal plan is ~0 (and never negative beyond rounding).
    #[test]
    fn the_dual_bound_is_tight_at_the_optimum(
        v in 0.0f64..27.8, extra in 0.0f64..150.0, v_ref in 0.0f64..27.8,
        w in weight_choices(), target in 0.0f64..80.0,
    ) {
        let gap = planner_core::safety::d_s(&p(), v) + 0.05 + extra;
        let Some(pr) = weighted(v, gap, v_ref, w, target) else { return Ok(()) };
        let mut s = IpmSolver::<f64, N>::default();
        let Ok(sol) = s.solve(&pr, None) else { return Ok(()) };
        let d = s.duals().expect("a successful solve leaves its duals");
        let g = certified_gap(&pr, &d, &sol.v).unwrap();
        let j = sol.objective;
        prop_assert!(g.abs() <= 1e-6 * rel(j), "certified gap {g} at the optimum, J* = {j}");
    }
}

/// Multipliers that are negative or not finite give no bound.
#[test]
fn invalid_multipliers_give_no_bound() {
    let pr = problem(10.0, 60.0, 20.0, 0.0, 0.0).unwrap();
    let v = [10.0; N];
    for bad in [-1e-9, f64::NAN, f64::INFINITY] {
        for family in 0..5 {
            let mut a = [[0.5; N]; 5];
            a[family][7] = bad;
            let d = duals(a);
            assert!(!d.valid());
            assert_eq!(dual_bound(&pr, &d, &v), None, "family {family}, λ = {bad}");
            assert_eq!(certified_gap(&pr, &d, &v), None);
        }
    }
    let d = duals([[0.0; N]; 5]);
    assert!(d.valid());
    // λ = 0: q is the unconstrained minimum of J, here J = 0 at v = v_prev = v_ref.
    let pr = problem(20.0, 200.0, 20.0, 0.0, 0.0).unwrap();
    let q = dual_bound(&pr, &d, &v).unwrap();
    assert!(q.abs() < 1e-9, "{q}");
}

/// Shifting moves every family's multipliers forward, repeating the last.
#[test]
fn duals_shift_with_the_plan() {
    let a: [[f64; N]; 5] = core::array::from_fn(|f| core::array::from_fn(|k| (10 * f + k) as f64));
    let d = duals(a).shifted(3);
    let families = [d.upper, d.lower, d.accel, d.decel, d.safety];
    for (f, fam) in families.iter().enumerate() {
        for (k, &x) in fam.iter().enumerate() {
            assert_eq!(x, (10 * f + (k + 3).min(N - 1)) as f64, "family {f}, k {k}");
        }
    }
    assert_eq!(duals(a).shifted(0), duals(a));
}

/// The solver reports its duals only after a successful solve, and `advance` moves them
/// one step on.
#[test]
fn the_solver_reports_and_advances_its_duals() {
    let pr = problem(12.0, 30.0, 27.8, 0.0, 0.0).unwrap();
    let mut s = IpmSolver::<f64, N>::default();
    assert!(s.duals().is_none());
    s.solve(&pr, None).unwrap();
    let d = s.duals().unwrap();
    let families = [d.upper, d.lower, d.accel, d.decel, d.safety];
    assert!(
        families.iter().flatten().any(|&x| x > 1e-3),
        "a constraint is active: {d:?}"
    );
    s.advance();
    assert_eq!(s.duals().unwrap(), d.shifted(1));
    let mut capped = IpmSolver::<f64, N>::new(Settings::default().with_max_iter(1).expect("valid"));
    assert!(capped.solve(&pr, None).is_err());
    assert!(capped.duals().is_none());
}

/// What the planner should do at a step by the rule of `Planner::try_reuse`, computed
/// from its public state before the step: `Some(certified gap)` to reuse.
fn expected_reuse(
    pl: &Planner<f64, N>,
    last: Option<StepStatus<f64>>,
    age: u8,
    pr: &SingleLaneProblem<f64, N>,
) -> Option<f64> {
    let policy = pl.reuse()?;
    let fresh = matches!(last?, StepStatus::Solved { .. } | StepStatus::Reused { .. });
    if !fresh || age >= policy.max_age {
        return None;
    }
    let plan = verify(&p(), pr, shifted(pl.plan()?)).ok()?;
    let d = pl.solver().duals()?.shifted(1);
    let g = certified_gap(pr, &d, &plan)?;
    (g <= policy.tolerance * rel(pr.objective(&plan))).then_some(g)
}

/// A drive behind a stop-and-go leader: the planner reuses exactly when its rule says,
/// every reused plan satisfies this step's exact constraints, and its certified gap
/// bounds J(plan) − J* as a fresh solve finds it.
#[test]
fn a_reusing_planner_follows_its_rule_and_its_certificate_holds() {
    let p = p();
    let policy = ReusePolicy {
        tolerance: 1e-2,
        max_age: 3,
    };
    let mut pl = Planner::<f64, N>::new(p, CostWeights::default()).unwrap();
    pl.set_reuse(Some(policy)).unwrap();
    assert_eq!(pl.reuse(), Some(policy));
    let mut check = IpmSolver::<f64, N>::default();
    let (mut x, mut v, mut xl, mut vl) = (0.0f64, 15.0f64, 60.0f64, 15.0f64);
    let (mut last, mut age) = (None, 0u8);
    let (mut reused, mut solved, mut oldest) = (0, 0, 0u8);
    for step in 0..4000u32 {
        let accel = if (step / 300) % 2 == 0 {
            0.9 * p.a_min()
        } else {
            p.a_max()
        };
        let gap = (xl - x - p.length() - p.d0()).min(free_road_gap(&p, N));
        let pr = problem(v, gap, p.v_max(), 0.0, 0.0).unwrap();
        let expected = expected_reuse(&pl, last, age, &pr);
        let c = pl.step_gap(v, gap, 0.0, p.v_max()).unwrap();
        match c.status {
            StepStatus::Reused {
                age: a,
                certified_gap: g,
            } => {
                assert_eq!(expected, Some(g), "step {step}");
                assert_eq!(a, age + 1, "step {step}");
                let plan = *pl.plan().unwrap();
                let worst = pr.max_violation(&plan);
                assert!(
                    worst.amount <= speed_slack(&p).max(f64::VERIFY_SLACK_M),
                    "{worst:?}"
                );
                let best = check.solve(&pr, None).unwrap().objective;
                let lost = pr.objective(&plan) - best;
                assert!(
                    lost <= g + 1e-7 * rel(best),
                    "step {step}: lost {lost} > certified {g}"
                );
                assert_eq!(c.v, plan[0]);
                reused += 1;
                age = a;
                oldest = oldest.max(a);
            }
            StepStatus::Solved { .. } => {
                assert_eq!(expected, None, "step {step}: should have reused");
                solved += 1;
                age = 0;
            }
            StepStatus::Fallback(FallbackReason::NoRoom | FallbackReason::InvariantViolated) => {}
            other => panic!("step {step}: {other:?}"),
        }
        last = Some(c.status);
        v = c.v;
        x += v * p.h();
        vl = (vl + accel * p.h()).clamp(0.0, p.v_max());
        xl += vl * p.h();
    }
    assert!(
        reused > 400 && solved > 400,
        "reused {reused}, solved {solved}"
    );
    assert_eq!(oldest, policy.max_age);
}

/// Without a policy nothing is reused; a bad policy is refused and changes nothing.
#[test]
fn reuse_is_opt_in_and_checked() {
    let p = p();
    let mut pl = Planner::<f64, N>::new(p, CostWeights::default()).unwrap();
    assert_eq!(pl.reuse(), None);
    for _ in 0..50 {
        let c = pl.step_gap(20.0, 500.0, 0.0, 20.0).unwrap();
        assert!(matches!(c.status, StepStatus::Solved { .. }), "{c:?}");
    }
    let good = ReusePolicy {
        tolerance: 0.0,
        max_age: 2,
    };
    pl.set_reuse(Some(good)).unwrap();
    for bad in [-1e-3, f64::NAN, f64::INFINITY] {
        let r = pl.set_reuse(Some(ReusePolicy {
            tolerance: bad,
            max_age: 9,
        }));
        assert_eq!(r, Err(ConfigError::InvalidReuse));
        assert_eq!(pl.reuse(), Some(good));
    }
    pl.set_reuse(None).unwrap();
    assert_eq!(pl.reuse(), None);
    assert_eq!(ReusePolicy::<f64>::default().max_age, 4);
}

/// Cruising at the reference speed on a free road, the shifted plan is optimal: the
/// planner reuses it up to the age cap, then solves, and after a reset starts cold.
#[test]
fn a_cruising_planner_reuses_up_to_its_cap() {
    let mut pl = Planner::<f64, N>::new(p(), CostWeights::default()).unwrap();
    pl.set_reuse(Some(ReusePolicy::default())).unwrap();
    let mut kinds = Vec::new();
    for _ in 0..11 {
        let c = pl.step_gap(20.0, 1e4, 0.0, 20.0).unwrap();
        kinds.push(match c.status {
            StepStatus::Solved { .. } => 0,
            StepStatus::Reused { age, certified_gap } => {
                assert!(certified_gap.abs() < 1e-6, "{certified_gap}");
                age
            }
            s => panic!("{s:?}"),
        });
        assert!((c.v - 20.0).abs() < 1e-9);
    }
    assert_eq!(kinds, [0, 1, 2, 3, 4, 0, 1, 2, 3, 4, 0]);
    pl.reset();
    let c = pl.step_gap(20.0, 1e4, 0.0, 20.0).unwrap();
    assert!(matches!(c.status, StepStatus::Solved { .. }));
    // A caller's braking plan is not a solved one: the next step solves.
    pl.set_braking_plan(20.0);
    let c = pl.step_gap(20.0, 1e4, 0.0, 20.0).unwrap();
    assert!(matches!(c.status, StepStatus::Solved { .. }));
}

/// The multi-lane planner passes the policy to its speed planner.
#[test]
fn the_lane_planner_reuses_too() {
    let mut pl = LanePlanner::<f64, N>::new(p(), CostWeights::default(), 0).unwrap();
    pl.set_reuse(Some(ReusePolicy::default())).unwrap();
    assert_eq!(
        pl.set_reuse(Some(ReusePolicy {
            tolerance: -1.0,
            max_age: 1
        })),
        Err(ConfigError::InvalidReuse)
    );
    let mut reused = 0;
    let mut x = 0.0;
    for _ in 0..20 {
        let o = LaneObservation {
            pose: Pose {
                x,
                y: 1.8,
                theta: 0.0,
            },
            v_prev: 15.0,
            omega_prev: 0.0,
            others: &[],
            road: Road {
                lanes: 3,
                lane_width: 3.6,
                end_x: None,
            },
            target_lane: 0,
            target: 0.0,
            v_ref: 15.0,
        };
        let c = pl.step(&o).unwrap();
        reused += u32::from(matches!(c.status, StepStatus::Reused { .. }));
        x += 15.0 * p().h();
    }
    assert!(reused >= 10, "{reused}");
}
