//! Lines of the `candump -l` log format, `(seconds.micros) iface ID#DATA`, so that a
//! gateway's traffic can be read by can-utils, python-can and cantools.

use core::fmt::Write;
use embedded_can::{Frame, Id};
use heapless::String;

/// One `candump -l` line (without newline) for `frame` seen at `micros` µs on `iface`;
/// a frame with more than 8 data bytes is a CAN FD frame, written `ID##0DATA` (flags 0:
/// no bit-rate switch) as candump writes it. `None` if the interface name does not fit
/// (the line holds 192 bytes).
pub fn candump_line<Fr: Frame>(micros: u64, iface: &str, frame: &Fr) -> Option<String<192>> {
    let mut s = String::new();
    write!(
        s,
        "({}.{:06}) {} ",
        micros / 1_000_000,
        micros % 1_000_000,
        iface
    )
    .ok()?;
    match frame.id() {
        Id::Extended(e) => write!(s, "{:08X}#", e.as_raw()).ok()?,
        Id::Standard(st) => write!(s, "{:03X}#", st.as_raw()).ok()?,
    }
    if frame.data().len() > 8 {
        s.push_str("#0").ok()?;
    }
    for b in frame.data() {
        write!(s, "{b:02X}").ok()?;
    }
    Some(s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::{FdFrame, PlainFrame};
    use embedded_can::{ExtendedId, StandardId};

    #[test]
    fn classic_and_fd_lines_as_candump_writes_them() {
        let id = ExtendedId::new(0x18FF_1F07).unwrap();
        let eight = FdFrame::new(id, &[0xAB; 8]).unwrap();
        assert_eq!(
            candump_line(1_700_000_000_123_456, "vcan0", &eight)
                .unwrap()
                .as_str(),
            "(1700000000.123456) vcan0 18FF1F07#ABABABABABABABAB"
        );
        let fd = FdFrame::new(id, &[0x01; 12]).unwrap();
        assert_eq!(
            candump_line(2_000_001, "can1", &fd).unwrap().as_str(),
            "(2.000001) can1 18FF1F07##0010101010101010101010101"
        );
        let std = PlainFrame::new(StandardId::new(0x12).unwrap(), &[]).unwrap();
        assert_eq!(
            candump_line(0, "vcan0", &std).unwrap().as_str(),
            "(0.000000) vcan0 012#"
        );
        // The longest line fits: 64 data bytes on a 15-byte interface name.
        let big = FdFrame::new(id, &[0xFF; 64]).unwrap();
        let line = candump_line(u64::MAX, "abcdefghijklmno", &big).unwrap();
        assert!(line.ends_with(&"FF".repeat(64)));
        assert!(candump_line(0, &"x".repeat(200), &big).is_none());
    }
}
