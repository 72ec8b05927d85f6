//! Fuzzes the decoder: the input is read as a sequence of frames ([`frames::next`]),
//! pushed into one reassembler. Any input must give messages, `None`s or typed errors — never a panic — and a rejected frame must
//! leave the reassembler unchanged.
#![no_main]

use can_gateway::{Message, Reassembler};
use libfuzzer_sys::fuzz_target;

#[path = "frames.rs"]
mod frames;

fuzz_target!(|bytes: &[u8]| {
    let mut r = Reassembler::<8>::new();
    let mut rest = bytes;
    while let Some((frame, after)) = frames::next(rest) {
        rest = after;
        let before = format!("{r:?}");
        match r.push::<f64, _>(&frame) {
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
