//! Any byte stream on a serial-line CAN link (`can_gateway::slcan`): every line gives a
//! frame, a command or a typed error, never a panic; and every frame read writes back as a
//! line that reads as the same frame.
#![no_main]

use can_gateway::slcan::{encode, parse, Line, LineBuffer, MAX_LINE};
use can_gateway::PlainFrame;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut lines = LineBuffer::new();
    for &byte in data {
        if let Some(Ok(Line::Frame(f))) = lines.push::<PlainFrame>(byte) {
            let mut out = [0u8; MAX_LINE + 1];
            let n = encode(&f, &mut out).expect("a classic frame fits a line");
            let back = parse::<PlainFrame>(&out[..n - 1]).expect("a written line reads");
            assert_eq!(back, Line::Frame(f));
        }
    }
});
