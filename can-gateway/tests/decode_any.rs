//! The decoder on arbitrary input: every frame gives a message, `None` or a typed error,
//! never a panic; a rejected frame leaves the reassembler as it was; and every message
//! survives encode → frames → decode with its fields within one resolution step.

use can_gateway::wire::{
    MessageKind, Request, TrackWire, HEADING_RES, POS_RES, SPEED_RES, YAW_RATE_RES,
};
use can_gateway::{encode, Frames, Instant, Message, Reassembler};
use embedded_can::{ExtendedId, Frame, Id, StandardId};
use planner_core::{BodyLength, BrakeLimit, VehicleState};
use proptest::prelude::*;

use can_gateway::PlainFrame as F8;

fn any_frame() -> impl Strategy<Value = F8> {
    (
        any::<bool>(),
        any::<u32>(),
        prop::collection::vec(any::<u8>(), 0..=8),
        any::<bool>(),
        // Bias toward this protocol's identifiers so decoding goes deep.
        prop::sample::select(vec![1u8, 2, 3, 4, 5, 7, 15]),
        0u8..4,
        any::<u8>(),
    )
        .prop_map(|(ours, raw, data, remote, kind, idx, sa)| {
            let id = if ours {
                Id::Extended(
                    ExtendedId::new(
                        6 << 26
                            | 0xFF << 16
                            | u32::from(kind) << 12
                            | u32::from(idx) << 8
                            | u32::from(sa),
                    )
                    .expect("29 bits"),
                )
            } else if raw & 1 == 0 {
                Id::Standard(StandardId::new((raw >> 1 & 0x7FF) as u16).expect("11 bits"))
            } else {
                Id::Extended(ExtendedId::new(raw & 0x1FFF_FFFF).expect("29 bits"))
            };
            if remote && !ours {
                F8::new_remote(id, data.len()).expect("dlc ≤ 8")
            } else {
                F8::new(id, &data).expect("≤ 8 bytes")
            }
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(20_000))]

    #[test]
    fn any_frames_never_panic_and_errors_change_nothing(frames in prop::collection::vec(any_frame(), 1..40), now_ms in any::<u64>()) {
        let mut r = Reassembler::<8>::new();
        for f in &frames {
            let before = format!("{r:?}");
            match r.push::<f64, _>(f, Instant::from_millis(now_ms)) {
                Err(_) => prop_assert_eq!(before, format!("{r:?}")),
                Ok(Some(Message::State(s))) => {
                    prop_assert!(s.x.is_finite() && s.v >= 0.0 && s.v <= 100.0);
                }
                Ok(_) => {}
            }
        }
    }

    #[test]
    fn state_round_trip(
        id in any::<u16>(),
        x in -2.0e7f64..2.0e7,
        y in -300.0f64..300.0,
        theta in -3.1f64..3.1,
        v in 0.0f64..100.0,
        omega in -5.0f64..5.0,
        lane in 0u8..15,
        alpha in prop::option::of(0u8..15),
        beta in prop::option::of(0u8..15),
        stamp_ms in 0u64..u64::MAX / 1_000,
        skew_ms in -86_400_000i64..86_400_000,
        counter in 0u8..16,
        cooperative in any::<bool>(),
        (brake, length) in (any::<u8>(), any::<u8>()),
    ) {
        // Any uptime; the receiver's clock within a day of the stamp either way.
        let stamp = Instant::from_millis(stamp_ms);
        let now = Instant::from_millis(stamp_ms.saturating_add_signed(skew_ms));
        let s = VehicleState { id, x, y, theta, v, omega, lane, alpha, beta, stamp, cooperative,
            brake: BrakeLimit::from_tenths(brake), length: BodyLength::from_tenths(length) };
        let frames: Frames<F8> = encode(&Message::State(s), (id & 0xFF) as u8, counter).expect("in range");
        prop_assert_eq!(frames.len(), MessageKind::State.frames());
        let mut r = Reassembler::<2>::new();
        let mut got = None;
        for f in &frames {
            got = r.push::<f64, _>(f, now).expect("valid frames");
        }
        let Some(Message::State(d)) = got else { panic!("a state") };
        prop_assert_eq!((d.id, d.lane, d.alpha, d.beta, d.cooperative), (id, lane, alpha, beta, cooperative));
        // The declared limit and length arrive exactly; 0 is "not declared" both ways.
        prop_assert_eq!((d.brake, d.length), (s.brake, s.length));
        prop_assert!((d.x - x).abs() <= POS_RES / 2.0 + 1e-9);
        prop_assert!((d.y - y).abs() <= POS_RES / 2.0 + 1e-9);
        prop_assert!((d.theta - theta).abs() <= HEADING_RES / 2.0 + 1e-9);
        prop_assert!((d.v - v).abs() <= SPEED_RES / 2.0 + 1e-9);
        prop_assert!((d.omega - omega).abs() <= YAW_RATE_RES / 2.0 + 1e-9);
        prop_assert_eq!(d.stamp, stamp);
    }

    #[test]
    fn request_round_trip(id in any::<u16>(), h in 0u8..4, l in 0u8..2, s in 0.0f64..1.0e5, v in 0.0f64..50.0, at_ms in 0u64..1u64 << 40, (brake, length) in (any::<u8>(), any::<u8>()), junction in proptest::option::of(any::<u8>())) {
        let at = Instant::from_millis(at_ms);
        let req = Request { id, inlet: TrackWire { heading: h, lane: l }, outlet: TrackWire { heading: (h + 1) % 4, lane: l }, arrival: at, s, v,
            brake: BrakeLimit::from_tenths(brake), length: BodyLength::from_tenths(length) };
        let msg = match junction {
            Some(junction) => Message::JunctionRequest { junction, request: req },
            None => Message::Request(req),
        };
        let frames: Frames<F8> = encode(&msg, (id & 0xFF) as u8, 0).expect("in range");
        let mut r = Reassembler::<2>::new();
        let mut got = None;
        for f in &frames {
            got = r.push::<f64, _>(f, at).expect("valid");
        }
        let (d, declared) = match got {
            Some(Message::Request(d)) => (d, (None, None)),
            Some(Message::JunctionRequest { junction: j, request: d }) => {
                prop_assert_eq!(Some(j), junction);
                // A junction request's body arrives exactly; 0 is "not declared" both ways.
                (d, (req.brake, req.length))
            }
            _ => panic!("a request"),
        };
        prop_assert_eq!((d.id, d.inlet, d.outlet), (id, req.inlet, req.outlet));
        prop_assert!((d.s - s).abs() <= POS_RES / 2.0 + 1e-9 && (d.v - v).abs() <= SPEED_RES / 2.0 + 1e-9);
        prop_assert_eq!(d.arrival, at);
        // The plain request has no room for a body: it declares none.
        prop_assert_eq!((d.brake, d.length), declared);
    }
}
