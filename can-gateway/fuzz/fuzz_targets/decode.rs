//! Fuzzes the decoder: the input's first 8 bytes are the receiver's clock (ms, so that
//! the restoring of wrapped wire times is fuzzed too), the rest is read as a sequence of
//! frames ([`frames::next`]), pushed into one reassembler. Any input must give messages, `None`s or typed errors — never a panic — and a rejected frame must
//! leave the reassembler unchanged.
#![no_main]

use can_gateway::{Message, Reassembler};
use libfuzzer_sys::fuzz_target;
use can_gateway::Instant;

#[path = "frames.rs"]
mod frames;

fuzz_target!(|bytes: &[u8]| {
    let mut r = Reassembler::<8>::new();
    let (clock, mut rest) = bytes.split_at(bytes.len().min(8));
    let mut ms = [0u8; 8];
    ms[..clock.len()].copy_from_slice(clock);
    let now = Instant::from_millis(u64::from_le_bytes(ms));
    while let Some((frame, after)) = frames::next(rest) {
        rest = after;
        let before = format!("{r:?}");
        match r.push::<f64, _>(&frame, now) {
            Err(_) => assert_eq!(
                before,
                format!("{r:?}"),
                "a rejected frame changed the state"
            ),
            Ok(Some(Message::State(s))) => assert!(s.x.is_finite() && s.v >= 0.0),
            Ok(_) => {}
        }
    }
});
