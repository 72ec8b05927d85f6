//! Fuzzes the decoder: the input is read as a sequence of frames (1 flag byte, 4 id
//! bytes, 1 length byte, up to 8 data bytes), pushed into one reassembler. Any input must
//! give messages, `None`s or typed errors — never a panic — and a rejected frame must
//! leave the reassembler unchanged.
#![no_main]

use can_gateway::{Message, Reassembler};
use embedded_can::{ExtendedId, Frame, Id, StandardId};
use libfuzzer_sys::fuzz_target;

use can_gateway::PlainFrame;

fuzz_target!(|bytes: &[u8]| {
    let mut r = Reassembler::<8>::new();
    let mut rest = bytes;
    while rest.len() >= 6 {
        let flags = rest[0];
        let raw = u32::from_le_bytes([rest[1], rest[2], rest[3], rest[4]]);
        let len = usize::from(rest[5] % 9).min(rest.len() - 6);
        let data = &rest[6..6 + len];
        rest = &rest[6 + len..];
        let id = if flags & 1 == 0 {
            // Bias toward this protocol's identifiers: priority 6, PF 0xFF.
            Id::Extended(ExtendedId::new(6 << 26 | 0xFF << 16 | (raw & 0xFFFF)).unwrap())
        } else if flags & 2 == 0 {
            Id::Extended(ExtendedId::new(raw & 0x1FFF_FFFF).unwrap())
        } else {
            Id::Standard(StandardId::new((raw & 0x7FF) as u16).unwrap())
        };
        let frame = if flags & 4 != 0 {
            PlainFrame::new_remote(id, data.len()).unwrap()
        } else {
            PlainFrame::new(id, data).unwrap()
        };
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
