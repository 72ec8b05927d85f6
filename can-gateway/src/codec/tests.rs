//! Unit tests of the codec.

use super::quantize::{libm_floor, speed, StateWire};
use super::*;
use crate::secoc::TRAILER_LEN;
use crate::wire::{
    fd_len, frame_id, Message, Request, TrackWire, CLOCK_ADDRESS, FD_INDEX, FD_SECURED_INDEX,
    HEADING_RES, MANAGER_ADDRESS, NO_LANE, SPEED_LIMIT, SPEED_RES, YAW_RATE_RES,
};
use embedded_can::{ExtendedId, Frame, Id};
use planner_core::{Instant, VehicleState};

use crate::frame::PlainFrame as TestFrame;

/// The receiver's clock in these tests (every stamp is within 24.8 days of it).
const NOW: Instant = Instant::from_secs(20);

/// `s` seconds after the epoch, to the millisecond.
fn secs(s: f64) -> Instant {
    Instant::from_millis((s * 1e3).round() as u64)
}

fn state() -> VehicleState<f64> {
    VehicleState {
        id: 0x0107,
        x: 1234.56,
        y: 5.4,
        theta: -0.1234,
        v: 15.02,
        omega: 0.25,
        lane: 2,
        alpha: Some(1),
        beta: None,
        stamp: secs(12.34),
        cooperative: true,
        brake: None,
        length: None,
    }
}

/// States every 10 ms, received 3 ms later, by a receiver whose clock reads 0, 60
/// days, just before the wire's 32-bit milliseconds wrap (49.7 days), or a century:
/// every one is accepted (none stale across the wrap) with its stamp restored exactly,
/// and encoding never runs out of range.
#[test]
fn every_fresh_state_is_taken_whatever_the_uptime_and_across_the_wrap() {
    let day = 86_400_000u64;
    for base_ms in [0, 60 * day, (1 << 32) - 500, 36_525 * day] {
        let mut r = Reassembler::<4>::new();
        for k in 0..100u64 {
            let stamp = Instant::from_millis(base_ms + 10 * k);
            let st = VehicleState { stamp, ..state() };
            let frames: Frames<TestFrame> =
                encode(&Message::State(st), 0x07, k as u8).expect("any uptime encodes");
            let now = stamp.saturating_add(planner_core::Duration::from_millis(3));
            let mut got = None;
            for f in &frames {
                got = r.push::<f32, _>(f, now).expect("fresh");
            }
            let Some(Message::State(s)) = got else {
                panic!("a state at {base_ms} + {k}");
            };
            assert_eq!(s.stamp, stamp);
        }
    }
}

#[test]
fn restored_times_are_the_nearest_to_the_receivers_clock() {
    let wrap = 1u64 << 32;
    let at = |ms| Instant::from_millis(ms);
    // Just after the wrap, a stamp sent just before it.
    assert_eq!(
        restore_millis((wrap - 5) as u32, at(wrap + 3)),
        at(wrap - 5)
    );
    // Just before it, a stamp from a sender whose clock is a little ahead.
    assert_eq!(restore_millis(2, at(wrap - 1)), at(wrap + 2));
    // Near the epoch, nothing before it.
    assert_eq!(restore_millis(u32::MAX, at(1)), at(u64::from(u32::MAX)));
    assert_eq!(restore_millis(7, at(0)), at(7));
    // 24 days either way is exact.
    let now = 3 * wrap + 12_345;
    for d in [0, 1, 24 * 86_400_000] {
        assert_eq!(restore_millis((now + d) as u32, at(now)), at(now + d));
        assert_eq!(restore_millis((now - d) as u32, at(now)), at(now - d));
    }
}

#[test]
fn round_trip_and_e2e_checks() {
    let m = Message::State(state());
    let frames: Frames<TestFrame> = encode(&m, 0x07, 3).unwrap();
    assert_eq!(frames.len(), 4);
    let mut r = Reassembler::<4>::new();
    for f in &frames[..3] {
        assert_eq!(r.push::<f64, _>(f, NOW), Ok(None));
    }
    let Ok(Some(Message::State(s))) = r.push::<f64, _>(&frames[3], NOW) else {
        panic!("a state");
    };
    let e = state();
    assert_eq!(
        (s.id, s.lane, s.alpha, s.beta),
        (e.id, e.lane, e.alpha, e.beta)
    );
    assert!((s.x - e.x).abs() <= 0.005 && (s.y - e.y).abs() <= 0.005);
    assert!((s.v - e.v).abs() <= 0.01 && s.stamp == e.stamp);
    assert!((s.theta - e.theta).abs() <= HEADING_RES && (s.omega - e.omega).abs() <= YAW_RATE_RES);
    // The same message again: duplicate (same counter), reassembler unchanged.
    let before = r.clone().slots;
    for f in &frames[..3] {
        assert_eq!(r.push::<f64, _>(f, NOW), Ok(None));
    }
    assert_eq!(
        r.push::<f64, _>(&frames[3], NOW),
        Err(DecodeError::Duplicate)
    );
    // A newer counter but an older stamp: stale.
    let mut old = state();
    old.stamp = secs(1.0);
    let frames: Frames<TestFrame> = encode(&Message::State(old), 0x07, 4).unwrap();
    for f in &frames[..3] {
        let _ = r.push::<f64, _>(f, NOW);
    }
    assert_eq!(r.push::<f64, _>(&frames[3], NOW), Err(DecodeError::Stale));
    assert_eq!(r.slots[0].last_counter, before[0].last_counter);
    // A flipped bit: CRC.
    let mut newer = state();
    newer.stamp = secs(20.0);
    let mut frames: Frames<TestFrame> = encode(&Message::State(newer), 0x07, 5).unwrap();
    let mut d = [0u8; 8];
    d.copy_from_slice(frames[1].data());
    d[3] ^= 0x10;
    frames[1] = TestFrame::new(frames[1].id(), &d).unwrap();
    for f in &frames[..3] {
        let _ = r.push::<f64, _>(f, NOW);
    }
    assert_eq!(r.push::<f64, _>(&frames[3], NOW), Err(DecodeError::Crc));
    // A continuation without its first frame.
    let mut r2 = Reassembler::<4>::new();
    assert_eq!(
        r2.push::<f64, _>(&frames[2], NOW),
        Err(DecodeError::OutOfSequence)
    );
    // Sender address and id disagree.
    let frames: Frames<TestFrame> = encode(&Message::State(state()), 0x08, 1).unwrap();
    for f in &frames[..3] {
        let _ = r2.push::<f64, _>(f, NOW);
    }
    assert_eq!(
        r2.push::<f64, _>(&frames[3], NOW),
        Err(DecodeError::SenderMismatch)
    );
}

#[test]
fn intersection_messages_round_trip() {
    let req = Request {
        id: 9,
        inlet: TrackWire {
            heading: 2,
            lane: 1,
        },
        outlet: TrackWire {
            heading: 3,
            lane: 1,
        },
        arrival: secs(3.5),
        s: 97.25,
        v: 13.9,
        brake: None,
        length: None,
    };
    let mut r = Reassembler::<8>::new();
    for (m, sa) in [
        (Message::Request(req), 9u8),
        (
            Message::Grant {
                id: 9,
                until: secs(4.0),
            },
            MANAGER_ADDRESS,
        ),
        (
            Message::Revoke {
                id: 9,
                at: secs(4.5),
            },
            MANAGER_ADDRESS,
        ),
        (
            Message::Exit {
                id: 9,
                at: secs(9.0),
            },
            9,
        ),
    ] {
        let frames: Frames<TestFrame> = encode(&m, sa, 0).unwrap();
        let mut got = None;
        for f in &frames {
            got = r.push::<f64, _>(f, NOW).unwrap();
        }
        match (got.unwrap(), m) {
            (Message::Request(a), Message::Request(b)) => {
                assert_eq!((a.id, a.inlet, a.outlet), (b.id, b.inlet, b.outlet));
                assert!((a.s - b.s).abs() < 0.006 && a.arrival == b.arrival);
            }
            (a, b) => assert_eq!(a, b),
        }
    }
    // A grant or revoke from anyone but the manager is refused (a vehicle granting
    // itself entry), and leaves the reassembler as it was.
    for m in [
        Message::<f64>::Grant {
            id: 9,
            until: secs(5.0),
        },
        Message::Revoke {
            id: 9,
            at: secs(5.0),
        },
    ] {
        for sa in [9u8, 0, CLOCK_ADDRESS] {
            let frames: Frames<TestFrame> = encode(&m, sa, 3).unwrap();
            let before = r.slots.clone();
            assert_eq!(
                r.push::<f64, _>(&frames[0], NOW),
                Err(DecodeError::SenderMismatch)
            );
            assert_eq!(r.slots, before);
        }
    }
    // Encoding refuses what a field cannot carry.
    let mut s = state();
    s.v = f64::NAN;
    assert_eq!(
        encode::<f64, TestFrame>(&Message::State(s), 7, 0).unwrap_err(),
        EncodeError::OutOfRange(Field::Speed)
    );
    s = state();
    s.lane = 15;
    assert_eq!(
        encode::<f64, TestFrame>(&Message::State(s), 7, 0).unwrap_err(),
        EncodeError::OutOfRange(Field::Lane)
    );
}

fn request(id: u16) -> Request<f64> {
    Request {
        id,
        inlet: TrackWire {
            heading: 2,
            lane: 1,
        },
        outlet: TrackWire {
            heading: 3,
            lane: 1,
        },
        arrival: secs(3.5),
        s: 97.25,
        v: 13.9,
        brake: None,
        length: None,
    }
}

/// Every message that names its sender, each with the vehicle it names (id 9).
fn naming_vehicle_9() -> [Message<f64>; 6] {
    let mut st = state();
    st.id = 9;
    [
        Message::Exit {
            id: 9,
            at: secs(9.0),
        },
        Message::JunctionExit {
            junction: 2,
            id: 9,
            at: secs(9.0),
        },
        Message::Request(request(9)),
        Message::JunctionRequest {
            junction: 2,
            request: request(9),
        },
        Message::State(st),
        Message::Located {
            segment: 4,
            state: st,
        },
    ]
}

/// Pushes every frame of `m` from `sa`; the last push's result.
fn push_all(
    r: &mut Reassembler<8>,
    m: &Message<f64>,
    sa: u8,
    counter: u8,
) -> Result<Option<Message<f64>>, DecodeError> {
    let frames: Frames<TestFrame> = encode(m, sa, counter).unwrap();
    let mut last = Ok(None);
    for f in &frames {
        last = r.push::<f64, _>(f, NOW);
    }
    last
}

mod secured {
    use super::*;
    use crate::secoc::{derive_key, FreshnessRx, Key, KeyStore};

    pub(super) const MASTER: Key = Key([7; 16]);

    pub(super) fn keys() -> KeyStore<8> {
        let mut k = KeyStore::new();
        for sa in [9u8, 8, MANAGER_ADDRESS, CLOCK_ADDRESS] {
            k.insert(sa, derive_key(&MASTER, sa)).unwrap();
        }
        k
    }

    /// Every kind, each from a sender allowed to send it.
    pub(super) fn every_kind() -> [(Message<f64>, u8); 11] {
        let [e, je, rq, jrq, st, loc] = naming_vehicle_9();
        let Message::Located { state: own, .. } = loc else {
            unreachable!("naming_vehicle_9 ends with a located state")
        };
        [
            (
                Message::Ego {
                    segment: 3,
                    lanes: 3,
                    state: own,
                    v_ref: 13.9,
                },
                CLOCK_ADDRESS,
            ),
            (
                Message::Command(crate::wire::Command {
                    period: 513,
                    v: f64::from(13.871_234_f32),
                    omega: f64::from(-0.012_345_678_f32),
                    status: crate::wire::CommandStatus::Yield,
                    lane: 1,
                    alpha: Some(0),
                    beta: Some(0),
                }),
                9,
            ),
            (e, 9),
            (je, 9),
            (rq, 9),
            (jrq, 9),
            (st, 9),
            (loc, 9),
            (
                Message::Grant {
                    id: 9,
                    until: secs(4.0),
                },
                MANAGER_ADDRESS,
            ),
            (
                Message::Revoke {
                    id: 9,
                    at: secs(4.0),
                },
                MANAGER_ADDRESS,
            ),
            (
                Message::Sync {
                    period: 4,
                    last: false,
                },
                CLOCK_ADDRESS,
            ),
        ]
    }

    pub(super) struct Rx {
        pub(super) r: Reassembler<8>,
        keys: KeyStore<8>,
        fresh: FreshnessRx<16>,
    }

    impl Rx {
        pub(super) fn new() -> Self {
            Self {
                r: Reassembler::new(),
                keys: keys(),
                fresh: FreshnessRx::default(),
            }
        }
        pub(super) fn push<Fr: Frame>(
            &mut self,
            f: &Fr,
            now_ms: u64,
        ) -> Result<Option<Message<f64>>, DecodeError> {
            let v = Verifier {
                keys: &self.keys,
                freshness: &mut self.fresh,
            };
            self.r
                .push_secured::<f64, _, 8, 16>(f, Instant::from_millis(now_ms), v)
        }
        fn push_all(
            &mut self,
            frames: &[TestFrame],
            now_ms: u64,
        ) -> Vec<Result<Option<Message<f64>>, DecodeError>, 8> {
            frames.iter().map(|f| self.push(f, now_ms)).collect()
        }
    }

    fn sign(
        m: &Message<f64>,
        sa: u8,
        counter: u8,
        key_of: u8,
        fv: u64,
    ) -> SecuredFrames<TestFrame> {
        encode_secured(m, sa, counter, &derive_key(&MASTER, key_of), fv).unwrap()
    }

    #[test]
    fn every_kind_round_trips_with_its_authenticator_and_not_before() {
        for (m, sa) in every_kind() {
            let mut rx = Rx::new();
            let frames = sign(&m, sa, 3, sa, 1_000);
            assert_eq!(frames.len(), m.kind().frames() + 1);
            let out = rx.push_all(&frames, 1_000);
            let (last, rest) = out.split_last().unwrap();
            assert!(
                rest.iter().all(|r| *r == Ok(None)),
                "{m:?}: accepted before its MAC"
            );
            let got = (*last).unwrap().unwrap();
            assert_eq!(
                encode::<f64, TestFrame>(&got, sa, 3).unwrap(),
                encode(&m, sa, 3).unwrap()
            );
            // The same frames again: the E2E counter already refuses them.
            let again = rx.push_all(&frames, 1_010);
            assert_eq!(*again.last().unwrap(), Err(DecodeError::Duplicate), "{m:?}");
            // After a newer message, the old one replayed: its freshness is taken (states
            // and ticks are refused by their stamps first).
            let later = match m {
                Message::State(mut st) => {
                    st.stamp = st
                        .stamp
                        .saturating_add(planner_core::Duration::from_millis(100));
                    Message::State(st)
                }
                Message::Located { segment, mut state } => {
                    state.stamp = state
                        .stamp
                        .saturating_add(planner_core::Duration::from_millis(100));
                    Message::Located { segment, state }
                }
                Message::Ego {
                    segment,
                    lanes,
                    mut state,
                    v_ref,
                } => {
                    state.stamp = state
                        .stamp
                        .saturating_add(planner_core::Duration::from_millis(100));
                    Message::Ego {
                        segment,
                        lanes,
                        state,
                        v_ref,
                    }
                }
                Message::Sync { period, last } => Message::Sync {
                    period: period + 1,
                    last,
                },
                other => other,
            };
            let newer = sign(&later, sa, 4, sa, 1_005);
            assert!(matches!(
                rx.push_all(&newer, 1_005).last(),
                Some(Ok(Some(_)))
            ));
            let replay = rx.push_all(&frames, 1_010);
            let expect = match m.kind() {
                MessageKind::State
                | MessageKind::Located
                | MessageKind::Ego
                | MessageKind::Sync => DecodeError::Stale,
                _ => DecodeError::Auth(AuthError::Replayed),
            };
            assert_eq!(*replay.last().unwrap(), Err(expect), "{m:?}");
            // A plain receiver refuses the authenticator frame's index.
            let mut plain = Reassembler::<8>::new();
            let mut res = Ok(None);
            for f in &frames {
                res = plain.push::<f64, _>(f, NOW);
            }
            assert_eq!(res, Err(DecodeError::BadFrameIndex));
        }
    }

    #[test]
    fn a_forged_grant_is_refused_and_changes_nothing() {
        // A vehicle writes the manager's address: the CRC and the sender rule pass, the
        // MAC (under the vehicle's own key, or any but the manager's) does not.
        let grant = Message::<f64>::Grant {
            id: 8,
            until: secs(9.0),
        };
        let mut rx = Rx::new();
        let forged = sign(&grant, MANAGER_ADDRESS, 1, 8, 2_000);
        let before = rx.r.slots.clone();
        let out = rx.push_all(&forged, 2_000);
        assert_eq!(
            *out.last().unwrap(),
            Err(DecodeError::Auth(AuthError::BadMac))
        );
        assert_eq!(
            rx.r.slots.len(),
            before.len() + 1,
            "only the partial frame is held"
        );
        assert!(rx.r.slots.iter().all(|s| s.last_counter.is_none()));
        // The real grant with the same counter is still accepted afterwards.
        let real = sign(&grant, MANAGER_ADDRESS, 1, MANAGER_ADDRESS, 2_000);
        assert!(matches!(
            rx.push_all(&real, 2_000).last(),
            Some(Ok(Some(_)))
        ));
        // An unknown sender has no key.
        let mut st = state();
        st.id = 0x33;
        let unknown = sign(&Message::State(st), 0x33, 0, 0x33, 2_000);
        assert_eq!(
            *rx.push_all(&unknown, 2_000).last().unwrap(),
            Err(DecodeError::Auth(AuthError::UnknownKey))
        );
    }

    #[test]
    fn stale_spliced_and_padded_authenticators_are_refused() {
        let m = Message::Exit {
            id: 9,
            at: secs(1.0),
        };
        let mut rx = Rx::new();
        // Recorded a second ago: outside the 500 ms window.
        let old = sign(&m, 9, 2, 9, 10_000);
        assert_eq!(
            *rx.push_all(&old, 11_000).last().unwrap(),
            Err(DecodeError::Auth(AuthError::Stale))
        );
        // The authenticator of another message (another time) spliced onto this one.
        let a = sign(&m, 9, 2, 9, 20_000);
        let b = sign(
            &Message::Exit {
                id: 9,
                at: secs(2.0),
            },
            9,
            2,
            9,
            20_001,
        );
        let spliced = [a[0], b[1]];
        assert_eq!(
            *rx.push_all(&spliced, 20_001).last().unwrap(),
            Err(DecodeError::Auth(AuthError::BadMac))
        );
        // Non-zero padding after the trailer.
        let mut data = [0u8; 8];
        data.copy_from_slice(a[1].data());
        data[7] = 1;
        let padded = TestFrame::new(a[1].id(), &data).unwrap();
        rx.push(&a[0], 20_000).unwrap();
        assert_eq!(rx.push(&padded, 20_000), Err(DecodeError::BadLength));
        // The genuine one still goes through after all that.
        assert!(matches!(rx.push_all(&a, 20_000).last(), Some(Ok(Some(_)))));
    }
}

mod fd {
    use super::secured::{every_kind, Rx, MASTER};
    use super::*;
    use crate::frame::FdFrame;
    use crate::secoc::derive_key;

    fn fd(m: &Message<f64>, sa: u8, counter: u8) -> FdFrame {
        encode_fd(m, sa, counter).unwrap()
    }

    fn with_data(f: &FdFrame, data: &[u8]) -> FdFrame {
        FdFrame::new_fd(f.id(), data).unwrap()
    }

    #[test]
    fn every_kind_fits_one_frame_that_carries_its_classic_chunks() {
        for (m, sa) in every_kind() {
            let n = m.kind().frames();
            let f = fd(&m, sa, 5);
            let used = 1 + n * CHUNK;
            assert_eq!(f.data().len(), fd_len(used).unwrap(), "{m:?}");
            assert_eq!(f.is_fd(), used > 8);
            assert_eq!(f.data()[0], FD_INDEX << 4 | 5);
            let Id::Extended(id) = f.id() else {
                panic!("extended")
            };
            assert_eq!(id.as_raw(), frame_id(m.kind(), FD_INDEX, sa));
            let classic: Frames<TestFrame> = encode(&m, sa, 5).unwrap();
            for (i, c) in classic.iter().enumerate() {
                assert_eq!(
                    &f.data()[1 + i * CHUNK..1 + (i + 1) * CHUNK],
                    &c.data()[1..]
                );
            }
            assert!(f.data()[used..].iter().all(|b| *b == 0));
            let mut r = Reassembler::<8>::new();
            let got = r.push::<f64, _>(&f, NOW).unwrap().unwrap();
            assert_eq!(encode::<f64, TestFrame>(&got, sa, 5).unwrap(), classic);
            let before = r.slots.clone();
            assert_eq!(r.push::<f64, _>(&f, NOW), Err(DecodeError::Duplicate));
            assert_eq!(r.slots, before);
        }
        // A classic frame type cannot carry a message beyond 8 bytes.
        let st = Message::State(state());
        assert_eq!(
            encode_fd::<f64, TestFrame>(&st, 7, 0),
            Err(EncodeError::Frame)
        );
    }

    #[test]
    fn malformed_frames_are_refused_and_change_nothing() {
        let st = Message::State(state());
        let f = fd(&st, 0x07, 2);
        let d = f.data();
        assert_eq!(d.len(), 32);
        let mut r = Reassembler::<8>::new();
        // A classic first frame of another message is pending.
        let classic: Frames<TestFrame> = encode(&st, 0x07, 9).unwrap();
        assert_eq!(r.push::<f64, _>(&classic[0], NOW), Ok(None));
        let before = r.slots.clone();
        let mut longer = [0u8; 48];
        longer[..32].copy_from_slice(d);
        let mut padded = [0u8; 32];
        padded.copy_from_slice(d);
        padded[31] = 1;
        let mut header = [0u8; 32];
        header.copy_from_slice(d);
        header[0] = 2;
        let mut flipped = [0u8; 32];
        flipped.copy_from_slice(d);
        flipped[5] ^= 0x10;
        let mut other = state();
        other.id = 0x0108;
        let cases = [
            (with_data(&f, &d[..24]), DecodeError::BadLength),
            (with_data(&f, &longer), DecodeError::BadLength),
            (with_data(&f, &padded), DecodeError::BadLength),
            (with_data(&f, &header), DecodeError::HeaderMismatch),
            (with_data(&f, &flipped), DecodeError::Crc),
            // Sent by 0x07, naming vehicle 0x0108.
            (
                fd(&Message::State(other), 0x07, 2),
                DecodeError::SenderMismatch,
            ),
        ];
        for (bad, why) in cases {
            assert_eq!(r.push::<f64, _>(&bad, NOW), Err(why));
            assert_eq!(r.slots, before, "{why:?} changed the reassembler");
        }
        // The genuine frame supersedes the pending classic reassembly.
        assert!(matches!(
            r.push::<f64, _>(&f, NOW),
            Ok(Some(Message::State(_)))
        ));
        assert_eq!(
            r.push::<f64, _>(&classic[1], NOW),
            Err(DecodeError::OutOfSequence)
        );
    }

    #[test]
    fn a_secured_frame_carries_the_classic_authenticator_and_a_plain_one_is_refused() {
        for (m, sa) in every_kind() {
            let n = m.kind().frames();
            let key = derive_key(&MASTER, sa);
            let f: FdFrame = encode_fd_secured(&m, sa, 3, &key, 1_000).unwrap();
            let used = 1 + n * CHUNK + TRAILER_LEN;
            assert_eq!(f.data().len(), fd_len(used).unwrap(), "{m:?}");
            assert_eq!(f.data()[0] >> 4, FD_SECURED_INDEX);
            // The same MAC and freshness as the classic authenticator frame.
            let classic: SecuredFrames<TestFrame> = encode_secured(&m, sa, 3, &key, 1_000).unwrap();
            assert_eq!(
                &f.data()[1 + n * CHUNK..used],
                &classic[n].data()[1..1 + TRAILER_LEN]
            );
            let mut rx = Rx::new();
            let got = rx.push(&f, 1_000).unwrap().unwrap();
            assert_eq!(
                encode::<f64, TestFrame>(&got, sa, 3).unwrap(),
                encode(&m, sa, 3).unwrap()
            );
            // A plain receiver reads the message (it verifies nothing).
            assert!(Reassembler::<8>::new()
                .push::<f64, _>(&f, NOW)
                .unwrap()
                .is_some());
            // A secured receiver never takes a frame without an authenticator.
            let mut rx = Rx::new();
            assert_eq!(
                rx.push(&fd(&m, sa, 3), 1_000),
                Err(DecodeError::BadFrameIndex)
            );
            assert!(rx.r.slots.is_empty());
        }
        // A vehicle forging the manager's grant: refused, nothing recorded.
        let grant = Message::<f64>::Grant {
            id: 8,
            until: secs(9.0),
        };
        let forged: FdFrame =
            encode_fd_secured(&grant, MANAGER_ADDRESS, 1, &derive_key(&MASTER, 8), 2_000).unwrap();
        let mut rx = Rx::new();
        assert_eq!(
            rx.push(&forged, 2_000),
            Err(DecodeError::Auth(AuthError::BadMac))
        );
        assert!(rx.r.slots.is_empty());
    }
}

#[test]
fn exits_requests_and_states_come_only_from_the_vehicle_they_name() {
    // On an Exit the manager forgets the vehicle: one forged by another node would let
    // a conflicting route be granted while the vehicle is still inside A_S.
    for m in naming_vehicle_9() {
        let mut r = Reassembler::<8>::new();
        for sa in [8u8, 10, 0x19, MANAGER_ADDRESS, CLOCK_ADDRESS] {
            let before = r.slots.clone();
            assert_eq!(
                push_all(&mut r, &m, sa, 1).map(|_| ()),
                Err(DecodeError::SenderMismatch),
                "{m:?} from {sa:#x}"
            );
            // Only the partial frames of that sender are kept: nothing accepted.
            assert!(
                r.slots.iter().all(|s| s.last_counter.is_none()),
                "{m:?} from {sa:#x}: {before:?}"
            );
        }
        assert!(
            matches!(push_all(&mut r, &m, 9, 1), Ok(Some(_))),
            "{m:?} from its own vehicle is accepted"
        );
    }
}

#[test]
fn continuation_frames_of_another_message_are_not_spliced_in() {
    // Two states of one sender: frames of the second must not complete the first,
    // whatever their CRC (which alone lets 1 in 256 splices through).
    let (mut a, mut b) = (state(), state());
    a.stamp = secs(20.0);
    b.stamp = secs(21.0);
    b.x = -50.0;
    let fa: Frames<TestFrame> = encode(&Message::State(a), 0x07, 3).unwrap();
    let fb: Frames<TestFrame> = encode(&Message::State(b), 0x07, 4).unwrap();
    let mut r = Reassembler::<4>::new();
    assert_eq!(r.push::<f64, _>(&fa[0], NOW), Ok(None));
    let kept = r.slots.clone();
    // b's second frame after a's first: another counter.
    assert_eq!(
        r.push::<f64, _>(&fb[1], NOW),
        Err(DecodeError::OutOfSequence)
    );
    assert_eq!(r.slots, kept, "a refused frame changes nothing");
    // a's last frame before its second: out of order.
    assert_eq!(
        r.push::<f64, _>(&fa[2], NOW),
        Err(DecodeError::OutOfSequence)
    );
    assert_eq!(r.slots, kept);
    // a itself still completes.
    assert_eq!(r.push::<f64, _>(&fa[1], NOW), Ok(None));
    assert_eq!(r.push::<f64, _>(&fa[2], NOW), Ok(None));
    let Ok(Some(Message::State(got))) = r.push::<f64, _>(&fa[3], NOW) else {
        panic!("a completes");
    };
    assert!((got.x - a.x).abs() < 0.01);
    // b's first frame, then a's (old) frames: a's counter is not b's.
    assert_eq!(r.push::<f64, _>(&fb[0], NOW), Ok(None));
    assert_eq!(
        r.push::<f64, _>(&fa[1], NOW),
        Err(DecodeError::OutOfSequence)
    );
    // A splice whose CRC happens to match is still refused: build b's second frame
    // with a's counter in its header and check that the counter alone refuses it.
    let mut d = [0u8; 8];
    d.copy_from_slice(fb[1].data());
    d[0] = (d[0] & 0xF0) | 0x03;
    let forged = TestFrame::new(fb[1].id(), &d).unwrap();
    assert_eq!(
        r.push::<f64, _>(&forged, NOW),
        Err(DecodeError::OutOfSequence)
    );
}

#[test]
fn sync_ticks_come_from_the_clock_in_order() {
    let mut r = Reassembler::<4>::new();
    let tick = |period, last, sa, counter| -> Frames<TestFrame> {
        encode::<f64, _>(&Message::Sync { period, last }, sa, counter).unwrap()
    };
    let f = tick(7, false, CLOCK_ADDRESS, 1);
    assert_eq!(f.len(), 1);
    assert_eq!(
        r.push::<f64, _>(&f[0], NOW),
        Ok(Some(Message::Sync {
            period: 7,
            last: false
        }))
    );
    // A tick not newer than the last, or from another node, is refused.
    assert_eq!(
        r.push::<f64, _>(&tick(7, false, CLOCK_ADDRESS, 2)[0], NOW),
        Err(DecodeError::Stale)
    );
    assert_eq!(
        r.push::<f64, _>(&tick(8, false, 0x12, 2)[0], NOW),
        Err(DecodeError::SenderMismatch)
    );
    assert_eq!(
        r.push::<f64, _>(&tick(8, true, CLOCK_ADDRESS, 2)[0], NOW),
        Ok(Some(Message::Sync {
            period: 8,
            last: true
        }))
    );
}

#[test]
fn foreign_frames_are_refused() {
    let mut r = Reassembler::<2>::new();
    let std_id = embedded_can::StandardId::new(0x123).unwrap();
    let f = TestFrame::new(std_id, &[0; 8]).unwrap();
    assert_eq!(r.push::<f64, _>(&f, NOW), Err(DecodeError::NotOurs));
    let f = TestFrame::new(ExtendedId::new(0x18FEF100).unwrap(), &[0; 8]).unwrap();
    assert_eq!(r.push::<f64, _>(&f, NOW), Err(DecodeError::ForeignId));
    let f = TestFrame::new(
        ExtendedId::new(frame_id(MessageKind::Grant, 0, 0)).unwrap(),
        &[0; 5],
    )
    .unwrap();
    assert_eq!(r.push::<f64, _>(&f, NOW), Err(DecodeError::BadLength));
    let f = TestFrame::new(
        ExtendedId::new(frame_id(MessageKind::Grant, 1, 0)).unwrap(),
        &[0x10; 8],
    )
    .unwrap();
    assert_eq!(r.push::<f64, _>(&f, NOW), Err(DecodeError::BadFrameIndex));
    let raw = 6 << 26 | 0xFF << 16 | 0xC0 << 8 | 1;
    let f = TestFrame::new(ExtendedId::new(raw).unwrap(), &[0; 8]).unwrap();
    assert_eq!(r.push::<f64, _>(&f, NOW), Err(DecodeError::UnknownKind(12)));
    assert!(r.slots.is_empty());
}

/// Survivors of `cargo mutants -f can-gateway/src/codec.rs` (now `codec/`; docs/mutants.md), each
/// killed here: range checks on encoding, the heading's wrap, the decoder's bounds,
/// remote frames, staleness of `Located`, and every field of the junction messages.
mod mutation_audit {
    use super::*;

    #[test]
    fn finite_values_outside_a_field_are_refused() {
        let mut s = state();
        s.v = -1.0;
        let e = encode::<f64, TestFrame>(&Message::State(s), 7, 0).unwrap_err();
        assert_eq!(e, EncodeError::OutOfRange(Field::Speed));
        s = state();
        s.x = 3.0e7; // beyond i32 at 0.01 m
        let e = encode::<f64, TestFrame>(&Message::State(s), 7, 0).unwrap_err();
        assert_eq!(e, EncodeError::OutOfRange(Field::X));
    }

    #[test]
    fn tracks_must_fit_their_nibbles() {
        for (heading, lane, ok) in [(3, 15, true), (4, 0, false), (0, 16, false), (4, 16, false)] {
            let mut req = request(9);
            req.inlet = TrackWire { heading, lane };
            let got = encode::<f64, TestFrame>(&Message::Request(req), 9, 0);
            assert_eq!(got.is_ok(), ok, "heading {heading} lane {lane}");
            if !ok {
                assert_eq!(
                    got.unwrap_err(),
                    EncodeError::OutOfRange(Field::TrackHeading)
                );
            }
        }
        // Both nibbles arrive where they were put.
        let mut req = request(9);
        req.inlet = TrackWire {
            heading: 3,
            lane: 15,
        };
        let mut r = Reassembler::<8>::new();
        let Ok(Some(Message::Request(got))) = push_all(&mut r, &Message::Request(req), 9, 0) else {
            panic!("a request");
        };
        assert_eq!(got.inlet, req.inlet);
    }

    #[test]
    fn headings_wrap_into_minus_pi_to_pi() {
        let pi = core::f64::consts::PI;
        for (theta, want) in [
            (3.0 * pi + 0.25, -pi + 0.25),
            (2.0 * pi + 0.5, 0.5),
            (-2.0 * pi - 0.5, -0.5),
            (pi, -pi),
            (-pi, -pi),
            (1.0, 1.0),
        ] {
            let mut s = state();
            s.theta = theta;
            let mut r = Reassembler::<8>::new();
            let Ok(Some(Message::State(got))) = push_all(&mut r, &Message::State(s), 7, 0) else {
                panic!("a state");
            };
            assert!(
                (got.theta - want).abs() <= HEADING_RES,
                "{theta} → {}, want {want}",
                got.theta
            );
        }
        assert_eq!(libm_floor(1.0), 1.0);
        assert_eq!(libm_floor(-0.5), -1.0);
        assert_eq!(libm_floor(2.5), 2.0);
    }

    fn wire_state(heading: i16, speed: u16) -> StateWire {
        StateWire {
            x: 0,
            y: 0,
            heading,
            speed,
            yaw: 0,
            lanes: 0xF1,
            beta_flags: NO_LANE,
            stamp: 1,
            brake: 0,
            length: 0,
        }
    }

    #[test]
    fn decoded_headings_and_speeds_are_bounded() {
        let pi = core::f64::consts::PI;
        let at_pi = (pi / HEADING_RES).round() as i16;
        assert!(wire_state(at_pi, 0).state::<f64>(7, NOW).is_ok());
        assert!(wire_state(-at_pi, 0).state::<f64>(7, NOW).is_ok());
        assert_eq!(
            wire_state(at_pi + 2, 0).state::<f64>(7, NOW).err(),
            Some(DecodeError::OutOfRange(Field::Heading))
        );
        assert_eq!(
            wire_state(i16::MAX, 0).state::<f64>(7, NOW).err(),
            Some(DecodeError::OutOfRange(Field::Heading))
        );
        let limit = (SPEED_LIMIT / SPEED_RES).round() as u16;
        assert!(wire_state(0, limit).state::<f64>(7, NOW).is_ok());
        assert_eq!(
            wire_state(0, limit + 1).state::<f64>(7, NOW).err(),
            Some(DecodeError::OutOfRange(Field::Speed))
        );
        assert_eq!(speed(limit), Ok(SPEED_LIMIT));
        assert_eq!(speed(limit + 1), Err(DecodeError::OutOfRange(Field::Speed)));
    }

    #[test]
    fn remote_frames_are_not_ours() {
        let id = ExtendedId::new(frame_id(MessageKind::Grant, 0, MANAGER_ADDRESS)).unwrap();
        let f = TestFrame::new_remote(id, 8).unwrap();
        let mut r = Reassembler::<2>::new();
        assert_eq!(r.push::<f64, _>(&f, NOW), Err(DecodeError::NotOurs));
        assert!(r.slots.is_empty());
    }

    #[test]
    fn an_older_located_state_is_stale() {
        let mut r = Reassembler::<8>::new();
        let mut st = state();
        st.id = 7;
        st.stamp = secs(20.0);
        let newer = Message::Located {
            segment: 1,
            state: st,
        };
        assert!(matches!(push_all(&mut r, &newer, 7, 1), Ok(Some(_))));
        st.stamp = secs(10.0);
        let older = Message::Located {
            segment: 1,
            state: st,
        };
        assert_eq!(push_all(&mut r, &older, 7, 2), Err(DecodeError::Stale));
    }

    #[test]
    fn both_state_kinds_carry_the_braking_limit_and_zero_means_undeclared() {
        let mut st = state();
        st.id = 7;
        st.brake = planner_core::BrakeLimit::from_mps2(4.5);
        let brake_of = |m: Option<Message<f64>>| match m {
            Some(Message::Located { state, .. } | Message::State(state)) => state.brake,
            _ => panic!("a state"),
        };
        for located in [false, true] {
            let message = |st: VehicleState<f64>| match located {
                true => Message::Located {
                    segment: 1,
                    state: st,
                },
                false => Message::State(st),
            };
            let mut r = Reassembler::<8>::new();
            let mut declared = st;
            let got = push_all(&mut r, &message(declared), 7, 1);
            assert_eq!(brake_of(got.unwrap()), declared.brake, "located {located}");
            // An older sender's zero byte: not declared, so followers take a wall.
            declared.brake = None;
            declared.stamp = declared
                .stamp
                .saturating_add(planner_core::Duration::from_millis(10));
            let got = push_all(&mut r, &message(declared), 7, 2);
            assert_eq!(brake_of(got.unwrap()), None, "located {located}");
            // CAN FD carries the same byte.
            let fd: crate::FdFrame = encode_fd(&message(st), 7, 3).unwrap();
            let mut r = Reassembler::<8>::new();
            let got = r.push::<f64, _>(&fd, NOW);
            assert_eq!(brake_of(got.unwrap()), st.brake, "located {located}");
        }
    }

    #[test]
    fn junction_messages_keep_every_field() {
        let mut req = request(9);
        req.s = 1000.25; // beyond 16 bits at 0.01 m: the third byte counts
        req.arrival = secs(123.456);
        req.v = 13.9;
        req.brake = planner_core::BrakeLimit::from_mps2(4.5);
        req.length = planner_core::BodyLength::from_m(16.5);
        let m = Message::JunctionRequest {
            junction: 2,
            request: req,
        };
        let mut r = Reassembler::<8>::new();
        let Ok(Some(Message::JunctionRequest {
            junction,
            request: got,
        })) = push_all(&mut r, &m, 9, 0)
        else {
            panic!("a junction request");
        };
        assert_eq!(
            (junction, got.id, got.inlet, got.outlet),
            (2, 9, req.inlet, req.outlet)
        );
        assert!((got.s - req.s).abs() < 0.006, "{}", got.s);
        assert_eq!(got.arrival, req.arrival);
        assert!((got.v - req.v).abs() < 0.011, "{}", got.v);
        assert_eq!((got.brake, got.length), (req.brake, req.length));
        // CAN FD carries the same bytes.
        let fd: crate::FdFrame = encode_fd(&m, 9, 3).unwrap();
        let Ok(Some(Message::JunctionRequest {
            request: fd_got, ..
        })) = Reassembler::<8>::new().push::<f64, _>(&fd, NOW)
        else {
            panic!("a junction request over CAN FD");
        };
        assert_eq!((fd_got.brake, fd_got.length), (req.brake, req.length));
        // The plain request too: its two frames declare no body.
        let Ok(Some(Message::Request(got))) = push_all(&mut r, &Message::Request(req), 9, 1) else {
            panic!("a request");
        };
        assert!((got.s - req.s).abs() < 0.006 && got.arrival == req.arrival);
        assert_eq!((got.brake, got.length), (None, None));
        let exit = Message::JunctionExit {
            junction: 2,
            id: 9,
            at: secs(77.125),
        };
        assert_eq!(push_all(&mut r, &exit, 9, 2), Ok(Some(exit)));
    }
}

/// A solved command in lane 0, changing to none, its speed and yaw rate `v` and `omega`
/// (as an f32 planner computed them).
fn cmd(v: f32, omega: f32) -> crate::wire::Command<f64> {
    crate::wire::Command {
        period: 7,
        v: f64::from(v),
        omega: f64::from(omega),
        status: crate::wire::CommandStatus::Solved,
        lane: 0,
        alpha: None,
        beta: None,
    }
}

/// A command carries the f32 its planner computed, bit for bit; one that is not a
/// plausible command (NaN, reversing, spinning, an unknown status, no lane) is refused.
#[test]
fn commands_keep_their_f32_bits_and_refuse_garbage() {
    // The edges are plausible: standing, the speed limit, a full turn per second.
    let full_turn = 2.0 * core::f32::consts::PI;
    for (v, omega) in [
        (13.9_f32, 0.0_f32),
        (1e-7, -1e-9),
        (0.1 + 0.2, 0.333_333_34),
        (0.0, full_turn),
        (SPEED_LIMIT as f32, -full_turn),
    ] {
        let mut r = Reassembler::<8>::new();
        let got = push_all(&mut r, &Message::Command(cmd(v, omega)), 4, 1);
        let Ok(Some(Message::Command(c))) = got else {
            panic!("{got:?}")
        };
        // Every field back, the lanes' "none" included.
        assert_eq!(c.map(|x| x as f32), cmd(v, omega).map(|x| x as f32));
        assert_eq!(
            ((c.v as f32).to_bits(), (c.omega as f32).to_bits()),
            (v.to_bits(), omega.to_bits())
        );
    }
    // Bytes an encoder would refuse to write, written by hand.
    let bad = |edit: &dyn Fn(&mut [u8; 14])| {
        let m = Message::Command(cmd(1.0, 0.0));
        let mut body = super::encode::protected(&m, 4, 1).unwrap();
        let mut chunk = [0u8; 14];
        chunk.copy_from_slice(&body[..14]);
        edit(&mut chunk);
        body[..13].copy_from_slice(&chunk[..13]);
        body[13] = message_crc(MessageKind::Command, 4, 1, &body[..13]);
        let mut r = Reassembler::<8>::new();
        let mut res = Ok(None);
        for i in 0..2 {
            let mut data = [0u8; 8];
            data[0] = (i as u8) << 4 | 1;
            data[1..].copy_from_slice(&body[i * 7..i * 7 + 7]);
            let id = ExtendedId::new(frame_id(MessageKind::Command, i as u8, 4)).unwrap();
            res = r.push::<f64, _>(&TestFrame::new(id, &data).unwrap(), NOW);
        }
        res
    };
    let speed = crate::layout::COMMAND.speed.start;
    let yaw = crate::layout::COMMAND.yaw.start;
    let put = |b: &mut [u8; 14], at: usize, x: f32| b[at..at + 4].copy_from_slice(&x.to_le_bytes());
    for v in [f32::NAN, -1.0, 101.0, f32::INFINITY] {
        assert_eq!(
            bad(&|b| put(b, speed, v)),
            Err(DecodeError::OutOfRange(Field::Speed)),
            "{v}"
        );
    }
    for w in [f32::NAN, 7.0, -7.0] {
        assert_eq!(
            bad(&|b| put(b, yaw, w)),
            Err(DecodeError::OutOfRange(Field::YawRate)),
            "{w}"
        );
    }
    let status = crate::layout::COMMAND.status.start;
    assert_eq!(
        bad(&|b| b[status] = 9),
        Err(DecodeError::OutOfRange(Field::Flag))
    );
    let lanes = crate::layout::COMMAND.lanes.start;
    assert_eq!(
        bad(&|b| b[lanes] = 0xFF),
        Err(DecodeError::OutOfRange(Field::Lane))
    );
    let beta = crate::layout::COMMAND.beta.start;
    assert_eq!(
        bad(&|b| b[beta] = 0x1F),
        Err(DecodeError::OutOfRange(Field::Flag))
    );
}

/// What an encoder cannot put on the wire in a command, it refuses; and a command is its
/// sender's: any vehicle may send one, the time master not.
#[test]
fn commands_are_encoded_only_when_they_fit_and_come_from_vehicles() {
    let enc = |c: crate::wire::Command<f64>| {
        encode::<f64, TestFrame>(&Message::Command(c), 4, 1).map(|_| ())
    };
    let mut c = cmd(1.0, 0.0);
    c.v = f64::NAN;
    assert_eq!(enc(c), Err(EncodeError::OutOfRange(Field::Speed)));
    let mut c = cmd(1.0, 0.0);
    c.omega = f64::INFINITY;
    assert_eq!(enc(c), Err(EncodeError::OutOfRange(Field::YawRate)));
    let mut c = cmd(1.0, 0.0);
    c.lane = NO_LANE;
    assert_eq!(enc(c), Err(EncodeError::OutOfRange(Field::Lane)));
    let mut c = cmd(1.0, 0.0);
    c.beta = Some(NO_LANE);
    assert_eq!(enc(c), Err(EncodeError::OutOfRange(Field::Lane)));
    // A command is its sender's: any vehicle may send one, the time master not.
    let mut r = Reassembler::<8>::new();
    assert_eq!(
        push_all(&mut r, &Message::Command(cmd(1.0, 0.0)), CLOCK_ADDRESS, 1).map(|_| ()),
        Err(DecodeError::SenderMismatch)
    );
}

/// A vehicle's own state comes only from the time master's address (the world, in
/// simulation): a vehicle cannot tell another where it is.
#[test]
fn ego_states_come_only_from_the_time_master() {
    let Message::Located { segment, state } = naming_vehicle_9()[5] else {
        unreachable!("the sixth names a located state")
    };
    let ego = Message::Ego {
        segment,
        lanes: 2,
        state,
        v_ref: 27.8,
    };
    for sa in [9u8, 8, MANAGER_ADDRESS] {
        let mut r = Reassembler::<8>::new();
        assert_eq!(
            push_all(&mut r, &ego, sa, 1).map(|_| ()),
            Err(DecodeError::SenderMismatch),
            "from {sa:#x}"
        );
    }
    // A road has 1 to 14 lanes: the encoder writes no other count, the decoder reads none.
    for lanes in [0u8, NO_LANE, 200] {
        let m = Message::Ego {
            segment,
            lanes,
            state,
            v_ref: 27.8,
        };
        assert_eq!(
            encode::<f64, TestFrame>(&m, CLOCK_ADDRESS, 1).map(|_| ()),
            Err(EncodeError::OutOfRange(Field::Lane))
        );
    }
    let edge = |lanes| Message::Ego {
        segment,
        lanes,
        state,
        v_ref: 27.8,
    };
    for lanes in [1u8, 14] {
        let mut r = Reassembler::<8>::new();
        assert!(matches!(
            push_all(&mut r, &edge(lanes), CLOCK_ADDRESS, 1),
            Ok(Some(_))
        ));
    }
    let written: Frames<TestFrame> = encode(&edge(2), CLOCK_ADDRESS, 1).unwrap();
    let at = crate::layout::EGO.road_lanes.start;
    for bad in [0u8, NO_LANE] {
        let mut bytes = super::encode::protected(&edge(2), CLOCK_ADDRESS, 1).unwrap();
        bytes[at] = bad;
        bytes[27] = message_crc(MessageKind::Ego, CLOCK_ADDRESS, 1, &bytes[..27]);
        let mut r = Reassembler::<8>::new();
        let mut res = Ok(None);
        for (i, f) in written.iter().enumerate() {
            let mut data = [0u8; 8];
            data.copy_from_slice(f.data());
            data[1..].copy_from_slice(&bytes[i * 7..i * 7 + 7]);
            res = r.push::<f64, _>(&TestFrame::new(f.id(), &data).unwrap(), NOW);
        }
        assert_eq!(res, Err(DecodeError::OutOfRange(Field::Lane)), "{bad}");
    }
    let mut r = Reassembler::<8>::new();
    let got = push_all(&mut r, &ego, CLOCK_ADDRESS, 1);
    assert!(
        matches!(got, Ok(Some(Message::Ego { v_ref, .. })) if (v_ref - 27.8).abs() < 0.011),
        "{got:?}"
    );
}
