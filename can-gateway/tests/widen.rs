//! `Message::map`: every kind of message converted between `f32` and `f64` keeps its kind
//! and every field, its numbers converted by the caller's function (an MCU's codec works
//! in `f32`, a host that mirrors it in `f64`).

use can_gateway::wire::{Command, CommandStatus, Request, TrackWire};
use can_gateway::{Instant, Message};
use planner_core::VehicleState;

fn state(id: u16) -> VehicleState<f32> {
    VehicleState {
        id,
        x: 10.5,
        y: 3.5,
        theta: 0.25,
        v: 12.0,
        omega: 0.0,
        lane: 1,
        alpha: None,
        beta: Some(1),
        stamp: Instant::from_millis(1_000),
        cooperative: true,
        brake: None,
        length: None,
    }
}

fn every_kind() -> [Message<f32>; 11] {
    let at = Instant::from_millis(2_500);
    let request = Request {
        id: 4,
        inlet: TrackWire {
            heading: 1,
            lane: 0,
        },
        outlet: TrackWire {
            heading: 2,
            lane: 1,
        },
        arrival: at,
        s: 31.25,
        v: 8.5,
        brake: None,
        length: None,
    };
    [
        Message::State(state(3)),
        Message::Request(request),
        Message::Grant { id: 4, until: at },
        Message::Revoke { id: 4, at },
        Message::Exit { id: 4, at },
        Message::Located {
            segment: 6,
            state: state(5),
        },
        Message::JunctionRequest {
            junction: 2,
            request,
        },
        Message::JunctionExit {
            junction: 2,
            id: 4,
            at,
        },
        Message::Sync {
            period: 77,
            last: true,
        },
        Message::Ego {
            segment: 6,
            lanes: 3,
            state: state(5),
            v_ref: 13.5,
        },
        Message::Command(Command {
            period: 9,
            v: 7.25,
            omega: -0.125,
            status: CommandStatus::Yield,
            lane: 1,
            alpha: Some(0),
            beta: None,
        }),
    ]
}

#[test]
fn every_message_widens_and_narrows_back_unchanged() {
    for m in every_kind() {
        let wide = m.map(|x| f64::from(x) * 2.0);
        assert_eq!(wide.kind(), m.kind());
        assert_eq!(wide.map(|x| (x / 2.0) as f32), m, "{m:?}");
    }
    // The numbers went through the function.
    let Message::JunctionRequest { request, .. } = every_kind()[6].map(|x| f64::from(x) + 1.0)
    else {
        panic!("kind changed")
    };
    assert_eq!((request.s, request.v), (32.25, 9.5));
    let Message::Located { state, .. } = every_kind()[5].map(|x| f64::from(x) * 2.0) else {
        panic!("kind changed")
    };
    assert_eq!((state.x, state.y, state.v), (21.0, 7.0, 24.0));
    let Message::Ego { state, v_ref, .. } = every_kind()[9].map(|x| f64::from(x) * 2.0) else {
        panic!("kind changed")
    };
    assert_eq!((state.x, v_ref), (21.0, 27.0));
    let Message::Command(c) = every_kind()[10].map(|x| f64::from(x) + 1.0) else {
        panic!("kind changed")
    };
    assert_eq!((c.v, c.omega, c.period), (8.25, 0.875, 9));
}

/// A command's status is the planner's step status, one byte on the wire, and back.
#[test]
fn command_statuses_name_the_planners_steps_and_round_trip() {
    use planner_core::{FallbackReason as R, Method, SolveError, StepStatus as S};
    let cases: [(S<f32>, CommandStatus, bool); 7] = [
        (
            S::Solved {
                iterations: 3,
                method: Method::InteriorPoint,
            },
            CommandStatus::Solved,
            true,
        ),
        (
            S::Reused {
                age: 1,
                certified_gap: 0.0,
            },
            CommandStatus::Reused,
            true,
        ),
        (
            S::Fallback(R::InvariantViolated),
            CommandStatus::InvariantViolated,
            false,
        ),
        (S::Fallback(R::NoRoom), CommandStatus::NoRoom, false),
        (
            S::Fallback(R::Solver(SolveError::IterationLimit { iterations: 60 })),
            CommandStatus::Solver,
            false,
        ),
        (S::Fallback(R::Yield), CommandStatus::Yield, false),
        (S::Fallback(R::Lateral), CommandStatus::Lateral, false),
    ];
    for (step, status, planned) in cases {
        assert_eq!(CommandStatus::of(&step), status, "{step:?}");
        assert_eq!(status.planned(), planned, "{status:?}");
    }
    assert!(!CommandStatus::Rejected.planned() && !CommandStatus::Verification.planned());
    for code in 0..=255u8 {
        match CommandStatus::from_code(code) {
            Some(s) => assert_eq!(s as u8, code),
            None => assert!(code > 8, "{code}"),
        }
    }
}
