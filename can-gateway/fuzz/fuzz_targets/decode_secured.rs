//! Fuzzes the secured decoder (SecOC-style authenticators, issue 17): the input is read as
//! a sequence of frames (1 flag byte, 4 id bytes, 1 length byte, up to 8 data bytes, 1
//! clock byte that moves the receiver's clock on), pushed into one reassembler with a key
//! store and a freshness record. Any input must give messages, `None`s or typed errors —
//! never a panic — and a rejected frame must leave both the reassembler and the freshness
//! record unchanged. Half the inputs start with a genuinely signed message, so the fuzzer
//! also mutates frames that reach the MAC check.
#![no_main]

use can_gateway::codec::{encode_secured, SecuredFrames, Verifier};
use can_gateway::secoc::{derive_key, FreshnessRx, Key, KeyStore};
use can_gateway::{Message, PlainFrame, Reassembler};
use embedded_can::{ExtendedId, Frame, Id, StandardId};
use libfuzzer_sys::fuzz_target;

const MASTER: Key = Key([0x5a; 16]);

fuzz_target!(|bytes: &[u8]| {
    let mut keys = KeyStore::<4>::new();
    for sa in [1u8, 2, 0xF0, 0xF1] {
        keys.insert(sa, derive_key(&MASTER, sa)).unwrap();
    }
    let mut fresh = FreshnessRx::<8>::default();
    let mut r = Reassembler::<8>::new();
    let mut now: u64 = 1_000;
    let mut frames: Vec<PlainFrame> = Vec::new();
    if bytes.first().is_some_and(|b| b & 1 == 1) {
        let m = Message::<f64>::Grant { id: 2, until: 3.0 };
        let signed: SecuredFrames<PlainFrame> =
            encode_secured(&m, 0xF1, 1, &derive_key(&MASTER, 0xF1), now).unwrap();
        frames.extend(signed);
    }
    let mut rest = bytes;
    while rest.len() >= 7 {
        let flags = rest[0];
        let raw = u32::from_le_bytes([rest[1], rest[2], rest[3], rest[4]]);
        let len = usize::from(rest[5] % 9).min(rest.len() - 7);
        let data = &rest[6..6 + len];
        now += u64::from(rest[6 + len]);
        rest = &rest[7 + len..];
        let id = if flags & 1 == 0 {
            Id::Extended(ExtendedId::new(6 << 26 | 0xFF << 16 | (raw & 0xFFFF)).unwrap())
        } else if flags & 2 == 0 {
            Id::Extended(ExtendedId::new(raw & 0x1FFF_FFFF).unwrap())
        } else {
            Id::Standard(StandardId::new((raw & 0x7FF) as u16).unwrap())
        };
        frames.push(if flags & 4 != 0 {
            PlainFrame::new_remote(id, data.len()).unwrap()
        } else {
            PlainFrame::new(id, data).unwrap()
        });
    }
    for frame in &frames {
        let before = format!("{r:?} {fresh:?}");
        let v = Verifier {
            keys: &keys,
            freshness: &mut fresh,
            now_ms: now,
        };
        match r.push_secured::<f64, _, 4, 8>(frame, v) {
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
