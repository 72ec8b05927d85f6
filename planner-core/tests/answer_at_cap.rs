//! `Settings::with_answer_at_cap`: the iteration cap as a deadline. A solve never takes
//! more Newton steps than `max_iter`, all of them counted (active-set steps and a retry's
//! too); at the cap it answers with its iterate (`Method::Capped`), which the planner
//! applies only if the exact verification of (10) passes — so a capped planner's every
//! solved command is a verified plan's first speed, and its vehicle stays safe behind a
//! leader that brakes and starts again.

use planner_core::planner::verify;
use planner_core::{
    CostWeights, IpmSolver, Method, MpcSolver, Params, Planner, Real, Settings, SingleLaneProblem,
    SolveError, StepStatus,
};
use proptest::prelude::*;

const N: usize = 50;

fn capped(max_iter: u32) -> Settings<f32> {
    Settings::default()
        .with_max_iter(max_iter)
        .expect("a cap in range")
        .with_answer_at_cap(true)
}

fn problem(v_prev: f32, gap: f32, v_ref: f32) -> SingleLaneProblem<f32, N> {
    SingleLaneProblem::new(
        &Params::table_i(),
        v_prev,
        gap,
        f32::SAFETY_MARGIN_M,
        CostWeights::default(),
        0.0,
        v_ref,
    )
    .expect("a valid problem")
}

#[test]
fn at_the_cap_it_answers_with_its_iterate_instead_of_an_error() {
    // A cold start from standing takes more than two steps (7 at N = 50).
    let pr = problem(0.0, 100.0, 15.0);
    let plain = Settings::default().with_max_iter(2).expect("in range");
    let err = IpmSolver::<f32, N>::new(plain).solve(&pr, None);
    assert_eq!(err, Err(SolveError::IterationLimit { iterations: 2 }));
    let sol = IpmSolver::<f32, N>::new(capped(2))
        .solve(&pr, None)
        .expect("an answer at the cap");
    assert_eq!((sol.method, sol.iterations), (Method::Capped, 2));
    // Given enough steps it converges as without the deadline, to the same plan.
    let full = IpmSolver::<f32, N>::new(capped(60))
        .solve(&pr, None)
        .expect("solves");
    let free = IpmSolver::<f32, N>::new(Settings::default())
        .solve(&pr, None)
        .expect("solves");
    assert_eq!(full.method, Method::InteriorPoint);
    assert_eq!(full.v, free.v);
    assert!(!Settings::<f32>::default().answer_at_cap());
    assert!(capped(5).answer_at_cap());
}

#[test]
fn the_planners_take_the_settings() {
    let mut pl = Planner::<f32, N>::new(Params::table_i(), CostWeights::default()).expect("ok");
    assert_eq!(pl.solver().settings(), &Settings::default());
    pl.set_solver_settings(capped(7));
    assert_eq!(pl.solver().settings(), &capped(7));
    let mut lp =
        planner_core::LanePlanner::<f32, N>::new(Params::table_i(), CostWeights::default(), 0)
            .expect("ok");
    assert_eq!(lp.solver_settings(), &Settings::default());
    lp.set_solver_settings(capped(7));
    assert_eq!(lp.solver_settings(), &capped(7));
}

/// One vehicle behind a leader that cruises, brakes fully to a stop, waits and pulls
/// away, planned by a capped planner: (steps solved, capped answers applied, fallbacks,
/// smallest gap left beyond the safe distance).
fn follow(max_iter: u32, v0: f32, gap0: f32, brake_at: u32) -> (u32, u32, u32, f32) {
    let p = Params::<f32>::table_i();
    let mut pl = Planner::<f32, N>::new(p, CostWeights::default()).expect("table I");
    pl.set_solver_settings(capped(max_iter));
    let (h, brake) = (p.h(), p.brake());
    let (mut v, mut lead_v, mut gap) = (v0, v0, gap0);
    let (mut solved, mut capped_used, mut fallbacks) = (0, 0, 0);
    let mut least = f32::INFINITY;
    for k in 0..800u32 {
        // The leader: cruise, brake at its limit to a stop, wait, start again.
        lead_v = if k < brake_at {
            lead_v
        } else if k < brake_at + 300 {
            (lead_v - brake * h).max(0.0)
        } else {
            (lead_v + 2.0 * h).min(v0)
        };
        let c = pl.step_gap(v, gap, 0.0, 15.0).expect("valid input");
        match c.status {
            StepStatus::Solved { iterations, method } => {
                assert!(
                    iterations <= max_iter,
                    "{iterations} steps past a cap of {max_iter}"
                );
                solved += 1;
                if method == Method::Capped {
                    capped_used += 1;
                    // What was applied is a verified plan's first speed.
                    let pr = problem(v, gap, 15.0);
                    let plan = pl.plan().copied().expect("a solved step leaves its plan");
                    assert_eq!(verify(&p, &pr, plan), Ok(plan));
                    assert_eq!(plan.first().copied(), Some(c.v));
                }
            }
            StepStatus::Fallback(_) => fallbacks += 1,
            _ => {}
        }
        // The world: both move a period; the invariant of Lemma 3 toward the leader's
        // position (the paper's wall): dS(v) < gap.
        gap += (lead_v - c.v) * h;
        v = c.v;
        least = least.min(gap - planner_core::safety::d_s(&p, v));
    }
    (solved, capped_used, fallbacks, least)
}

#[test]
fn a_capped_planner_follows_a_stopping_leader_safely() {
    let (solved, capped_used, fallbacks, least) = follow(4, 15.0, 60.0, 100);
    println!("cap 4: {solved} solved ({capped_used} capped), {fallbacks} fallbacks, least {least}");
    assert!(
        capped_used > 0,
        "a cap of 4 at N = 50 is reached on this drive"
    );
    assert!(least >= 0.0, "the invariant broke: {least}");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]
    #[test]
    fn every_cap_keeps_the_invariant(
        max_iter in 1u32..12,
        v0 in 0.0f32..20.0,
        slack in 1.0f32..40.0,
        brake_at in 0u32..200,
    ) {
        let p = Params::<f32>::table_i();
        let gap0 = planner_core::safety::d_s(&p, v0) + p.h() * v0 + slack;
        let (_, _, _, least) = follow(max_iter, v0, gap0, brake_at);
        prop_assert!(least >= 0.0, "cap {}: the invariant broke by {}", max_iter, least);
    }
}
