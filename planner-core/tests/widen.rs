//! Converting a status, a fallback reason, a violation and a state between `f32` and
//! `f64` (`map`): every field carried, numbers converted by the caller's function — what a
//! host mirroring an MCU's `f32` planner does with every step, now that the enums grow
//! (`#[non_exhaustive]`) and it can no longer match them all itself.

use planner_core::{
    BrakeLimit, ConstraintKind, FallbackReason, Instant, Method, SolveError, StepStatus,
    VehicleState, Violation,
};

fn statuses() -> [StepStatus<f32>; 8] {
    let violation = Violation {
        amount: 0.25f32,
        kind: ConstraintKind::Safety,
        step: 7,
    };
    [
        StepStatus::Solved {
            iterations: 9,
            method: Method::ActiveSet,
        },
        StepStatus::Reused {
            age: 3,
            certified_gap: 0.125,
        },
        StepStatus::Fallback(FallbackReason::InvariantViolated),
        StepStatus::Fallback(FallbackReason::NoRoom),
        StepStatus::Fallback(FallbackReason::Solver(SolveError::IterationLimit {
            iterations: 40,
        })),
        StepStatus::Fallback(FallbackReason::Verification(violation)),
        StepStatus::Fallback(FallbackReason::Yield),
        StepStatus::Fallback(FallbackReason::Lateral),
    ]
}

#[test]
fn statuses_widen_and_narrow_back_unchanged() {
    for s in statuses() {
        let wide = s.map(f64::from);
        assert_eq!(wide.map(|x| x as f32), s);
        // The numbers went through the function, not around it.
        assert_eq!(s.map(|x| f64::from(x) * 2.0).map(|x| (x / 2.0) as f32), s);
    }
    let doubled = statuses()[1].map(|x| f64::from(x) * 2.0);
    assert_eq!(
        doubled,
        StepStatus::Reused {
            age: 3,
            certified_gap: 0.25
        }
    );
    let v = statuses()[5].map(|x| f64::from(x) + 1.0);
    let StepStatus::Fallback(FallbackReason::Verification(v)) = v else {
        panic!("{v:?}")
    };
    assert_eq!(
        (v.amount, v.kind, v.step),
        (1.25, ConstraintKind::Safety, 7)
    );
}

#[test]
fn a_state_carries_every_field() {
    let s = VehicleState {
        id: 7,
        x: 1.5f32,
        y: -2.0,
        theta: 0.25,
        v: 13.5,
        omega: -0.125,
        lane: 2,
        alpha: Some(3),
        beta: Some(1),
        stamp: Instant::from_micros(5_000_000),
        cooperative: false,
        brake: BrakeLimit::from_mps2(4.5f32),
        length: None,
    };
    let wide = s.map(|x| f64::from(x) * 2.0);
    assert_eq!(
        (wide.x, wide.y, wide.theta, wide.v, wide.omega),
        (3.0, -4.0, 0.5, 27.0, -0.25)
    );
    assert_eq!(wide.map(|x| (x / 2.0) as f32), s);
}
