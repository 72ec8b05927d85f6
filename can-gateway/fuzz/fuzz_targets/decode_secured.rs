//! Fuzzes the secured decoder (SecOC-style authenticators): the input is read as
//! a sequence of frames ([`frames::next`]), each followed by one byte that moves the
//! receiver's clock on, pushed into one reassembler with a key
//! store and a freshness record. Any input must give messages, `None`s or typed errors —
//! never a panic — and a rejected frame must leave both the reassembler and the freshness
//! record unchanged. Half the inputs start with genuinely signed messages (classic frames,
//! or CAN FD frames with their MAC inside), so the fuzzer also mutates frames that reach
//! the MAC check.
#![no_main]

use can_gateway::codec::{encode_fd_secured, encode_secured, SecuredFrames, Verifier};
use can_gateway::secoc::{derive_key, FreshnessRx, Key, KeyStore};
use can_gateway::{FdFrame, Message, PlainFrame, Reassembler};
use libfuzzer_sys::fuzz_target;
use can_gateway::Instant;

#[path = "frames.rs"]
mod frames;

const MASTER: Key = Key([0x5a; 16]);

fuzz_target!(|bytes: &[u8]| {
    let mut keys = KeyStore::<4>::new();
    for sa in [1u8, 2, 0xF0, 0xF1] {
        keys.insert(sa, derive_key(&MASTER, sa)).unwrap();
    }
    let mut fresh = FreshnessRx::<8>::default();
    let mut r = Reassembler::<8>::new();
    let mut now: u64 = 1_000;
    let mut received: Vec<FdFrame> = Vec::new();
    let m = Message::<f64>::Grant {
        id: 2,
        until: Instant::from_millis(3_000),
    };
    let key = derive_key(&MASTER, 0xF1);
    match bytes.first().map(|b| b & 3) {
        Some(1) => {
            let signed: SecuredFrames<PlainFrame> = encode_secured(&m, 0xF1, 1, &key, now).unwrap();
            received.extend(signed.into_iter().map(FdFrame::from));
        }
        Some(3) => {
            let at = Instant::from_millis(bytes.get(1).map_or(1_000, |b| u64::from(*b) * 1_000));
            let exit = Message::<f64>::Exit { id: 1, at };
            received.push(encode_fd_secured(&exit, 1, 2, &derive_key(&MASTER, 1), now).unwrap());
            received.push(encode_fd_secured(&m, 0xF1, 1, &key, now).unwrap());
        }
        _ => {}
    }
    let mut rest = bytes;
    // Each frame ([`frames::next`]) is followed by one byte that moves the clock on.
    while let Some((frame, after)) = frames::next(rest) {
        let Some((&tick, after)) = after.split_first() else {
            break;
        };
        now += u64::from(tick);
        rest = after;
        received.push(frame);
    }
    for frame in &received {
        let before = format!("{r:?} {fresh:?}");
        let v = Verifier {
            keys: &keys,
            freshness: &mut fresh,
        };
        match r.push_secured::<f64, _, 4, 8>(frame, Instant::from_millis(now), v) {
            Err(_) => assert_eq!(
                before,
                format!("{r:?} {fresh:?}"),
                "a rejected frame changed the state"
            ),
            Ok(Some(Message::State(s))) => assert!(s.x.is_finite() && s.v >= 0.0),
            Ok(_) => {}
        }
    }
});
