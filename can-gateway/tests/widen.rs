//! `Message::map`: every kind of message converted between `f32` and `f64` keeps its kind
//! and every field, its numbers converted by the caller's function (an MCU's codec works
//! in `f32`, a host that mirrors it in `f64`).

use can_gateway::wire::{Request, TrackWire};
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

fn every_kind() -> [Message<f32>; 9] {
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
}
