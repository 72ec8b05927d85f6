//! The fuzz targets' reading of their input as frames.

use can_gateway::PlainFrame;
use embedded_can::{ExtendedId, Frame, Id, StandardId};

/// One frame from the front of `rest` — 1 flag byte, 4 id bytes, 1 length byte, up to 8
/// data bytes — and what follows it; `None` when fewer than 6 bytes are left.
pub fn next(rest: &[u8]) -> Option<(PlainFrame, &[u8])> {
    if rest.len() < 6 {
        return None;
    }
    let flags = rest[0];
    let raw = u32::from_le_bytes([rest[1], rest[2], rest[3], rest[4]]);
    let len = usize::from(rest[5] % 9).min(rest.len() - 6);
    let data = &rest[6..6 + len];
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
    Some((frame, &rest[6 + len..]))
}
