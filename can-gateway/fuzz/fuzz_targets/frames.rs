//! The fuzz targets' reading of their input as frames, classic and CAN FD.

use can_gateway::wire::{FD_LENGTHS, FD_SECURED_INDEX};
use can_gateway::FdFrame;
use embedded_can::{ExtendedId, Frame, Id, StandardId};

/// One frame from the front of `rest` — 1 flag byte, 4 id bytes, 1 length byte, up to 64
/// data bytes — and what follows it; `None` when fewer than 6 bytes are left. A length
/// beyond 8 is rounded down to a CAN FD data length; flag bit 3 makes the frame index of
/// this protocol's identifiers a CAN FD one (15, or 14 with bit 4), so that whole-message
/// frames are reached often.
pub fn next(rest: &[u8]) -> Option<(FdFrame, &[u8])> {
    if rest.len() < 6 {
        return None;
    }
    let flags = rest[0];
    let mut raw = u32::from_le_bytes([rest[1], rest[2], rest[3], rest[4]]);
    let mut len = usize::from(rest[5] % 65).min(rest.len() - 6);
    if len > 8 {
        len = FD_LENGTHS
            .iter()
            .copied()
            .filter(|&l| l <= len)
            .max()
            .unwrap_or(8);
    }
    let data = &rest[6..6 + len];
    if flags & 8 != 0 {
        let index = if flags & 16 != 0 {
            u32::from(FD_SECURED_INDEX)
        } else {
            15
        };
        raw = raw & !0x0F00 | index << 8;
    }
    let id = if flags & 1 == 0 {
        // Bias toward this protocol's identifiers: priority 6, PF 0xFF.
        Id::Extended(ExtendedId::new(6 << 26 | 0xFF << 16 | (raw & 0xFFFF)).unwrap())
    } else if flags & 2 == 0 {
        Id::Extended(ExtendedId::new(raw & 0x1FFF_FFFF).unwrap())
    } else {
        Id::Standard(StandardId::new((raw & 0x7FF) as u16).unwrap())
    };
    let frame = if flags & 4 != 0 {
        FdFrame::new_remote(id, data.len().min(8)).unwrap()
    } else {
        FdFrame::new(id, data).unwrap()
    };
    Some((frame, &rest[6 + len..]))
}
