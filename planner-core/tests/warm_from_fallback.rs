//! `Planner::set_warm_from_fallback`: after a fallback, a planner set to `false` solves
//! cold — exactly as a planner that never planned, whatever it solved before — and one
//! left at the default starts from the fallback's braking plan, the vertex where the
//! interior-point method creeps (the firmware's late period in the loop).

use planner_core::{
    CostWeights, FallbackReason, IpmSolver, LanePlanner, LanePlannerSlot, Method, MpcSolver,
    Params, Planner, PlannerSlot, Real, Settings, SingleLaneProblem, StepStatus,
};

const N: usize = 20;

fn planner() -> Planner<f32, N> {
    Planner::new(Params::table_i(), CostWeights::default()).expect("table I is valid")
}

/// A drive that solves, falls back (its gap cut below its stopping distance), stands with
/// no room (a fallback at v = 0: the braking plan is all zeros), then has room ahead
/// again: the gap and speed the firmware's vehicle 2 saw in the loop.
fn after_a_fallback(pl: &mut Planner<f32, N>) -> StepStatus<f32> {
    let solved = pl.step_gap(5.0, 100.0, 0.0, 15.0).expect("valid");
    assert!(matches!(solved.status, StepStatus::Solved { .. }));
    let fallback = pl.step_gap(5.0, 0.5, 0.0, 15.0).expect("valid");
    assert_eq!(
        fallback.status,
        StepStatus::Fallback(FallbackReason::InvariantViolated)
    );
    let no_room = pl
        .step_gap(0.0, f32::SAFETY_MARGIN_M + 2e-4, 0.0, 15.0)
        .expect("valid");
    assert_eq!(no_room.status, StepStatus::Fallback(FallbackReason::NoRoom));
    let standing = pl
        .step_gap(0.0, f32::SAFETY_MARGIN_M + 0.07, 0.0, 15.0)
        .expect("valid");
    standing.status
}

#[test]
fn the_default_starts_from_the_braking_plan() {
    assert!(planner().warm_from_fallback());
    let mut pl = planner();
    pl.set_warm_from_fallback(false);
    assert!(!pl.warm_from_fallback());
    pl.set_warm_from_fallback(true);
    assert!(pl.warm_from_fallback());
    let mut lp =
        LanePlanner::<f32, N>::new(Params::table_i(), CostWeights::default(), 0).expect("valid");
    assert!(lp.warm_from_fallback());
    lp.set_warm_from_fallback(false);
    assert!(!lp.warm_from_fallback());
}

#[test]
fn a_planner_built_in_a_slot_has_the_default() {
    // The empty slot holds `false` (all zeros, so that a static slot sits in .bss); a
    // planner built in it is what `new` builds, and so is one rebuilt after a change.
    let mut slot = PlannerSlot::<f32, N>::new();
    let pl = slot
        .init(Params::table_i(), CostWeights::default())
        .expect("valid");
    assert!(pl.warm_from_fallback());
    pl.set_warm_from_fallback(false);
    let pl = slot
        .init(Params::table_i(), CostWeights::default())
        .expect("valid");
    assert!(pl.warm_from_fallback());
    let mut lane_slot = LanePlannerSlot::<f32, N>::new();
    let lp = lane_slot
        .init(Params::table_i(), CostWeights::default(), 0)
        .expect("valid");
    assert!(lp.warm_from_fallback());
}

#[test]
fn after_a_fallback_it_solves_as_a_fresh_planner_does() {
    let mut cold = planner();
    cold.set_warm_from_fallback(false);
    let status = after_a_fallback(&mut cold);
    let fresh = planner()
        .step_gap(0.0, f32::SAFETY_MARGIN_M + 0.07, 0.0, 15.0)
        .expect("valid");
    assert_eq!(status, fresh.status);
    assert_eq!(cold.plan(), planner_plan(0.07).as_ref());
}

/// A fresh planner's plan for standing with `room` ahead.
fn planner_plan(room: f32) -> Option<[f32; N]> {
    let mut pl = planner();
    pl.step_gap(0.0, f32::SAFETY_MARGIN_M + room, 0.0, 15.0)
        .expect("valid");
    pl.plan().copied()
}

/// The speed problem vehicle 2's computer solved in the loop (multi-lane road, N = 20,
/// f32) when it could move again after standing with no room: 0.0693 m of room ahead of
/// its stopping point, v_{t−h} = 0, v_ref = 15 m/s.
fn standing_start() -> SingleLaneProblem<f32, N> {
    let gap = f32::from_bits(0x3d8e_017a);
    SingleLaneProblem::new(
        &Params::table_i(),
        0.0,
        gap,
        0.0,
        CostWeights::default(),
        0.0,
        15.0,
    )
    .expect("the invariant holds")
}

#[test]
fn from_the_braking_plan_the_standing_start_takes_twice_as_long() {
    let pr = standing_start();
    // The problem as the firmware had it: V^k_t rises at amax, then falls to the stop.
    assert!((pr.hi[14] - 0.57).abs() < 1e-6 && (pr.hi[19] - 0.259_127_7).abs() < 1e-6);
    let braking_plan = [0.0f32; N];
    let iterations = |warm: Option<&[f32; N]>| {
        IpmSolver::<f32, N>::new(Settings::default())
            .solve(&pr, warm)
            .expect("solves")
            .iterations
    };
    let (warm, cold) = (iterations(Some(&braking_plan)), iterations(None));
    // 32 against 15 when measured; the test asks only for the order.
    assert!(
        warm > cold + cold / 2,
        "from the braking plan {warm}, cold {cold}"
    );
}

#[test]
fn after_a_solve_it_still_starts_warm() {
    // Only a warm start tries the active-set step: a second solve on a free road that it
    // answers shows that `false` leaves solves after solves warm.
    let mut pl = planner();
    pl.set_warm_from_fallback(false);
    let first = pl.step_gap(10.0, 100.0, 0.0, 15.0).expect("valid");
    assert!(matches!(first.status, StepStatus::Solved { .. }));
    let second = pl.step_gap(first.v, 99.9, 0.0, 15.0).expect("valid");
    assert!(
        matches!(
            second.status,
            StepStatus::Solved {
                method: Method::ActiveSet,
                ..
            }
        ),
        "{second:?}"
    );
}
